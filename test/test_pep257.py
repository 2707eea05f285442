"""The standard ament pep257 lint test (Google docstring convention, see STYLE)."""

from ament_pep257.main import main
import pytest


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    # Google-style docstrings (STYLE.md); like ament's own convention, missing docstrings
    # (D100-D107) are not errors.
    rc = main(argv=['.', '--convention', 'google', '--add-ignore',
                    'D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107'])
    assert rc == 0, 'Found code style errors / warnings'
