"""Hopkins155 smoke test: LAAV and plain RV on five varied sequences, with error bounds.

Sequences: 1R2RC_g12 (checkerboard, 2 motions), cars1 (traffic, 2), arm (articulated, 2),
2T3RCR_g13 (checkerboard, 2, the hardest here), three-cars (3 motions, 320x240).

Measured misclassification (working tree of 2026-11-22 ~04:05, after the geometry and KL
fixes), in the order above:

    LAAV seed 0:  0, 0, 2.6 %, 4.96 %, 0   mean 1.51 %
    LAAV seed 1:  0, 0, 2.6 %, 0.47 %, 0   mean 0.61 %
    LAAV seeds 2, 3: means 0.99 %, 0.57 %
    RV   seed 0:  0, 0, 2.6 %, 6.62 %, 0   mean 1.84 %
    RV   seeds 1-3: means 1.09 %, 0.52 %, 0.61 %

(arm's 2.6 % is 2 of 77 points.) Earlier the same day LAAV with seeds 1-3 put three-cars
at 46 % (the fine-to-coarse merge joined two cars), means 12-14 %. The bounds below hold
the current code with margin and would catch such a regression. Runtime ~10 s.
"""

from __future__ import annotations

import numpy as np
import pytest

from laav import load_sequence, misclassification_rate, random_voting, segment

pytestmark = [pytest.mark.hopkins, pytest.mark.slow]

SEQUENCES = ["1R2RC_g12", "cars1", "arm", "2T3RCR_g13", "three-cars"]
# per-sequence ceilings (measured worst over seeds 0-3 and both methods in brackets)
CEILING = {"1R2RC_g12": 0.02, "cars1": 0.02, "arm": 0.08, "2T3RCR_g13": 0.15,
           "three-cars": 0.02}  # [0, 0, 2.6 %, 6.6 %, 0]
MEAN_CEILING = 0.05
LAAV_SEEDS = (0, 1)


@pytest.fixture(scope="module")
def sequences(hopkins_root, hopkins_rows):
    names = {r["sequence"]: r for r in hopkins_rows}
    out = {}
    for name in SEQUENCES:
        assert name in names, f"{name} not in sequences.csv"
        seq = load_sequence(hopkins_root / name)
        assert seq.n_motions == int(names[name]["num_motions"])
        out[name] = seq
    return out


@pytest.fixture(scope="module")
def errors(sequences):
    err = {}
    for name, seq in sequences.items():
        for s in LAAV_SEEDS:
            res = segment(seq, seq.n_motions, seed=s)
            err["laav", s, name] = misclassification_rate(seq.labels, res.labels)
        res = random_voting(seq, seq.n_motions, seed=0)
        err["rv", 0, name] = misclassification_rate(seq.labels, res.labels)
    return err


def _table(err, method, seed):
    return {n: round(err[method, seed, n], 4) for n in SEQUENCES}


@pytest.mark.parametrize("seed", LAAV_SEEDS)
def test_laav_hopkins_smoke(errors, seed):
    e = _table(errors, "laav", seed)
    assert np.mean(list(e.values())) <= MEAN_CEILING, e
    bad = {n: v for n, v in e.items() if v > CEILING[n]}
    assert not bad, f"over the per-sequence ceiling: {bad} (all: {e})"


def test_rv_hopkins_smoke(errors):
    e = _table(errors, "rv", 0)
    assert np.mean(list(e.values())) <= MEAN_CEILING, e
    bad = {n: v for n, v in e.items() if v > CEILING[n]}
    assert not bad, f"over the per-sequence ceiling: {bad} (all: {e})"
