"""bench_slam_real.py's graph back end and Wean corner lines (not an entry point).

``grid --backend graph``: each run is ``landmark_nav evaluate BAG --backend graph``
(:func:`landmark_nav.evaluation.slam_graph.evaluate_graph_bag`) with the log's reference
noise (``REFERENCE_SD``), printed as the docs' "Graph back end" table, and checked against
the targets: the final trajectory's SE(2)-aligned ATE at most 1/10 of the
odometry's; its RPE over 1 m at most the odometry's or within 1 cm of the reference's own
floor (``sqrt(2)`` times its per-pose std, ``sqrt(along^2 + across^2)``: two poses' noise);
the reference inside the final 95 % ellipse with the reference's std added on at least
80 % of the scans (the plain ellipse for a log without a measured std). Exit status 1
when a run misses one (the ``missed`` column names it).

``wean --backend graph``: the graph back end on each Wean run
(:func:`landmark_nav.evaluation.graph_wall_check.graph_wall_check`: its structural corners
placed with its final poses stand for the landmarks it does not keep). Printed per run:
keyframes, loops accepted and proposed, poses, poses in wall cells, those left with one
cell of tolerance and the cells the log's scans see through excused
(``poses_in_wall_counted``; the target is 0), poses in unknown cells, scan end points near a
wall with the graph's and with the odometry's poses, the structural corners' share within
10 cm of a wall cell (asks >= 0.9), their count and the count left out, the same share per
place (``corner_places``: detections within 10 cm linked, places seen >= 3 times) and the
places' count, back-end ms per scan. With ``--corners``, also whether the log's own
scans agree with the grid at the corner places
(:func:`~landmark_nav.evaluation.graph_wall_check.place_scan_agreement`); with ``--plot``
the places off the walls drawn (``<log>_off_wall_places.png``). ``--cell-alignment``: the
grid alignment without its continuous refinement (whole cells).
"""

import math
from pathlib import Path
import sys

from landmark_nav.evaluation.graph_wall_check import graph_wall_check, placed_run
from landmark_nav.evaluation.occupancy_check import corner_wall_check
from landmark_nav.evaluation.slam import bag_odometry_noise
from landmark_nav.evaluation.slam_graph import run_graph
from landmark_nav.evaluation.slam_plots import plot_corner_wall_check, plot_place_crops
from landmark_nav.laser.corners import CornerParams
import numpy as np


def graph_backend(args) -> str:
    """Return ``args.backend``; with ``graph``, exit naming an option only the EKF reads."""
    if args.backend == 'graph':
        given = [f'--{n.replace("_", "-")}' for n in ('set', 'params_file', 'establish_hits')
                 if getattr(args, n, None)]
        given += ['--landmarks'] if getattr(args, 'landmarks', None) not in (None, 'both') else []
        if given:
            sys.exit(f'error: {", ".join(given)}: EKF options, not read by --backend graph')
    return args.backend


def graph_targets(r: dict) -> dict:
    """Issue 41's targets of one graph run (module docstring): whether each holds."""
    sd = r.get('reference_sd')
    floor = math.sqrt(2.0) * math.hypot(*sd) if sd else math.nan  # the reference's RPE
    return {'ate': r['final_ate_se2_rmse'] <= 0.1 * r['odom_ate_se2_rmse'],
            'rpe': (r['final_rpe_trans_rmse'] <= r['odom_rpe_trans_rmse']
                    or r['final_rpe_trans_rmse'] <= floor + 0.01),
            'ellipse': r.get('final_ellipse95_ref_share', r['final_ellipse95_share']) >= 0.8}


def graph_grid(results: list) -> int:
    """Print the graph's rows and targets (module docstring); 1 when a run misses one."""
    print('log | seed | ATE final / online [cm] | ATE odometry [cm] | ATE / odometry | RPE 1 m '
          'graph / odometry [cm] | loops accepted of proposed (refused) | factors verified / '
          "odometry | in 95 % ellipse, with the reference's noise [%] | ms/scan | missed")
    missed = 0
    for name, seed, r in results:
        refused = ', '.join(f'{v} {k}' for k, v in r['loops_refused'].items() if v)
        miss = [k for k, ok in graph_targets(r).items() if not ok]
        missed += bool(miss)
        print(f"{name} | {seed} | {100 * r['final_ate_se2_rmse']:.1f} / "
              f"{100 * r['online_ate_se2_rmse']:.1f} | {100 * r['odom_ate_se2_rmse']:.1f} | "
              f"{r['final_ate_se2_rmse'] / r['odom_ate_se2_rmse']:.3f} | "
              f"{100 * r['final_rpe_trans_rmse']:.1f} / {100 * r['odom_rpe_trans_rmse']:.1f} | "
              f"{r['loops_accepted']} of {r['loops_proposed']} ({refused}) | "
              f"{r['motions'].get('scan_verified', 0)} / {r['motions'].get('odometry', 0)} | "
              f"{100 * r['final_ellipse95_share']:.1f}, "
              f"{100 * r.get('final_ellipse95_ref_share', math.nan):.1f} | "
              f"{r['ms_per_scan']:.0f} | {', '.join(miss) or '-'}", flush=True)
    print(f'{len(results)} runs, {len(results) - missed} within all three targets (ATE <= '
          'odometry / 10, RPE <= odometry or reference floor + 1 cm, ellipse with the '
          "reference's noise >= 80 %)")
    return 1 if missed else 0


def wean_graph(grid, sc, label: str, args) -> None:
    """Run the graph back end on one Wean bag and print its line (module docstring)."""
    run = run_graph(sc, bag_odometry_noise(sc)[0])
    cp = CornerParams(sigma_r=sc.laser.sigma_range, sigma_phi=sc.laser.sigma_angle)
    w = graph_wall_check(grid, sc, run, cp, refine=not getattr(args, 'cell_alignment', False))
    s, c, g = w['check']['slam'], w['corners'], run.graph
    print(f'{label} {len(g.keyframes)} {g.loop_counts.accepted} {g.loop_counts.proposed} '
          f'{s["poses"]} {s["poses_in_wall"]} {w["poses_in_wall_counted"]} '
          f'{s["poses_unknown"]} {s["point_share"]:.3f} '
          f'{w["check"]["odometry"]["point_share"]:.3f} {c["structural_share"]:.3f} '
          f'{c["structural_count"]} {c["structural_left_out"]} {w["places"]["share"]:.3f} '
          f'{w["places"]["count"]} {1e3 * run.seconds / max(len(run.stamps), 1):.0f}',
          flush=True)
    if args.corners or args.plot:
        corners_on_walls(grid, sc, placed_run(sc, run, cp), s['transform'], cp, label, args,
                         c)
        a = w['agreement']
        print(f"{label} scan points within 10 cm of a wall cell: all {a['overall']:.3f}; at "
              f"the {a['off']['count']} corner places off the walls (within 0.1 m) "
              f"{a['off']['at_share']:.3f}, around them (0.5-1.5 m) "
              f"{a['off']['ring_share']:.3f} ({a['off']['scans_off']} places with their scan "
              f"points mostly off the walls too); at the {a['on']['count']} places on the "
              f"walls {a['on']['at_share']:.3f}, around them {a['on']['ring_share']:.3f}")
        for p in a['places']:
            if not p['on_wall']:
                print(f"{label} place off the walls at ({p['centre'][0]:.2f}, "
                      f"{p['centre'][1]:.2f}): {p['views']} views, "
                      f"{'convex' if p['convex'] else 'concave'}, {p['distance']:.2f} m from a "
                      f"wall cell; its scan points {p['at_distance']:.2f} m (median), "
                      f"{p['at_share']:.2f} on a wall; around it {p['ring_share']:.2f}")
    if args.plot:
        out = Path(args.plot) / (label.replace('/', '_') + '_off_wall_places.png')
        if plot_place_crops(grid, c, w['agreement'], w['scan_points'],
                            f'{label}: structural corner places off the walls', out):
            print(f'wrote {out}')


def corners_on_walls(grid, sc, run, transform, corner_params, label: str, args,
                     cw=None) -> None:
    """Print (and with --plot draw) where every scan's corners fall on the grid.

    ``cw``: the run's :func:`~landmark_nav.evaluation.occupancy_check.corner_wall_check`
    result when already computed.
    """
    if cw is None:
        cw = corner_wall_check(grid, sc, run, transform, corner_params)
    print(f'{label} corners within 10 cm of a wall cell ({cw["seen_through"]} cells seen '
          f'through: corners near them left out): structural {cw["structural_share"]:.3f} of '
          f'{cw["structural_count"]} (left out {cw["structural_left_out"]}), other '
          f'{cw["other_share"]:.3f} of {cw["other_count"]} (left out {cw["other_left_out"]})')
    off = cw['structural'] & ~cw['left_out'] & ~cw['on_wall']
    d = cw['wall_distance'][off]
    print(f'{label} structural convex {cw["structural_convex_share"]:.3f} of '
          f'{cw["structural_convex_count"]}, concave {cw["structural_concave_share"]:.3f} of '
          f'{cw["structural_concave_count"]}; off the walls: {int(np.sum(cw["convex"][off]))} '
          f'of {int(off.sum())} convex, distance to a wall cell [m] '
          + (' / '.join(f'{q:.2f}' for q in np.quantile(d, [0.1, 0.5, 0.9]))
             + ' (10 / 50 / 90 %)' if d.size else '-'))
    print(f'{label} structural with both arm ends seen (no arm occluded, no silhouette: '
          f'Corner.occluded, Corner.silhouette) {cw["structural_seen_ends_share"]:.3f} of '
          f'{cw["structural_seen_ends_count"]}')
    if args.plot:
        out = Path(args.plot) / (label.replace('#', '_').replace('/', '_')
                                 + '_structural_corners.png')
        plot_corner_wall_check(grid, cw, f'{label}: structural corners on wean.dat', out)
        print(f'wrote {out}')
