"""Charts of flexlink_ros: one module per topic, each with a plot_<topic>(out_dir) function."""
