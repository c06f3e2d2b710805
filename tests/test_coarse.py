"""Fine-to-coarse merge (laav.coarse.merge_models) and point labels from atoms."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from laav import LaavParams, build_atoms, merge_models, misclassification_rate, segment
from laav.atoms import Atoms
from laav.coarse import point_labels_from_atoms
from laav.multicut import Multicut

synthetic = pytest.importorskip("laav.synthetic")

SCENES = [(1, 0), (1, 1), (1, 2), (1, 3), (2, 0), (2, 1), (2, 2), (2, 3)]
_cache: dict = {}


def scene_and_atoms(n_objects, seed):
    key = (n_objects, seed)
    if key not in _cache:
        seq = synthetic.make_sequence(n_objects=n_objects, n_frames=20, n_points=300, rng=seed)
        atoms = build_atoms(seq, LaavParams(), np.random.default_rng(0))
        _cache[key] = (seq, pure_atoms(seq, atoms))
    return _cache[key]


def pure_atoms(seq, atoms):
    """The atoms that hold a single motion (the merge is tested apart from atom errors)."""
    keep = [i for i, m in enumerate(atoms.members) if np.unique(seq.labels[m]).size == 1]
    remap = np.full(atoms.n_atoms + 1, -1)
    remap[keep] = np.arange(len(keep))
    members = tuple(atoms.members[i] for i in keep)
    covered = np.zeros(atoms.n_points, dtype=bool)
    for m in members:
        covered[m] = True
    return dataclasses.replace(
        atoms, members=members, seeds=atoms.seeds[keep], owner=remap[atoms.owner],
        affines=atoms.affines[keep], residuals=tuple(atoms.residuals[i] for i in keep),
        unassigned=np.flatnonzero(~covered))


def true_fine_models(seq, atoms):
    """2 C pure fine models: each motion's atoms split in two by the seed's x in frame 0."""
    C = seq.n_motions
    motion = np.array([seq.labels[m[0]] for m in atoms.members])
    x = seq.points[0, atoms.seeds, 0]
    fine = np.empty(atoms.n_atoms, dtype=np.int64)
    for c in range(C):
        idx = np.flatnonzero(motion == c)
        assert idx.size >= 2, "scene too sparse for this test"
        fine[idx] = 2 * c + (x[idx] > np.median(x[idx]))
    mc = Multicut(atom_labels=fine, n_models=2 * C, multicut_labels=fine, n_segments=2 * C,
                  cut=np.zeros(0, bool), objective=0.0, contractions=np.zeros((0, 2), np.int64),
                  contraction_costs=np.zeros(0))
    return mc


def check_coarse(seq, atoms, mc, co, C):
    n = mc.n_models
    assert co.fine_to_coarse.shape == (n,)
    assert np.array_equal(np.unique(co.fine_to_coarse), np.arange(min(C, n)))
    assert np.array_equal(co.atom_labels, co.fine_to_coarse[mc.atom_labels])
    fp = co.fine_point_labels
    assert np.array_equal(fp, point_labels_from_atoms(atoms, mc.atom_labels))
    assert np.array_equal(co.point_labels >= 0, fp >= 0)
    assert np.array_equal(co.point_labels[fp >= 0], co.fine_to_coarse[fp[fp >= 0]])
    assert np.array_equal(fp < 0, np.isin(np.arange(seq.n_points), atoms.unassigned))
    Z = co.affinity
    assert Z.shape == (n, n) and np.allclose(Z, Z.T) and np.allclose(np.diag(Z), 1.0)
    assert np.all(Z >= 0) and np.all(Z <= 1 + 1e-12)
    D = co.epipolar_distance
    assert np.allclose(D, D.T) and np.allclose(np.diag(D), 0.0) and np.all(D >= 0)
    F = seq.n_frames
    fr = co.frame_pairs
    assert fr.ndim == 2 and fr.shape[1] == 2
    assert np.all((fr >= 0) & (fr < F))
    assert np.all(np.abs(fr[:, 0] - fr[:, 1]) >= max(1, F // 3))
    Fm = co.pair_fundamental(seq.points, 0, min(1, n - 1))
    assert Fm.shape == (3, 3) and np.isclose(np.linalg.det(Fm), 0.0, atol=1e-9)


@pytest.mark.parametrize("n_objects, seed", SCENES)
def test_merge_groups_true_fine_models(n_objects, seed):
    """Given 2 C pure fine models, the merge must pair them by motion (default params).

    Measured (HEAD d098fe9 + geometry fix): wrong on 3 of 48 (scene, rng seed) cases, all
    2-motion scenes (scene seeds 0, 3, 7 with rng seed 0: grouping [0 1 0 1], [0 0 1 0],
    [0 1 1 0]), since the pooled model-level voting became the default; with
    ``pooled_trials=0`` (the paper's pairwise votes) 48 of 48 are right.
    """
    seq, atoms = scene_and_atoms(n_objects, seed)
    C = seq.n_motions
    mc = true_fine_models(seq, atoms)
    co = merge_models(seq, atoms, mc, C, LaavParams(), np.random.default_rng(0))
    check_coarse(seq, atoms, mc, co, C)
    truth = np.arange(2 * C) // 2
    assert misclassification_rate(truth, co.fine_to_coarse) == 0.0, co.fine_to_coarse
    cov = co.point_labels >= 0
    assert misclassification_rate(seq.labels[cov], co.point_labels[cov]) == 0.0


@pytest.mark.parametrize("n_objects, seed", SCENES)
def test_merge_groups_true_fine_models_pairwise_votes(n_objects, seed):
    """The paper's pairwise four-atom epipolar votes alone (pooled voting off)."""
    seq, atoms = scene_and_atoms(n_objects, seed)
    C = seq.n_motions
    mc = true_fine_models(seq, atoms)
    p = LaavParams(pooled_trials=0)
    co = merge_models(seq, atoms, mc, C, p, np.random.default_rng(0))
    check_coarse(seq, atoms, mc, co, C)
    assert misclassification_rate(np.arange(2 * C) // 2, co.fine_to_coarse) == 0.0
    # the affinity separates: every same-motion pair above every cross-motion pair
    same = (np.arange(2 * C)[:, None] // 2) == (np.arange(2 * C)[None, :] // 2)
    off = ~np.eye(2 * C, dtype=bool)
    assert co.affinity[same & off].min() > co.affinity[~same].max()
    assert co.epipolar_distance[same & off].max() < co.epipolar_distance[~same].min()


def test_merge_is_deterministic_and_identity_when_few_models():
    seq, atoms = scene_and_atoms(2, 0)
    mc = true_fine_models(seq, atoms)
    a = merge_models(seq, atoms, mc, 3, LaavParams(), np.random.default_rng(4))
    b = merge_models(seq, atoms, mc, 3, LaavParams(), np.random.default_rng(4))
    assert np.array_equal(a.fine_to_coarse, b.fine_to_coarse)
    assert np.array_equal(a.affinity, b.affinity)
    # as many motions as fine models: nothing to merge
    c = merge_models(seq, atoms, mc, 6, LaavParams(), np.random.default_rng(0))
    assert np.array_equal(c.fine_to_coarse, np.arange(6))


def test_merge_without_atoms():
    seq, atoms = scene_and_atoms(1, 0)
    empty = build_atoms(seq, LaavParams(r1=0.1, r2=0.2), np.random.default_rng(0))
    mc = Multicut(np.zeros(0, np.int64), 0, np.zeros(0, np.int64), 0, np.zeros(0, bool), 0.0,
                  np.zeros((0, 2), np.int64), np.zeros(0))
    co = merge_models(seq, empty, mc, 2, LaavParams(), np.random.default_rng(0))
    assert co.fine_to_coarse.size == 0
    assert np.all(co.point_labels == -1) and np.all(co.fine_point_labels == -1)


def test_point_labels_from_atoms_rules():
    """Owner's label wins; a shared ring feature takes the majority (ties: smallest)."""
    members = (np.array([0, 1, 2, 5]), np.array([2, 3, 4, 5]), np.array([4, 5, 6, 7]))
    owner = np.array([0, 0, -1, 1, -1, -1, 2, 2, -1])
    atoms = Atoms(members=members, seeds=np.array([0, 3, 6]), owner=owner,
                  affines=np.zeros((3, 2, 2, 3)), residuals=tuple(np.zeros(4) for _ in range(3)),
                  unassigned=np.array([8]), r1=1.0, r2=2.0, n_points=9)
    lab = point_labels_from_atoms(atoms, np.array([1, 0, 1]))
    # 0,1: owner 0 -> 1; 2: atoms 0,1 -> tie 1 vs 0 -> 0; 3: owner 1 -> 0;
    # 4: atoms 1,2 -> tie -> 0; 5: atoms 0,1,2 -> 1 twice -> 1; 6,7: owner 2 -> 1; 8: none
    assert lab.tolist() == [1, 1, 0, 0, 0, 1, 1, 1, -1]


#: The default's coarse stage (the joint merge on 4C fine models since 2026-12-02) is right
#: on every scene here; the epipolar merge of the default before it was wrong on 3-motion
#: scene 0 (the strict xfail here until then; the test below keeps that scene).
@pytest.mark.parametrize("n_objects, seed", SCENES[::2])
def test_segment_coarse_labels_match_truth_on_covered_points(n_objects, seed):
    seq = synthetic.make_sequence(n_objects=n_objects, n_frames=20, n_points=300, rng=seed)
    res = segment(seq, seq.n_motions, seed=0)
    cov = res.coarse.point_labels >= 0
    err = misclassification_rate(seq.labels[cov], res.coarse.point_labels[cov])
    assert err < 0.01, f"coarse error on covered points {err:.3f}"


def test_epipolar_merge_is_wrong_where_the_coding_merge_is_right():
    """The scene the paper's merge gets wrong (3 motions, scene 0, seed 0): kept as the
    measured reason for a coding-length merge (the default's ``"auto"`` is the joint one);
    strict both ways."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    errs = {}
    for merge, k in (("coding", 3), ("epipolar", 2)):
        p = LaavParams(coarse_merge=merge, fine_per_motion=k)
        co = segment(seq, seq.n_motions, p, seed=0).coarse
        cov = co.point_labels >= 0
        errs[merge] = misclassification_rate(seq.labels[cov], co.point_labels[cov])
    assert errs["coding"] < 0.01 < errs["epipolar"], errs


@pytest.mark.parametrize("seed", range(12))
def test_affinity_clustering_equals_scikit_learn(seed):
    """The coarse merge's spectral clustering (laav._spectral.affinity_clustering, a dense
    eigensolver, no scikit-learn import) labels as scikit-learn's
    SpectralClustering(affinity="precomputed", assign_labels="cluster_qr") did, on
    affinities shaped like the merge's: blocks of near-1 entries, noise, a unit diagonal."""
    from sklearn.cluster import SpectralClustering

    from laav._spectral import affinity_clustering

    rng = np.random.default_rng(seed)
    C = int(rng.integers(2, 6))
    n = int(rng.integers(C + 1, 5 * C + 3))  # both sides of scikit-learn's 5 x C switch
    group = rng.integers(0, C, n)
    Z = np.where(group[:, None] == group[None, :], rng.uniform(0.4, 1.0, (n, n)),
                 rng.uniform(0.0, 0.5, (n, n)) ** rng.uniform(1, 4))
    Z = np.triu(Z, 1)
    Z = Z + Z.T
    np.fill_diagonal(Z, 1.0)
    ref = SpectralClustering(n_clusters=C, affinity="precomputed", assign_labels="cluster_qr",
                             random_state=seed).fit_predict(Z + 1e-9)
    ours = affinity_clustering(Z + 1e-9, C)
    assert ours.dtype == np.int64 and ours.shape == (n,)
    assert np.array_equal(ours, ref)


def test_the_epipolar_merge_does_not_import_scikit_learn():
    """The merge's spectral clustering is laav's own: a fresh process segments without
    loading scikit-learn (its import, 0.3-2 s, was the explorer's slow first move)."""
    import subprocess
    import sys

    code = ("import sys, laav; from laav.synthetic import make_sequence; "
            "laav.segment(make_sequence(n_objects=1, n_frames=10, n_points=200, rng=0), 2); "
            "print(any(m == 'sklearn' or m.startswith('sklearn.') for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"


def test_voting_features_keeps_every_model_in_proportion():
    from laav.coarse import MIN_MODEL_FEATURES, voting_features

    rng = np.random.default_rng(0)
    sizes = np.array([3000, 900, 40, 10, 500])
    models = rng.permutation(np.repeat(np.arange(sizes.size), sizes))
    features = np.arange(models.size) * 3 + 1  # any indices
    keep = voting_features(features, models, sizes.size, 1000, np.random.default_rng(5))
    assert np.all(np.diff(keep) > 0) and np.isin(keep, features).all()
    kept = np.bincount(models[np.searchsorted(features, keep)], minlength=sizes.size)
    want = np.minimum(sizes, np.maximum(MIN_MODEL_FEATURES, np.ceil(1000 * sizes / sizes.sum())))
    assert np.array_equal(kept, want)  # 684, 206, 32 (of 40), 10 (all), 114
    again = voting_features(features, models, sizes.size, 1000, np.random.default_rng(5))
    assert np.array_equal(keep, again)


def test_pooled_voting_on_a_sample_of_many_atom_features(monkeypatch):
    """rv_max_points caps the coarse stage's pooled voting: at or above the number of atom
    features nothing changes (the labels of rv_max_points=None); with a fifth of them
    (300 of about 1,500 features) the merge finds the true motions, as with all, on three
    seeds. (The merge is itself a random process: on other scenes some seeds go wrong with
    all features too.)"""
    from laav.atoms import build_atoms
    from laav.graph import atom_graph
    from laav.multicut import solve_multicut

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=1500, rng=5)
    p = LaavParams.with_plain_rv()  # the epipolar merge, whose pooled voting is capped
    atoms = build_atoms(seq, p, np.random.default_rng(0))
    mc = solve_multicut(atom_graph(seq, atoms, p), p.n_fine(3, True))
    n_feat = int((point_labels_from_atoms(atoms, mc.atom_labels) >= 0).sum())
    assert n_feat > 1000

    import laav.coarse

    sampled = []
    real = laav.coarse.voting_features
    monkeypatch.setattr(laav.coarse, "voting_features",
                        lambda *a: sampled.append(real(*a)) or sampled[-1])

    def coarse(cap, seed):
        return merge_models(seq, atoms, mc, 3, p.replace(rv_max_points=cap), np.random.default_rng(seed))

    for seed in (1, 2, 3):
        full = coarse(None, seed)
        assert np.array_equal(coarse(n_feat, seed).point_labels, full.point_labels)
        assert not sampled
        sample = coarse(300, seed)
        assert len(sampled) == 1 and 300 <= sampled.pop().size <= 300 + 6  # (ceil per model)
        for res in (sample, full):
            cov = res.point_labels >= 0
            assert misclassification_rate(seq.labels[cov], res.point_labels[cov]) == 0


@pytest.mark.parametrize("hidden", [0.0, 0.4])
def test_pairwise_votes_batched_by_model_pairs_are_the_same(monkeypatch, hidden):
    """The pairwise votes fit a batch of model pairs at a time (memory bounded for large
    coarse_frames x coarse_samples, which took ~47 MB per 100 samples at once): one pair
    per batch gives the same votes, distances, median samples and labels (complete and
    incomplete tracks)."""
    import laav.coarse as coarse_module
    from laav import Pipeline
    from laav.bench import hide_entries

    seq, _ = scene_and_atoms(2, 0)
    if hidden:
        seq = hide_entries(seq, hidden, 0)
    params = LaavParams(coarse_frames=9, coarse_samples=11)
    whole = Pipeline(seq, 3, params, seed=0).result
    monkeypatch.setattr(coarse_module, "_PAIRWISE_BATCH", 1)
    single = Pipeline(seq, 3, params, seed=0).result
    a, b = whole.coarse, single.coarse
    assert a.pairwise_vote.shape[0] >= 6  # several model pairs
    for x, y in ((a.pairwise_vote, b.pairwise_vote), (a.epipolar_distance, b.epipolar_distance),
                 (a.vote_samples.fundamental, b.vote_samples.fundamental),
                 (a.vote_samples.points, b.vote_samples.points),
                 (a.vote_samples.frames, b.vote_samples.frames),
                 (a.vote_samples.distance, b.vote_samples.distance), (whole.labels, single.labels)):
        np.testing.assert_array_equal(x, y)  # NaN where a model pair has no sample: equal too
