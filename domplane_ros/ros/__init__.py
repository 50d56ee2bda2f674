"""The live ROS 2 adapter: ``plane_node`` and the ROS message building it needs."""
