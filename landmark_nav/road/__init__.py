"""Road following cores (visual navigation chapter §4).

Pure numpy/OpenCV; no rclpy (the node is :mod:`landmark_nav.nodes.road_classifier`).

* :mod:`.terrain` -- terrain classification from single tilted-2-D-laser scans (§4.2):
  raw height, roughness, step, curvature, slope, width; traversable segments; obstacles.
"""
