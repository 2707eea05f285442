"""Every node's main: thread limits, one-line parameter errors, clean shutdown on signals."""

import os
from pathlib import Path
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[1]
NODES = ['corner_extractor', 'line_extractor', 'ekf_slam', 'sonar_localizer',
         'landmark_detector']

# Run a node's main with rclpy.spin replaced by a probe that prints the thread pools.
PROBE = """
import importlib, sys
import rclpy
from threadpoolctl import threadpool_info
def spin(node):
    pools = sorted((i['internal_api'], i['num_threads']) for i in threadpool_info())
    import cv2
    print('POOLS', pools, 'cv2', cv2.getNumThreads(), flush=True)
    raise KeyboardInterrupt
rclpy.spin = spin
module = importlib.import_module('landmark_nav.nodes.' + sys.argv[1])
sys.exit(module.main([sys.argv[0]]))
"""


def node_env(**extra) -> dict:
    """Return the environment of a node subprocess (no thread variables unless given)."""
    env = {k: v for k, v in os.environ.items()
           if k not in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
                        'BLIS_NUM_THREADS', 'LANDMARK_NAV_THREADS')}
    env['PYTHONPATH'] = str(REPO) + os.pathsep + env.get('PYTHONPATH', '')
    env.update(extra)
    return env


def probe_pools(node: str, **extra) -> str:
    """Return the POOLS line a node prints when it starts spinning."""
    out = subprocess.run([sys.executable, '-c', PROBE, node], env=node_env(**extra),
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    return [line for line in out.stdout.splitlines() if line.startswith('POOLS')][0]


@pytest.mark.parametrize('node', NODES)
def test_numerical_libraries_are_single_threaded_in_every_node(node):
    line = probe_pools(node)
    pools = eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0])
    assert pools and all(n == 1 for _, n in pools), line
    assert line.endswith('cv2 1'), line


def test_thread_limit_can_be_configured():
    line = probe_pools('ekf_slam', LANDMARK_NAV_THREADS='2')
    pools = eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0])
    assert all(n == 2 for _, n in pools) and line.endswith('cv2 2'), line
    line = probe_pools('ekf_slam', OPENBLAS_NUM_THREADS='2')  # the user's own setting stays
    assert ('openblas', 2) in eval(line.split(' ', 1)[1].rsplit(' cv2', 1)[0]), line
