"""Deterministic simulator: world, robot, odometry, laser and sonar, named scenarios."""
