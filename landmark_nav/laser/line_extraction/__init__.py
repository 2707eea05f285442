"""The steps of the line extractors of :mod:`landmark_nav.laser.lines`, one module each.

Import the public names from :mod:`landmark_nav.laser.lines`; these modules hold its
parts (the step numbers are those of its docstring):

* :mod:`.params`: ``LineParams``, ``METHODS``, ``CHI2_2DOF_95``.
* :mod:`.tls_fit`: total-least-squares fits in Hessian normal form from moment sums
  (corner chapter eqs. 5-10), the (rho, alpha) covariance from the point noise (line
  chapter eq. 7), the RMSE (eq. 21), ``fit_line`` and ``point_covariances``.
* :mod:`.scan_batch`: all clusters of a scan as one batch of points.
* :mod:`.split`: split-and-merge's recursive split at the farthest point (eq. 4).
* :mod:`.alfa`: ALFA's binary search for the line ends (RMSE, eq. 21, floating threshold).
* :mod:`.cleanup`: steps 1-2, break refinement and endpoint clean-up.
* :mod:`.merge`: step 3, the chi-square collinearity test and the merge of neighbours.
* :mod:`.growth`: step 4, growth over free points beside the lines.
* :mod:`.see_through`: step 5, no line over a beam seen through it (cuts at openings).
* :mod:`.occlusion`: step 5, extents cut at occluders and one fit across them.
* :mod:`.segments`: step 6 and ``LineSegment``, the result.

No module here imports :mod:`landmark_nav.laser.lines`.
"""
