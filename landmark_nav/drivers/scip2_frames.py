"""SCIP 2.0 frames: the decoded replies, the sensor geometry and the beam angles.

:class:`ScanFrame` (``MD``/``MS``/``ME`` scans, ``GD``/``GS``/``GE`` replies with data),
:class:`InfoReply` (``VV``/``PP``/``II``), :class:`TimeReply` (``TM1``) and
:class:`StatusReply` (every reply without data: acknowledgements and error statuses), as
:mod:`.scip2_decoder` returns them; :class:`SensorParams` (the ``PP`` reply,
``docs/protocols/scip2.md`` §5) and :func:`step_angles`. Entry point:
:mod:`landmark_nav.drivers.scip2`.
"""

from dataclasses import dataclass
import math
from typing import Dict, Optional, Tuple, Union

from landmark_nav.drivers.errors import FramingError
from landmark_nav.drivers.scip2_commands import status_meaning
import numpy as np


@dataclass(frozen=True)
class StatusReply:
    """A reply without data: acknowledgements (``00``) and error statuses."""

    command: str  # 'BM', 'QT', 'MD', 'SCIP2.0', ...
    parameters: str  # the echoed decimal parameters ('' for commands without any)
    status: str
    tag: str = ''

    @property
    def meaning(self) -> str:
        """Meaning of the status (see :func:`status_meaning`)."""
        return status_meaning(self.command, self.status)


@dataclass(frozen=True)
class InfoReply:
    """Reply to ``VV``, ``PP`` or ``II``: ``KEY:value`` lines in order of arrival.

    Checksum errors on these replies are tolerated (some URG-04LX firmware sends wrong ones on
    the ``VV`` serial line) and listed in ``checksum_warnings`` instead of raised.
    """

    command: str
    status: str
    fields: Tuple[Tuple[str, str], ...]
    checksum_warnings: Tuple[str, ...] = ()
    tag: str = ''

    def as_dict(self) -> Dict[str, str]:
        """Return the fields as a dict (a repeated key keeps its last value)."""
        return dict(self.fields)


@dataclass(frozen=True)
class TimeReply:
    """Reply to ``TM1``: the sensor's 24-bit millisecond counter."""

    status: str
    timestamp_ms: int
    tag: str = ''


@dataclass(frozen=True, eq=False)
class ScanFrame:
    """One scan: reply to ``GD``/``GS``/``GE`` or one ``MD``/``MS``/``ME`` scan (arrays read-only).

    ``ranges_m[i]`` belongs to step ``start_step + i * cluster`` (see :func:`step_angles`).
    """

    command: str  # 'MD', 'MS', 'ME', 'GD', 'GS' or 'GE'
    status: str  # '99' for MD/MS/ME scans, '00' for GD/GS/GE
    timestamp_ms: int  # raw 24-bit sensor time of step 0 (wraps every 2**24 ms)
    ranges_m: np.ndarray  # (N,) float64, REP 117 (+inf no return, NaN error)
    raw: np.ndarray  # (N,) uint32, the decoded values (mm, or error codes < DMIN_MM)
    intensities: Optional[np.ndarray]  # (N,) uint32 for ME/GE, else None
    start_step: int
    end_step: int
    cluster: int  # steps per value (an echoed 00 counts as 1)
    scan_interval: Optional[int] = None  # MD/MS/ME: scans skipped between outputs
    remaining_scans: Optional[int] = None  # MD/MS/ME: nn of the echo (00 = continuous)
    tag: str = ''


Frame = Union[ScanFrame, InfoReply, TimeReply, StatusReply]


@dataclass(frozen=True)
class SensorParams:
    """Sensor geometry from the ``PP`` reply (defaults: URG-04LX, docs/protocols/scip2.md §5)."""

    model: str = 'URG-04LX'
    dmin_mm: int = 20
    dmax_mm: int = 5600
    ares: int = 1024  # steps per revolution
    amin: int = 44  # first measurable step
    amax: int = 725  # last measurable step
    afrt: int = 384  # step facing forwards
    scan_rpm: int = 600

    @classmethod
    def from_info(cls, reply: InfoReply) -> 'SensorParams':
        """Build from a ``PP`` reply.

        Raises:
            FramingError: If a field is missing or not an integer.
        """
        fields = reply.as_dict()
        try:
            return cls(model=fields.get('MODL', ''),
                       dmin_mm=int(fields['DMIN']), dmax_mm=int(fields['DMAX']),
                       ares=int(fields['ARES']), amin=int(fields['AMIN']),
                       amax=int(fields['AMAX']), afrt=int(fields['AFRT']),
                       scan_rpm=int(fields['SCAN']))
        except (KeyError, ValueError) as err:
            raise FramingError(f'PP reply: missing or non-integer field ({err})') from err

    def step_angle(self, step: float) -> float:
        """Return the angle (rad, CCW positive, 0 = front) of a step."""
        return (step - self.afrt) * 2.0 * math.pi / self.ares


URG_04LX = SensorParams()


def step_angles(start_step: int, count: int, cluster: int = 1,
                params: SensorParams = URG_04LX) -> np.ndarray:
    """Return the angles (rad) of the values of a scan.

    Value i is placed at step ``start_step + i * cluster``, as urg_node places ``angle_min``
    at the first step and uses ``cluster`` steps per increment.
    """
    steps = start_step + cluster * np.arange(count, dtype=np.float64)
    return (steps - params.afrt) * (2.0 * math.pi / params.ares)


__all__ = ['Frame', 'InfoReply', 'ScanFrame', 'SensorParams', 'StatusReply', 'TimeReply',
           'URG_04LX', 'step_angles']
