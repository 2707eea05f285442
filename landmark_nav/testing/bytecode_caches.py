"""Bytecode caches of a test run, written once before the pytest-xdist workers start.

Every worker imports every test module: pytest rewrites the module's asserts and compiles it
(its cache: ``__pycache__/<name>.<tag>-pytest-<version>.pyc``), and the package's modules are
compiled (``__pycache__/<name>.<tag>.pyc``), each unless its cache exists. On a fresh clone
the four workers of ``make test`` each did all of it (4.2 CPU-s per worker for the test
modules alone); :func:`write_bytecode_caches` does it once, on every CPU, so the workers
find the caches. A cache is written as the workers would write it: the rewriting is
pytest's own (:mod:`_pytest.assertion.rewrite`, the functions its import hook calls), and
an existing valid cache is left alone.
"""

from concurrent.futures import ProcessPoolExecutor
import multiprocessing
import os
from pathlib import Path
import py_compile
from typing import Iterable, List


def _rewritten_test_cache(path: str) -> None:
    """Write pytest's rewritten-code cache of one test module (as its import hook does)."""
    from _pytest.assertion import rewrite
    fn = Path(path)
    pyc = rewrite.get_cache_dir(fn) / (fn.name[:-3] + rewrite.PYC_TAIL)
    if rewrite._read_pyc(fn, pyc) is not None:
        return
    # the config only switches the assertion pass hook on (checked by the caller)
    source_hash, co = rewrite._rewrite_test(fn, None)
    if rewrite.try_makedirs(pyc.parent):
        rewrite._write_pyc(_NoTrace(), co, source_hash, pyc)


class _NoTrace:
    """The assertion state's tracer, for the messages of a failed cache write (dropped)."""

    @staticmethod
    def trace(message: str) -> None:
        """Drop the message (a cache that cannot be written is rewritten on import)."""


def _module_cache(path: str) -> None:
    """Compile one module into its ``__pycache__`` as its import would."""
    try:
        py_compile.compile(path, doraise=True,
                           invalidation_mode=py_compile.PycInvalidationMode.TIMESTAMP)
    except py_compile.PyCompileError:
        pass  # the import reports it


def _is_current(path: Path) -> bool:
    """Return whether ``path``'s timestamp cache exists and is not older than the source."""
    import importlib.util
    cache = Path(importlib.util.cache_from_source(str(path)))
    try:
        return cache.stat().st_mtime >= path.stat().st_mtime
    except OSError:
        return False


def write_bytecode_caches(test_modules: Iterable[Path], modules: Iterable[Path]) -> int:
    """Write the missing caches of ``test_modules`` (rewritten) and ``modules`` (compiled).

    Returns:
        The number of files handled (those whose cache was missing or stale).
    """
    from _pytest.assertion import rewrite
    jobs: List[tuple] = []
    for fn in test_modules:
        pyc = rewrite.get_cache_dir(fn) / (fn.name[:-3] + rewrite.PYC_TAIL)
        if rewrite._read_pyc(fn, pyc) is None:
            jobs.append((_rewritten_test_cache, str(fn)))
    jobs += [(_module_cache, str(p)) for p in modules if not _is_current(p)]
    if not jobs:
        return 0
    # forked before the workers exist: the test process holds no DDS or thread state yet
    with ProcessPoolExecutor(max_workers=os.cpu_count() or 1,
                             mp_context=multiprocessing.get_context('fork')) as pool:
        for done in [pool.submit(f, arg) for f, arg in jobs]:
            done.result()
    return len(jobs)


__all__ = ['write_bytecode_caches']
