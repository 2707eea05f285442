"""One thin module per ROS executable."""
