"""Conversions between ROS 2 messages and numpy arrays; knows nothing of hair."""
