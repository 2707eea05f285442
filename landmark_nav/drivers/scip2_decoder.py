"""SCIP 2.0 decoder: one reply (:func:`decode_reply`) or a byte stream (:class:`Scip2Decoder`).

The sensor answers with LF-terminated lines (``docs/protocols/scip2.md`` §2-§6): the echo of
the command, a status line (2 status characters + checksum character), data lines (each
ending in its checksum character) and an empty line. Measurement data is cut into
64-character blocks; a value may straddle two lines. Bytes in, frames of
:mod:`.scip2_frames` out; no clock, no I/O. Entry point: :mod:`landmark_nav.drivers.scip2`.
"""

import re
from typing import List, Union

from landmark_nav.drivers.errors import (ChecksumError, FramingError, ProtocolError,
                                         TruncatedError)
from landmark_nav.drivers.scip2_commands import (_CONTINUOUS, _ECHO_RE, _INFO_COMMANDS,
                                                 _MAX_ECHO, _scan_geometry, _value_count,
                                                 BLOCK_CHARS, SCAN_COMMANDS)
from landmark_nav.drivers.scip2_frames import (Frame, InfoReply, ScanFrame, StatusReply,
                                               TimeReply)
from landmark_nav.drivers.scip2_values import (checksum, decode_int, decode_values,
                                               ranges_from_raw)
from landmark_nav.drivers.stream import StreamDecoder


def _ascii(data: bytes, what: str, offset: int) -> str:
    if any(c < 0x20 or c > 0x7E for c in data):
        raise FramingError(f'{what} {bytes(data)!r} at offset {offset} is not printable ASCII',
                           offset)
    return data.decode('ascii')


def _check_line(line: bytes, what: str, offset: int) -> bytes:
    """Return the payload of a line after verifying its checksum character."""
    if len(line) < 2:
        raise FramingError(f'{what} {bytes(line)!r} at offset {offset} has no checksum', offset)
    payload = line[:-1]
    expected = checksum(payload)
    if line[-1] != expected:
        raise ChecksumError(f'{what} at offset {offset}: checksum {chr(line[-1])!r} != '
                            f'expected {chr(expected)!r}', offset)
    return payload


def _parse_reply(m: 're.Match[bytes]', body: bytes, offset: int) -> Frame:
    """Parse one reply: ``m`` matched its echo line, ``body`` = lines up to the empty line."""
    text = m.group(1).decode('ascii')
    tag = (m.group(2) or b';')[1:].decode('ascii')
    command = text if text == 'SCIP2.0' else text[:2]
    params = '' if text == 'SCIP2.0' else text[2:]
    where = f'reply to {text} at offset {offset}'
    if not body:
        raise FramingError(f'{where}: no status line', offset)
    lines = body.split(b'\n')
    offsets = [offset + m.end() - m.start()]
    for line in lines[:-1]:
        offsets.append(offsets[-1] + len(line) + 1)
    status_line = lines[0]
    warnings = []
    if len(status_line) == 1:  # bare status: SCIP2.0 answers '0', SCIP 1.1 answers 'E'
        status = _ascii(status_line, 'status', offsets[0])
    elif len(status_line) == 3:
        status = _ascii(status_line[:2], 'status', offsets[0])
        try:
            _check_line(status_line, f'{where}: status line', offsets[0])
        except ChecksumError as err:
            if command not in _INFO_COMMANDS:
                raise
            warnings.append(str(err))
    else:
        raise FramingError(f'{where}: status line {bytes(status_line)!r} must have 1 or 3 '
                           'characters', offsets[0])
    data_lines, data_offsets = lines[1:], offsets[1:]

    if command in _INFO_COMMANDS and status == '00':
        return _parse_info(command, status, data_lines, data_offsets, warnings, tag, where)
    if command == 'TM' and params == '1' and status == '00':
        if len(data_lines) != 1 or len(data_lines[0]) != 5:
            raise FramingError(f'{where}: expected one time line of 4 characters + checksum',
                               offset)
        stamp = _check_line(data_lines[0], f'{where}: time line', data_offsets[0])
        return TimeReply(status, decode_int(stamp), tag)
    if command in SCAN_COMMANDS and status == ('99' if command in _CONTINUOUS else '00'):
        return _parse_scan(command, params, status, data_lines, data_offsets, tag, where)
    if data_lines:
        raise FramingError(f'{where}: status {status!r} with {len(data_lines)} unexpected '
                           'data line(s)', offset)
    return StatusReply(command, params, status, tag)


def _parse_info(command: str, status: str, lines: List[bytes], offsets: List[int],
                warnings: List[str], tag: str, where: str) -> InfoReply:
    fields = []
    for line, off in zip(lines, offsets):
        # "KEY:VALUE;C": the checksum C is the last byte and may itself be ';'
        text, sep, ck = line[:-2], line[-2:-1], line[-1:]
        if sep != b';':
            warnings.append(f'{where}: info line at offset {off} has no checksum')
            text = line
        elif ck[0] != checksum(text):
            warnings.append(f'{where}: info line at offset {off}: checksum {chr(ck[0])!r} != '
                            f'expected {chr(checksum(text))!r}')
        key, colon, value = _ascii(text, 'info line', off).partition(':')
        if not colon:
            raise FramingError(f'{where}: info line {bytes(line)!r} at offset {off} has no '
                               '":"', off)
        fields.append((key, value))
    return InfoReply(command, status, tuple(fields), tuple(warnings), tag)


def _parse_scan(command: str, params: str, status: str, lines: List[bytes],
                offsets: List[int], tag: str, where: str) -> ScanFrame:
    start, end, cluster = _scan_geometry(params.encode('ascii'))
    width = SCAN_COMMANDS[command]
    if not lines:
        raise TruncatedError(f'{where}: no timestamp line', offsets[0] if offsets else None)
    if len(lines[0]) != 5:
        raise FramingError(f'{where}: timestamp line at offset {offsets[0]} must have 4 '
                           'characters + checksum', offsets[0])
    timestamp = decode_int(_check_line(lines[0], f'{where}: timestamp line', offsets[0]))
    chunks = []
    for i, (line, off) in enumerate(zip(lines[1:], offsets[1:]), 1):
        if len(line) > BLOCK_CHARS + 1:
            raise FramingError(f'{where}: data line {i} at offset {off} has {len(line) - 1} '
                               f'characters (max {BLOCK_CHARS})', off)
        chunks.append(_check_line(line, f'{where}: data line {i}', off))
    data = b''.join(chunks)
    n = _value_count(start, end, cluster)
    # ceil((end - start + 1) / cluster) values (docs/protocols/scip2.md §5); a final partial
    # cluster dropped by some firmware (floor) is tolerated.
    n_floor = max(0, (end - start + 1) // cluster)
    if len(data) not in (n * width, n_floor * width):
        kind = TruncatedError if len(data) < n_floor * width else FramingError
        raise kind(f'{where}: {len(data)} data characters; expected {n * width}', offsets[0])
    try:
        values = decode_values(data, 3 if width == 6 else width)
    except FramingError as err:
        raise FramingError(f'{where}: {err}', offsets[0]) from err
    intensities = None
    if width == 6:
        values = values.reshape(-1, 2)
        intensities = values[:, 1].copy()
        intensities.setflags(write=False)
        values = values[:, 0].copy()
    ranges = ranges_from_raw(values)
    values.setflags(write=False)
    ranges.setflags(write=False)
    continuous = command in _CONTINUOUS
    return ScanFrame(command=command, status=status, timestamp_ms=timestamp,
                     ranges_m=ranges, raw=values, intensities=intensities,
                     start_step=start, end_step=end, cluster=cluster,
                     scan_interval=int(params[10]) if continuous else None,
                     remaining_scans=int(params[11:13]) if continuous else None, tag=tag)


def _reply_bound(m: 're.Match[bytes]') -> int:
    """Return the most bytes a well-formed reply starting with echo ``m`` can have."""
    text = m.group(1)
    base = m.end() - m.start() + 4 + 1 + 8  # echo, status line, empty line, slack
    command = text[:2].decode('ascii')
    if command in SCAN_COMMANDS:
        start, end, cluster = _scan_geometry(text[2:])
        chars = _value_count(start, end, cluster) * SCAN_COMMANDS[command]
        return base + 6 + chars + 2 * (-(-chars // BLOCK_CHARS))
    if command in _INFO_COMMANDS:
        return 4096
    return base + 6  # TM1 time line


def decode_reply(data: bytes) -> Frame:
    """Decode exactly one complete reply (echo line through the empty line).

    Raises:
        FramingError: If ``data`` does not start with a valid echo line, a line is malformed
            or bytes follow the empty line.
        TruncatedError: If the empty line (or required data) is missing.
        ChecksumError: If a status, timestamp or data line has a wrong checksum.
    """
    data = bytes(data)
    m = _ECHO_RE.match(data)
    if m is None:
        raise FramingError(f'no valid SCIP 2.0 echo line at the start of {data[:20]!r}', 0)
    t = data.find(b'\n\n', m.end() - 1)
    if t < 0:
        raise TruncatedError(f'reply to {m.group(1).decode()} has no terminating empty line',
                             0)
    if t + 2 != len(data):
        raise FramingError(f'{len(data) - t - 2} bytes follow the end of the reply at '
                           f'offset {t + 2}', t + 2)
    return _parse_reply(m, data[m.end():t], 0)


class Scip2Decoder(StreamDecoder):
    """Incremental decoder of the sensor -> host byte stream.

    :meth:`feed` returns the frames completed by the new bytes and, in stream order, the
    errors met on the way as :class:`ProtocolError` objects (not raised):

    * bytes before a valid echo line are skipped and reported once as a :class:`FramingError`
      when the next reply starts (the decoder resynchronises on the next valid echo line);
    * a reply with a bad checksum is reported as a :class:`ChecksumError` and skipped;
    * a reply cut short by the start of the next one is reported as a :class:`TruncatedError`
      and the next reply is decoded.

    The output does not depend on how the stream is cut into chunks. Offsets in the errors
    count bytes since the decoder was created.
    """

    unit = 'echo line'

    def __init__(self) -> None:
        """Create a decoder with an empty buffer."""
        super().__init__()

    def feed(self, data: bytes) -> List[Union[Frame, ProtocolError]]:
        """Add bytes; return the completed frames and the errors, in stream order."""
        buf = self._buf
        buf += data
        out: List[Union[Frame, ProtocolError]] = []
        pos = 0
        while True:
            m = _ECHO_RE.search(buf, pos)
            if m is None:
                # Keep what may be the start of an echo line: an echo cannot contain LF.
                keep = max(pos, len(buf) - _MAX_ECHO, buf.rfind(b'\n') + 1)
                self._skip(pos, keep)
                pos = keep
                break
            start = m.start()
            self._skip(pos, start)
            offset = self._base + start
            bound = m.start() + _reply_bound(m)
            t = buf.find(b'\n\n', m.end() - 1, bound)
            if t < 0:
                if len(buf) < bound:
                    pos = start
                    break  # wait for the rest of the reply
                nxt = _ECHO_RE.search(buf, start + 1, bound)
                self._report(out, TruncatedError(
                    f'reply to {m.group(1).decode()} at offset {offset} has no end within '
                    f'{bound - start} bytes', offset))
                pos = nxt.start() if nxt else start + 1
                self._quiet = nxt is None
                continue
            try:
                frame = _parse_reply(m, bytes(buf[m.end():t]), offset)
            except ProtocolError as err:
                # Resynchronise one byte after the failed echo: its tag may hide a real echo.
                nxt = _ECHO_RE.search(buf, start + 1, t + 1)
                if nxt is not None:
                    err = TruncatedError(
                        f'reply to {m.group(1).decode()} at offset {offset} cut short by the '
                        f'next reply at offset {self._base + nxt.start()} ({err})', offset)
                self._report(out, err)
                pos = nxt.start() if nxt else t + 2
                continue
            self._report(out, frame)
            pos = t + 2
        self._consume(pos)
        return out


__all__ = ['Scip2Decoder', 'decode_reply']
