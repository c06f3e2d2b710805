"""A second process for LAAV's own candidates: speed only, the labels do not change.

LAAV's fine-tuning (``rv_select="laav"``, the default on complete tracks) runs its informed
trial and ``rv_missing_trials`` trials from every missing-motion start, 3-7 trials that do
not depend on one another (each draws from its own random stream and keeps its own
convergence test, :func:`laav.voting._informed_side_by_side`), then polishes each distinct
result and scores it (:func:`laav.voting.candidate_part`). With a :class:`VotingHelper`
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
from concurrent.futures import CancelledError, Future, ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from concurrent.futures.process import BrokenProcessPool

__all__ = ["VotingHelper"]

#: How often (s) the caller, waiting for the helper's half, checks its own stop request.
_POLL_S = 0.01
#: How often (s) the helper's process checks that its parent is still there.
_PARENT_POLL_S = 0.5

#: in the helper's process: every job whose id is at most this stops (a shared integer; the
#: process runs its jobs one at a time, in the order submitted, so a stopped job's id is
#: never below a job that still runs)
_cancelled = None


def _init(cancelled, parent: int) -> None:
    global _cancelled
    _cancelled = cancelled
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

    with limited_threads(), interruptible(lambda: _cancelled.value >= job):
        return func(*args)


def _candidate_part(*args) -> tuple:
    """:func:`laav.voting.candidate_part` without its memo of fits (which stays here)."""
    from .voting import candidate_part

    results, finished, cost, _ = candidate_part(*args)
    return results, finished, cost


class VotingHelper:
    """A process that runs part of LAAV's own voting trials (module docstring).

    Parameters
    ----------
    start : bool
        Start the process now (default), so that the first fine-tuning does not wait for
        it; else at the first use.

    Notes
    -----
    One helper may serve several pipelines and threads: its process runs one half at a
    time, the others wait their turn. :meth:`close` ends it (also at interpreter exit).

    Examples
    --------
    >>> helper = VotingHelper()                             # doctest: +SKIP
    >>> pipe = laav.Pipeline(seq, 3, helper=helper)         # doctest: +SKIP
    >>> helper.close()                                      # doctest: +SKIP
    """

    def __init__(self, start: bool = True):
        self._lock = threading.Lock()
        self._ctx = multiprocessing.get_context("spawn")
        self._cancelled = self._ctx.Value("q", -1, lock=False)
        self._ids = itertools.count()
        self._pool: ProcessPoolExecutor | None = None
        self._closed = False
        #: jobs handed to the process so far (each one half of a fine-tuning's trials)
        self.jobs = 0
        if start:
            with self._lock:
                self._ensure().submit(_warm)  # the process and its imports, now

    def _ensure(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._pool = ProcessPoolExecutor(1, mp_context=self._ctx, initializer=_init,
                                             initargs=(self._cancelled, os.getpid()))
        return self._pool

    def submit(self, args: tuple) -> tuple[int, Future] | None:
        """Start :func:`laav.voting.candidate_part` on ``args`` in the helper's process (its
        value without the memo of fits): (job id, Future), or None when the helper is closed
        or broken."""
        return self.submit_call(_candidate_part, *args)

    def submit_call(self, func, *args) -> tuple[int, Future] | None:
        """Start ``func(*args)`` in the helper's process (``func`` importable by name, the
        arguments and value picklable; the laav computations in it stop at their checks
        when the job is stopped): (job id, Future), or None when the helper is closed or
        broken. The explorer runs plain Random Voting for its RV card so."""
        with self._lock:
            if self._closed:
                return None
            job = next(self._ids)
            try:
                handle = job, self._ensure().submit(_run, job, func, args)
                self.jobs += 1
                return handle
            except (BrokenProcessPool, RuntimeError):  # died, or shutting down
                self._pool = None
                return None

    def result(self, handle: tuple[int, Future], check):
        """The value of the job of ``handle``, waiting for it; ``check()`` is called while
        waiting (the caller's own stop request: it may raise, and the helper's job then
        stops at its next voting iteration). None when the helper could not deliver it
        (its process died): the caller computes it itself. An exception of the job is
        raised here."""
        job, fut = handle
        try:
            while True:
                try:
                    return fut.result(timeout=_POLL_S)
                except FutureTimeout:
                    check()
        except (BrokenProcessPool, CancelledError):
            with self._lock:
                self._pool = None  # a new process at the next use
            return None
        except BaseException:
            self.stop(handle)
            raise

    def stop(self, handle: tuple[int, Future]) -> None:
        """Stop the job of ``handle``: not started, it never starts; running, it stops at
        its next voting iteration."""
        job, fut = handle
        if not fut.cancel():
            with self._lock:
                self._cancelled.value = max(self._cancelled.value, job)

    def close(self) -> None:
        """End the helper's process (a running job is stopped first)."""
        with self._lock:
            self._closed = True
            pool, self._pool = self._pool, None
        if pool is not None:
            self._cancelled.value = 2**62  # every job
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> VotingHelper:
        return self

    def __exit__(self, *exc) -> None:
        self.close()
