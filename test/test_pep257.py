"""The standard ament pep257 lint test (Google docstring convention).

Run in a fresh interpreter, like the flake8 test, so that no state of earlier tests in the
test process can disturb it.
"""

import subprocess
import sys

import pytest

# The repository writes Google-style docstrings (a one-line summary, then Args / Returns /
# Raises sections where they apply); like ament's own convention, missing docstrings
# (D100-D107) are not errors.
_LINT = ('import sys\n'
         'from ament_pep257.main import main\n'
         "sys.exit(main(argv=['.', '--convention', 'google', '--add-ignore',\n"
         "                'D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107']))\n")


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    child = subprocess.run([sys.executable, '-c', _LINT], capture_output=True, text=True,
                           timeout=600)
    assert child.returncode == 0, 'pep257 found code style errors / warnings:\n' + (
        child.stdout + child.stderr)[-5000:]
