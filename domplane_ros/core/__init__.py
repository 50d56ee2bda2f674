"""The estimator core: homographies, potentials, the two-step iteration, prior, features, mask.

``result`` holds the result values (one failure type, :class:`FailedEstimate`), ``estimator``
the two-step iteration over one feature set (``TwoStep``), ``plane`` the one-call
``estimate_plane``, ``prior`` the candidates and the one prior search (``PriorSearch``),
``screening`` their cheap energy. Nothing here imports rclpy, message packages or rosbags: it
takes numpy arrays and typed config objects and returns typed result values.
"""
