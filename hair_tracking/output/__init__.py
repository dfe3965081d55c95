"""From simulated hair to published outputs, ROS-free: shared by the node and the bag runs."""
