"""Landmarks vs AprilTag 3 and OpenCV ArUco composited into real photographs.

Run from the repository root (needs the test extra ``pupil-apriltags``, see
requirements-test.txt, and the York Urban photographs in ``../shared/data``)::

    python benchmarks/bench_landmarks_real.py [detection|pose|all] [--per-size N] ...

The same trials (background, pose, print, blur, gain/gamma, noise, JPEG 70) are rendered
once per marker type and run through the landmark detector, AprilTag tag36h11 at decimate
1 and 2 and ArUco DICT_6X6_250 with sub-pixel corners, single-threaded, in one run; it
prints detection against px per module and tilt, wrong codes, false detections, pose
errors at 1 m and 2.2 m and the time per frame with its ratios. The method and every
option are those of :mod:`landmark_nav.evaluation.landmarks_real` (this script is its
command line with the benchmark's defaults: 100 trials per size, 150 per distance, seed 1).
"""

from pathlib import Path
import sys

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from landmark_nav.evaluation.landmarks_real import main  # noqa: E402

if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
