"""Device drivers: pure protocol modules (SCIP 2.0, SICK LMS2xx, P2OS) and their transports.

The protocol modules (:mod:`.scip2`, :mod:`.lms2xx`, :mod:`.p2os`) are byte-level encoders and
decoders: bytes in, frames out. They never read the clock, do no I/O and do not import rclpy;
every error they raise is a :class:`~landmark_nav.drivers.errors.ProtocolError`.
"""

from landmark_nav.drivers.errors import (ChecksumError, EncodeError, FramingError,
                                         ProtocolError, TruncatedError)

__all__ = ['ChecksumError', 'EncodeError', 'FramingError', 'ProtocolError', 'TruncatedError']
