"""The joint score's descent (laav.joint, ``rv_descent``): checked against a direct
computation of the score, and in the chain."""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, misclassification_rate, random_voting, synthetic
from laav.coding import labelling_coding_length, principal_trajectories
from laav.joint import _move_gains, joint_descent, joint_score, unit2
from laav.refine import frame_pairs, motion_distances


def scene(seed=0, n_objects=2):
    return synthetic.make_sequence(n_objects=n_objects, n_frames=20, n_points=240, rng=seed)


def swapped(labels, share, C, seed=0):
    """``labels`` with ``share`` of the points moved to another motion at random."""
    rng = np.random.default_rng(seed)
    out = labels.copy()
    pick = rng.random(labels.size) < share
    out[pick] = (out[pick] + rng.integers(1, C, pick.sum())) % C
    return out


def test_move_gains_are_the_score_change_of_each_single_move():
    """Every point's gain for every other motion, against the joint score's parts computed
    directly (the coding length of the whole relabelled labelling; the epipolar term with
    the motions' matrices of the start held fixed, as a sweep holds them)."""
    seq = scene(3)
    C = 3
    p = LaavParams()
    L = swapped(seq.labels, 0.05, C, seed=1)
    F = seq.n_frames
    u2 = unit2(p)
    epi = np.log1p(motion_distances(seq.points, L, C, frame_pairs(F, 8), u2) / u2)
    gain = _move_gains(principal_trajectories(seq.points), L, C, 2 * F, p.coding_eps, epi,
                       p.coarse_epipolar_weight)
    base = labelling_coding_length(seq.points, L, C, p.coding_eps)
    rng = np.random.default_rng(2)
    for i in rng.choice(seq.n_points, 12, replace=False):
        for b in range(C):
            if b == L[i]:
                assert gain[i, b] == np.inf
                continue
            T = L.copy()
            T[i] = b
            direct = (labelling_coding_length(seq.points, T, C, p.coding_eps) - base
                      + p.coarse_epipolar_weight * (epi[b, i] - epi[L[i], i]))
            assert gain[i, b] == pytest.approx(direct, rel=1e-6, abs=1e-6)


@pytest.mark.parametrize("seed", [0, 1])
def test_descent_lowers_the_score_and_mends_scattered_errors(seed):
    seq = scene(seed)
    C = 3
    p = LaavParams()
    start = swapped(seq.labels, 0.04, C, seed)
    out, moved = joint_descent(seq.points, start, C, p)
    assert moved == np.count_nonzero(out != start) > 0
    assert joint_score(seq.points, out, C, p) < joint_score(seq.points, start, C, p)
    assert misclassification_rate(out, seq.labels) < 0.25 * misclassification_rate(start, seq.labels)
    again, moved2 = joint_descent(seq.points, start, C, p)  # no random draw: the same
    assert np.array_equal(again, out) and moved2 == moved


def test_descent_does_not_repair_a_wrong_partition():
    """A local search: from labels that split one motion and join two others (an early
    stage broken), the result stays far from the truth."""
    seq = scene(4)
    L = seq.labels.copy()
    big = np.flatnonzero(L == 0)
    L[L == 2] = 1  # motions 1 and 2 joined
    L[big[: big.size // 2]] = 2  # motion 0 split in two
    out, moved = joint_descent(seq.points, L, 3, LaavParams())
    assert moved > 0  # it did search (and lowered the score) ...
    assert joint_score(seq.points, out, 3, LaavParams()) < joint_score(seq.points, L, 3, LaavParams())
    assert misclassification_rate(out, seq.labels) > 0.15  # ... but not to the truth


def test_descent_keeps_every_motion_at_eight_points_or_more():
    """A motion at the floor (8 points, 2 of them another motion's) loses none of its
    points in a sweep (others may move into it; once above the floor, a later sweep may take
    the 2 out); no motion ever ends under 8; the score still falls."""
    seq = scene(7)
    C = 3
    p = LaavParams()
    L = seq.labels.copy()
    small = np.flatnonzero(L == 2)
    L[small[6:]] = 0  # motion 2 keeps 6 of its points ...
    L[np.flatnonzero(seq.labels == 1)[:2]] = 2  # ... and 2 of motion 1's: 8 in all
    assert np.count_nonzero(L == 2) == 8
    one, moved = joint_descent(seq.points, L, C, p, max_sweeps=1)
    assert moved > 0 and np.all(one[L == 2] == 2)  # nothing left the motion at the floor
    out, moved = joint_descent(seq.points, L, C, p)
    assert moved > 0 and np.bincount(out, minlength=C).min() >= 8
    assert joint_score(seq.points, out, C, p) < joint_score(seq.points, one, C, p)


def test_the_motion_count_profile_never_descends():
    """The profile's constants were fitted on labellings without the descent: whatever the
    caller's settings, its pipeline runs without it (the command line passes LaavParams())."""
    from laav.motions import _prepare

    seq = scene(8, n_objects=1)
    ctx = _prepare(seq, 3, LaavParams(), 0, 4)
    assert ctx.pipe.params.rv_descent is False


def test_descent_leaves_the_truth_and_degenerate_starts_alone():
    seq = scene(5, n_objects=1)
    p = LaavParams()
    out, moved = joint_descent(seq.points, seq.labels, 2, p)
    assert misclassification_rate(out, seq.labels) == 0.0
    tiny = seq.labels.copy()
    tiny[:] = 0
    tiny[:5] = 1  # a motion under 8 points: the score is infinite, nothing to descend on
    out, moved = joint_descent(seq.points, tiny, 2, p)
    assert moved == 0 and np.array_equal(out, tiny)
    out, moved = joint_descent(seq.points, np.zeros(seq.n_points, int), 1, p)
    assert moved == 0


def test_the_chain_descends_only_with_rv_descent():
    """``Voting.descended`` counts the moves; off, the labels are the polished candidate's;
    the paper preset never descends."""
    seq = scene(6)
    start = swapped(seq.labels, 0.3, 3, seed=6)
    p = LaavParams(rv_max_iter=2, rv_reassign=False)  # voting and polish leave work to do
    on = random_voting(seq, 3, p, seed=0, init_labels=start)
    off = random_voting(seq, 3, p.replace(rv_descent=False), seed=0, init_labels=start)
    assert on.descended == np.count_nonzero(on.labels != off.labels) > 0
    assert off.descended == 0
    assert joint_score(seq.points, on.labels, 3, p) < joint_score(seq.points, off.labels, 3, p)
    assert LaavParams.paper().rv_descent is False and LaavParams.own_chain().rv_descent is True
