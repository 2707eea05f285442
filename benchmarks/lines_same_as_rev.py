"""Check that the line extractors give the same lines as at another git revision.

Run from the repository root (needs ``../shared/data/carmen``)::

    python benchmarks/lines_same_as_rev.py [--rev HEAD] [--step 1] [--tol 1e-9] [LOG ...]

``landmark_nav/laser/lines.py`` of ``--rev`` is loaded with the rest of that revision's
``landmark_nav/laser`` package (``git archive``: the modules it imports, e.g. ``lowess.py``
and ``line_extraction/``, as they were there) and both versions extract the lines of
every ``--step``-th scan of the Carmen logs (default: all scans of the six logs of
``bench_lines_real.py``, segmented as there), with both methods and the default
parameters. Per scan the line
count, beam indices and point counts must be equal and rho, alpha, the end points, RMSE
and covariance must agree to ``--tol`` (absolute, alpha wrapped). Prints one row per log
and method; exits 1 on a difference. Meant for speed work that must not change results.
"""

import argparse
import importlib
import importlib.util
import io
import math
from pathlib import Path
import subprocess
import sys
import tarfile
import tempfile

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_lines_real import LOGS, MAX_RANGE  # noqa: E402
from landmark_nav.importers.carmen import read_carmen_scans  # noqa: E402
from landmark_nav.laser import lines as new_lines  # noqa: E402
from landmark_nav.laser.segmentation import segment_scan  # noqa: E402
from landmark_nav.testing.shared_data import SHARED_DATA  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


LASER = 'landmark_nav.laser'


def load_rev(rev: str):
    """Return ``landmark_nav/laser/lines.py`` of git revision ``rev`` as a module.

    The revision's ``landmark_nav/laser`` package is extracted to a temporary folder and
    imported in place of the current one while ``lines`` and the modules it imports load;
    then the current modules are put back (the loaded ones keep the names they imported).
    """
    tar = subprocess.run(['git', 'archive', rev, 'landmark_nav/laser'], cwd=ROOT, check=True,
                         capture_output=True).stdout
    tmp = Path(tempfile.mkdtemp())
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(tmp, filter='data')
    folder = tmp / 'landmark_nav' / 'laser'
    current = {k: v for k, v in sys.modules.items() if k == LASER or k.startswith(LASER + '.')}
    for k in current:
        del sys.modules[k]
    try:
        spec = importlib.util.spec_from_file_location(
            LASER, folder / '__init__.py', submodule_search_locations=[str(folder)])
        pkg = importlib.util.module_from_spec(spec)
        sys.modules[LASER] = pkg
        spec.loader.exec_module(pkg)
        return importlib.import_module(LASER + '.lines')
    finally:
        for k in [k for k in sys.modules if k == LASER or k.startswith(LASER + '.')]:
            del sys.modules[k]
        sys.modules.update(current)
        sys.modules['landmark_nav'].laser = current[LASER]


def difference(a, b) -> float:
    """Return the largest difference of two lines' values (inf if discrete parts differ)."""
    if (a.first_index, a.last_index, a.num_points) != (b.first_index, b.last_index,
                                                       b.num_points):
        return math.inf
    da = abs((a.alpha - b.alpha + math.pi) % (2.0 * math.pi) - math.pi)
    return max(abs(a.rho - b.rho), da, abs(a.rmse - b.rmse),
               float(np.max(np.abs(a.start - b.start))), float(np.max(np.abs(a.end - b.end))),
               float(np.max(np.abs(a.covariance - b.covariance))))


def main() -> None:
    """Compare the two versions on the logs and print the result."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('logs', nargs='*', default=list(LOGS), help='log names (default: all six)')
    ap.add_argument('--rev', default='HEAD', help='git revision to compare with')
    ap.add_argument('--step', type=int, default=1, help='every step-th scan')
    ap.add_argument('--tol', type=float, default=1e-9, help='largest difference allowed')
    args = ap.parse_args()
    old = load_rev(args.rev)
    failed = False
    print('| log | method | scans | lines | scans that differ | largest difference |')
    print('| --- | --- | --- | --- | --- | --- |')
    for name in args.logs:
        path = SHARED_DATA / 'carmen' / f'{name}-corrected.log.gz'
        scans = list(read_carmen_scans(path, max_range=MAX_RANGE))[::args.step]
        for method in new_lines.METHODS:
            p_new = new_lines.LineParams(method=method)
            p_old = old.LineParams(method=method)
            n_lines, n_diff, worst = 0, 0, 0.0
            for s in scans:
                r = np.asarray(s.ranges, dtype=float)
                angles = s.angle_min + s.angle_increment * np.arange(r.size)
                valid = np.isfinite(r) & (r > 0.0)
                clusters = segment_scan(r, angles, valid, float(s.angle_increment),
                                        sigma_r=p_new.sigma_r)
                a = new_lines.extract_lines(clusters, p_new)
                b = old.extract_lines(clusters, p_old)
                d = math.inf if len(a) != len(b) else max(
                    [difference(x, y) for x, y in zip(a, b)], default=0.0)
                n_lines += len(b)
                n_diff += d > args.tol
                worst = max(worst, d)
            failed |= n_diff > 0
            print(f'| {name} | {method} | {len(scans)} | {n_lines} | {n_diff} | {worst:.3g} |',
                  flush=True)
    sys.exit(1 if failed else 0)


if __name__ == '__main__':
    main()
