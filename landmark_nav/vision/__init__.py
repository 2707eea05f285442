"""Vision cores: the artificial landmark design and the camera model.

Pure Python/numpy/OpenCV; no rclpy and no message types (see
:mod:`landmark_nav.conversions` for CameraInfo <-> :class:`CameraModel`).

* :mod:`.landmark` -- :class:`LandmarkDesign` (the printed frame + code geometry of the visual
  navigation chapter §2.1, encode/decode/render), :func:`write_printable`,
  :class:`InvalidCodeError`.
* :mod:`.camera` -- :class:`CameraModel` (pinhole + plumb_bob distortion in the REP 103
  camera optical frame), :data:`OPTICAL_FROM_BODY`.
"""
