"""SCIP 2.0 encoders: host commands, and sensor replies for emulators and tests.

The host side (``docs/protocols/scip2.md`` §4-§5): :func:`encode_command`,
:func:`encode_scan_request`, :func:`encode_baud_request`, :func:`encode_time_request`. The
sensor side: :func:`encode_line` (payload + checksum + LF), :func:`encode_reply`,
:func:`encode_info_reply`, :func:`encode_scan_reply_raw` and :func:`encode_scan_reply`, whose
output :func:`~.scip2_decoder.decode_reply` decodes back. Entry point:
:mod:`landmark_nav.drivers.scip2`.
"""

from typing import List, Optional, Sequence, Tuple, Union

from landmark_nav.drivers.errors import EncodeError
from landmark_nav.drivers.scip2_commands import (_CONTINUOUS, _ECHO_RE, _INFO_COMMANDS, _LF,
                                                 _scan_geometry, _SIMPLE_COMMANDS, _TAG_RE,
                                                 _value_count, BAUD_RATES, BLOCK_CHARS,
                                                 SCAN_COMMANDS)
from landmark_nav.drivers.scip2_values import (checksum, encode_int, encode_values,
                                               ranges_to_raw)
import numpy as np

# ---------------------------------------------------------------------------- host encoders


def _tag_suffix(tag: Optional[str]) -> bytes:
    if tag is None:
        return b''
    if not _TAG_RE.fullmatch(tag):
        raise EncodeError(f'tag {tag!r} must be up to 16 letters, digits, spaces or "._+@"')
    return b';' + tag.encode('ascii')


def _digits(value: int, width: int, low: int, high: int, what: str) -> bytes:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise EncodeError(f'{what} must be an integer; got {value!r}')
    if not low <= value <= high:
        raise EncodeError(f'{what}={value} is outside [{low}, {high}]')
    return b'%0*d' % (width, int(value))


def encode_command(command: str, tag: Optional[str] = None) -> bytes:
    """Encode a command without parameters (``VV PP II BM QT RS SCIP2.0``).

    Raises:
        EncodeError: For another command or an invalid tag.
    """
    if command not in _SIMPLE_COMMANDS:
        raise EncodeError(f'{command!r} is not one of {_SIMPLE_COMMANDS}')
    return command.encode('ascii') + _tag_suffix(tag) + b'\n'


def encode_scan_request(command: str, start_step: int, end_step: int, cluster: int = 1,
                        scan_interval: int = 0, num_scans: int = 0,
                        tag: Optional[str] = None) -> bytes:
    """Encode a scan request: ``MDssssEEEEccinn`` (also MS, ME) or ``GDssssEEEEcc`` (GS, GE).

    Args:
        command: One of :data:`SCAN_COMMANDS`.
        start_step: First step, 0..9999.
        end_step: Last step, start_step..9999.
        cluster: Steps merged into one value, 1..99.
        scan_interval: Continuous commands: scans skipped between outputs, 0..9.
        num_scans: Continuous commands: number of scans, 0..99 (0 = until ``QT``).
        tag: Optional tag echoed by the sensor.

    Raises:
        EncodeError: If an argument is out of range.
    """
    if command not in SCAN_COMMANDS:
        raise EncodeError(f'{command!r} is not a scan command {tuple(SCAN_COMMANDS)}')
    out = (command.encode('ascii') + _digits(start_step, 4, 0, 9999, 'start_step')
           + _digits(end_step, 4, int(start_step), 9999, 'end_step')
           + _digits(cluster, 2, 1, 99, 'cluster'))
    if command in _CONTINUOUS:
        out += _digits(scan_interval, 1, 0, 9, 'scan_interval')
        out += _digits(num_scans, 2, 0, 99, 'num_scans')
    return out + _tag_suffix(tag) + b'\n'


def encode_baud_request(baud: int, tag: Optional[str] = None) -> bytes:
    """Encode ``SSbbbbbb`` (RS-232 baud rate, applied after the ``00`` reply).

    Raises:
        EncodeError: If ``baud`` is not one of :data:`BAUD_RATES`.
    """
    if baud not in BAUD_RATES:
        raise EncodeError(f'baud {baud!r} is not one of {BAUD_RATES}')
    return b'SS%06d' % baud + _tag_suffix(tag) + b'\n'


def encode_time_request(mode: int, tag: Optional[str] = None) -> bytes:
    """Encode ``TM0`` (enter time-adjust mode), ``TM1`` (read time) or ``TM2`` (leave).

    Raises:
        EncodeError: If ``mode`` is not 0, 1 or 2.
    """
    return b'TM' + _digits(mode, 1, 0, 2, 'mode') + _tag_suffix(tag) + b'\n'


# ---------------------------------------------------------------------------- sensor encoders


def encode_line(payload: bytes) -> bytes:
    """Return ``payload`` + its checksum character + LF."""
    return bytes(payload) + bytes((checksum(payload), _LF))


def _echo_bytes(echo: Union[str, bytes]) -> bytes:
    e = echo.encode('ascii') if isinstance(echo, str) else bytes(echo)
    e = e.rstrip(b'\r\n')
    if not _ECHO_RE.fullmatch(e + b'\n'):
        raise EncodeError(f'{e!r} is not a valid SCIP 2.0 echo line')
    return e


def encode_reply(echo: Union[str, bytes], status: str, lines: Sequence[bytes] = ()) -> bytes:
    """Build a reply: echo, status line, ``lines`` (checksums appended), empty line.

    A 1-character status (``SCIP2.0`` answers a bare ``0``) is sent without checksum.

    Raises:
        EncodeError: If the echo or the status is invalid.
    """
    s = status.encode('ascii')
    if len(s) not in (1, 2) or b'\n' in s:
        raise EncodeError(f'status {status!r} must have 1 or 2 characters')
    out = [_echo_bytes(echo) + b'\n', s + b'\n' if len(s) == 1 else encode_line(s)]
    out.extend(encode_line(line) for line in lines)
    out.append(b'\n')
    return b''.join(out)


def encode_info_reply(command: str, fields: Sequence[Tuple[str, str]],
                      status: str = '00') -> bytes:
    """Build a ``VV``/``PP``/``II`` reply from ``(key, value)`` pairs.

    Raises:
        EncodeError: For another command.
    """
    if command not in _INFO_COMMANDS:
        raise EncodeError(f'{command!r} is not one of {_INFO_COMMANDS}')
    out = [command.encode('ascii') + b'\n', encode_line(status.encode('ascii'))]
    for key, value in fields:
        text = f'{key}:{value}'.encode('ascii')
        out.append(text + b';' + bytes((checksum(text), _LF)))
    out.append(b'\n')
    return b''.join(out)


def _data_lines(data: bytes) -> List[bytes]:
    return [data[i:i + BLOCK_CHARS] for i in range(0, len(data), BLOCK_CHARS)]


def encode_scan_reply_raw(echo: Union[str, bytes], raw: Sequence[int], timestamp_ms: int,
                          intensities: Optional[Sequence[int]] = None,
                          status: Optional[str] = None) -> bytes:
    """Build a scan reply (sensor side) from raw values (mm or error codes).

    Args:
        echo: The echo line (with or without LF), e.g. ``b'GD0384038701'``; it fixes the
            command, the steps and the cluster count, hence the number of values.
        raw: One value per cluster, ``ceil((end - start + 1) / cluster)`` of them.
        timestamp_ms: Sensor time, taken modulo 2**24.
        intensities: ``ME``/``GE`` only: one intensity per value.
        status: Status; default ``'99'`` for ``MD``/``MS``/``ME``, ``'00'`` otherwise.

    Raises:
        EncodeError: If the echo is not a scan command, the count does not match or a value
            does not fit.
    """
    e = _echo_bytes(echo)
    command = e[:2].decode('ascii')
    if command not in SCAN_COMMANDS:
        raise EncodeError(f'echo {e!r} is not a scan command')
    start, end, cluster = _scan_geometry(e[2:])
    n = _value_count(start, end, cluster)
    values = np.asarray(raw, dtype=np.int64).ravel()
    if values.size != n:
        raise EncodeError(f'echo {e!r} needs {n} values; got {values.size}')
    width = SCAN_COMMANDS[command]
    if width == 6:
        if intensities is None:
            raise EncodeError(f'{command} needs intensities')
        inten = np.asarray(intensities, dtype=np.int64).ravel()
        if inten.size != n:
            raise EncodeError(f'{command} needs {n} intensities; got {inten.size}')
        data = encode_values(np.stack([values, inten], axis=1), 3)
    else:
        if intensities is not None:
            raise EncodeError(f'{command} carries no intensities')
        data = encode_values(values, width)
    if status is None:
        status = '99' if command in _CONTINUOUS else '00'
    time_line = encode_int(int(timestamp_ms) % (1 << 24), 4)
    return encode_reply(e, status, [time_line] + _data_lines(data))


def encode_scan_reply(echo: Union[str, bytes], ranges_m: Sequence[float], timestamp_ms: int,
                      intensities: Optional[Sequence[int]] = None,
                      status: Optional[str] = None) -> bytes:
    """Build a scan reply (sensor side) from ranges in metres.

    Ranges are rounded to mm; +inf is sent as code 0 and NaN as code 19, which decode back to
    +inf and NaN, so :func:`decode_reply` returns the input after mm quantisation.

    Raises:
        EncodeError: See :func:`ranges_to_raw` and :func:`encode_scan_reply_raw`.
    """
    e = _echo_bytes(echo)
    width = SCAN_COMMANDS.get(e[:2].decode('ascii'), 3)
    return encode_scan_reply_raw(e, ranges_to_raw(ranges_m, 3 if width == 6 else width),
                                 timestamp_ms, intensities, status)


__all__ = ['encode_baud_request', 'encode_command', 'encode_info_reply', 'encode_line',
           'encode_reply', 'encode_scan_reply', 'encode_scan_reply_raw', 'encode_scan_request',
           'encode_time_request']
