"""The artificial visual landmark: printed geometry, code layout, encode/decode, rendering.

Source: visual navigation chapter §2.1 (design), §2.2.2–2.2.3 (frame and code detection) and
§2.2.4 (landmark coordinates). The geometry below is the package's exact reading of the
chapter; detector, pose estimator and simulator all use it through :class:`LandmarkDesign`.

Large landmark (``kind='3x3'``, the default)
--------------------------------------------
* The printed frame is a square of side ``frame_width`` (default 0.175 m, the chapter's) made
  of 7 x 7 *blocks* of side ``s = frame_width / 7``. Block ``(i, j)``: ``i`` = column from the
  left, ``j`` = row from the top, both 0..6. Arrays in this module are indexed
  ``[row, column]`` = ``[j, i]``.
* The outer ring (``i`` or ``j`` in {0, 6}) and the inner ring (``i`` or ``j`` in {1, 5}) form
  the double checkerboard frame: block ``(i, j)`` is black iff ``i + j`` is even.
* *Grid points* ``(u, v)`` are measured in blocks from the top-left outer corner of the frame,
  ``u`` to the right, ``v`` down. The X-corners used for detection lie on the line between
  the two rings: ``(k, 1), (k, 6), (1, k), (6, k)`` for ``k = 1..6``, i.e. six corners per
  frame edge (eq. 3). The four frame corners h'_1..h'_4 (eq. 5) are the grid points
  ``(1, 1), (6, 1), (6, 6), (1, 6)``, each shared by two edges.
* Code area: blocks ``(2..4, 2..4)``, a 3 x 3 grid of *squares* (one block each) on white.
  Upright square layout (row-major)::

      *  *  1
      2  3  4
      5  6  7

  The two ``*`` squares are the orientation mark, always all black. Each square holds four
  bits as 2 x 2 half-block *cells*: top-left = bit 1 (value 8), top-right = bit 2 (4),
  bottom-left = bit 3 (2), bottom-right = bit 4 (1); a set bit is a black cell. Square 1 is
  the most significant nibble: ``code = sum(nibble_k << 4 * (7 - k))``. So the chapter's
  Fig. 1 code 156 = 0x9C has square 6 = 0x9 and square 7 = 0xC, and Fig. 3's 123456789 =
  0x75BCD15 has square 1 = 0x7 ... square 7 = 0x5.
* Valid codes: ``0 <= code < 2**28`` and no other rotation may show two all-black squares at
  the orientation-mark position, i.e. squares (1, 4), (7, 6) and (5, 2) must not both be 0xF.
  That leaves ``16 * 255**3 = 265 302 000`` codes (about 27.98 bits). The chapter counts
  "some 24 usable bits ... 2**24 - 2**16 = 16 711 680" (§2.1); it does not say which
  combinations it excludes, so this exact rule replaces its estimate (it is a superset).
* Printed with a white quiet zone of one block around the frame (outside ``frame_width``).

Small landmark (``kind='2x2'``, 9 bits)
---------------------------------------
6 x 6 blocks of side ``frame_width / 6``, the same colouring rule, code area blocks
``(2..3, 2..3)``; frame corners at grid points ``(1, 1), (5, 1), (5, 5), (1, 5)`` (five
X-corners per edge). The top-left square is the all-black orientation mark; top-right (most
significant), bottom-left and bottom-right (least significant) carry three bits each in the
cells of bits 1..3 (values 4, 2, 1); the bit-4 cell is always white, so no rotation can be
mistaken for the mark and all 512 codes 0..511 are valid.

Landmark coordinates (§2.2.4)
-----------------------------
Origin at the centre of the frame, x out of the printed face (towards the viewer), z up, y to
the right when looking at the landmark (to the left when looking along x, as for a robot).
Grid point ``(u, v)`` is at ``(0, (u - n/2) s, (n/2 - v) s)`` with ``n`` blocks per side, so
the frame corners are at ``(0, +-b, +-b)`` with ``b = 2.5 s = frame_width * 5/14`` (0.0625 m
for 0.175 m) for the large landmark and ``b = 2 s = frame_width / 3`` for the small one; the
top-right corner is the chapter's ``B = (0, b_y, b_z)`` with both positive.
"""

from dataclasses import dataclass
import math
from pathlib import Path
import struct
from typing import Optional, Tuple, Union
import zlib

import numpy as np

KINDS = ('3x3', '2x2')
DEFAULT_FRAME_WIDTH = 0.175
MM_PER_INCH = 25.4


class InvalidCodeError(ValueError):
    """A landmark code is out of range or cannot be distinguished from another rotation."""


# bit weights of the 2 x 2 cells of one square, [row, col] (bit 1 = 8 ... bit 4 = 1)
_CELL_WEIGHTS = np.array([[8, 4], [2, 1]], dtype=np.int64)


@dataclass(frozen=True)
class LandmarkDesign:
    """Geometry of one landmark design (see the module docstring for the exact layout).

    Attributes:
        kind: ``'3x3'`` (7 x 7 blocks, 28-bit code field) or ``'2x2'`` (6 x 6 blocks, 9 bits).
        frame_width: side of the printed frame [m] (without the quiet zone), > 0.
    """

    kind: str = '3x3'
    frame_width: float = DEFAULT_FRAME_WIDTH

    def __post_init__(self) -> None:
        """Validate the kind and the frame width."""
        if self.kind not in KINDS:
            raise ValueError(f'landmark kind must be one of {KINDS}; got {self.kind!r}')
        w = self.frame_width
        if isinstance(w, bool) or not isinstance(w, (int, float, np.floating, np.integer)) \
                or not math.isfinite(float(w)) or float(w) <= 0.0:
            raise ValueError(f'frame_width must be a finite number > 0 [m]; got {w!r}')
        object.__setattr__(self, 'frame_width', float(w))

    # ------------------------------------------------------------------ sizes
    @property
    def n_blocks(self) -> int:
        """Blocks per side of the frame: 7 (3x3) or 6 (2x2)."""
        return 7 if self.kind == '3x3' else 6

    @property
    def block_size(self) -> float:
        """Side of one block [m]: ``frame_width / n_blocks``."""
        return self.frame_width / self.n_blocks

    @property
    def code_squares(self) -> int:
        """Code squares per side of the code area: 3 or 2."""
        return 3 if self.kind == '3x3' else 2

    @property
    def corners_per_edge(self) -> int:
        """X-corners on each frame edge, frame corners included: 6 (eq. 3) or 5."""
        return self.n_blocks - 1

    @property
    def code_bits(self) -> int:
        """Width of the code field in bits: 28 (3x3) or 9 (2x2)."""
        return 28 if self.kind == '3x3' else 9

    @property
    def half_side(self) -> float:
        """Half side ``b`` of the square spanned by the frame corners [m]."""
        return (0.5 * self.n_blocks - 1.0) * self.block_size

    @property
    def printed_width(self) -> float:
        """Printed side including a one-block quiet zone on each side [m]."""
        return (self.n_blocks + 2) * self.block_size

    # ------------------------------------------------------------------ geometry
    def grid_to_landmark(self, uv: np.ndarray) -> np.ndarray:
        """Convert grid points to landmark coordinates.

        Args:
            uv: (..., 2) grid coordinates ``(u, v)`` in blocks from the top-left outer corner
                of the frame, ``u`` to the right, ``v`` down.

        Returns:
            (..., 3) points ``(0, y, z)`` [m] in the landmark frame (x out of the face, y right
            when looking at the landmark, z up, origin at the frame centre).
        """
        uv = np.asarray(uv, dtype=float)
        if uv.shape[-1] != 2:
            raise ValueError(f'grid points need a last axis of size 2; got shape {uv.shape}')
        h = 0.5 * self.n_blocks
        s = self.block_size
        out = np.zeros(uv.shape[:-1] + (3,))
        out[..., 1] = (uv[..., 0] - h) * s
        out[..., 2] = (h - uv[..., 1]) * s
        return out

    def frame_corner_grid(self) -> np.ndarray:
        """Return the (4, 2) grid points of the frame corners h'_1..h'_4 (eq. 5).

        Order as seen from the front: top-left, top-right, bottom-right, bottom-left.
        """
        a, e = 1.0, float(self.n_blocks - 1)
        return np.array([[a, a], [e, a], [e, e], [a, e]])

    def frame_corners(self) -> np.ndarray:
        """Return the (4, 3) landmark coordinates [m] of the frame corners h'_1..h'_4 (eq. 5).

        Order as seen from the front (looking at the printed face, upright): top-left,
        top-right, bottom-right, bottom-left, i.e. ``(0, -b, b), (0, b, b), (0, b, -b),
        (0, -b, -b)``. Row 1 is the chapter's top-right corner ``B = (0, b_y, b_z)``.
        """
        return self.grid_to_landmark(self.frame_corner_grid())

    def edge_corner_grid(self) -> np.ndarray:
        """Return the (4, corners_per_edge, 2) grid points of the X-corners of each edge.

        Edge ``e`` runs from frame corner ``e`` to frame corner ``e + 1 (mod 4)`` in the order
        of :meth:`frame_corners`: top (left to right), right (top to bottom), bottom (right to
        left), left (bottom to top). The first and last corner of each edge are frame corners.
        """
        c = self.frame_corner_grid()
        t = np.linspace(0.0, 1.0, self.corners_per_edge)[:, None]
        return np.stack([c[e] + t * (c[(e + 1) % 4] - c[e]) for e in range(4)])

    def edge_corners(self) -> np.ndarray:
        """Return the (4, corners_per_edge, 3) landmark coordinates of the frame X-corners.

        Same order as :meth:`edge_corner_grid` (6 corners per edge for 3x3, 5 for 2x2).
        """
        return self.grid_to_landmark(self.edge_corner_grid())

    def block_colours(self) -> np.ndarray:
        """Return the (n_blocks, n_blocks) int8 block colours, ``[row, column]``.

        1 = black frame block, 0 = white frame block, -1 = code area. The inner-ring entries
        are the frame's known black and white cells used to threshold the code (§2.2.3).
        """
        n = self.n_blocks
        j, i = np.mgrid[0:n, 0:n]
        out = ((i + j) % 2 == 0).astype(np.int8)
        m = self.code_squares
        out[2:2 + m, 2:2 + m] = -1
        return out

    def code_cells(self) -> np.ndarray:
        """Return the bit-cell rectangles of the code area in blocks, upright orientation.

        Returns:
            (2m, 2m, 4) float array (m = :attr:`code_squares`); entry ``[row, col]`` is
            ``(u0, v0, u1, v1)``, the half-block cell in grid coordinates (blocks from the
            top-left outer corner, u right, v down). Indices match the bit grid of
            :meth:`encode`; square ``(r, c)`` covers rows ``2r, 2r+1`` and columns
            ``2c, 2c+1``, and within a square ``[0, 0]`` = bit 1 (8), ``[0, 1]`` = bit 2 (4),
            ``[1, 0]`` = bit 3 (2), ``[1, 1]`` = bit 4 (1).
        """
        k = 2 * self.code_squares
        rows, cols = np.mgrid[0:k, 0:k].astype(float)
        u0 = 2.0 + 0.5 * cols
        v0 = 2.0 + 0.5 * rows
        return np.stack([u0, v0, u0 + 0.5, v0 + 0.5], axis=-1)

    # ------------------------------------------------------------------ codes
    @property
    def code_limit(self) -> int:
        """Exclusive upper bound of the code field: 2**28 or 2**9."""
        return 1 << self.code_bits

    def _check_int(self, code: object) -> int:
        if isinstance(code, (bool, np.bool_)) or not isinstance(code, (int, np.integer)):
            raise InvalidCodeError(f'landmark code must be an integer; got {code!r}')
        return int(code)

    def _nibbles(self, code: int) -> list:
        """Nibbles of squares 1..7 (3x3), most significant first."""
        return [(code >> (4 * (7 - k))) & 0xF for k in range(1, 8)]

    def is_valid_code(self, code: object) -> bool:
        """Return True if ``code`` can be printed and read back unambiguously.

        3x3: ``0 <= code < 2**28`` and none of the square pairs (1, 4), (7, 6), (5, 2) is
        0xF, 0xF (they would form a second orientation mark in another rotation).
        2x2: ``0 <= code < 512``.
        """
        try:
            code = self._check_int(code)
        except InvalidCodeError:
            return False
        if not 0 <= code < self.code_limit:
            return False
        if self.kind == '2x2':
            return True
        q = self._nibbles(code)
        for a, b in ((1, 4), (7, 6), (5, 2)):
            if q[a - 1] == 0xF and q[b - 1] == 0xF:
                return False
        return True

    def count_valid_codes(self) -> int:
        """Return the number of valid codes: 16 * 255**3 = 265302000 (3x3) or 512 (2x2).

        For 3x3 the three excluded pairs use six distinct squares; square 3 is free.
        """
        return 16 * 255 ** 3 if self.kind == '3x3' else 512

    def check_code(self, code: object) -> int:
        """Return ``code`` as an int, or raise :class:`InvalidCodeError` saying why."""
        code = self._check_int(code)
        if not 0 <= code < self.code_limit:
            raise InvalidCodeError(
                f'landmark code {code} out of range for a {self.kind} landmark '
                f'(0 <= code < {self.code_limit})')
        if not self.is_valid_code(code):
            raise InvalidCodeError(
                f'landmark code {code} (0x{code:07X}) is ambiguous: two all-black (0xF) squares '
                'at squares (1, 4), (7, 6) or (5, 2) look like the orientation mark when rotated')
        return code

    def _square_values(self, code: int) -> np.ndarray:
        """Return the (m, m) 4-bit square values of a valid code, marks = 0xF."""
        m = self.code_squares
        sq = np.zeros((m, m), dtype=np.int64)
        if self.kind == '3x3':
            vals = [0xF, 0xF] + self._nibbles(code)
        else:
            vals = [0xF, ((code >> 6) & 7) << 1, ((code >> 3) & 7) << 1, (code & 7) << 1]
        sq.flat[:] = vals
        return sq

    def encode(self, code: int) -> np.ndarray:
        """Return the upright bit grid of a code.

        Args:
            code: a valid code (:meth:`is_valid_code`).

        Returns:
            (2m, 2m) bool array, ``[row, col]`` of the half-block cells of the code area
            (m = :attr:`code_squares`), True = black, orientation mark included.

        Raises:
            InvalidCodeError: if the code is not valid for this design.
        """
        code = self.check_code(code)
        sq = self._square_values(code)
        m = self.code_squares
        bits = np.zeros((2 * m, 2 * m), dtype=bool)
        for r in range(m):
            for c in range(m):
                bits[2 * r:2 * r + 2, 2 * c:2 * c + 2] = (sq[r, c] & _CELL_WEIGHTS) != 0
        return bits

    def _mark_positions(self) -> Tuple[Tuple[int, int], ...]:
        return ((0, 0), (0, 1)) if self.kind == '3x3' else ((0, 0),)

    def decode_with_rotation(self, bits: np.ndarray) -> Optional[Tuple[int, int]]:
        """Decode a bit grid seen in any of the four 90-degree rotations.

        Args:
            bits: (2m, 2m) array-like of bools (True/nonzero = black), the code-area cells as
                read from the image, ``[row, col]`` in the image's reading order.

        Returns:
            ``(code, k)`` where ``np.rot90(bits, k)`` is the upright grid (k in 0..3, counter-
            clockwise quarter turns), or None if no rotation or more than one rotation shows
            the orientation mark (all cells of the mark squares black), or if the upright grid
            is not a valid code (a bit-4 cell set in a 2x2 landmark, an ambiguous 3x3 code).

        Raises:
            ValueError: if ``bits`` does not have shape (2m, 2m).
        """
        b = np.asarray(bits)
        m = self.code_squares
        if b.shape != (2 * m, 2 * m):
            raise ValueError(f'{self.kind} bit grid must have shape {(2 * m, 2 * m)}; '
                             f'got {b.shape}')
        b = b.astype(bool)
        found = []
        for k in range(4):
            up = np.rot90(b, k)
            if all(up[2 * r:2 * r + 2, 2 * c:2 * c + 2].all() for r, c in self._mark_positions()):
                found.append((k, up))
        if len(found) != 1:
            return None
        k, up = found[0]
        sq = np.zeros((m, m), dtype=np.int64)
        for r in range(m):
            for c in range(m):
                sq[r, c] = int((up[2 * r:2 * r + 2, 2 * c:2 * c + 2] * _CELL_WEIGHTS).sum())
        if self.kind == '3x3':
            code = 0
            for v in sq.flat[2:]:
                code = (code << 4) | int(v)
        else:
            vals = sq.flat[1:]
            if any(v & 1 for v in vals):
                return None
            code = (int(vals[0]) >> 1 << 6) | (int(vals[1]) >> 1 << 3) | (int(vals[2]) >> 1)
        if not self.is_valid_code(code):
            return None
        return code, k

    def decode(self, bits: np.ndarray) -> Optional[int]:
        """Return the code of a bit grid in any rotation, or None (see decode_with_rotation)."""
        res = self.decode_with_rotation(bits)
        return None if res is None else res[0]

    # ------------------------------------------------------------------ rendering
    def half_block_image(self, code: int, quiet_zone_blocks: int = 1) -> np.ndarray:
        """Return the landmark as a bool grid of half-block cells (True = black).

        Shape ``(2 (n_blocks + 2 q), 2 (n_blocks + 2 q))`` with ``q = quiet_zone_blocks``.
        """
        q = _check_nonneg_int(quiet_zone_blocks, 'quiet_zone_blocks')
        bits = self.encode(code)
        n = self.n_blocks
        frame = np.repeat(np.repeat(self.block_colours() == 1, 2, axis=0), 2, axis=1)
        frame[4:4 + bits.shape[0], 4:4 + bits.shape[1]] = bits
        out = np.zeros((2 * (n + 2 * q), 2 * (n + 2 * q)), dtype=bool)
        out[2 * q:2 * q + 2 * n, 2 * q:2 * q + 2 * n] = frame
        return out

    def render(self, code: int, px_per_block: int, quiet_zone_blocks: int = 1) -> np.ndarray:
        """Render the landmark exactly, axis-aligned, upright.

        Args:
            code: a valid code.
            px_per_block: pixels per block, a positive even integer (bit cells are half blocks).
            quiet_zone_blocks: width of the white margin around the frame, in blocks.

        Returns:
            uint8 (N, N) image, white = 255, black = 0, ``N = (n_blocks + 2 q) px_per_block``.
            Pixel edge ``x = 0`` (the left edge of column 0) is grid coordinate ``u = -q``;
            grid point ``(u, v)`` is at pixel-edge coordinate ``((u + q) p, (v + q) p)``, i.e. at
            OpenCV pixel-centre coordinate ``((u + q) p - 0.5, (v + q) p - 0.5)``.

        Raises:
            InvalidCodeError: invalid code.
            ValueError: bad ``px_per_block`` or ``quiet_zone_blocks``.
        """
        p = _check_nonneg_int(px_per_block, 'px_per_block')
        if p < 2 or p % 2:
            raise ValueError(f'px_per_block must be a positive even integer; got {px_per_block!r}')
        cells = self.half_block_image(code, quiet_zone_blocks)
        img = np.where(cells, np.uint8(0), np.uint8(255))
        h = p // 2
        return np.repeat(np.repeat(img, h, axis=0), h, axis=1)


def _check_nonneg_int(value: object, what: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) \
            or value < 0:
        raise ValueError(f'{what} must be a non-negative integer; got {value!r}')
    return int(value)


# ---------------------------------------------------------------------- printable files
PRINTABLE_SUFFIXES = ('.png', '.svg', '.pdf')


def _runs(cells: np.ndarray):
    """Yield (row, col0, col1) horizontal runs of True cells."""
    for r, row in enumerate(cells):
        padded = np.concatenate([[False], row, [False]]).astype(np.int8)
        d = np.diff(padded)
        for c0, c1 in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
            yield r, int(c0), int(c1)


def png_with_resolution(img: np.ndarray, px_per_metre: float) -> bytes:
    """Encode a uint8 image as PNG with a pHYs chunk (pixels per metre, both axes).

    The PNG comes from ``cv2.imencode``; the 9-byte pHYs chunk (unit 1 = metre) is inserted
    right after IHDR, as the PNG specification requires (before the image data).
    """
    import cv2
    ok, buf = cv2.imencode('.png', img)
    if not ok:
        raise ValueError('PNG encoding failed')
    data = buf.tobytes()
    ppm = int(round(px_per_metre))
    body = b'pHYs' + struct.pack('>IIB', ppm, ppm, 1)
    chunk = struct.pack('>I', 9) + body + struct.pack('>I', zlib.crc32(body) & 0xFFFFFFFF)
    end_ihdr = 8 + 8 + 13 + 4  # signature, IHDR length + type, IHDR data, CRC
    if data[12:16] != b'IHDR':
        raise ValueError('unexpected PNG layout from cv2.imencode')
    return data[:end_ihdr] + chunk + data[end_ihdr:]


def write_printable(code: int, path: Union[str, Path],
                    design: LandmarkDesign = LandmarkDesign(), dpi: float = 300.0,
                    quiet_zone_blocks: int = 1) -> Path:
    """Write a printable landmark at true scale; the format follows the file suffix.

    * ``.png``: bitmap whose pHYs chunk carries the resolution so that it prints at true
      size; ``px_per_block`` is ``dpi`` times the block size rounded to an even integer and
      the stored resolution follows from it (nearest integer pixels per metre, the PNG
      unit: exact for the default 0.175 m frame, relative scale error < 1e-4 otherwise).
    * ``.svg``: width and height in millimetres, ``viewBox`` in millimetres, exact black
      rectangles (horizontal runs of half-block cells) on a white background.
    * ``.pdf``: one page of exactly the printed size (1 pt = 1/72 inch), vector rectangles,
      no margins (via matplotlib's PDF backend).

    The printed side is ``(n_blocks + 2 q) * block_size`` (0.225 m for the default design,
    wider than an A4 sheet's 210 mm: printing at 100 % on A4 trims part of the quiet zone,
    which only needs to stay white).

    Args:
        code: a valid code for ``design``.
        path: output file; suffix ``.png``, ``.svg`` or ``.pdf`` (case-insensitive).
        design: the landmark design (kind and frame width).
        dpi: PNG resolution in dots per inch (ignored for SVG and PDF), > 0.
        quiet_zone_blocks: white margin around the frame in blocks.

    Returns:
        The path written.

    Raises:
        InvalidCodeError: invalid code.
        ValueError: unknown suffix or bad dpi / quiet zone.
        OSError: the file cannot be written.
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in PRINTABLE_SUFFIXES:
        raise ValueError(f'unknown landmark file type {path.suffix!r} for {path}; '
                         f'use one of {", ".join(PRINTABLE_SUFFIXES)}')
    cells = design.half_block_image(code, quiet_zone_blocks)
    cell_m = 0.5 * design.block_size
    side_m = cells.shape[0] * cell_m
    if suffix == '.png':
        if not (isinstance(dpi, (int, float)) and math.isfinite(dpi) and dpi > 0):
            raise ValueError(f'dpi must be a finite number > 0; got {dpi!r}')
        p = max(2, 2 * int(round(0.5 * dpi * design.block_size * 1000.0 / MM_PER_INCH)))
        img = design.render(code, p, quiet_zone_blocks)
        path.write_bytes(png_with_resolution(img, p / design.block_size))
    elif suffix == '.svg':
        mm = cell_m * 1000.0
        side = side_m * 1000.0

        def f(x: float) -> str:
            return f'{x:.6f}'.rstrip('0').rstrip('.')

        parts = [
            '<?xml version="1.0" encoding="UTF-8"?>',
            f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{f(side)}mm" '
            f'height="{f(side)}mm" viewBox="0 0 {f(side)} {f(side)}" '
            'shape-rendering="crispEdges">',
            f'<title>landmark {design.kind} code {int(code)} frame '
            f'{f(design.frame_width * 1000.0)} mm</title>',
            f'<rect x="0" y="0" width="{f(side)}" height="{f(side)}" fill="#ffffff"/>',
        ]
        for r, c0, c1 in _runs(cells):
            parts.append(f'<rect x="{f(c0 * mm)}" y="{f(r * mm)}" width="{f((c1 - c0) * mm)}" '
                         f'height="{f(mm)}" fill="#000000"/>')
        parts.append('</svg>')
        path.write_text('\n'.join(parts) + '\n', encoding='utf-8')
    else:
        from matplotlib.backends.backend_pdf import FigureCanvasPdf
        from matplotlib.figure import Figure
        from matplotlib.patches import Rectangle
        side_in = side_m * 1000.0 / MM_PER_INCH
        fig = Figure(figsize=(side_in, side_in))
        FigureCanvasPdf(fig)
        ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
        ax.set_axis_off()
        k = cells.shape[0]
        ax.set_xlim(0, k)
        ax.set_ylim(k, 0)
        for r, c0, c1 in _runs(cells):
            ax.add_patch(Rectangle((c0, r), c1 - c0, 1, facecolor='black', edgecolor='none',
                                   linewidth=0, antialiased=False))
        fig.savefig(path, format='pdf', facecolor='white',
                    metadata={'Title': f'landmark {design.kind} code {int(code)}'})
    return path


__all__ = ['DEFAULT_FRAME_WIDTH', 'InvalidCodeError', 'KINDS', 'LandmarkDesign',
           'png_with_resolution', 'PRINTABLE_SUFFIXES', 'write_printable']
