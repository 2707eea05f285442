"""Bookkeeping shared by the three stream decoders (SCIP 2.0, LMS2xx, P2OS).

A stream decoder keeps the bytes of an incomplete frame, counts stream offsets across
:meth:`StreamDecoder.feed` calls, and reports bytes skipped while hunting for the next frame
once, as a :class:`~landmark_nav.drivers.errors.FramingError` placed before the next valid
item. Subclasses implement ``feed`` (the framing of their protocol) with :meth:`_skip`,
:meth:`_report` and :meth:`_consume`.
"""

from typing import List

from landmark_nav.drivers.errors import FramingError


class StreamDecoder:
    """Buffer, stream offsets and skipped-byte reporting of an incremental decoder."""

    #: What a valid item starts with, for the skipped-bytes message.
    unit = 'frame'

    def __init__(self) -> None:
        """Start with an empty buffer at stream offset 0."""
        self._buf = bytearray()
        self._base = 0  # stream offset of self._buf[0]
        self._garbage = 0  # bytes skipped since the last reported item
        self._garbage_at = 0
        self._quiet = False  # skipped bytes belong to an error already reported

    @property
    def buffered(self) -> int:
        """Number of bytes held for an incomplete frame."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop buffered bytes (e.g. after a reconnect); offsets keep counting."""
        self._base += len(self._buf)
        self._buf.clear()
        self._garbage = 0
        self._quiet = False

    def _skip(self, pos: int, end: int) -> None:
        """Note that buffer bytes ``pos:end`` are skipped."""
        if end > pos:
            if not self._garbage:
                self._garbage_at = self._base + pos
            self._garbage += end - pos

    def _report(self, out: List[object], item: object) -> None:
        """Append ``item`` to ``out``, preceded by the skipped-bytes error if there is one."""
        if self._garbage and not self._quiet:
            out.append(FramingError(f'skipped {self._garbage} bytes before a valid {self.unit} '
                                    f'at offset {self._garbage_at}', self._garbage_at))
        self._garbage = 0
        self._quiet = False
        out.append(item)

    def _consume(self, pos: int) -> None:
        """Drop the first ``pos`` buffered bytes (decoded or skipped)."""
        del self._buf[:pos]
        self._base += pos
