"""Locate the real recordings of ``../shared/data`` beside the repository root.

Tests and benchmarks that need real data call :func:`shared_data`; when the folder is not
there (a machine without the data), pytest skips with a reason naming the missing path.
"""

from pathlib import Path

#: ``<repository>/../shared/data``: where the real logs and images are looked for.
SHARED_DATA = Path(__file__).resolve().parents[2].parent / 'shared' / 'data'


def shared_data(*parts: str) -> Path:
    """Return ``../shared/data/<parts>``, or skip the calling test naming the missing path.

    Outside pytest (benchmarks, tools) a missing path raises :class:`FileNotFoundError`.
    """
    path = SHARED_DATA.joinpath(*parts)
    if not path.exists():
        reason = f'real data not found: {path} (see ../shared/data/README.md)'
        try:
            import pytest
        except ImportError:  # pragma: no cover - benchmarks without pytest
            raise FileNotFoundError(reason) from None
        pytest.skip(reason)
    return path
