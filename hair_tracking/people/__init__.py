"""Every person in view: one hair per person, the people's guides advanced together (no ROS)."""
