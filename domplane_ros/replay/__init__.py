"""The offline adapter: ``plane_replay`` reads a rosbag2 file and records what the node would."""
