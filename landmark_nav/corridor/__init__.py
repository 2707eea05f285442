"""Corridor following cores (visual navigation chapter §3): vanishing point, orientation.

Pure numpy/OpenCV; no rclpy.

* :mod:`.vanishing_point` -- the chapter's candidate clustering (§3.1.2), its projective and
  weighted form, segment labelling from end-point noise, Manhattan directions.
* :mod:`.orientation` -- camera tilt and robot heading from the corridor VP (eq. 21) with
  the camera mount.
"""
