"""One camera-pair stream: input checks, pairing, the pipeline across frames and its status.

Shared by the live node (:mod:`domplane_ros.ros`) and the offline replay
(:mod:`domplane_ros.replay`); no ROS imports.
"""
