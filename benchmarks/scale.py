"""Thousands of tracks: seconds and peak memory of every LAAV stage against P (issue 14 item 8).

For each size a synthetic sequence (``laav.synthetic.make_sequence``: two moving objects
and the background, 640 x 480 image, 0.5 px noise, seed 0) runs the pipeline's stages one
after another, exactly as :class:`laav.Pipeline` does, twice, each time in a fresh
subprocess:

* a *timing* run (no tracing): CPU seconds per stage (``time.process_time``, robust to
  other work on a shared machine) and the wall total, and the process's peak resident memory
  (``resource.getrusage(...).ru_maxrss``: interpreter, numpy and the sequence included);
* a *memory* run under ``tracemalloc``: the peak of the memory allocated *during* each
  stage (``tracemalloc.reset_peak`` before it), i.e. what the stage adds above what is
  already held.

Stages: ``neighbourhoods`` (the trajectory neighbourhood structure the atoms and the graph
share: a KD-tree since issue 14; before, the dense P x P distance matrix), ``atoms``,
``graph``, ``multicut``, ``coarse``, ``voting``. One BLAS thread. Prints one line per size
and writes a Markdown report with machine, date and git commit.

    python benchmarks/scale.py [--sizes 1000,2000,5000,20000] [--frames 100] [--seed 0]
        [--report docs/bench/scale.md] [--no-memory]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
STAGES = ("neighbourhoods", "atoms", "graph", "multicut", "coarse", "voting")
NOISE = 0.5
N_OBJECTS = 2


def _child(P: int, F: int, seed: int, memory: bool, missing: float = 0.0) -> dict:
    """One size in this (fresh) process: every stage in turn, timed or traced."""
    import resource
    import tracemalloc

    import numpy as np

    import laav
    from laav import atoms as atoms_mod
    from laav.coarse import merge_models
    from laav.graph import atom_graph
    from laav.multicut import solve_multicut
    from laav.pipeline import _stage_rngs
    from laav.synthetic import make_sequence
    from laav.voting import random_voting

    laav.preload()
    seq = make_sequence(n_objects=N_OBJECTS, n_frames=F, n_points=P, noise=NOISE, rng=seed)
    if missing > 0:  # the seeded occlusion of `laav bench --missing` (tracks start late, ...)
        from laav.synthetic import occlude

        seq = occlude(seq, missing, rng=seed)
    C = seq.n_motions
    p = laav.LaavParams()
    rngs = _stage_rngs(seed)
    new_api = hasattr(atoms_mod, "Neighbourhoods")
    out = {"P": P, "F": F, "C": C, "seconds": {}, "cpu": {}, "peak_mb": {},
           "visible": float(seq.visible.mean()) if seq.visible is not None else 1.0}
    st: dict = {}

    def run(stage):
        if stage == "neighbourhoods":
            if not seq.is_complete:  # as laav.Pipeline does
                st["nb"] = atoms_mod.MaskedNeighbourhoods(seq.points, seq.visible)
            else:
                st["nb"] = (atoms_mod.Neighbourhoods(seq.points) if new_api
                            else atoms_mod.trajectory_distances(seq.points))
        elif stage == "atoms":
            st["atoms"] = atoms_mod.build_atoms(seq, p, np.random.default_rng(rngs["atoms"]), st["nb"])
        elif stage == "graph":
            st["graph"] = atom_graph(seq, st["atoms"], p, st["nb"])
        elif stage == "multicut":
            st["multicut"] = solve_multicut(st["graph"], p.n_fine(C))
        elif stage == "coarse":
            st["coarse"] = merge_models(seq, st["atoms"], st["multicut"], C, p,
                                        np.random.default_rng(rngs["coarse"]))
        elif stage == "voting":
            init = st["coarse"].point_labels
            init = None if C == 1 or not (init >= 0).any() else init
            st["voting"] = random_voting(seq, C, p, np.random.default_rng(rngs["voting"]),
                                         init_labels=init)

    from threadpoolctl import threadpool_limits

    with threadpool_limits(1):
        if memory:
            tracemalloc.start()
        for stage in STAGES:
            if memory:
                tracemalloc.reset_peak()
                before = tracemalloc.get_traced_memory()[0]
            t, c = time.perf_counter(), time.process_time()
            run(stage)
            out["seconds"][stage] = time.perf_counter() - t
            out["cpu"][stage] = time.process_time() - c
            if memory:
                out["peak_mb"][stage] = (tracemalloc.get_traced_memory()[1] - before) / 2**20
        if memory:
            tracemalloc.stop()
    out["maxrss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    out["atoms"] = st["atoms"].n_atoms
    out["edges"] = st["graph"].n_edges
    out["error_pct"] = 100 * laav.misclassification_rate(seq.labels, st["voting"].labels)
    v = st["voting"]
    out["voting"] = {"trials": v.n_trials, "iterations": v.n_iterations,
                     "converged": bool(v.converged), "candidates": len(v.costs)}
    out["labels_crc"] = int(__import__("zlib").crc32(np.asarray(st["voting"].labels, np.int64).tobytes()))
    return out


def _spawn(P, F, seed, memory, timeout, missing=0.0):
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(P), "--frames", str(F),
           "--seed", str(seed), "--missing", str(missing)] + (["--memory"] if memory else [])
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"P": P, "F": F, "failed": f"timed out after {timeout} s"}
    if res.returncode != 0:
        tail = (res.stderr.strip().splitlines() or ["?"])[-1]
        return {"P": P, "F": F, "failed": f"exit {res.returncode}: {tail}"}
    return json.loads(res.stdout.strip().splitlines()[-1])


def _fmt_row(t: dict, m: dict | None) -> str:
    if "failed" in t:
        return f"| {t['P']:,} | {t['F']} | - | failed: {t['failed']} |" + " |" * (2 * len(STAGES) + 3)
    secs = " | ".join(f"{t['cpu'][s]:.2f}" for s in STAGES)
    total = sum(t["cpu"].values())
    wall = sum(t["seconds"].values())
    if m and "failed" not in m:
        mems = " | ".join(f"{m['peak_mb'][s]:.0f}" for s in STAGES)
        mmax = f"{max(m['peak_mb'].values()):.0f}"
    else:
        mems = " | ".join("-" for _ in STAGES)
        mmax = "-"
    return (f"| {t['P']:,} | {t['F']} | {t.get('visible', 1.0):.0%} | {secs} | **{total:.1f}** | "
            f"{wall:.1f} | {mems} | {mmax} | "
            f"{t['maxrss_mb']:.0f} | {t['atoms']} | {t['edges']} | {t['error_pct']:.2f} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1000,2000,5000,20000")
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--missing", type=float, default=0.0,
                    help="share of entries hidden by laav.synthetic.occlude (default 0: complete)")
    ap.add_argument("--report", default=str(HERE.parent / "docs" / "bench" / "scale.md"))
    ap.add_argument("--no-memory", action="store_true", help="skip the tracemalloc runs")
    ap.add_argument("--timeout", type=float, default=3600.0, help="seconds per subprocess")
    ap.add_argument("--child", type=int, help=argparse.SUPPRESS)
    ap.add_argument("--memory", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child is not None:
        print(json.dumps(_child(args.child, args.frames, args.seed, args.memory, args.missing)),
              flush=True)
        return 0

    sys.path.insert(0, str(HERE))
    from _machine import cpu_model, git_commit, laav_version

    rows = []
    for P in (int(s) for s in args.sizes.split(",")):
        t = _spawn(P, args.frames, args.seed, False, args.timeout, args.missing)
        m = None if args.no_memory or "failed" in t else _spawn(P, args.frames, args.seed, True,
                                                                 args.timeout, args.missing)
        rows.append((t, m))
        if "failed" in t:
            print(f"P={P} F={args.frames}: {t['failed']}", flush=True)
            continue
        line = " ".join(f"{s}={t['cpu'][s]:.2f}s" for s in STAGES)
        if m and "failed" not in m:
            line += " | peak " + " ".join(f"{s}={m['peak_mb'][s]:.0f}MB" for s in STAGES)
        print(f"P={P} F={args.frames} cpu={sum(t['cpu'].values()):.1f}s "
              f"wall={sum(t['seconds'].values()):.1f}s {line} | "
              f"maxrss={t['maxrss_mb']:.0f}MB atoms={t['atoms']} edges={t['edges']} "
              f"error={t['error_pct']:.2f}% voting={t['voting']}", flush=True)

    head_s = " | ".join(f"{s} CPU s" for s in STAGES)
    head_m = " | ".join(f"{s} MB" for s in STAGES)
    lines = [
        f"# LAAV against the number of tracks ({time.strftime('%Y-%m-%d %H:%M %Z')})",
        "",
        f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores (one BLAS thread used), "
        f"{platform.system()} {platform.release()} {platform.machine()}",
        f"- Software: Python {platform.python_version()}, laav {laav_version()} (git {git_commit()})",
        f"- Data: `laav.synthetic.make_sequence(n_objects={N_OBJECTS}, n_frames={args.frames}, "
        f"n_points=P, noise={NOISE}, rng={args.seed})` (3 motions, 640 x 480), default `LaavParams()`"
        + (f"; then `laav.synthetic.occlude(seq, {args.missing}, rng={args.seed})` (visible share "
           "in the table): every stage's missing-data variant runs" if args.missing > 0 else ""),
        "- Command: `python benchmarks/scale.py "
        + " ".join(argv if argv is not None else sys.argv[1:]) + "`",
        "- Seconds: a run without tracing, in a fresh process per size; CPU seconds of the process "
        "(time.process_time: the machine is shared, wall time depends on its load), and the wall "
        "total. Stage MB: the peak of "
        "memory allocated during the stage above what was held before it (tracemalloc, a second "
        "fresh process). maxrss: the timing process's peak resident memory (interpreter, "
        "libraries and sequence included).",
        "",
        f"| P | F | visible | {head_s} | total CPU s | wall s | {head_m} | max stage MB | maxrss MB | "
        "atoms | edges | error % |",
        "|" + "---|" * (2 * len(STAGES) + 10),
    ]
    lines += [_fmt_row(t, m) for t, m in rows]
    lines.append("")
    path = Path(args.report)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
