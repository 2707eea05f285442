"""Hokuyo SCIP 2.0 (URG laser range finders): command encoders and reply decoders.

Pure byte-level code following ``docs/protocols/scip2.md`` (§2-§6): bytes in, frames out; no clock,
no I/O. The host sends a 2-letter command with fixed-width decimal parameters, an optional tag
(``;`` + up to 16 characters) and LF. The sensor answers with LF-terminated lines: the echo of the
command, a status line (2 status characters + checksum character), data lines (each ending in its
checksum character) and an empty line. Measurement data is cut into 64-character blocks; a value
may straddle two lines.

Checksum of a line: ``(sum of its bytes & 0x3F) + 0x30``. Values are groups of 6 bits, most
significant first, each + 0x30: 2 characters (12 bits, ``MS``/``GS``), 3 characters (18 bits,
``MD``/``GD``), 4 characters (24 bits, the millisecond timestamp).

Ranges follow REP 117: distances below DMIN (20 mm) are URG error codes, mapped by
:data:`ERROR_CODE_RANGES` to +inf (no return: nothing measurable within range) or NaN (error);
no URG code means "too close", so the decoder never produces -inf.

Frames: :class:`ScanFrame` (``MD``/``MS``/``ME`` scans, ``GD``/``GS``/``GE`` replies with
data), :class:`InfoReply` (``VV``/``PP``/``II``), :class:`TimeReply` (``TM1``) and
:class:`StatusReply` (every reply without data: acknowledgements and error statuses).
:class:`Scip2Decoder` decodes a byte stream incrementally; :func:`decode_reply` decodes exactly
one reply. The ``encode_*_reply`` functions build sensor replies for emulators and tests.

Modules, each named after what it computes:

* :mod:`.scip2_commands` -- the command tables, echo lines and :func:`status_meaning` (§6);
* :mod:`.scip2_values` -- :func:`checksum`, the 6-bit value codec and the REP 117 ranges;
* :mod:`.scip2_frames` -- the frame classes, :class:`SensorParams` and :func:`step_angles`;
* :mod:`.scip2_encoders` -- the host command encoders and the sensor reply encoders;
* :mod:`.scip2_decoder` -- :func:`decode_reply` and :class:`Scip2Decoder`.

This module is the entry point: it re-exports their public names.
"""

from landmark_nav.drivers.scip2_commands import (BAUD_RATES, BLOCK_CHARS, SCAN_COMMANDS,
                                                 status_meaning)
from landmark_nav.drivers.scip2_decoder import decode_reply, Scip2Decoder
from landmark_nav.drivers.scip2_encoders import (encode_baud_request, encode_command,
                                                 encode_info_reply, encode_line, encode_reply,
                                                 encode_scan_reply, encode_scan_reply_raw,
                                                 encode_scan_request, encode_time_request)
from landmark_nav.drivers.scip2_frames import (Frame, InfoReply, ScanFrame, SensorParams,
                                               StatusReply, step_angles, TimeReply, URG_04LX)
from landmark_nav.drivers.scip2_values import (checksum, decode_int, decode_values, DMIN_MM,
                                               encode_int, encode_values, ERROR_CODE_RANGES,
                                               ranges_from_raw, ranges_to_raw)

__all__ = [
    'BAUD_RATES', 'BLOCK_CHARS', 'DMIN_MM', 'ERROR_CODE_RANGES', 'Frame', 'InfoReply',
    'SCAN_COMMANDS', 'Scip2Decoder', 'ScanFrame', 'SensorParams', 'StatusReply', 'TimeReply',
    'URG_04LX', 'checksum', 'decode_int', 'decode_reply', 'decode_values',
    'encode_baud_request', 'encode_command', 'encode_info_reply', 'encode_int', 'encode_line',
    'encode_reply', 'encode_scan_reply', 'encode_scan_reply_raw', 'encode_scan_request',
    'encode_time_request', 'encode_values', 'ranges_from_raw', 'ranges_to_raw',
    'status_meaning', 'step_angles',
]
