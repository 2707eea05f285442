"""Shared test set-up: every test process gets a private DDS domain on localhost."""

from pathlib import Path

from landmark_nav.testing import isolate_dds
import pytest

REPO = Path(__file__).resolve().parents[1]

isolate_dds()


@pytest.fixture(scope='session')
def repo() -> Path:
    """Return the repository root."""
    return REPO
