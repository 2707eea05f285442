"""Road following evaluations on the command line.

* ``landmark_nav evaluate-road-outline FOLDER``: the vision road outline on labelled street
  frames (IoU, precision, recall per frame set; overlays).
* ``landmark_nav train-road-outline --data DIR [DIR ...] --out FILE [--kind cnn]
  [--cnn-steps N]``: fit the outline's road-probability model (the perceptron, or the
  convolutional network with PyTorch installed) to labelled street frames.
* ``landmark_nav evaluate-road-laser``: tilted-laser terrain classification on the park-road
  simulator (per-reading accuracy, road width as in Table 3).
* ``landmark_nav evaluate-road-vision``: the laser-seeded vision outline on rendered park-road
  frames (road width in the robot's ground plane, failures per lighting).

Each takes the ``road_classifier`` node's parameter files (``--params-file FILE``,
repeatable, then ``--set NAME=VALUE``; :mod:`landmark_nav.tools.node_parameters`) and runs
the configuration the node would run with them (:mod:`landmark_nav.road.configuration`):
the outline's parameters for ``evaluate-road-outline``; the laser mount and the terrain
parameters for ``evaluate-road-laser``; all of them (laser and camera mounts, terrain,
fusion, outline, seed band) for ``evaluate-road-vision``. A name the node does not declare
stops the command (exit status 2) naming the nearest declared one.
"""

import argparse
import json
from pathlib import Path
from typing import Optional


def _configuration(args: argparse.Namespace, scene: Optional[dict] = None):
    """Return the ``road_classifier`` configuration of ``--params-file`` and ``--set``.

    ``scene``: values between the files and ``--set`` (the simulated roads'
    ``SIM_OUTLINE``: the chapter's criterion on rendered frames, whatever a node file says;
    ``--set`` still overrides it).
    """
    from landmark_nav.road.configuration import NODE, road_configuration
    from landmark_nav.tools.node_parameters import given_parameters
    return road_configuration({**given_parameters(args.params_file, [], NODE), **(scene or {}),
                               **given_parameters([], args.set, NODE)})


def _cmd_evaluate_road_outline(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.road_outline import (evaluate_folder, format_summary,
                                                      frame_names, summarize, write_overlays)
    params = _configuration(args).outline
    folder = Path(args.folder)
    names = frame_names(folder)
    if args.every > 1:
        names = names[args.offset::args.every]
    scores = evaluate_folder(folder, params, names=names)
    summary = summarize(scores)
    print(format_summary(summary))
    if args.json:
        Path(args.json).write_text(json.dumps(
            {'summary': summary, 'frames': [s.__dict__ for s in scores]}, indent=1))
    if args.overlays:
        ranked = sorted(scores, key=lambda s: s.iou)
        k = len(ranked) - 1
        picks = [ranked[round(k * q)].name for q in (0.0, 0.25, 0.5, 0.75, 1.0)]
        path = write_overlays(folder, picks, args.overlays, params)
        print(f'overlays (min, quartiles, max IoU): {path}')
    return 0


def add_parsers(sub, parser_class) -> None:
    """Add the road subcommands to the ``landmark_nav`` command line."""
    from landmark_nav.road.configuration import NODE
    from landmark_nav.tools.node_parameters import add_arguments
    p = sub.add_parser('evaluate-road-outline', help='score the vision road outline on a '
                       'folder of labelled street frames (images/, labels_camvid11/)')
    p.add_argument('folder', help='e.g. ../shared/data/camvid_road')
    p.add_argument('--every', type=int, default=1, help='use every N-th frame (default 1)')
    p.add_argument('--offset', type=int, default=0, help='first frame index with --every')
    p.add_argument('--json', help='write the per-frame scores and the summary here')
    p.add_argument('--overlays', help='write a montage of five overlays (min, quartiles, '
                   'max IoU) to this image file')
    add_arguments(p, NODE)
    p.set_defaults(func=_cmd_evaluate_road_outline)

    p = sub.add_parser('train-road-outline', help='fit the road-probability model of the road '
                       'outline to folders of labelled street frames (images/, '
                       'labels_camvid11/)')
    p.add_argument('--data', nargs='+', required=True, metavar='DIR',
                   help='e.g. ../shared/data/camvid_train')
    p.add_argument('--out', required=True, help='model file to write (.npz)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    p.add_argument('--kind', choices=['mlp', 'cnn'], default='mlp', help="'mlp' (default): the "
                   "perceptron of outline_method 'learned'; 'cnn': the "
                   "convolutional network of outline_method 'cnn' (needs torch)")
    p.add_argument('--cnn-steps', type=int, default=None, metavar='N',
                   help='with --kind cnn: training mini-batches (default: CNN_STEPS of '
                   'landmark_nav.evaluation.road_cross_drive, as bench_road.py --cross-drive)')
    p.add_argument('--steps', type=int, dest='cnn_steps', help=argparse.SUPPRESS)  # old name
    p.set_defaults(func=_cmd_train_road_outline)

    p = sub.add_parser('evaluate-road-laser', help='score the tilted-laser terrain '
                       'classification on simulated park roads (accuracy, road width)')
    p.add_argument('--kinds', nargs='+', default=['asphalt', 'gravel'],
                   choices=['asphalt', 'gravel'], help='road kinds (Table 3)')
    p.add_argument('--scans', type=int, default=1000, help='scans per road (default 1000)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    add_arguments(p, NODE)
    p.set_defaults(func=_cmd_evaluate_road_laser)

    p = sub.add_parser('evaluate-road-vision', help='score the vision road width on simulated '
                       'park roads (laser-seeded outline, rendered frames)')
    p.add_argument('--kinds', nargs='+', default=['asphalt', 'gravel'],
                   choices=['asphalt', 'gravel'], help='road kinds (Table 3)')
    p.add_argument('--lighting', nargs='+', default=['overcast', 'soft_shadows',
                                                     'hard_shadows'],
                   choices=['overcast', 'soft_shadows', 'hard_shadows'], help='lighting')
    p.add_argument('--frames', type=int, default=250, help='frames per case (default 250; '
                   '0: only --overlays)')
    p.add_argument('--seed', type=int, default=0, help='random seed (default 0)')
    p.add_argument('--markings', action='store_true', help='paint a dashed centre line')
    p.add_argument('--overlays', help='also write the five rendered overlays (overcast, soft '
                   'and hard shadows, gravel, markings + pedestrian) to this image file')
    add_arguments(p, NODE)
    p.set_defaults(func=_cmd_evaluate_road_vision)


def _cmd_train_road_outline(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation import road_cross_drive as rcd
    import numpy as np
    folders = [Path(d) for d in args.data]
    if args.kind == 'cnn':
        from landmark_nav.road.road_cnn_training import torch_module
        try:
            torch_module()  # before the feature maps: say at once when it is missing
        except ImportError as err:
            import sys
            print(f'error: {err}', file=sys.stderr)
            return 2
        data = rcd.feature_maps(folders, seed=args.seed)
        model = rcd.train_cnn(data, seed=args.seed, steps=args.cnn_steps or rcd.CNN_STEPS)
        unit = 'maps'
    else:
        data = rcd.sample_frames(folders, seed=args.seed)
        model = rcd.train(data, seed=args.seed)
        unit = 'pixels'
    path = model.save(args.out)
    drives = ', '.join(f'{d} {n}' for d, n in zip(*np.unique(data.drive, return_counts=True)))
    print(f'{len(data.drive)} {unit} (drive: {unit} {drives}); {len(data.skipped)} frames '
          f'skipped, their seed band not road: {" ".join(data.skipped) or "none"}')
    print(f'model: {path} ({path.stat().st_size} bytes)')
    return 0


def _cmd_evaluate_road_laser(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.road_laser import evaluate_laser_road
    config = _configuration(args)
    print(f'{"road":8s} {"true m":>6s} {"scans":>5s} {"acc %":>6s} {"min %":>6s} '
          f'{"width":>6s} {"sigma":>6s} {"N":>5s} {"fail":>4s}')
    for kind in args.kinds:
        s = evaluate_laser_road(kind, args.scans, args.seed, config.laser, config.terrain)
        print(f'{kind:8s} {s.true_width:6.2f} {s.scans:5d} {100 * s.accuracy:6.2f} '
              f'{100 * s.accuracy_min:6.2f} {s.width_mean:6.3f} {s.width_std:6.3f} '
              f'{s.widths:5d} {s.failures:4d}')
    return 0


def _cmd_evaluate_road_vision(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.road_fusion import (evaluate_vision_road, SIM_OUTLINE,
                                                     write_sim_overlays)
    config = _configuration(args, SIM_OUTLINE)
    print(f'{"road":8s} {"lighting":13s} {"true m":>6s} {"frames":>6s} {"width":>6s} '
          f'{"sigma":>6s} {"N":>5s} {"fail %":>6s} {"open %":>6s} {"reach":>5s}')
    if args.frames < 0:
        raise SystemExit(f'evaluate-road-vision: --frames must be >= 0; got {args.frames}')
    for kind in args.kinds if args.frames else ():
        for light in args.lighting:
            s = evaluate_vision_road(kind, light, args.frames, args.seed, args.markings,
                                     config)
            print(f'{kind:8s} {light:13s} {s.true_width:6.2f} {s.frames:6d} '
                  f'{s.width_mean:6.3f} {s.width_std:6.3f} {s.widths:5d} '
                  f'{100 * s.failures / s.frames:6.1f} {100 * s.routes_open / s.frames:6.1f} '
                  f'{s.reach_median:5.2f}')
    if args.overlays:
        print(f'overlays: {write_sim_overlays(args.overlays, args.seed, config=config)}')
    return 0
