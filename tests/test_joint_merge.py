"""Stage 4's joint merge (``coarse_merge="joint"``): a shortlist of partitions by coding
length, re-ranked by coding length + ``coarse_epipolar_weight`` x epipolar cost."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_coarse_votes import models_of_single_atoms  # tests/ is on sys.path

from laav import LaavParams, LaavWarning, merge_models, misclassification_rate
from laav.coding import best_partition, model_stats
from laav.refine import frame_pairs, motion_distances

synthetic = pytest.importorskip("laav.synthetic")

JOINT = LaavParams(coarse_merge="joint", fine_per_motion=3)


def atom_models(seq, sizes, rng):
    """Fine models that are single atoms: ``sizes[c]`` lists the sizes of motion c's models
    (disjoint random features of that motion)."""
    members = []
    for c, per in enumerate(sizes):
        pool = rng.permutation(np.flatnonzero(seq.labels == c))
        start = 0
        for size in per:
            members.append(np.sort(pool[start:start + size]))
            start += size
    return models_of_single_atoms(seq, members) + (members,)


def scene(seed, n_objects=2):
    return synthetic.make_sequence(n_objects=n_objects, n_frames=20, n_points=300, rng=seed,
                                   noise=0.5)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_joint_merge_scores_its_shortlist_and_keeps_the_best(seed):
    seq = scene(seed)
    atoms, mc, members = atom_models(seq, [[15, 15, 15]] * seq.n_motions,
                                     np.random.default_rng(seed))
    co = merge_models(seq, atoms, mc, seq.n_motions, JOINT, np.random.default_rng(0))
    sl = co.shortlist
    assert co.method == "joint" and sl is not None
    assert 1 <= sl.assign.shape[0] <= JOINT.coarse_candidates
    assert np.all(np.diff(sl.coding_length) >= 0)  # the shortlist, by coding length
    assert np.allclose(sl.score, sl.coding_length + JOINT.coarse_epipolar_weight * sl.epipolar_cost)
    assert sl.chosen == int(np.argmin(sl.score))
    chosen = sl.assign[sl.chosen]
    assert np.array_equal(co.fine_to_coarse, chosen)  # both numbered by first model
    assert co.coding_length == pytest.approx(sl.coding_length[sl.chosen])
    # the epipolar cost: every point's robust Sampson distance to its own motion
    cov = co.fine_point_labels >= 0
    pts, fine = seq.points[:, cov], co.fine_point_labels[cov]
    for a, e in zip(sl.assign, sl.epipolar_cost):
        lab = a[fine]
        D = motion_distances(pts, lab, seq.n_motions, frame_pairs(seq.n_frames, 8))
        assert e == pytest.approx(np.log1p(D[lab, np.arange(lab.size)]).sum())
    # pure models of independent motions: the merge is right
    cov = co.point_labels >= 0
    assert misclassification_rate(seq.labels[cov], co.point_labels[cov]) == 0.0


def test_epipolar_cost_separates_what_coding_length_alone_confuses():
    """A partition that mixes two independently moving objects costs more epipolar
    evidence than the true one; the weight makes it decide between close coding lengths."""
    seq = scene(3)
    atoms, mc, members = atom_models(seq, [[15, 15, 15]] * seq.n_motions,
                                     np.random.default_rng(3))
    co = merge_models(seq, atoms, mc, seq.n_motions,
                      JOINT.replace(coarse_candidates=50), np.random.default_rng(0),
                      full_shortlist=True)  # every partition's epipolar cost
    sl = co.shortlist
    truth = np.repeat(np.arange(seq.n_motions), 3)
    true_row = [i for i, a in enumerate(sl.assign) if np.array_equal(a, truth)]
    assert true_row, "the true partition is on the shortlist"
    others = np.delete(sl.epipolar_cost, true_row)
    assert sl.epipolar_cost[true_row[0]] < others.min()


def test_no_motion_of_fewer_than_eight_points():
    seq = scene(4, n_objects=1)
    rng = np.random.default_rng(4)
    atoms, mc, members = atom_models(seq, [[30, 30, 5], [20, 20]], rng)  # model 2: 5 points
    co = merge_models(seq, atoms, mc, 2, JOINT, np.random.default_rng(0))
    for a in co.shortlist.assign:
        sizes = np.bincount(a, weights=[m.size for m in members], minlength=2)
        assert sizes.min() >= 8
    # the coding merge alone may isolate it; the joint merge never does
    assert (co.fine_to_coarse == co.fine_to_coarse[2]).sum() > 1


def test_without_epipolar_weight_it_is_the_coding_merge():
    seq = scene(5)
    atoms, mc, _ = atom_models(seq, [[15, 15, 15]] * seq.n_motions, np.random.default_rng(5))
    p = JOINT.replace(coarse_epipolar_weight=0.0)
    joint = merge_models(seq, atoms, mc, seq.n_motions, p, np.random.default_rng(0))
    code = merge_models(seq, atoms, mc, seq.n_motions, p.replace(coarse_merge="coding"),
                        np.random.default_rng(0))
    stats = model_stats(seq.points, joint.fine_point_labels, mc.n_models)
    best, _ = best_partition(stats, seq.n_motions, p.coding_eps)
    assert np.array_equal(joint.fine_to_coarse, code.fine_to_coarse)
    assert np.array_equal(joint.fine_to_coarse, best)
    assert code.shortlist is None


def test_incomplete_data_falls_back_to_the_epipolar_merge_with_a_warning():
    seq = scene(6)
    atoms, mc, _ = atom_models(seq, [[15, 15, 15]] * seq.n_motions, np.random.default_rng(6))
    vis = np.ones((seq.n_frames, seq.n_points), bool)
    vis[:3, ::7] = False
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        co = merge_models(seq.points, atoms, mc, seq.n_motions, JOINT, np.random.default_rng(0),
                          visible=vis)
    assert co.method == "epipolar" and co.shortlist is None
    assert any(issubclass(w.category, LaavWarning) and "'joint'" in str(w.message)
               for w in caught)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_the_shortlist_stops_where_no_partition_can_win_and_chooses_the_same(seed):
    """The joint merge scores its shortlist by increasing coding length and stops at the
    first partition whose coding length alone exceeds the best score (an epipolar cost is
    >= 0): its scores are the full comparison's first ones, bit for bit, it chooses the same
    partition, and every partition it did not score has a coding length above that best
    score. On these scenes it stops early (the point of it: fewer motion fits)."""
    seq = scene(seed, n_objects=2)
    atoms, mc, _ = atom_models(seq, [[15, 15, 15, 15]] * seq.n_motions, np.random.default_rng(seed))
    p = JOINT.replace(coarse_candidates=20)
    fast = merge_models(seq, atoms, mc, seq.n_motions, p, np.random.default_rng(0))
    full = merge_models(seq, atoms, mc, seq.n_motions, p, np.random.default_rng(0),
                        full_shortlist=True)
    a, b = fast.shortlist, full.shortlist
    k = a.score.size
    assert b.score.size == p.coarse_candidates and 1 <= k < b.score.size
    for f in ("assign", "coding_length", "epipolar_cost", "score"):
        assert np.array_equal(getattr(a, f), getattr(b, f)[:k]), f
    assert a.chosen == b.chosen and np.array_equal(fast.point_labels, full.point_labels)
    assert np.all(b.coding_length[k:] > a.score.min())
    assert np.all(b.score[k:] > a.score.min())


def test_a_pipeline_can_be_asked_for_the_whole_comparison_later():
    """``Pipeline.update(full_shortlist=True)`` reruns the coarse stage to score every
    partition (``Shortlist.complete``), the labels as before; back to False, the first
    partitions only again."""
    from laav import Pipeline

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=1)
    pipe = Pipeline(seq, 3)
    part = pipe.result
    assert not part.coarse.shortlist.complete
    whole = pipe.update(full_shortlist=True)
    assert pipe.full_shortlist and whole.coarse.shortlist.complete
    assert whole.coarse.shortlist.score.size > part.coarse.shortlist.score.size
    assert whole.atoms is part.atoms and whole.multicut is part.multicut  # (coarse on only)
    assert np.array_equal(whole.labels, part.labels)
    again = pipe.update(full_shortlist=False)
    assert np.array_equal(again.coarse.shortlist.score, part.coarse.shortlist.score)
