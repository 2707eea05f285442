"""The README is a front page: short, one table row per executable, a page for each."""

import ast
from pathlib import Path
import re

from landmark_nav.tools.docs_params import BEGIN, NODES
import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / 'README.md').read_text()
MAX_LINES = 400


def _executables():
    """Return the EXECUTABLES dict of setup.py, read without running setup()."""
    tree = ast.parse((ROOT / 'setup.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and [t.id for t in node.targets] == ['EXECUTABLES']:
            return ast.literal_eval(node.value)
    raise AssertionError('setup.py has no EXECUTABLES dict')


EXECUTABLES = _executables()


def _table_rows():
    """Return {executable: its row} of the README's table under '## Executables'."""
    section = README.split('\n## Executables\n', 1)[1].split('\n## ', 1)[0]
    rows = {}
    for line in section.splitlines():
        m = re.match(r'^\| `([a-z_]+)` \|', line)
        if m:
            rows[m.group(1)] = line
    return rows


def test_readme_is_at_most_400_lines():
    assert len(README.splitlines()) <= MAX_LINES


def test_the_executables_are_those_of_setup_py():
    assert 'ekf_slam' in EXECUTABLES and 'landmark_nav' in EXECUTABLES
    assert set(_table_rows()) == set(EXECUTABLES)


@pytest.mark.parametrize('exe', sorted(EXECUTABLES))
def test_every_executable_has_a_row_linking_an_existing_page(exe):
    row = _table_rows()[exe]
    links = re.findall(r'\]\((docs/[^)#]+\.md)\)', row)
    assert links, f'README row of {exe} links no docs page: {row}'
    page = ROOT / links[-1]
    assert page.is_file(), f'{exe}: {links[-1]} does not exist'
    text = page.read_text()
    assert f'`{exe}`' in text, f'{links[-1]} does not name {exe}'
    if exe in NODES:
        assert links[-1] == NODES[exe][2], f'{exe}: README links {links[-1]}'
        assert BEGIN.format(exe) in text, f'{links[-1]}: no parameter table of {exe}'


def test_every_relative_link_of_the_readme_and_the_pages_resolves():
    pages = [ROOT / 'README.md', *sorted((ROOT / 'docs').rglob('*.md'))]
    for page in pages:
        for target in re.findall(r'\]\(([^)#\s]+)(?:#[^)]*)?\)', page.read_text()):
            if re.match(r'[a-z]+://', target):
                continue
            assert (page.parent / target).exists(), f'{page.relative_to(ROOT)}: {target}'
