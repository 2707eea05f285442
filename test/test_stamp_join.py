"""StampJoin: the parts of a feature set paired by stamp; lost parts given up."""

from landmark_nav.nodes.stamp_join import StampJoin
import pytest


def test_pairs_by_stamp_in_either_order():
    j = StampJoin(('corners', 'scan'))
    assert j.add('scan', 10, 's10') == []
    assert j.add('corners', 10, 'c10') == [(10, {'scan': 's10', 'corners': 'c10'}, ())]
    assert j.add('corners', 20, 'c20') == []
    assert j.add('scan', 20, 's20') == [(20, {'corners': 'c20', 'scan': 's20'}, ())]
    assert len(j) == 0


def test_a_later_message_of_a_part_gives_up_the_waiting_ones():
    """One publisher delivers in order: a later scan means the earlier one was lost."""
    j = StampJoin(('corners', 'scan'))
    j.add('corners', 10, 'c10')
    j.add('scan', 5, 's5')  # older: the corners of 5 may still come
    assert len(j) == 2
    out = j.add('scan', 20, 's20')  # scan 10 lost; scan 5 still waits for corners
    assert out == [(10, {'corners': 'c10'}, ('scan',))]
    out = j.add('corners', 20, 'c20')  # corners 5 lost; 20 complete; stamp order
    assert out == [(5, {'scan': 's5'}, ('corners',)),
                   (20, {'scan': 's20', 'corners': 'c20'}, ())]


def test_a_part_without_publisher_is_not_waited_for():
    j = StampJoin(('corners', 'scan'))
    alive = {'corners': True, 'scan': False}
    assert j.add('corners', 10, 'c', alive.get) == [(10, {'corners': 'c'}, ('scan',))]


def test_the_oldest_goes_on_when_too_many_wait():
    j = StampJoin(('corners', 'scan'), max_waiting=2)
    assert j.add('corners', 30, 'c30') == [] and j.add('scan', 10, 's10') == []
    assert j.add('scan', 5, 's5') == [(5, {'scan': 's5'}, ('corners',))]
    with pytest.raises(ValueError, match='unknown part'):
        j.add('lines', 1, None)
