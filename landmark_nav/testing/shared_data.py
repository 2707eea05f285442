"""Locate the real recordings of ``../shared/data`` beside the repository root.

Tests and benchmarks that need real data call :func:`shared_data`; when the folder is not
there (a machine without the data), pytest skips with a reason naming the missing path.
"""

from pathlib import Path
import sys

#: ``<repository>/../shared/data``: where the real logs and images are looked for.
SHARED_DATA = Path(__file__).resolve().parents[2].parent / 'shared' / 'data'


def shared_data(*parts: str) -> Path:
    """Return ``../shared/data/<parts>``, or skip the calling test naming the missing path.

    Outside pytest (benchmarks, tools: pytest not imported) a missing path raises
    :class:`FileNotFoundError` with the same message.
    """
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        reason = f'real data not found: {path} (see ../shared/data/README.md)'
        pytest = sys.modules.get('pytest')
        if pytest is None:  # a benchmark or tool, even where pytest is installed
            raise FileNotFoundError(reason)
        pytest.skip(reason)
    return path
