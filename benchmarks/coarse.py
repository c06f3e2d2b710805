"""Stage 4 alone on Hopkins155: how often the fine-to-coarse labels are right, per merge.

For every sequence and seed, atoms, graph and multicut run once per number of fine models
(``--per-motion``, fine models per motion), and each merge of ``--merges`` labels the
points in atoms: ``epipolar`` (the paper's: spectral clustering of the epipolar-vote
affinity, our pooled-voting blend unless ``paper``), ``coding:EPS`` (the partition of
least coding length, distortion EPS px), ``joint[:W[:K]]`` (the K partitions of least
coding length re-ranked by coding length + W x epipolar cost), ``paper`` (the paper's
pairwise votes alone), ``oracle`` (each fine model to its majority true motion: the
ceiling of any merge of those fine models).
The error is taken on the points in atoms ("coarse"). Per configuration it prints the
count of sequences <= 1 % and > 10 % wrong, the mean, and a 5-fold cross-validation
grouped by source video that chooses the configuration on four folds and reports the
fifth (``benchmarks/cv.py``). Writes a CSV of every run and a Markdown report with the
machine, date and git commit.

    python benchmarks/coarse.py [--data DIR] [--seeds 0] [--per-motion 2,3,4]
        [--merges epipolar,paper,coding:10,joint:1,joint:2,oracle] [--out FILE] [--report FILE]
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
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from _machine import cpu_model, git_commit  # noqa: E402 - this folder, on sys.path
from cv import cross_validate  # noqa: E402
from speed import data_dir, truth_files  # noqa: E402

import laav  # noqa: E402
from laav.atoms import Neighbourhoods, build_atoms  # noqa: E402
from laav.coarse import merge_models, point_labels_from_atoms  # noqa: E402
from laav.graph import atom_graph  # noqa: E402
from laav.multicut import solve_multicut  # noqa: E402
from laav.pipeline import _stage_rngs  # noqa: E402

FIELDS = ["config", "sequence", "motions", "seed", "coarse", "coverage", "seconds"]


def merge_params(merge: str) -> laav.LaavParams | None:
    """The parameters of a merge name; None for ``oracle`` (every fine model to the true
    motion most of its points belong to: the best any merge of these fine models can do)."""
    if merge == "oracle":
        return None
    if merge == "paper":
        return laav.LaavParams.paper()
    if merge == "epipolar":
        return laav.LaavParams(coarse_merge="epipolar")
    kind, _, value = merge.partition(":")
    if kind == "coding" and value:
        return laav.LaavParams(coarse_merge="coding", coding_eps=float(value))
    if kind == "joint":  # joint[:W[:K]]: epipolar weight W, shortlist of K partitions
        w, _, k = value.partition(":")
        p = laav.LaavParams(coarse_merge="joint")
        return p.replace(coarse_epipolar_weight=float(w or p.coarse_epipolar_weight),
                         coarse_candidates=int(k or p.coarse_candidates))
    raise argparse.ArgumentTypeError(f"unknown merge {merge!r}")


def oracle_labels(seq, fine_pts: np.ndarray, n_models: int) -> np.ndarray:
    """Every fine model's points labelled with the model's majority true motion."""
    f2c = np.array([np.bincount(seq.labels[fine_pts == j], minlength=seq.n_motions).argmax()
                    for j in range(n_models)], dtype=np.int64)
    return np.where(fine_pts >= 0, f2c[np.maximum(fine_pts, 0)], -1)


def run_sequence(path: Path, seed: int, per_motion: list[int], merges: list[str]) -> list[dict]:
    seq = laav.load_sequence(path)
    C = seq.n_motions
    rng = _stage_rngs(seed)
    base = laav.LaavParams()
    D = Neighbourhoods(seq.points)
    atoms = build_atoms(seq, base, np.random.default_rng(rng["atoms"]), D)
    graph = atom_graph(seq, atoms, base, D)
    rows = []
    for k in per_motion:
        mc = solve_multicut(graph, k * C)
        for merge in merges:
            p = merge_params(merge)
            t = time.perf_counter()
            if p is None:
                labels = oracle_labels(seq, point_labels_from_atoms(atoms, mc.atom_labels),
                                       mc.n_models)
            else:
                labels = merge_models(seq, atoms, mc, C, p,
                                      np.random.default_rng(rng["coarse"])).point_labels
            dt = time.perf_counter() - t
            cov = labels >= 0
            err = laav.misclassification_rate(seq.labels[cov], labels[cov]) if cov.any() else 1.0
            rows.append({"config": f"{merge}/{k}C", "sequence": seq.name, "motions": C, "seed": seed,
                         "coarse": round(100 * err, 4), "coverage": round(float(cov.mean()), 4),
                         "seconds": round(dt, 5)})
    return rows


def summarise(rows: list[dict]) -> tuple[list[str], dict]:
    per: dict = {}
    motions = {}
    for r in rows:
        per.setdefault(r["config"], {}).setdefault(r["sequence"], []).append(float(r["coarse"]))
        motions[r["sequence"]] = int(r["motions"])
    errors = {c: {s: float(np.mean(v)) for s, v in d.items()} for c, d in per.items()}
    lines = ["| configuration | <= 1 % wrong | > 10 % wrong | mean % (2 / 3 / all) | median ms |",
             "|---|---|---|---|---|"]
    secs = {}
    for r in rows:
        secs.setdefault(r["config"], []).append(float(r["seconds"]))
    for c, e in errors.items():
        v = np.array(list(e.values()))
        m = np.array([motions[s] for s in e])
        lines.append(f"| {c} | {(v <= 1).sum()} of {v.size} | {(v > 10).sum()} | "
                     f"{v[m == 2].mean():.2f} / {v[m == 3].mean():.2f} / {v.mean():.2f} | "
                     f"{1000 * np.median(secs[c]):.1f} |")
    # the oracle reads the truth: a ceiling to compare with, never a configuration to choose
    return lines, cross_validate({c: e for c, e in errors.items()
                                  if not c.startswith("oracle/")}, motions)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data")
    ap.add_argument("--seeds", default="0")
    ap.add_argument("--per-motion", default="2,3,4")
    ap.add_argument("--merges", default="paper,epipolar,coding:5.5,coding:10,coding:17")
    ap.add_argument("--only", action="append", default=[])
    ap.add_argument("--out", default="bench-out/coarse.csv")
    ap.add_argument("--report", default=None)
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    per_motion = [int(k) for k in args.per_motion.split(",")]
    merges = args.merges.split(",")
    for m in merges:
        merge_params(m)
    files = truth_files(data_dir(args.data), args.only)
    rows = []
    for i, f in enumerate(files):
        for s in seeds:
            rows += run_sequence(f, s, per_motion, merges)
        print(f"{i + 1}/{len(files)} {f.parent.name}", file=sys.stderr, flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=FIELDS)
        w.writeheader()
        w.writerows(rows)
    lines, cv = summarise(rows)
    text = ["# Stage 4 alone: fine-to-coarse labels on the points in atoms",
            "",
            f"{time.strftime('%Y-%m-%d')}, {cpu_model()}, Python {platform.python_version()}, "
            f"git {git_commit()}; {len(files)} sequences x seeds {args.seeds}; atoms, graph and "
            "multicut of the default parameters; configuration = merge / fine models.",
            "", *lines, "",
            "5-fold cross-validation grouped by source video (the configuration chosen on four "
            "folds by mean coarse error, reported on the fifth):", "",
            "| fold | chosen on the other folds | sequences | held-out mean % |", "|---|---|---|---|"]
    text += [f"| {k} | {b} | {n} | {e:.2f} |" for k, b, n, e in cv["folds"]]
    text += ["", "| figure | 2 motions | 3 motions | all |", "|---|---|---|---|",
             "| cross-validated (held out) | " + " | ".join(f"{v:.2f}" for v in cv["cv"]) + " |"]
    print("\n".join(text))
    if args.report:
        Path(args.report).write_text("\n".join(text) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
