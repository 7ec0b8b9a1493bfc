"""Wire and file formats: CDR, MCAP reading and writing, the rosbag2 recorder."""  # noqa: A005
# flexlink_ros.io is never the standard io: every import of it is package-qualified.
