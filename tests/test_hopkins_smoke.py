"""Hopkins155 smoke test: LAAV and plain RV on five varied sequences, with error bounds.

Sequences: 1R2RC_g12 (checkerboard, 2 motions), cars1 (traffic, 2), arm (articulated, 2),
2T3RCR_g13 (checkerboard, 2, the hardest here), three-cars (3 motions, 320x240).

Measured misclassification (2026-11-29 evening, after the joint reassignment and the
batched trials), seeds 0-3, in the order above:

    LAAV: 0 on every sequence and seed, except three-cars at seed 1: 45.66 % (0 since 2026-11-30)
    RV:   0 on every sequence and seed, except 2T3RCR_g13 at seed 2: 0.95 %

2026-11-30: with one random stream per voting trial (labels no longer depend on
``rv_batch``) three-cars at seed 1 is right (0 %); seeds 0 and 1 of every sequence are
now within the ceilings, so KNOWN_FAILURES is empty. The coarse merge still joins two
cars of three-cars at most seeds (benchmarks/TUNING.md); LAAV recovers through plain RV
and the model selection. A (sequence, seed) that fails again goes back into
KNOWN_FAILURES, with why, and its strict check below. (On 2026-11-22
arm was 2.6 % and 2T3RCR_g13 up to 6.6 %.) Runtime ~10 s.
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
#: (sequence, seed) pairs that fail today, with why (see the module docstring)
KNOWN_FAILURES: dict = {}


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
    e = {n: v for n, v in _table(errors, "laav", seed).items() if (n, seed) not in KNOWN_FAILURES}
    assert np.mean(list(e.values())) <= MEAN_CEILING, e
    bad = {n: v for n, v in e.items() if v > CEILING[n]}
    assert not bad, f"over the per-sequence ceiling: {bad} (all: {e})"


@pytest.mark.parametrize("name, seed", sorted(KNOWN_FAILURES) or [pytest.param(
    None, None, marks=pytest.mark.skip(reason="no known failure today"))])
def test_laav_hopkins_known_failures(errors, name, seed):
    if errors["laav", seed, name] > CEILING[name]:
        pytest.xfail(KNOWN_FAILURES[name, seed])
    pytest.fail(f"{name} at seed {seed} now passes ({errors['laav', seed, name]:.4f}): "
                "remove it from KNOWN_FAILURES")


def test_rv_hopkins_smoke(errors):
    e = _table(errors, "rv", 0)
    assert np.mean(list(e.values())) <= MEAN_CEILING, e
    bad = {n: v for n, v in e.items() if v > CEILING[n]}
    assert not bad, f"over the per-sequence ceiling: {bad} (all: {e})"


def test_joint_selection_keeps_laavs_right_start(hopkins_root):
    """2T3RCR_g13, seed 3: the coarse labels are right and LAAV's informed trial keeps
    them, but plain RV's unconverged trials (17 % wrong) have the lower subspace cost, so
    the selection by subspace cost (the default until 2026-12-01) returned one of them.
    The joint score (coding length + epipolar cost) ranks LAAV's trial first
    (benchmarks/TUNING.md, "The selection by the joint score"). Both with plain RV beside
    LAAV's trial (``LaavParams.with_plain_rv()``, the default until 2026-12-02); the default
    since, with no plain RV, keeps LAAV's right trial too."""
    from laav import LaavParams

    seq = load_sequence(hopkins_root / "2T3RCR_g13")
    joint = segment(seq, seq.n_motions, LaavParams.with_plain_rv(), seed=3)
    assert joint.params.rv_select == "joint" and joint.voting.selected == "informed"
    assert misclassification_rate(seq.labels, joint.labels) < 0.01
    own = segment(seq, seq.n_motions, seed=3)
    assert own.voting.selected == "informed" and misclassification_rate(seq.labels, own.labels) < 0.01
    old = segment(seq, seq.n_motions, LaavParams.with_plain_rv(rv_select="subspace"), seed=3)
    assert old.voting.selected.startswith("plain")
    assert misclassification_rate(seq.labels, old.labels) > 0.1
