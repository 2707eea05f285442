"""landmark_nav: landmark-based navigation for a differential-drive robot (ROS 2 Jazzy)."""

__version__ = '0.1.0'
