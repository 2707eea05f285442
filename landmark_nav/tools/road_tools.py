"""Road following evaluations on the command line.

* ``landmark_nav evaluate-road-outline FOLDER``: the vision road outline on labelled street
  frames (IoU, precision, recall per frame set; overlays).
* ``landmark_nav evaluate-road-laser``: tilted-laser terrain classification on the park-road
  simulator (per-reading accuracy, road width as in Table 3).
"""

import argparse
import json
from pathlib import Path


def _cmd_evaluate_road_outline(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.road_outline import (evaluate_folder, format_summary,
                                                      frame_names, summarize, write_overlays)
    folder = Path(args.folder)
    names = frame_names(folder)
    if args.every > 1:
        names = names[args.offset::args.every]
    scores = evaluate_folder(folder, names=names)
    summary = summarize(scores)
    print(format_summary(summary))
    if args.json:
        Path(args.json).write_text(json.dumps(
            {'summary': summary, 'frames': [s.__dict__ for s in scores]}, indent=1))
    if args.overlays:
        ranked = sorted(scores, key=lambda s: s.iou)
        k = len(ranked) - 1
        picks = [ranked[round(k * q)].name for q in (0.0, 0.25, 0.5, 0.75, 1.0)]
        path = write_overlays(folder, picks, args.overlays)
        print(f'overlays (min, quartiles, max IoU): {path}')
    return 0


def add_parsers(sub, parser_class) -> None:
    """Add the road subcommands to the ``landmark_nav`` command line."""
    p = sub.add_parser('evaluate-road-outline', help='score the vision road outline on a '
                       'folder of labelled street frames (images/, labels_camvid11/)')
    p.add_argument('folder', help='e.g. ../shared/data/camvid_road')
    p.add_argument('--every', type=int, default=1, help='use every N-th frame (default 1)')
    p.add_argument('--offset', type=int, default=0, help='first frame index with --every')
    p.add_argument('--json', help='write the per-frame scores and the summary here')
    p.add_argument('--overlays', help='write a montage of five overlays (min, quartiles, '
                   'max IoU) to this image file')
    p.set_defaults(func=_cmd_evaluate_road_outline)

    p = sub.add_parser('evaluate-road-laser', help='score the tilted-laser terrain '
                       'classification on simulated park roads (accuracy, road width)')
    p.add_argument('--kinds', nargs='+', default=['asphalt', 'gravel'],
                   choices=['asphalt', 'gravel'], help='road kinds (Table 3)')
    p.add_argument('--scans', type=int, default=1000, help='scans per road (default 1000)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    p.set_defaults(func=_cmd_evaluate_road_laser)


def _cmd_evaluate_road_laser(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.road_laser import evaluate_laser_road
    print(f'{"road":8s} {"true m":>6s} {"scans":>5s} {"acc %":>6s} {"min %":>6s} '
          f'{"width":>6s} {"sigma":>6s} {"N":>5s} {"fail":>4s}')
    for kind in args.kinds:
        s = evaluate_laser_road(kind, args.scans, args.seed)
        print(f'{kind:8s} {s.true_width:6.2f} {s.scans:5d} {100 * s.accuracy:6.2f} '
              f'{100 * s.accuracy_min:6.2f} {s.width_mean:6.3f} {s.width_std:6.3f} '
              f'{s.widths:5d} {s.failures:4d}')
    return 0
