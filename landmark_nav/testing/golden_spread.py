"""Recompute the golden figures of a committed bag and their spread over simulator seeds.

Run from the repository root::

    python -m landmark_nav.testing.golden_spread NAME [--seeds 1-6] [--write] [--bags DIR]

NAME: office, hallway, calibration or corridor.

Reads ``bags/<name>/expected.yaml`` (``--bags DIR``: ``DIR/<name>/expected.yaml``; its runs
and figures, see :mod:`landmark_nav.testing.golden`), runs every run on the committed bag
(seed 1) twice -- the second time with the BLAS thread pools limited to one thread, to see
run-to-run floating-point variation -- and on ``landmark_nav simulate <name> --seed S``
recordings of the other seeds, then prints per figure the seed-1 value, the largest
relative difference between the two seed-1 runs and the min / max over the seeds.
``--write`` stores the seed-1 values and the seed spread back into expected.yaml (the
tolerances are left as they are).
"""

import argparse
from pathlib import Path
import sys
import tempfile
from typing import Any, Dict, List, Optional, Sequence

from landmark_nav.testing.golden import figure_value, run_outputs
from landmark_nav.tools.cli import main as cli_main
from threadpoolctl import threadpool_limits
import yaml

BAGS = Path(__file__).resolve().parents[2] / 'bags'  # the committed bags of a checkout

HEADER = """\
# Golden results of bags/{name} (`landmark_nav simulate {name} --seed 1`): the README
# figures this bag produces, asserted by test/test_golden.py. Per figure: the README text,
# the run and the output (file, key) it is read from, the seed-1 value, the tolerance (abs,
# or rel times |value|) and the spread over seeds 1-6 of the same scenario. Values and
# spread: `python -m landmark_nav.testing.golden_spread {name} --write`.
"""


def _seeds(text: str) -> List[int]:
    if '-' in text:
        lo, hi = (int(v) for v in text.split('-'))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(',')]


def _figures(data: Dict[str, Any], bag: Path, out: Path) -> Dict[str, float]:
    outputs = {run: run_outputs(run, bag, out / run) for run in data['runs']}
    return {fid: float(figure_value(outputs[fig['source'][0]], fig['source']))
            for fid, fig in data['figures'].items()}


def _round(v: float) -> float:
    return float(f'{v:.6g}')


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the seeds and print (and optionally store) the figures."""
    ap = argparse.ArgumentParser(prog='python -m landmark_nav.testing.golden_spread',
                                 description=__doc__.split('\n')[0])
    ap.add_argument('name', choices=['office', 'hallway', 'calibration', 'corridor'])
    ap.add_argument('--seeds', default='1-6', help='seeds, e.g. 1-6 or 1,3,5 (1 = the bag)')
    ap.add_argument('--write', action='store_true', help='store values and spread')
    ap.add_argument('--bags', default=str(BAGS), metavar='DIR',
                    help=f'folder of the committed bags (default {BAGS})')
    args = ap.parse_args(argv)
    bag = Path(args.bags) / args.name
    path = bag / 'expected.yaml'
    if not path.is_file():
        sys.exit(f'error: {path} not found (a bag folder with expected.yaml under --bags DIR)')
    data = yaml.safe_load(path.read_text())
    seeds = _seeds(args.seeds)
    per_seed: Dict[int, Dict[str, float]] = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for seed in seeds:
            if seed == 1:
                src = bag
            else:
                src = tmp / f'{args.name}{seed}'
                cli_main(['simulate', args.name, '--seed', str(seed), '--out', str(src)])
            per_seed[seed] = _figures(data, src, tmp / f'out{seed}')
            print(f'seed {seed} done', file=sys.stderr)
        with threadpool_limits(limits=1):
            repeat = _figures(data, bag, tmp / 'repeat')
    first = per_seed.get(1)
    print(f'{"figure":<40} {"seed 1":>14} {"rerun rel diff":>14} {"min":>11} {"max":>11}')
    worst = 0.0
    for fid, fig in data['figures'].items():
        vals = [per_seed[s][fid] for s in seeds]
        diff = float('nan')
        if first is not None:
            diff = abs(repeat[fid] - first[fid]) / max(abs(first[fid]), 1e-300)
            worst = max(worst, diff)
            if args.write:
                fig['value'] = first[fid]
        print(f'{fid:<40} {first[fid] if first else float("nan"):>14.6g} {diff:>14.2g} '
              f'{min(vals):>11.4g} {max(vals):>11.4g}')
        if args.write:
            fig['seed_spread'] = {
                'seeds': f'{seeds[0]}-{seeds[-1]}', 'min': _round(min(vals)),
                'max': _round(max(vals)), 'values': [_round(v) for v in vals]}
    print(f'largest relative difference between the two seed-1 runs: {worst:.3g}')
    if args.write:
        path.write_text(HEADER.format(name=args.name)
                        + yaml.safe_dump(data, sort_keys=False, width=99, allow_unicode=True,
                                         default_flow_style=None))
        print(f'wrote {path}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
