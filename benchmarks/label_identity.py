"""Fingerprints of LAAV's labels on a fixed set of runs: check that a change moved no label.

A change meant only to make a stage faster, or to reorganise code, must give the same labels
bit for bit. This script runs 103 fixed runs and prints one md5 per run of the labels
(``int64``) and of every stage's labels (fine, coarse, final), plus one md5 of them all:

- 12 Hopkins155 sequences (two and three motions, ``_g`` subsets, checkerboard, traffic,
  articulated) x seeds 0-1 x the default preset / ``LaavParams.with_plain_rv()`` /
  ``LaavParams.paper()`` (72 runs);
- those 12 at seed 0 with sigma = 1 px of noise and with 40 % of the tracks' samples missing
  (24 runs);
- ``laav.synthetic.make_family`` scenes 0-2 of ``small_motion`` and ``same_direction`` (6);
- a 2,500-track synthetic scene (1).

With ``--all``, also every Hopkins155 sequence (all 155) with the default preset at seeds 0-1
and with 20 % and 40 % of the tracks' samples missing at seed 0 (620 more runs; 723 in
all take about 5 minutes): what a change to a stage every sequence passes through should be checked on.

Usage::

    python benchmarks/label_identity.py --out /tmp/before.json        # on the old commit
    python benchmarks/label_identity.py --compare /tmp/before.json    # on the new one
    python benchmarks/label_identity.py --all --out /tmp/before.json  # (and --all --compare)

``--compare`` prints every run whose fingerprint differs and exits 1 if any does. When
comparing two commits in worktrees, set ``PYTHONPATH`` to the tree being measured (see
README.md, "Comparing two commits"). Hopkins155: ``$HOPKINS155`` or
``../shared/data/hopkins155`` relative to the repository; missing sequences are skipped and
named on stderr. Takes about 2 minutes on the development machine (one core used).
"""

from __future__ import annotations

import argparse
import hashlib
import itertools
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from _machine import cpu_model, git_commit  # noqa: E402

import laav  # noqa: E402
from laav.synthetic import add_noise, make_family, make_sequence, occlude  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SEQUENCES = ("1R2RC", "cars1", "two_cranes", "2T3RCRT_g23", "head", "kanatani3", "people1", "truck2",
             "cars2B", "1RT2RCR", "three-cars", "2RT3RCT_B")
PRESETS = {"default": laav.LaavParams, "with_plain_rv": laav.LaavParams.with_plain_rv,
           "paper": laav.LaavParams.paper}


def _md5(a) -> str:
    return hashlib.md5(np.ascontiguousarray(np.asarray(a, dtype=np.int64)).tobytes()).hexdigest()


#: (stage, attribute) of each stage's labels in a :class:`laav.LaavResult`
STAGE_LABELS = (("multicut", "atom_labels"), ("coarse", "fine_point_labels"), ("coarse", "point_labels"),
                ("voting", "labels"))


def fingerprint(result) -> str:
    """md5 of the final labels and of each stage's: the fine models of the atoms, the fine
    and coarse labels of the points in atoms, the fine-tuning's labels."""
    parts = [_md5(result.labels)]
    for stage, attr in STAGE_LABELS:
        labels = getattr(getattr(result, stage), attr)  # (an AttributeError: the model changed)
        parts.append(_md5(labels))
    return ":".join(parts)


def every_sequence(root: Path):
    """(name, sequence, C, params, seed) of ``--all``'s runs: every Hopkins155 sequence
    (``speed.truth_files``: without ``dancing``), the default preset at seeds 0-1, then with
    20 % and 40 % of its samples hidden (``occlude``, rng 0) at seed 0."""
    from speed import truth_files  # this folder

    for path in truth_files(root, []):
        seq = laav.load_sequence(path)
        for seed in (0, 1):
            yield f"all/{seq.name}/seed{seed}", seq, seq.n_motions, laav.LaavParams(), seed
        for level in (20, 40):
            yield (f"all/{seq.name}/missing{level}", occlude(seq, level / 100, rng=0), seq.n_motions,
                   laav.LaavParams(), 0)


def runs(root: Path):
    """(name, sequence, C, params, seed) of every run, in a fixed order."""
    found = []
    for name in SEQUENCES:
        if (root / name).is_dir():
            found.append(laav.load_sequence(root / name))
        else:
            print(f"note: {name} not found under {root}: skipped", file=sys.stderr)
    for seq in found:
        for preset, make in PRESETS.items():
            for seed in (0, 1):
                yield f"{seq.name}/{preset}/seed{seed}", seq, seq.n_motions, make(), seed
    for seq in found:
        yield f"{seq.name}/noise1", add_noise(seq, 1.0, rng=0), seq.n_motions, laav.LaavParams(), 0
        occluded = occlude(seq, 0.4, rng=0)
        yield f"{seq.name}/missing40", occluded, seq.n_motions, laav.LaavParams(), 0
    for fam in ("small_motion", "same_direction"):
        for scene in range(3):
            seq = make_family(fam, rng=scene)
            yield f"{fam}/scene{scene}", seq, seq.n_motions, laav.LaavParams(), 0
    big = make_sequence(n_objects=2, n_points=2500, rng=0, name="synthetic2500")
    yield "synthetic2500", big, big.n_motions, laav.LaavParams(), 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, help="write the fingerprints here (JSON)")
    ap.add_argument("--compare", type=Path, help="compare with fingerprints written by --out")
    ap.add_argument("--all", action="store_true",
                    help="also every Hopkins155 sequence, clean at seeds 0-1 and 20 / 40 %% missing")
    args = ap.parse_args(argv)
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else REPO.parent / "shared" / "data" / "hopkins155"
    prints = {}
    t0 = time.perf_counter()
    every = every_sequence(root) if args.all else ()
    for name, seq, c, params, seed in itertools.chain(runs(root), every):
        prints[name] = fingerprint(laav.segment(seq, c, params, seed=seed))
    total = hashlib.md5(json.dumps(prints, sort_keys=True).encode()).hexdigest()
    report = {"commit": git_commit(), "machine": cpu_model(), "laav": laav.__file__,
              "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "runs": len(prints),
              "seconds": round(time.perf_counter() - t0, 1), "all": total, "fingerprints": prints}
    print(json.dumps({k: v for k, v in report.items() if k != "fingerprints"}))
    if args.out:
        args.out.write_text(json.dumps(report, indent=1) + "\n")
    if args.compare:
        old = json.loads(args.compare.read_text())["fingerprints"]
        moved = [k for k in sorted(set(old) | set(prints)) if old.get(k) != prints.get(k)]
        for k in moved:
            print(f"differs: {k}: {old.get(k)} -> {prints.get(k)}")
        print(f"{len(moved)} of {len(prints)} runs differ from {args.compare}")
        return 1 if moved else 0
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
