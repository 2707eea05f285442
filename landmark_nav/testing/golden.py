"""Golden results: the documented figures each committed bag produces, and how to recompute them.

Each ``bags/<name>/expected.yaml`` lists *runs* (a documented command and the Python
entry point the command line calls for it) and *figures* (a documented figure, the run and the
output file / key it is read from, the seed-1 value, its tolerance and the spread over
simulator seeds 1-6). :func:`run_outputs` executes one run and returns its outputs as
plain dicts (the JSON files the tools write, or the parsed report), :func:`figure_value`
picks one figure out of them and :func:`within_tolerance` applies the tolerance.

``test/test_golden.py`` asserts every figure on the committed bag;
``python -m landmark_nav.testing.golden_spread`` recomputes the values and the seed spread.
"""

import json
import math
from pathlib import Path
import re
from typing import Any, Callable, Dict, Tuple

import yaml

#: Repository root (``bags/`` lives here).
ROOT = Path(__file__).resolve().parents[2]

Outputs = Dict[str, Any]


#: The JSON files the outputs of these runs are read from, so that a run already computed
#: elsewhere (the test suite computes the office demo and JCBB evaluation once per run)
#: gives its outputs with :func:`read_outputs`.
RUN_FILES = {'demo': ('slam.json', 'drift.json'), 'evaluate_jcbb': ('slam.json',),
             'localization': ('localization_ekf.json', 'localization_ukf.json')}


def read_outputs(run: str, out: Any) -> Outputs:
    """Return the outputs of a run of :data:`RUN_FILES` already written into ``out``."""
    return {name: json.loads((Path(out) / name).read_text()) for name in RUN_FILES[run]}


def _demo(bag: Path, out: Path) -> Outputs:
    from landmark_nav.tools.demo import run_demo
    run_demo(bag, out)
    return read_outputs('demo', out)


def _evaluate_jcbb(bag: Path, out: Path) -> Outputs:
    from landmark_nav.evaluation.slam import evaluate_bag
    from landmark_nav.tools.demo import chapter_config
    evaluate_bag(bag, 'jcbb', out, progress=False, config=chapter_config(bag))
    return read_outputs('evaluate_jcbb', out)


def _features(every: int) -> Callable[[Path, Path], Outputs]:
    def run(bag: Path, out: Path) -> Outputs:
        from landmark_nav.evaluation.feature_bags import evaluate_bag_features
        out.mkdir(parents=True, exist_ok=True)
        evaluate_bag_features(bag, every=every, json_out=out / 'features.json')
        return {'features.json': json.loads((out / 'features.json').read_text())}
    return run


def _localization(bag: Path, out: Path, map_path: Any = None) -> Outputs:
    from landmark_nav.evaluation.localization_bags import evaluate_localization
    for filt in ('ekf', 'ukf'):
        evaluate_localization(bag, filt, map_path=map_path, out_dir=out)
    return read_outputs('localization', out)


def _sonar_map_localization(bag: Path, out: Path) -> Outputs:
    from landmark_nav.tools.localization_tools import build_sonar_map
    out.mkdir(parents=True, exist_ok=True)
    build_sonar_map(bag, out=out / 'map.yaml')
    return _localization(bag, out / 'localization', map_path=out / 'map.yaml')


_MEAN = re.compile(r'^\s*mean\s+([\d.]+) -> ([\d.]+)\s+([\d.]+) -> ([\d.]+)\s*$', re.M)
_REDUCTION = re.compile(r'reduction: heading x([\d.]+), position x([\d.]+)')


def parse_calibration_report(report: str) -> Dict[str, float]:
    """Return the validation means of a ``calibrate-odometry`` report (as printed).

    Raises:
        ValueError: The report has no validation summary.
    """
    mean, red = _MEAN.search(report), _REDUCTION.search(report)
    if mean is None or red is None:
        raise ValueError('calibration report without a validation summary:\n' + report)
    p0, p1, h0, h1 = (float(v) for v in mean.groups())
    return {'position_mm_before': p0, 'position_mm_after': p1, 'heading_deg_before': h0,
            'heading_deg_after': h1, 'heading_reduction': float(red.group(1)),
            'position_reduction': float(red.group(2))}


def _calibrate(bag: Path, out: Path) -> Outputs:
    from landmark_nav.tools.calibrate_odometry import calibrate_odometry
    factors, report = calibrate_odometry(bag)
    return {'factors': dict(factors), 'report': parse_calibration_report(report)}


def _evaluate_corridor(bag: Path, out: Path) -> Outputs:
    from landmark_nav.evaluation.corridor_bag import evaluate_corridor_bag
    evaluate_corridor_bag(bag, out)
    return {'corridor.json': json.loads((out / 'corridor.json').read_text())}


#: Run name (as used in expected.yaml) -> ``f(bag, out_dir) -> outputs``.
RUNS: Dict[str, Callable[[Path, Path], Outputs]] = {
    'demo': _demo,
    'evaluate_jcbb': _evaluate_jcbb,
    'features': _features(1),
    'lines': _features(4),
    'localization': _localization,
    'sonar_map_localization': _sonar_map_localization,
    'calibrate': _calibrate,
    'evaluate_corridor': _evaluate_corridor,
}


def expected_path(bag: Any) -> Path:
    """Return ``<bag>/expected.yaml``."""
    return Path(bag) / 'expected.yaml'


def load_expected(bag: Any) -> Dict[str, Any]:
    """Read and check ``<bag>/expected.yaml``.

    Raises:
        ValueError: A figure names an unknown run or lacks value, readme_line or tolerance.
    """
    path = expected_path(bag)
    data = yaml.safe_load(path.read_text())
    for name in data.get('runs', {}):
        if name not in RUNS:
            raise ValueError(f'{path}: unknown run {name!r} (known: {", ".join(RUNS)})')
    for fid, fig in data.get('figures', {}).items():
        run = fig.get('source', [None])[0]
        if run not in data.get('runs', {}):
            raise ValueError(f'{path}: figure {fid} reads run {run!r}, not listed in runs')
        if 'value' not in fig or 'readme_line' not in fig or not ({'rel', 'abs'} & set(fig)):
            raise ValueError(f'{path}: figure {fid} needs value, readme_line and rel or abs')
    return data


def run_outputs(run: str, bag: Any, out: Any) -> Outputs:
    """Execute one run of expected.yaml on ``bag`` writing into ``out``; return its outputs."""
    return RUNS[run](Path(bag), Path(out))


def figure_value(outputs: Outputs, source) -> Any:
    """Pick ``source = [run, file, 'dotted.key']`` out of the outputs of its run."""
    _, name, key = source
    value = outputs[name]
    for part in str(key).split('.'):
        value = value[part]
    return value


def tolerance(figure: Dict[str, Any]) -> float:
    """Return the allowed absolute deviation of a figure: ``max(abs, rel * |value|)``."""
    return max(float(figure.get('abs', 0.0)),
               float(figure.get('rel', 0.0)) * abs(float(figure['value'])))


def within_tolerance(got: Any, figure: Dict[str, Any]) -> Tuple[bool, float]:
    """Return (``got`` within the tolerance of ``figure['value']``, allowed deviation)."""
    tol = tolerance(figure)
    if got is None or not math.isfinite(float(got)):
        return False, tol
    return abs(float(got) - float(figure['value'])) <= tol, tol
