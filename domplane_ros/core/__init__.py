"""The estimator core: homographies, potentials, the two-step iteration, prior, features, mask.

Nothing here imports rclpy, message packages or rosbags: it takes numpy arrays and typed config
objects and returns typed result values.
"""
