"""Stages 1-4 on Hopkins155 with missing data: the coarse labels against the fine-model count.

Every sequence is occluded as in ``benchmarks/missing.py`` (the same seeded
``laav.synthetic.occlude``), its atoms and graph built once with the default parameters
(seed 0), and then, for each configuration ``MERGE:PER`` (``--configs``), the multicut is
brought to ``PER x C`` fine models and merged into C motions. A negative ``PER`` means the
multicut's own number of segments, clamped to ``[2C, |PER| C]``. Per run it writes the
sequence, C, P, the configuration, the multicut's own segment count, the coarse error on
the points in atoms (%), their share, and the seconds of the count adjustment and of the
merge (``--out``); it prints per configuration the mean coarse error for two / three / all
motions and the runs <= 1 % / > 10 % wrong, and ``--cv`` adds 5-fold cross-validation
grouped by source video (``benchmarks/cv.py``) over the configurations, on the coarse
error averaged over the levels given.

Only stages 1-4 run (no fine-tuning): 155 sequences x 5 configurations take a few minutes.

    python benchmarks/missing_fine.py [--data DIR] [--levels 0.2,0.4]
        [--configs epipolar:2,epipolar:16] [--part 0 --parts 2] [--out FILE] [--cv]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from cv import cross_validate  # noqa: E402 - this folder, on sys.path
from speed import data_dir, truth_files  # noqa: E402

import laav  # noqa: E402
from laav.atoms import MaskedNeighbourhoods, Neighbourhoods, build_atoms  # noqa: E402
from laav.coarse import merge_models  # noqa: E402
from laav.graph import atom_graph  # noqa: E402
from laav.multicut import solve_multicut  # noqa: E402
from laav.noise import estimate_noise  # noqa: E402
from laav.pipeline import _stage_rngs  # noqa: E402
from laav.synthetic import BENCH_SPREAD, occlude, occlusion_rng  # noqa: E402

FIELDS = ["sequence", "motions", "points", "level", "config", "segments", "coarse",
          "coverage", "multicut_s", "merge_s"]


def run(path: Path, level: float, configs: list[tuple[str, int]]) -> list[dict]:
    seq = laav.load_sequence(path)
    occl = occlude(seq, level, occlusion_rng(0, seq.name, level), spread=BENCH_SPREAD) if level else seq
    C = seq.n_motions
    vis = None if occl.is_complete else occl.visible
    params = laav.LaavParams().for_noise(estimate_noise(occl.points, vis))  # as Pipeline does
    rngs = _stage_rngs(0)
    dist = Neighbourhoods(occl.points) if vis is None else MaskedNeighbourhoods(occl.points, vis)
    atoms = build_atoms(occl, params, np.random.default_rng(rngs["atoms"]), dist)
    graph = atom_graph(occl, atoms, params, dist)
    rows = []
    for merge, per in configs:
        t0 = time.perf_counter()
        if per < 0:
            own = solve_multicut(graph, 2 * C).n_segments
            p = params.replace(fine_models=int(np.clip(own, 2 * C, -per * C)), coarse_merge=merge)
        else:
            p = params.replace(fine_per_motion=per, coarse_merge=merge)
        mc = solve_multicut(graph, p.n_fine(C, occl.is_complete))
        t1 = time.perf_counter()
        co = merge_models(occl, atoms, mc, C, p, np.random.default_rng(rngs["coarse"]))
        t2 = time.perf_counter()
        cov = co.point_labels >= 0
        err = laav.misclassification_rate(seq.labels[cov], co.point_labels[cov]) if cov.any() else np.nan
        rows.append({"sequence": seq.name, "motions": C, "points": seq.n_points, "level": f"{level:g}",
                     "config": f"{merge}:{per}", "segments": mc.n_segments,
                     "coarse": f"{100 * err:.3f}", "coverage": f"{cov.mean():.3f}",
                     "multicut_s": f"{t1 - t0:.4f}", "merge_s": f"{t2 - t1:.4f}"})
    return rows


def _mean(values: np.ndarray) -> str:
    return f"{values.mean():.2f}" if values.size else "-"


def summarise(rows: list[dict], cv: bool) -> list[str]:
    lines = ["| level | configuration | runs | coarse error % 2 / 3 / all | <= 1 % / > 10 % | "
             "merge s median / max |", "|---|---|---|---|---|---|"]
    for level in sorted({r["level"] for r in rows}, key=float):
        order = sorted({r["config"] for r in rows},
                       key=lambda c: (c.split(":")[0], abs(int(c.split(":")[1])), c))
        for cfg in order:
            rs = [r for r in rows if r["level"] == level and r["config"] == cfg]
            if not rs:
                continue
            e = np.array([float(r["coarse"]) for r in rs])
            m = np.array([int(r["motions"]) for r in rs])
            s = np.array([float(r["merge_s"]) for r in rs])
            lines.append(f"| {100 * float(level):.0f} % | {cfg} | {e.size} | {_mean(e[m == 2])} / "
                         f"{_mean(e[m == 3])} / {e.mean():.2f} | {(e <= 1).sum()} / {(e > 10).sum()} | "
                         f"{np.median(s):.3f} / {s.max():.2f} |")
    if cv:  # over the configurations run at every level above 0, on those levels' rows
        levels = {r["level"] for r in rows if float(r["level"]) > 0}
        common = set.intersection(*({r["config"] for r in rows if r["level"] == v} for v in levels))
        errors: dict = defaultdict(lambda: defaultdict(list))
        motions = {}
        for r in rows:
            if r["level"] not in levels or r["config"] not in common:
                continue
            errors[r["config"]][r["sequence"]].append(float(r["coarse"]))
            motions[r["sequence"]] = int(r["motions"])
        errs = {c: {s: float(np.mean(v)) for s, v in d.items()} for c, d in errors.items()}
        for seed in range(3):
            out = cross_validate(errs, motions, 5, seed)
            lines.append(f"\nCV (fold seed {seed}): chosen {[f[1] for f in out['folds']]}; held-out "
                         "coarse error 2 / 3 / all " + " / ".join(f"{x:.2f}" for x in out["cv"]) + " %")
    return lines


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--levels", default="0.2,0.4")
    ap.add_argument("--configs", default="epipolar:2,epipolar:4,epipolar:8,epipolar:16,epipolar:32")
    ap.add_argument("--part", type=int, default=0)
    ap.add_argument("--parts", type=int, default=1)
    ap.add_argument("--out", default="bench-out/missing_fine.csv")
    ap.add_argument("--summarise", nargs="*", help="only summarise these CSV files")
    ap.add_argument("--cv", action="store_true")
    args = ap.parse_args(argv)
    if args.summarise:
        rows = [r for f in args.summarise for r in csv.DictReader(open(f, newline=""))]
        print("\n".join(summarise(rows, args.cv)))
        return 0
    levels = [float(v) for v in args.levels.split(",")]
    configs = [(c.split(":")[0], int(c.split(":")[1])) for c in args.configs.split(",")]
    files = truth_files(data_dir(args.data), [])[args.part::args.parts]
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    rows = []
    with open(out, "w", newline="") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore", laav.LaavWarning)
        w = csv.DictWriter(fh, FIELDS)
        w.writeheader()
        for k, f in enumerate(files):
            for level in levels:
                new = run(f, level, configs)
                w.writerows(new)
                fh.flush()
                rows += new
            print(f"{k + 1}/{len(files)} {f.parent.name}", file=sys.stderr, flush=True)
    print("\n".join(summarise(rows, args.cv)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
