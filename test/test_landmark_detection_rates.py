"""Detection rates of the landmark detector on rendered data (visual navigation §2.3, Table 2).

The sizes the issue names: 2000 error-free reads from 5 px per block up, and 500
landmark-free frames with distractors. The full statistics come from the command line
(``python -m landmark_nav.evaluation.vision``), which runs the same functions.
"""

from landmark_nav.evaluation.vision import detection_vs_size, false_detections
import pytest


@pytest.mark.slow
def test_table2_detection_from_five_block_pixels_and_2000_error_free_reads():
    rows = detection_vs_size(block_pixels=(5.0, 6.0, 8.0), frames=223, seed=11)
    reads = sum(r.detected for r in rows)
    assert reads >= 2000
    for r in rows:   # every rotation (0, 22.5, 45 deg) and size >= 5 px per block
        assert r.p_detect >= 0.95, r
    assert sum(r.wrong for r in rows) == 0                   # no read to a wrong code
    assert sum(r.correct for r in rows) >= 0.999 * reads


@pytest.mark.slow
def test_no_false_detections_in_500_landmark_free_frames():
    views = false_detections(frames=300, seed=12, source='views')
    scattered = false_detections(frames=200, seed=13, source='scattered')
    for res in (views, scattered):
        assert res.false_detections == 0, res
        # the distractors did produce landmark-like frames that the code step rejected
        assert res.frame_candidates > res.frames
        assert set(res.distractors) == {'checkerboard', 'grid', 'text', 'tiles', 'poster'}
