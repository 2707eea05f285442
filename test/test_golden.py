"""Golden results: every README figure of a committed bag, recomputed as the README says.

``bags/<name>/expected.yaml`` holds per figure the run (README command) and output it comes
from, the seed-1 value and its tolerance (see its ``tolerance_policy``). Each run executes
once per module (the Python entry point the command line calls, writing the same JSON
files), and every figure is one test case.
"""

from landmark_nav.testing.golden import (figure_value, load_expected, ROOT, run_outputs,
                                         within_tolerance)
import pytest

BAGS = ('office', 'hallway', 'calibration')
EXPECTED = {name: load_expected(ROOT / 'bags' / name) for name in BAGS}
CASES = [(name, fid) for name in BAGS for fid in EXPECTED[name]['figures']]


@pytest.fixture(scope='module')
def outputs(tmp_path_factory):
    """Return ``get(bag, run)``: the outputs of one run, computed on first use."""
    cache = {}

    def get(name, run):
        if (name, run) not in cache:
            out = tmp_path_factory.mktemp(f'{name}_{run}')
            cache[name, run] = run_outputs(run, ROOT / 'bags' / name, out)
        return cache[name, run]
    return get


def test_expected_files_describe_their_bag():
    for name, data in EXPECTED.items():
        assert data['bag'] == f'bags/{name}' and data['scenario'] == name
        assert data['figures'], name
        for run in data['runs'].values():
            assert run['command'].startswith('landmark_nav ')
        for fid, fig in data['figures'].items():
            spread = fig['seed_spread']
            assert spread['seeds'] == '1-6' and len(spread['values']) == 6, fid
            assert spread['min'] <= spread['max'], fid


@pytest.mark.parametrize('name,fid', CASES, ids=[f'{n}:{f}' for n, f in CASES])
def test_figure(outputs, name, fid):
    fig = EXPECTED[name]['figures'][fid]
    got = figure_value(outputs(name, fig['source'][0]), fig['source'])
    ok, tol = within_tolerance(got, fig)
    assert ok, (f'bags/{name} {fid} ({fig["readme"]}): got {got!r}, expected '
                f'{fig["value"]!r} +- {tol:.3g} (seeds 1-6: {fig["seed_spread"]["min"]} .. '
                f'{fig["seed_spread"]["max"]}); if the change is intended, update '
                f'bags/{name}/expected.yaml and the README together')
