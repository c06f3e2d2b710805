"""Cross-validated error on Hopkins155, folds grouped by source video.

Reads the runs of ``benchmarks/chain.py`` (one row per configuration, sequence and seed)
and treats a set of configurations as the candidate values of a constant (``--grid``,
e.g. ``default,ag0.5,ag6`` for ``rv_select_agreement`` = 2, 0.5, 6). The 155 sequences
come from 50 videos: a three-motion sequence ``X`` and its two-motion subsets ``X_g12``,
``X_g13``, ``X_g23`` are one video. Videos are split into ``--folds`` folds (seeded
shuffle); for each fold the configuration with the lowest mean error on the *other*
folds is chosen, and its error on this fold is what the fold reports. The cross-validated
figure is the mean over all sequences of the error they got as held-out data, beside the
all-data figure of each configuration (which is what tuning on everything would report).

    python benchmarks/cv.py --runs bench-out/chain.csv[,more.csv] --grid default,ag0.5,ag6 [--folds 5]
"""

from __future__ import annotations

import argparse
import csv
import re
import sys

import numpy as np

_SUBSET = re.compile(r"_g(12|13|23)$")


def video_of(sequence: str) -> str:
    """The source video of a Hopkins155 sequence (its ``_gXY`` suffix removed)."""
    return _SUBSET.sub("", sequence)


def folds_by_video(sequences, n_folds: int, seed: int = 0) -> dict:
    """Sequence -> fold index, every video's sequences in one fold."""
    videos = sorted({video_of(s) for s in sequences})
    order = np.random.default_rng(seed).permutation(len(videos))
    fold_of_video = {videos[i]: k % n_folds for k, i in enumerate(order)}
    return {s: fold_of_video[video_of(s)] for s in sequences}


def cross_validate(errors: dict, motions: dict, n_folds: int = 5, seed: int = 0) -> dict:
    """``errors[config][sequence]`` = mean error (% over seeds) -> per-fold choices and figures."""
    configs = list(errors)
    seqs = sorted(set.intersection(*(set(e) for e in errors.values())))
    fold = folds_by_video(seqs, n_folds, seed)
    held = {}
    chosen = []
    for k in range(n_folds):
        train = [s for s in seqs if fold[s] != k]
        test = [s for s in seqs if fold[s] == k]
        best = min(configs, key=lambda c: np.mean([errors[c][s] for s in train]))
        chosen.append((k, best, len(test), float(np.mean([errors[best][s] for s in test]))))
        held.update({s: errors[best][s] for s in test})

    def split(values: dict) -> tuple:
        e = np.array([values[s] for s in seqs])
        m = np.array([motions[s] for s in seqs])
        return e[m == 2].mean(), e[m == 3].mean(), e.mean()

    return {"folds": chosen, "cv": split(held),
            "all_data": {c: split(errors[c]) for c in configs}, "n_sequences": len(seqs)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", required=True,
                    help="chain.py CSV(s), comma-separated; a configuration's runs come from "
                         "the first file that has it (for the seeds asked)")
    ap.add_argument("--grid", required=True, help="comma-separated configuration names")
    ap.add_argument("--folds", type=int, default=5)
    ap.add_argument("--seed", type=int, default=0, help="seed of the fold shuffle")
    ap.add_argument("--seeds", default=None, help="only runs of these seeds (e.g. 0,1)")
    args = ap.parse_args(argv)
    grid = args.grid.split(",")
    seeds = None if args.seeds is None else {int(x) for x in args.seeds.split(",")}
    per: dict = {c: {} for c in grid}
    motions = {}
    taken: set = set()  # configurations read from an earlier file
    for path in args.runs.split(","):
        here: set = set()
        with open(path, newline="") as fh:
            for r in csv.DictReader(fh):
                c = r["config"]
                if c in per and c not in taken and (seeds is None or int(r["seed"]) in seeds):
                    per[c].setdefault(r["sequence"], []).append(float(r["error"]))
                    motions[r["sequence"]] = int(r["motions"])
                    here.add(c)
        taken |= here
    missing = [c for c in grid if not per[c]]
    if missing:
        print(f"cv.py: no runs of {', '.join(missing)} in {args.runs}", file=sys.stderr)
        return 2
    errors = {c: {s: float(np.mean(v)) for s, v in d.items()} for c, d in per.items()}
    res = cross_validate(errors, motions, args.folds, args.seed)
    print(f"{res['n_sequences']} sequences, {args.folds} folds grouped by video, grid {grid}")
    print("| fold | chosen on the other folds | sequences | held-out mean % |")
    print("|---|---|---|---|")
    for k, best, n, e in res["folds"]:
        print(f"| {k} | {best} | {n} | {e:.2f} |")
    print("\n| figure | 2 motions | 3 motions | all |\n|---|---|---|---|")
    print("| cross-validated (held out) | " + " | ".join(f"{v:.2f}" for v in res["cv"]) + " |")
    for c, v in res["all_data"].items():
        print(f"| all data, {c} | " + " | ".join(f"{x:.2f}" for x in v) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
