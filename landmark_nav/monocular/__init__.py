"""Monocular localization against a 3-D line model (self-localization chapter §5).

Pure Python/numpy/OpenCV; no rclpy and no message types.

* :mod:`.model` -- :class:`LineModel` (vertices, edges, faces), its YAML file format,
  :func:`hallway_model` and the default model file :data:`DEFAULT_MODEL_PATH`.
* :mod:`.visibility` -- camera pose from the robot pose (eq. 16), projection (eqs. 14-15),
  visible model lines (§5.1: frustum test + midpoint ray cast against the faces).
* :mod:`.matching` -- Hough-space parameters of projected model lines, their covariance
  (eqs. 62-65), Mahalanobis gating and one-to-one assignment.
* :mod:`.localizer` -- the EKF (eqs. 55, 59-61, 66-71) with a lost state.
* :mod:`landmark_nav.vision.rwrht` -- image lines by the Random Window Randomized Hough
  Transform (Algorithm 2).
"""
