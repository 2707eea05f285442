"""The ``landmark_nav`` command line: simulate, record, replay, inspect and evaluate.

Every subcommand reports bad input (missing or corrupt bag, unknown scenario, bad
seed, ...) as one line on stderr and exits with status 2; no tracebacks.
"""

import argparse
import os
from pathlib import Path
import sys
from typing import List, Optional

from landmark_nav.bag import BagError

PROG = 'landmark_nav'


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit status 2).

    A description taken from a docstring is printed without its reST literal quotes.
    """

    def __init__(self, *args, **kwargs) -> None:
        if kwargs.get('description'):
            kwargs['description'] = kwargs['description'].replace('``', '')
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> None:
        """Print ``prog: error: message`` and exit with status 2."""
        self.exit(2, f'{self.prog}: error: {message}\n')


def _seed(text: str) -> int:
    """Parse a simulator seed: an integer in [0, 2**32)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'seed must be an integer, got {text!r}') from None
    if not 0 <= value < 2**32:
        raise argparse.ArgumentTypeError(f'seed must be in [0, 2**32), got {value}')
    return value


def _existing_file(text: str) -> str:
    """Parse the path of an input file that must exist (argparse names the option)."""
    if not Path(text).is_file():
        raise argparse.ArgumentTypeError(f'no such file: {text}')
    return text


def _cmd_simulate(args: argparse.Namespace) -> int:
    from landmark_nav.sim.record import record_scenario
    overrides = {}
    if args.laser_sigma_range is not None:
        overrides['laser'] = {'sigma_range': args.laser_sigma_range}
    corridor = {'distance': args.distance, 'downscale': args.image_size, 'raw': args.raw_images}
    given = [k for k, v in corridor.items() if v not in (None, False)]
    if given and args.scenario != 'corridor':
        raise ValueError(f'--{given[0].replace("_", "-")} applies to the corridor scenario '
                         f'only')
    if args.scenario == 'corridor':
        overrides.update(distance=args.distance, downscale=args.image_size)
        if args.raw_images:
            overrides['jpeg_quality'] = None
    summary = record_scenario(args.scenario, args.seed, args.out, force=args.force,
                              **overrides)
    print(summary)
    return 0


def _cmd_corridor_loop(args: argparse.Namespace) -> int:
    import math
    import rclpy
    from landmark_nav.sim.corridor_loop import LoopConfig, run_loop
    cfg = LoopConfig(start=(args.start, args.offset, math.radians(args.heading)),
                     distance=args.distance, lengths=args.lengths, follower=args.follower,
                     downscale=args.image_size or 2)
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        result = run_loop(context, cfg, seed=args.seed)
    except TimeoutError as err:
        raise ValueError(str(err)) from None
    finally:
        rclpy.try_shutdown(context=context)
    s = result.summary()
    print(f'{len(result.legs)} legs ({", ".join(f"{v:.1f}" for v in result.legs)} m), path '
          f'{s["path_m"]:.1f} m, {s["frames"]:.0f} frames; lateral after the first 2 m: max '
          f'{100 * s["max_abs_lateral_after_2m"]:.2f} cm, RMS '
          f'{100 * s["rms_lateral_after_2m"]:.2f} cm; smallest wall clearance '
          f'{100 * s["min_wall_clearance"]:.1f} cm; {s["wall_seconds"]:.0f} s')
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from landmark_nav.nodes.bag_player import options_from_args, run
    run(args.bag, options_from_args(args))
    return 0


def _cmd_info(args: argparse.Namespace) -> int:
    from landmark_nav.tools.bag_info import describe_bag
    print(describe_bag(args.bag))
    return 0


def _cmd_evaluate_features(args: argparse.Namespace) -> int:
    from landmark_nav.tools.evaluate_features import run
    print(run(args.bag, every=args.every, sigma_r=args.sigma_r, json_out=args.json,
              reference=args.reference, mount=args.mount, sensor_sigma_r=args.sensor_sigma_r,
              scans=args.scans, seed=args.seed, truth_free=args.truth_free,
              progress=sys.stderr.isatty(), params_files=args.params_file,
              settings=args.set))
    return 0


def _cmd_import(args: argparse.Namespace) -> int:
    from landmark_nav.importers import import_log
    result = import_log(args.log, args.out, fmt=args.format, poses=args.poses,
                        reference=args.reference, drift=args.drift, seed=args.seed,
                        lenient=args.lenient, force=args.force, max_scans=args.max_scans,
                        fallback_period=args.period, progress=sys.stderr.isatty(),
                        max_range=args.max_range, odom_lines=args.odom_lines,
                        fov=args.fov, range_max_from=args.range_max_from, run=args.run)
    print(result.summary)
    return 0


def _positive_int(text: str) -> int:
    """Parse an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected an integer, got {text!r}') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def _positive_float(text: str) -> float:
    """Parse a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'expected a number, got {text!r}') from None
    if not 0 < value < float('inf'):
        raise argparse.ArgumentTypeError(f'must be > 0, got {text}')
    return value


def _sigma_or_auto(text: str):
    """Parse ``auto`` or a finite number > 0."""
    return 'auto' if text == 'auto' else _positive_float(text)


def _image_size(text: str) -> int:
    """Parse a corridor camera size ``WxH``; return the downscale of 640 x 480 (1, 2, 4)."""
    sizes = {'640x480': 1, '320x240': 2, '160x120': 4}
    if text not in sizes:
        raise argparse.ArgumentTypeError(f'expected one of {", ".join(sizes)}, got {text!r}')
    return sizes[text]


def _cmd_calibrate_odometry(args: argparse.Namespace) -> int:
    from landmark_nav.tools.calibrate_odometry import calibrate_odometry
    _, report = calibrate_odometry(args.bags, write_params=args.write_params,
                                   method=args.method, iterations=args.iterations)
    print(report)
    return 0


def _slam_configuration(args: argparse.Namespace, notes=None):
    """Return the ``ekf_slam`` configuration of ``evaluate``.

    The files, then the bag's statements (``--laser-pose`` and ``--sigma-r`` for what it does
    not state), then ``--set`` and the flags; ``notes`` (a list) takes what they replaced.
    """
    from landmark_nav.evaluation.slam import bag_configuration
    from landmark_nav.tools.node_parameters import given_parameters
    files = given_parameters(args.params_file, [], 'ekf_slam')
    settings = given_parameters([], args.set, 'ekf_slam')
    flags = {'association': args.association, 'landmarks': args.landmarks,
             'scan_matching': True if args.scan_matching else None,
             'scan_matching_fit_pairs': args.scan_matching_fit_pairs,
             'scan_matching_side_starts': args.scan_matching_side_starts}
    settings.update({k: v for k, v in flags.items() if v is not None})
    return bag_configuration(args.bag, files, settings, args.sigma_r, args.laser_pose, notes)


#: ``evaluate``'s options the graph back end does not take (``ekf_slam``'s filter): dest ->
#: option.
_NOT_GRAPH = {'set': '--set', 'params_file': '--params-file', 'association': '--association',
              'landmarks': '--landmarks', 'mode': '--mode', 'map': '--map',
              'map_pose_sigma': '--map-pose-sigma', 'save_map': '--save-map', 'view': '--view',
              'scan_matching': '--scan-matching',
              'scan_matching_fit_pairs': '--scan-matching-fit-pairs',
              'scan_matching_side_starts': '--scan-matching-side-starts'}


def _refuse_graph_options(args: argparse.Namespace) -> None:
    """Refuse an option of ``evaluate`` the graph back end would ignore (one line, exit 2).

    Raises:
        ValueError: Names each option given and its values.
    """
    given = []
    for dest, option in _NOT_GRAPH.items():
        value = getattr(args, dest)
        if dest in ('set', 'params_file'):  # repeatable
            given += [f'{option} {v}' for v in value]
        elif value is True:
            given.append(option)
        elif value is not None and value is not False:
            text = ' '.join(map(str, value)) if isinstance(value, list) else value
            given.append(f'{option} {text}')
    if given:
        raise ValueError(f'--backend graph does not take {", ".join(given)} (they configure '
                         "the ekf back end's filter; the graph back end takes --out, "
                         '--max-seconds, --reference, --align, --laser-pose, --sigma-r, '
                         '--rpe-delta)')


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.slam import evaluate_bag, format_summary
    import numpy as np
    if args.backend == 'graph':
        _refuse_graph_options(args)
        from landmark_nav.evaluation.slam_graph import evaluate_graph_bag, format_graph_summary
        print(format_graph_summary(evaluate_graph_bag(
            args.bag, args.out, max_seconds=args.max_seconds, reference=args.reference,
            align=args.align, laser_pose=args.laser_pose, sigma_r=args.sigma_r,
            rpe_delta=args.rpe_delta)))
        if args.out is not None:
            print(f'written: {args.out}/slam_graph.json, trajectory_graph_{{online,final}}.tum, '
                  'trajectory_gt.tum')
        return 0
    progress = not args.no_progress and sys.stderr.isatty()
    if args.mode == 'localization' and args.map is None:
        raise ValueError('--mode localization needs --map FILE.npz (a map saved with '
                         '--save-map)')
    notes = []
    config = _slam_configuration(args, notes)
    pose_cov = None if args.map_pose_sigma is None else np.diag(
        np.square(np.asarray(args.map_pose_sigma, dtype=float)))
    result = evaluate_bag(args.bag, None, args.out, progress=progress,
                          max_seconds=args.max_seconds,
                          reference=args.reference, align=args.align,
                          laser_pose=args.laser_pose, sigma_r=args.sigma_r,
                          rpe_delta=args.rpe_delta, slam_map=args.map,
                          save_map_to=args.save_map, map_pose_covariance=pose_cov,
                          mode=args.mode, config=config, notes=notes)
    print(format_summary(result))
    if result.get('map_file'):
        print(f'map written: {result["map_file"]}')
    if args.view is not None:
        from landmark_nav.evaluation.viewer import write_slam_view
        view = write_slam_view(args.bag, args.view, result['association'],
                               max_seconds=args.max_seconds, reference=args.reference,
                               laser_pose=args.laser_pose, sigma_r=args.sigma_r,
                               config=config)
        print(f'viewer file: {view["mcap"]} (Foxglove / Lichtblick; layout '
              'viewer/slam_layout.json)')
    if args.out is not None and result['reference'] is None:
        print(f'written: {args.out}/slam.json, trajectory_{{slam,odom}}.tum, slam_map.png')
    elif args.out is not None:
        print(f'written: {args.out}/slam.json, trajectory_{{slam,odom,gt}}.tum, slam_map.png, '
              f'slam_trajectory.png, slam_errors.png')
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from landmark_nav.tools.demo import run_demo
    print(run_demo(args.bag, args.out))
    return 0


def _cmd_evaluate_corridor(args: argparse.Namespace) -> int:
    from landmark_nav.evaluation.corridor_bag import (evaluate_corridor_bag,
                                                      format_corridor_evaluation)
    from landmark_nav.tools.node_parameters import given_parameters
    files = given_parameters(args.params_file, [], 'corridor_follower')
    settings = given_parameters([], args.set, 'corridor_follower')
    print(format_corridor_evaluation(evaluate_corridor_bag(args.bag, args.out, files=files,
                                                           settings=settings)))
    return 0


def _cmd_evaluate_localization(args: argparse.Namespace) -> int:
    import math
    from landmark_nav.evaluation.localization_bags import (evaluate_localization,
                                                           format_evaluation)
    from landmark_nav.localization.configuration import localizer_configuration
    from landmark_nav.tools.node_parameters import given_parameters
    files = given_parameters(args.params_file, [], 'sonar_localizer')
    settings = given_parameters([], args.set, 'sonar_localizer')
    values = localizer_configuration({**files, **settings}).values
    std = ((args.initial_std[0], args.initial_std[1], math.radians(args.initial_std[2]))
           if args.initial_std else tuple(values[f'initial_pose.std_{n}'] for n in 'xy')
           + (values['initial_pose.std_yaw'],))
    chosen = args.filter or settings.get('filter', 'both')
    for filt in ['ekf', 'ukf'] if chosen == 'both' else [chosen]:
        result = evaluate_localization(
            args.bag, filt, map_path=args.map or values['map_file'] or None,
            seed_for_initial=args.seed, initial_std=std, out_dir=args.out,
            odometry_source=args.odometry_source or settings.get('odometry_source'),
            files=files, settings=settings)
        print(format_evaluation(result))
    return 0


def _cmd_build_sonar_map(args: argparse.Namespace) -> int:
    from landmark_nav.tools.localization_tools import build_sonar_map, format_map_summary
    print(format_map_summary(build_sonar_map(args.bag, args.poses, args.out, args.resolution)))
    return 0


def _cmd_rasterize_map(args: argparse.Namespace) -> int:
    from landmark_nav.tools.localization_tools import format_map_summary, rasterize_map
    print(format_map_summary(rasterize_map(args.source, args.out, args.resolution)))
    return 0


def _cmd_make_landmark(args: argparse.Namespace) -> int:
    from landmark_nav.tools.make_landmark import run
    print(run(args.code, args.out, kind=args.kind, frame_width=args.frame_width, dpi=args.dpi))
    return 0


def _cmd_config(args: argparse.Namespace) -> int:
    from landmark_nav.tools.config_files import config_path, listing
    if args.node is None:
        print(listing())
        return 0
    print(config_path(args.node))
    return 0


def build_parser() -> argparse.ArgumentParser:
    """Return the argument parser with every subcommand."""
    from landmark_nav.nodes.bag_player import add_replay_arguments
    from landmark_nav.tools.node_parameters import add_arguments as add_parameter_arguments

    parser = _Parser(prog=PROG, description=__doc__.split('\n')[0])
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND',
                                parser_class=_Parser)

    p = sub.add_parser('simulate', help='simulate a named scenario into a rosbag2 (MCAP) bag')
    p.add_argument('scenario',
                   help='scenario name: office, hallway, calibration, ambiguous, '
                        'landmark_views, landmark_shuttle, corridor or park_road')
    p.add_argument('--seed', type=_seed, default=1, help='random seed (default 1)')
    p.add_argument('--out', required=True, help='bag directory to create')
    p.add_argument('--force', action='store_true', help='replace an existing bag directory')
    p.add_argument('--laser-sigma-range', type=float, default=None, metavar='METRES',
                   help='laser range noise std (default 0.01 m)')
    p.add_argument('--distance', type=_positive_float, default=None, metavar='METRES',
                   help='corridor: distance driven (default 3; at most 28)')
    p.add_argument('--image-size', type=_image_size, default=None, metavar='WxH',
                   help='corridor: 640x480, 320x240 (default) or 160x120')
    p.add_argument('--raw-images', action='store_true',
                   help='corridor: raw mono8 frames on /camera/image_raw instead of JPEG on '
                        '/camera/image_raw/compressed')
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser('corridor-loop',
                       help='simulated robot and camera in the rendered corridor, driven by a '
                            'running corridor_follower (stamped_cmd_vel: true) through cmd_vel')
    p.add_argument('--seed', type=_seed, default=1, help='scene and noise seed (default 1)')
    p.add_argument('--distance', type=_positive_float, default=26.0, metavar='METRES',
                   help='length of a leg (default 26)')
    p.add_argument('--lengths', type=_positive_int, default=3,
                   help='legs back and forth (default 3)')
    p.add_argument('--start', type=float, default=2.0, metavar='METRES',
                   help='start along the 30 m corridor (default 2)')
    p.add_argument('--offset', type=float, default=0.15, metavar='METRES',
                   help='start left of the centre line (default 0.15)')
    p.add_argument('--heading', type=float, default=4.0, metavar='DEG',
                   help='start heading off the corridor axis (default 4)')
    p.add_argument('--image-size', type=_image_size, default=None, metavar='WxH',
                   help='640x480, 320x240 (default) or 160x120')
    p.add_argument('--follower', default='corridor_follower',
                   help='name of the follower node (its service <name>/enable)')
    p.set_defaults(func=_cmd_corridor_loop)

    p = sub.add_parser('replay', help='publish a bag into the ROS graph (like ros2 bag play)')
    add_replay_arguments(p)
    p.set_defaults(func=_cmd_replay)

    p = sub.add_parser('info', help='print the topics, counts and duration of a bag')
    p.add_argument('bag', help='rosbag2 directory')
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser('import', help='turn a real laser log (Carmen, CMU Wean, BreezySLAM) '
                                      'into a rosbag2 (MCAP) bag')
    p.add_argument('log', help='log file (.gz or plain): Carmen .log/.clf, Wean robotdata*.log, '
                               'BreezySLAM .dat')
    p.add_argument('--out', required=True, help='bag directory to create')
    p.add_argument('--format', choices=['carmen', 'wean', 'breezyslam'], default=None,
                   help='log format (default: guessed from the file name, else its content)')
    p.add_argument('--poses', choices=['raw', 'corrected'], default=None,
                   help='Carmen: what the pose fields hold (default corrected for files '
                        'named *corrected*, else raw)')
    p.add_argument('--reference', default=None, metavar='FILE',
                   help='Carmen: the corrected log of the same run, paired with a raw log '
                        'scan by scan (identical readings) as /ground_truth/odom')
    p.add_argument('--odom-lines', action='store_true',
                   help='Carmen corrected logs: rebuild the raw odometry from the ODOM lines '
                        '(re-anchored at each scan) instead of synthetic drift')
    p.add_argument('--drift', default=None, metavar='MODEL',
                   help='drift model of the synthetic odometry of logs without raw '
                        'odometry: pioneer (default), none, or gains such as '
                        '"k_d=0.05 k_theta=0.05 k_dtheta=0.1"')
    p.add_argument('--seed', type=_seed, default=None,
                   help='seed of the synthetic drift (default 0)')
    p.add_argument('--lenient', action='store_true',
                   help='skip and count malformed lines instead of failing')
    p.add_argument('--max-scans', type=_positive_int, default=None, metavar='N',
                   help='import only the first N scans (and the odometry up to the last)')
    p.add_argument('--max-range', type=_positive_float, default=None, metavar='METRES',
                   help='Carmen: readings at or above this are "no return" (default: the '
                        "log's ROBOTLASER1 maximum_range or PARAM robot_front_laser_max, "
                        'else 50, unless the readings overrule it: --range-max-from)')
    p.add_argument('--range-max-from', choices=['auto', 'header', 'data'], default='auto',
                   help='Carmen: where the range cap comes from (without --max-range): the '
                        "log's header (maximum_range, PARAM robot_front_laser_max, else 50 m) "
                        'unless at least 1 %% of the readings lie above it (auto, default), '
                        'the header always (header), or the readings (data)')
    p.add_argument('--fov', type=_positive_float, default=None, metavar='DEG',
                   help='Carmen: field of view of FLASER / RLASER lines, beams spread evenly '
                        'from -DEG/2 to +DEG/2 (needed for counts other than 180, 181, 360, '
                        '361)')
    p.add_argument('--period', type=_positive_float, default=1.0, metavar='SECONDS',
                   help='scan period assumed when a log has no two distinct stamps '
                        '(default 1.0)')
    p.add_argument('--run', type=_positive_int, default=None, metavar='K',
                   help='import only run K (1, 2, ...) of a log that holds several (the '
                        'clock restarts where the robot is elsewhere; the summary lists them; '
                        'default: all, joined)')
    p.add_argument('--force', action='store_true', help='replace an existing bag directory')
    p.set_defaults(func=_cmd_import)

    p = sub.add_parser('evaluate-features',
                       help='score corner and line extractors on a bag: against the ground '
                            'truth of a simulator bag, else with truth-free metrics (PLE ray '
                            'metric, false-surface beams, fit, repeatability)',
                       epilog="Each method runs with its node's configuration (corner_extractor "
                       'or line_extractor; the parameter method is set per row): the '
                       'defaults, then the --params-file files, then what the bag states (a '
                       "simulator bag's laser noise; on other bags the range noise estimated "
                       'from the scans unless --set gives sigma_r), then --set, then '
                       '--sigma-r. max_beams has no effect here.')
    p.add_argument('bag', help='rosbag2 directory with /scan (simulator or imported)')
    p.add_argument('--every', type=int, default=1, help='use every n-th scan')
    p.add_argument('--sigma-r', type=_sigma_or_auto, default=None, metavar='METRES|auto',
                   help='range noise the extractors assume [m], or auto: estimated from the '
                        "bag's scans (local line fits, at least the range step / sqrt(12) and "
                        "the sensor's stated noise; the false-surface margin follows it) "
                        '(default: the simulated one on a simulator bag, else auto)')
    p.add_argument('--truth-free', action='store_true',
                   help='truth-free metrics even on a simulator bag')
    p.add_argument('--reference', default=None, metavar='FILE.tum', type=_existing_file,
                   help='truth-free: reference poses (base_link in map, TUM) for '
                        'repeatability (default: /ground_truth/odom of the bag)')
    p.add_argument('--mount', type=float, nargs=3, default=None, metavar=('X', 'Y', 'YAW'),
                   help='truth-free: laser mount base_link -> laser [m m rad] when the bag '
                        'states none (default 0 0 0)')
    p.add_argument('--sensor-sigma-r', type=float, default=None,
                   help='truth-free: the sensor range noise [m] for the false-surface margin '
                        'max(3 sigma_r, 5 cm) when the bag states none (default 0.01)')
    p.add_argument('--scans', type=int, default=20,
                   help='truth-free: scans drawn for f / ray RMSE / fit (default 20)')
    p.add_argument('--seed', type=int, default=0,
                   help='truth-free: seed of numpy.random.default_rng for the draw (default 0)')
    p.add_argument('--json', default=None, help='also write the figures to this JSON file')
    p.add_argument('--params-file', action='append', default=[], metavar='FILE',
                   help='corner_extractor and line_extractor parameter file (ROS 2 YAML, as '
                        "ros2 run --params-file: /** and each node's section; repeatable, a "
                        'later file wins; e.g. "$(landmark_nav config line_extractor)")')
    p.add_argument('--set', action='append', default=[], metavar='NODE.NAME=VALUE',
                   help='one parameter, after the files: corner_extractor.NAME=VALUE, '
                        'line_extractor.NAME=VALUE, or NAME=VALUE for each node declaring it '
                        '(the value as YAML, as -p NAME:=VALUE; repeatable)')
    p.set_defaults(func=_cmd_evaluate_features)

    p = sub.add_parser('calibrate-odometry',
                       help='estimate the odometry factors k1, k2, k3 from calibration runs')
    p.add_argument('bags', nargs='+', help='bag(s) recorded by `simulate calibration`')
    p.add_argument('--write-params', default=None, metavar='FILE',
                   help='write k1, k2, k3 into this ROS 2 parameter file under '
                        'base_driver.ros__parameters (e.g. config/base_driver.yaml); '
                        'other keys are kept')
    p.add_argument('--method', choices=('chapter', 'joint'), default='chapter',
                   help='chapter: Algorithm 1 per data set, averaged (default); '
                        'joint: one weighted least-squares fit over all runs')
    p.add_argument('--iterations', type=int, default=2,
                   help='Algorithm 1 iterations (default 2, as in the chapter)')
    p.set_defaults(func=_cmd_calibrate_odometry)

    p = sub.add_parser('evaluate', help='run EKF-SLAM on a bag and score it against a reference '
                       '(without one: map, path and filter figures only)',
                       epilog="The filter runs ekf_slam's configuration: its defaults, then "
                       'the --params-file files, then what the bag states (laser mount and '
                       'noise, odometry noise model), then --set and the options above, as '
                       '`landmark_nav pipeline replay` gives them to the node; the corner '
                       'extractor and lines.sigma_r take the resulting laser_sigma_range '
                       'unless --set lines.sigma_r. The filter '
                       'of the corner chapter: --params-file "$(landmark_nav config '
                       'ekf_slam_chapter)".')
    p.add_argument('bag', help='rosbag2 directory with /scan, /odom and optionally a reference '
                   '(/ground_truth/odom or --reference)')
    p.add_argument('--association', choices=['icnn', 'jcbb'], default=None,
                   help='data association (the parameter association; default icnn)')
    p.add_argument('--backend', choices=['ekf', 'graph'], default='ekf',
                   help="ekf (default): the ekf_slam node's filter; graph: the keyframe pose "
                        'graph with loop closure (iSAM2; docs/graph_slam.md; '
                        'takes --out, --max-seconds, --reference, --align, --laser-pose, '
                        '--sigma-r, --rpe-delta, --no-progress only and refuses the others, '
                        '--set included)')
    p.add_argument('--out', default=None,
                   help='directory for the TUM trajectories, slam.json and the PNGs')
    p.add_argument('--reference', default=None, metavar='FILE.tum', type=_existing_file,
                   help='reference trajectory (TUM file) instead of /ground_truth/odom')
    p.add_argument('--align', choices=['none', 'se2', 'se3', 'sim3'], default='se2',
                   help='alignment of the aligned ATE (default se2; the unaligned ATE is '
                        'always printed)')
    p.add_argument('--laser-pose', type=float, nargs=3, default=None,
                   metavar=('X', 'Y', 'YAW'),
                   help='laser mount in base_link [m m rad] when the bag does not state it '
                        '(default 0 0 0; --set laser_pose=[X,Y,YAW] wins over the bag)')
    p.add_argument('--sigma-r', type=float, default=None,
                   help='laser range noise [m] when the bag does not state it (--set '
                   'laser_sigma_range=... wins over the bag)')
    p.add_argument('--rpe-delta', type=float, default=1.0,
                   help='RPE distance along the reference [m] (default 1)')
    p.add_argument('--max-seconds', type=float, default=None,
                   help='use only the first seconds of the bag')
    p.add_argument('--view', default=None, metavar='DIR',
                   help='also write the inputs and outputs as one MCAP for Foxglove / '
                        'Lichtblick into the new bag directory DIR')
    p.add_argument('--no-progress', action='store_true', help='no progress bar')
    p.add_argument('--landmarks', choices=['corners', 'lines', 'both'], default=None,
                   help='landmarks the filter maps (the parameter landmarks; default both)')
    p.add_argument('--mode', choices=['slam', 'localization'], default=None,
                   help='slam (default) or localization on --map (no new landmarks)')
    p.add_argument('--map', default=None, metavar='FILE.npz',
                   help='start on this saved map (the first odometry pose is its start pose)')
    p.add_argument('--map-pose-sigma', type=float, nargs=3, default=None,
                   metavar=('SX', 'SY', 'SYAW'),
                   help='1-sigma of that start pose [m m rad] (default 0 0 0)')
    p.add_argument('--save-map', default=None, metavar='FILE.npz',
                   help='write the final map (landmark_nav.slam.slam_map format)')
    p.add_argument('--scan-matching', action='store_true',
                   help="predict with the scans' point-to-line ICP motion where it agrees "
                        'with the odometry (the parameter scan_matching; on by default: this '
                        'turns it back on over a file that turns it off, such as '
                        'ekf_slam_chapter; --set scan_matching=false turns it off)')
    p.add_argument('--scan-matching-fit-pairs', type=float, default=None, metavar='P',
                   help='the parameter scan_matching_fit_pairs (default 0.3)')
    p.add_argument('--scan-matching-side-starts', type=float, default=None, metavar='K',
                   help='the parameter scan_matching_side_starts (default 2.5)')
    add_parameter_arguments(p, 'ekf_slam')
    p.set_defaults(func=_cmd_evaluate)

    p = sub.add_parser('demo', help='odometry drift and EKF-SLAM (chapter profile) on a '
                       'simulator bag against its ground truth: figures, plots and a viewer '
                       'file into out/')
    p.add_argument('--bag', default='bags/office', help='bag to evaluate (default bags/office)')
    p.add_argument('--out', default='out', help='output directory (default out)')
    p.set_defaults(func=_cmd_demo)

    p = sub.add_parser('evaluate-corridor',
                       help="run the corridor follower offline on a corridor bag (the node's "
                            'estimation loop) against its ground truth; writes corridor.json',
                       epilog="The loop runs corridor_follower's configuration: its defaults, "
                       'then the --params-file files, then what the bag states (corridor '
                       'width and height, centre line, camera mount), then --set. The '
                       'controller and interface parameters have no effect here.')
    p.add_argument('bag', help='rosbag2 directory recorded by `simulate corridor` (e.g. '
                               'bags/corridor)')
    p.add_argument('--out', default='out/corridor', help='output directory')
    add_parameter_arguments(p, 'corridor_follower')
    p.set_defaults(func=_cmd_evaluate_corridor)

    p = sub.add_parser('evaluate-localization',
                       help='run the sonar EKF / UKF offline on a simulator bag against its '
                            'ground truth; writes JSON + PNGs',
                       epilog="The filter runs sonar_localizer's configuration: its defaults, "
                       'then the --params-file files, then what the bag and the map state '
                       '(the odometry source, wheel radius, axle length and k1..k3 of the '
                       'bag; unknown: free on a map file with unknown cells), then --set, '
                       'then the options above. Every filter is evaluated unless --set '
                       'filter or --filter chooses one. The initial pose is drawn around the '
                       "ground truth; the sonar topics and mounts are the bag's; the frames, "
                       'sync_timeout, stale_cycles and sonar_timeout have no effect here.')
    p.add_argument('bag', help='rosbag2 directory recorded by `simulate` (e.g. bags/hallway)')
    p.add_argument('--filter', choices=['ekf', 'ukf', 'both'], default=None,
                   help='filter to evaluate (default both, or --set filter=...)')
    p.add_argument('--map', default=None, metavar='YAML',
                   help='map_server YAML (default: the world of ground_truth.yaml rasterised '
                        'at 0.1 m)')
    p.add_argument('--seed', type=_seed, default=None,
                   help='seed of the initial estimate (default 1000 + the bag seed)')
    p.add_argument('--initial-std', type=float, nargs=3, default=None,
                   metavar=('X_M', 'Y_M', 'YAW_DEG'),
                   help='std of the initial estimate and covariance (default the '
                        'parameters initial_pose.std_*: 0.055 0.055 5)')
    p.add_argument('--odometry-source', choices=['joint_states', 'odom'], default=None,
                   help='motion input (default joint_states if recorded)')
    p.add_argument('--out', default='out/localization', help='output directory')
    add_parameter_arguments(p, 'sonar_localizer')
    p.set_defaults(func=_cmd_evaluate_localization)

    p = sub.add_parser('build-sonar-map',
                       help='occupancy grid from the sonar readings of a bag at known poses')
    p.add_argument('bag', help='rosbag2 directory with /sonar/range_0..15')
    p.add_argument('--poses', default='/ground_truth/odom',
                   help='nav_msgs/Odometry topic with the poses (default /ground_truth/odom)')
    p.add_argument('--out', default='map.yaml', help='map YAML to write (PGM beside it)')
    p.add_argument('--resolution', type=float, default=0.1, help='cell size [m] (default 0.1)')
    p.set_defaults(func=_cmd_build_sonar_map)

    p = sub.add_parser('rasterize-map',
                       help="rasterise the simulator's world (bag or scenario) into a map file")
    p.add_argument('source', help='bag directory with ground_truth.yaml, or a scenario name')
    p.add_argument('--out', required=True, help='map YAML to write (PGM beside it)')
    p.add_argument('--resolution', type=float, default=0.1, help='cell size [m] (default 0.1)')
    p.set_defaults(func=_cmd_rasterize_map)

    from landmark_nav.tools.make_landmark import add_arguments as add_landmark_arguments
    p = sub.add_parser('make-landmark',
                       help='write a printable visual landmark (PNG, SVG or PDF) at true scale')
    add_landmark_arguments(p)
    p.set_defaults(func=_cmd_make_landmark)

    p = sub.add_parser('config', help="print the path of a node's shipped parameter file "
                       'or profile (for --params-file; no NAME: list the files and profiles)')
    p.add_argument('node', nargs='?', default=None, metavar='NAME',
                   help='node or profile name, e.g. ekf_slam or ekf_slam_chapter')
    p.set_defaults(func=_cmd_config)

    from landmark_nav.tools.pipeline import add_parser as add_pipeline_parser
    add_pipeline_parser(sub, _Parser)

    from landmark_nav.tools.emulate import add_parsers as add_emulate_parsers
    add_emulate_parsers(sub, _Parser)

    from landmark_nav.tools.drive import add_parser as add_drive_parser
    add_drive_parser(sub, _Parser)

    from landmark_nav.tools.road_tools import add_parsers as add_road_parsers
    add_road_parsers(sub, _Parser)

    from landmark_nav.tools.docs_params import add_parser as add_docs_params_parser
    add_docs_params_parser(sub, _Parser)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    """Run the command line; return the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except KeyboardInterrupt:
        return 130
    except (BagError, ValueError, OSError) as err:
        print(f'{PROG}: error: {err}', file=sys.stderr)
        return 2
    except Exception as err:  # last resort: still one line, with a way to get the trace
        if os.environ.get('LANDMARK_NAV_DEBUG'):
            raise
        print(f'{PROG}: internal error: {type(err).__name__}: {err} '
              '(set LANDMARK_NAV_DEBUG=1 for a traceback)', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
