"""Camera scenarios for the visual landmark: ``landmark_views`` and ``landmark_shuttle``.

Both are pure-python generators of :class:`CameraFrame` (image + camera model + ground truth)
that tests and evaluations iterate in memory; :mod:`landmark_nav.sim.camera_record` writes
them into bags.

Conventions
-----------
* Camera poses are world poses of the REP 103 optical frame (z forward, x right, y down).
* A landmark's ground truth is ``(rotation, translation)`` with
  ``p_optical = rotation @ p_landmark + translation``, the landmark frame of
  :mod:`landmark_nav.vision.landmark` (origin at the frame centre, x out of the printed
  face, y right when looking at it, z up).
* View angles (``landmark_views``) are relative to the line of sight: in the camera's
  REP 103 body frame (x forward, y left, z up; ``body = OPTICAL_FROM_BODY.T @ optical``)
  the landmark's orientation is ``R = L Rz(pi + turn) Ry(tilt) Rx(roll)`` (active
  rotations), where ``L`` (:func:`line_of_sight_frame`) turns the body x axis onto the
  direction of the landmark centre keeping z up. ``turn = tilt = roll = 0`` is a landmark
  facing the camera upright; ``turn`` rotates it about the vertical, ``tilt > 0`` tips its
  face downward (the visual navigation chapter's "down tilt", §2.2.4), ``roll`` is the
  in-plane rotation, counter-clockwise as seen by the camera. The angle between the
  landmark normal and the line of sight is ``acos(cos(turn) cos(tilt))``.
* Frames and stamps: frame ``i`` has stamp ``START_NS + i * 100 ms`` (landmark_views) or the
  simulation time (landmark_shuttle). Randomness of view ``i`` comes from
  ``np.random.default_rng([seed, i])`` (scene) and ``np.random.default_rng([seed, i, 1])``
  (pixel noise), so any view can be regenerated alone, bit for bit.

Modules, each named after what it computes (this one is the entry point and re-exports
their public names):

* :mod:`.camera_frames` -- :class:`CameraFrame`, :class:`LandmarkTruth`, the default camera
  and the renderer cache;
* :mod:`.landmark_views` -- the ``landmark_views`` scenario: :class:`ViewOptions`,
  :func:`view_scene`, :func:`landmark_view`, :func:`iter_landmark_views`;
* :mod:`.landmark_shuttle` -- the ``landmark_shuttle`` scenario (§2.3.3):
  :class:`ShuttleConfig`, :func:`iter_landmark_shuttle`, :func:`oracle_localizer`.
"""

from .camera_frames import (CameraFrame, default_camera, landmark_truth, LandmarkTruth,
                            simulator_for)
from .landmark_shuttle import (iter_landmark_shuttle, oracle_localizer,
                               robot_pose_from_landmark, shuttle_scene, ShuttleArrival,
                               ShuttleConfig, ShuttleSample)
from .landmark_views import (iter_landmark_views, landmark_view, line_of_sight_frame,
                             random_code, random_photometry, sample_spec, view_scene,
                             ViewOptions)

CAMERA_SCENARIOS = ('landmark_views', 'landmark_shuttle')

__all__ = ['CAMERA_SCENARIOS', 'CameraFrame', 'default_camera', 'iter_landmark_shuttle',
           'iter_landmark_views', 'landmark_truth', 'landmark_view', 'LandmarkTruth',
           'line_of_sight_frame',
           'oracle_localizer', 'random_code', 'random_photometry', 'robot_pose_from_landmark',
           'sample_spec', 'ShuttleArrival', 'ShuttleConfig', 'ShuttleSample', 'shuttle_scene',
           'simulator_for', 'ViewOptions', 'view_scene']
