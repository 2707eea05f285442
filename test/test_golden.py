"""Golden results: every documented figure of a committed bag, recomputed as its page says.

``bags/<name>/expected.yaml`` holds per figure the run (the documented command) and output it
comes from, the seed-1 value and its tolerance (see its ``tolerance_policy``). Each run
executes once per module (the Python entry point the command line calls, writing the same
JSON files), and every figure is one test case; a second case per figure checks that the
number quoted in expected.yaml is the value as the documentation rounds it and that the
documentation (README.md and the pages under docs/) prints it in the one line that
``readme_line`` (a regular expression) picks out.
"""

import re

from landmark_nav.testing.golden import (figure_value, load_expected, read_outputs, ROOT,
                                         run_outputs, within_tolerance)
import pytest

BAGS = ('office', 'hallway', 'calibration', 'corridor')
EXPECTED = {name: load_expected(ROOT / 'bags' / name) for name in BAGS}
CASES = [(name, fid) for name in BAGS for fid in EXPECTED[name]['figures']]
#: The documentation pages and their lines: README.md and every page under docs/.
PAGES = {str(p.relative_to(ROOT)): p.read_text().splitlines()
         for p in [ROOT / 'README.md', *sorted((ROOT / 'docs').rglob('*.md'))]}


@pytest.fixture(scope='module')
def outputs(tmp_path_factory, office_demo, office_evaluation, hallway_bag_localization,
            hallway_sonar_map_localization):
    """Return ``get(bag, run)``: the outputs of one run, computed on first use.

    The office demo and JCBB evaluation and the hallway localizations (on the true map and on
    the sonar map) are the suite's shared runs (conftest), the same calls as the runs of
    expected.yaml.
    """
    shared = {('office', 'demo'): ('demo', lambda: office_demo[1]),
              ('office', 'evaluate_jcbb'): ('evaluate_jcbb', lambda: office_evaluation('jcbb')[1]),
              ('hallway', 'localization'): ('localization', lambda: hallway_bag_localization[1]),
              ('hallway', 'sonar_map_localization'): (
                  'localization', lambda: hallway_sonar_map_localization[1] / 'localization')}
    cache = {}

    def get(name, run):
        if (name, run) not in cache:
            if (name, run) in shared:
                files, folder = shared[name, run]
                cache[name, run] = read_outputs(files, folder())
            else:
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
                f'bags/{name}/expected.yaml and the documentation together')


_QUOTED = re.compile(r'([-\d.]+) ?(cm|mm|m|deg|%|x)?( of steps| of distance)?$')


@pytest.mark.parametrize('name,fid', CASES, ids=[f'{n}:{f}' for n, f in CASES])
def test_readme_quotes_the_value(name, fid):
    """The number in ``readme`` is the value rounded as printed, and one page prints it."""
    fig = EXPECTED[name]['figures'][fid]
    m = _QUOTED.search(fig['readme'])
    assert m, fig['readme']
    text, unit = m.group(1), m.group(2)
    digits = len(text.split('.')[1]) if '.' in text else 0
    scale = 1.0
    if unit == 'cm':
        scale = 100.0
    elif unit == 'mm' and not fid.endswith('_mm_before') and not fid.endswith('_mm_after'):
        scale = 1000.0
    elif unit == '%' and abs(fig['value']) <= 1.0:
        scale = 100.0
    assert round(fig['value'] * scale, digits) == float(text), (fid, fig['value'])
    lines = [(page, line) for page, page_lines in PAGES.items() for line in page_lines
             if re.search(fig['readme_line'], line)]
    assert len(lines) == 1, (f'readme_line {fig["readme_line"]!r} picks {len(lines)} lines of '
                             f'README.md and docs/: {[page for page, _ in lines]}')
    page, line = lines[0]
    number = re.compile(r'(?<![\w.])' + re.escape(text) + r'(?![\w])')
    assert number.search(line), f'{page} line {line!r} does not quote {text} ({fid})'
