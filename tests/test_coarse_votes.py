"""The fine-to-coarse stage's votes against a direct, independent computation (issue 12
item 6).

The scene is built so that the stage's random draws cannot matter: every fine model is one
atom of exactly six features (the stage draws six features per atom, so it draws all of
them, in some order) and the four-atom samples of a pair of models then always hold model
j's features twice and model k's twice. The paper's pairwise vote of each pair is then a
closed form per frame pair, computed here from scratch (own normalised 8-point algorithm
by SVD, own Sampson distance, loops instead of batches), and compared with
``Coarse.epipolar_distance`` and ``Coarse.affinity``.
"""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, merge_models
from laav.atoms import Atoms
from laav.multicut import Multicut

synthetic = pytest.importorskip("laav.synthetic")

PER_ATOM = 6  # the stage's features per atom (laav.coarse._PER_ATOM)


def one_atom_models(seq, n_per_motion, rng):
    """``n_per_motion`` fine models per motion, each a single atom of six features of it."""
    members = []
    for c in range(seq.n_motions):
        pool = rng.permutation(np.flatnonzero(seq.labels == c))
        for i in range(n_per_motion):
            members.append(np.sort(pool[i * PER_ATOM:(i + 1) * PER_ATOM]))
    return models_of_single_atoms(seq, members) + (members,)


def models_of_single_atoms(seq, members):
    """(atoms, multicut) where atom i holds the features ``members[i]`` and is fine model i."""
    N, P, F = len(members), seq.n_points, seq.n_frames
    owner = np.full(P, -1, dtype=np.int64)
    for i, m in enumerate(members):
        owner[m] = i
    atoms = Atoms(members=tuple(members), seeds=np.array([m[0] for m in members]), owner=owner,
                  affines=np.zeros((N, F, 2, 3)), residuals=tuple(np.zeros(m.size) for m in members),
                  unassigned=np.flatnonzero(owner < 0), r1=20.0, r2=40.0, n_points=P)
    labels = np.arange(N, dtype=np.int64)
    mc = Multicut(atom_labels=labels, n_models=N, multicut_labels=labels, n_segments=N,
                  cut=np.zeros(0, bool), objective=0.0, contractions=np.zeros((0, 2), np.int64),
                  contraction_costs=np.zeros(0))
    return atoms, mc


def direct_fundamental(x1, x2):
    """Hartley's normalised 8-point algorithm, written out: x2^T F x1 = 0."""
    def normaliser(x):
        c = x.mean(axis=0)
        s = np.sqrt(2.0) / np.sqrt(((x - c) ** 2).sum(axis=1).mean())
        return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])

    T1, T2 = normaliser(x1), normaliser(x2)
    a = (T1 @ np.c_[x1, np.ones(len(x1))].T).T
    b = (T2 @ np.c_[x2, np.ones(len(x2))].T).T
    A = np.array([np.outer(bi, ai).ravel() for ai, bi in zip(a, b)])
    f = np.linalg.svd(A)[2][-1].reshape(3, 3)
    U, S, Vt = np.linalg.svd(f)
    f = U @ np.diag([S[0], S[1], 0.0]) @ Vt
    F = T2.T @ f @ T1
    return F / np.linalg.norm(F)


def direct_sampson(F, x1, x2):
    out = []
    for p, q in zip(x1, x2):
        p3, q3 = np.append(p, 1.0), np.append(q, 1.0)
        Fp, Ftq = F @ p3, F.T @ q3
        out.append((q3 @ F @ p3) ** 2 / (Fp[0] ** 2 + Fp[1] ** 2 + Ftq[0] ** 2 + Ftq[1] ** 2))
    return np.array(out)


def direct_pair_votes(points, members, frame_pairs, lam):
    """Paper's pairwise vote of every pair of one-atom models: per frame pair, F from both
    models' features; the pair's distance is the larger of the two models' mean Sampson
    distances; the vote is exp(-lam * distance); both averaged over the frame pairs."""
    n = len(members)
    D, Z = np.zeros((n, n)), np.eye(n)
    for j in range(n):
        for k in range(j + 1, n):
            g = np.concatenate([members[j], members[k]])
            dist = []
            for fl, fr in frame_pairs:
                F = direct_fundamental(points[fl, g], points[fr, g])
                d = direct_sampson(F, points[fl, g], points[fr, g])
                dist.append(max(d[:PER_ATOM].mean(), d[PER_ATOM:].mean()))
            dist = np.array(dist)
            D[j, k] = D[k, j] = dist.mean()
            Z[j, k] = Z[k, j] = np.exp(-lam * dist).mean()
    return D, Z


def direct_motion_distance(points, members):
    """Paper's motion-difference term: per frame step, the distance between two models' mean
    velocities over the spread of all velocities (+ 1e-3 px), maximised over the steps."""
    F = points.shape[0]
    n = len(members)
    out = np.zeros((n, n))
    for j in range(n):
        for k in range(n):
            worst = 0.0
            for t in range(F - 1):
                v = points[t + 1] - points[t]
                sigma = np.sqrt(v[:, 0].var() + v[:, 1].var()) + 1e-3
                vj, vk = v[members[j]].mean(axis=0), v[members[k]].mean(axis=0)
                worst = max(worst, np.linalg.norm(vj - vk) / sigma)
            out[j, k] = worst
    return out


@pytest.mark.parametrize("n_objects, seed", [(1, 0), (1, 3), (2, 1)])
def test_paper_pairwise_votes_match_direct_computation(n_objects, seed):
    seq = synthetic.make_sequence(n_objects=n_objects, n_frames=12, n_points=240, noise=0.5,
                                  rng=seed)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(seed))
    params = LaavParams.paper(coarse_frames=3, coarse_samples=2)
    co = merge_models(seq, atoms, mc, seq.n_motions, params, np.random.default_rng(seed))
    D, Z = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    np.testing.assert_allclose(co.epipolar_distance, D, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(co.affinity, Z, rtol=1e-6, atol=1e-9)
    # the votes mean something: on average, models of one motion vote higher than models
    # of two (not pair by pair: six features per model leave the 8-point fit weak)
    motion = np.array([seq.labels[m[0]] for m in members])
    same = motion[:, None] == motion[None, :]
    off = ~np.eye(len(members), dtype=bool)
    assert Z[same & off].mean() > 10 * Z[~same].mean()


@pytest.mark.parametrize("seed", [0, 2])
def test_the_joint_merge_reads_the_pairwise_votes_only_when_asked_and_they_are_the_papers(
        seed, monkeypatch):
    """The default (joint) merge does not use the paper's pairwise votes: their samples are
    drawn (the generator's stream must not depend on whether they are read) but fitted only
    when read; then they equal the direct computation, as the paper preset's do."""
    import laav.coarse as coarse_module

    seq = synthetic.make_sequence(n_objects=1, n_frames=12, n_points=240, noise=0.5, rng=seed)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(seed))
    fits = []
    real = coarse_module._sample_fits
    monkeypatch.setattr(coarse_module, "_sample_fits", lambda *a: fits.append(1) or real(*a))
    params = LaavParams(coarse_frames=3, coarse_samples=2)
    assert params.merge_for(True) == "joint"
    rng = np.random.default_rng(seed)
    co = merge_models(seq, atoms, mc, seq.n_motions, params, rng)
    after = rng.bit_generator.state
    assert co.method == "joint" and fits == []  # decided without them
    D, Z = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    np.testing.assert_allclose(co.epipolar_distance, D, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(co.pairwise_vote, Z, rtol=1e-6, atol=1e-9)
    assert len(fits) == 1  # once, for all three
    assert co.vote_samples.distance.shape == (len(members), len(members)) and len(fits) == 1
    # the draws were made when the merge ran: reading them later moved no generator
    rng2 = np.random.default_rng(seed)
    merge_models(seq, atoms, mc, seq.n_motions, params, rng2).pairwise_vote  # noqa: B018
    assert rng2.bit_generator.state == after


def test_default_blend_is_pairwise_votes_plus_coassociation():
    """The epipolar merge's Z is (1 - w) co-association of its pooled-voting trials + w
    pairwise votes: with the pairwise part computed directly, what is left must be a co-association,
    i.e. a multiple of 1 / pooled_trials in [0, 1] on every pair."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=12, n_points=240, noise=0.5, rng=4)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(4))
    params = LaavParams(coarse_merge="epipolar", coarse_frames=3, coarse_samples=2)
    assert 0 < params.pairwise_weight < 1 and params.pooled_trials > 0
    co = merge_models(seq, atoms, mc, seq.n_motions, params, np.random.default_rng(4))
    _, pair = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    w = params.pairwise_weight
    coassoc = (co.affinity - w * pair) / (1.0 - w)
    off = ~np.eye(len(members), dtype=bool)
    counts = coassoc[off] * params.pooled_trials
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    assert np.all((counts > -1e-6) & (counts < params.pooled_trials + 1e-6))


def test_motion_term_matches_direct_computation():
    seq = synthetic.make_sequence(n_objects=1, n_frames=10, n_points=200, noise=0.5, rng=2)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(2))
    params = LaavParams.paper(coarse_frames=2, coarse_samples=1, motion_weight=0.7)
    co = merge_models(seq, atoms, mc, seq.n_motions, params, np.random.default_rng(2))
    M = direct_motion_distance(seq.points, members)
    np.testing.assert_allclose(co.motion_distance, M, rtol=1e-9, atol=1e-12)
    _, pair = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    Z = pair * np.exp(-0.7 * M)
    np.fill_diagonal(Z, 1.0)
    np.testing.assert_allclose(co.affinity, Z, rtol=1e-6, atol=1e-9)


def test_direct_computation_detects_a_wrong_vote(monkeypatch):
    """The comparison above can fail: a stage whose distance were in px instead of px^2
    (a square root too many) no longer matches."""
    import laav.coarse as coarse_mod

    seq = synthetic.make_sequence(n_objects=1, n_frames=12, n_points=240, noise=0.5, rng=0)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(0))
    params = LaavParams.paper(coarse_frames=3, coarse_samples=2)
    right = coarse_mod.sampson_distance
    monkeypatch.setattr(coarse_mod, "sampson_distance", lambda *a: np.sqrt(right(*a)))
    co = merge_models(seq, atoms, mc, seq.n_motions, params, np.random.default_rng(0))
    D, _ = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    assert not np.allclose(co.epipolar_distance, D, rtol=1e-6, atol=1e-9)


def test_vote_samples_are_fits_the_vote_used():
    """``Coarse.vote_samples`` (what the explorer's epipolar panel draws) is a sample the
    vote was built from: refitting its features on its frames gives its F and its
    distance, its frames are among the stage's frame pairs, its first half is model j's."""
    from laav import build_atoms

    seq = synthetic.make_sequence(n_objects=1, n_frames=15, n_points=240, noise=0.5, rng=6)
    atoms = build_atoms(seq, LaavParams(), np.random.default_rng(0))
    n = 4
    fine = np.arange(atoms.n_atoms, dtype=np.int64) % n
    mc = Multicut(atom_labels=fine, n_models=n, multicut_labels=fine, n_segments=n,
                  cut=np.zeros(0, bool), objective=0.0, contractions=np.zeros((0, 2), np.int64),
                  contraction_costs=np.zeros(0))
    co = merge_models(seq, atoms, mc, 2, LaavParams(), np.random.default_rng(3))
    vs = co.vote_samples
    owner_model = np.full(seq.n_points, -1)
    for i, m in enumerate(atoms.members):
        owner_model[m] = fine[i]
    pairs = {tuple(p) for p in co.frame_pairs.tolist()}
    for j in range(n):
        assert np.all(vs.frames[j, j] == -1) and not np.any(vs.fundamental[j, j])
        for k in range(n):
            if j == k:
                continue
            fl, fr = vs.frames[j, k]
            assert (fl, fr) in pairs
            g = vs.points[j, k]
            half = g.size // 2
            F = direct_fundamental(seq.points[fl, g], seq.points[fr, g])
            Fs = vs.fundamental[j, k] / np.linalg.norm(vs.fundamental[j, k])
            assert min(np.abs(F - Fs).max(), np.abs(F + Fs).max()) < 1e-6
            d = direct_sampson(F, seq.points[fl, g], seq.points[fr, g])
            assert vs.distance[j, k] == pytest.approx(max(d[:half].mean(), d[half:].mean()),
                                                      rel=1e-6)
            # the features come from atoms of the two models (a shared ring feature may
            # be owned by another model's atom: compare by atom membership)
            in_j = [any(f in atoms.members[a] for a in np.flatnonzero(fine == j)) for f in g[:half]]
            in_k = [any(f in atoms.members[a] for a in np.flatnonzero(fine == k)) for f in g[half:]]
            assert all(in_j) and all(in_k)
            assert vs.distance[j, k] == vs.distance[k, j]


def test_terms_of_z_are_returned_apart():
    """``Coarse.pairwise_vote`` is the directly computed pairwise vote and ``affinity`` is
    its blend with ``Coarse.coassociation`` (the epipolar merge, as on incomplete tracks)."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=12, n_points=240, noise=0.5, rng=4)
    atoms, mc, members = one_atom_models(seq, 2, np.random.default_rng(4))
    params = LaavParams(coarse_merge="epipolar", coarse_frames=3, coarse_samples=2)
    co = merge_models(seq, atoms, mc, seq.n_motions, params, np.random.default_rng(4))
    _, pair = direct_pair_votes(seq.points, members, co.frame_pairs, params.lam)
    np.testing.assert_allclose(co.pairwise_vote, pair, rtol=1e-6, atol=1e-9)
    w = params.pairwise_weight
    Z = (1 - w) * co.coassociation + w * co.pairwise_vote
    np.fill_diagonal(Z, 1.0)
    np.testing.assert_allclose(co.affinity, Z, rtol=1e-12)


def test_the_joint_merges_fit_floor_unit_scales_with_the_coordinates_not_lambda():
    """The joint merge's fits take their floor in a unit of the coordinates (so a λ move
    reuses them): a power of two, 1.0 for a 128-256 px spread, scaled exactly with the
    coordinates by a power of two, unmoved by translation."""
    from laav.coarse import _coordinate_unit2

    rng = np.random.default_rng(0)
    x = rng.normal(scale=150.0, size=(10, 50, 2)) + 320.0
    u = _coordinate_unit2(x)
    assert u == 1.0
    for k in (-10, -3, 3, 13):
        assert _coordinate_unit2(x * 2.0 ** k) == u * 4.0 ** k
    assert _coordinate_unit2(x + 1e4) == u
