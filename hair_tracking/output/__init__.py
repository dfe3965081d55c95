"""What the hair is published as and with which settings: shared by bags and ros, no ROS."""
