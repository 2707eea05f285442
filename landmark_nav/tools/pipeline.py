"""``landmark_nav pipeline NAME``: start a whole pipeline of nodes with one command.

Each node runs as its own process with its shipped parameter file
(:func:`~landmark_nav.tools.config_files.config_path`), the shipped profiles given with
``--profile NAME`` (e.g. ``ekf_slam_chapter``) and the overrides given with
``--set NODE.PARAMETER=VALUE``; honcho (a Python port of Foreman) starts them, prefixes
every output line with the node's name and, on Ctrl-C or SIGTERM, stops them all with
SIGTERM (every node shuts down cleanly on it). When one process ends, the others are
stopped too (so a replay pipeline ends with its bag, unless ``--loop``; when the player
ended by itself, first it waits up to ``--drain-timeout`` seconds until the nodes have
processed every scan, :mod:`~landmark_nav.tools.pipeline_drain`). Stopped by a
signal, the command exits 0 if every node did (honcho alone would give 130 / 143), else
with the first node's non-zero status.

Pipelines:

* ``slam``: live robot SLAM, laser_driver + base_driver + corner_extractor + ekf_slam;
* ``sonar``: sonar localization, base_driver + sonar_localizer (give it a map:
  ``--set sonar_localizer.map_file=/path/map.yaml``, or publish one on ``/map``);
* ``landmarks``: landmark navigation, base_driver + landmark_detector (the camera driver is
  the user's; ``--set landmark_detector.landmark_map=/path/landmarks.yaml`` for robot fixes);
* ``replay``: a bag's ``/scan`` and ``/odom`` through the SLAM nodes, bag_player +
  corner_extractor + ekf_slam (the player waits up to 30 s until both topics are
  subscribed by every node that takes them, so no scan is lost to the nodes' start-up).
  Each node gets what the bag states, as ``landmark_nav evaluate`` uses it
  (:func:`stated_parameters`): ``ekf_slam`` the laser mount, its noise and the odometry noise
  model, ``corner_extractor`` the laser's noise (``sigma_r`` is ``ekf_slam``'s
  ``laser_sigma_range``: the bag's, or ``--set ekf_slam.laser_sigma_range``); a node's own
  ``--set`` wins. It ends with one result line (:mod:`~landmark_nav.tools.replay_result`): the bag,
  its scans and the seconds it took, the poses ekf_slam published and their ATE against
  the bag's ``/ground_truth/odom`` when it has one, the output topics.
"""

import argparse
import shlex
import sys
from typing import Any, Dict, List, Optional, Sequence

from landmark_nav.parameter_names import unknown_parameter
from landmark_nav.tools.config_files import config_path

#: Seconds a replay waits for its nodes after the player ended (``--drain-timeout``).
DRAIN_TIMEOUT_S = 120.0
PIPELINES = {
    'slam': ('laser_driver', 'base_driver', 'corner_extractor', 'ekf_slam'),
    'sonar': ('base_driver', 'sonar_localizer'),
    'landmarks': ('base_driver', 'landmark_detector'),
    'replay': ('bag_player', 'corner_extractor', 'ekf_slam'),
}


def _overrides(settings: Sequence[str], nodes: Sequence[str]) -> Dict[str, List[str]]:
    """Parse ``NODE.PARAMETER=VALUE`` settings into ``-p`` arguments per node.

    The nodes refuse a parameter they do not declare (exit status 2, the nearest name);
    ``ekf_slam``'s names are checked here, before anything starts.

    Raises:
        ValueError: A setting is malformed, names a node outside the pipeline or an
            unknown ``ekf_slam`` parameter.

    """
    out: Dict[str, List[str]] = {n: [] for n in nodes}
    for text in settings:
        key, sep, value = text.partition('=')
        node, dot, name = key.partition('.')
        if not (sep and dot and node and name):
            raise ValueError(f'--set {text!r}: expected NODE.PARAMETER=VALUE')
        if node not in out or node == 'bag_player':
            raise ValueError(f'--set {text!r}: no node {node!r} with parameters in this '
                             f'pipeline ({", ".join(n for n in nodes if n != "bag_player")})')
        if node == 'ekf_slam':  # its parameters are known without starting it
            from landmark_nav.slam.configuration import NODE, parameters
            known = parameters()
            if name not in known:
                raise ValueError(f'--set {text!r}: {unknown_parameter(NODE, name, known)}')
        out[node] += ['-p', f'{name}:={value}']
    return out


def stated_parameters(bag: str, files: Sequence[str] = (), settings: Sequence[str] = ()
                      ) -> Dict[str, Dict[str, Any]]:
    """Return what a bag states for each node of a replay, to give it before its ``--set``.

    :func:`landmark_nav.evaluation.slam.run_parameters`, as ``evaluate`` uses it, over
    ``ekf_slam``'s profile ``files`` (``--params-file`` arguments) and ``settings``
    (``NODE.PARAMETER=VALUE``): ``{'ekf_slam': values, 'corner_extractor': values,
    'line_extractor': values}``, each empty for a bag that cannot be read (the player reports
    that). ``launch/replay.launch.py`` gives the nodes the same values. Prints a ``note:``
    line on stderr for what a setting replaced (as ``evaluate`` notes it).
    """
    from landmark_nav.evaluation.slam import EXTRACTOR_NODES, run_parameters
    from landmark_nav.tools.node_parameters import given_parameters, parse_setting
    slam = [t for t in settings if t.partition('=')[0].startswith('ekf_slam.')]
    notes = []
    try:
        values = run_parameters(bag, given_parameters(files[1::2], [], 'ekf_slam'),
                                dict(parse_setting(t, 'ekf_slam') for t in slam), notes=notes)
    except Exception:  # noqa: B902 - the player names the problem with the bag
        return {node: {} for node in ('ekf_slam',) + EXTRACTOR_NODES}
    for note in notes:
        print(f'note: ekf_slam: {note}', file=sys.stderr)
    return values


def bag_settings(bag: str, files: Sequence[str] = (), settings: Sequence[str] = ()
                 ) -> Dict[str, List[str]]:
    """Return :func:`stated_parameters` as ``-p`` arguments per node."""
    from landmark_nav.tools.node_parameters import as_ros_arguments
    return {node: as_ros_arguments(values)
            for node, values in stated_parameters(bag, files, settings).items()}


def _profile_files(names: Sequence[str], nodes: Sequence[str]) -> Dict[str, List[str]]:
    """Return the ``--params-file`` arguments of shipped profiles, by node.

    Raises:
        ValueError: Not a shipped profile of a node of the pipeline.

    """
    from landmark_nav.tools.config_files import profiles
    known = profiles()
    out: Dict[str, List[str]] = {n: [] for n in nodes}
    for name in names:
        if known.get(name) not in out:
            raise ValueError(f'--profile {name!r}: not a profile of a node of this pipeline '
                             f'({", ".join(k for k, n in known.items() if n in out) or "none"})')
        out[known[name]] += ['--params-file', str(config_path(name))]
    return out


def pipeline_commands(name: str, settings: Sequence[str] = (), bag: Optional[str] = None,
                      rate: float = 1.0, loop: bool = False,
                      profiles: Sequence[str] = ()) -> Dict[str, List[str]]:
    """Return the command line of every process of a pipeline, by node name.

    Each node gets its shipped parameter file, then its ``profiles`` (e.g.
    ``ekf_slam_chapter``), then what the bag states (``replay``), then ``settings``.

    Raises:
        ValueError: Unknown pipeline, a bad ``--set`` or ``--profile``, or a replay without
            a bag.
        FileNotFoundError: A node's parameter file is missing.

    """
    if name not in PIPELINES:
        raise ValueError(f'unknown pipeline {name!r}; one of {", ".join(PIPELINES)}')
    nodes = PIPELINES[name]
    extra = _overrides(settings, nodes)
    files = _profile_files(profiles, nodes)
    stated = bag_settings(bag, files['ekf_slam'], settings) if (
        bag and 'bag_player' in nodes) else {}
    commands = {}
    for node in nodes:
        cmd = [sys.executable, '-m', f'landmark_nav.nodes.{node}']
        if node == 'bag_player':
            if not bag:
                raise ValueError(f'pipeline {name} needs --bag')
            cmd += [bag, '--rate', repr(float(rate)), '--topics', '/scan', '/odom',
                    '--wait-for-subscribers', '30', '--min-subscribers',
                    f'/scan={_scan_subscribers(settings)}', '/odom=1'] + (
                        ['--loop'] if loop else [])
        else:
            cmd += (['--ros-args', '--params-file', str(config_path(node))] + files[node]
                    + stated.get(node, []) + extra[node])
        commands[node] = cmd
    return commands


def check_replay_bag(bag: str) -> None:
    """Refuse a bag the replay cannot play, before any node starts (one line, exit 2).

    Raises:
        BagError: No bag there, or it cannot be read.
        ValueError: It has no ``/scan`` or no ``/odom``.

    """
    from landmark_nav.bag import BagReader
    with BagReader(bag) as reader:
        topics = reader.topics()
    missing = [t for t in ('/scan', '/odom') if t not in topics]
    if missing:
        raise ValueError(f'{bag} has no {" and no ".join(missing)} topic (pipeline replay '
                         'plays /scan and /odom)')


def _scan_subscribers(settings: Sequence[str]) -> int:
    """Return the number of replay nodes subscribing ``/scan``.

    corner_extractor, and ekf_slam unless its visibility is off and it maps corners only.
    """
    values = dict(s.partition('=')[::2] for s in settings)
    slam = (values.get('ekf_slam.visibility', 'true').lower() not in ('false', '0')
            or values.get('ekf_slam.landmarks', 'corners').strip('\'"') != 'corners')
    return 1 + int(slam)


def add_parser(sub, parser_class) -> None:
    """Add the ``pipeline`` subcommand to the ``landmark_nav`` command line."""
    p = sub.add_parser('pipeline', help='start a pipeline of nodes (slam, sonar, landmarks, '
                       'replay) with the shipped parameters; Ctrl-C stops it',
                       description=__doc__.split('\n')[0])
    p.add_argument('name', choices=sorted(PIPELINES), help='which pipeline: ' + '; '.join(
        f'{name} = {" + ".join(nodes)}' for name, nodes in PIPELINES.items()))
    p.add_argument('--bag', help='bag to replay (pipeline replay)')
    p.add_argument('--rate', type=float, default=1.0, help='replay speed factor (default 1)')
    p.add_argument('--loop', action='store_true', help='replay the bag in a loop')
    p.add_argument('--drain-timeout', type=float, default=DRAIN_TIMEOUT_S, metavar='SECONDS',
                   help='replay: when the bag has been played, wait up to this long until the '
                   f'nodes have processed every scan (default {DRAIN_TIMEOUT_S:g}; 0: stop at '
                   'once), then stop them and say what was discarded')
    p.add_argument('--set', action='append', default=[], metavar='NODE.PARAMETER=VALUE',
                   help='override a parameter, e.g. laser_driver.port=/dev/ttyUSB0 '
                   '(repeatable)')
    p.add_argument('--profile', action='append', default=[], metavar='NAME',
                   help="a shipped profile on top of its node's file, e.g. ekf_slam_chapter "
                   "(the chapter's filter; landmark_nav config lists them; repeatable)")
    p.add_argument('--dry-run', action='store_true', help='print the commands, start nothing')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Start the pipeline and wait until it stops; return honcho's exit status."""
    commands = pipeline_commands(args.name, args.set, args.bag, args.rate, args.loop,
                                 args.profile)
    if args.dry_run:
        for node, cmd in commands.items():
            print(f'{node}: {shlex.join(cmd)}')
        return 0
    if args.name == 'replay':
        check_replay_bag(args.bag)
    from honcho.printer import Printer
    from landmark_nav.tools.pipeline_drain import DrainingManager, scans_in_bag
    scans = scans_in_bag(args.bag) if args.name == 'replay' and not args.loop else None
    manager = DrainingManager(Printer(sys.stdout, colour=sys.stdout.isatty(),
                                      width=max(len(n) for n in commands)),
                              scans, args.drain_timeout)
    for node, cmd in commands.items():
        manager.add_process(node, 'exec ' + shlex.join(cmd))  # no shell between
    recorder = None
    if args.name == 'replay':
        from landmark_nav.tools.replay_result import PoseRecorder
        recorder = PoseRecorder()  # before the nodes: it sees their first pose
        manager.also_ready = recorder.connected  # the player starts once it is matched
    try:
        manager.loop()
    finally:
        if recorder is not None:
            stamps, poses = recorder.stop()
    if recorder is not None:
        from landmark_nav.tools.replay_result import reference_ate, result_line
        played_s = manager.played_seconds()
        ate = reference_ate(args.bag, stamps, poses) if played_s is not None else None
        print(result_line(args.bag, args.rate, scans, played_s, stamps, poses, ate,
                          recorder.other_publishers()), flush=True)
    return exit_status(manager)


#: honcho's exit status after it stopped the nodes on SIGINT / SIGTERM (128 + signal).
_SIGNAL_STATUS = (130, 143)


def exit_status(manager) -> int:
    """Return the pipeline's exit status once honcho's loop has ended.

    Stopped by SIGINT / SIGTERM, every node exiting 0 is a clean stop (0) like a single
    node's; otherwise the first non-zero status of a node (or honcho's own).
    """
    codes = [p.get('returncode') for p in manager._processes.values()]  # honcho 2.0
    if manager.returncode in _SIGNAL_STATUS:
        return next((c for c in codes if c), 0)
    return manager.returncode or 0
