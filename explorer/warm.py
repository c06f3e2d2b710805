"""The first result of ``laav-explore``, computed in a child process from the command's start.

The server starts a session's computation once its page is on screen (so that it does not
slow the page down), and the first result came 4-6 s after the trajectories
(docs/bench/explorer_browser_latency.md). A forked child (at a lower priority: the page
comes first) computes the same :class:`laav.Pipeline` meanwhile, on the other core, without
holding the server's GIL, and sends its state back, then plain Random Voting's run shown
beside it; the first session's explorer takes them (``Explorer(pipeline=..., plain_rv=...)``),
so that its first result is ready, or nearly, when the page is. The labels are those
computed in-process (the same inputs, seed and code; ``tests/test_explorer_warm.py``).

No GUI imports here.
"""

from __future__ import annotations

import gc
import multiprocessing
import os
import pickle
import threading
from concurrent.futures import Future
from typing import NamedTuple

import laav

__all__ = ["Warm", "first_results", "pipeline_state", "pipeline_from_state"]

#: Attributes of a :class:`laav.Pipeline` that do not travel: the sequence (the parent has
#: it, and the explorer checks identity), the lock and the voting helper (a process handle).
_LOCAL = ("seq", "_lock", "helper")


def pipeline_state(pipe: laav.Pipeline) -> bytes:
    """A pipeline's computed state as bytes (without its sequence and lock)."""
    return pickle.dumps({k: v for k, v in vars(pipe).items() if k not in _LOCAL},
                        protocol=pickle.HIGHEST_PROTOCOL)


def pipeline_from_state(data: bytes, seq: laav.Sequence) -> laav.Pipeline:
    """The pipeline of :func:`pipeline_state` again, on ``seq`` (the sequence it was computed
    on): it updates like the original (:meth:`laav.Pipeline.update`)."""
    pipe = laav.Pipeline.__new__(laav.Pipeline)
    vars(pipe).update(pickle.loads(data))
    pipe.seq = seq
    pipe._lock = threading.Lock()
    pipe.helper = None
    missing = {"params", "n_motions", "seed", "result", "_stages", "full_shortlist"} - set(vars(pipe))
    if missing:  # laav.Pipeline changed its attributes: not usable, compute in-process
        raise ValueError(f"pipeline state without {sorted(missing)}")
    return pipe


class Warm(NamedTuple):
    """The first results computed in the child: Futures of the pipeline and of plain RV's
    run for the same settings (each None when the child could not deliver it), and of the
    pipeline's preview (:meth:`laav.Pipeline.update`'s ``preview``: the result with LAAV's
    own fine-tuning, before the rest of the fine-tuning; its value None when there was none;
    the Future itself None: not computed there)."""

    pipeline: Future
    plain_rv: Future
    preview: Future | None = None


def _child(conn, other_end, parent: int, seq, n_motions, params, seed) -> None:
    from laav._interrupt import interruptible

    from .state import Settings, explorer_pipeline, plain_rv_of

    # only the parent reads: with this end open here too, a send to a parent that has gone
    # would wait for ever (a state is larger than the pipe's buffer)
    other_end.close()
    # a short-lived job in a copy of the server's heap: a full collection walks all of it
    # (up to 0.3 s on the 2-core VM) and frees next to nothing; the process ends soon
    gc.disable()
    try:  # the page being served and drawn comes first on a busy machine
        os.nice(10)
    except OSError:
        pass
    orphaned = lambda: os.getppid() != parent  # noqa: E731 - the parent has gone: stop
    try:
        with interruptible(orphaned):  # checked between stages and once per voting iteration
            sent = []

            def preview(result):  # LAAV's own fine-tuning: shown while the rest computes
                conn.send_bytes(pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL))
                sent.append(True)

            try:
                data = pipeline_state(explorer_pipeline(seq, n_motions, params, seed, preview=preview))
            except BaseException:  # noqa: BLE001 - the parent then computes it itself
                data = b""
            if not sent:
                conn.send_bytes(b"")  # no preview
            conn.send_bytes(data)
            try:
                settings = Settings(laav.LaavParams() if params is None else params, seed, n_motions)
                data = pickle.dumps(plain_rv_of(seq, settings), protocol=pickle.HIGHEST_PROTOCOL)
            except BaseException:  # noqa: BLE001
                data = b""
            conn.send_bytes(data)
    except OSError:  # the parent has gone
        pass
    finally:
        conn.close()


#: Longest a held pipeline state waits for its release (:func:`first_results`' ``hold``).
HOLD_MAX_S = 5.0


def first_results(seq: laav.Sequence, n_motions: int, params: laav.LaavParams | None = None,
                  seed: int = 0, hold: threading.Event | None = None) -> Warm:
    """Start computing ``laav.Pipeline(seq, n_motions, params, seed)`` (its preview sent
    first), then plain Random Voting's run for the same settings
    (:func:`explorer.state.plain_rv_of`), in a forked child.

    Returns their Futures (:class:`Warm`); a Future's value is None when the child could not
    deliver it (no ``fork`` on this platform, the child failed or died): the explorer then
    computes it itself, as without this. Call before starting threads (a fork copies only
    the calling thread).

    ``hold``: the pipeline's state, once received, is rebuilt (unpickled) only when this
    event is set, or after :data:`HOLD_MAX_S`: rebuilding it imports what its stages hold
    (scipy.spatial's KD-tree: ~0.18 s of the interpreter), which fell on the first page's
    way when it arrived meanwhile; ``laav-explore`` sets it once the first page is built."""
    pipe_fut: Future = Future()
    rv_fut: Future = Future()
    preview_fut: Future = Future()
    try:
        ctx = multiprocessing.get_context("fork")
        recv, send = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_child, args=(send, recv, os.getpid(), seq, n_motions, params, seed),
                           name="laav-explore-first", daemon=True)
        proc.start()
        send.close()
    except (ValueError, OSError):  # no fork here
        for fut in (preview_fut, pipe_fut, rv_fut):
            fut.set_result(None)
        return Warm(pipe_fut, rv_fut, preview_fut)

    def wait() -> None:
        pipe = voting = preview = None
        try:
            data = recv.recv_bytes()
            preview = pickle.loads(data) if data else None
        except Exception:  # noqa: BLE001 - EOF (the child died) or an unusable result
            preview = None
        preview_fut.set_result(preview if isinstance(preview, laav.LaavResult) else None)
        try:
            data = recv.recv_bytes()
            if data:
                if hold is not None:
                    hold.wait(HOLD_MAX_S)
                pipe = pipeline_from_state(data, seq)
        except Exception:  # noqa: BLE001 - EOF (the child died) or an unusable state
            pipe = None
        pipe_fut.set_result(pipe)
        try:
            data = recv.recv_bytes()
            voting = pickle.loads(data) if data else None
        except Exception:  # noqa: BLE001
            voting = None
        finally:
            recv.close()
            proc.join(5)
        rv_fut.set_result(voting if isinstance(voting, laav.Voting) else None)

    threading.Thread(target=wait, name="laav-explore-first-wait", daemon=True).start()
    return Warm(pipe_fut, rv_fut, preview_fut)
