"""Procedural textures for the camera simulator: walls, floors and landmark-free distractors.

Every function returns a uint8 (H, W) texture (0 = black ink, 255 = white) and draws its
randomness only from the ``rng`` passed in (deterministic for a seeded generator). The
distractors are the things a landmark detector must not mistake for a landmark: ordinary
checkerboards of several sizes, regular line grids, text-like lines of glyph blobs, tiled
surfaces and posters of random blobs.
"""

import math
from typing import Tuple

import cv2
import numpy as np

DISTRACTOR_KINDS = ('checkerboard', 'grid', 'text', 'tiles', 'poster')


def _smooth_noise(rng: np.random.Generator, shape: Tuple[int, int], scale: float) -> np.ndarray:
    """Return zero-mean, unit-std smooth noise of correlation length ``scale`` texels."""
    h, w = shape
    sh, sw = max(2, int(math.ceil(h / scale)) + 1), max(2, int(math.ceil(w / scale)) + 1)
    coarse = rng.standard_normal((sh, sw)).astype(np.float32)
    out = cv2.resize(coarse, (w, h), interpolation=cv2.INTER_CUBIC)
    out -= out.mean()
    std = float(out.std())
    return out / std if std > 0 else out


def wall(rng: np.random.Generator, shape: Tuple[int, int] = (150, 300), mean: float = 190.0,
         contrast: float = 10.0) -> np.ndarray:
    """Return a plain painted wall: ``mean`` grey with low-contrast smooth blotches."""
    n = contrast * (_smooth_noise(rng, shape, 25.0) + 0.3 * _smooth_noise(rng, shape, 4.0))
    return np.clip(mean + n, 0, 255).astype(np.uint8)


def checkerboard(rows: int, cols: int, square_px: int = 16, border_px: int = 16,
                 invert: bool = False) -> np.ndarray:
    """Return an ordinary checkerboard of rows x cols squares on a white border."""
    if rows < 1 or cols < 1 or square_px < 1 or border_px < 0:
        raise ValueError('checkerboard needs rows, cols, square_px >= 1 and border_px >= 0')
    j, i = np.mgrid[0:rows, 0:cols]
    black = ((i + j) % 2 == 0) ^ bool(invert)
    board = np.where(black, 0, 255).astype(np.uint8)
    board = np.repeat(np.repeat(board, square_px, axis=0), square_px, axis=1)
    return np.pad(board, border_px, constant_values=255)


def line_grid(rows: int, cols: int, cell_px: int = 20, line_px: int = 3,
              border_px: int = 10) -> np.ndarray:
    """Return a regular grid of black lines (graph paper, window bars, shelving)."""
    h, w = rows * cell_px + line_px, cols * cell_px + line_px
    img = np.full((h, w), 255, dtype=np.uint8)
    for r in range(rows + 1):
        img[r * cell_px:r * cell_px + line_px, :] = 0
    for c in range(cols + 1):
        img[:, c * cell_px:c * cell_px + line_px] = 0
    return np.pad(img, border_px, constant_values=255)


def text_like(rng: np.random.Generator, lines: int = 8, chars: int = 30,
              glyph_px: int = 10) -> np.ndarray:
    """Return lines of random glyph-like blobs and strokes (a printed page or a sign)."""
    gh, gw = glyph_px, max(3, int(0.7 * glyph_px))
    margin = glyph_px
    h = 2 * margin + lines * int(1.8 * gh)
    w = 2 * margin + chars * (gw + 2)
    img = np.full((h, w), 255, dtype=np.uint8)
    for li in range(lines):
        y = margin + li * int(1.8 * gh)
        x = margin
        n = int(rng.integers(chars // 2, chars + 1))
        for _ in range(n):
            if rng.random() < 0.15:  # word gap
                x += gw + 2
                continue
            glyph = rng.random((gh, gw)) < 0.45
            glyph = cv2.morphologyEx(glyph.astype(np.uint8), cv2.MORPH_CLOSE,
                                     np.ones((2, 2), np.uint8)).astype(bool)
            if x + gw > w - margin:
                break
            img[y:y + gh, x:x + gw][glyph] = 0
            x += gw + 2
    return img


def tiles(rng: np.random.Generator, rows: int = 6, cols: int = 6, tile_px: int = 24,
          grout_px: int = 2, contrast: float = 60.0) -> np.ndarray:
    """Return tiles of random grey levels separated by dark grout lines."""
    step = tile_px + grout_px
    img = np.full((rows * step + grout_px, cols * step + grout_px), 40, dtype=np.uint8)
    base = 150.0
    for r in range(rows):
        for c in range(cols):
            v = np.clip(base + contrast * (rng.random() - 0.5) * 2.0, 0, 255)
            y, x = grout_px + r * step, grout_px + c * step
            img[y:y + tile_px, x:x + tile_px] = int(v)
    return img


def poster(rng: np.random.Generator, shape: Tuple[int, int] = (120, 90),
           levels: int = 4) -> np.ndarray:
    """Return a poster of random blobs: smooth noise posterized to a few grey levels."""
    n = _smooth_noise(rng, shape, float(rng.uniform(6.0, 20.0)))
    edges = np.quantile(n, np.linspace(0, 1, levels + 1)[1:-1])
    q = np.digitize(n, edges)
    greys = np.sort(rng.uniform(0, 255, levels))
    img = greys[q].astype(np.uint8)
    return np.pad(img, 4, constant_values=255)


def floor_tiles(rng: np.random.Generator, rows: int = 40, cols: int = 40,
                tile_px: int = 30) -> np.ndarray:
    """Return a low-contrast tiled floor (light grout, slightly varying tiles)."""
    step = tile_px + 1
    img = np.full((rows * step + 1, cols * step + 1), 150, dtype=np.uint8)
    shades = np.clip(115 + rng.normal(0, 6, (rows, cols)), 0, 255).astype(np.uint8)
    big = np.repeat(np.repeat(shades, step, axis=0), step, axis=1)
    img[1:, 1:] = big[:img.shape[0] - 1, :img.shape[1] - 1]
    img[::step, :] = 150
    img[:, ::step] = 150
    return img


def random_distractor(rng: np.random.Generator, kind: str = None) -> Tuple[np.ndarray, float,
                                                                           str]:
    """Return ``(texture, metres_per_texel, kind)`` of a random distractor.

    Sizes are those of real objects: checkerboards with 1.5-5 cm squares (3x3 up to 10x9
    squares, i.e. also the landmark's 7 x 7 block count), grids with 2-6 cm cells, text with
    0.8-3 cm glyphs, tiles of 5-15 cm and posters of 20-60 cm.
    """
    kind = kind if kind is not None else DISTRACTOR_KINDS[int(rng.integers(len(DISTRACTOR_KINDS)))]
    if kind == 'checkerboard':
        rows, cols = int(rng.integers(3, 11)), int(rng.integers(3, 11))
        sq = float(rng.uniform(0.015, 0.05))
        tex = checkerboard(rows, cols, 16, int(rng.integers(0, 17)), bool(rng.random() < 0.5))
        return tex, sq / 16.0, kind
    if kind == 'grid':
        rows, cols = int(rng.integers(3, 10)), int(rng.integers(3, 10))
        cell = float(rng.uniform(0.02, 0.06))
        return line_grid(rows, cols, 20, int(rng.integers(1, 6))), cell / 20.0, kind
    if kind == 'text':
        g = float(rng.uniform(0.008, 0.03))
        tex = text_like(rng, int(rng.integers(3, 12)), int(rng.integers(10, 40)), 10)
        return tex, g / 10.0, kind
    if kind == 'tiles':
        t = float(rng.uniform(0.05, 0.15))
        tex = tiles(rng, int(rng.integers(2, 7)), int(rng.integers(2, 7)), 24, 2)
        return tex, t / 24.0, kind
    if kind == 'poster':
        size = float(rng.uniform(0.2, 0.6))
        h = int(rng.integers(80, 160))
        tex = poster(rng, (h, int(h * rng.uniform(0.6, 1.4))))
        return tex, size / h, kind
    raise ValueError(f'unknown distractor kind {kind!r}; valid: {DISTRACTOR_KINDS}')


__all__ = ['checkerboard', 'DISTRACTOR_KINDS', 'floor_tiles', 'line_grid', 'poster',
           'random_distractor', 'text_like', 'tiles', 'wall']
