"""The estimator core: homographies, potentials, the two-step iteration, prior, features, mask.

``result`` holds the result values (one failure type, :class:`FailedEstimate`), ``estimator``
the two-step iteration over one feature set (``TwoStep``) and ``estimate_plane``,
``prior`` the candidates and the one prior search (``PriorSearch``). Nothing here imports
rclpy, message packages or rosbags: it takes numpy arrays and typed config objects and returns
typed result values.
"""
