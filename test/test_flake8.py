"""The standard ament flake8 lint test, run in a fresh interpreter.

flake8 checks files in a pool of forked workers; forked from the test process, which by
then holds rclpy, DDS and OpenCV state of earlier tests, the workers crashed while
collecting garbage and the pool hung the test run. A child interpreter has none of it.

The docstrings are checked once, by the pep257 test (pydocstyle, with the checks the
flake8-docstrings plugin added to it): flake8 runs here without that plugin, which ran
pydocstyle over the same files a second time.
"""

import subprocess
import sys

import pytest

_LINT = ('import importlib.metadata, sys\n'
         'every = importlib.metadata.distributions\n'
         'importlib.metadata.distributions = lambda **kw: (\n'
         "    d for d in every(**kw) if d.metadata['Name'] != 'flake8-docstrings')\n"
         'from ament_flake8.main import main_with_errors\n'
         'rc, errors = main_with_errors(argv=[])\n'
         'print("\\n".join(errors))\n'
         'sys.exit(rc)\n')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    child = subprocess.run([sys.executable, '-c', _LINT], capture_output=True, text=True,
                           timeout=600)
    assert child.returncode == 0, 'flake8 found code style errors / warnings:\n' + (
        child.stdout + child.stderr)[-5000:]
