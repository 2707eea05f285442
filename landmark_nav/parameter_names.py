"""Parameter names: the nearest declared name to an unknown one ("did you mean ...?").

The nodes reject an override of a parameter they do not declare (``-p`` or
``--params-file``) and the command line an unknown ``--set`` / ``--params-file`` name,
with the message of :func:`unknown_parameter`: a typo must not leave the default in force
while the user believes otherwise.
"""

import difflib
from typing import Iterable, Optional


def nearest_name(name: str, known: Iterable[str]) -> Optional[str]:
    """Return the known name closest to ``name`` (difflib ratio >= 0.6), or None."""
    known = list(known)
    match = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    if not match:  # a nested name: compare the last part (``odometry.sigma_xy`` -> ...)
        tail = name.rsplit('.', 1)[-1]
        by_tail = {k.rsplit('.', 1)[-1]: k for k in known}
        match = [by_tail[m] for m in difflib.get_close_matches(tail, list(by_tail), n=1,
                                                               cutoff=0.6)]
    return match[0] if match else None


def unknown_parameter(node: str, name: str, known: Iterable[str]) -> str:
    """Return the one-line message for an undeclared parameter ``name`` of ``node``."""
    near = nearest_name(name, known)
    hint = f' (did you mean {near}?)' if near else ''
    return f'{node} has no parameter {name!r}{hint}'
