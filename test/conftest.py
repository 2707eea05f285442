"""Shared test set-up: a private DDS domain on localhost; owned processes; shared runs.

Every process a test starts is owned (:mod:`landmark_nav.testing.pytest_processes`): the
``processes`` fixture stops, kills if it must, and reaps it at the end of the test; a test
after which a process it started still runs fails, and so does the run if anything it
started outlives it.
"""

from pathlib import Path
from typing import Callable, Dict, Tuple

from landmark_nav.testing import isolate_dds
import pytest

pytest_plugins = ('landmark_nav.testing.pytest_processes',)

REPO = Path(__file__).resolve().parents[1]

isolate_dds()  # a domain of this process's own (each xdist worker its own), localhost only


@pytest.fixture(scope='session')
def repo() -> Path:
    """Return the repository root."""
    return REPO


@pytest.fixture(scope='session')
def office_evaluation(tmp_path_factory) -> Callable[[str], Tuple[dict, Path]]:
    """Return ``get(association)``: ``evaluate_bag`` of bags/office, once per session.

    ``get`` gives the figures and the folder with the written files (TUM, slam.json,
    plots); test_evaluate_slam.py and test_trajectory.py need the same run.
    """
    from landmark_nav.evaluation.slam import evaluate_bag
    done: Dict[str, Tuple[dict, Path]] = {}

    def get(association: str) -> Tuple[dict, Path]:
        if association not in done:
            out = tmp_path_factory.mktemp(f'office_{association}')
            done[association] = (evaluate_bag(REPO / 'bags' / 'office', association, out,
                                              progress=False), out)
        return done[association]
    return get


def pytest_collection_modifyitems(items):
    """Put the files that hold slow tests first (the rest keep their order).

    ``make test`` gives each pytest-xdist worker whole files in collection order; a long
    file that started last would run alone at the end while the other workers idle.
    """
    slow_files = {item.path for item in items if item.get_closest_marker('slow')}
    items.sort(key=lambda item: item.path not in slow_files)
