"""SCIP 2.0 command set: commands, echo lines, scan geometry and reply statuses.

The host sends a 2-letter command with fixed-width decimal parameters, an optional tag (``;``
+ up to 16 characters) and LF (``docs/protocols/scip2.md`` §2-§5); the sensor's reply starts
with the echo of that line. This module holds what the encoders
(:mod:`.scip2_encoders`) and the decoder (:mod:`.scip2_decoder`) both need: the command
tables, the echo-line pattern, the number of values a scan command's steps and cluster
count give, and the meaning of every status code (§6, :func:`status_meaning`). Entry point:
:mod:`landmark_nav.drivers.scip2`.
"""

import re
from typing import Dict, Tuple

BLOCK_CHARS = 64  # data characters per line (the last line of a reply may be shorter)
_LF = 0x0A

# Scan commands -> characters per value (docs/protocols/scip2.md §4-§5). ME/GE (distance +
# intensity, 3 + 3 characters) exist on the UTM-30LX only (the URG-04LX lacks them).
SCAN_COMMANDS: Dict[str, int] = {'MD': 3, 'MS': 2, 'ME': 6, 'GD': 3, 'GS': 2, 'GE': 6}
_CONTINUOUS = ('MD', 'MS', 'ME')
_INFO_COMMANDS = ('VV', 'PP', 'II')
_SIMPLE_COMMANDS = ('VV', 'PP', 'II', 'BM', 'QT', 'RS', 'SCIP2.0')
BAUD_RATES = (19200, 38400, 57600, 115200, 250000, 500000, 750000)  # SS, scip2.md §5

_TAG_RE = re.compile(r'[A-Za-z0-9 ._+@]{0,16}')
# One echo line: command with its fixed-width parameters, optional tag, LF.
_ECHO_RE = re.compile(
    rb'(SCIP2\.0|(?:MD|MS|ME)[0-9]{13}|(?:GD|GS|GE)[0-9]{10}|SS[0-9]{6}|TM[0-2]'
    rb'|VV|PP|II|BM|QT|RS)(;[A-Za-z0-9 ._+@]{0,16})?\n')
_MAX_ECHO = 15 + 1 + 16 + 1  # longest echo line (MD + tag + LF)


# ---------------------------------------------------------------------------- status codes

# (command, status) -> meaning, as docs/protocols/scip2.md §6 lists them.
_SCAN_PARAM_ERRORS = {
    '01': 'starting step has a non-numeric value',
    '02': 'end step has a non-numeric value',
    '03': 'cluster count has a non-numeric value',
    '04': 'end step is out of range',
    '05': 'end step is smaller than the starting step',
}
_STATUS_TABLE: Dict[Tuple[str, str], str] = {}
for _cmd in SCAN_COMMANDS:
    for _code, _text in _SCAN_PARAM_ERRORS.items():
        _STATUS_TABLE[(_cmd, _code)] = _text
for _cmd in _CONTINUOUS:
    _STATUS_TABLE[(_cmd, '06')] = 'scan interval has a non-numeric value'
    _STATUS_TABLE[(_cmd, '07')] = 'number of scans has a non-numeric value'
    _STATUS_TABLE[(_cmd, '99')] = 'scan data follows'
for _cmd in ('GD', 'GS', 'GE'):
    _STATUS_TABLE[(_cmd, '10')] = 'laser is off (send BM first)'
_STATUS_TABLE.update({
    ('BM', '01'): 'unable to switch the laser on: laser malfunction',
    ('BM', '02'): 'laser is already on',
    ('SS', '01'): 'baud rate has a non-numeric value',
    ('SS', '02'): 'invalid baud rate',
    ('SS', '03'): 'the sensor already runs at this baud rate',
    ('SS', '04'): 'baud rate not supported by the sensor',
    ('TM', '01'): 'invalid time-adjust control code',
    ('TM', '02'): 'time-adjust mode requested while already in it',
    ('TM', '03'): 'time-adjust mode left while not in it',
    ('TM', '04'): 'time requested while not in time-adjust mode',
    ('SCIP2.0', '0'): 'switched to SCIP 2.0 (or already in it)',
})


def status_meaning(command: str, status: str) -> str:
    """Return the meaning of a reply status.

    Args:
        command: Command name (``'MD'``, ``'BM'``, ``'SCIP2.0'``, ...).
        status: Status string of the reply (2 characters, or 1 for bare replies).

    Returns:
        A short English description; ``'unknown status ...'`` for codes not in the tables.
    """
    key = (command[:2] if command != 'SCIP2.0' else command, status)
    if key in _STATUS_TABLE:
        return _STATUS_TABLE[key]
    if status == '00':
        return 'command received without error'
    if status == 'E':
        return 'error reply of SCIP 1.1: the sensor must be switched with SCIP2.0'
    if len(status) == 2 and status[0] == '0' and 'A' <= status[1] <= 'I':
        if status == '0I':
            return 'invalid command: sensor in firmware-update mode'
        if status == '0E':
            return 'invalid command in this state (unconfirmed: time-adjust mode)'
        return 'invalid command'
    if status.isdigit() and len(status) == 2:
        code = int(status)
        if 21 <= code <= 49:
            return 'processing stopped to verify an error'
        if 50 <= code <= 97:
            return 'hardware trouble'
        if code == 98:
            return 'resumed after confirming normal laser operation'
    return f'unknown status {status!r}'


# ---------------------------------------------------------------------------- scan geometry


def _scan_geometry(params: bytes) -> Tuple[int, int, int]:
    start, end, cluster = int(params[0:4]), int(params[4:8]), int(params[8:10])
    cluster = max(cluster, 1)  # an echoed cluster count of 00 behaves as 1
    return start, end, cluster


def _value_count(start: int, end: int, cluster: int) -> int:
    return max(0, -(-(end - start + 1) // cluster))


__all__ = ['BAUD_RATES', 'BLOCK_CHARS', 'SCAN_COMMANDS', 'status_meaning']
