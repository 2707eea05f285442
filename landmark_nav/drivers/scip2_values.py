"""SCIP 2.0 value encoding: checksums, 6-bit characters and REP 117 ranges.

Pure byte-level code following ``docs/protocols/scip2.md`` (§3, §6). Checksum of a line:
``(sum of its bytes & 0x3F) + 0x30``. Values are groups of 6 bits, most significant first,
each + 0x30: 2 characters (12 bits, ``MS``/``GS``), 3 characters (18 bits, ``MD``/``GD``),
4 characters (24 bits, the millisecond timestamp).

Ranges follow REP 117: distances below DMIN (20 mm) are URG error codes, mapped by
:data:`ERROR_CODE_RANGES` to +inf (no return: nothing measurable within range) or NaN (error);
no URG code means "too close", so the decoder never produces -inf. Entry point:
:mod:`landmark_nav.drivers.scip2`.
"""

import math
from typing import Sequence, Tuple

from landmark_nav.drivers.errors import EncodeError, FramingError
import numpy as np

DMIN_MM = 20  # URG-04LX: values below this are error codes, not distances
# URG error codes (range values < DMIN_MM) -> REP 117 value (docs/protocols/scip2.md §6). The
# sensor documents give the codes' meanings only; the classification is ours: codes saying the
# target is beyond the measurable range or returned too little light (0 possibly at 22 m, 1-5
# low intensity, 6 possibly at 5.7 m) mean "no return" (+inf); codes saying a measurement
# failed (7 neighbour steps in error, 8 intensity difference, 9 erred twice, 16 possibly within
# 4096 mm, 18 strong reflector, 19 non-measurable) and the unspecified ones are errors (NaN).
# No code means "too close", so -inf never appears.
ERROR_CODE_RANGES: Tuple[float, ...] = tuple(
    math.inf if code <= 6 else math.nan for code in range(DMIN_MM))
_CODE_LUT = np.array(ERROR_CODE_RANGES, dtype=np.float64)
_NO_RETURN_CODE = 0  # encoder: +inf -> "possibly at 22 m"
_ERROR_CODE = 19  # encoder: NaN -> "non-measurable distance"


def checksum(data: bytes) -> int:
    """Return the SCIP checksum character (as an int) of ``data``: (byte sum & 0x3F) + 0x30."""
    return (sum(data) & 0x3F) + 0x30


def encode_int(value: int, width: int) -> bytes:
    """Encode a non-negative integer in ``width`` characters of 6 bits (+ 0x30 each).

    Raises:
        EncodeError: If the value does not fit in ``6 * width`` bits.
    """
    value = int(value)
    if not 0 <= value < 1 << (6 * width):
        raise EncodeError(f'value {value} does not fit {width} SCIP characters')
    return bytes(((value >> (6 * (width - 1 - i))) & 0x3F) + 0x30 for i in range(width))


def decode_int(chars: bytes) -> int:
    """Decode one value of ``len(chars)`` SCIP characters (6 bits each).

    Raises:
        FramingError: If a character is outside 0x30..0x6F.
    """
    value = 0
    for i, c in enumerate(chars):
        if not 0x30 <= c <= 0x6F:
            raise FramingError(f'invalid SCIP data character 0x{c:02X} at index {i}')
        value = (value << 6) | (c - 0x30)
    return value


def encode_values(values: Sequence[int], width: int) -> bytes:
    """Encode non-negative integers in ``width`` characters each (vectorised).

    Raises:
        EncodeError: If a value is negative or too large for ``width`` characters.
    """
    v = np.asarray(values, dtype=np.int64).ravel()
    if v.size and (int(v.min()) < 0 or int(v.max()) >= 1 << (6 * width)):
        bad = int(np.flatnonzero((v < 0) | (v >= 1 << (6 * width)))[0])
        raise EncodeError(f'value {int(v[bad])} at index {bad} does not fit {width} '
                          'SCIP characters')
    shifts = 6 * np.arange(width - 1, -1, -1, dtype=np.int64)
    chars = ((v[:, None] >> shifts) & 0x3F) + 0x30
    return chars.astype(np.uint8).tobytes()


def decode_values(data: bytes, width: int) -> np.ndarray:
    """Decode concatenated ``width``-character values (checksums already removed).

    Returns:
        (len(data) // width,) uint32 array.

    Raises:
        FramingError: If the length is not a multiple of ``width`` or a character is outside
            0x30..0x6F.
    """
    if len(data) % width:
        raise FramingError(f'{len(data)} data characters are not a multiple of {width}')
    a = np.frombuffer(data, dtype=np.uint8) - np.uint8(0x30)  # wraps below 0x30 to >= 0xD0
    if a.size and int(a.max()) > 63:
        bad = int(np.flatnonzero(a > 63)[0])
        raise FramingError(f'invalid SCIP data character 0x{data[bad]:02X} at data index {bad}')
    a = a.reshape(-1, width).astype(np.uint32)
    out = a[:, 0].copy()
    for i in range(1, width):
        out <<= 6
        out |= a[:, i]
    return out


def ranges_from_raw(raw: np.ndarray) -> np.ndarray:
    """Convert decoded values (mm) to metres; error codes become +inf or NaN (REP 117)."""
    raw = np.asarray(raw)
    ranges = raw / 1000.0  # division rounds correctly: 1001 -> 1.001 exactly as typed
    codes = raw < DMIN_MM
    if codes.any():
        ranges[codes] = _CODE_LUT[raw[codes]]
    return ranges


def ranges_to_raw(ranges_m: Sequence[float], width: int = 3) -> np.ndarray:
    """Quantise ranges (m) to the values a sensor sends: mm, +inf -> code 0, NaN -> code 19.

    Raises:
        EncodeError: For -inf, for finite ranges that round below DMIN (the sensor has no
            "too close" code; send a code with :func:`encode_scan_reply_raw` instead) or beyond
            the ``width``-character maximum.
    """
    r = np.asarray(ranges_m, dtype=np.float64).ravel()
    raw = np.empty(r.shape, dtype=np.int64)
    finite = np.isfinite(r)
    with np.errstate(invalid='ignore', over='ignore'):
        mm = np.round(r[finite] * 1000.0)
    limit = (1 << (6 * width)) - 1
    if mm.size and (mm.min() < DMIN_MM or mm.max() > limit):
        idx = np.flatnonzero(finite)[int(np.flatnonzero((mm < DMIN_MM) | (mm > limit))[0])]
        raise EncodeError(f'range {r[idx]!r} m at index {idx} is outside '
                          f'[{DMIN_MM}, {limit}] mm')
    if np.any(r == -np.inf):
        idx = int(np.flatnonzero(r == -np.inf)[0])
        raise EncodeError(f'range -inf at index {idx}: SCIP has no "too close" code')
    raw[finite] = mm.astype(np.int64)
    raw[np.isnan(r)] = _ERROR_CODE
    raw[r == np.inf] = _NO_RETURN_CODE
    return raw


__all__ = ['DMIN_MM', 'ERROR_CODE_RANGES', 'checksum', 'decode_int', 'decode_values',
           'encode_int', 'encode_values', 'ranges_from_raw', 'ranges_to_raw']
