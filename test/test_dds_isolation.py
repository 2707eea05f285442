"""Concurrent test runs on one machine get DDS domains of their own."""

import fcntl
import os
import subprocess
import sys

from landmark_nav.testing.harness import claim_domain
import pytest


def _claim_in_child(start: int, lock_dir) -> int:
    code = ('import sys; from landmark_nav.testing.harness import claim_domain; '
            f'print(claim_domain({start}, sys.argv[1]))')
    out = subprocess.run([sys.executable, '-c', code, str(lock_dir)], check=True,
                         capture_output=True, text=True).stdout
    return int(out)


def test_a_held_domain_is_skipped_and_a_free_one_reused(tmp_path):
    held = claim_domain(57, tmp_path)
    assert held == 57
    assert claim_domain(57, tmp_path) == 57  # this process keeps its own domain
    # another process starting from the same domain (pids equal modulo 80) moves on
    assert _claim_in_child(57, tmp_path) == 58
    # the child has exited: its domain is free again for the next one
    assert _claim_in_child(58, tmp_path) == 58


def test_the_runs_own_domain_is_locked_again_in_another_lock_dir(tmp_path):
    """Holding domain D in one lock directory says nothing about another.

    The test above once failed when this run's own domain happened to be 57.
    """
    domain = int(os.environ['ROS_DOMAIN_ID'])
    assert claim_domain(domain, tmp_path) == domain
    assert _claim_in_child(domain, tmp_path) == (20 if domain == 99 else domain + 1)


def test_the_search_wraps_from_99_to_20(tmp_path):
    handles = []
    try:
        for domain, expected in ((99, 20), (20, 21)):
            handles.append(open(tmp_path / f'landmark_nav-dds-domain-{domain}.lock', 'a'))
            fcntl.flock(handles[-1], fcntl.LOCK_EX | fcntl.LOCK_NB)
            assert _claim_in_child(99, tmp_path) == expected
    finally:
        for handle in handles:
            handle.close()


def test_this_run_holds_its_domain():
    """The conftest's isolate_dds claimed the domain in ROS_DOMAIN_ID for this process."""
    domain = int(os.environ['ROS_DOMAIN_ID'])
    assert 20 <= domain <= 99
    with pytest.raises(subprocess.CalledProcessError):
        subprocess.run([sys.executable, '-c',
                        'import fcntl, sys, tempfile, pathlib; '
                        'h = open(pathlib.Path(tempfile.gettempdir()) / '
                        f'"landmark_nav-dds-domain-{domain}.lock", "a"); '
                        'fcntl.flock(h, fcntl.LOCK_EX | fcntl.LOCK_NB)'],
                       check=True, capture_output=True)
