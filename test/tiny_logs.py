"""Tiny real-format logs of a simulated room, for the benchmark smoke runs.

A rectangular room (8 x 5 m) with a pillar, ray cast for a robot driving along it: a Carmen
log (``FLASER``, 361 beams over 180 deg, the pose as the corrected pose), a CMU Wean log
(``O`` and ``L`` lines, cm, 180 beams, the laser 25 cm ahead) and the room as a beesoft
occupancy map (``wean.dat.gz``, 10 cm cells, the value the probability of free space as in
the Wean data). Also a raw byte capture of a SCIP 2.0 laser (:func:`write_scip2_capture`).
"""

import gzip
import math
from pathlib import Path

import numpy as np

ROOM = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 5.0], [0.0, 5.0]])
PILLAR = np.array([[5.0, 3.2], [5.8, 3.2], [5.8, 4.0], [5.0, 4.0]])


def _walls() -> np.ndarray:
    """Return the wall segments, (M, 2, 2)."""
    segs = []
    for poly in (ROOM, PILLAR):
        segs += [(poly[k], poly[(k + 1) % len(poly)]) for k in range(len(poly))]
    return np.array(segs)


def ray_cast(pose, angles: np.ndarray, max_range: float = 30.0) -> np.ndarray:
    """Return the distance along each beam (laser at ``pose``) to the nearest wall."""
    walls = _walls()
    d = np.stack([np.cos(pose[2] + angles), np.sin(pose[2] + angles)], axis=1)   # (N, 2)
    a, b = walls[:, 0], walls[:, 1]                                             # (M, 2)
    e = b - a
    denom = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]
    w = a[None] - np.asarray(pose[:2])[None, None]
    with np.errstate(divide='ignore', invalid='ignore'):
        t = (w[..., 0] * e[None, :, 1] - w[..., 1] * e[None, :, 0]) / denom
        u = (w[..., 0] * d[:, None, 1] - w[..., 1] * d[:, None, 0]) / denom
    hit = (np.abs(denom) > 1e-12) & (t > 0) & (u >= 0) & (u <= 1)
    return np.minimum(np.where(hit, t, np.inf).min(axis=1), max_range)


def poses(n: int) -> np.ndarray:
    """Return ``n`` poses of a drive along the room on an S curve (10 Hz, 0.5 m/s)."""
    k = np.arange(n)
    x, y = 1.0 + 0.05 * k, 2.0 + 0.6 * np.sin(0.1 * k)
    return np.column_stack([x, y, np.arctan2(0.06 * np.cos(0.1 * k), 0.05)])


def write_carmen(path: Path, n: int = 40, seed: int = 0) -> Path:
    """Write a Carmen ``-corrected`` log of ``n`` scans (1 cm range noise); return its path."""
    rng = np.random.default_rng(seed)
    angles = np.radians(np.linspace(-90.0, 90.0, 361))
    lines = []
    for k, p in enumerate(poses(n)):
        r = ray_cast(p, angles) + rng.normal(0.0, 0.01, angles.size)
        pose = ' '.join(f'{v:.4f}' for v in p)
        stamp = 1000.0 + 0.1 * k
        lines.append(f'FLASER 361 {" ".join(f"{v:.3f}" for v in r)} {pose} {pose} '
                     f'{stamp:.3f} host {stamp:.3f}\n')
    with gzip.open(path, 'wt') as f:
        f.writelines(lines)
    return path


def write_wean(folder: Path, name: str = 'robotdata1', n: int = 40, seed: int = 0) -> Path:
    """Write ``folder/<name>.log.gz`` and ``folder/wean.dat.gz``; return the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    angles = np.radians(np.arange(180) - 89.5)
    lines = []
    for k, p in enumerate(poses(n)):
        laser = np.array([p[0] + 0.25 * math.cos(p[2]), p[1] + 0.25 * math.sin(p[2]), p[2]])
        cm = 100.0 * (ray_cast(laser, angles) + rng.normal(0.0, 0.01, angles.size))
        x, y, t = 100.0 * p[0], 100.0 * p[1], p[2]
        xl, yl = 100.0 * laser[0], 100.0 * laser[1]
        ts = 0.1 * k
        lines.append(f'O {x:.2f} {y:.2f} {t:.5f} {ts:.3f}\n')
        lines.append(f'L {x:.2f} {y:.2f} {t:.5f} {xl:.2f} {yl:.2f} {t:.5f} '
                     f'{" ".join(str(int(round(v))) for v in cm)} {ts + 0.05:.3f}\n')
    with gzip.open(folder / f'{name}.log.gz', 'wt') as f:
        f.writelines(lines)
    # The map: 10 cm cells over 10 x 7 m (the room at 1 m from the edges), 1 = free,
    # 0 = wall, -1 = outside the building; rows are x, columns y (beesoft order).
    nx, ny = 100, 70
    c = (np.arange(nx) + 0.5) * 0.1 - 1.0
    r = (np.arange(ny) + 0.5) * 0.1 - 1.0
    x, y = np.meshgrid(c, r, indexing='ij')
    inside = (x > 0) & (x < 8) & (y > 0) & (y < 5)
    pillar = (x > 5.0) & (x < 5.8) & (y > 3.2) & (y < 4.0)
    near = (x > -0.2) & (x < 8.2) & (y > -0.2) & (y < 5.2)
    grid = np.where(inside & ~pillar, 1.0, np.where(near, 0.0, -1.0))
    with gzip.open(folder / 'wean.dat.gz', 'wt') as f:
        f.write('robot_specifications->resolution 10\n')
        f.write(f'global_map[0]: {nx} {ny}\n')
        for row in grid:
            f.write(' '.join(f'{v:g}' for v in row) + '\n')
    return folder


def write_york(folder: Path, images: int = 2, seed: int = 0, off_deg: float = 0.0) -> Path:
    """Write York Urban-format images (``NAME.jpg`` + ``NAME_gt.npz``) of line segments.

    Each 640 x 480 image holds dark segments toward the three orthogonal vanishing points
    of a random camera rotation (the dataset's intrinsics and y-up convention); the
    ground truth lists the segments and their vanishing point (1-based, as the dataset).
    ``off_deg``: in every odd-numbered image the true direction nearest the optical axis
    is turned by this angle about the camera's x axis, so an estimate of it is about that
    far off (directions on both sides of 2 deg, as a calibration needs).
    """
    import cv2
    from landmark_nav.evaluation.vanishing_points import YORK_FLIP, YORK_K
    folder.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(seed)
    for n in range(images):
        a, b = rng.uniform(-0.4, 0.4, 2)
        ca, sa, cb, sb = math.cos(a), math.sin(a), math.cos(b), math.sin(b)
        rot = np.array([[ca, 0, sa], [0, 1, 0], [-sa, 0, ca]]) @ np.array(
            [[1, 0, 0], [0, cb, -sb], [0, sb, cb]])
        img = np.full((480, 640), 200, np.uint8)
        lines, assoc = [], []
        for i in range(3):
            d = rot[:, i]
            for _ in range(12):
                p = rng.uniform([60, 60], [580, 420])
                ray = np.linalg.solve(YORK_K, [p[0], p[1], 1.0])
                q = YORK_K @ (ray + 0.4 * d)   # a point further along the 3-D direction
                q = q[:2] / q[2] if q[2] > 1e-3 else p + 80 * d[:2] / np.linalg.norm(d[:2])
                u = (q - p) / max(np.linalg.norm(q - p), 1e-9)
                e = p + 70.0 * u
                cv2.line(img, tuple(int(v) for v in p), tuple(int(v) for v in e), 30, 2)
                lines.append([p[0], p[1], e[0], e[1]])
                assoc.append(i + 1)
        cv2.imwrite(str(folder / f'T{n:03d}.jpg'), img)
        if n % 2:
            t = math.radians(off_deg)
            k = int(np.argmax(np.abs(rot[2])))
            rot = rot.copy()
            rot[:, k] = np.array([[1, 0, 0], [0, math.cos(t), -math.sin(t)],
                                  [0, math.sin(t), math.cos(t)]]) @ rot[:, k]
        np.savez(folder / f'T{n:03d}_gt.npz', vp=np.linalg.inv(YORK_FLIP) @ rot,
                 lines=np.array(lines), vp_association=np.array(assoc))
    return folder


def write_camvid(folder: Path, frames: int = 2, seed: int = 0) -> Path:
    """Write CamVid-format frames (``images/NAME.png``, ``labels_camvid11/NAME.png``).

    480 x 360: a grey road (label 3) widening toward the bottom between green verges and
    a blue sky, with pixel noise.
    """
    import cv2
    rng = np.random.default_rng(seed)
    (folder / 'images').mkdir(parents=True, exist_ok=True)
    (folder / 'labels_camvid11').mkdir(parents=True, exist_ok=True)
    h, w = 360, 480
    v, u = np.mgrid[0:h, 0:w]
    for n in range(frames):
        half = np.clip((v - 150) * 0.9, 0, None)
        road = (v > 150) & (np.abs(u - w / 2 - 10 * n) < half)
        label = np.where(road, 3, np.where(v < 150, 0, 4)).astype(np.uint8)
        colour = np.array([[200, 170, 120], [110, 110, 110], [60, 140, 60]], float)
        rgb = colour[np.where(v < 150, 0, np.where(road, 1, 2))]
        rgb = np.clip(rgb + rng.normal(0, 6, rgb.shape), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / 'images' / f'f{n:03d}.png'), rgb[..., ::-1])
        cv2.imwrite(str(folder / 'labels_camvid11' / f'f{n:03d}.png'), label)
    return folder


def write_scip2_capture(path: Path, frames: int = 3) -> Path:
    """Write the bytes a URG laser sends for ``frames`` ``MD`` scans of the room (a capture).

    1081 steps over 270 deg at 0.25 deg, ranges ray cast in mm along the path, encoded by
    the emulator's encoder as ``cat /dev/ttyACM0 > FILE`` would record them.
    """
    from landmark_nav.drivers import scip2
    angles = np.radians(np.arange(-540, 541) * 0.25)
    out = b''
    for k, pose in enumerate(poses(frames)):
        mm = np.rint(1000.0 * ray_cast(pose, angles)).astype(int)
        out += scip2.encode_scan_reply_raw(b'MD0000108001000', mm, 1000 + 25 * k)
    path.write_bytes(out)
    return path
