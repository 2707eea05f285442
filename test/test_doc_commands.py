r"""Every command printed in README.md and docs/ names what exists and options it accepts.

The commands are read from the fenced code blocks (``sh``, ``bash``, ``console`` or no
language) and from the inline code spans of the prose that start like a command
(``landmark_nav ...``, ``ros2 run|launch landmark_nav ...``, ``[python] benchmarks/...``,
``python -m landmark_nav...``, ``make ...``, a console script of ``setup.py``, optionally
after ``.venv/bin/`` and ``NAME=value`` environment settings; a span of one word is a name,
not a command). A line is split at ``&&``, ``||``, ``;``, ``|`` and a trailing ``&``; a
trailing ``\\`` joins the next line; ``#`` starts a comment.

Checked per command:

* ``landmark_nav SUB``: ``SUB`` is a subcommand of the command line;
* ``ros2 run landmark_nav EXE`` and ``EXE`` itself: ``EXE`` is a console script of
  ``setup.py``; a ROS node's options all come after ``--ros-args``;
* ``ros2 launch landmark_nav FILE name:=value``: ``launch/FILE`` exists and declares each
  ``name``;
* ``python benchmarks/NAME.py [SUB]``: the script exists and, when it has subcommands,
  ``SUB`` is one of them; ``python -m MODULE``: the module exists;
* ``landmark_nav config NAME`` (also inside ``$(...)``): ``config/NAME.yaml`` exists;
* ``make TARGET``: the Makefile has the target;
* every ``--option`` (before ``--ros-args``) appears in the ``--help`` of the command (of
  the subcommand when there is one), read in one child interpreter for all commands.

Placeholders in the prose (``[--seed S]``, ``BAG``, ``...``) are read as written: the
brackets are dropped, an option inside them is checked like any other.
"""

import ast
import json
from pathlib import Path
import re
import shlex
import subprocess
import sys
from typing import Dict, Iterator, List, Optional, Tuple

REPO = Path(__file__).resolve().parents[1]
DOCS = sorted([REPO / 'README.md'] + list((REPO / 'docs').rglob('*.md')))
SHELL_LANGUAGES = ('', 'sh', 'bash', 'console', 'shell')
SEPARATORS = re.compile(r'\s(?:&&|\|\||;|\|)\s|;$|\s&$')


def console_scripts() -> Dict[str, str]:
    """Return setup.py's ``EXECUTABLES`` (console script -> ``module:function``)."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == 'EXECUTABLES' for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError('setup.py: no EXECUTABLES')


SCRIPTS = console_scripts()
# Console scripts with a command line of their own (argparse); the others are ROS nodes.
ARGPARSE_SCRIPTS = ('landmark_nav', 'bag_player')


def _blocks(text: str) -> Tuple[List[Tuple[int, str]], str]:
    """Return the lines of the shell code blocks [(line number, text)], and the prose."""
    lines, prose, fence = [], [], None
    for n, line in enumerate(text.splitlines(), 1):
        m = re.match(r'^\s*(```+|~~~+)\s*([\w-]*)', line)
        if m and fence is None:
            fence = (m.group(1), m.group(2).lower())
            prose.append('')
            continue
        if fence is not None and line.strip().startswith(fence[0]):
            fence = None
            prose.append('')
            continue
        if fence is None:
            prose.append(line)
        else:
            prose.append('')
            if fence[1] in SHELL_LANGUAGES:
                lines.append((n, line))
    return lines, '\n'.join(prose)


def _strip_comment(line: str) -> str:
    """Drop a ``#`` comment outside quotes and ``$(...)``."""
    quote, depth = None, 0
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in '\'"':
            quote = c
        elif c == '(':
            depth += 1
        elif c == ')':
            depth = max(0, depth - 1)
        elif c == '#' and depth == 0 and (i == 0 or line[i - 1].isspace()):
            return line[:i]
    return line


def _command_prefix(words: List[str]) -> List[str]:
    """Drop ``NAME=value`` settings and a ``.venv/bin/`` or ``./`` path in front."""
    while words and re.match(r'^[A-Z_][A-Z0-9_]*=', words[0]):
        words = words[1:]
    if words:
        words = [re.sub(r'^(\.venv/bin/|\./)', '', words[0])] + words[1:]
    if words and re.match(r'^benchmarks/\w+\.py$', words[0]):
        words = ['python'] + words   # a benchmark named without its interpreter
    return words


def _is_ours(words: List[str]) -> bool:
    """Whether a command (after :func:`_command_prefix`) is one of the project's."""
    if not words:
        return False
    head = words[0]
    return (head in SCRIPTS or head == 'make'
            or (head == 'ros2' and words[1:2] in (['run'], ['launch'])
                and words[2:3] == ['landmark_nav'])
            or (head in ('python', 'python3') and len(words) > 1
                and (words[1].startswith('benchmarks/')
                     or (words[1] == '-m' and len(words) > 2
                         and words[2].startswith('landmark_nav')))))


def _split(text: str, prose: bool = False) -> Iterator[List[str]]:
    """Yield the words of each simple command of a shell line (prose: brackets dropped)."""
    for part in SEPARATORS.split(text):
        if prose:
            part = part.replace('[', ' ').replace(']', ' ')
        try:
            words = shlex.split(part)
        except ValueError:
            words = part.split()
        words = _command_prefix(words)
        if words:
            yield words


def _with_substitutions(where: str, words: List[str]) -> List[Tuple[str, List[str]]]:
    """Return the command and those of its ``$(...)`` substitutions."""
    out = [(where, words)]
    for w in words:
        for inner in re.findall(r'\$\(([^()]*)\)', w):
            out += [(where, c) for c in _split(inner) if _is_ours(c)]
    return out


def _doc_name(path: Path) -> str:
    """Name a page in a report: its path in the repository (README.md and docs/README.md)."""
    try:
        return str(path.resolve().relative_to(REPO))
    except ValueError:
        return path.name


def doc_commands(path: Path) -> List[Tuple[str, List[str]]]:
    """Return ``(where, words)`` of each of the project's commands printed in ``path``."""
    text = path.read_text()
    name = _doc_name(path)
    lines, prose = _blocks(text)
    out, joined, first = [], '', None
    for n, line in lines:
        line = _strip_comment(line).rstrip()
        first = first or n
        if line.endswith('\\'):
            joined += line[:-1] + ' '
            continue
        for words in _split(joined + line):
            if _is_ours(words):
                out += _with_substitutions(f'{name}:{first}', words)
        joined, first = '', None
    for m in re.finditer(r'(?<!`)`([^`]+)`(?!`)', prose):
        span = ' '.join(m.group(1).split())
        n = prose.count('\n', 0, m.start()) + 1
        for words in _split(_strip_comment(span), prose=True):
            if len(words) > 1 and _is_ours(words):
                out += _with_substitutions(f'{name}:{n}', words)
    return out


def _options(words: List[str]) -> List[str]:
    """Return the ``--option`` names of a command, up to ``--ros-args``."""
    out = []
    for w in words:
        if w == '--ros-args':
            break
        if w.startswith('--') and len(w) > 2:
            out.append(w.split('=', 1)[0].rstrip(',.:'))
    return out


def _arguments(words: List[str]) -> List[str]:
    """Return the words after the executable (after the script of ``python SCRIPT``)."""
    if words[0] == 'ros2':
        words = words[3:]
    if words[0] in ('python', 'python3'):
        return words[3:] if words[1] == '-m' else words[2:]
    return words[1:]


# One child interpreter prints the --help of each job: [kind, target, argv] -> output.
_HELP_RUNNER = r"""
import contextlib, importlib, io, json, runpy, sys
repo, result = sys.argv[1:3]
sys.path.insert(0, repo + '/benchmarks')
sys.path.insert(0, repo)
jobs = json.load(sys.stdin)
out = []
for kind, target, argv in jobs:
    buf = io.StringIO()
    code = None
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
        sys.argv = list(argv)
        try:
            if kind == 'script':
                runpy.run_path(target, run_name='__main__')
            elif kind == 'module':
                runpy.run_module(target, run_name='__main__', alter_sys=True)
            else:
                module, func = target.split(':')
                getattr(importlib.import_module(module), func)()
        except SystemExit as e:
            code = e.code
        except BaseException as e:
            print(f'{type(e).__name__}: {e}')
            code = 'exception'
    out.append([code, buf.getvalue()])
with open(result, 'w') as f:
    json.dump(out, f)
"""


def _help_job(words: List[str]) -> Tuple[Optional[Tuple[str, str, tuple]], Optional[str]]:
    """Return the --help job of a command (None: nothing to ask) or a problem."""
    head = words[0]
    if head == 'ros2' and words[1] == 'launch':
        return None, _launch_problem(words[3:])
    if head == 'ros2':
        words = words[3:]
        if not words:
            return None, 'ros2 run landmark_nav without an executable'
        head = words[0]
    if head == 'make':
        return None, None
    if head in ('python', 'python3'):
        if words[1] == '-m':
            return ('module', words[2], (words[2], '--help')), None
        script = REPO / words[1]
        if not script.is_file():
            return None, f'{words[1]}: no such script'
        return ('script', str(script), (words[1], '--help')), None
    if head not in SCRIPTS:
        return None, f'{head}: not a console script of setup.py'
    if head == 'landmark_nav' and words[1:2] == ['config'] and len(words) > 2 \
            and not words[2].isupper() and not (REPO / 'config' / f'{words[2]}.yaml').is_file():
        return None, f'landmark_nav config {words[2]}: no config/{words[2]}.yaml'
    if head not in ARGPARSE_SCRIPTS:
        before = words[1:words.index('--ros-args')] if '--ros-args' in words else words[1:]
        opts = [w for w in before if w.startswith('-')]
        if before in (['-h'], ['--help']):      # ``NODE --help``: the node prints its help
            return None, None
        return None, (f'{head} is a ROS node: options {opts} before --ros-args'
                      if opts else None)
    return ('console', SCRIPTS[head], (head, '--help')), None


def _launch_problem(words: List[str]) -> Optional[str]:
    """Check ``ros2 launch landmark_nav FILE name:=value ...``: the file and its arguments."""
    if not words:
        return 'ros2 launch landmark_nav without a launch file'
    path = REPO / 'launch' / words[0]
    if not path.is_file():
        return f'{words[0]}: no such launch file in launch/'
    declared = set(re.findall(r"DeclareLaunchArgument\(\s*'([\w]+)'", path.read_text()))
    unknown = [w.split(':=')[0] for w in words[1:]
               if ':=' in w and w.split(':=')[0] not in declared]
    return f'{words[0]}: no launch argument {unknown}' if unknown else None


def _subcommands(help_text: str) -> List[str]:
    """Return the subcommands of an argparse help text (empty: none).

    A parser with subcommands shows ``{a,b,c} ...`` or ``METAVAR ...`` in its usage (a list
    of choices shows ``[{a,b} ...]``); with a metavar the names are the lines indented by
    four spaces under it.
    """
    usage = ' '.join(help_text.split('\n\n', 1)[0].split())   # argparse wraps long usages
    m = re.search(r'(?<![\[\w])(\{[\w,-]+\}|[A-Z][A-Z_]*) \.\.\.', usage)
    if not m:
        return []
    if m.group(1).startswith('{'):
        return m.group(1)[1:-1].split(',')
    return re.findall(r'^    ([\w-]+)', help_text, re.M)


def _make_targets() -> set:
    text = (REPO / 'Makefile').read_text()
    return set(re.findall(r'^([A-Za-z][\w-]*):', text, re.M))


def _run_helps(jobs: List[tuple], tmp: Path) -> List[Tuple[object, str]]:
    result = tmp / 'helps.json'
    child = subprocess.run([sys.executable, '-c', _HELP_RUNNER, str(REPO), str(result)],
                           input=json.dumps([list(j[:2]) + [list(j[2])] for j in jobs]),
                           capture_output=True, text=True, cwd=REPO, timeout=600)
    assert child.returncode == 0 and result.is_file(), child.stdout + child.stderr
    return [tuple(r) for r in json.loads(result.read_text())]


def test_the_docs_have_commands():
    found = [c for path in DOCS for c in doc_commands(path)]
    assert any(w[0] == 'landmark_nav' for _, w in found)
    assert any(w[0] == 'make' for _, w in found)


def test_command_extraction(tmp_path):
    doc = tmp_path / 'x.md'
    doc.write_text('Run `landmark_nav evaluate BAG [--out DIR]` or `ls -l`, then\n'
                   '`OPENBLAS_NUM_THREADS=1 python benchmarks/bench_x.py run\n--seeds 0`.\n'
                   '```sh\nmake demo   # the job\n.venv/bin/landmark_nav info /tmp/a && \\\n'
                   '  landmark_nav replay /tmp/a --rate 2\nevo_ape tum a b\n'
                   'ekf_slam --ros-args --params-file "$(landmark_nav config ekf_slam)"\n'
                   '```\n```python\nlandmark_nav = 1\n```\n')
    assert [w for _, w in doc_commands(doc)] == [
        ['make', 'demo'], ['landmark_nav', 'info', '/tmp/a'],
        ['landmark_nav', 'replay', '/tmp/a', '--rate', '2'],
        ['ekf_slam', '--ros-args', '--params-file', '$(landmark_nav config ekf_slam)'],
        ['landmark_nav', 'config', 'ekf_slam'],
        ['landmark_nav', 'evaluate', 'BAG', '--out', 'DIR'],
        ['python', 'benchmarks/bench_x.py', 'run', '--seeds', '0']]


def check_commands(commands: List[Tuple[str, List[str]]], tmp_path: Path) -> List[str]:
    """Return a line per problem of the commands (module docstring)."""
    problems, targets = [], _make_targets()
    first_jobs: Dict[tuple, tuple] = {}
    for where, words in commands:
        if words[0] == 'make':
            missing = [t for t in words[1:] if not t.startswith('-') and '=' not in t
                       and t not in targets]
            if missing:
                problems.append(f'{where}: make {missing}: no such target')
            continue
        job, problem = _help_job(words)
        if problem:
            problems.append(f'{where}: {problem}')
        if job is not None:
            first_jobs.setdefault(job, job)
    jobs = list(first_jobs)
    helps = dict(zip(jobs, _run_helps(jobs, tmp_path)))
    # Walk down the subcommands (``landmark_nav emulate urg``), one level per round.
    pending = []
    for where, words in commands:
        job, _ = _help_job(words) if words[0] != 'make' else (None, None)
        if job is not None:
            pending.append((where, words, job, _arguments(words)))
    checks = []
    while pending:
        deeper, new_jobs = [], {}
        for where, words, job, pos in pending:
            code, text = helps[job]
            if code not in (0, None):
                problems.append(f'{where}: {" ".join(job[2])}: exit status {code}\n'
                                f'{text[-800:]}')
                continue
            subs = _subcommands(text)
            if not subs:
                checks.append((where, words, job))
                continue
            # The subcommand is the first argument; ``a|b`` in the prose names alternatives.
            names = pos[0].split('|') if pos and not pos[0].startswith('-') else [None]
            if any(n not in subs for n in names):
                problems.append(f'{where}: {" ".join(job[2][:-1])}: subcommand '
                                f'{pos[0] if pos else None!r} not one of {subs}')
                continue
            for name in names:
                sub_job = (job[0], job[1], job[2][:-1] + (name, '--help'))
                new_jobs[sub_job] = None
                deeper.append((where, words, sub_job, pos[1:]))
        todo = [j for j in new_jobs if j not in helps]
        helps.update(zip(todo, _run_helps(todo, tmp_path) if todo else []))
        pending = deeper
    for where, words, job in checks:
        accepted = set(re.findall(r'--[\w-]+', helps[job][1]))
        for opt in _options(words):
            if opt not in accepted:
                problems.append(f'{where}: {" ".join(job[2][:-1])}: {opt} is not an option')
    return problems


def test_every_doc_command_runs_as_printed(tmp_path):
    problems = check_commands([c for path in DOCS for c in doc_commands(path)], tmp_path)
    assert not problems, f'{len(problems)} doc commands do not run as printed:\n' + '\n'.join(
        problems)


def test_check_finds_what_does_not_run(tmp_path):
    doc = tmp_path / 'x.md'
    doc.write_text('```sh\nmake demo nothing\nlandmark_nav info BAG --no-such-option\n'
                   'landmark_nav no-such-command\nlandmark_nav emulate urg --motion rotate\n'
                   'python benchmarks/bench_lines.py clusters --scans 3 --bogus 1\n'
                   'python benchmarks/bench_lines.py --scans 3\n'
                   'python benchmarks/no_such.py\nekf_slam --rate 2 --ros-args -p a:=1\n'
                   'no_such_node --ros-args\n'
                   'ros2 launch landmark_nav slam.launch.py laser_port:=/dev/x no_arg:=1\n'
                   'ros2 launch landmark_nav none.launch.py\n'
                   'ekf_slam --ros-args --params-file "$(landmark_nav config no_such)"\n'
                   'ekf_slam --help\nekf_slam --help --rate 2\n```\n')
    commands = doc_commands(doc)
    assert [w[0] for _, w in commands] == [
        'make', 'landmark_nav', 'landmark_nav', 'landmark_nav', 'python', 'python', 'python',
        'ekf_slam', 'ros2', 'ros2', 'ekf_slam', 'landmark_nav', 'ekf_slam',
        'ekf_slam']   # not no_such_node
    subs = _subcommands(_help_text([sys.executable, '-m', 'landmark_nav.tools.cli', '--help']))
    assert 'emulate' in subs
    assert check_commands(commands, tmp_path) == [
        "x.md:2: make ['nothing']: no such target",
        'x.md:8: benchmarks/no_such.py: no such script',
        "x.md:9: ekf_slam is a ROS node: options ['--rate'] before --ros-args",
        "x.md:11: slam.launch.py: no launch argument ['no_arg']",
        'x.md:12: none.launch.py: no such launch file in launch/',
        'x.md:13: landmark_nav config no_such: no config/no_such.yaml',
        "x.md:15: ekf_slam is a ROS node: options ['--help', '--rate'] before --ros-args",
        f"x.md:4: landmark_nav: subcommand 'no-such-command' not one of {subs}",
        "x.md:7: benchmarks/bench_lines.py: subcommand '--scans' not one of "
        "['clusters', 'logs']",
        'x.md:3: landmark_nav info: --no-such-option is not an option',
        'x.md:6: benchmarks/bench_lines.py clusters: --bogus is not an option']


def _help_text(argv: List[str]) -> str:
    return subprocess.run(argv, capture_output=True, text=True, cwd=REPO).stdout
