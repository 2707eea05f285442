"""The corridor follower in closed loop over DDS: three lengths of the corridor back and forth.

Run from the repository root::

    python benchmarks/bench_corridor_loop.py [--seed S] [--distance M] [--lengths N]

Starts the ``corridor_follower`` node in a process of its own (its shipped parameters,
with the rendered corridor's camera mount and geometry, ``stamped_cmd_vel: true`` and
``speed`` 0.5 m/s) on a private DDS domain (localhost only), and drives the simulated robot
of :mod:`landmark_nav.sim.corridor_loop` with the node's ``cmd_vel``: 320 x 240 frames at
5 Hz, odometry at 20 Hz with Kleeman noise and a 1 % right-wheel scale error, start 15 cm
off the centre line and 4 deg off the corridor axis, 2 m into the 30 m corridor, legs of
26 m (to 2 m before the far end and back), turning on the spot at the ends with the
follower disabled.

Acceptance (issue): within 5 cm of the centre line on 3 lengths, never touching a wall
(robot radius 0.25 m). The lateral figures are taken after the first 2 m of path (the
start transient from 15 cm off).
"""

import argparse
import math
import os
from pathlib import Path
import subprocess
import sys
import tempfile

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

import yaml  # noqa: E402


def main() -> int:
    """Run the loop and print its figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--distance', type=float, default=26.0, help='leg length [m]')
    ap.add_argument('--lengths', type=int, default=3, help='legs, back and forth')
    ap.add_argument('--domain', type=int, default=80 + os.getpid() % 10)
    args = ap.parse_args()
    os.environ['ROS_DOMAIN_ID'] = str(args.domain)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    import rclpy
    from landmark_nav.sim.corridor_loop import follower_parameters, LoopConfig, run_loop
    from landmark_nav.tools.config_files import config_path
    cfg = LoopConfig(start=(2.0, 0.15, math.radians(4.0)), distance=args.distance,
                     lengths=args.lengths)
    params = yaml.safe_load(Path(config_path('corridor_follower')).read_text())
    params['corridor_follower']['ros__parameters'].update(follower_parameters(cfg))
    with tempfile.TemporaryDirectory() as tmp:
        pfile = Path(tmp) / 'corridor_follower.yaml'
        pfile.write_text(yaml.safe_dump(params))
        env = dict(os.environ, PYTHONPATH=str(REPO) + os.pathsep
                   + os.environ.get('PYTHONPATH', ''))
        node = subprocess.Popen([sys.executable, '-m', 'landmark_nav.nodes.corridor_follower',
                                 '--ros-args', '--params-file', str(pfile),
                                 '--log-level', 'error'], env=env, cwd=REPO)
        context = rclpy.Context()
        rclpy.init(context=context)
        try:
            result = run_loop(context, cfg, seed=args.seed)
        finally:
            node.terminate()
            node.wait(timeout=30)
            rclpy.try_shutdown(context=context)
    s = result.summary()
    print(f'closed loop over DDS, {args.lengths} x {args.distance:.0f} m back and forth '
          f'(seed {args.seed}): {s["steps"]:.0f} odometry steps, {s["frames"]:.0f} frames, '
          f'path {s["path_m"]:.1f} m, legs {", ".join(f"{v:.1f}" for v in result.legs)} m, '
          f'{s["wall_seconds"]:.0f} s wall')
    print(f'  lateral after the first 2 m: max {100 * s["max_abs_lateral_after_2m"]:.2f} cm, '
          f'RMS {100 * s["rms_lateral_after_2m"]:.2f} cm (start {100 * cfg.start[1]:.0f} cm '
          f'off); smallest wall clearance {100 * s["min_wall_clearance"]:.1f} cm '
          f'(robot radius {100 * cfg.robot_radius:.0f} cm)')
    ok = (s['max_abs_lateral_after_2m'] <= 0.05 and s['min_wall_clearance'] > 0
          and len(result.legs) == args.lengths)
    print('  acceptance (within 5 cm, no wall touched):', 'met' if ok else 'NOT met')
    return 0


if __name__ == '__main__':
    sys.exit(main())
