# flexlink_ros.io never shadows the standard io: every import in the package is absolute.
"""Wire and file formats: CDR, MCAP reading and writing, the rosbag2 recorder."""  # noqa: A005
