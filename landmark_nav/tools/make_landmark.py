"""``landmark_nav make-landmark``: write a printable landmark (PNG, SVG or PDF) at true scale."""

import argparse
import math
from pathlib import Path

from landmark_nav.vision.landmark import (DEFAULT_FRAME_WIDTH, KINDS, LandmarkDesign,
                                          PRINTABLE_SUFFIXES, write_printable)


def parse_code(text: str) -> int:
    """Parse a landmark code: decimal or 0x-prefixed hexadecimal (e.g. 156 or 0x9C)."""
    try:
        return int(text, 0)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'landmark code must be an integer (decimal or 0x hex); got {text!r}') from None


def parse_frame_width(text: str) -> float:
    """Parse a frame width in metres: finite and > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'frame width must be a number [m]; got {text!r}') \
            from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f'frame width must be > 0 m; got {text!r}')
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the make-landmark arguments to a (sub)parser."""
    parser.add_argument('code', type=parse_code,
                        help='landmark code, decimal or 0x hex (e.g. 156 or 0x75BCD15)')
    parser.add_argument('--kind', choices=KINDS, default='3x3',
                        help='3x3: 7x7-block frame, 28-bit code field (default); '
                             '2x2: 6x6-block frame, codes 0..511')
    parser.add_argument('--frame-width', type=parse_frame_width, default=DEFAULT_FRAME_WIDTH,
                        metavar='METRES',
                        help=f'printed frame side without the quiet zone (default '
                             f'{DEFAULT_FRAME_WIDTH})')
    parser.add_argument('--dpi', type=float, default=300.0, help='PNG resolution (default 300)')
    parser.add_argument('--out', required=True,
                        help=f'output file, type from the suffix: {", ".join(PRINTABLE_SUFFIXES)}')


def run(code: int, out: str, kind: str = '3x3', frame_width: float = DEFAULT_FRAME_WIDTH,
        dpi: float = 300.0) -> str:
    """Write the landmark file and return a one-line summary.

    Raises:
        ValueError: invalid code (InvalidCodeError), frame width, dpi or file suffix.
        OSError: the file cannot be written.
    """
    design = LandmarkDesign(kind, frame_width)
    if Path(out).suffix.lower() not in PRINTABLE_SUFFIXES:
        raise ValueError(f'unknown landmark file type {Path(out).suffix!r} for {out}; '
                         f'use one of {", ".join(PRINTABLE_SUFFIXES)}')
    design.check_code(code)
    path = write_printable(code, out, design, dpi=dpi)
    side_mm = design.printed_width * 1000.0
    return (f'{path}: {kind} landmark code {code} (0x{code:X}), frame '
            f'{frame_width * 1000.0:g} mm, printed {side_mm:g} x {side_mm:g} mm '
            f'with a {design.block_size * 1000.0:g} mm quiet zone; print at 100 % scale')
