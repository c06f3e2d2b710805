"""The seed sweep: LAAV on one sequence with seeds 0-9, in the background (no GUI imports).

LAAV's random stages (atoms, the fine-to-coarse merge, Random Voting) draw from the seed,
so one result can be a typical one or a bad draw. :class:`SeedSweep` runs
:func:`laav.segment` with the sequence, C and parameters shown and one seed after another
on its own worker thread, and reports each seed's :class:`SeedRow` as it is done: every
stage's error against the ground truth (fine models, coarse, final; the same measures as
the Numbers card, :func:`explorer.views.stage_numbers`) or, without ground truth, the
share of points on which the seed agrees with the first seed's final labels and the
segmentation it gives (seeds grouped by their final labels, :func:`segmentation_groups`),
and how Random Voting converged.

Each seed's :class:`laav.Pipeline` (whose labels equal :func:`laav.segment`'s; it scores
the joint merge's whole shortlist, as every explorer pipeline does, for card 3) can be
handed on (``on_pipeline``): the explorer keeps it, so that a click on the seed's row
shows it at once instead of computing it again.

A newer sweep, :meth:`SeedSweep.cancel` or :meth:`SeedSweep.close` stops the one running
at its next Python step (the seed being computed is dropped); the explorer cancels it when
the parameters, C or the sequence change (a seed change keeps it: the rows stay valid).
"""

from __future__ import annotations

import dataclasses
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

import laav
from laav import LaavParams
from laav._interrupt import interruptible

from .state import Cancelled, explorer_pipeline
from .views import labelling_distance, stage_numbers

__all__ = ["SEEDS", "SeedRow", "SweepKey", "SeedSweep", "seed_row", "worst_seed", "worst_stage",
           "worst_note", "table_columns", "header_line", "row_line", "segmentation_groups", "group_name",
           "SAME_SEGMENTATION"]

#: The seeds one sweep runs.
SEEDS = tuple(range(10))


@dataclasses.dataclass(frozen=True)
class SweepKey:
    """What a sweep's rows depend on: the sequence (by identity), C and the parameters."""

    sequence: laav.Sequence
    n_motions: int
    params: LaavParams

    def __eq__(self, other) -> bool:
        return (isinstance(other, SweepKey) and self.sequence is other.sequence
                and self.n_motions == other.n_motions and self.params == other.params)

    def __hash__(self) -> int:
        return hash((id(self.sequence), self.n_motions, self.params))


@dataclasses.dataclass(frozen=True, eq=False)
class SeedRow:
    """One seed's outcome.

    Attributes
    ----------
    seed : int
    error_fine, error_coarse, error_final : float or None
        Misclassification rates (fractions) of the stages against the ground truth, as the
        Numbers card measures them (fine and coarse on the points in atoms, a fine model
        counted as its majority true motion); None without ground truth.
    agreement : float
        Share of points whose final motion is the same as with the sweep's first seed
        (after the best matching of motions, ``1 - labelling_distance``: a point both leave
        unlabelled is no difference).
    converged : bool
        Whether LAAV's informed trial converged (plain RV, without one: the returned trial),
        as card 4 says.
    iterations : int
        That trial's iterations, as card 4 counts them.
    all_iterations : int
        Random Voting iterations of the run, every trial's (``Voting.n_iterations``).
    seconds : float
        Time of this seed's pipeline (:func:`laav.segment`'s labels; the joint merge's whole
        shortlist scored, a few ms more than the library's default).
    labels : numpy.ndarray
        The final labels.
    """

    seed: int
    error_fine: float | None
    error_coarse: float | None
    error_final: float | None
    agreement: float
    converged: bool
    iterations: int
    all_iterations: int
    seconds: float
    labels: np.ndarray


def seed_row(seq: laav.Sequence, result: laav.LaavResult, reference: np.ndarray | None,
             seconds: float = 0.0) -> SeedRow:
    """The :class:`SeedRow` of ``result`` (``reference``: the first seed's final labels,
    None when this is the first seed)."""
    num = stage_numbers(seq, result)
    labels = np.asarray(result.labels)
    agree = 1.0 if reference is None else 1.0 - labelling_distance(reference, labels)

    def f(v):
        return None if v is None else float(v)

    v = result.voting
    own = v.informed_changed is not None  # LAAV's informed trial, as card 4 describes it
    return SeedRow(int(result.seed), f(num["error_fine"]), f(num["error_coarse"]), f(num["error_final"]),
                   agree, bool(v.informed_converged if own else v.converged),
                   len(v.informed_changed if own else v.changed), int(v.n_iterations),
                   float(seconds), labels)


#: Without ground truth, a seed gives a group's segmentation when its final labels agree with
#: the group's first seed's on at least this share of the points (motions matched one to one,
#: :func:`explorer.views.labelling_distance`).
SAME_SEGMENTATION = 0.99


def segmentation_groups(rows: Sequence[SeedRow]) -> list[list[int]]:
    """The rows (indices) grouped by the segmentation they give, in seed order: a row joins
    the first group whose first row's final labels agree with its own on at least
    :data:`SAME_SEGMENTATION` of the points, else starts a group (so two seeds of one group
    may differ on up to twice the rest, and another order of the rows could group them
    otherwise; seeds 0-9 come in order). Without ground truth the
    sweep shows these groups, not a "worst" seed: which of two segmentations is right, the
    seeds cannot say (and agreement with seed 0 would make seed 0's the reference)."""
    groups: list[list[int]] = []
    for i, r in enumerate(rows):
        for g in groups:
            first = rows[g[0]].labels
            if 1.0 - labelling_distance(first, r.labels) >= SAME_SEGMENTATION:
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def group_name(k: int) -> str:
    """The name of the k-th segmentation: A, B, …, Z, then 27, 28, …"""
    return chr(ord("A") + k) if k < 26 else str(k + 1)


def worst_seed(rows: Sequence[SeedRow]) -> int | None:
    """The seed of the worst row, with ground truth: the highest final error, then coarse,
    then fine; among equals the most iterations. None for no rows, when every row scores the
    same, or without ground truth (:func:`segmentation_groups` then)."""
    if not rows or rows[0].error_final is None:
        return None
    if len({_errors(r) for r in rows}) == 1:
        return None  # every seed scores the same: none is worse
    return max(rows, key=lambda r: (*_errors(r), r.all_iterations)).seed


def _errors(r: SeedRow) -> tuple[float, float, float]:
    """A row's final, coarse and fine errors: what :func:`worst_seed` ranks by, in order."""
    return (r.error_final, r.error_coarse or 0.0, r.error_fine or 0.0)


def worst_stage(rows: Sequence[SeedRow]) -> str | None:
    """The stage whose error decides :func:`worst_seed`: ``"final"`` when the seeds' final
    errors differ, else ``"coarse"``, else ``"fine"`` (every seed ends equally right or
    wrong: the worst is only the worst start); None when there is no worst seed."""
    if worst_seed(rows) is None:
        return None
    return next(stage for i, stage in enumerate(("final", "coarse", "fine"))
                if len({_errors(r)[i] for r in rows}) > 1)


def worst_note(rows: Sequence[SeedRow]) -> str:
    """The worst row's note: "◀ worst", or "◀ worst coarse" / "◀ worst fine" when every
    seed's final error is the same (:func:`worst_stage`)."""
    stage = worst_stage(rows)
    return "◀ worst" if stage in (None, "final") else f"◀ worst {stage}"


def _pct(v: float | None) -> str:
    return "–" if v is None else f"{100 * v:.1f} %"


def table_columns(rows: Sequence[SeedRow]) -> dict:
    """The rows as table columns of text (and the worst row's marks): ``seed`` (int),
    ``fine``, ``coarse``, ``final``, ``agreement``, ``group`` (the segmentation, e.g. "B (6
    of 10)", :func:`segmentation_groups`), ``converged``, ``iterations``, ``time``, ``note``
    (:func:`worst_note` on the worst row, with ground truth)."""
    worst = worst_seed(rows) if len(rows) > 1 else None
    note = worst_note(rows)
    group = [""] * len(rows)
    for k, g in enumerate(segmentation_groups(rows)):
        for i in g:
            group[i] = f"{group_name(k)} ({len(g)} of {len(rows)})"
    return {
        "group": group,
        "seed": [r.seed for r in rows],
        "fine": [_pct(r.error_fine) for r in rows],
        "coarse": [_pct(r.error_coarse) for r in rows],
        "final": [_pct(r.error_final) for r in rows],
        "agreement": [_pct(r.agreement) for r in rows],
        "converged": ["yes" if r.converged else "no (cap)" for r in rows],
        "iterations": [str(r.iterations) if r.all_iterations == r.iterations
                       else f"{r.iterations} (of {r.all_iterations})" for r in rows],
        "time": [f"{1000 * r.seconds:.0f} ms" for r in rows],
        "note": [note if r.seed == worst else "" for r in rows],
    }


#: The table's columns, with and without ground truth: (key of :func:`table_columns`, title).
_COLUMNS = {True: (("seed", "seed"), ("fine", "fine models"), ("coarse", "coarse"), ("final", "final"),
                   ("converged", "converged"), ("iterations", "iterations"), ("time", "time")),
            False: (("seed", "seed"), ("group", "segmentation"), ("agreement", "same as seed 0"),
                    ("converged", "converged"), ("iterations", "iterations"), ("time", "time"))}


#: Characters of the widest cell a column holds (beyond its title): "150 (of 1050)", "1015 ms".
_CELL_CHARS = {"iterations": 13, "group": 12, "time": 7}


def _widths(has_truth: bool) -> list[int]:
    return [max(len(title), 6, _CELL_CHARS.get(key, 0)) for key, title in _COLUMNS[has_truth]]


def header_line(has_truth: bool) -> str:
    """The table's header as one line of fixed-width text (see :func:`row_line`)."""
    return "  ".join(t.rjust(w) for (_, t), w in zip(_COLUMNS[has_truth], _widths(has_truth)))


def row_line(table: dict, i: int, has_truth: bool) -> str:
    """Row ``i`` of :func:`table_columns` as one line of fixed-width text, aligned under
    :func:`header_line`, ending in its note ("◀ worst")."""
    cells = [str(table[k][i]).rjust(w) for (k, _), w in zip(_COLUMNS[has_truth], _widths(has_truth))]
    return "  ".join(cells) + ("  " + table["note"][i] if table["note"][i] else "")


class SeedSweep:
    """Runs seed sweeps on a worker thread of its own, one at a time.

    ``on_row(sweep_id, row, done, total)`` is called after each seed and
    ``on_end(sweep_id, rows, cancelled)`` once at the end, both **from the worker thread**;
    ``on_pipeline(seq, n_motions, params, seed, pipeline)`` (optional, from the worker
    thread too) receives each seed's finished :class:`laav.Pipeline` before its row.
    """

    def __init__(self, on_row: Callable | None = None, on_end: Callable | None = None,
                 on_pipeline: Callable | None = None) -> None:
        self.on_row, self.on_end, self.on_pipeline = on_row, on_end, on_pipeline
        self._worker = ThreadPoolExecutor(1, thread_name_prefix="laav-explore-sweep")
        self._lock = threading.Lock()
        self._id = 0  # the newest sweep; an older one stops at its next check
        self._active = False
        self._busy = False  # the worker is inside a sweep
        self.key: SweepKey | None = None  # the newest sweep's settings
        self.rows: list[SeedRow] = []
        self.closed = False

    @property
    def sweep_id(self) -> int:
        return self._id

    @property
    def running(self) -> bool:
        return self._active

    def start(self, seq: laav.Sequence, n_motions: int, params: LaavParams,
              seeds: Sequence[int] = SEEDS) -> int:
        """Sweep ``seeds`` on ``seq`` with C = ``n_motions`` and ``params`` (a sweep still
        running is cancelled). Returns the sweep's id, as passed to the callbacks."""
        if self.closed:
            raise RuntimeError("the sweep was closed")
        self.cancel()
        with self._lock:
            self._id += 1
            sid = self._id
            self.key = SweepKey(seq, int(n_motions), params)
            self.rows = []
            self._active = True
        self._worker.submit(self._run, sid, seq, int(n_motions), params, tuple(int(s) for s in seeds))
        return sid

    def cancel(self) -> bool:
        """Stop the sweep running (its next seed is not started, the one computing is
        interrupted). Returns False when none was running."""
        with self._lock:
            if not self._active:
                return False
            self._id += 1  # the seed computing stops at its next check (laav._interrupt)
            self._active = False
        return True

    def matches(self, seq: laav.Sequence, n_motions: int, params: LaavParams) -> bool:
        """The newest sweep was made with these settings."""
        return self.key is not None and self.key == SweepKey(seq, int(n_motions), params)

    def _run(self, sid: int, seq, C: int, params, seeds) -> None:
        self._busy = True
        try:
            self._sweep(sid, seq, C, params, seeds)
        finally:
            self._busy = False

    def _sweep(self, sid: int, seq, C: int, params, seeds) -> None:
        rows: list[SeedRow] = []
        cancelled = False
        reference = None
        try:
            for i, seed in enumerate(seeds):
                if sid != self._id:
                    raise Cancelled
                t0 = time.perf_counter()
                with interruptible(lambda: sid != self._id):  # raises Cancelled when stale
                    pipe = explorer_pipeline(seq, C, params, seed)  # laav.segment's labels
                result = pipe.result
                dt = time.perf_counter() - t0
                if sid != self._id:
                    raise Cancelled
                if self.on_pipeline is not None:
                    try:
                        self.on_pipeline(seq, C, params, seed, pipe)
                    except Exception:  # keeping it is a convenience: the sweep goes on
                        traceback.print_exc()
                row = seed_row(seq, result, reference, dt)
                if reference is None:
                    reference = row.labels
                rows.append(row)
                with self._lock:
                    if sid != self._id:
                        raise Cancelled
                    self.rows = list(rows)
                if self.on_row is not None:
                    self.on_row(sid, row, i + 1, len(seeds))
        except Cancelled:
            cancelled = True
        except Exception:  # an algorithm bug must not kill the worker
            traceback.print_exc()
            cancelled = True
        with self._lock:
            if sid == self._id:
                self._active = False
        if self.on_end is not None:
            try:
                self.on_end(sid, rows, cancelled)
            except Exception:
                traceback.print_exc()

    def wait(self, timeout: float = 60.0) -> bool:
        """Block until no sweep is running (tests)."""
        deadline = time.monotonic() + timeout
        while self._active or self._busy:
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)
        return True

    def close(self) -> None:
        self.closed = True
        self.cancel()
        self._worker.shutdown(wait=False, cancel_futures=True)
