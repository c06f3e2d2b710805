"""LAAV on Hopkins155 with missing data: the seeded occlusion model at several levels.

Every sequence's complete ground-truth tracks are occluded by :func:`laav.synthetic.occlude`
(tracks start late, end early and have one gap; a share ``LEVEL`` of the F x P entries
hidden, ``spread`` 0.5), with a generator seeded by ``(seed, sequence name, level)``, and
segmented by :func:`laav.segment` with the default parameters and the same seed. Level 0
is the complete sequence itself (the complete-data code).

Per run it records the error (``laav.misclassification_rate``: a point left unlabelled,
label -1, counts as an error), the share of unlabelled points, the coarse stage's error on
the points in atoms and its coverage, and the seconds of the call. It writes one CSV row
per run (``--out``, resumable: rows already there are kept) and prints, per level, the
mean error for two / three / all motions, the worst run, the unlabelled share and the
median time. ``--every N`` takes every N-th sequence by name (a spread subset);
``--report`` writes the table with the machine, date and git commit.

    python benchmarks/missing.py [--data DIR] [--levels 0,0.2,0.4] [--seed 0] [--every 1]
                                 [--only GLOB] [--jobs 1] [--out FILE] [--report FILE]
                                 [--set NAME=VALUE ...]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, git_commit  # noqa: E402 - this folder, on sys.path
from speed import data_dir, truth_files  # noqa: E402

import laav  # noqa: E402
from laav.bench import params_from_assignments  # noqa: E402
from laav.synthetic import BENCH_SPREAD, occlude, occlusion_rng  # noqa: E402

FIELDS = ["sequence", "motions", "points", "frames", "level", "seed", "missing", "error",
          "unlabelled", "coarse", "coverage", "selected", "seconds"]
SPREAD = BENCH_SPREAD  # occlude()'s spread: how much the tracks' losses differ


def run_sequence(path: str, levels: list[float], seed: int,
                 params: laav.LaavParams | None = None) -> list[dict]:
    seq = laav.load_sequence(path)
    rows = []
    for level in levels:
        occl = occlude(seq, level, occlusion_rng(seed, seq.name, level), spread=SPREAD) if level else seq
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", laav.LaavWarning)
            res = laav.segment(occl, seq.n_motions, params, seed=seed)
        sec = time.perf_counter() - t
        cov = res.coarse.point_labels >= 0
        cerr = (laav.misclassification_rate(seq.labels[cov], res.coarse.point_labels[cov])
                if cov.any() else float("nan"))
        rows.append({
            "sequence": seq.name, "motions": seq.n_motions, "points": seq.n_points,
            "frames": seq.n_frames, "level": f"{level:g}", "seed": seed,
            "missing": f"{1 - occl.visible_share:.4f}",
            "error": f"{100 * laav.misclassification_rate(seq.labels, res.labels):.4f}",
            "unlabelled": f"{100 * np.mean(res.labels < 0):.4f}",
            "coarse": f"{100 * cerr:.4f}", "coverage": f"{cov.mean():.4f}",
            "selected": res.voting.selected, "seconds": f"{sec:.4f}"})
    return rows


def summarise(rows: list[dict]) -> list[str]:
    lines = ["| missing | runs | 2 / 3 / all mean error % | median % | worst % | runs > 2 % | "
             "unlabelled % (mean / max) | coarse <= 1 % / > 10 % | median s |",
             "|---|---|---|---|---|---|---|---|---|"]
    for level in sorted({r["level"] for r in rows}, key=float):
        rs = [r for r in rows if r["level"] == level]
        e = np.array([float(r["error"]) for r in rs])
        m = np.array([int(r["motions"]) for r in rs])
        u = np.array([float(r["unlabelled"]) for r in rs])
        ce = np.array([float(r["coarse"]) for r in rs if r["coarse"] != "nan"])
        two = f"{e[m == 2].mean():.2f}" if (m == 2).any() else "-"
        three = f"{e[m == 3].mean():.2f}" if (m == 3).any() else "-"
        lines.append(f"| {100 * float(level):.0f} % | {e.size} | {two} / {three} / {e.mean():.2f} | "
                     f"{np.median(e):.2f} | {e.max():.1f} | {(e > 2).sum()} | {u.mean():.2f} / "
                     f"{u.max():.1f} | {(ce <= 1).sum()} / {(ce > 10).sum()} | "
                     f"{np.median([float(r['seconds']) for r in rs]):.2f} |")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--levels", default="0,0.2,0.4")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--every", type=int, default=1, help="every N-th sequence by name")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--out", default="bench-out/missing.csv")
    ap.add_argument("--report", default=None)
    ap.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                    help="a LaavParams field other than its default (repeatable)")
    args = ap.parse_args(argv)
    params = params_from_assignments(args.set)  # laav bench's --param parsing
    levels = [float(v) for v in args.levels.split(",")]
    files = truth_files(data_dir(args.data), args.only)[::max(1, args.every)]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    done = []
    if out.is_file():
        with open(out, newline="") as fh:
            done = [r for r in csv.DictReader(fh) if int(r["seed"]) == args.seed]
    have = {(r["sequence"], r["level"]) for r in done}
    todo = [f for f in files if any((f.parent.name, f"{v:g}") not in have for v in levels)]
    redo = {f.parent.name for f in todo}
    rows = [r for r in done if r["sequence"] not in redo]
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        w.writerows(rows)
        with ProcessPoolExecutor(max(1, args.jobs)) as ex:
            for k, new in enumerate(ex.map(run_sequence, [str(f) for f in todo],
                                           [levels] * len(todo), [args.seed] * len(todo),
                                           [params] * len(todo))):
                w.writerows(new)
                fh.flush()
                rows += new
                print(f"{k + 1}/{len(todo)} {new[0]['sequence']} "
                      + " ".join(f"{r['level']}:{float(r['error']):.2f}" for r in new),
                      file=sys.stderr, flush=True)
    names = {f.parent.name for f in files}
    rows = [r for r in rows if r["sequence"] in names and float(r["level"]) in levels]
    table = summarise(rows)
    print("\n".join(table))
    if args.report:
        n_seq = len({r["sequence"] for r in rows})
        head = [f"# LAAV with missing data on Hopkins155 ({time.strftime('%Y-%m-%d %H:%M %Z')})",
                "", f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores, "
                f"{platform.system()} {platform.release()}; one thread per process, "
                f"{args.jobs} process(es), shared with other jobs",
                f"- Software: Python {platform.python_version()}, numpy {np.__version__}, "
                f"laav {laav.__version__} (git {git_commit()})",
                f"- Hopkins155: {n_seq} sequences (every {args.every}. by name), seed {args.seed}, "
                f"parameters {', '.join(args.set) or 'default'}; occlusion "
                f"`laav.synthetic.occlude(seq, level, rng, spread={SPREAD})` seeded by (seed, name, level)",
                "- `python benchmarks/missing.py " + " ".join(argv or sys.argv[1:]) + "`",
                "- Error: `laav.misclassification_rate` against the ground truth of all points; "
                "a point left unlabelled (-1) counts as an error. Coarse: the fine-to-coarse "
                "labels on the points in atoms.", ""]
        Path(args.report).write_text("\n".join(head + table) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
