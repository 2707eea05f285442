"""Helpers shared by the benchmark scripts (not an entry point).

Data folders: a benchmark that reads recordings takes ``--data DIR`` (default
``../shared/data/<name>`` beside the repository when it exists) and log arguments, each a
log name looked up in that folder (``aces`` -> ``DIR/aces-corrected.log.gz`` for the
Carmen logs) or a path to a log file. A folder or log that is not there stops the script
with a message naming it (exit status 1).
"""

import argparse
import ast
import math
import os
from pathlib import Path
import sys
import tempfile
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402

# The six Radish logs of ../shared/data/carmen, in the order of the README's tables.
CARMEN_LOGS = ('aces', 'seattle', 'fhw', 'freiburg-101', 'belgioioso', 'acapulco')
CARMEN_SUFFIX = '-corrected.log.gz'


def add_data_argument(parser: argparse.ArgumentParser, name: str) -> None:
    """Add ``--data DIR`` (default ``../shared/data/<name>``) to ``parser``."""
    parser.add_argument('--data', default=str(SHARED_DATA / name), metavar='DIR',
                        help=f'folder of the recordings (default: {SHARED_DATA / name})')


def data_folder(path: str) -> Path:
    """Return ``path`` as a folder; stop with a clear message when it is not one."""
    folder = Path(path)
    if not folder.is_dir():
        sys.exit(f'error: data folder {folder} not found (give one with --data DIR)')
    return folder


def log_paths(data: str, logs: Iterable[str], suffix: str = CARMEN_SUFFIX
              ) -> List[Tuple[str, Path]]:
    """Return ``(name, path)`` of each log: a file path as given, else ``DATA/<name><suffix>``.

    The name of a file path is its file name without ``suffix`` (or without its extensions).
    Stops with a message naming the first log or folder that is not there.
    """
    out = []
    for log in logs:
        path = Path(log)
        if path.is_file():
            name = path.name[:-len(suffix)] if path.name.endswith(suffix) else \
                path.name.split('.')[0]
            out.append((name, path))
            continue
        path = data_folder(data) / f'{log}{suffix}'
        if not path.is_file():
            sys.exit(f'error: log {log}: {path} not found (a log name in --data DIR, or a '
                     'path to a log file)')
        out.append((log, path))
    return out


def parse_set(items: Iterable[str]) -> dict:
    """Return ``{NAME: value}`` of ``--set NAME=VALUE`` items (values read as Python literals)."""
    out = {}
    for item in items:
        key, sep, value = item.partition('=')
        if not sep:
            sys.exit(f'error: --set {item!r}: expected NAME=VALUE')
        try:
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            sys.exit(f'error: --set {item!r}: {value!r} is not a Python literal '
                     "(quote strings: NAME=\"'text'\")")
    return out


def best_ms(fn: Callable[[], object], repeat: int) -> float:
    """Return the best-of-``repeat`` time of one call of ``fn`` [ms] (per-scan sample)."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return 1e3 * best


def approx_poly(clusters: list, eps: float) -> int:
    """Run cv2.approxPolyDP on every cluster; return the number of vertices."""
    import cv2
    import numpy as np
    n = 0
    for c in clusters:
        contour = np.ascontiguousarray(c.points, dtype=np.float32).reshape(-1, 1, 2)
        n += len(cv2.approxPolyDP(contour, eps, False))
    return n


# The two lasers of the simulated office scans: the default LMS200-like one and a 1081-beam
# UTM-30LX-like one.
LASERS = {
    '361 beams (180 deg, 0.5 deg)': {},
    '1081 beams (270 deg, 0.25 deg)': {
        'angle_min': -math.radians(135.0), 'angle_max': math.radians(135.0),
        'angle_increment': math.radians(0.25), 'time_increment': (1.0 / 40.0) / 1440.0,
        'range_max': 30.0},
}


def spread(items: list, count: int) -> list:
    """Return ``count`` items spread evenly over ``items``."""
    step = max(1, len(items) // max(1, count))
    return items[::step][:count]


def office_scans(laser: dict, count: int) -> list:
    """Return ``count`` scans spread over the simulated office run (seed 1) with this laser."""
    from landmark_nav.sim import run_scenario, ScanSample
    res = run_scenario('office', seed=1, laser=laser or True)
    return spread(res.of_type(ScanSample), count)


def bag_scans(bag: str, count: int, max_seconds: Optional[float] = None) -> list:
    """Return ``count`` scans (:class:`ScanSample`) spread over a bag's ``/scan``."""
    from landmark_nav.evaluation.bags import load_bag
    from landmark_nav.sim import ScanSample
    if not Path(bag, 'metadata.yaml').is_file():
        sys.exit(f'error: bag {bag} not found (a rosbag2 folder with metadata.yaml)')
    scenario = load_bag(bag, max_seconds=max_seconds, require_reference=False)
    scans = scenario.of_type(ScanSample)
    if not scans:
        sys.exit(f'error: bag {bag} has no /scan message')
    return spread(scans, count)


def subcommand_parser(doc: str) -> Tuple[argparse.ArgumentParser, Any]:
    """Return a parser described by ``doc``'s first line and its subcommand group."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    return parser, parser.add_subparsers(dest='command', required=True)


def add_logs_argument(parser: argparse.ArgumentParser, folder: str, logs: Iterable[str]
                      ) -> None:
    """Add the positional LOG arguments (default ``logs``) and ``--data DIR`` (``folder``)."""
    parser.add_argument('logs', nargs='*', default=list(logs), metavar='LOG',
                        help='log names in --data DIR or paths to log files (default: '
                             + ' '.join(logs) + ')')
    add_data_argument(parser, folder)


def run_subcommand(parser: argparse.ArgumentParser, argv=None) -> int:
    """Parse ``argv`` and run the chosen subcommand's ``run`` function; return its status."""
    args = parser.parse_args(argv)
    return args.run(args)


IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg')
IMAGE_TOPICS = ('/camera/image_raw', '/camera/image_raw/compressed')


def load_images(path: str, count: Optional[int] = None) -> List[Tuple[str, Any]]:
    """Return ``(name, grey uint8 image)`` of ``count`` images spread over ``path`` (all: None).

    ``path`` is a folder of images (``*.png``, ``*.jpg``, ``*.jpeg``, sorted by name; colour
    images are converted to grey) or a rosbag2 folder with ``/camera/image_raw`` (mono8,
    bgr8, rgb8 or mono16) or ``/camera/image_raw/compressed``. Stops with a message naming
    the folder when it holds no image, and naming the file or message that cannot be read.
    """
    folder = data_folder(path)
    if (folder / 'metadata.yaml').is_file():
        return _bag_images(folder, count)
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        sys.exit(f'error: {folder} holds no image ({", ".join(IMAGE_SUFFIXES)}) and is not '
                 'a bag')
    import cv2
    out = []
    for p in files if count is None else spread(files, count):
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        if img is None:
            sys.exit(f'error: cannot read the image {p}')
        out.append((p.name, img))
    return out


def _bag_images(folder: Path, count: Optional[int]) -> List[Tuple[str, Any]]:
    """Return ``(name, grey image)`` of the camera images of a bag (see :func:`load_images`)."""
    from landmark_nav.bag.reader import BagReader
    from landmark_nav.conversions import ConversionError
    from landmark_nav.landmark_msgs import compressed_to_gray, image_to_gray
    with BagReader(folder) as bag:
        topics = [t for t in IMAGE_TOPICS if t in bag.topics()]
        if not topics:
            sys.exit(f'error: bag {folder} has none of the image topics '
                     f'{", ".join(IMAGE_TOPICS)}')
        msgs = list(bag.messages(topics=topics[:1]))
        if count is not None:
            msgs = spread(msgs, count)
        out = []
        for m in msgs:
            try:
                msg = m.decode()
                img = (compressed_to_gray(msg) if m.topic.endswith('compressed')
                       else image_to_gray(msg))
            except ConversionError as e:
                sys.exit(f'error: bag {folder}, {m.topic} at {m.log_time_ns} ns: {e}')
            out.append((f'{m.topic}@{m.log_time_ns}', img))
    return out


def live_run(domain: int, out: Optional[str], prefix: str) -> Tuple[Path, Dict[str, str], list]:
    """Prepare a live run on the emulated robot: DDS isolated on ``domain``.

    Returns the run's folder (``out``, else a new temporary one named ``prefix...``), the
    environment of its processes (this repository first on ``PYTHONPATH``) and the command
    that starts ``landmark_nav``.
    """
    from landmark_nav.testing import isolate_dds
    isolate_dds(domain)
    folder = Path(out or tempfile.mkdtemp(prefix=prefix))
    folder.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep + os.environ.get('PYTHONPATH', ''))
    return folder, env, [sys.executable, '-m', 'landmark_nav.tools.cli']
