"""Device emulators: the package's simulator world behind the real device protocols.

``landmark_nav emulate urg|lms200|p2os`` serves one on a pseudo-terminal (stable symlink) and
a TCP port, so the drivers can be run end to end without hardware; see :mod:`.server`.
"""
