"""Per-session state of the explorer: the sequence, its :class:`laav.Pipeline`, a worker thread.

No GUI imports here. The app sets :attr:`ExplorerState.on_result` and friends; they are
called **from worker threads**, so the app must hop to its document thread itself.

Live recomputation
------------------
Every request (a parameter change, a new sequence) validates the settings at once with
:class:`laav.LaavParams` (an invalid combination is reported immediately and changes
nothing), then bumps a *generation counter* and queues a job on a single worker thread.
A newer request supersedes the computation running at once: it stops at the pipeline's
next check (between stages, once per voting iteration; :class:`Superseded`, see
:mod:`laav._interrupt`) and :meth:`laav.Pipeline.update` rolls back to its last result, so
the next job starts from a consistent pipeline. A job whose
generation is no longer the newest when it starts is skipped, and a result whose
generation is no longer the newest when it finishes is dropped, so a burst of slider moves
computes only the newest one, and the views only ever receive whole results of the newest
request.

Plain Random Voting from a random start (the comparison shown beside LAAV's fine-tuning)
runs on a second worker thread, once per sequence/seed/RV settings, and is cached. It
yields to LAAV: a new request interrupts it too (it is asked for again with the next
result), so it never slows down the computation the user is waiting for.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import threading
import time
import traceback
from collections import OrderedDict, deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from contextlib import contextmanager

import numpy as np

import laav
from laav import MIN_POINTS, LaavParams, LaavResult, Pipeline, Sequence
from laav._interrupt import Interrupted, interruptible
from laav._interrupt import check as check_interrupt
from laav.params import _BOUNDS
from laav.voting import NOT_PLAIN_FIELDS, SELECTION_FIELDS

from .views import COLOR_MODES, TRUTH_MODES, align_labels, stage_numbers

__all__ = ["ExplorerState", "Superseded", "Cancelled", "Settings", "RV_FIELDS", "Change", "describe_change",
           "non_defaults", "PARAM_NAMES", "URL_KEYS", "VIEW_COLORS", "parse_settings", "query_of",
           "settings_from_json", "parse_value", "Origin", "params_file_note", "check_motions",
           "explorer_pipeline"]

_helper_lock = threading.Lock()
_helper: list = []  # the server's one VotingHelper, once started (empty: not yet)


#: Fewest logical cores for the voting helper by default: the server, the helper and the
#: browser each need one. On the 2-core development VM the helper took 30-50 ms off a
#: radius move's computation but nothing off what the browser shows, which then shares the
#: second core (docs/bench/explorer_browser_latency_2026-12-03c.md).
HELPER_MIN_CORES = 4


def shared_helper():
    """The server's :class:`laav.helper.VotingHelper` (one process for every session),
    started at the first call; None when it cannot start, with ``LAAV_VOTING_HELPER=0``,
    and, unless ``LAAV_VOTING_HELPER=1``, on machines of fewer than
    :data:`HELPER_MIN_CORES` logical cores. Speed only: LAAV's own voting trials run half
    in it, the labels are the same."""
    import os

    from laav.helper import VotingHelper

    want = os.environ.get("LAAV_VOTING_HELPER", "")
    if want == "0" or (want != "1" and (os.cpu_count() or 1) < HELPER_MIN_CORES):
        return None
    with _helper_lock:
        if not _helper:
            try:
                helper = VotingHelper()
            except (OSError, RuntimeError, ValueError):  # no process here: compute alone
                helper = None
            _helper.append(helper)  # (it closes itself at interpreter exit)
        return _helper[0]


#: Raised in the worker when a newer request made its computation useless
#: (:mod:`laav._interrupt`: between stages and once per voting iteration, never in clean-up code).
Superseded = Interrupted


class _Interruptible:
    """A worker's computation that a newer request stops (``with window(should_stop)``);
    counts the computations stopped (tests read it)."""

    def __init__(self) -> None:
        self.interrupted = 0

    @contextmanager
    def __call__(self, should_stop):
        try:
            with interruptible(should_stop):
                yield
        except Interrupted:
            self.interrupted += 1
            raise


#: Raised in the worker when :meth:`ExplorerState.cancel` stopped its computation (the
#: same cooperative stop as :data:`Superseded`).
Cancelled = Interrupted


def _await(fut: Future):
    """(Worker.) The value of ``fut``, computed elsewhere; None if it failed. The wait stops
    like a computation (:class:`Superseded`, at the worker's checks)."""
    while True:
        try:
            return fut.result(timeout=0.05)
        except FutureTimeout:
            check_interrupt()
        except Exception:  # computed elsewhere and failed: the caller computes it itself
            traceback.print_exc()
            return None


def explorer_pipeline(seq: Sequence, n_motions: int, params: LaavParams | None = None, seed: int = 0,
                      **kw) -> Pipeline:
    """A :class:`laav.Pipeline` as the explorer makes them (``kw``: ``preview``, ``helper``):
    :func:`laav.segment`'s labels, the joint merge's whole shortlist scored
    (``full_shortlist``), since card 3 draws every pair's margin from it."""
    return Pipeline(seq, n_motions, params, seed, full_shortlist=True, **kw)


def plain_rv_of(seq: Sequence, settings: Settings) -> laav.Voting:
    """Plain Random Voting from a random start for ``settings`` (what the explorer shows
    beside LAAV's fine-tuning; computed by :class:`ExplorerState` or :mod:`explorer.warm`)."""
    return laav.random_voting(seq, settings.n_motions, settings.params, settings.seed)


#: Most points of a sequence whose next seed is computed ahead (``seeds_ahead``): above,
#: a second pipeline's memory and seconds of CPU after every result are not spent.
AHEAD_MAX_POINTS = 2000
#: Pipelines kept for settings not shown (the next seed, the one a step replaced, and a
#: seed sweep's ten), oldest dropped first: at most this many, and at most
#: :data:`AHEAD_BUDGET_BYTES` by :data:`PIPELINE_BYTES_PER_ENTRY` (at least 3).
AHEAD_KEEP = 12
#: Memory the kept pipelines of one tab may take, about.
AHEAD_BUDGET_BYTES = 128 * 2**20
#: A pipeline's retained memory per trajectory entry (frame x point): 145 bytes measured
#: (tracemalloc, 2,000 tracks x 100 frames, 3 motions, default settings: 29 MB).
PIPELINE_BYTES_PER_ENTRY = 150
#: Seconds without a request, a new result or a person moving a view control (a frame, a
#: colouring, the replay's step: :meth:`ExplorerState.touch`) before the next seed is
#: computed ahead (``seeds_ahead``). Computed at once, it shared the
#: server's interpreter with the views being drawn and the next move being read: demo λ
#: moves in Chromium took 271-305 ms against 212-249 with the wait
#: (docs/bench/explorer_browser_latency_2026-12-02d.md). A person moving a slider moves it
#: again within this; one looking at a result does not.
AHEAD_IDLE_S = 1.0
#: How a result shown at once was computed (the status line says it).
AHEAD_IDLE, AHEAD_SWEEP = "ahead, while idle", "by the seed sweep"

#: The parameters plain Random Voting depends on (its cache key): every ``rv_*`` field it reads and
#: those its selection's joint score reads.
RV_FIELDS = tuple(f.name for f in dataclasses.fields(LaavParams)
                  if f.name.startswith("rv_") and f.name not in NOT_PLAIN_FIELDS) + SELECTION_FIELDS


#: How far an estimated C can be trusted: laav.estimate_motions on Hopkins155, held out by
#: cross-validation grouped by video (docs/bench/motions.md, 2026-12-06: 91.6 % right, 77 %
#: of the three-motion sequences, whose misses mostly said 2); a single motion alone is called
#: 2, flagged by the one-motion check (docs/bench/motions_one.md).
ESTIMATE_NOTE = ("The estimate is right on 92 % of Hopkins155's sequences but 77 % of its "
                 "three-motion ones, where it mostly says 2: if the seed sweep finds several "
                 "segmentations, try C + 1. It calls a single motion 2; when it says "
                 "\"compare C = 1\", try C = 1.")


@dataclasses.dataclass(frozen=True)
class Origin:
    """How a sequence the explorer shows came from its file: what the page says about it
    and how the exports number its points (the explorer keeps one per sequence).

    Attributes
    ----------
    motions_estimate : int or None
        C as :func:`laav.estimate_motions` estimated it (a file without ground truth), and
        ``motions_reason`` its reason; None when C was given or comes from ground truth.
    point_ids : ndarray of shape (P,), int64, or None
        The file's number of each point, when they are not ``0 .. P-1`` (``--complete-only``
        keeps the tracks seen in every frame, as ``laav segment --complete-only`` does).
    note : str
        One line for the page (e.g. how many tracks ``--complete-only`` dropped).
    """

    motions_estimate: int | None = None
    motions_reason: str = ""
    point_ids: np.ndarray | None = dataclasses.field(default=None, compare=False)
    note: str = ""

    def motions_note(self, n_motions: int) -> str:
        """Where C = ``n_motions`` (the one computed) comes from, for a file without ground truth."""
        if self.motions_estimate is None:  # (the command's --motions, or the box since)
            return f"C = {n_motions} as given (--motions or the C box); the C box changes it."
        if n_motions == self.motions_estimate:
            return (f"C = {n_motions} was estimated: {self.motions_reason}. {ESTIMATE_NOTE} "
                    "The C box changes it.")
        return f"C = {n_motions} is taken from the C box (estimated: {self.motions_estimate})."


@dataclasses.dataclass(frozen=True)
class Settings:
    """What the user asked for: parameters, seed and number of motions C."""

    params: LaavParams
    seed: int
    n_motions: int

    def update_kwargs(self) -> dict:
        """Keyword arguments for :meth:`laav.Pipeline.update` (the full settings: the
        pipeline works out itself which stages they touch)."""
        return {**self.params.to_dict(), "seed": self.seed, "n_motions": self.n_motions}


#: Short names the page uses for parameters (status line, "what changed"); every other
#: parameter goes by its LaavParams field name (the URL and params.json keys).
PARAM_NAMES = {"r1": "R1", "r2": "R2", "lam": "λ", "fine_models": "fine models", "coding_eps": "ε",
               "rv_alpha": "α", "rv_max_iter": "iteration cap", "seed": "seed", "n_motions": "C"}


def _fmt(v) -> str:
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _values(settings: Settings, complete: bool = True) -> dict:
    """Every setting by name, as shown: fine_models as the number of fine models used (on
    complete or incomplete tracks)."""
    d = settings.params.to_dict()
    d["fine_models"] = settings.params.n_fine(settings.n_motions, complete)
    d["seed"], d["n_motions"] = settings.seed, settings.n_motions
    return d


def _nearest_base(settings: Settings, default_motions: int, complete: bool) -> tuple:
    """The defaults or the preset (:data:`laav.params.PRESETS`, as ``--preset`` spells them)
    nearest ``settings``: ``(name, its values, the names that differ, the settings' values)``;
    a preset costs one entry more than its differing settings (``preset = NAME``), so on a
    tie the defaults win. Values as :func:`_values` (C against ``default_motions``; the fine
    models follow C)."""
    from laav.params import PRESETS

    now = _values(settings, complete)
    best = None
    for name, make in PRESETS.items():  # "default" first
        base = make()
        values = _values(Settings(base, 0, default_motions), complete)
        values["fine_models"] = base.n_fine(settings.n_motions, complete)
        diff = [k for k in now if now[k] != values[k]]
        cost = len(diff) + (name != "default")
        if best is None or cost < best[0]:
            best = (cost, name, values, diff)
    return best[1], best[2], best[3], now


def non_defaults(settings: Settings, default_motions: int | None,
                 complete: bool = True) -> list[str]:
    """``name = value`` for every setting that differs from the defaults (the LaavParams
    defaults, seed 0, C of the ground truth, the default number of fine models for the C in
    use, on complete or incomplete tracks). Parameters nearer a preset
    (:data:`laav.params.PRESETS`, as ``--preset`` spells them) than the defaults are said as
    ``preset = NAME`` and the settings that differ from it (the paper preset's 13 fields and
    its fine models were 14 code names in a class's status line)."""
    motions = settings.n_motions if default_motions is None else default_motions
    name, _, diff, now = _nearest_base(settings, motions, complete)
    head = [] if name == "default" else [f"preset = {name}"]
    return head + [f"{PARAM_NAMES.get(k, k)} = {_fmt(now[k])}" for k in diff]


@dataclasses.dataclass(frozen=True)
class Change:
    """What one recompute changed against the result shown before it (same sequence).

    Attributes
    ----------
    settings : tuple of (name, old, new)
        The settings that changed (short names, see :data:`PARAM_NAMES`).
    errors : tuple of (stage, old, new)
        Error rates (fractions) of the coarse and final stages, when there is ground truth.
    moved : numpy.ndarray
        Indices of the points whose final motion changed (the new labels matched to the
        old ones first, so a mere renaming of motions moves nothing).
    """

    settings: tuple
    errors: tuple
    moved: np.ndarray

    def text(self, final: str = "final") -> str:
        """One line, e.g. ``R1 20 → 21: coarse 3.6 → 14.2 %, final 0.0 → 1.1 %, 17 points
        changed motion``; ``final`` names the new labels' stage (a preview's: LAAV's trial,
        the final labels still to come)."""
        what = ", ".join(f"{n} {_fmt(a)} → {_fmt(b)}" for n, a, b in self.settings) or "recomputed"
        parts = [f"{final if st == 'final' else st} {100 * a:.1f} → {100 * b:.1f} %"
                 for st, a, b in self.errors]
        n = int(self.moved.size)
        parts.append(f"{n} point{'s' if n != 1 else ''} changed motion")
        return f"{what}: {', '.join(parts)}"


def describe_change(seq: Sequence, before: LaavResult, before_settings: Settings, after: LaavResult,
                    after_settings: Settings) -> Change:
    """The :class:`Change` from ``before`` to ``after`` (two results on ``seq``)."""
    complete = seq.is_complete
    was, was_base, _, old = _nearest_base(before_settings, before_settings.n_motions, complete)
    now, now_base, _, new = _nearest_base(after_settings, after_settings.n_motions, complete)
    # a preset chosen (or left): said as "preset default → paper", with the settings that moved
    # otherwise, not every field the preset sets
    switched = was != now
    changed = tuple([("preset", was, now)] * switched + [
        (PARAM_NAMES.get(k, k), old[k], new[k]) for k in new
        if new[k] != old[k] and not (switched and old[k] == was_base[k] and new[k] == now_base[k])])
    errors = ()
    if seq.labels is not None:
        a, b = stage_numbers(seq, before), stage_numbers(seq, after)
        errors = tuple((st, a[f"error_{st}"], b[f"error_{st}"]) for st in ("coarse", "final")
                       if a[f"error_{st}"] is not None and b[f"error_{st}"] is not None)
    prev = np.asarray(before.labels)
    moved = np.flatnonzero(align_labels(after.labels, prev) != prev)
    return Change(changed, errors, moved)


# ---------------------------------------------------------------------- settings as text
_FIELDS = {f.name: f for f in dataclasses.fields(LaavParams)}
_DEFAULTS = LaavParams()
#: Each field's kind as LaavParams validates it ("int", "int|None", "float", "bool", ...)
_KINDS = {name: kind for name, kind, _, _ in _BOUNDS}
#: Colour-by keys in the URL (``color=final``) -> the views' colour modes.
VIEW_COLORS = tuple(COLOR_MODES.values())
#: Keys of the page URL's query: every LaavParams field, then the seed, C, frame, colour,
#: the guided tour's step (1-based; absent when the tour is not running) and the name of a
#: sequence opened in the page (absent for the one a new page starts with: ``query_of``).
URL_KEYS = tuple(_FIELDS) + ("seed", "motions", "frame", "color", "tour", "sequence")
_TRUE, _FALSE = ("1", "true", "on", "yes"), ("0", "false", "off", "no")


def parse_value(name: str, text: str):
    """The value of LaavParams field ``name`` written as ``text`` (URL, ``--param``).

    Raises ValueError with a readable message; the value is *not* range-checked here
    (constructing LaavParams does that)."""
    if name not in _FIELDS:
        raise ValueError(f"unknown parameter {name!r}")
    t = str(text).strip()
    kind = _KINDS[name]  # by the field's kind, not its default (None for some)
    try:
        if kind == "int|None":  # None: "auto" for the fine-model counts, no cap for rv_max_points
            words = ("", "none", "auto") if name in ("fine_models", "fine_per_motion") else ("none",)
            return None if t.lower() in words else int(t)
        if kind == "bool":
            if t.lower() in _TRUE:
                return True
            if t.lower() in _FALSE:
                return False
            raise ValueError
        if kind == "int":
            return int(t)
        if kind.startswith("float"):
            return float(t)
        return t
    except ValueError:
        what = ("a whole number" + (" or none" if kind == "int|None" else "") if kind.startswith("int")
                else "true or false" if kind == "bool" else "a number")
        raise ValueError(f"{name} must be {what}, got {t[:40]!r}") from None


#: The largest seed (laav's: seeds are in [0, 2**63)); the URL, params files, the command line
#: and check_settings all use it.
SEED_MAX = 2**63 - 1


def _whole(name: str, text, lo: int, hi: int) -> int:
    try:
        v = int(str(text).strip())
    except ValueError:
        raise ValueError(f"{name} must be a whole number, got {str(text)[:40]!r}") from None
    if not lo <= v <= hi:
        raise ValueError(f"{name} must be between {lo} and {hi}, got {v}")
    return v


def parse_settings(pairs: dict, seq: Sequence, base: Settings) -> tuple[Settings, dict, list[str]]:
    """Settings (and view state) from text key/value pairs: a page URL's query, ``--param``.

    ``pairs`` maps :data:`URL_KEYS` to strings (a list of strings: the last one counts).
    Every parameter goes through :class:`laav.LaavParams` and the seed, C, frame and colour
    are checked against ``seq``. Returns ``(settings, view, problems)``: the settings from
    ``base`` with every valid value applied, ``view`` with ``frame`` / ``color`` when given
    and valid, and one readable message per key that was not used (never raises).
    A ``sequence`` naming another sequence than ``seq`` (an address made where that one was
    opened) is one such message, and the address's C is then not used (another sequence's C,
    as for a params.json); its other values are.
    """
    problems: list[str] = []
    values: dict = {}
    view: dict = {}
    seed, C = base.seed, base.n_motions
    made_on = _query_text(pairs["sequence"]) if "sequence" in pairs else None
    other = made_on is not None and made_on != seq.name
    for key, raw in pairs.items():
        raw = _query_text(raw)
        try:
            if key in _FIELDS:
                values[key] = parse_value(key, raw)
            elif key == "seed":
                seed = _whole("seed", raw, 0, SEED_MAX)
            elif key == "motions":
                if other:  # another sequence's C, as a params.json's (settings_from_json)
                    raise ValueError(f"motions={str(raw)[:12]} was {str(made_on)[:80]!r}'s C: "
                                     f"C stays {base.n_motions}")
                C = _whole("motions (C)", raw, 1, seq.n_points)
            elif key == "sequence":
                if other:
                    raise ValueError(
                        f"this address was made on the sequence {str(made_on)[:80]!r}, opened in "
                        f"that page (an address does not carry the data); this page shows "
                        f"{seq.name!r}, to which its other settings are applied. Open "
                        f"{str(made_on)[:80]!r} here (the upload box) to see it")
            elif key == "frame":
                view["frame"] = _whole("frame", raw, 0, seq.n_frames - 1)
            elif key == "tour":
                from .tour import TOUR

                view["tour"] = _whole("tour", raw, 1, len(TOUR))
            elif key == "color":
                shown = [c for c in VIEW_COLORS if seq.labels is not None or c not in TRUTH_MODES]
                if str(raw) in TRUTH_MODES and seq.labels is None:  # (the select has none either)
                    raise ValueError(f"color={raw} needs a ground truth, which this sequence does "
                                     "not have: the final labels are shown")
                if str(raw) not in shown:
                    raise ValueError(f"color must be one of {', '.join(shown)}, got {str(raw)[:40]!r}")
                view["color"] = str(raw)
            else:
                raise ValueError(f"unknown setting {str(key)[:40]!r}")
        except ValueError as exc:
            problems.append(str(exc))
    params = base.params
    if values:
        try:
            params = base.params.replace(**values)
        except (ValueError, TypeError) as exc:
            problems.append(str(exc))
            # keep the values that are fine on their own
            for k, v in values.items():
                try:
                    params = params.replace(**{k: v})
                except (ValueError, TypeError):
                    pass
    new = Settings(params, seed, C)
    try:
        check_settings(seq, new)
    except ValueError as exc:
        problems.append(str(exc))
        new = Settings(params, seed, base.n_motions)
        try:
            check_settings(seq, new)
        except ValueError:
            new = base
    return new, view, problems


def _query_text(raw) -> str:
    """A query value as text: of a repeated key the last (bokeh hands lists), bytes decoded."""
    if isinstance(raw, (list, tuple)):
        raw = raw[-1] if raw else ""
    return raw.decode("utf-8", "replace") if isinstance(raw, bytes) else raw


def _short_float(v: float) -> str:
    """``25.0`` -> ``"25"``; as many digits as it takes to read back the same float."""
    g = format(v, "g")
    return g if float(g) == v else repr(v)


def query_of(settings: Settings, default_motions: int | None, frame: int = 0,
             color: str | None = None, default_color: str | None = None,
             tour: int | None = None, sequence: str | None = None) -> dict[str, str]:
    """The URL query for these settings and view: only what differs from the defaults
    (``parse_settings(query_of(s, ...), seq, ...)`` gives ``s`` back, on the sequence named
    ``sequence``); ``tour``: the guided tour's step shown (0-based; None when the tour is not
    running), written 1-based;
    ``sequence``: the name of the sequence shown when it is not the one a new page starts
    with (opened in this page: a page opened at this address says so, not showing it)."""
    q: dict[str, str] = {}
    if sequence is not None:
        q["sequence"] = str(sequence)
    for name in _FIELDS:
        v = getattr(settings.params, name)
        if v != getattr(_DEFAULTS, name):
            q[name] = ("none" if v is None else "true" if v is True else "false" if v is False
                       else _short_float(v) if isinstance(v, float) else str(v))
    if settings.seed != 0:
        q["seed"] = str(settings.seed)
    if default_motions is None or settings.n_motions != default_motions:
        q["motions"] = str(settings.n_motions)
    if frame:
        q["frame"] = str(int(frame))
    if color is not None and color != default_color:
        q["color"] = color
    if tour is not None:
        q["tour"] = str(int(tour) + 1)
    return q


def is_params_json(head: bytes) -> bool:
    """Whether a file starting with ``head`` is a params.json (:func:`settings_from_json`):
    its first non-blank byte, after a UTF-8 byte-order mark, is ``{``. No sequence format
    starts so (a tracks CSV starts with its header). The upload box and ``laav-explore
    FILE`` tell one by it."""
    return head.removeprefix(b"\xef\xbb\xbf").lstrip()[:1] == b"{"


def settings_from_json(text: str | bytes, seq: Sequence, base: Settings,
                       defaults: LaavParams | None = None) -> Settings:
    """Settings from a params.json the explorer exported (``{"params": {...}, "seed": ...,
    "n_motions": ...}``) or a bare ``{field: value}`` object; a field it does not name is
    ``defaults``' (default: ``LaavParams()``; ``laav-explore --preset`` gives its preset).
    The file's C (``n_motions``) is taken only when its ``sequence`` is ``seq``'s name (or
    it names none): another sequence's C stays ``base``'s.
    Raises ValueError (readable) when it is not such a file or a value is invalid; nothing
    is half-applied."""
    # (the file checked by laav's reader first: JSON, one object, valid parameters)
    new_params = LaavParams.from_json(text, _DEFAULTS if defaults is None else defaults)
    d = json.loads(text)
    seed = d.get("seed", base.seed)
    # C is a property of the sequence: a file exported for another one does not set it
    C = base.n_motions if _exported_for_another(d, seq) else d.get("n_motions", base.n_motions)
    if not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed <= SEED_MAX:
        raise ValueError(f"seed must be a whole number between 0 and {SEED_MAX}, got {str(seed)[:40]}")
    if not isinstance(C, int) or isinstance(C, bool):
        raise ValueError(f"n_motions must be a whole number, got {C!r}")
    new = Settings(new_params, seed, C)
    check_settings(seq, new)
    return new


def _exported_for_another(d: dict, seq: Sequence) -> bool:
    """Whether a params file's object ``d`` names a sequence other than ``seq``."""
    source = d.get("sequence")
    return isinstance(source, str) and source != seq.name


def params_file_note(text: str | bytes, seq: Sequence, used: Settings, name: str) -> str | None:
    """What the page says about the params file ``name`` (``text``, valid:
    :func:`settings_from_json` read it into ``used``) when it was exported for another
    sequence: its parameters and seed are applied, its C is not. None otherwise."""
    d = json.loads(text)
    if not _exported_for_another(d, seq):
        return None
    C = d.get("n_motions")
    return (f"{name} was exported for {d['sequence']}: its parameters and seed are applied to "
            f"{seq.name}" + (f", its C = {C} is not (C stays {used.n_motions})"
                             if isinstance(C, int) and C != used.n_motions else "") + ".")


def check_motions(seq: Sequence, C) -> None:
    """Raise ValueError with a readable message when ``seq`` cannot be split into ``C`` motions."""
    if not isinstance(C, int) or C < 1:
        raise ValueError(f"the number of motions C must be a positive integer, got {C!r}")
    if C > seq.n_points:
        raise ValueError(f"C = {C} motions is more than the {seq.n_points} points of the sequence")
    if C > 1 and seq.n_points < MIN_POINTS * C:
        # (laav only warns, "the labels are probably meaningless", and a C of 99 on the demo's
        # 350 points took 35 s to say so: a shared link could ask for it)
        raise ValueError(f"C = {C} motions need at least {MIN_POINTS} points each (the 8-point "
                         f"algorithm fits each motion's epipolar geometry): the {seq.n_points} "
                         f"points of the sequence allow at most {max(1, seq.n_points // MIN_POINTS)}")


def check_settings(seq: Sequence, settings: Settings) -> None:
    """Raise ValueError with a readable message when ``settings`` cannot run on ``seq``."""
    seed = settings.seed
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or not 0 <= seed <= SEED_MAX:
        raise ValueError(f"seed must be a whole number between 0 and {SEED_MAX}, got {seed!r}")
    C = settings.n_motions
    check_motions(seq, C)
    settings.params.n_fine(C, seq.is_complete)  # at least C fine models


def _fit_drawn_votes(result: LaavResult) -> None:
    """(Worker.) The cards draw the paper's pairwise votes, which the default merge does not
    fit unless read (:class:`laav.coarse.PairwiseVotes`): fitted here (a worker), not on
    the page's thread."""
    if result.coarse is not None:
        result.coarse.vote_samples  # noqa: B018


#: Numbers the states of this process, for their worker threads' names (ExplorerState.threads).
_STATE_NUMBERS = itertools.count(1)


class ExplorerState:
    """One explorer session's data and computation.

    Parameters
    ----------
    seq : laav.Sequence
    n_motions : int, optional
        C; defaults to the ground truth's number of motions.
    params : laav.LaavParams, optional
    seed : int
    pipeline : Future or Pipeline, optional
        A pipeline for ``seq`` computed elsewhere (the CLI computes one in a child process
        while the server starts: :mod:`explorer.warm`); the first result is its
        :meth:`~laav.Pipeline.update` to the settings asked for instead of a fresh one. A
        Future of None (or of an exception) means: compute it here.
    autostart : bool
        Queue the first computation at once (else call :meth:`start`).
    plain_rv : Future, optional
        Plain RV's run (:func:`plain_rv_of`) for ``seq`` and the first settings, computed
        elsewhere: used instead of computing it when those settings are shown (None: compute).
    preview : Future, optional
        The preview of ``pipeline`` (a :class:`~laav.LaavResult` with LAAV's own fine-tuning,
        or None: :mod:`explorer.warm`), shown (:attr:`on_preview`) when it arrives before the
        first result, if the first settings are still the ones asked for.
    seeds_ahead : bool
        While nothing is asked for, compute the result and plain RV for the next seed
        (seed + 1) on sequences of at most :data:`AHEAD_MAX_POINTS` points, so that a step
        of the seed slider shows them at once (``laav-explore`` turns it on). The result
        is that of a fresh :class:`laav.Pipeline` for those settings, as a recomputation
        gives; any request stops the computation ahead at its next check.
    voting_helper : bool
        Once :meth:`preload` is called (the app: when the page is complete), run half of
        LAAV's own voting trials and plain RV for the RV card in the server's voting helper
        process (:func:`shared_helper`; speed only, the same labels). False: all here.

    Attributes
    ----------
    result : LaavResult or None
        The last good result (None until the first computation finishes).
    sequence : laav.Sequence
        The sequence ``result`` belongs to.
    settings : Settings
        The settings of ``result``.
    error : str or None
        The last problem reported (None after a good result).
    busy : bool
        True while a request is queued or computing.
    """

    def __init__(self, seq: Sequence, n_motions: int | None = None, params: LaavParams | None = None,
                 seed: int = 0, pipeline: Future | Pipeline | None = None, autostart: bool = True,
                 plain_rv: Future | None = None, seeds_ahead: bool = False,
                 preview: Future | None = None, voting_helper: bool = True):
        if n_motions is None:
            if seq.n_motions is None:
                raise ValueError(f"{seq.name} has no ground truth: the number of motions C is needed")
            n_motions = seq.n_motions
        target = Settings(LaavParams() if params is None else params, int(seed), int(n_motions))
        check_settings(seq, target)
        self.on_result: Callable[[LaavResult, Sequence, Settings, int], None] | None = None
        self.on_error: Callable[[str], None] | None = None
        self.on_busy: Callable[[bool], None] | None = None
        self.on_plain_rv: Callable[[laav.Voting, tuple], None] | None = None
        #: called (a worker) with a result whose pairwise votes :meth:`fit_votes` has
        #: fitted, and False (the cards that draw them draw again); True: the fit was
        #: dropped before it started (a newer request)
        self.on_votes: Callable[[LaavResult, bool], None] | None = None
        #: called (worker thread) with a *preview* of a result on its way: LAAV's own
        #: fine-tuning alone, while the rest of the fine-tuning still computes (plain RV and
        #: the selection: a new seed, C or RV setting with ``with_plain_rv()``; in the
        #: default chain the missed-motion trials its gate lets through;
        #: :meth:`laav.Pipeline.update`'s ``preview``); then, unless the
        #: computation is cancelled, fails or is superseded, ``on_result`` with the result,
        #: same generation. Not :attr:`result`: the state moves on only with the result
        self.on_preview: Callable[[LaavResult, Sequence, Settings, int], None] | None = None
        #: called with the new :attr:`target` whenever it changes (a request, a load, a
        #: cancel or a failed load falling back): the Advanced panel shows it
        self.on_target: Callable[[Settings], None] | None = None
        self.sequence = seq
        self.settings = target
        self.result: LaavResult | None = None
        self.error: str | None = None
        #: what the last recompute changed (None after a new sequence or the first result)
        self.change: Change | None = None
        self._changes: OrderedDict = OrderedDict()
        self.compute_seconds = 0.0
        self._target = target
        self._target_seq = seq
        self._pipe: Pipeline | None = None
        #: the voting helper the session's pipeline uses (speed only; :func:`shared_helper`,
        #: attached by :meth:`preload`), or None
        self.helper = None
        self._want_helper = voting_helper
        self._lock = threading.Lock()
        self._gen = 0
        self._published = 0
        self._pending = 0
        self._quiet_since = time.monotonic()  # the last job's end or touch() (AHEAD_IDLE_S)
        self._idle = threading.Condition(self._lock)
        #: the workers' threads are named after this state (close() finds them by name: an
        #: executor starts its thread within submit, so a thread is listed once it exists)
        self._thread_tag = f"laav-explore-state{next(_STATE_NUMBERS)}"
        self._worker = ThreadPoolExecutor(1, thread_name_prefix=self._thread_tag + "-pipeline")
        self._rv_worker = ThreadPoolExecutor(1, thread_name_prefix=self._thread_tag + "-plain-rv")
        #: the drawn votes' fits (fit_votes): beside plain RV, not queued behind it
        self._votes_worker = ThreadPoolExecutor(1, thread_name_prefix=self._thread_tag + "-votes")
        # the pipeline's first-use imports (~1 s), ahead of the first job: they overlap the
        # page's loading, and stage timings shown to the user do not include them. With a
        # pipeline computed elsewhere the first job needs none of them: the app asks for
        # them once the page shows the first result and all its cards (preload()), so that
        # they do not hold this process's GIL while the page is being built and drawn
        self._preloaded = pipeline is None
        if self._preloaded:
            self._worker.submit(laav.preload)
        self._rv_cache: OrderedDict = OrderedDict()
        self._rv_key = None
        #: compute the next seed's result (and plain RV) while idle (see :meth:`_ahead_job`)
        self.seeds_ahead = bool(seeds_ahead)
        self._ahead: OrderedDict = OrderedDict()  # (id(seq), Settings) -> (Pipeline, how)
        #: results shown from a pipeline computed ahead (tests read it)
        self.ahead_used = 0
        self._ahead_results: deque = deque(maxlen=4)  # (result, how) of results shown at once
        #: the pipeline's and plain RV's computations, interruptible by a newer request
        self.computing = _Interruptible()
        self.rv_computing = _Interruptible()
        self._closed = False
        self._first = pipeline
        # the preview of that pipeline (explorer.warm), for the settings it was computed with
        self._first_preview = None if preview is None else (target, preview)
        self._warm: tuple | None = None  # (sequence, Future) of a superseded first job
        # plain RV for the first settings computed elsewhere: (its cache key, Future)
        self._rv_warm = None if plain_rv is None else (self.plain_rv_key(seq, target), plain_rv)
        self._started = False
        if autostart:
            self.start()

    def retarget(self, settings: Settings) -> None:
        """Before :meth:`start`: compute ``settings`` first instead (a shared URL's state).
        A warm pipeline given for other settings is updated to them (only the stages they
        touch rerun; the result equals a fresh computation)."""
        check_settings(self._target_seq, settings)
        if self._started:
            raise RuntimeError("retarget() only before start(); use request()")
        if settings != self._target:
            self._target = self.settings = settings
            self._notify_target()

    def touch(self) -> None:
        """A person is using the page (a frame move, another colouring): the next seed is not
        computed ahead until :data:`AHEAD_IDLE_S` after this either."""
        with self._lock:
            self._quiet_since = time.monotonic()

    def preload(self) -> None:
        """Start the pipeline's first-use imports (:func:`laav.preload`) in a thread of their
        own, if not done yet, and the voting helper's process (:func:`shared_helper`, unless
        ``voting_helper=False``): the app calls it once the page is complete, so that
        neither competes with the first page."""
        if self._closed:
            return
        if self._want_helper and self.helper is None:
            self.helper = shared_helper()
        if not self._preloaded:
            self._preloaded = True
            threading.Thread(target=laav.preload, name="laav-explore-preload", daemon=True).start()

    def start(self) -> None:
        """Queue the first computation (call after setting the ``on_*`` hooks)."""
        if not self._started:
            self._submit("load", self._target_seq, self._target, self._first)
            self._first = None
            with self._idle:
                self._started = True
                self._idle.notify_all()

    # ------------------------------------------------------------------ requests
    @property
    def target(self) -> Settings:
        """The settings most recently requested (valid ones only)."""
        return self._target

    @property
    def target_sequence(self) -> Sequence:
        """The sequence most recently requested (being read into the pipeline, or shown)."""
        return self._target_seq

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def generation(self) -> int:
        return self._gen

    @property
    def published_generation(self) -> int:
        return self._published

    @property
    def busy(self) -> bool:
        return self._pending > 0

    def request(self, params: dict | None = None, seed: int | None = None,
                n_motions: int | None = None) -> int | None:
        """Ask for new settings. ``params`` holds :class:`LaavParams` fields (the full set
        or a few). Returns the request's generation, or None when the settings are invalid
        (then :attr:`error` says why, ``on_error`` was called and nothing else changed)."""
        base = self._target
        try:
            new = Settings(
                base.params.replace(**params) if params else base.params,
                base.seed if seed is None else int(seed),
                base.n_motions if n_motions is None else n_motions,
            )
            check_settings(self._target_seq, new)
        except ValueError as exc:
            self._report(str(exc))
            return None
        if new == base and self._pending == 0 and self.result is not None and self.error is None:
            return self._gen  # nothing to do
        return self._submit("update", self._target_seq, new)

    def load(self, seq: Sequence, n_motions: int | None = None) -> int | None:
        """Switch to another sequence (C from its ground truth unless given)."""
        C = n_motions if n_motions is not None else seq.n_motions
        if C is None:
            self._report(f"{seq.name} has no ground-truth labels: set the number of motions C first")
            return None
        new = dataclasses.replace(self._target, n_motions=int(C))
        try:
            check_settings(seq, new)
        except ValueError as exc:
            self._report(f"cannot segment {seq.name}: {exc}")
            return None
        return self._submit("load", seq, new)

    def cancel(self) -> bool:
        """Stop the computation running and drop every queued request: the views keep the
        last result, and the next request starts from its settings. Returns False when
        nothing was running. The computation stops at its next check (between stages,
        once per voting iteration: :mod:`laav._interrupt`; ``Pipeline.update`` rolls
        back); its result, if it still finishes, is dropped."""
        with self._lock:
            if self._pending == 0:
                return False
            self._gen += 1  # the running job stops and is dropped, queued ones are skipped
            if self.result is not None:
                self._target_seq, self._target = self.sequence, self.settings
        self._notify_target()
        return True

    def report(self, message: str) -> None:
        """Show a problem found outside the state (e.g. an unreadable upload)."""
        self._report(message)

    def _report(self, message: str) -> None:
        self.error = message
        if self.on_error is not None:
            self.on_error(message)

    def _submit(self, kind: str, seq: Sequence, target: Settings, pipeline=None) -> int:
        with self._lock:
            self._gen += 1
            gen = self._gen
            if seq is not self._target_seq:
                self._ahead.clear()  # pipelines of the sequence shown: of no use for another
            self._target, self._target_seq = target, seq
            self._pending += 1
            # the computation running now (its generation is no longer the newest) and plain
            # RV stop at their next check: they are of no use any more
            self._rv_key = None
        self._notify_target()
        self._notify_busy()
        try:
            self._worker.submit(self._job, gen, kind, seq, target, pipeline)
        except RuntimeError:  # closed
            with self._lock:
                self._pending -= 1
                self._idle.notify_all()
        return gen

    def _notify_target(self):
        if self.on_target is not None:
            try:
                self.on_target(self._target)
            except Exception:  # a GUI hook must never kill the worker
                traceback.print_exc()

    def _notify_busy(self):
        if self.on_busy is not None:
            try:
                self.on_busy(self._pending > 0)
            except Exception:  # a GUI hook must never kill the worker
                traceback.print_exc()

    # ------------------------------------------------------------------ worker
    def _job(self, gen: int, kind: str, seq: Sequence, target: Settings, pipeline) -> None:
        try:
            if gen != self._gen:
                return  # superseded before it started
            t0 = time.perf_counter()
            try:
                with self.computing(lambda: gen != self._gen):
                    if gen != self._gen:
                        return
                    if kind == "load" or self._pipe is None or self._pipe.seq is not seq:
                        self._show_first_preview(gen, seq, target)
                        warm = self._warm_pipeline(seq, pipeline)
                        if warm is not None:  # computed elsewhere: only what differs is rerun
                            pipe, before = self._with_helper(warm), warm.result
                            t0 = time.perf_counter()  # (the wait is not this computation's)
                            # (a caller's pipeline may score only part of the joint merge's
                            # shortlist: card 3 draws the whole comparison)
                            try:
                                result = pipe.update(**target.update_kwargs(), full_shortlist=True,
                                                     preview=self._previewer(gen, seq, target))
                            except Superseded:  # (rolled back:) the next job starts from it
                                self._warm = (seq, warm)
                                raise
                            if result is before:  # as computed elsewhere: its own stage times
                                t0 -= sum(result.timings.values())
                        else:
                            pipe = self._with_helper(explorer_pipeline(
                                seq, target.n_motions, target.params, target.seed,
                                preview=self._previewer(gen, seq, target), helper=self.helper))
                            result = pipe.result
                    else:
                        entry = self._take_ahead(seq, target)
                        if entry is not None:  # computed ahead: as a fresh Pipeline's
                            pipe, how = entry
                            result = pipe.result
                            t0 -= sum(result.timings.values())  # its own stage times
                            with self._lock:
                                self._ahead_results.append((result, how))
                        else:
                            pipe = self._with_helper(self._pipe)
                            result = pipe.update(**target.update_kwargs(),
                                                 preview=self._previewer(gen, seq, target))
                    # (the drawn votes are not fitted here: fit_votes, once it is shown)
            except Superseded:
                return  # a newer request is queued: it starts now
            except ValueError as exc:  # includes laav.SequenceError
                if gen == self._gen:
                    self._fail(kind, str(exc))
                return
            except Exception as exc:  # an algorithm bug must not kill the session
                traceback.print_exc()
                if gen == self._gen:
                    self._fail(kind, f"internal error in the pipeline: {type(exc).__name__}: {exc}")
                return
            self._pipe = pipe
            if gen != self._gen:
                return  # a newer request came in meanwhile: drop this result
            self.compute_seconds = time.perf_counter() - t0
            self.change = self._remember_change(seq, target, result)
            self.result, self.sequence, self.settings = result, seq, target
            self.error = None
            self._published = gen
            if self.on_result is not None:
                self.on_result(result, seq, target, gen)
            self.request_plain_rv()
        except Exception:
            traceback.print_exc()
        finally:
            with self._lock:
                self._pending -= 1
                self._quiet_since = time.monotonic()
                self._idle.notify_all()
            self._notify_busy()

    def _remember_change(self, seq: Sequence, target: Settings, result: LaavResult) -> Change | None:
        """What ``result`` (for ``target``) changed against the result shown, kept for
        :meth:`change_of` (the last 8: previews take their places too)."""
        change = None
        if self.result is not None and self.sequence is seq and result is not self.result:
            try:
                change = describe_change(seq, self.result, self.settings, result, target)
            except Exception:  # a summary must never cost the result
                traceback.print_exc()
        self._changes[id(result)] = (result, change)
        while len(self._changes) > 8:
            self._changes.popitem(last=False)
        return change

    def _show_first_preview(self, gen: int, seq: Sequence, target: Settings) -> None:
        """(Worker.) Show the warm pipeline's preview (computed elsewhere, see ``preview`` of
        the constructor) when it arrives, if it is for ``target`` and the result is not shown
        by then; at most once."""
        first, self._first_preview = self._first_preview, None
        if first is None or first[0] != target or seq is not self._target_seq:
            return
        show = self._previewer(gen, seq, target)

        def arrived(fut: Future) -> None:
            try:
                result = fut.result()
            except Exception:  # noqa: BLE001 - no preview then
                return
            if isinstance(result, LaavResult):
                show(result)

        first[1].add_done_callback(arrived)

    def _previewer(self, gen: int, seq: Sequence, target: Settings):
        """The ``preview`` hook of one job's :meth:`Pipeline.update` (see :attr:`on_preview`)."""
        def preview(result: LaavResult) -> None:
            with self._lock:
                stale = gen != self._gen or self._published >= gen or self.on_preview is None
            if stale:
                return  # superseded, or the result is out already
            self._remember_change(seq, target, result)
            try:
                self.on_preview(result, seq, target, gen)
            except Exception:  # a GUI hook must never kill the worker
                traceback.print_exc()
        return preview

    def _warm_pipeline(self, seq: Sequence, pipeline) -> Pipeline | None:
        """(Worker.) The pipeline computed elsewhere for ``seq`` (given, or left by a first job
        that a newer request superseded), None if there is none or it failed. Waiting for it
        is interruptible like a computation; the pipeline is then kept for the next job."""
        if pipeline is None and self._warm is not None and self._warm[0] is seq:
            pipeline = self._warm[1]
        self._warm = None
        if not isinstance(pipeline, Future):
            return pipeline
        try:
            pipe = _await(pipeline)
        except Interrupted:
            self._warm = (seq, pipeline)  # the next job on this sequence takes it
            raise
        return pipe if isinstance(pipe, laav.Pipeline) and pipe.seq is seq else None

    def _fail(self, kind: str, message: str) -> None:
        with self._lock:
            # fall back to what is on screen so the next request starts from it
            if self.result is not None:
                self._target_seq = self.sequence
                if kind == "load":
                    self._target = self.settings
        self._notify_target()
        self._report(message + (" — still showing the last valid result" if self.result else ""))

    def change_of(self, result: LaavResult) -> Change | None:
        """The :class:`Change` that ``result`` made (None for a first result or a new sequence)."""
        entry = self._changes.get(id(result))
        return entry[1] if entry is not None and entry[0] is result else None

    def default_motions(self, seq: Sequence | None = None) -> int | None:
        """C of the ground truth of ``seq`` (the shown sequence by default), if it has one."""
        seq = self.sequence if seq is None else seq
        return seq.n_motions if seq.labels is not None else None

    def wait(self, timeout: float = 60.0) -> bool:
        """Block until no request is queued or computing (and its views were notified);
        before :meth:`start`, until the first computation has started and finished."""
        deadline = time.monotonic() + timeout
        with self._idle:
            while self._pending > 0 or not self._started:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._idle.wait(left)
        return True

    # ------------------------------------------------------------------ plain RV
    def plain_rv_key(self, seq: Sequence | None = None, settings: Settings | None = None) -> tuple:
        """Plain RV's cache key for ``seq`` / ``settings`` (default: the shown ones)."""
        seq = self.sequence if seq is None else seq
        s = self.settings if settings is None else settings
        return (id(seq), s.seed, s.n_motions) + tuple(getattr(s.params, f) for f in RV_FIELDS)

    def plain_rv(self, seq: Sequence | None = None, settings: Settings | None = None) -> laav.Voting | None:
        """Cached plain RV for the shown sequence/settings (or ``seq`` / ``settings``, e.g. a
        pinned result's), or None if not computed (yet, or any more)."""
        return self._rv_cache.get(self.plain_rv_key(seq, settings))

    def request_plain_rv(self) -> Future | None:
        """Compute plain RV (random start) for the shown settings off the UI thread."""
        key = self.plain_rv_key()
        self._rv_key = key
        if key in self._rv_cache:
            if self.on_plain_rv is not None:
                self.on_plain_rv(self._rv_cache[key], key)
            self._queue_ahead()
            return None
        if self._closed:
            return None
        seq, s = self.sequence, self.settings
        try:
            fut = self._rv_worker.submit(self._rv_job, key, seq, s)
        except RuntimeError:  # closed, or the interpreter is shutting down
            return None
        self._queue_ahead()  # after plain RV in the same worker
        return fut

    # ------------------------------------------------------------------ the drawn votes
    def fit_votes(self, result: LaavResult) -> Future | None:
        """Fit ``result``'s pairwise epipolar votes (what card 3 draws; the default merge
        does not fit them) in a worker of their own (beside plain RV's, not behind it), then
        call :attr:`on_votes`; None when they are fitted already (or the state is closed).

        The app asks once a result is on the page: fitted before it, in the computation,
        they were 57 ms of a 445 ms R1 move on the demo that nothing on screen needed (card
        3 is below the fold; it shows "fitting…" until they arrive). A fit not started when
        a newer request comes is dropped and reported so (:attr:`on_votes`' second
        argument): the app asks again while the result is still the one shown (the newer
        request may have been cancelled or failed)."""
        if result.coarse is None or result.coarse.pairwise.fitted or self._closed:
            return None
        gen = self._gen

        def job() -> None:
            dropped = False
            try:
                with interruptible(lambda: gen != self._gen or self._closed):
                    check_interrupt()  # (superseded while queued)
                    _fit_drawn_votes(result)
            except Superseded:
                dropped = True
            except Exception:  # a drawing's fit must never cost the session (the cards
                traceback.print_exc()  # are told all the same: they stop waiting for it)
            if self.on_votes is not None and not self._closed:
                self.on_votes(result, dropped)

        try:
            return self._votes_worker.submit(job)
        except RuntimeError:  # closed
            return None

    # ------------------------------------------------------------------ the next seed, ahead
    def computed_ahead(self, result) -> str | None:
        """How ``result`` was computed before it was asked for: :data:`AHEAD_SWEEP`
        (:meth:`offer_pipeline`), :data:`AHEAD_IDLE` (``seeds_ahead``), or None."""
        with self._lock:
            shown = list(self._ahead_results)
        return next((how for r, how in shown if r is result), None)

    def compute_ahead(self) -> None:
        """Compute the next seed for the result shown (with ``seeds_ahead``), after what
        plain RV's worker has queued; nothing before the first result."""
        if self.result is not None:
            self._queue_ahead()

    def _queue_ahead(self) -> None:
        seq, s, gen = self.sequence, self.settings, self._gen
        if (not self.seeds_ahead or self._closed or seq.n_points > AHEAD_MAX_POINTS
                or s.seed >= SEED_MAX):
            return
        try:
            self._rv_worker.submit(self._ahead_job, gen, seq, dataclasses.replace(s, seed=s.seed + 1))
        except RuntimeError:  # closed
            pass

    def _take_ahead(self, seq: Sequence, target: Settings) -> tuple | None:
        """The pipeline computed ahead for ``target`` and how (see :meth:`computed_ahead`),
        if any; the one it replaces is kept in its place for the settings shown (a step back
        to them is then shown at once too)."""
        with self._lock:
            entry = self._ahead.pop((id(seq), target), None)
            if entry is not None and self._pipe is not None and self.sequence is seq:
                self._keep_ahead((id(seq), self.settings), self._pipe, AHEAD_IDLE)
        if entry is not None:
            self.ahead_used += 1
        return entry

    def _keep_ahead(self, key, pipe: Pipeline, how: str) -> None:
        """(Under the lock.) Keep ``pipe`` for ``key`` as the newest entry, then trim."""
        self._ahead.pop(key, None)  # a rewritten key is the newest, never the one trimmed
        self._ahead[key] = (pipe, how)
        self._trim_ahead()

    def _trim_ahead(self) -> None:
        seq = self.sequence
        size = 1 if seq is None else seq.n_frames * seq.n_points * PIPELINE_BYTES_PER_ENTRY
        keep = max(3, min(AHEAD_KEEP, AHEAD_BUDGET_BYTES // size))
        while len(self._ahead) > keep:
            self._ahead.popitem(last=False)

    def offer_pipeline(self, seq: Sequence, n_motions: int, params: LaavParams, seed: int,
                       pipeline: Pipeline) -> bool:
        """Keep ``pipeline`` (computed elsewhere for these settings, e.g. by the seed sweep)
        for a later request of exactly them, which then shows its result at once, as the
        next seed computed ahead is shown. Only for the sequence shown and sequences of at
        most :data:`AHEAD_MAX_POINTS` points. Returns whether it was kept. (Any thread.)"""
        key = (id(seq), Settings(params, int(seed), int(n_motions)))
        with self._lock:  # the sequence shown and still asked for (no load since)
            if (self._closed or seq is not self.sequence or seq is not self._target_seq
                    or seq.n_points > AHEAD_MAX_POINTS or key in self._ahead):
                return False
            self._keep_ahead(key, pipeline, AHEAD_SWEEP)
        return True

    def _ahead_job(self, gen: int, seq: Sequence, target: Settings) -> None:
        """(Plain RV's worker, after plain RV for the settings shown.) A fresh pipeline and
        plain RV for ``target`` (the next seed), kept for :meth:`_job` and the RV card; any
        request (a new generation ``gen``) stops it."""
        def stop():
            return gen != self._gen or self._closed

        key = (id(seq), target)
        try:
            with self.rv_computing(stop):
                with self._idle:  # the job that showed the result is still finishing:
                    while not stop():  # its end notifies (a new request too, as its job
                        if self._pending > 0:  # ends; close: timeout); then AHEAD_IDLE_S
                            self._idle.wait(0.25)  # without a request or result
                            continue
                        left = self._quiet_since + AHEAD_IDLE_S - time.monotonic()
                        if left <= 0:
                            break
                        self._idle.wait(min(left, 0.25))
                if stop():
                    return
                with self._lock:
                    have = key in self._ahead
                if not have:
                    pipe = explorer_pipeline(seq, target.n_motions, target.params, target.seed)
                    with self._lock:
                        if seq is self._target_seq:  # no other sequence asked for since
                            self._keep_ahead(key, pipe, AHEAD_IDLE)
                pkey = self.plain_rv_key(seq, target)
                if pkey not in self._rv_cache:
                    self._keep_plain_rv(pkey, plain_rv_of(seq, target))
        except Superseded:
            return
        except Exception:  # a computation ahead must never cost the session
            traceback.print_exc()

    def _rv_job(self, key, seq, s: Settings) -> None:
        if key != self._rv_key:
            return  # stale (a newer request came in: asked for again with its result)
        try:
            with self.rv_computing(lambda: key != self._rv_key):
                if key != self._rv_key:
                    return
                voting = None
                warm = self._rv_warm
                if warm is not None and warm[0] == key:  # computed elsewhere (explorer.warm)
                    voting = _await(warm[1])  # kept for later if a new request stops the wait
                    self._rv_warm = None
                if voting is None:
                    voting = self._plain_rv_of(seq, s)
        except Superseded:
            return
        except Exception:
            traceback.print_exc()
            return
        self._keep_plain_rv(key, voting)
        if key == self._rv_key and self.on_plain_rv is not None:
            self.on_plain_rv(voting, key)

    def _with_helper(self, pipe: Pipeline) -> Pipeline:
        """``pipe``, its next computations sped up by the session's voting helper (if any):
        half of LAAV's own trials and the votes card 3 draws fitted there."""
        pipe.helper, pipe.prefetch_votes = self.helper, self.helper is not None
        return pipe

    def _plain_rv_of(self, seq: Sequence, s: Settings) -> laav.Voting:
        """(Plain RV's worker.) :func:`plain_rv_of`, in the voting helper's process when there
        is one (the same labels): here it would hold this process's interpreter lock while
        the result it accompanies is being sent to the page."""
        helper = self.helper
        handle = None if helper is None else helper.submit_call(
            laav.random_voting, seq, s.n_motions, s.params, s.seed)
        voting = None if handle is None else helper.result(handle, check_interrupt)
        return plain_rv_of(seq, s) if voting is None else voting

    def _keep_plain_rv(self, key, voting) -> None:
        """Cache plain RV's run under ``key`` (the 16 latest kept)."""
        self._rv_cache[key] = voting
        while len(self._rv_cache) > 16:
            self._rv_cache.popitem(last=False)

    def wait_plain_rv(self, timeout: float = 60.0) -> laav.Voting | None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            v = self.plain_rv()
            if v is not None:
                return v
            time.sleep(0.02)
        return None

    def threads(self) -> list[threading.Thread]:
        """The worker threads of this state still running (the pipeline's, plain RV's, the
        drawn votes')."""
        tag = self._thread_tag + "-"
        return [t for t in threading.enumerate() if t.name.startswith(tag)]

    def close(self, timeout: float | None = 10.0) -> bool:
        """Stop: queued jobs are dropped, the running ones stop at their next check (every
        stage checks between steps), and their threads are joined for up to ``timeout``
        seconds (None: no wait). True when every worker thread has ended."""
        self._closed = True
        with self._lock:
            self._gen += 1  # anything still queued is now stale
            self._rv_key = None  # plain RV computing now stops at its next check
            self._idle.notify_all()  # a computation ahead waiting for a job stops now
        workers = (self._worker, self._rv_worker, self._votes_worker)
        for w in workers:
            w.shutdown(wait=False, cancel_futures=True)
        if timeout is None:
            return False
        deadline = time.monotonic() + timeout
        threads = self.threads()
        for t in threads:
            t.join(max(0.0, deadline - time.monotonic()))
        return not any(t.is_alive() for t in threads)
