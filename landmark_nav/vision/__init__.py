"""Vision cores: the artificial landmark (design, detection, pose) and the camera model.

Pure Python/numpy/OpenCV; no rclpy and no message types (see
:mod:`landmark_nav.conversions` for CameraInfo <-> :class:`CameraModel`).

* :mod:`.landmark` -- :class:`LandmarkDesign` (the printed frame + code geometry of the visual
  navigation chapter §2.1, encode/decode/render), :func:`write_printable`,
  :class:`InvalidCodeError`.
* :mod:`.camera` -- :class:`CameraModel` (pinhole + plumb_bob distortion in the REP 103
  camera optical frame), :data:`OPTICAL_FROM_BODY`.
* :mod:`.detector` -- corner filters, frame and code detection (chapter §2.2.1–2.2.3):
  :func:`~.detector.detect_landmarks` over its four steps :mod:`.corner_candidates`
  (eqs. 1–2, saddle points), :mod:`.frame_search` (eqs. 3–4), :mod:`.frame_fit` (eq. 5,
  sub-pixel refinement) and :mod:`.code_reading` (cells, threshold, decoding).
* :mod:`.pose` -- 6-DOF landmark pose by Gauss–Newton (§2.2.4, eqs. 6–19) with covariance,
  and the ``cv2.solvePnP`` reference.
* :mod:`.localize` -- landmark map, camera mount, robot pose from a detection and the
  odometry correction by landmark fixes (§2.3.3).
* :mod:`.image_lines` -- straight line segments: Canny + the segmented Hough transform of
  the visual navigation chapter §3.1.1, OpenCV HoughLinesP and LSD behind one interface
  (shared by the corridor follower and the monocular localizer).
* :mod:`.rwrht` -- Canny + the Random Window Randomized Hough Transform (self-localization
  chapter §5.2, Algorithm 2) and :func:`~.rwrht.detect_model_lines`, the line sources of
  the monocular localizer.
* :mod:`landmark_nav.evaluation.vision` (not in this package) -- Table 1 / Table 2 style
  statistics on rendered frames
  (``python -m landmark_nav.evaluation.vision``).
"""
