"""Per-stage timings of LAAV and Random Voting over Hopkins155, on one core.

For every sequence (true number of motions, default parameters, seed 0) this times

* LAAV: ``laav.Pipeline(seq, C)`` -- the per-stage seconds of ``LaavResult.timings``
  (atoms, graph, multicut, coarse, voting) and the wall time of the whole call (total);
* a lambda change: ``Pipeline.update(lam=1.5 * lam)`` on that pipeline (reruns the
  fine-to-coarse and voting stages only);
* plain Random Voting: ``laav.random_voting(seq, C)`` (total).

It prints medians and 90th percentiles (ms) over sequences, overall and by number of
motions, and writes the same as Markdown with the machine (platform, CPU model, cores)
and the date (``--out``, default ``bench-out/speed.md``).

One core: the BLAS/OpenMP thread counts are set to 1 in the environment before numpy is
imported, and the script runs in a single process. One untimed warm-up run comes first
so that lazy imports of the algorithm's dependencies do not land in the first sequence.

    python benchmarks/speed.py [--data DIR] [--every K] [--only GLOB] [--limit N] [--out FILE]

The data folder is ``--data``, else ``$HOPKINS155``, else ``../shared/data/hopkins155``
next to the repository. ``dancing`` and rows of ``sequences.csv`` with
``in_hopkins155 = no`` are skipped.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
             "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_var] = "1"  # one core: must happen before numpy is imported

import argparse  # noqa: E402
import csv  # noqa: E402
import fnmatch  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, git_commit  # noqa: E402 - this folder, on sys.path

import laav  # noqa: E402

#: Stage names, in pipeline order: the keys of ``LaavResult.timings`` (set by warm_up).
STAGES: tuple = ("atoms", "graph", "multicut", "coarse", "voting")
REPO = Path(__file__).resolve().parents[1]


def data_dir(arg: str | None) -> Path:
    """``--data``, else ``$HOPKINS155``, else ``../shared/data/hopkins155`` beside the repo."""
    if arg:
        return Path(arg).expanduser()
    if os.environ.get("HOPKINS155"):
        return Path(os.environ["HOPKINS155"]).expanduser()
    return REPO.parent / "shared" / "data" / "hopkins155"


def truth_files(root: Path, only: list[str]) -> list[Path]:
    """The benchmark's truth files, sorted by name, without ``dancing`` and excluded rows."""
    excluded = {"dancing"}
    table = root / "sequences.csv"
    if table.is_file():
        with open(table, newline="") as fh:
            excluded |= {r["sequence"] for r in csv.DictReader(fh)
                         if r.get("in_hopkins155", "").strip().lower() == "no"}
    files = [f for f in laav.find_truth_files(root) if f.parent.name not in excluded]
    if only:
        files = [f for f in files if any(fnmatch.fnmatchcase(f.parent.name, g) for g in only)]
    return files


def warm_up(seq) -> None:
    """One untimed run of everything timed below; takes the stage names from its timings."""
    global STAGES
    pipe = laav.Pipeline(seq, seq.n_motions)
    STAGES = tuple(pipe.result.timings)
    pipe.update(lam=pipe.params.lam * 1.5)
    laav.random_voting(seq, seq.n_motions, seed=0)


def time_sequence(seq, seed: int = 0) -> dict:
    """Seconds per stage (LAAV), total, lambda update and plain RV for one sequence."""
    C = seq.n_motions
    t = time.perf_counter()
    pipe = laav.Pipeline(seq, C, seed=seed)
    total = time.perf_counter() - t
    out = {s: float(pipe.result.timings.get(s, 0.0)) for s in STAGES}
    out["total"] = total
    before = pipe.result
    t = time.perf_counter()
    after = pipe.update(lam=pipe.params.lam * 1.5)
    out["update"] = time.perf_counter() - t
    out["update_reused_voting"] = after.voting is before.voting
    t = time.perf_counter()
    laav.random_voting(seq, C, seed=seed)
    out["rv"] = time.perf_counter() - t
    return out


def table(results: list[dict], title: str) -> list[str]:
    rows = [(s, f"LAAV {s}") for s in STAGES] + [
        ("total", "LAAV total (wall time of `Pipeline(seq, C)`)"),
        ("update", "λ change: `Pipeline.update(lam=1.5 λ)`"),
        ("rv", "plain Random Voting total"),
    ]
    lines = [f"### {title} ({len(results)} sequences)", "",
             "| | median ms | p90 ms |", "|---|---:|---:|"]
    for key, label in rows:
        v = 1000.0 * np.array([r[key] for r in results])
        lines.append(f"| {label} | {np.median(v):.1f} | {np.percentile(v, 90):.1f} |")
    return lines + [""]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="Hopkins155 folder (default $HOPKINS155 or ../shared/data/hopkins155)")
    ap.add_argument("--every", type=int, default=1, metavar="K",
                    help="use every K-th sequence by name (default 1: all)")
    ap.add_argument("--only", action="append", default=[], metavar="GLOB",
                    help="only sequences whose name matches (repeatable)")
    ap.add_argument("--limit", type=int, default=None, metavar="N", help="at most N sequences")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="bench-out/speed.md", help="Markdown report (default %(default)s)")
    args = ap.parse_args(argv)
    if args.every < 1 or (args.limit is not None and args.limit < 1):
        ap.error("--every and --limit must be positive")

    root = data_dir(args.data)
    if not root.is_dir():
        print(f"speed.py: error: {root}: no such folder (give --data or set HOPKINS155)",
              file=sys.stderr)
        return 2
    files = truth_files(root, args.only)[:: args.every][: args.limit]
    if not files:
        print(f"speed.py: error: no benchmark *_truth.mat files under {root}", file=sys.stderr)
        return 2

    seqs = [laav.load_sequence(f) for f in files]
    warm_up(seqs[0])
    results = []
    started = time.strftime("%Y-%m-%d %H:%M %Z")
    t0 = time.perf_counter()
    for i, seq in enumerate(seqs, 1):
        r = time_sequence(seq, args.seed)
        r["motions"] = seq.n_motions
        results.append(r)
        print(f"[{i}/{len(seqs)}] {seq.name}: LAAV {r['total']:.2f} s, update {r['update']:.2f} s, "
              f"RV {r['rv']:.2f} s", file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - t0

    stage_sum = np.array([sum(r[s] for s in STAGES) for r in results])
    overhead = np.array([r["total"] for r in results]) - stage_sum
    lines = [
        f"# LAAV speed on Hopkins155, one core ({started})",
        "",
        f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores (one used), "
        f"{platform.system()} {platform.release()} {platform.machine()}",
        f"- Software: Python {platform.python_version()}, numpy {np.__version__}, "
        f"laav {laav.__version__} (git {git_commit()})",
        f"- Data: {len(seqs)} sequences of {root}"
        + (f" (every {args.every}th)" if args.every > 1 else "")
        + (f", only {', '.join(args.only)}" if args.only else ""),
        f"- Settings: default `LaavParams`, true number of motions, seed {args.seed}; "
        "BLAS/OpenMP threads = 1; one untimed warm-up run",
        f"- Wall time of the measurement: {elapsed:.0f} s. Per-stage times are "
        "`LaavResult.timings`; total minus their sum (call overhead) has median "
        f"{1000 * np.median(overhead):.1f} ms.",
        f"- The λ change left the coarse labels as they were, so `Pipeline.update` reused the "
        f"fine-tuning, on {sum(r['update_reused_voting'] for r in results)} of {len(results)} "
        "sequences; on the others it reran it.",
        "",
    ]
    lines += table(results, "All sequences")
    for k in sorted({r["motions"] for r in results}):
        lines += table([r for r in results if r["motions"] == k], f"{k} motions")
    text = "\n".join(lines)
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"written: {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
