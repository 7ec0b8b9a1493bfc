"""Studies beside the node's model: independent peers and comparisons (no ROS imports)."""
