"""Cooperative interruption of a long computation.

An application that runs the pipeline in a worker (the explorer) stops a run that a newer
request made useless: inside :func:`interruptible`, the pipeline calls :func:`check` between
its stages and Random Voting once per voting iteration, and ``check`` raises
:class:`Interrupted` when ``should_stop()`` is true. It is raised only there, never inside
clean-up code, so every ``finally`` (thread limits, the pipeline's roll-back) runs whole.
Without :func:`interruptible` (the default), ``check`` does nothing.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import contextmanager

__all__ = ["Interrupted", "check", "interruptible"]

_local = threading.local()


class Interrupted(Exception):
    """The computation was stopped by its ``should_stop`` (see :func:`interruptible`)."""


def check() -> None:
    """Raise :class:`Interrupted` when this thread's ``should_stop()`` is true."""
    stop = getattr(_local, "should_stop", None)
    if stop is not None and stop():
        raise Interrupted


@contextmanager
def interruptible(should_stop: Callable[[], bool]):
    """Inside, this thread's pipeline runs stop at their next :func:`check` once
    ``should_stop()`` returns true."""
    prev = getattr(_local, "should_stop", None)
    _local.should_stop = should_stop
    try:
        yield
    finally:
        _local.should_stop = prev
