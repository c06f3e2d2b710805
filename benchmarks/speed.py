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

``--threads`` measures instead what the pipeline's own thread cap (one BLAS/OpenMP thread
during a run, :mod:`laav._threads`) does, in fresh processes: the wall time of
``Pipeline(seq, C)`` and of ``random_voting`` (median of ``--repeats``) with the
environment's default thread counts against the one-thread environment of the per-stage
timings, each alone and with one busy core beside it (another process spinning), and the
same with the cap switched off (``laav._threads.MAX_THREADS = None``). It prints the
ratios to the one-thread time; ``--only`` defaults to ``people1`` there::

    python benchmarks/speed.py --threads [--only GLOB] [--repeats N] [--rounds N] [--out FILE]

The data folder is ``--data``, else ``$HOPKINS155``, else ``../shared/data/hopkins155``
next to the repository. ``dancing`` and rows of ``sequences.csv`` with
``in_hopkins155 = no`` are skipped.
"""

from __future__ import annotations

import os
import sys

THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
               "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")
if "--threads-child" not in sys.argv:  # a --threads child keeps the environment it is given
    for _var in THREAD_VARS:
        os.environ[_var] = "1"  # one core: must happen before numpy is imported

import argparse  # noqa: E402
import csv  # noqa: E402
import fnmatch  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
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
    out["iterations"] = pipe.result.voting.n_iterations
    out["converged"] = pipe.result.voting.converged
    before = pipe.result
    t = time.perf_counter()
    after = pipe.update(lam=pipe.params.lam * 1.5)
    out["update"] = time.perf_counter() - t
    out["update_reused_voting"] = after.voting is before.voting
    t = time.perf_counter()
    rv = laav.random_voting(seq, C, seed=seed)
    out["rv"] = time.perf_counter() - t
    out["rv_iterations"] = rv.n_iterations
    return out


def ratios(results: list[dict]) -> list[str]:
    """LAAV against plain RV measured in the same run: time and voting iterations."""
    lines = ["### LAAV against plain RV (same run, same sequences)", "",
             "| sequences | LAAV / RV median time | LAAV / RV median voting iterations | "
             "LAAV fine-tuning converged |", "|---|---|---|---|"]
    for k in [None, *sorted({r["motions"] for r in results})]:
        rs = [r for r in results if k is None or r["motions"] == k]
        t, t_rv = (np.median([r[key] for r in rs]) for key in ("total", "rv"))
        it, it_rv = (np.median([r[key] for r in rs]) for key in ("iterations", "rv_iterations"))
        lines.append(f"| {'all' if k is None else f'{k} motions'} ({len(rs)}) | "
                     f"{t / t_rv:.2f} ({1e3 * t:.0f} / {1e3 * t_rv:.0f} ms) | "
                     f"{it / max(it_rv, 1):.2f} ({it:.0f} / {it_rv:.0f}) | "
                     f"{100 * np.mean([r['converged'] for r in rs]):.0f} % |")
    return lines + [""]


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


# ----------------------------------------------------------------------- --threads
#: (name, environment threads, cap on) of the configurations measured by --threads.
THREAD_CONFIGS = [("one-thread environment", "1", True), ("default environment", None, True),
                  ("default environment, cap off", None, False)]


def threads_child(files: list[Path], cap: bool, repeats: int) -> dict:
    """In this process: median seconds of Pipeline(seq, C) and random_voting per sequence."""
    from threadpoolctl import threadpool_info

    import laav._threads

    if not cap:
        laav._threads.MAX_THREADS = None
    seqs = [laav.load_sequence(f) for f in files]
    warm_up(seqs[0])
    out = {"pools": sorted({f"{i['internal_api']}={i['num_threads']}" for i in threadpool_info()})}
    for seq in seqs:
        laav_s, rv_s = [], []
        for _ in range(repeats):
            t = time.perf_counter()
            laav.Pipeline(seq, seq.n_motions)
            laav_s.append(time.perf_counter() - t)
            t = time.perf_counter()
            laav.random_voting(seq, seq.n_motions, seed=0)
            rv_s.append(time.perf_counter() - t)
        out[seq.name] = {"laav": float(np.median(laav_s)), "rv": float(np.median(rv_s))}
    return out


def _threads_run(files: list[Path], env_threads, cap: bool, busy: bool, repeats: int) -> dict:
    """One fresh process of threads_child (beside a spinning process when ``busy``)."""
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARS}
    if env_threads is not None:
        env.update(dict.fromkeys(THREAD_VARS, env_threads))
    cmd = [sys.executable, __file__, "--threads-child", "--repeats", str(repeats),
           *[a for f in files for a in ("--file", str(f))]] + ([] if cap else ["--no-cap"])
    spinner = subprocess.Popen([sys.executable, "-c", "while True: pass"]) if busy else None
    try:
        proc = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
    finally:
        if spinner is not None:
            spinner.kill()
            spinner.wait()
    return json.loads(proc.stdout.strip().splitlines()[-1])


def measure_threads(files: list[Path], repeats: int, rounds: int) -> str:
    """Every THREAD_CONFIGS entry, idle and beside a busy core, interleaved over ``rounds``
    (so that other load on the machine hits all alike); the report as Markdown."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    per_round: dict = {}
    for k in range(rounds):
        for busy in (False, True):
            for name, env_threads, cap in THREAD_CONFIGS:
                r = _threads_run(files, env_threads, cap, busy, repeats)
                per_round.setdefault((name, busy), []).append(r)
                print(f"round {k + 1}: {name}{', one busy core' if busy else ''}: {r}",
                      file=sys.stderr, flush=True)
    runs = {}
    for key, rs in per_round.items():  # median over rounds of each process's median
        runs[key] = {"pools": rs[0]["pools"]}
        for s in (s for s in rs[0] if s != "pools"):
            runs[key][s] = {m: float(np.median([r[s][m] for r in rs])) for m in ("laav", "rv")}
    base = runs[(THREAD_CONFIGS[0][0], False)]
    names = [k for k in base if k != "pools"]
    lines = [f"# LAAV and BLAS/OpenMP threads ({time.strftime('%Y-%m-%d %H:%M %Z')})", "",
             f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, "
             f"{platform.system()} {platform.release()} {platform.machine()}",
             f"- Software: Python {platform.python_version()}, numpy {np.__version__}, "
             f"laav {laav.__version__} (git {git_commit()})",
             f"- Wall time of `Pipeline(seq, C)` (LAAV) and `random_voting(seq, C)` (RV): median "
             f"of {repeats} runs in a fresh process after one warm-up, median of {rounds} such "
             "processes per row, the rows interleaved. Ratio = time / time in the one-thread "
             "environment without the busy core. Busy core: another process spinning meanwhile.",
             f"- Load average (1 min) before the measurement: {load:.2f} on {os.cpu_count()} cores",
             "- Thread pools outside a run: default environment "
             f"{', '.join(runs[('default environment', False)]['pools'])}; one-thread environment "
             f"{', '.join(base['pools'])}",
             "- Same-load ratio: time / time in the one-thread environment under the same load "
             "(busy core or not).",
             "",
             "| configuration | sequence | LAAV ms | LAAV ratio | same-load | RV ms | RV ratio | same-load |",
             "|---|---|---:|---:|---:|---:|---:|---:|"]
    for (name, busy), r in runs.items():
        same = runs[(THREAD_CONFIGS[0][0], busy)]
        for s in names:
            cells = [f"{1000 * r[s][m]:.0f} | {r[s][m] / base[s][m]:.2f} | {r[s][m] / same[s][m]:.2f}"
                     for m in ("laav", "rv")]
            lines.append(f"| {name}{', one busy core' if busy else ''} | {s} | {cells[0]} | {cells[1]} |")
    return "\n".join(lines + [""])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", help="Hopkins155 folder (default $HOPKINS155 or ../shared/data/hopkins155)")
    ap.add_argument("--every", type=int, default=1, metavar="K",
                    help="use every K-th sequence by name (default 1: all)")
    ap.add_argument("--only", action="append", default=[], metavar="GLOB",
                    help="only sequences whose name matches (repeatable)")
    ap.add_argument("--limit", type=int, default=None, metavar="N", help="at most N sequences")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None,
                    help="Markdown report (default bench-out/speed.md, with --threads bench-out/threads.md)")
    ap.add_argument("--threads", action="store_true",
                    help="measure the thread cap instead (default, one thread, busy core; see above)")
    ap.add_argument("--repeats", type=int, default=3, metavar="N",
                    help="--threads: runs per sequence and process (default 3)")
    ap.add_argument("--rounds", type=int, default=3, metavar="N",
                    help="--threads: processes per configuration, interleaved (default 3)")
    ap.add_argument("--threads-child", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--file", action="append", default=[], help=argparse.SUPPRESS)
    ap.add_argument("--no-cap", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.threads_child:
        print(json.dumps(threads_child([Path(f) for f in args.file], not args.no_cap, args.repeats)))
        return 0
    if args.threads and not args.only:
        args.only = ["people1"]
    args.out = args.out or ("bench-out/threads.md" if args.threads else "bench-out/speed.md")
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

    if args.threads:
        return _emit(measure_threads(files, args.repeats, args.rounds), args.out)

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
    lines += ratios(results)
    lines += table(results, "All sequences")
    for k in sorted({r["motions"] for r in results}):
        lines += table([r for r in results if r["motions"] == k], f"{k} motions")
    return _emit("\n".join(lines), args.out)


def _emit(text: str, out: str) -> int:
    """Print the report and write it to ``out``."""
    print(text)
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    print(f"written: {path}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
