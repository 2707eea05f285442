"""The ``landmark_nav`` command line."""
