"""``landmark_nav evaluate-road-outline``: the vision road outline on labelled street frames."""

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
        print(f'overlays (min, quartiles, max IoU): {write_overlays(folder, picks, args.overlays)}')
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
