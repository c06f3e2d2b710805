"""One BLAS/OpenMP thread for the pipeline's own work (threadpoolctl), restored after.

LAAV's matrices are small (a few hundred points, a few dozen frames): BLAS and OpenMP
threads only add synchronisation, and on a busy machine they wait for cores. Measured
with ``benchmarks/speed.py --threads``. ``laav bench --jobs N`` parallelises over
processes instead, each of which runs its sequences single-threaded.

BLAS thread pools are process-wide, so their limit is counted: concurrent runs (two
explorer sessions in one server) share one, set by the first to start and restored when
the last one ends, which may be another thread. threadpoolctl (>= 3.6) lets only one
thread at a time change OpenBLAS's pool and keeps that claim for a limit set outside a
``with`` block, so this module gives the claim back after each change (it would otherwise
turn the restoring thread's change into a no-op). OpenMP's thread count is per calling
thread, so every thread that runs the pipeline limits (and restores) its own. Nested runs
(``segment`` calling ``random_voting``) reuse the enclosing limit.
"""

from __future__ import annotations

import functools
import sys
import threading
from contextlib import contextmanager

__all__ = ["MAX_THREADS", "limited_threads", "single_threaded"]

#: Thread cap applied during a run; None disables the cap (``benchmarks/speed.py`` uses
#: that to measure the uncapped pipeline).
MAX_THREADS: int | None = 1

_lock = threading.Lock()
_blas_users = 0
_blas_limiter = None
_local = threading.local()  # .depth: nesting in this thread
_pools = None  # threadpoolctl's controller of the libraries the pipeline uses
_pools_modules = -1  # len(sys.modules) when _pools was made


@contextmanager
def limited_threads():
    """Cap BLAS/OpenMP thread pools at :data:`MAX_THREADS` inside the block."""
    global _blas_users, _blas_limiter, _pools, _pools_modules
    if MAX_THREADS is None or getattr(_local, "depth", 0):
        yield  # no cap, or already inside a capped block of this thread
        return
    from threadpoolctl import ThreadpoolController

    with _lock:
        if _pools is None or _pools_modules != len(sys.modules):
            # threadpoolctl sees only libraries already loaded: load scipy's BLAS (imported
            # lazily by the stages) first. Finding the libraries takes ~3 ms, so it is done
            # again only when modules were imported since (a library loaded later, e.g.
            # scikit-learn's OpenMP, was otherwise never capped in this process)
            from .pipeline import preload

            preload()
            _pools, _pools_modules = ThreadpoolController(), len(sys.modules)
        pools = _pools
        if _blas_users == 0:
            _release_openblas_claim()
            _blas_limiter = pools.select(user_api="blas").limit(limits=MAX_THREADS)
            _release_openblas_claim()
        _blas_users += 1
    openmp = pools.select(user_api="openmp").limit(limits=MAX_THREADS)  # this thread's
    _local.depth = 1
    try:
        yield
    finally:
        _local.depth = 0
        openmp.restore_original_limits()
        with _lock:
            _blas_users -= 1
            if _blas_users == 0:
                _release_openblas_claim()
                _blas_limiter.restore_original_limits()
                _release_openblas_claim()
                _blas_limiter = None


def _release_openblas_claim() -> None:
    """Let any thread change OpenBLAS's thread count again (see the module docstring)."""
    import threadpoolctl

    clear = getattr(getattr(threadpoolctl, "OpenBLASController", None), "clear_controlling_thread", None)
    if clear is not None:
        clear(force=True)


def single_threaded(func):
    """Decorator: run ``func`` inside :func:`limited_threads`."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        with limited_threads():
            return func(*args, **kwargs)

    return wrapper
