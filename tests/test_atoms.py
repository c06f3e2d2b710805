"""Atom construction (laav.atoms.build_atoms) on clean rigid synthetic scenes."""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, build_atoms
from laav.atoms import trajectory_distances

synthetic = pytest.importorskip("laav.synthetic")

# (n_objects, scene seed): 2- and 3-motion clean rigid scenes, 20 frames, 300 points
SCENES = [(1, 0), (1, 1), (1, 2), (1, 3), (2, 0), (2, 1), (2, 2), (2, 3)]
_cache: dict = {}


def scene(n_objects, seed, n_points=300, n_frames=20):
    key = (n_objects, seed, n_points, n_frames)
    if key not in _cache:
        _cache[key] = synthetic.make_sequence(n_objects=n_objects, n_frames=n_frames,
                                              n_points=n_points, rng=seed)
    return _cache[key]


def atoms_of(seq, seed=0, params=None):
    return build_atoms(seq, params or LaavParams(), np.random.default_rng(seed))


def leverage(points0, members):
    X = np.column_stack([points0[members], np.ones(members.size)])
    return np.diag(X @ np.linalg.pinv(X))


@pytest.mark.parametrize("n_objects, seed", SCENES)
def test_no_atom_mixes_two_motions(n_objects, seed):
    seq = scene(n_objects, seed)
    atoms = atoms_of(seq)
    mixed = []
    for i, m in enumerate(atoms.members):
        if np.unique(seq.labels[m]).size > 1:
            lev = leverage(seq.points[0], m)
            mixed.append((i, seq.labels[m].tolist(), np.round(lev, 3).tolist()))
    # Every mixed atom seen so far held members of another motion whose leverage in the
    # affine fit was >= 0.92 (the other members nearly collinear, or few): the fit passes
    # through such a member whatever its motion, so its small residual proves nothing.
    assert not mixed, f"{len(mixed)} of {atoms.n_atoms} atoms mix motions (atom, labels, leverage): {mixed}"


@pytest.mark.parametrize("n_objects, seed", SCENES[::2])
def test_atom_structure(n_objects, seed):
    seq = scene(n_objects, seed)
    p = LaavParams()
    atoms = atoms_of(seq, params=p)
    D = trajectory_distances(seq.points)
    P = seq.n_points
    assert atoms.n_atoms > 0
    assert atoms.seeds.shape == (atoms.n_atoms,)
    assert atoms.affines.shape == (atoms.n_atoms, seq.n_frames, 2, 3)
    assert atoms.owner.shape == (P,)
    member_of = [set() for _ in range(P)]
    for i, m in enumerate(atoms.members):
        s = atoms.seeds[i]
        assert m.dtype == np.int64 and np.all(np.diff(m) > 0), "members not sorted/unique"
        assert m.size >= p.atom_min_size
        assert s in m, "the seed is not a member of its atom"
        assert np.all(D[s, m] <= p.r2 + 1e-9), "member beyond r2 of the seed"
        # members within r1 of the seed are owned by this atom
        inner = m[D[s, m] <= p.r1]
        assert np.all(atoms.owner[inner] == i)
        assert atoms.residuals[i].shape == m.shape
        for j in m:
            member_of[j].add(i)
    for j in range(P):
        o = atoms.owner[j]
        if o >= 0:
            assert o in member_of[j], "owner does not hold the feature"
            assert D[atoms.seeds[o], j] <= p.r1 + 1e-9, "owned feature beyond r1"
            # paper: features within R1 "are excluded from being joined to other atoms in
            # the followed iterations" -- no LATER atom holds an owned feature (an earlier
            # atom may hold it in its ring r1..r2)
            assert max(member_of[j]) == o, f"feature {j} owned by {o} is in later atom(s)"
    # seeds are never owned by an earlier atom, and are all distinct
    assert np.unique(atoms.seeds).size == atoms.n_atoms
    for i, s in enumerate(atoms.seeds):
        assert atoms.owner[s] in (-1, i)
    # unassigned = features in no atom
    none = np.array([len(ms) == 0 for ms in member_of])
    assert np.array_equal(atoms.unassigned, np.flatnonzero(none))
    assert atoms.coverage == pytest.approx(1 - none.sum() / P)
    assert np.array_equal(atoms.membership().sum(0) > 0, ~none)


@pytest.mark.parametrize("n_objects, seed", SCENES)
def test_members_are_inliers_of_their_atoms_model(n_objects, seed):
    """A member is an inlier: RMS residual under its atom's (final) affine model below
    ``affine_threshold``. Measured: 2 of 588 atoms (scenes 2-motion seed 2, 3-motion seed 2)
    keep a member at 1.56 / 1.77 px, because the consensus is refitted at most twice and the
    stored model is a further refit on the final members."""
    seq = scene(n_objects, seed)
    p = LaavParams()
    atoms = atoms_of(seq, params=p)
    over = [(i, float(r.max())) for i, r in enumerate(atoms.residuals)
            if np.any(r >= p.affine_threshold)]
    assert not over, f"atoms with members over {p.affine_threshold} px: {over}"


@pytest.mark.parametrize("n_objects, seed", SCENES[::2])
def test_affines_fit_members(n_objects, seed):
    seq = scene(n_objects, seed)
    atoms = atoms_of(seq)
    for i, m in enumerate(atoms.members):
        A = atoms.affines[i]
        pred = seq.points[0, m] @ np.swapaxes(A[:, :, :2], -1, -2) + A[:, None, :, 2]
        rms = np.sqrt(((pred - seq.points[:, m]) ** 2).sum(-1).mean(0))
        assert np.allclose(rms, atoms.residuals[i], atol=1e-6)
        # frame 0 maps (nearly) to itself
        assert np.allclose(A[0], [[1, 0, 0], [0, 1, 0]], atol=1e-6)


@pytest.mark.parametrize("n_objects", [1, 2])
def test_coverage_high_on_clean_dense_scenes(n_objects):
    """Coverage depends on point density: measured 0.90-0.96 at 500 points over seeds 0-2
    (0.69-0.85 at 200-300 points, where more features have < 3 neighbours within r2)."""
    for seed in range(2):
        seq = scene(n_objects, seed, n_points=500)
        atoms = atoms_of(seq)
        assert atoms.coverage > 0.8, f"coverage {atoms.coverage:.2f} (scene seed {seed})"


def test_deterministic_for_a_seed():
    seq = scene(2, 0)
    a = atoms_of(seq, seed=5)
    b = atoms_of(seq, seed=5)
    assert len(a.members) == len(b.members)
    assert all(np.array_equal(x, y) for x, y in zip(a.members, b.members))
    assert np.array_equal(a.seeds, b.seeds) and np.array_equal(a.owner, b.owner)
    assert np.array_equal(a.affines, b.affines)
    c = atoms_of(seq, seed=6)  # a different seed may (and here does) differ
    assert not np.array_equal(a.seeds[: c.n_atoms], c.seeds[: a.n_atoms])


def test_precomputed_distances_give_the_same_atoms():
    seq = scene(1, 1)
    D = trajectory_distances(seq.points)
    a = build_atoms(seq, LaavParams(), np.random.default_rng(0))
    b = build_atoms(seq.points, LaavParams(), np.random.default_rng(0), distances=D)
    assert all(np.array_equal(x, y) for x, y in zip(a.members, b.members))
    assert np.array_equal(a.owner, b.owner)


@pytest.mark.parametrize("offset", [-300.0, 1000.0, 5000.0])
def test_translation_invariant(offset):
    """Shifting every coordinate changes no distance and no affine residual, so the atoms
    must not change. (Regressions: a collinearity test in absolute pixel units formed no
    atom at all at +1000 px; a biased fit_affine changed memberships at +1000 px.)"""
    seq = scene(2, 1)
    a = atoms_of(seq)
    b = atoms_of(seq.points + offset)
    assert a.n_atoms == b.n_atoms
    assert all(np.array_equal(x, y) for x, y in zip(a.members, b.members))
    assert np.array_equal(a.owner, b.owner)


def test_trajectory_distances():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 100, (9, 12, 2))
    D = trajectory_distances(pts)
    frames = np.unique(np.round(np.linspace(0, 8, 6)).astype(int))
    ref = np.max([np.linalg.norm(pts[f][:, None] - pts[f][None], axis=-1) for f in frames], 0)
    assert np.allclose(D, ref, atol=1e-6)
    assert np.allclose(D, D.T) and np.allclose(np.diag(D), 0, atol=1e-6)


def test_no_atoms_with_tiny_radii():
    seq = scene(1, 0)
    atoms = atoms_of(seq, params=LaavParams(r1=0.1, r2=0.2))
    assert atoms.n_atoms == 0
    assert atoms.coverage == 0.0
    assert np.array_equal(atoms.unassigned, np.arange(seq.n_points))
    assert np.all(atoms.owner == -1)
    assert atoms.affines.shape == (0, seq.n_frames, 2, 3)
    assert atoms.centers(seq.points).shape == (seq.n_frames, 0, 2)


def test_paper_atoms_judge_features_on_one_frame_pair():
    """atom_frames="pair": each atom's RANSAC sees one random frame pair, so a feature that
    moves with the atom on that pair but not elsewhere can join it; "all" never lets it."""
    rng = np.random.default_rng(0)
    F = 12
    g = np.stack(np.meshgrid(np.arange(6) * 6.0, np.arange(6) * 6.0), -1).reshape(-1, 2) + 100
    shift = np.cumsum(rng.normal(0, 2.0, (F, 2)), axis=0)
    pts = np.repeat(g[None], F, axis=0) + shift[:, None]
    # point 0 follows the grid except in one frame, where it jumps 15 px
    pts[F // 2, 0] += 15.0
    p_all = LaavParams(r1=8.0, r2=16.0)
    p_pair = LaavParams.paper(r1=8.0, r2=16.0)
    assert p_pair.atom_frames == "pair" and p_all.atom_frames == "all"
    in_all = [0 in m for m in build_atoms(pts, p_all, np.random.default_rng(1)).members]
    assert not any(in_all)
    joined = [any(0 in m for m in build_atoms(pts, p_pair, np.random.default_rng(s)).members)
              for s in range(10)]
    assert any(joined)  # on pairs without the jumping frame it fits the grid's affine map


def test_hypothesis_residuals_equal_the_homogeneous_solve():
    """RANSAC's residuals, written in the seed's frame with a closed-form 2 x 2 inverse, are
    those of the affine map solved from the three samples' homogeneous 3 x 3 system (the
    textbook way), for every hypothesis and candidate."""
    from laav.atoms import _hypothesis_residuals

    rng = np.random.default_rng(0)
    n, F = 25, 7
    src = rng.uniform(200, 400, (n, 2))  # image coordinates far from the origin
    Y = rng.uniform(0, 640, (n, 2 * F))
    seed = 4
    pairs = np.array([[0, 1], [2, 9], [24, 3], [10, 11], [5, 17]])
    got = _hypothesis_residuals(src, Y, seed, pairs)
    X = np.column_stack([src, np.ones(n)])
    samp = np.column_stack([np.full(len(pairs), seed), pairs])
    sol = np.linalg.solve(X[samp], Y[samp])  # (B, 3, 2F)
    expect = X @ sol - Y
    assert got.shape == (len(pairs), n, 2 * F)
    assert np.abs(got - expect).max() < 1e-8 * np.abs(Y).max()
    # the map passes through its three samples
    for b, (i, j) in enumerate(pairs):
        assert np.abs(got[b, [seed, i, j]]).max() < 1e-9 * np.abs(Y).max()
