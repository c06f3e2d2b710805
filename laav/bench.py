"""Benchmark runner: every sequence x method x seed x noise level x missing share of a
Hopkins155-style folder.

The results go to ``runs.csv`` (one row per run, :data:`COLUMNS`), which is the single
source of every number in the report (:mod:`laav.report`). The runner

* reads ``<seq>/<seq>_truth.mat`` folders (skipping ``dancing``, rows of ``sequences.csv``
  with ``in_hopkins155 = no`` and anything that is not a readable truth file, each with a
  message);
* adds zero-mean Gaussian pixel noise ``N(0, sigma^2 I)`` to every trajectory point from a
  generator seeded by ``(seed, crc32(sequence name), round(sigma * 1e6))`` only, so a run
  gives the same result wherever and in whatever order it executes;
* then, for a missing share ``m > 0``, hides ``round(m F P)`` of the (frame, point) entries
  with the seeded occlusion model :func:`laav.synthetic.occlude` (tracks start late, end
  early and have one gap; ``spread`` :data:`laav.synthetic.BENCH_SPREAD`) and the generator
  :func:`laav.synthetic.occlusion_rng` ``(seed, sequence name, m)``: the same entries as
  ``benchmarks/missing.py`` hides;
* runs LAAV (:func:`laav.segment`) and/or plain Random Voting (:func:`laav.random_voting`)
  with the run's seed;
* appends each batch of rows to ``runs.csv`` as soon as it arrives (so an interrupted
  bench keeps what finished) and skips, on a rerun with the same output folder, every run
  whose key ``(sequence, method, seed, noise, missing)`` is already there;
* runs batches in parallel processes with joblib, or on a Dask distributed cluster;
* records which code made every row (``version``, ``commit``: :mod:`laav._provenance`,
  taken where the run executes) and in ``bench.json``; a resume under another commit or
  version is refused unless ``allow_mixed`` (``--allow-mixed``).

Only the public API of :mod:`laav` is used. Everything here is importable without
matplotlib, joblib, tqdm or dask; they are imported when needed.
"""

from __future__ import annotations

import csv
import dataclasses
import fnmatch
import json
import math
import os
import sys
import time
import zlib
from collections.abc import Callable, Iterable
from collections.abc import Sequence as SeqT
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from . import (
    LaavParams,
    Sequence,
    SequenceError,
    load_sequence,
    misclassification_rate,
    random_voting,
    segment,
)
from ._provenance import provenance
from .params import PRESETS  # the named presets (``--preset``), also read here
from .synthetic import BENCH_SPREAD, occlude, occlusion_rng

__all__ = [
    "COLUMNS", "KEY", "METHODS", "BenchError", "BenchSequence", "BenchSummary",
    "parse_param", "params_from_assignments", "parse_noise", "format_noise", "noise_rng",
    "add_pixel_noise", "parse_missing", "MAX_MISSING", "hide_entries", "run_one", "discover",
    "plan_runs", "read_runs", "run_key", "run_bench",
]

#: Columns of ``runs.csv``, in order. ``missing`` is the share of the F x P entries hidden
#: (0: the complete sequence); ``unlabelled`` the share (%) of points the method left
#: without a label (-1; counted as errors in ``error``). ``version`` and ``commit`` name the
#: code that made the row (package version; git short hash with ``-dirty``, or ``unknown``).
COLUMNS = ("sequence", "category", "motions", "points", "frames", "method", "seed", "noise",
           "missing", "error", "unlabelled", "seconds", "iterations", "trials", "converged",
           "version", "commit")
#: The columns of files written before ``missing`` and ``unlabelled`` existed (still read:
#: missing 0, unlabelled unknown (NaN); rewritten with them by a resume).
NO_MISSING_COLUMNS = tuple(c for c in COLUMNS if c not in ("missing", "unlabelled"))
#: The columns of files written before the provenance columns (still read; "" for them).
LEGACY_COLUMNS = NO_MISSING_COLUMNS[:-2]
#: Columns that identify a run (resume key).
KEY = ("sequence", "method", "seed", "noise", "missing")
#: Missing shares must lie in [0, MAX_MISSING).
MAX_MISSING = 0.95
#: Methods the bench knows: LAAV and plain Random Voting.
METHODS = ("laav", "rv")

RUNS_CSV = "runs.csv"
META_JSON = "bench.json"
FAILURES_LOG = "failures.log"

_INT_COLS = ("motions", "points", "frames", "seed", "iterations", "trials")
_FLOAT_COLS = ("noise", "error", "seconds")
_OLD_HEADERS = {COLUMNS: "current", NO_MISSING_COLUMNS: "no-missing",
                LEGACY_COLUMNS: "legacy"}
_NOT_IN_BENCHMARK = ("dancing",)
_METADATA_FILES = ("README.md", "sequences.csv")


class BenchError(Exception):
    """A problem with the bench's inputs or output folder (reported without traceback)."""


# --------------------------------------------------------------------------- parameters


def _convert(raw: str):
    low = raw.strip().lower()
    if low in ("none", "null"):
        return None
    if low in ("true", "yes", "on"):
        return True
    if low in ("false", "no", "off"):
        return False
    for cast in (int, float):
        try:
            return cast(raw)
        except ValueError:
            pass
    return raw


def _choices(key: str) -> tuple:
    """The allowed strings of a ``"choice"`` field of :class:`~laav.LaavParams` (else ())."""
    from .params import _BOUNDS

    return next((lo for name, kind, lo, _ in _BOUNDS if name == key and kind == "choice"), ())


def parse_param(text: str) -> tuple[str, object]:
    """Parse ``"key=value"`` into a :class:`~laav.LaavParams` field name and a value.

    Numbers, ``true``/``false`` and ``none`` are converted (``none`` stays a string for a
    field that has it among its choices: ``rv_select=none``); an integer given for a float
    field becomes a float. Validation of the value itself is left to ``LaavParams``.

    Raises
    ------
    BenchError
        When the text has no ``=`` or names no ``LaavParams`` field.
    """
    if "=" not in text:
        raise BenchError(f"--param expects key=value, got {text!r}")
    key, raw = (s.strip() for s in text.split("=", 1))
    names = [f.name for f in dataclasses.fields(LaavParams)]
    if key not in names:
        raise BenchError(f"unknown LAAV parameter {key!r} (known: {', '.join(names)})")
    value = _convert(raw)
    if value is None and raw.strip().lower() in _choices(key):
        value = raw.strip().lower()  # a choice named "none" (rv_select=none), not None
    default = getattr(LaavParams(), key)
    if isinstance(default, bool) and isinstance(value, int) and value in (0, 1):
        value = bool(value)
    elif isinstance(default, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    return key, value


def read_params_file(path, base: LaavParams) -> tuple[LaavParams, int | None]:
    """A params file the explorer exported (or a bare ``{field: value}`` object): its
    parameters on ``base`` (:meth:`LaavParams.from_json`) and its seed (None when it names
    none). Raises :class:`BenchError` naming the file when it cannot be read, is not one, or
    holds an invalid parameter or seed."""
    try:
        with open(path, "rb") as fh:
            text = fh.read(1 << 20)
    except OSError as exc:
        raise BenchError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    try:
        params = LaavParams.from_json(text, base)
    except ValueError as exc:
        raise BenchError(f"{path}: {exc}") from None
    seed = json.loads(text).get("seed")  # (an object: from_json checked it)
    if seed is not None and (not isinstance(seed, int) or isinstance(seed, bool) or not 0 <= seed < 2**63):
        raise BenchError(f"{path}: seed must be a whole number in [0, 2**63), got {str(seed)[:40]}")
    return params, seed


def params_from_assignments(assignments: Iterable[str] | None, preset: str = "default",
                            params_file: str | None = None) -> LaavParams:
    """A :class:`~laav.LaavParams` with the ``key=value`` assignments applied to a preset:
    ``"default"`` (``LaavParams()``, ours), ``"paper"`` (:meth:`LaavParams.paper`) or
    ``"with-plain-rv"`` (:meth:`LaavParams.with_plain_rv`); with ``params_file`` (a params
    file the explorer exported, :func:`read_params_file`) its fields first, then the
    assignments (:func:`params_and_seed`, without the file's seed).

    Raises
    ------
    BenchError
        For a malformed assignment, an unknown field or an invalid value, or a params file
        that cannot be read or is not one (naming the file).
    """
    return params_and_seed(assignments, preset, params_file)[0]


def params_and_seed(assignments: Iterable[str] | None, preset: str = "default",
                    params_file: str | None = None) -> tuple[LaavParams, int | None]:
    """:func:`params_from_assignments`, and the params file's seed (None without a file or
    when it names none): the file is read once."""
    changes = dict(parse_param(a) for a in (assignments or ()))
    if preset not in PRESETS:
        raise BenchError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    base, seed = PRESETS[preset](), None
    if params_file is not None:
        base, seed = read_params_file(params_file, base)
    try:
        return base.replace(**changes), seed
    except (ValueError, TypeError) as exc:
        raise BenchError(str(exc)) from None


# --------------------------------------------------------------------------- noise


def format_noise(sigma: float) -> str:
    """The text written to ``runs.csv`` for a noise level (exact, shortest: ``0.5``, ``2``)."""
    return np.format_float_positional(float(sigma), trim="-")


def _parse_levels(text, what: str, example: str, valid, rule: str) -> tuple[float, ...]:
    """Levels from ``"0,0.5"`` or a sequence of numbers, each checked by ``valid``; sorted,
    unique, written as :func:`format_noise` writes them."""
    items = text.split(",") if isinstance(text, str) else list(text)
    out = []
    for item in items:
        if isinstance(item, str) and not item.strip():
            continue
        try:
            v = float(item)
        except (TypeError, ValueError):
            raise BenchError(f"{what} {item!r} is not a number (e.g. {example})") from None
        if not (math.isfinite(v) and valid(v)):
            raise BenchError(f"{what} must be {rule}, got {item!r}")
        out.append(float(format_noise(v)))
    if not out:
        raise BenchError(f"no {what} given (e.g. {example})")
    return tuple(sorted(set(out)))


def parse_noise(text: str | Iterable[float]) -> tuple[float, ...]:
    """Noise levels (pixels) from ``"0,0.5,1,2"`` or a sequence of numbers; sorted, unique."""
    return _parse_levels(text, "noise level", "--noise 0,0.5,1,2", lambda v: v >= 0,
                         "a finite number >= 0 px")


def parse_missing(text: str | Iterable[float]) -> tuple[float, ...]:
    """Missing shares from ``"0,0.2,0.4"`` or a sequence of numbers, each in [0, 0.95);
    sorted, unique."""
    return _parse_levels(text, "missing share", "--missing 0,0.2,0.4",
                         lambda v: 0.0 <= v < MAX_MISSING,
                         f"a number in [0, {MAX_MISSING:g}) (a share of the entries, not a "
                         f"percentage)")


def hide_entries(seq: Sequence, missing: float, seed: int) -> Sequence:
    """``seq`` with a share ``missing`` of its entries hidden by the seeded occlusion model.

    ``missing == 0`` returns ``seq`` unchanged. The hidden entries depend only on ``(seed,
    seq.name, missing)`` (:func:`laav.synthetic.occlusion_rng`), as in
    ``benchmarks/missing.py``.
    """
    if missing == 0:
        return seq
    return occlude(seq, missing, occlusion_rng(seed, seq.name, missing), spread=BENCH_SPREAD)


def noise_rng(seed: int, name: str, sigma: float) -> np.random.Generator:
    """The generator of the noise of run ``(name, seed, sigma)``; independent of method."""
    entropy = [int(seed), zlib.crc32(name.encode("utf-8")), int(round(float(sigma) * 1e6))]
    return np.random.default_rng(np.random.SeedSequence(entropy))


def add_pixel_noise(seq: Sequence, sigma: float, seed: int) -> Sequence:
    """``seq`` with N(0, sigma^2 I) pixel noise on every point of every frame (a copy).

    ``sigma == 0`` returns ``seq`` unchanged. The noise depends only on ``(seed,
    seq.name, sigma)``.
    """
    if sigma == 0:
        return seq
    rng = noise_rng(seed, seq.name, sigma)
    return seq.with_points(seq.points + rng.normal(0.0, float(sigma), size=seq.points.shape))


# --------------------------------------------------------------------------- one run


@dataclass(frozen=True, eq=False)
class BenchSequence:
    """A benchmark sequence: its ground truth and where it came from."""

    name: str
    category: str
    seq: Sequence
    path: str = ""

    @property
    def motions(self) -> int:
        return int(self.seq.n_motions)


def run_one(item: BenchSequence, method: str, seed: int, sigma: float,
            params: LaavParams | None = None, missing: float = 0.0) -> dict:
    """Run one method on one (noisy, occluded) sequence and score it; a ``runs.csv`` row
    (typed).

    The noise is added first, then a share ``missing`` of the entries hidden
    (:func:`hide_entries`). ``error`` is the misclassification rate in percent over all
    points (a point left unlabelled counts as wrong); ``unlabelled`` the share (%) of such
    points; ``seconds`` the wall time of the segmentation call alone; ``iterations``,
    ``trials`` and ``converged`` come from the Random Voting stage (LAAV's fine-tuning, or
    plain RV).
    """
    seq = hide_entries(add_pixel_noise(item.seq, sigma, seed), missing, seed)
    C = item.motions
    t0 = time.perf_counter()
    if method == "laav":
        voting = segment(seq, C, params, seed).voting
    elif method == "rv":
        voting = random_voting(seq, C, params, seed)
    else:
        raise ValueError(f"unknown method {method!r} (known: {', '.join(METHODS)})")
    seconds = time.perf_counter() - t0
    error = 100.0 * misclassification_rate(item.seq.labels, voting.labels)
    return {
        "sequence": item.name, "category": item.category, "motions": C,
        "points": item.seq.n_points, "frames": item.seq.n_frames, "method": method,
        "seed": int(seed), "noise": float(sigma), "missing": float(missing),
        "error": float(error), "unlabelled": 100.0 * float(np.mean(voting.labels < 0)),
        "seconds": seconds,
        "iterations": int(voting.n_iterations), "trials": int(voting.n_trials),
        "converged": bool(voting.converged), **provenance(),
    }


_WARM = False


def _warm_up_sequence() -> Sequence:
    """A small two-motion scene (two rigid point clouds seen by a fixed pinhole camera)."""
    rng = np.random.default_rng(12345)
    F, n = 8, 40
    pts = []
    for k in range(2):
        X = rng.uniform(-1, 1, (n, 3)) + np.array([2.5 * k - 1.2, 0.0, 6.0])
        frames = []
        for f in range(F):
            a = 0.04 * f * (1 if k else -1)
            R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
            c = X.mean(0)
            Y = (X - c) @ R.T + c + np.array([0.05 * f * (k - 0.5), 0.03 * f * k, 0.0])
            frames.append(320 + 500 * Y[:, :2] / Y[:, 2:])
        pts.append(np.stack(frames))
    return Sequence(np.concatenate(pts, axis=1), np.repeat([0, 1], n), name="warm-up")


def _warm_up(params: LaavParams) -> None:
    """Run both methods once, untimed, so that one-off costs (lazy imports of the
    algorithm's dependencies, caches) do not land in the first run's ``seconds``."""
    global _WARM
    if _WARM:
        return
    _WARM = True
    seq = _warm_up_sequence()
    small = params.replace(rv_max_iter=min(params.rv_max_iter, 5), rv_trials=1)
    try:
        segment(seq, 2, small, 0)
        random_voting(seq, 2, small, 0)
    except Exception:  # best effort only; a real failure shows up in the real runs
        pass


@dataclass(frozen=True, eq=False)
class _Batch:
    item: BenchSequence
    runs: tuple  # of (method, seed, sigma, missing)


def _run_batch(batch: _Batch, params: LaavParams) -> list:
    """Run a batch (worker side); a failure becomes a ``("failed", key, message)`` record."""
    _warm_up(params)
    out = []
    for method, seed, sigma, missing in batch.runs:
        try:
            out.append(("ok", run_one(batch.item, method, seed, sigma, params, missing)))
        except Exception as exc:  # one bad run must not stop the bench
            key = (batch.item.name, method, int(seed), float(sigma), float(missing))
            out.append(("failed", key, f"{type(exc).__name__}: {exc}"))
    return out


# --------------------------------------------------------------------------- discovery


def _read_sequences_csv(root: Path) -> dict:
    path = root / "sequences.csv"
    if not path.is_file():
        return {}
    with open(path, newline="") as fh:
        return {row.get("sequence", ""): row for row in csv.DictReader(fh)}


def _matches(name: str, only: SeqT[str] | None) -> bool:
    return not only or any(fnmatch.fnmatchcase(name, g) for g in only)


def discover(data: str | os.PathLike, only: SeqT[str] | None = None,
             log: Callable[[str], None] = print, max_points: int | None = None) -> list[BenchSequence]:
    """The benchmark sequences of a Hopkins155-style folder, sorted by name.

    Parameters
    ----------
    data : path
        Folder of ``<seq>/<seq>_truth.mat`` (and optionally ``sequences.csv`` with columns
        ``sequence``, ``category``, ``in_hopkins155``).
    only : list of str, optional
        Glob patterns on sequence names; only matching sequences are used.
    log : callable
        Receives one message per skipped entry: a folder without a sequence, a file that
        cannot be read (parsed in a child process, so even a file crashing the MAT reader
        is only skipped), one with more than ``max_points`` points, or without labels.
    max_points : int, optional
        Most points a sequence may have (default :data:`laav.io.MAX_POINTS`); a larger
        one is skipped with a message.

    Raises
    ------
    BenchError
        When ``data`` is not a folder or no sequence is left.
    """
    root = Path(data)
    if not root.is_dir():
        raise BenchError(f"{root}: not a folder (expected a Hopkins155-style data folder)")
    meta = _read_sequences_csv(root)
    found = []
    for entry in sorted(root.iterdir(), key=lambda p: p.name):
        name = entry.name
        if name.startswith(".") or name in _METADATA_FILES:
            continue
        if not _matches(name, only):
            continue
        if not entry.is_dir():
            log(f"skipping {name}: not a sequence folder")
            continue
        row = meta.get(name, {})
        if name in _NOT_IN_BENCHMARK or row.get("in_hopkins155", "").strip().lower() == "no":
            log(f"skipping {name}: not one of the Hopkins155 benchmark sequences")
            continue
        truth = entry / f"{name}_truth.mat"
        if not truth.is_file():
            log(f"skipping {name}: no {name}_truth.mat in the folder")
            continue
        try:
            # isolated: a damaged file can't crash the bench
            seq = load_sequence(truth, isolated=True, max_points=max_points)
        except SequenceError as exc:
            log(f"skipping {name}: {exc}")
            continue
        if seq.labels is None:
            log(f"skipping {name}: {truth} has no ground-truth labels (variable 's')")
            continue
        found.append(BenchSequence(name=name, category=row.get("category", "").strip(),
                                   seq=seq, path=str(truth)))
    if not found:
        what = f" matching {', '.join(only)}" if only else ""
        raise BenchError(f"{root}: no benchmark sequences{what} (expected <seq>/<seq>_truth.mat)")
    return found


def plan_runs(sequences: SeqT[BenchSequence], methods: SeqT[str], seeds: int,
              noise: SeqT[float], missing: SeqT[float] = (0.0,)) -> list[tuple]:
    """Every ``(sequence name, method, seed, sigma, missing)``: sequences x methods x seeds x
    noise x missing shares."""
    return [(s.name, m, seed, float(sigma), float(share)) for s in sequences for share in missing
            for sigma in noise for seed in range(seeds) for m in methods]


# --------------------------------------------------------------------------- runs.csv


def run_key(row: dict) -> tuple:
    """``(sequence, method, seed, noise, missing)`` of a typed row (missing 0 when absent)."""
    return (row["sequence"], row["method"], int(row["seed"]), float(row["noise"]),
            float(row.get("missing", 0.0)))


def _parse_row(raw: dict) -> dict | None:
    try:
        row = {c: raw[c] for c in LEGACY_COLUMNS}
        if any(v is None for v in row.values()) or not row["sequence"] or not row["method"]:
            return None
        for c in _INT_COLS:
            row[c] = int(row[c])
        for c in _FLOAT_COLS:
            row[c] = float(row[c])
        conv = row["converged"].strip().lower()
        if conv not in ("true", "false"):
            return None
        row["converged"] = conv == "true"
    except (KeyError, ValueError, TypeError, AttributeError):
        return None
    try:  # files from before these columns: complete data, unlabelled share not recorded
        row["missing"] = float(raw.get("missing") or 0.0)
        unl = raw.get("unlabelled")
        row["unlabelled"] = float(unl) if unl not in (None, "") else float("nan")
    except (ValueError, TypeError):
        return None
    row["version"] = raw.get("version") or ""  # "" in files from before these columns
    row["commit"] = raw.get("commit") or ""
    return row


def _format_row(row: dict) -> dict:
    out = dict(row)
    out["noise"] = format_noise(row["noise"])
    out["missing"] = format_noise(row.get("missing", 0.0))
    out["error"] = repr(float(row["error"]))
    unl = float(row.get("unlabelled", float("nan")))
    out["unlabelled"] = f"{unl:.4f}" if math.isfinite(unl) else ""
    out["seconds"] = f"{row['seconds']:.4f}"
    out["converged"] = "True" if row["converged"] else "False"
    return out


def read_runs(path: str | os.PathLike, repair: bool = False) -> list[dict]:
    """The rows of a ``runs.csv``, typed (ints, floats, bool ``converged``).

    A row that cannot be parsed (e.g. a line cut short when the bench was killed) and a
    repeated key are dropped; with ``repair=True`` the file is then rewritten without
    them. A file with the columns of before ``version`` and ``commit`` existed
    (:data:`LEGACY_COLUMNS`) is read with "" there, one from before ``missing`` and
    ``unlabelled`` (:data:`NO_MISSING_COLUMNS`) with missing 0 (complete data) and
    unlabelled NaN (not recorded); ``repair`` rewrites either with the current columns.

    Raises
    ------
    BenchError
        When the file's header is none of these.
    """
    path = Path(path)
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        header = tuple(reader.fieldnames or ())
        legacy = header in _OLD_HEADERS and header != COLUMNS
        if header not in _OLD_HEADERS:
            raise BenchError(
                f"{path}: unexpected columns {reader.fieldnames}; expected {','.join(COLUMNS)} "
                "(use a new --out folder)"
            )
        rows, seen, bad = [], set(), 0
        for raw in reader:
            row = _parse_row(raw)
            if row is None or run_key(row) in seen:
                bad += 1
                continue
            seen.add(run_key(row))
            rows.append(row)
    if (bad or legacy) and repair:
        _write_rows(path, rows)
    return rows


def _write_rows(path: Path, rows: list[dict]) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(_format_row(r) for r in rows)
    os.replace(tmp, path)


def _sort_key(row: dict) -> tuple:
    return (row["sequence"], row["method"], row.get("missing", 0.0), row["noise"], row["seed"])


# --------------------------------------------------------------------------- meta


def _code(version: str, commit: str) -> str:
    return f"laav {version or '?'} at git {commit or 'unrecorded'}"


def _check_meta(out: Path, params: LaavParams, existing: list[dict], allow_mixed: bool) -> None:
    """Refuse to resume ``out`` with other parameters, or (unless ``allow_mixed``) under
    other code than made its rows; then write ``bench.json``."""
    meta_path = out / META_JSON
    current = params.to_dict()
    try:
        old_meta = json.loads(meta_path.read_text()) if meta_path.is_file() else {}
    except (OSError, ValueError):
        old_meta = None
    if old_meta is not None and (out / RUNS_CSV).is_file():
        old = old_meta.get("params", {})
        if old_meta and old != current:
            diff = sorted(set(old) | set(current))
            diff = [f"{k}: {old.get(k)!r} -> {current.get(k)!r}" for k in diff
                    if old.get(k) != current.get(k)]
            raise BenchError(
                f"{out / RUNS_CSV} was made with other LAAV parameters ({'; '.join(diff)}); "
                "use a new --out folder, or the same --param options (LAAV's defaults may "
                "have changed since)"
            )
    code = provenance()
    this = (code["version"], code["commit"])
    made_by = {(r["version"], r["commit"]) for r in existing}
    others = sorted(made_by - {this})
    if others and not allow_mixed:
        raise BenchError(
            f"{out / RUNS_CSV} holds runs made by other code ({'; '.join(_code(*c) for c in others)}) "
            f"than this {_code(*this)}; use a new --out folder, or --allow-mixed to add runs "
            "anyway (every row records the code that made it)"
        )
    meta = {"laav_version": code["version"], "commit": code["commit"], "params": current,
            "updated": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    if others:
        meta["mixed"] = [_code(*c) for c in sorted(made_by | {this})]
    meta_path.write_text(json.dumps(meta, indent=2) + "\n")


# --------------------------------------------------------------------------- runner


class _OutLock:
    """An exclusive lock on the output folder, so two benches never write one runs.csv."""

    def __init__(self, out: Path):
        self.path = out / ".bench.lock"
        self.fh = None

    def __enter__(self):
        try:
            import fcntl
        except ImportError:  # not POSIX: no lock
            return self
        self.fh = open(self.path, "w")
        try:
            fcntl.flock(self.fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            self.fh.close()
            self.fh = None
            raise BenchError(f"{self.path.parent}: another laav bench is writing here; wait for "
                             "it or use another --out") from None
        return self

    def __exit__(self, *exc):
        if self.fh is not None:
            self.fh.close()  # releases the lock
        return False


@dataclass
class BenchSummary:
    """What :func:`run_bench` did."""

    out: Path
    runs_csv: Path
    report: Path | None = None
    sequences: int = 0
    planned: int = 0
    already_done: int = 0
    completed: int = 0
    failed: list = field(default_factory=list)
    interrupted: bool = False


def _batches(items: dict, todo: list[tuple], n_workers: int, max_batch: int) -> list[_Batch]:
    """Group runs by sequence (the sequence is shipped once per batch), in chunks small
    enough that every worker gets several batches."""
    size = max(1, min(max_batch, math.ceil(len(todo) / max(1, 4 * n_workers))))
    by_seq: dict = {}
    for name, method, seed, sigma, share in todo:
        by_seq.setdefault(name, []).append((method, seed, sigma, share))
    out = []
    for name, runs in by_seq.items():
        for i in range(0, len(runs), size):
            out.append(_Batch(items[name], tuple(runs[i:i + size])))
    return out


def _results_joblib(make_batches, params, jobs):
    from joblib import Parallel, delayed

    batches = make_batches(_n_workers(jobs))
    # processes (loky), each running its batches with the pipeline's one BLAS/OpenMP thread
    par = Parallel(n_jobs=jobs, backend="loky", return_as="generator_unordered", batch_size=1)
    gen = par(delayed(_run_batch)(b, params) for b in batches)
    try:
        yield from gen
    finally:
        gen.close()


def _results_dask(make_batches, params, address):
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise BenchError("--scheduler needs dask.distributed: pip install 'laav[dask]'") from None
    try:
        client = Client(address, timeout="30s")
    except (OSError, TimeoutError) as exc:
        raise BenchError(f"cannot connect to the Dask scheduler at {address}: {exc}") from None
    try:
        batches = make_batches(max(1, sum(client.nthreads().values())))
        futures = client.map(_run_batch, batches, params=params, pure=False)
        try:
            for fut in as_completed(futures):
                yield fut.result()
        finally:
            client.cancel(futures)
    finally:
        client.close()


def _n_workers(jobs: int | None) -> int:
    n = os.cpu_count() or 1
    if jobs is None or jobs == 0:
        return n
    return jobs if jobs > 0 else max(1, n + 1 + jobs)


def run_bench(
    data: str | os.PathLike,
    out: str | os.PathLike = "bench-out",
    methods: SeqT[str] = METHODS,
    seeds: int = 1,
    noise: SeqT[float] = (0.0,),
    only: SeqT[str] | None = None,
    jobs: int | None = None,
    scheduler: str | None = None,
    params: LaavParams | None = None,
    progress: bool = True,
    report: bool = True,
    max_batch: int = 8,
    log: Callable[[str], None] | None = None,
    allow_mixed: bool = False,
    max_points: int | None = None,
    missing: SeqT[float] = (0.0,),
) -> BenchSummary:
    """Run (or resume) a benchmark and write ``runs.csv`` and the report into ``out``.

    Parameters
    ----------
    data : path
        Hopkins155-style folder (see :func:`discover`).
    out : path
        Output folder; created if needed. Runs already in its ``runs.csv`` are skipped.
    methods : sequence of {"laav", "rv"}
    seeds : int
        Seeds ``0 .. seeds-1`` per sequence, method and noise level.
    noise : sequence of float
        Noise levels sigma in pixels.
    missing : sequence of float
        Shares in [0, 0.95) of the F x P entries to hide after the noise (0: complete
        data); see :func:`hide_entries`. A share a sequence cannot lose (every track keeps
        2 frames, so at most 1 - 2 / F) makes its runs fail with a message.
    only : sequence of str, optional
        Glob patterns on sequence names.
    jobs : int, optional
        Worker processes (joblib; None or 0 = all cores, negative as in joblib).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:port``); the runs go there
        instead of local processes. Workers need the same ``laav`` installed.
    params : LaavParams, optional
        Parameters of both methods; recorded in ``bench.json`` and checked on resume.
    progress : bool
        Show a tqdm progress bar (stderr).
    report : bool
        Write ``report.md`` and the figures at the end.
    max_batch : int
        Most runs sent to a worker at once.
    log : callable, optional
        Receives messages (default: print to stderr).
    allow_mixed : bool
        Resume even when ``runs.csv`` holds rows made by another package version or git
        commit than the running code (refused by default).
    max_points : int, optional
        Most points a sequence may have (default :data:`laav.io.MAX_POINTS`); larger ones
        are skipped with a message (see :func:`discover`).

    Returns
    -------
    BenchSummary
        ``interrupted`` is True after Ctrl-C (what finished is in ``runs.csv``).
    """
    say = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    methods = tuple(methods)
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise BenchError(f"unknown method(s) {bad or methods}; choose from {', '.join(METHODS)}")
    if not isinstance(seeds, int) or seeds < 1:
        raise BenchError(f"--seeds must be a positive integer, got {seeds!r}")
    noise = parse_noise(noise)
    missing = parse_missing(missing)
    params = LaavParams() if params is None else params

    # inputs first, then the output
    items = {s.name: s for s in discover(data, only, say, max_points=max_points)}

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with _OutLock(out):
        return _run_locked(items, out, methods, seeds, noise, jobs, scheduler, params, progress,
                           report, max_batch, say, allow_mixed, missing)


def _run_locked(items, out, methods, seeds, noise, jobs, scheduler, params, progress, report,
                max_batch, say, allow_mixed, missing=(0.0,)) -> BenchSummary:
    runs_csv = out / RUNS_CSV
    if runs_csv.is_file() and runs_csv.stat().st_size == 0:
        runs_csv.unlink()
    existing = read_runs(runs_csv, repair=True) if runs_csv.is_file() else []
    _check_meta(out, params, existing, allow_mixed)

    planned = plan_runs(list(items.values()), methods, seeds, noise, missing)
    done = {run_key(r) for r in existing}
    todo = [k for k in planned if k not in done]
    summary = BenchSummary(out=out, runs_csv=runs_csv, sequences=len(items),
                           planned=len(planned), already_done=len(planned) - len(todo))
    if summary.already_done:
        say(f"resuming: {summary.already_done} of {len(planned)} runs already in {runs_csv}")

    new_file = not runs_csv.is_file()
    if todo:
        where = f"Dask scheduler {scheduler}" if scheduler else f"{_n_workers(jobs)} process(es)"
        say(f"running {len(todo)} of {len(planned)} runs ({len(items)} sequence(s) x "
            f"{len(methods)} method(s) x {seeds} seed(s) x {len(noise)} noise level(s) x "
            f"{len(missing)} missing share(s)) "
            f"on {where}")
    from tqdm import tqdm

    def make_batches(n_workers):
        return _batches(items, todo, n_workers, max_batch)

    bar = tqdm(total=len(todo), unit="run", desc="bench", disable=not progress or not todo,
               file=sys.stderr, dynamic_ncols=True)
    results = (_results_dask(make_batches, params, scheduler) if scheduler
               else _results_joblib(make_batches, params, jobs if jobs else -1))
    try:
        with open(runs_csv, "a", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=COLUMNS)
            if new_file:
                writer.writeheader()
                fh.flush()
            for records in (results if todo else ()):
                ok = [r[1] for r in records if r[0] == "ok"]
                writer.writerows(_format_row(r) for r in ok)
                fh.flush()
                for rec in records:
                    if rec[0] == "failed":
                        summary.failed.append((rec[1], rec[2]))
                        tqdm.write(f"FAILED {rec[1]}: {rec[2]}", file=sys.stderr)
                        with open(out / FAILURES_LOG, "a") as flog:
                            flog.write(f"{time.strftime('%Y-%m-%dT%H:%M:%S')} {rec[1]} {rec[2]}\n")
                summary.completed += len(ok)
                bar.update(len(records))
                bar.set_postfix_str(records[-1][1]["sequence"] if records[-1][0] == "ok"
                                    else records[-1][1][0], refresh=False)
    except KeyboardInterrupt:
        summary.interrupted = True
    finally:
        bar.close()
        if hasattr(results, "close"):
            results.close()

    rows = read_runs(runs_csv, repair=True)
    if not summary.interrupted:
        _write_rows(runs_csv, sorted(rows, key=_sort_key))
        if report and rows:
            from .report import write_report

            summary.report = write_report(out)
    return summary
