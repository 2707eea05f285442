"""The parameter tables of the docs pages against the nodes' own declarations.

Every parameter a node declares must appear in its page's marked table with the declared
default, and the table must hold nothing else; a failure names the rows to regenerate
(``landmark_nav docs-params --write``).
"""

from landmark_nav.tools import docs_params
from landmark_nav.tools.docs_params import (block, declared_parameters, DeclaredParameter,
                                            format_value, marked_block, NODES, ROOT,
                                            table_defaults, write_pages)
import pytest


@pytest.fixture(scope='module')
def declared():
    return declared_parameters()


def _page_block(node):
    page = ROOT / NODES[node][2]
    assert page.is_file(), f'{node}: no page {NODES[node][2]}'
    found = marked_block(page.read_text(), node)
    assert found is not None, f'{NODES[node][2]}: no parameter markers for {node}'
    return found


@pytest.mark.parametrize('node', list(NODES))
def test_every_declared_parameter_is_in_its_page_with_its_default(declared, node):
    printed = table_defaults(_page_block(node))
    rows = declared[node]
    assert rows, f'{node} declares no parameters'
    wrong = [f'{p.name}: page {printed[p.name]!r}, declared {p.default!r}' for p in rows
             if p.name in printed and printed[p.name] != p.default]
    missing = [p.name for p in rows if p.name not in printed]
    extra = sorted(set(printed) - {p.name for p in rows})
    assert not (wrong or missing or extra), (
        f'{NODES[node][2]} ({node}): regenerate with `landmark_nav docs-params --write`; '
        f'default differs: {wrong}; missing: {missing}; not declared: {extra}')


@pytest.mark.parametrize('node', list(NODES))
def test_the_page_table_is_the_generated_one(declared, node):
    """Types, ranges and descriptions too: the block is exactly what the tool writes."""
    assert _page_block(node) == block(node, declared[node]), (
        f'{NODES[node][2]} ({node}): regenerate with `landmark_nav docs-params --write`')


def test_declared_defaults_are_the_values_in_the_code(declared):
    """Spot checks against the declarations themselves (not against the tool's own output)."""
    from landmark_nav.laser.corners import CornerParams
    from landmark_nav.parameter_tables import READ_ONLY_NOTE
    corner = {p.name: p for p in declared['corner_extractor']}
    assert corner['method'].default == CornerParams().method == 'minus_cosine'
    assert corner['window'].default == str(CornerParams().window)
    assert corner['window'].type_name == 'int' and corner['window'].limits == '5 … 101'
    assert corner['segmentation.min_points'].default == '5'
    assert not any(p.description.endswith(READ_ONLY_NOTE) for p in declared['ekf_slam'])
    laser = {p.name: p for p in declared['laser_driver']}
    # The declared default, not the port the tool starts the driver on.
    assert laser['port'].default != '/nonexistent/landmark_nav_docs'
    assert laser['protocol'].limits == 'scip2, lms2xx'
    names = [p.name for p in declared['ekf_slam']]
    assert len(names) == len(set(names)) and 'use_sim_time' not in names


def test_a_changed_default_is_reported_by_row(tmp_path, declared, monkeypatch):
    """What the test above prints after a default changes: the row, both values."""
    node = 'corner_extractor'
    page = tmp_path / NODES[node][2]
    page.parent.mkdir(parents=True)
    page.write_text(f'# page\n\n{block(node, declared[node])}\n\ntext after\n')
    rows = [DeclaredParameter(p.name, p.type_name, '13' if p.name == 'window' else p.default,
                              p.limits, p.description) for p in declared[node]]
    printed = table_defaults(marked_block(page.read_text(), node))
    assert printed['window'] == '11' and {p.name for p in rows} == set(printed)
    assert write_pages({node: rows}, root=tmp_path) == [NODES[node][2]]
    text = page.read_text()
    assert table_defaults(marked_block(text, node))['window'] == '13'
    assert text.startswith('# page\n\n') and text.endswith('\n\ntext after\n')
    assert write_pages({node: rows}, root=tmp_path) == []
    monkeypatch.setattr(docs_params, 'NODES', {node: NODES[node]})
    page.write_text('# no markers\n')
    with pytest.raises(ValueError, match='no <!-- BEGIN PARAMETERS corner_extractor -->'):
        write_pages({node: rows}, root=tmp_path)


def test_values_are_formatted_as_a_parameter_file_writes_them():
    assert format_value(True) == 'true' and format_value(False) == 'false'
    assert format_value('') == "''" and format_value('map') == 'map'
    assert format_value([0.0, 1.5]) == '[0.0, 1.5]' and format_value(3) == '3'
    assert format_value(0.01) == '0.01' and format_value(float('inf')) == '.inf'
    assert format_value(-float('inf')) == '-.inf' and format_value(float('nan')) == '.nan'


@pytest.mark.parametrize('argv, asked', [
    (['corner_extractor', '--help'], True),
    (['corner_extractor', '-h'], True),
    (['corner_extractor', '-h', '--ros-args', '-p', 'window:=5'], True),
    (['corner_extractor'], False),
    (['corner_extractor', '--ros-args', '-r', '__node:=h', '-p', 'h:=1'], False),
])
def test_help_flag_before_ros_args_only(argv, asked):
    from landmark_nav.nodes.common import help_requested
    assert help_requested(argv) is asked


def test_node_help_prints_every_parameter_and_starts_nothing(declared, capfd, monkeypatch):
    from landmark_nav.nodes import common
    from landmark_nav.nodes.laser_driver import LaserDriver

    def no_start(*args, **kwargs):
        raise AssertionError('--help started the node')

    monkeypatch.setattr(common.rclpy, 'spin', no_start)
    assert common.run_node(LaserDriver, ['laser_driver', '--help']) == 0
    out, err = capfd.readouterr()
    assert out.startswith('usage: laser_driver [--ros-args ')
    for p in declared['laser_driver']:
        assert f'  {p.name} ({p.type_name}, default {p.default}' in out, p.name
    assert 'landmark_nav config laser_driver' in out and 'docs/drivers.md' in out
    # the port that does not exist (never the default device) is not reported as an error
    assert err == ''
