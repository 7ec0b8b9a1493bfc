"""Physics core of flexlink_ros: numpy/scipy only, no ROS import, usable offline."""
