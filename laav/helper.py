"""A second process for LAAV's own candidates: speed only, the labels do not change.

LAAV's fine-tuning (``rv_select="laav"``, the default on complete tracks) runs its informed
trial and ``rv_missing_trials`` trials from every missing-motion start it runs (with
``rv_missing_gate``, the default, the informed trial first and alone, here, then the starts
its result leaves unexplained), up to 7 trials that do not depend on one another (each
draws from its own random stream and keeps its own convergence test,
:func:`laav.own_chain.informed_side_by_side`), then polishes each distinct result and scores
it (:func:`laav.own_chain.candidate_part`). With a :class:`VotingHelper`
(``laav.Pipeline(..., helper=...)``, ``laav.random_voting(..., helper=...)``) every other
start's trial, polish and score run in the helper's process while this one does the rest,
on the machine's second core; the results are those of doing it all here
(``tests/test_helper.py``).

Numpy's small-array calls hold the interpreter lock, so threads do not help here; a process
does. The helper is started once (``spawn``: safe beside threads) and kept: a three-motion
fine-tuning takes 0.1-0.3 s, far too short to start a process for.

A computation stopped by :mod:`laav._interrupt` stops the helper's part too, at its next
voting iteration. If the helper's process dies, the part it held runs here instead.
"""

from __future__ import annotations

import itertools
import multiprocessing
import os
import threading
import time
import warnings
import weakref
from concurrent.futures import CancelledError, ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures.process import BrokenProcessPool

__all__ = ["VotingHelper"]

#: How often (s) the caller, waiting for the helper's half, checks its own stop request.
_POLL_S = 0.01
#: How often (s) the helper's process checks that its parent is still there.
_PARENT_POLL_S = 0.5

#: Jobs stopped, most recent last, in a ring of this many (shared with the process): jobs
#: are stopped by their exact id. (Not "every job up to an id": the pool hands the process
#: up to two more jobs than it runs, marked running, so a queued job of another caller can
#: be stopped while an earlier one runs.)
_STOPPED_RING = 32
#: After this many times the process died, the helper closes itself (a process that cannot
#: start, e.g. a script without ``if __name__ == "__main__":``, would otherwise be started
#: again for every fine-tuning).
_MAX_RESTARTS = 3

_stopped = None  # in the helper's process: the shared ring of stopped job ids


def _init(stopped, parent: int) -> None:
    global _stopped
    _stopped = stopped
    # a parent killed without clean-up (SIGTERM, SIGKILL) leaves this process waiting for
    # work for ever: it ends once the parent has gone
    threading.Thread(target=_end_with, args=(parent,), name="laav-helper-parent",
                     daemon=True).start()


def _end_with(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(_PARENT_POLL_S)
    os._exit(0)


def _warm() -> None:
    """In the helper's process: import what a job needs, before the first one."""
    from . import _interrupt, _threads, voting  # noqa: F401


def _run(job: int, func, args: tuple):
    """In the helper's process: ``func(*args)`` with one BLAS thread, stopped (raising
    :class:`laav._interrupt.Interrupted`) at its next check once the job is stopped."""
    from ._interrupt import interruptible
    from ._threads import limited_threads

    with limited_threads(), interruptible(lambda: job in _stopped[:]):
        return func(*args)


def _candidate_part(*args) -> tuple:
    """:func:`laav.own_chain.candidate_part` without its memo of fits (which stays here)."""
    from .own_chain import candidate_part

    results, finished, cost, _ = candidate_part(*args)
    return results, finished, cost


def _close_at_exit(helper: VotingHelper) -> None:
    """Close ``helper`` when the interpreter exits, before ``concurrent.futures`` waits for
    the running job (an ``atexit`` handler would run only after that wait): through
    ``threading``'s exit hooks, which run in reverse order of registration, so after the
    pool module's own hook was registered (at its import) this one runs first. Weakly: a
    helper no longer used is not kept alive by it."""
    ref = weakref.ref(helper)

    def close() -> None:
        h = ref()
        if h is not None:
            h.close()

    try:
        threading._register_atexit(close)
    except (AttributeError, RuntimeError):  # no such hook (another Python), or exiting already
        import atexit

        atexit.register(close)


class VotingHelper:
    """A process that runs part of LAAV's own voting trials (module docstring).

    Parameters
    ----------
    start : bool
        Start the process now (default); else at the first use. Until it is up and has
        imported what a job needs (:attr:`ready`, a second or two), the callers compute
        everything themselves: a computation never waits for the process to start.

    Notes
    -----
    One helper may serve several pipelines and threads: its process runs one job at a
    time, the others wait their turn. :meth:`close` ends it (also at interpreter exit,
    without waiting for a running job's end).
    As with any ``multiprocessing`` code, a script must create it under
    ``if __name__ == "__main__":`` (the process imports the script's main module); if the
    process cannot start or keeps dying, the helper closes itself after
    :data:`_MAX_RESTARTS` tries and every computation runs in the caller's process.

    Attributes
    ----------
    jobs : int
        Jobs handed to the process so far.
    delivered : int
        Jobs whose value the process delivered (the others were computed by the caller).

    Examples
    --------
    >>> helper = VotingHelper()                             # doctest: +SKIP
    >>> pipe = laav.Pipeline(seq, 3, helper=helper)         # doctest: +SKIP
    >>> helper.close()                                      # doctest: +SKIP
    """

    def __init__(self, start: bool = True):
        self._lock = threading.Lock()
        self._ctx = multiprocessing.get_context("spawn")
        self._stopped = self._ctx.Array("q", [-1] * _STOPPED_RING, lock=False)
        self._next_stop = 0
        self._ids = itertools.count()
        self._pool: ProcessPoolExecutor | None = None
        self._restarts = 0
        self._closed = False
        self.jobs = 0
        self.delivered = 0
        self._ready = None  # the new process's imports (a Future), while they run
        self._unfinished: set = set()  # ids of the jobs handed over and not yet finished
        self._unfinished_lock = threading.Lock()  # (done callbacks run in the pool's thread)
        _close_at_exit(self)
        if start:
            with self._lock:
                try:
                    self._ensure()
                except (BrokenProcessPool, RuntimeError, OSError):
                    self._broken(self._pool)

    def _ensure(self) -> ProcessPoolExecutor:
        if self._pool is None:
            pool = ProcessPoolExecutor(1, mp_context=self._ctx, initializer=_init,
                                       initargs=(self._stopped, os.getpid()))
            # the process and its imports, now (a second or two of one core): until they
            # are done no job is taken, the callers compute their parts themselves. A pool
            # whose process dies at once (e.g. a script that makes a helper at import,
            # which spawn runs again in the child) is never kept without its readiness.
            self._pool, self._ready = pool, None
            try:
                self._ready = pool.submit(_warm)
            except (BrokenProcessPool, RuntimeError, OSError):
                self._broken(pool)  # (counted: a helper whose process keeps dying closes)
                raise
        return self._pool

    @property
    def ready(self) -> bool:
        """Whether the process is up and has imported what a job needs (until then, and
        after it died until a new one is, :meth:`submit` returns None)."""
        with self._lock:
            return (not self._closed and self._pool is not None and self._ready is not None
                    and self._ready.done() and self._ready.exception() is None)

    def wait_ready(self, timeout: float = 60.0) -> bool:
        """Wait until :attr:`ready` (starting the process if needed); False on timeout or
        when the helper is closed."""
        with self._lock:
            if self._closed:
                return False
            try:
                self._ensure()
                fut = self._ready
            except (BrokenProcessPool, RuntimeError, OSError):
                self._broken(self._pool)
                return False
        try:
            fut.result(timeout=timeout)
        except Exception:  # noqa: BLE001 - died, or timed out
            return False
        return self.ready

    def _broken(self, pool) -> None:
        """(Under the lock.) ``pool``'s process died: a new one at the next use, unless it
        died too often (then closed for good)."""
        if pool is not None and pool is self._pool:
            self._pool = None
            self._restarts += 1
            if self._restarts >= _MAX_RESTARTS:
                self._closed = True
                warnings.warn(f"laav.VotingHelper: its process died {self._restarts} times; "
                              "computing without it (in a script, create the helper under "
                              "`if __name__ == '__main__':`)", RuntimeWarning, stacklevel=3)
            pool.shutdown(wait=False, cancel_futures=True)

    def submit(self, args: tuple) -> tuple | None:
        """Start :func:`laav.own_chain.candidate_part` on ``args`` in the helper's process (its
        value without the memo of fits): a handle for :meth:`result` and :meth:`stop`, or
        None when the helper is closed or broken."""
        return self.submit_call(_candidate_part, *args)

    def submit_call(self, func, *args) -> tuple | None:
        """Start ``func(*args)`` in the helper's process (``func`` importable by name, the
        arguments and value picklable; the laav computations in it stop at their checks
        when the job is stopped): a handle for :meth:`result` and :meth:`stop`, or None when
        the helper is closed or broken. The explorer runs plain Random Voting for its RV
        card so."""
        with self._lock:
            if self._closed:
                return None
            pool = None
            try:
                pool = self._ensure()
                if not self._ready.done():  # still starting: the caller computes it now
                    return None
                job = next(self._ids)
                fut = pool.submit(_run, job, func, args)
                handle = job, fut, pool
                with self._unfinished_lock:
                    self._unfinished.add(job)
                fut.add_done_callback(lambda _f, job=job: self._finished(job))
            except (BrokenProcessPool, RuntimeError, OSError):  # died, shutting down, no process
                self._broken(pool)
                return None
            self.jobs += 1
            return handle

    def result(self, handle: tuple, check):
        """The value of the job of ``handle``, waiting for it; ``check()`` is called while
        waiting (the caller's own stop request: it may raise, and the helper's job then
        stops at its next check). None whenever the helper did not deliver it: its process
        died, the helper was closed, the job was stopped by someone else or failed (e.g.
        arguments that do not pickle); the caller then computes it itself, and an error of
        the computation itself is raised there, as without a helper."""
        job, fut, pool = handle
        while True:
            try:
                value = fut.result(timeout=_POLL_S)
                break
            except FutureTimeout:
                pass
            except (BrokenProcessPool, CancelledError):  # died, or dropped by close()
                with self._lock:
                    if not self._closed:
                        self._broken(pool)
                return None
            except Exception:  # noqa: BLE001 - stopped elsewhere, or failed: the caller computes it
                return None
            try:
                check()
            except BaseException:
                self.stop(handle)
                raise
        with self._lock:
            self.delivered += 1
        return value

    def stop(self, handle: tuple) -> None:
        """Stop the job of ``handle``: not started, it never starts; running, it stops at
        its next check. Other jobs are not affected."""
        job, fut, _ = handle
        if not fut.cancel():
            with self._lock:
                self._stop_id(job)

    def _finished(self, job: int) -> None:
        with self._unfinished_lock:
            self._unfinished.discard(job)

    def _stop_id(self, job: int) -> None:
        """(Under the lock.) Job ``job`` stops at its next check in the process."""
        self._stopped[self._next_stop % _STOPPED_RING] = job
        self._next_stop += 1

    def close(self) -> None:
        """End the helper's process: the jobs queued are dropped, a running one stops at its
        next check (a voting iteration: at interpreter exit nothing waits for a job's end);
        the callers waiting compute their parts themselves."""
        with self._lock:
            self._closed = True
            pool, self._pool = self._pool, None
            with self._unfinished_lock:
                unfinished = sorted(self._unfinished)
            for job in unfinished[:_STOPPED_RING]:  # the oldest: the running one and those handed over
                self._stop_id(job)
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> VotingHelper:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
