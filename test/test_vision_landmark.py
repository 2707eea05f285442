"""Tests of the landmark design: geometry, code rules, encode/render/decode, printable files."""

import re
import struct
import xml.etree.ElementTree as ET
import zlib

import cv2
from landmark_nav.tools.cli import main as cli_main
from landmark_nav.vision.landmark import InvalidCodeError, LandmarkDesign, write_printable
import numpy as np
import pytest

BIG = LandmarkDesign()
SMALL = LandmarkDesign('2x2')


def read_bits(img: np.ndarray, design: LandmarkDesign, px_per_block: int,
              quiet: int = 1) -> np.ndarray:
    """Sample an axis-aligned render at the centres of the code cells (test's own reading)."""
    m = 2 * design.code_squares
    out = np.zeros((m, m), dtype=bool)
    for r in range(m):
        for c in range(m):
            u = quiet + 2 + 0.5 * c + 0.25  # cell centre in blocks from the image corner
            v = quiet + 2 + 0.5 * r + 0.25
            out[r, c] = img[int(v * px_per_block), int(u * px_per_block)] < 128
    return out


# ---------------------------------------------------------------------- geometry
def test_frame_geometry_large():
    assert BIG.n_blocks == 7 and BIG.block_size == pytest.approx(0.025)
    b = 0.175 * 5 / 14
    assert b == pytest.approx(0.0625)
    expected = np.array([[0, -b, b], [0, b, b], [0, b, -b], [0, -b, -b]])
    np.testing.assert_allclose(BIG.frame_corners(), expected, atol=1e-15)
    edges = BIG.edge_corners()
    assert edges.shape == (4, 6, 3)  # six corners per edge (eq. 3)
    for e in range(4):
        np.testing.assert_allclose(edges[e, 0], expected[e], atol=1e-15)
        np.testing.assert_allclose(edges[e, -1], expected[(e + 1) % 4], atol=1e-15)
        steps = np.linalg.norm(np.diff(edges[e], axis=0), axis=1)
        np.testing.assert_allclose(steps, 0.025, atol=1e-15)


def test_frame_geometry_small():
    d = LandmarkDesign('2x2', 0.12)
    assert d.n_blocks == 6 and d.corners_per_edge == 5
    b = 2 * 0.12 / 6
    np.testing.assert_allclose(d.frame_corners()[1], [0, b, b], atol=1e-15)
    assert d.edge_corners().shape == (4, 5, 3)


def test_x_corners_are_checkerboard_corners():
    """Every frame X-corner touches two black and two white frame blocks, diagonally."""
    for design in (BIG, SMALL):
        col = design.block_colours()
        assert col[0, 0] == 1 and col[1, 1] == 1  # outer and inner corner blocks black
        for u, v in design.edge_corner_grid().reshape(-1, 2):
            i, j = int(u), int(v)
            quad = col[j - 1:j + 1, i - 1:i + 1]
            assert set(quad.ravel()) == {0, 1}
            assert quad[0, 0] == quad[1, 1] != quad[0, 1] == quad[1, 0]


def test_block_colours_rule():
    col = BIG.block_colours()
    n = 7
    for j in range(n):
        for i in range(n):
            if 2 <= i <= 4 and 2 <= j <= 4:
                assert col[j, i] == -1
            else:
                assert col[j, i] == (1 if (i + j) % 2 == 0 else 0)


def test_bad_design_rejected():
    with pytest.raises(ValueError):
        LandmarkDesign('4x4')
    for w in (0.0, -0.1, float('nan'), float('inf')):
        with pytest.raises(ValueError):
            LandmarkDesign('3x3', w)


# ---------------------------------------------------------------------- codes
def test_encode_156_matches_chapter_figure():
    """156 = 0x9C: square 6 = 0x9 (bits 1 and 4), square 7 = 0xC (bits 1 and 2)."""
    bits = BIG.encode(156)
    expected = np.zeros((6, 6), dtype=bool)
    expected[0:2, 0:4] = True  # orientation marks
    expected[4, 2] = expected[5, 3] = True  # square 6 = 1001
    expected[4, 4] = expected[4, 5] = True  # square 7 = 1100
    np.testing.assert_array_equal(bits, expected)


def test_encode_123456789_nibbles():
    bits = BIG.encode(123456789)
    positions = [(0, 2), (1, 0), (1, 1), (1, 2), (2, 0), (2, 1), (2, 2)]
    digits = [int(c, 16) for c in '75BCD15']
    for (r, c), digit in zip(positions, digits):
        cell = bits[2 * r:2 * r + 2, 2 * c:2 * c + 2]
        assert 8 * cell[0, 0] + 4 * cell[0, 1] + 2 * cell[1, 0] + cell[1, 1] == digit


@pytest.mark.parametrize('design,code', [(BIG, 156), (BIG, 123456789), (BIG, 0),
                                         (BIG, 0xEFEFEFE), (SMALL, 0),
                                         (SMALL, 345), (SMALL, 511)])
def test_render_decode_round_trip_all_rotations(design, code):
    p = 8
    img = design.render(code, p)
    assert img.dtype == np.uint8 and set(np.unique(img)) <= {0, 255}
    assert img.shape == ((design.n_blocks + 2) * p,) * 2
    for k in range(4):
        seen = np.rot90(img, k)  # the landmark as a camera rolled by k quarter turns sees it
        bits = read_bits(seen, design, p)
        res = design.decode_with_rotation(bits)
        assert res is not None
        got, kk = res
        assert got == code
        np.testing.assert_array_equal(np.rot90(bits, kk), design.encode(code))


def test_render_frame_blocks():
    p = 4
    img = BIG.render(156, p, quiet_zone_blocks=1)
    assert np.all(img[:p, :] == 255) and np.all(img[:, -p:] == 255)  # quiet zone
    col = BIG.block_colours()
    for j in range(7):
        for i in range(7):
            if col[j, i] >= 0:
                block = img[(j + 1) * p:(j + 2) * p, (i + 1) * p:(i + 2) * p]
                assert np.all(block == (0 if col[j, i] == 1 else 255))


def _grid_from_nibbles(nibbles):
    bits = np.zeros((6, 6), dtype=bool)
    vals = [0xF, 0xF] + list(nibbles)
    for pos, v in enumerate(vals):
        r, c = divmod(pos, 3)
        bits[2 * r:2 * r + 2, 2 * c:2 * c + 2] = [[v & 8, v & 4], [v & 2, v & 1]]
    return bits


def test_validity_rule():
    for pair in ((1, 4), (7, 6), (5, 2)):
        nib = [3] * 7
        nib[pair[0] - 1] = nib[pair[1] - 1] = 0xF
        code = int(''.join(f'{v:X}' for v in nib), 16)
        assert not BIG.is_valid_code(code)
        with pytest.raises(InvalidCodeError):
            BIG.encode(code)
        # such a grid shows the mark in two rotations: the decoder must refuse it
        assert BIG.decode(_grid_from_nibbles(nib)) is None
        nib[pair[1] - 1] = 0xE
        assert BIG.is_valid_code(int(''.join(f'{v:X}' for v in nib), 16))
    # 0xF squares that never pair up are fine
    assert BIG.is_valid_code(0x0F0F0F0 & 0xFFFFFFF)
    for bad in (-1, 2 ** 28, 1.5, '156', True, None):
        assert not BIG.is_valid_code(bad)
        with pytest.raises(InvalidCodeError):
            BIG.check_code(bad)
    assert SMALL.is_valid_code(511) and not SMALL.is_valid_code(512)


def test_count_valid_codes_by_enumeration():
    """Count the valid 28-bit codes with an independent vectorised check."""
    total = 0
    chunk = 1 << 20  # every code, in chunks of 4 MB uint32 arrays (they stay in the cache)
    for start in range(0, 1 << 28, chunk):
        c = np.arange(start, start + chunk, dtype=np.uint32)

        def sq(k):
            return (c >> (4 * (7 - k))) & 0xF

        bad = ((sq(1) == 15) & (sq(4) == 15)) | ((sq(7) == 15) & (sq(6) == 15)) \
            | ((sq(5) == 15) & (sq(2) == 15))
        total += int(chunk - np.count_nonzero(bad))
    assert total == BIG.count_valid_codes() == 265302000
    assert total > 2 ** 24 - 2 ** 16  # the chapter's estimate (§2.1)
    assert SMALL.count_valid_codes() == sum(SMALL.is_valid_code(c) for c in range(1024))


def test_decode_rejects_unreadable_grids():
    assert BIG.decode(np.zeros((6, 6), bool)) is None  # no mark
    assert BIG.decode(np.ones((6, 6), bool)) is None  # marks everywhere
    with pytest.raises(ValueError):
        BIG.decode(np.zeros((4, 4), bool))
    g = SMALL.encode(5).copy()
    g[3, 3] = True  # bit 4 of the least significant square must stay white
    assert SMALL.decode(g) is None
    with pytest.raises(ValueError):
        BIG.render(156, 7)  # odd pixels per block cannot hold half-block cells


def test_random_codes_round_trip():
    rng = np.random.default_rng(3)
    n = 0
    while n < 300:
        code = int(rng.integers(2 ** 28))
        if not BIG.is_valid_code(code):
            continue
        n += 1
        bits = BIG.encode(code)
        k = int(rng.integers(4))
        assert BIG.decode_with_rotation(np.rot90(bits, -k)) == (code, k % 4)


# ---------------------------------------------------------------------- printable files
def _png_chunks(data: bytes):
    """Yield (type, payload) of the chunks of a PNG file, checking every CRC."""
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    pos = 8
    while pos < len(data):
        (n,) = struct.unpack('>I', data[pos:pos + 4])
        kind, payload = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        (crc,) = struct.unpack('>I', data[pos + 8 + n:pos + 12 + n])
        assert crc == zlib.crc32(kind + payload) & 0xFFFFFFFF
        yield kind, payload
        pos += 12 + n


def test_png_true_scale(tmp_path):
    path = write_printable(156, tmp_path / 'lm.png', BIG, dpi=300)
    chunks = list(_png_chunks(path.read_bytes()))
    kinds = [k for k, _ in chunks]
    assert kinds[0] == b'IHDR' and kinds.index(b'pHYs') < kinds.index(b'IDAT')
    ppx, ppy, unit = struct.unpack('>IIB', dict(chunks)[b'pHYs'])
    assert unit == 1 and ppx == ppy  # pixels per metre
    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    assert arr.dtype == np.uint8 and arr.ndim == 2
    side_mm = arr.shape[1] / ppx * 1000.0
    assert side_mm == pytest.approx(225.0, abs=0.02)  # 175 mm frame + two 25 mm quiet zones
    assert ppx * 0.0254 == pytest.approx(300.0, abs=2.0)  # about the requested dpi
    p = arr.shape[1] // 9
    assert arr.shape[1] == 9 * p and p % 2 == 0
    assert BIG.decode(read_bits(arr, BIG, p)) == 156


def test_svg_true_scale(tmp_path):
    path = write_printable(123456789, tmp_path / 'lm.svg', BIG)
    root = ET.parse(path).getroot()
    assert root.get('width') == '225mm' and root.get('height') == '225mm'
    assert root.get('viewBox') == '0 0 225 225'
    ns = '{http://www.w3.org/2000/svg}'
    black = [r for r in root.iter(ns + 'rect') if r.get('fill') == '#000000']
    area = sum(float(r.get('width')) * float(r.get('height')) for r in black)
    cells = BIG.half_block_image(123456789)
    assert area == pytest.approx(cells.sum() * 12.5 ** 2, rel=1e-9)
    # rasterise the rectangles back and decode
    img = np.full((18, 18), 255, np.uint8)
    for r in black:
        x, y = float(r.get('x')) / 12.5, float(r.get('y')) / 12.5
        w, h = float(r.get('width')) / 12.5, float(r.get('height')) / 12.5
        img[int(round(y)):int(round(y + h)), int(round(x)):int(round(x + w))] = 0
    assert BIG.decode(read_bits(img, BIG, 2)) == 123456789


def test_pdf_true_scale(tmp_path):
    d = LandmarkDesign('2x2', 0.12)
    path = write_printable(345, tmp_path / 'lm.pdf', d)
    data = path.read_bytes()
    assert data.startswith(b'%PDF')
    box = re.search(rb'/MediaBox\s*\[\s*([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s*\]', data)
    assert box is not None
    w_pt, h_pt = float(box.group(3)) - float(box.group(1)), float(box.group(4)) - float(
        box.group(2))
    side_mm = 120.0 * 8 / 6
    assert w_pt == pytest.approx(side_mm / 25.4 * 72, abs=0.01)
    assert h_pt == pytest.approx(side_mm / 25.4 * 72, abs=0.01)


def test_printable_errors(tmp_path):
    with pytest.raises(ValueError, match='file type'):
        write_printable(156, tmp_path / 'lm.jpg')
    with pytest.raises(InvalidCodeError):
        write_printable(2 ** 28, tmp_path / 'lm.svg')
    assert not (tmp_path / 'lm.svg').exists()


# ---------------------------------------------------------------------- command line
def test_cli_make_landmark(tmp_path, capsys):
    out = tmp_path / 'fig1.svg'
    assert cli_main(['make-landmark', '156', '--frame-width', '0.175', '--out', str(out)]) == 0
    assert out.is_file() and '225 x 225 mm' in capsys.readouterr().out
    out2 = tmp_path / 'small.png'
    assert cli_main(['make-landmark', '0x1FF', '--kind', '2x2', '--out', str(out2)]) == 0
    assert out2.is_file()


@pytest.mark.parametrize('argv', [
    ['make-landmark', str(2 ** 28), '--out', 'X.svg'],
    ['make-landmark', '512', '--kind', '2x2', '--out', 'X.svg'],
    ['make-landmark', str(0xF00F000), '--out', 'X.svg'],
    ['make-landmark', '156', '--frame-width', '0', '--out', 'X.svg'],
    ['make-landmark', '156', '--frame-width', 'nan', '--out', 'X.svg'],
    ['make-landmark', '156', '--out', 'X.gif'],
    ['make-landmark', 'abc', '--out', 'X.svg'],
])
def test_cli_make_landmark_errors(argv, tmp_path, capsys):
    argv = [a.replace('X.', str(tmp_path / 'x.')) for a in argv]
    with pytest.raises(SystemExit) as exc:
        rc = cli_main(argv)
        raise SystemExit(rc)
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip()
    assert err and '\n' not in err and 'Traceback' not in err
    assert not list(tmp_path.iterdir())
