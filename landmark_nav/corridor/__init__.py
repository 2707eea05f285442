"""Corridor following cores (visual navigation chapter §3).

Pure numpy/OpenCV; no rclpy (the node is :mod:`landmark_nav.nodes.corridor_follower`).

* :mod:`.vanishing_point` -- the chapter's candidate clustering (§3.1.2), its projective and
  weighted form, segment labelling from end-point noise, Manhattan directions.
* :mod:`.orientation` -- camera tilt and robot heading from the corridor VP (eq. 21) with
  the camera mount.
* :mod:`.lateral` -- line matching and lateral position (§3.1.4-3.1.5, eqs. 22-23).
* :mod:`.fusion` -- EKF of heading, position along and across the corridor with
  dead reckoning (§3.2, eq. 24).
* :mod:`.frame` -- the per-frame pipeline (image -> heading and lateral position).
* :mod:`.controller` -- speed ramp and steering law for ``cmd_vel``.
* :mod:`.follower` -- the follower's estimation loop (frames and odometry -> fused pose),
  run by the node and the offline evaluation.
"""
