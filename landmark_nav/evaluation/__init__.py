"""Offline evaluation: every scorer and runner of the package, above the algorithm cores.

The cores (laser, slam, localization, vision, ...) never import this package nor the
simulator; the tools and tests call these modules, so a figure printed by a command and
the one a test asserts come from the same code.

Modules:

* :mod:`.trajectory` -- ATE / RPE through ``evo``'s metrics, stamp association, TUM files.
* :mod:`.bags` -- a bag with ``/scan``, ``/odom`` and a reference seen as a scenario
  (laser facts from ``custom_data``, ``ground_truth.yaml`` or options); an Odometry
  topic as arrays (``read_track``).
* :mod:`.odometry_drift` -- odometry against the ground truth of a bag (``landmark_nav
  demo``'s drift table); the NEES of an odometry noise model over path windows.
* :mod:`.slam` -- EKF-SLAM runner and scores on simulated runs and bags
  (``landmark_nav evaluate``).
* :mod:`.features` -- corner and line extractor scores against the simulator's truth.
* :mod:`.scan_metrics` -- truth-free feature metrics for real scans (PLE ray metric,
  false-surface beams, repeatability).
* :mod:`.feature_bags` -- the feature runners on a bag (``landmark_nav evaluate-features``):
  simulator bags against their ground truth, any bag with ``/scan`` by the truth-free
  metrics.
* :mod:`.localization` -- sonar EKF / UKF runs and errors, the hallway study
  (``python -m landmark_nav.evaluation.localization``).
* :mod:`.localization_bags` -- the same on a bag (``landmark_nav evaluate-localization``).
* :mod:`.corridor_bag` -- the corridor follower's estimation loop on a bag against its
  ground truth (``landmark_nav evaluate-corridor``).
* :mod:`.vision` -- landmark detection and pose statistics on rendered frames
  (``python -m landmark_nav.evaluation.vision``).
* :mod:`.landmarks_real` -- landmarks, AprilTags and ArUco markers composited into real
  photographs (``python -m landmark_nav.evaluation.landmarks_real``), with its parts
  :mod:`.marker_composites`, :mod:`.marker_detectors`, :mod:`.marker_trials`,
  :mod:`.marker_free_frames` and :mod:`.landmark_stages`.
"""
