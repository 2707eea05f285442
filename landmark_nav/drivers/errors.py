"""Errors of the device-protocol modules; all are ``ValueError`` subclasses.

Every message says what failed and where (stream offset, line or field). Stream decoders do
not raise them: they return the exception objects in stream order next to the decoded frames,
so one corrupt frame never stops the stream.
"""

from typing import Optional

__all__ = ['ChecksumError', 'EncodeError', 'FramingError', 'ProtocolError', 'TruncatedError']


class ProtocolError(ValueError):
    """Base of every error raised (or reported) by the protocol modules.

    Attributes:
        offset: Byte offset of the offending frame (from the start of the stream for the
            stream decoders, from the start of the buffer for one-shot decoders), or None.
    """

    def __init__(self, message: str, offset: Optional[int] = None) -> None:
        super().__init__(message)
        self.offset = offset


class ChecksumError(ProtocolError):
    """A checksum or CRC does not match the bytes it covers."""


class FramingError(ProtocolError):
    """Bytes do not form a valid frame: bad start, length, character, field or layout."""


class TruncatedError(ProtocolError):
    """A frame ends before the length its header or layout requires."""


class EncodeError(ProtocolError):
    """A value cannot be represented in the protocol (an encoder argument is out of range)."""
