"""The standard ament pep257 lint test (Google docstring convention): the one docstring pass.

Run in a fresh interpreter, like the flake8 test, so that no state of earlier tests in the
test process can disturb it. The flake8 test runs without the flake8-docstrings plugin,
which ran pydocstyle over the same files a second time: the checks only that plugin made
(D204, D400, D401 with properties exempt, as the plugin has them) are added here.
"""

import subprocess
import sys

import pytest

# The repository writes Google-style docstrings (a one-line summary, then Args / Returns /
# Raises sections where they apply); like ament's own convention, missing docstrings
# (D100-D107) are not errors. ament_pep257 does not hand pydocstyle the property
# decorators (a property's summary may be a noun phrase); the child adds pydocstyle's.
_LINT = ('import functools, sys\n'
         'import ament_pep257.main as ament\n'
         'from pydocstyle.config import ConfigurationParser\n'
         'ament.check = functools.partial(ament.check, property_decorators=set(\n'
         "    ConfigurationParser.DEFAULT_PROPERTY_DECORATORS.split(',')))\n"
         "sys.exit(ament.main(argv=['.', '--convention', 'google', '--add-ignore',\n"
         "                'D100', 'D101', 'D102', 'D103', 'D104', 'D105', 'D106', 'D107',\n"
         "                '--add-select', 'D204', 'D400', 'D401']))\n")


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    child = subprocess.run([sys.executable, '-c', _LINT], capture_output=True, text=True,
                           timeout=600)
    assert child.returncode == 0, 'pep257 found code style errors / warnings:\n' + (
        child.stdout + child.stderr)[-5000:]
