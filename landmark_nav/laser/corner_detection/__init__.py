"""The parts of the corner detectors of :mod:`landmark_nav.laser.corners`, one module each.

Import the public names from :mod:`landmark_nav.laser.corners`; these modules hold its
parts (corner chapter, Namoshe et al., section 2.1):

* :mod:`.params`: ``CornerParams``, ``METHODS``.
* :mod:`.corner`: ``Corner``, the result, with its bisector and opening.
* :mod:`.scan_stack`: all clusters of a scan back to back, arm sample gathering.
* :mod:`.tls_lines`: total-least-squares lines from moment sums (eqs. 5-10), their
  intersection, its covariance and the lines' angle variances from the point noise
  ``Q_i`` (line chapter eq. 7, ``point_covariance``).
* :mod:`.windows`: the window detectors, ``sliding_window`` (section 2.1.1, eq. 1) and
  ``minus_cosine`` (section 2.1.3, eq. 11, midpoint-shift check of Figs. 11-12).
* :mod:`.refine`: refinement of minus-cosine detections by two TLS lines, and the arm
  checks (real surfaces, no false surface) shared with split and merge.
* :mod:`.split_merge`: the ``split_merge`` detector (section 2.1.2, eq. 4).
* :mod:`.arm_ends`: what the scan shows beyond each arm's outer end (``Corner.arm_ends``).

No module here imports :mod:`landmark_nav.laser.corners`.
"""
