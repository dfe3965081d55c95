"""From simulated hair to what is published, and with which settings: ROS-free, shared by the
node and the bag runs."""
