"""Pair the parts of one scan's feature set that come on different topics (ROS free).

The ``ekf_slam`` node builds one feature set per scan from up to two messages with the
scan's stamp: the corner cloud (``corners/features``) and the scan itself (``scan``: the
lines and the visibility geometry). :class:`StampJoin` holds each part until the other
parts with the same stamp have come, then hands the set on. A part is given up for a
waiting set, and the set handed on without it, when

* a message of that part with a later stamp comes (one publisher delivers in order, so
  the one with this stamp was lost: e.g. a scan dropped by the sensor-data QoS, a corner
  set the extractor skipped);
* that part has no publisher (``alive(part)`` is false: nothing would ever come);
* more than ``max_waiting`` sets wait (the oldest goes on).

Sets come out in stamp order of completion; the caller decides what an incomplete set is
worth (the node warns and uses what it has).
"""

import bisect
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

#: One handed-on set: ``(stamp_ns, {part: item}, missing parts)``.
JoinedSet = Tuple[int, Dict[str, Any], Tuple[str, ...]]


class StampJoin:
    """Join messages of several parts by their stamp (module docstring).

    Args:
        parts: The parts a complete set has (e.g. ``('corners', 'scan')``).
        max_waiting: Most sets held at once.
    """

    def __init__(self, parts: Sequence[str], max_waiting: int = 50) -> None:
        """Start with nothing waiting."""
        if not parts:
            raise ValueError('StampJoin needs at least one part')
        self.parts = tuple(parts)
        self.max_waiting = int(max_waiting)
        self._stamps: List[int] = []  # sorted stamps of the waiting sets
        self._sets: Dict[int, Dict[str, Any]] = {}

    def __len__(self) -> int:
        """Return the number of waiting sets."""
        return len(self._stamps)

    def clear(self) -> None:
        """Forget the waiting sets."""
        self._stamps.clear()
        self._sets.clear()

    def add(self, part: str, stamp_ns: int, item: Any,
            alive: Optional[Callable[[str], bool]] = None) -> List[JoinedSet]:
        """Add one part of the set at ``stamp_ns``; return the sets ready to go on.

        Args:
            part: One of :attr:`parts`.
            stamp_ns: The message's stamp [ns].
            item: What to keep for the set (a part given twice keeps the last).
            alive: ``alive(part)``: whether a part may still come (its topic has a
                publisher); None: always.

        Returns:
            The sets handed on, oldest first (possibly none).
        """
        if part not in self.parts:
            raise ValueError(f'unknown part {part!r} (expected one of {self.parts})')
        stamp_ns = int(stamp_ns)
        if stamp_ns not in self._sets:
            bisect.insort(self._stamps, stamp_ns)
            self._sets[stamp_ns] = {}
        self._sets[stamp_ns][part] = item
        out = []
        for t in list(self._stamps):
            have = self._sets[t]
            missing = tuple(p for p in self.parts if p not in have)
            gone = [p for p in missing if (p == part and t < stamp_ns)
                    or (alive is not None and not alive(p))]
            if not missing or len(gone) == len(missing):
                out.append(self._pop(t, missing))
        while len(self._stamps) > self.max_waiting:
            t = self._stamps[0]
            out.append(self._pop(t, tuple(p for p in self.parts if p not in self._sets[t])))
        return out

    def _pop(self, t: int, missing: Tuple[str, ...]) -> JoinedSet:
        self._stamps.remove(t)
        return t, self._sets.pop(t), missing


__all__ = ['JoinedSet', 'StampJoin']
