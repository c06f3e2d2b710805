"""Random Voting on a subset of many points (``rv_max_points``): with and without.

For each size P, each share of hidden entries and each seed, a synthetic scene
(``laav.synthetic.make_sequence(n_objects=2, n_frames=F, n_points=P, noise=0.5, rng=seed)``,
3 motions; then ``laav.synthetic.occlude(seq, missing, rng=seed)``) is segmented by
:class:`laav.Pipeline` with the default ``rv_max_points`` (voting on a seeded 1,000 of the
points, the rest placed by :func:`laav.refine.assign_jointly`), then the same pipeline's
voting is rerun with ``rv_max_points=None`` (every point votes; the stages before it are
shared, so the two differ in the voting only). Prints one JSON line per run and writes a
Markdown table with machine, date and git commit. One BLAS thread. Voting seconds are CPU
seconds of the process (robust to other work on a shared machine).

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


def run(sizes, missing, seeds, frames):
    import laav
    from laav.synthetic import make_sequence, occlude

    laav.preload()
    rows = []
    for P in sizes:
        for miss in missing:
            for seed in range(seeds):
                seq = make_sequence(n_objects=2, n_frames=frames, n_points=P, noise=0.5, rng=seed)
                if miss:
                    seq = occlude(seq, miss, rng=seed)
                pipe = laav.Pipeline(seq, seq.n_motions, laav.LaavParams(), seed=seed)
                limit = pipe.params.rv_max_points
                for m in (None, limit):  # each a fresh voting run (its memo is per rv_* settings)
                    t = time.process_time()
                    res = pipe.update(rv_max_points=m)
                    cpu = time.process_time() - t
                    row = {"P": P, "missing": miss, "seed": seed, "rv_max_points": m,
                           "error_pct": round(100 * laav.misclassification_rate(seq.labels, res.labels), 3),
                           "voting_cpu_s": round(cpu, 2), "selected": res.voting.selected}
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    return rows


def report(rows, path, argv):
    import numpy as np

    lines = [f"# Random Voting on a subset of many points, with and without "
             f"({time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())})", "",
             f"- Machine: {cpu_model()}, {os.cpu_count()} logical cores (shared; one BLAS thread), "
             f"{platform.system()} {platform.release()}",
             f"- Software: Python {platform.python_version()}, laav {laav_version()} (git {git_commit()})",
             f"- Command: `python benchmarks/subset.py {' '.join(argv)}`",
             "- Data: `laav.synthetic.make_sequence(n_objects=2, n_points=P, noise=0.5, rng=seed)` "
             "(3 motions), then `occlude(seq, missing, rng=seed)`; stages 1-4 shared, the voting "
             "run with the default `rv_max_points` and with None (every point votes).",
             "- Voting CPU s: the voting stage alone, CPU seconds of the process.", "",
             "| P | missing | rv_max_points | mean error % | worst % | mean voting CPU s | ratio |",
             "|---|---|---|---|---|---|---|"]
    keys = sorted({(r["P"], r["missing"]) for r in rows})
    for P, miss in keys:
        group = [r for r in rows if r["P"] == P and r["missing"] == miss]
        full = np.mean([r["voting_cpu_s"] for r in group if r["rv_max_points"] is None])
        for m in sorted({r["rv_max_points"] for r in group}, key=lambda v: v is None):
            g = [r for r in group if r["rv_max_points"] == m]
            cpu = np.mean([r["voting_cpu_s"] for r in g])
            lines.append(f"| {P:,} | {miss:.0%} | {m if m is not None else 'None (all)'} | "
                         f"{np.mean([r['error_pct'] for r in g]):.2f} | "
                         f"{max(r['error_pct'] for r in g):.2f} | {cpu:.1f} | {cpu / full:.2f} |")
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
