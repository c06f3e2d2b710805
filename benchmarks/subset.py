"""Voting on a subset of many points (``rv_max_points``): with and without, per stage.

For each size P, each share of hidden entries and each seed, a synthetic scene
(``laav.synthetic.make_sequence(n_objects=2, n_frames=F, n_points=P, noise=0.5, rng=seed)``,
3 motions; then ``laav.synthetic.occlude(seq, missing, rng=seed)``) runs stages 1-3 once
(the pipeline's stage generators for the seed), then three configurations of the two
stages that ``rv_max_points`` acts on:

- ``both`` (the default, 1,000): the fine-to-coarse stage's pooled voting lets a seeded,
  per-model stratified 1,000 atom features vote (:func:`laav.coarse.voting_features`), and
  Random Voting runs on a seeded 1,000 points, the rest placed by
  :func:`laav.refine.assign_jointly`;
- ``voting``: every atom feature votes in the coarse stage, Random Voting on 1,000 (the
  default before the coarse stage was capped);
- ``none``: every point votes in both.

Prints one JSON line per run (coarse error on the points in atoms, final error, CPU seconds
of each stage) and writes a Markdown table with machine, date and git commit. One BLAS
thread. CPU seconds of the process (robust to other work on a shared machine).

    python benchmarks/subset.py [--sizes 2000,5000] [--missing 0,0.5] [--seeds 3]
        [--frames 60] [--out docs/bench/subset.md]
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _machine import cpu_model, git_commit, laav_version  # noqa: E402

#: (name, the coarse stage's rv_max_points, the voting's): None = every point votes
CONFIGS = (("both", 1000, 1000), ("voting", None, 1000), ("none", None, None))


def run(sizes, missing, seeds, frames):
    import numpy as np

    import laav
    from laav.atoms import build_atoms
    from laav.coarse import merge_models
    from laav.graph import atom_graph
    from laav.multicut import solve_multicut
    from laav.pipeline import _stage_rngs
    from laav.synthetic import make_sequence, occlude
    from laav.voting import random_voting

    laav.preload()
    rows = []
    for P in sizes:
        for miss in missing:
            for seed in range(seeds):
                seq = make_sequence(n_objects=2, n_frames=frames, n_points=P, noise=0.5, rng=seed)
                if miss:
                    seq = occlude(seq, miss, rng=seed)
                C, p, rng = seq.n_motions, laav.LaavParams(), _stage_rngs(seed)
                atoms = build_atoms(seq, p, np.random.default_rng(rng["atoms"]))
                graph = atom_graph(seq, atoms, p)
                mc = solve_multicut(graph, p.n_fine(C, seq.is_complete))
                coarse_memo = {}
                for name, coarse_cap, voting_cap in CONFIGS:
                    if coarse_cap not in coarse_memo:
                        t = time.process_time()
                        coarse = merge_models(seq, atoms, mc, C, p.replace(rv_max_points=coarse_cap),
                                              np.random.default_rng(rng["coarse"]))
                        coarse_memo[coarse_cap] = (coarse, time.process_time() - t)
                    coarse, coarse_cpu = coarse_memo[coarse_cap]
                    cov = coarse.point_labels >= 0
                    t = time.process_time()
                    vot = random_voting(seq, C, p.replace(rv_max_points=voting_cap),
                                        np.random.default_rng(rng["voting"]),
                                        init_labels=coarse.point_labels)
                    cpu = time.process_time() - t
                    row = {"P": P, "missing": miss, "seed": seed, "config": name,
                           "coarse_pct": round(100 * laav.misclassification_rate(
                               seq.labels[cov], coarse.point_labels[cov]), 3),
                           "error_pct": round(100 * laav.misclassification_rate(seq.labels, vot.labels), 3),
                           "coarse_cpu_s": round(coarse_cpu, 2), "voting_cpu_s": round(cpu, 2),
                           "selected": vot.selected}
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    return rows


def report(rows, path, argv):
    import numpy as np

    lines = [f"# Voting on a subset of many points, with and without, per stage "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})", "",
             f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores (shared; one BLAS thread), "
             f"{platform.system()} {platform.release()}",
             f"- Software: Python {platform.python_version()}, laav {laav_version()} (git {git_commit()})",
             f"- Command: `python benchmarks/subset.py {' '.join(argv)}`",
             "- Data: `laav.synthetic.make_sequence(n_objects=2, n_points=P, noise=0.5, rng=seed)` "
             "(3 motions), then `occlude(seq, missing, rng=seed)`; stages 1-3 shared.",
             "- Configurations: `both` = the default (`rv_max_points=1000`: pooled voting in the "
             "fine-to-coarse stage on 1,000 atom features, Random Voting on 1,000 points); "
             "`voting` = every atom feature votes in the coarse stage, Random Voting on 1,000; "
             "`none` = every point votes in both.",
             "- CPU s: each stage alone, CPU seconds of the process; ratios against `none`.", "",
             "| P | missing | config | coarse error % | final error % (mean / worst) | coarse CPU s | "
             "ratio | voting CPU s | ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    keys = sorted({(r["P"], r["missing"]) for r in rows})
    for P, miss in keys:
        group = [r for r in rows if r["P"] == P and r["missing"] == miss]
        ref = [r for r in group if r["config"] == "none"]
        c0 = np.mean([r["coarse_cpu_s"] for r in ref])
        v0 = np.mean([r["voting_cpu_s"] for r in ref])
        for name, _, _ in CONFIGS:
            g = [r for r in group if r["config"] == name]
            if not g:
                continue
            c, v = np.mean([r["coarse_cpu_s"] for r in g]), np.mean([r["voting_cpu_s"] for r in g])
            err = [r["error_pct"] for r in g]
            lines.append(f"| {P:,} | {miss:.0%} | {name} | {np.mean([r['coarse_pct'] for r in g]):.2f} | "
                         f"{np.mean(err):.2f} / {max(err):.2f} | "
                         f"{c:.2f} | {c / c0:.2f} | {v:.1f} | {v / v0:.2f} |")
    lines += ["", "Per run:", "", "```", *(json.dumps(r) for r in rows), "```", ""]
    Path(path).write_text("\n".join(lines))
    print(f"wrote {path}")


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="2000,5000")
    ap.add_argument("--missing", default="0,0.5")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--out", default="docs/bench/subset.md")
    a = ap.parse_args(argv)
    rows = run([int(s) for s in a.sizes.split(",")], [float(s) for s in a.missing.split(",")],
               a.seeds, a.frames)
    report(rows, a.out, argv)


if __name__ == "__main__":
    main()
