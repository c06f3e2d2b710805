"""Hopkins155 with outlier tracks: LAAV with and without the veto, and plain Random Voting.

Real trackers lose points: a track slides off its feature and drifts. Hopkins155 has no
such track, so this script makes some. For every sequence, a share of its tracks (each
``--fractions`` value) is replaced by random walks that start at the track's frame-0
position and move by Gaussian steps of ``--steps`` px (standard deviation per coordinate
and frame). The draw is seeded by the sequence's name, the share and the step, so every
method and every run sees the same outliers. Each method gets the true number of motions;
its error is the misclassification on the *other* tracks (an outlier has no true motion).

Methods: LAAV's default (``LaavParams()``), the default without the veto on the joint
score's choices (``rv_outlier_veto=False``, what the default was before 2026-12-06) and
plain Random Voting, each at the LAAV seeds ``--seeds``. The report (one
Markdown table, ``--out``) gives, per outlier setting and method, the mean error on two /
three / all motions, the worst run, the runs over 10 %, and for the default the runs where
the veto kept a labelling the joint score would have replaced (``Voting.vetoed``); with
machine, date and commit.

    python benchmarks/outliers.py [--data DIR] [--seeds 0,1] [--fractions 0.05,0.1]
                                  [--steps 1,3] [--jobs 1] [--out bench-out/outliers.md]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import zlib  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, git_commit  # noqa: E402 - this folder, on sys.path
from speed import data_dir, truth_files  # noqa: E402

import laav  # noqa: E402

METHODS = ("LAAV (default)", "LAAV without the veto", "plain RV")


def with_outliers(seq: laav.Sequence, fraction: float, step: float) -> tuple[laav.Sequence, np.ndarray]:
    """``seq`` with ``round(fraction P)`` tracks replaced by random walks from their frame-0
    position (Gaussian steps of ``step`` px per coordinate and frame), and which (P,) bool.
    Seeded by the sequence's name, ``fraction`` and ``step``: the same outliers every time."""
    F, P, _ = seq.points.shape
    rng = np.random.default_rng([zlib.crc32(seq.name.encode()), round(1000 * fraction),
                                 round(100 * step)])
    which = np.zeros(P, dtype=bool)
    which[rng.choice(P, size=int(round(fraction * P)), replace=False)] = True
    points = seq.points.copy()
    walk = rng.normal(0.0, step, size=(F - 1, int(which.sum()), 2))
    points[1:, which] = points[0, which] + np.cumsum(walk, axis=0)
    return laav.Sequence(points=points, labels=seq.labels, name=seq.name), which


def _one(job) -> list[dict]:
    path, fraction, step, seeds = job
    seq = laav.load_sequence(path)
    noisy, out = with_outliers(seq, fraction, step)
    C = seq.n_motions
    rows = []
    for seed in seeds:
        for method in METHODS:
            vetoed = False
            if method == "plain RV":
                labels = laav.random_voting(noisy, C, seed=seed).labels
            else:
                params = laav.LaavParams(rv_outlier_veto=method == "LAAV (default)")
                res = laav.segment(noisy, C, params, seed=seed)
                labels, vetoed = res.labels, bool(res.voting.vetoed)
            err = 100.0 * laav.misclassification_rate(seq.labels[~out], labels[~out])
            rows.append({"sequence": seq.name, "motions": C, "fraction": fraction, "step": step,
                         "seed": seed, "method": method, "error": err, "vetoed": vetoed})
    return rows


def report(rows: list[dict], seeds, seconds: float, jobs: int = 1) -> str:
    lines = [
        f"# Hopkins155 with outlier tracks ({time.strftime('%Y-%m-%d %H:%M %Z')})",
        "",
        f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, "
        f"{platform.system()} {platform.release()}",
        f"- Software: Python {platform.python_version()}, numpy {np.__version__}, "
        f"laav {laav.__version__}, git {git_commit()}",
        f"- `benchmarks/outliers.py`, LAAV seeds {', '.join(map(str, seeds))}; "
        f"{len({r['sequence'] for r in rows})} sequences, {seconds:.0f} s in {jobs} process"
        f"{'es' if jobs > 1 else ''}",
        "- Error: misclassified tracks among those not replaced, %, mean over runs; the "
        "outliers are random walks from each replaced track's frame-0 position",
        "",
        "| outliers (share, step) | method | 2 motions | 3 motions | all | worst | runs > 10 % | veto used |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for fraction, step in dict.fromkeys((r["fraction"], r["step"]) for r in rows):
        for method in METHODS:
            rs = [r for r in rows if (r["fraction"], r["step"], r["method"]) == (fraction, step, method)]
            if not rs:
                continue
            e = np.array([r["error"] for r in rs])
            c = np.array([r["motions"] for r in rs])
            used = sum(r["vetoed"] for r in rs) if method == "LAAV (default)" else "-"
            lines.append(
                f"| {100 * fraction:.0f} %, {step:g} px | {method} | {e[c == 2].mean():.2f} | "
                f"{e[c == 3].mean():.2f} | **{e.mean():.2f}** | {e.max():.1f} | "
                f"{(e > 10).sum()} of {e.size} | {used} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--fractions", default="0.05,0.1")
    ap.add_argument("--steps", default="1,3")
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--only", action="append", default=[],
                    help="sequence name patterns (fnmatch, repeatable)")
    ap.add_argument("--out", default="bench-out/outliers.md")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    files = truth_files(data_dir(args.data), args.only)
    jobs = [(f, float(fr), float(st), seeds) for fr in args.fractions.split(",")
            for st in args.steps.split(",") for f in files]
    t0 = time.perf_counter()
    rows: list[dict] = []
    with ProcessPoolExecutor(max(1, args.jobs)) as pool:
        for k, part in enumerate(pool.map(_one, jobs, chunksize=2), start=1):
            rows.extend(part)
            if k % 50 == 0:
                print(f"{k}/{len(jobs)}", file=sys.stderr, flush=True)
    text = report(rows, seeds, time.perf_counter() - t0, max(1, args.jobs))
    print(text)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"written: {out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
