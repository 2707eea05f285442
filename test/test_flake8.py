"""The standard ament flake8 lint test, run in a fresh interpreter.

flake8 checks files in a pool of forked workers; forked from the test process, which by
then holds rclpy, DDS and OpenCV state of earlier tests, the workers crashed while
collecting garbage and the pool hung the test run. A child interpreter has none of it. It
checks the files in one process (``--jobs=1``): beside the suite's other workers a pool
gains no time and cost a quarter more CPU (33 vs 26 CPU-s).

The docstrings are checked once, by the pep257 test (pydocstyle, with the checks the
flake8-docstrings plugin added to it): flake8 runs here without that plugin, which ran
pydocstyle over the same files a second time.
"""

import subprocess
import sys

import pytest

# flake8-quotes tokenises each file twice (for its noqa lines, then for the strings) from
# the lines flake8 gives it: here it reads flake8's own tokens of those lines instead
# (``file_tokens``, the same list), a third of the plugin's time.
_QUOTES_ON_FLAKE8_TOKENS = (
    'import flake8_quotes\n'
    'class FileTokens:\n'
    '    tokens = ()\n'
    '    def __getattr__(self, name):\n'
    '        return getattr(tokenize, name)\n'
    '    def generate_tokens(self, readline):\n'
    '        return iter(self.tokens)\n'
    'flake8_quotes.tokenize = file_tokens = FileTokens()\n'
    'Checker = flake8_quotes.QuoteChecker\n'
    'init, run = Checker.__init__, Checker.run\n'
    "def __init__(self, tree, file_tokens, lines=None, filename='(none)'):\n"
    '    init(self, tree, lines, filename)\n'
    '    self.file_tokens = file_tokens\n'
    'def run_on_file_tokens(self):\n'
    '    file_tokens.tokens = self.file_tokens\n'
    '    yield from run(self)\n'
    'Checker.__init__, Checker.run = __init__, run_on_file_tokens\n')

_LINT = ('import importlib.metadata, sys, tokenize\n'
         'every = importlib.metadata.distributions\n'
         'importlib.metadata.distributions = lambda **kw: (\n'
         "    d for d in every(**kw) if d.metadata['Name'] != 'flake8-docstrings')\n"
         + _QUOTES_ON_FLAKE8_TOKENS +
         'import ament_flake8.main as ament\n'
         'style_guide = ament.get_flake8_style_guide\n'
         "ament.get_flake8_style_guide = lambda argv: style_guide(argv + ['--jobs=1'])\n"
         'rc, errors = ament.main_with_errors(argv=[])\n'
         'print("\\n".join(errors))\n'
         'sys.exit(rc)\n')


@pytest.mark.flake8
@pytest.mark.linter
def test_flake8():
    child = subprocess.run([sys.executable, '-c', _LINT], capture_output=True, text=True,
                           timeout=600)
    assert child.returncode == 0, 'flake8 found code style errors / warnings:\n' + (
        child.stdout + child.stderr)[-5000:]
