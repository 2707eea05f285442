"""Shared node helpers without DDS traffic: warning throttling, output paths."""

from pathlib import Path
from types import SimpleNamespace

from landmark_nav import heap
from landmark_nav.heap import release_free_heap
from landmark_nav.nodes.common import output_path, problem_kind, ProblemWarner


def warner(period=5.0):
    logged = []
    node = SimpleNamespace(get_logger=lambda: SimpleNamespace(warning=logged.append))
    return ProblemWarner(node, period), logged


def test_problem_kind_keeps_the_class_of_each_number():
    zero = problem_kind('LaserScan: angle_increment=0.0 must be > 0')
    negative = problem_kind('LaserScan: angle_increment=-0.01 must be > 0')
    assert zero != negative
    assert problem_kind('stamp 12 ns older') == problem_kind('stamp 15 ns older')
    assert problem_kind('x=nan') != problem_kind('x=inf') != problem_kind('x=-inf')
    assert problem_kind('on /sonar/range_12: 1e-4') == problem_kind('on /sonar/range_12: 3.5')
    assert problem_kind('on /sonar/range_12: 1') != problem_kind('on /sonar/range_3: 1')


def test_a_different_value_class_is_never_masked_and_repeats_are_counted():
    w, logged = warner()
    w.warn('angle_increment=0.0 must be > 0')
    w.warn('angle_increment=0.0 must be > 0')   # throttled
    w.warn('angle_increment=-0.01 must be > 0')  # another class: reported at once
    w.warn('angle_increment=-0.02 must be > 0')  # same class: throttled
    assert logged == ['angle_increment=0.0 must be > 0', 'angle_increment=-0.01 must be > 0']
    assert w.count == 4
    w._last = {k: v - 10.0 for k, v in w._last.items()}  # the period has passed
    w.warn('angle_increment=0.0 must be > 0')
    assert logged[-1] == ('angle_increment=0.0 must be > 0 (1 more like this in the last '
                          '5 s)')


def test_output_path_puts_relative_names_under_ros_home(monkeypatch, tmp_path):
    monkeypatch.setenv('ROS_HOME', str(tmp_path))
    assert output_path('maps/a.yaml') == tmp_path / 'landmark_nav' / 'maps' / 'a.yaml'
    assert output_path('/abs/a.yaml') == Path('/abs/a.yaml')
    monkeypatch.delenv('ROS_HOME')
    assert output_path('a.yaml') == Path.home() / '.ros' / 'landmark_nav' / 'a.yaml'


def test_free_heap_is_released_at_most_every_period(monkeypatch):
    calls = []
    monkeypatch.setitem(heap._heap, 'trim', calls.append)
    monkeypatch.setitem(heap._heap, 'last', -heap.HEAP_RELEASE_S)
    period = heap.HEAP_RELEASE_S
    assert release_free_heap(now=0.0) and calls == [0]  # malloc_trim(0): every free page
    assert not release_free_heap(now=0.5 * period) and calls == [0]
    assert release_free_heap(now=period) and calls == [0, 0]
    monkeypatch.setitem(heap._heap, 'trim', False)  # not glibc: nothing to call
    assert not release_free_heap(now=3.0 * period)
