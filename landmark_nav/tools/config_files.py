"""Where the shipped parameter files are: ``landmark_nav config NODE`` prints the path.

The files of ``config/`` are installed into ``share/landmark_nav/config`` (``setup.py``
data files): under the install prefix of a colcon build (the ament index) or under the
virtual environment's prefix of a pip install. In a source checkout (editable install or
``PYTHONPATH``) they are the repository's ``config/`` beside the package. So a command line
works from any directory::

    ekf_slam --ros-args --params-file "$(landmark_nav config ekf_slam)"

A *profile* is a file named ``<node>_<profile>.yaml`` that sets a few of the node's
parameters, given on top of its file (e.g. ``ekf_slam_chapter``: the chapter's filter);
``landmark_nav config`` lists the files, each profile with its node (:func:`listing`).
"""

from pathlib import Path
import sys
from typing import Dict, List

PACKAGE = 'landmark_nav'


def config_dirs() -> List[Path]:
    """Return the candidate directories of the parameter files, most specific first."""
    root = Path(__file__).resolve().parents[2]
    dirs = [root / 'config'] if (root / 'package.xml').is_file() else []  # a source checkout
    try:  # a colcon / ROS install
        from ament_index_python.packages import get_package_share_directory
        dirs.append(Path(get_package_share_directory(PACKAGE)) / 'config')
    except Exception:  # no ament index here, or the package is not in it
        pass
    dirs.append(Path(sys.prefix) / 'share' / PACKAGE / 'config')  # pip install
    return dirs


def config_path(node: str) -> Path:
    """Return the shipped parameter file of a node (e.g. ``ekf_slam``).

    Raises:
        FileNotFoundError: No directory holds ``<node>.yaml``; the message lists them and
            the names that have a file.

    """
    dirs = config_dirs()
    for d in dirs:
        path = d / f'{node}.yaml'
        if path.is_file():
            return path
    raise FileNotFoundError(
        f'no parameter file {node}.yaml in {", ".join(str(d) for d in dirs)}; the shipped '
        f'files: {", ".join(available()) or "none"} (an executable without one, such as '
        'bag_player, takes its options on its command line: --help)')


def available() -> List[str]:
    """Return the node names with a shipped parameter file."""
    for d in config_dirs():
        names = sorted(p.stem for p in d.glob('*.yaml'))
        if names:
            return names
    return []


def profiles() -> Dict[str, str]:
    """Return ``{profile file name: its node}`` of the shipped profiles."""
    names = available()
    return {name: node for name in names for node in names
            if name.startswith(node + '_')}


def listing() -> str:
    """Return the shipped files, one a line; a profile says its node and how to give it."""
    found = profiles()
    return '\n'.join(
        f'{name}  (profile of {found[name]}: --params-file "$(landmark_nav config '
        f'{found[name]})" --params-file "$(landmark_nav config {name})")'
        if name in found else name for name in available())
