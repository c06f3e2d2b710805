"""Label refinement after voting (laav.refine): the joint subspace + epipolar reassignment."""

from __future__ import annotations

import numpy as np
import pytest

from laav import LaavParams, load_sequence, misclassification_rate, random_voting, segment
from laav.refine import reassign_labels, subspace_residuals

synthetic = pytest.importorskip("laav.synthetic")


@pytest.fixture(scope="module")
def three_motions():
    return synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=3)


def _flip(labels, C, share, seed):
    rng = np.random.default_rng(seed)
    bad = labels.copy()
    flip = rng.choice(labels.size, int(share * labels.size), replace=False)
    bad[flip] = (bad[flip] + rng.integers(1, C, flip.size)) % C
    return bad, flip


def test_reassign_keeps_the_truth(three_motions):
    seq = three_motions
    lab, moved = reassign_labels(seq.points, seq.labels, seq.n_motions)
    assert moved == 0 and np.array_equal(lab, seq.labels)


@pytest.mark.parametrize("share", [0.1, 0.3])
def test_reassign_repairs_scattered_wrong_labels(three_motions, share):
    seq = three_motions
    C = seq.n_motions
    bad, flip = _flip(seq.labels, C, share, seed=1)
    lab, moved = reassign_labels(seq.points, bad, C)
    assert misclassification_rate(seq.labels, lab) < 0.01
    assert moved == int((lab != bad).sum()) >= 0.9 * flip.size
    assert set(np.unique(lab)) == set(range(C))  # the names are kept, not permuted


def test_reassign_leaves_labels_it_cannot_fit(three_motions):
    seq = three_motions
    tiny = np.zeros(seq.n_points, dtype=np.int64)
    tiny[:4] = 1  # motion 1 has 4 points: no rank-4 subspace (needs > 5)
    lab, moved = reassign_labels(seq.points, tiny, 2)
    assert moved == 0 and np.array_equal(lab, tiny)
    assert subspace_residuals(seq.points, tiny, 2) is None
    one, moved = reassign_labels(seq.points, np.zeros(seq.n_points, np.int64), 1)
    assert moved == 0 and (one == 0).all()


def test_subspace_residuals_are_small_for_own_motion_only(three_motions):
    seq = three_motions
    R = subspace_residuals(seq.points, seq.labels, seq.n_motions)
    assert R.shape == (seq.n_motions, seq.n_points)
    own = R[seq.labels, np.arange(seq.n_points)]
    other = np.where(np.arange(seq.n_motions)[:, None] == seq.labels, np.inf, R).min(0)
    assert np.median(own) < 0.05 * np.median(other)


def test_voting_reports_the_reassignment(three_motions):
    seq = three_motions
    C = seq.n_motions
    bad, _ = _flip(seq.labels, C, 0.3, seed=2)
    # one iteration of voting from a poor start cannot fix it; the reassignment does
    p = LaavParams(rv_max_iter=1, rv_select="none", rv_refine=False)
    off = random_voting(seq, C, p.replace(rv_reassign=False), seed=0, init_labels=bad)
    on = random_voting(seq, C, p, seed=0, init_labels=bad)
    assert off.reassigned == 0 and on.reassigned > 0
    assert misclassification_rate(seq.labels, on.labels) < misclassification_rate(seq.labels, off.labels)
    assert misclassification_rate(seq.labels, on.labels) < 0.01


# LAAV seed 0 without / with the reassignment, measured 2026-11-29 (%): sequences where
# voting alone leaves the same points wrong at every seed (seeds 1 and 2 give the same
# pairs on the first three, and 3.41 / 0.97, 4.38 / 0.97 on 2RT3RCR_g23)
HOPKINS_CASES = {"2RT3RCT_B_g12": (2.27, 0.0), "arm": (2.60, 0.0), "2RT3RCR_g23": (4.38, 1.22),
                 "cars10_g23": (10.06, 4.40)}


@pytest.mark.hopkins
@pytest.mark.parametrize("name", sorted(HOPKINS_CASES))
def test_reassignment_repairs_laav_on_hopkins(hopkins_root, name):
    seq = load_sequence(hopkins_root / name)
    C = seq.n_motions
    # the reassignment's own effect: the descent on the joint score after it (the default
    # since 2026-12-02) mends some of the same points, so it is off in both runs
    off = segment(seq, C, LaavParams(rv_reassign=False, rv_descent=False), seed=0)
    on = segment(seq, C, LaavParams(rv_descent=False), seed=0)
    e_off = misclassification_rate(seq.labels, off.labels)
    e_on = misclassification_rate(seq.labels, on.labels)
    assert on.voting.reassigned > 0 and off.voting.reassigned == 0
    assert e_on <= 0.5 * e_off, (e_on, e_off)
    assert e_on <= HOPKINS_CASES[name][1] / 100 + 0.01, e_on


@pytest.mark.parametrize("bad_value", [1, "yes", None])
def test_reassign_flag_is_validated(bad_value):
    with pytest.raises(ValueError, match="rv_reassign must be True or False"):
        LaavParams(rv_reassign=bad_value)


def test_assign_jointly_places_points_by_the_labelled_ones(three_motions):
    from laav.refine import assign_jointly

    seq = three_motions
    P, C = seq.n_points, seq.n_motions
    targets = np.arange(1, P, 2)
    known = seq.labels.copy()
    known[targets] = -1
    got = assign_jointly(seq.points, known, C, targets)
    assert (got == seq.labels[targets]).mean() > 0.99
    # it follows the labels it is given (an earlier stage's error is not repaired):
    # with two motions' names swapped on the labelled points, their targets swap too
    swapped = np.where(known == 0, 1, np.where(known == 1, 0, known))
    got2 = assign_jointly(seq.points, swapped, C, targets)
    assert (got2 == np.where(got == 0, 1, np.where(got == 1, 0, got))).mean() > 0.99


def test_assign_jointly_on_incomplete_tracks(three_motions):
    from laav._visibility import filled
    from laav.refine import assign_jointly

    seq = synthetic.occlude(three_motions, 0.4, rng=0)
    P, C = seq.n_points, seq.n_motions
    targets = np.arange(1, P, 2)
    known = seq.labels.copy()
    known[targets] = -1
    pts = filled(seq.points, seq.visible)
    got = assign_jointly(pts, known, C, targets, visible=seq.visible,
                         pairs=np.array([[0, seq.n_frames - 1]]))
    assert (got >= 0).mean() > 0.95  # points hidden in that pair go by their subspaces
    ok = got >= 0
    assert (got[ok] == seq.labels[targets][ok]).mean() > 0.97


def test_a_fit_memo_gives_the_same_numbers_and_fits_each_motion_once(three_motions, monkeypatch):
    """``fits`` (:func:`laav.refine.fit_memo`): a motion whose members were fitted before,
    on the same pairs and unit, is read back, not fitted again; every number is the one a
    fresh fit gives. Two labellings that differ in one motion share the other two fits."""
    import laav.refine as R

    seq = three_motions
    pts, lab = seq.points, np.asarray(seq.labels)
    other = lab.copy()
    other[np.flatnonzero(lab == 2)[:5]] = 1  # motions 1 and 2 differ, motion 0 does not
    pairs = R.frame_pairs(pts.shape[0], 12)
    calls = []
    real = R.pair_distances
    monkeypatch.setattr(R, "pair_distances", lambda *a: calls.append(1) or real(*a))
    fits = R.fit_memo(pts)
    eighs = []  # the subspace fits' eigenvector calls
    real_top = R.top_eigenvectors
    monkeypatch.setattr(R, "top_eigenvectors", lambda *a: eighs.append(1) or real_top(*a))
    for labels in (lab, other):
        fresh = R.motion_distances(pts, labels, 3, pairs)
        n = len(calls)
        memo = R.motion_distances(pts, labels, 3, pairs, fits=fits)
        np.testing.assert_array_equal(memo, fresh)
        assert len(calls) - n == (3 if labels is lab else 2)  # motion 0 read back the 2nd time
        np.testing.assert_array_equal(R.subspace_residuals(pts, labels, 3, fits=fits),
                                      R.subspace_residuals(pts, labels, 3))
    e = len(eighs)
    R.subspace_residuals(pts, other, 3, fits=fits)  # every motion read back: no fit
    assert len(eighs) == e
    R.subspace_residuals(pts, other, 3, rank=5, fits=fits)  # another rank: fitted again
    assert len(eighs) > e
    n = len(calls)
    np.testing.assert_array_equal(R.motion_distances(pts, other, 3, pairs, fits=fits), fresh)
    assert len(calls) == n  # all three read back
    # another set of pairs is another fit, not a hit
    R.motion_distances(pts, other, 3, R.frame_pairs(pts.shape[0], 8), fits=fits)
    assert len(calls) == n + 3
    R.motion_distances(pts, other, 3, pairs, unit2=4.0, fits=fits)  # another unit: no hit
    assert len(calls) == n + 6
    assert sum(k[0] == "subspace" for k in fits) == 8
    # a memo is for the points it was made with
    with pytest.raises(ValueError, match="fit_memo"):
        R.motion_distances(pts.copy(), other, 3, pairs, fits=fits)


def _thin_late_motion():
    """Noise-free scene: motion 1 is seen in frames 20-29 through 2 of its members only (too
    few to determine its rank-4 basis there: 2 x 4 are needed); five more of its points, the
    targets, are seen in frames 15-29, and five others (the late ones) in frames 20-29 only."""
    seq = synthetic.make_sequence(n_objects=2, n_frames=30, n_points=300, rng=0)
    lab = np.asarray(seq.labels)
    vis = np.ones((seq.n_frames, seq.n_points), bool)
    g1 = np.flatnonzero(lab == 1)
    targets, late = g1[:5], g1[5:10]
    vis[20:, g1[12:]] = False  # g1[10:12]: the 2 members seen late
    vis[:15, targets] = False
    vis[:20, late] = False
    labels = lab.copy()
    labels[targets] = labels[late] = -1
    return seq.points, lab, labels, vis, targets, late


def test_points_are_judged_where_every_motion_is_determined():
    """``shared_frames``: the targets are judged on frames 15-19, where every motion's basis
    is determined, and go to their own motion; judged on all their frames, motion 1's
    undetermined rows of frames 20-29 push them away. A point seen in none of the shared
    frames (the late ones) is judged on its own frames, not given residual 0 everywhere."""
    from laav.refine import assign_by_subspace, assign_jointly, subspace_residuals

    pts, lab, labels, vis, targets, late = _thin_late_motion()
    R = subspace_residuals(pts, labels, 3, visible=vis, shared_frames=True)
    np.testing.assert_array_equal(R[:, targets].argmin(axis=0), lab[targets])
    every = subspace_residuals(pts, labels, 3, visible=vis)
    assert (every[:, targets].argmin(axis=0) != lab[targets]).sum() >= 3  # what the rule mends
    np.testing.assert_array_equal(R[:, late], every[:, late])  # no shared frame: its own ones
    assert (R[:, late].max(axis=0) > 1.0).all()
    np.testing.assert_array_equal(assign_by_subspace(pts, labels, 3, vis, targets, 4), lab[targets])
    np.testing.assert_array_equal(assign_jointly(pts, labels, 3, targets, visible=vis), lab[targets])


def test_masked_scores_compare_motions_on_shared_evidence():
    """A point that only some motions have an epipolar distance for goes by the subspaces
    (a motion without a matrix is not ruled out); a point seen in too few frames for the
    subspaces (rank / 2) goes by the epipolar distances it has, whatever rounding left in R."""
    from laav.refine import _masked_scores

    R = np.array([[5.0, 1e-9], [0.01, 3e-9], [4.0, 2e-9]])  # (C, P): point 0 fits motion 1
    D = np.array([[1.0, 1.0], [np.inf, np.inf], [50.0, 50.0]])  # motion 1: no matrix
    s = _masked_scores(R, D, 1e-4, 0.5, informative=np.array([True, False]))
    assert s[:, 0].argmin() == 1  # the subspaces, not log(inf), decide
    assert s[:, 1].argmin() == 0  # too few frames: the finite epipolar distances decide
    assert np.isinf(s[1, 1])
    D2 = np.full_like(D, 2.0)  # every motion has a distance: the joint rule
    both = _masked_scores(R, D2, 1e-4, 0.5, informative=np.array([True, True]))
    np.testing.assert_allclose(both, np.log(R + 1e-4) + 0.5 * np.log(D2 + 1e-4))


def test_top_eigenvectors_span_what_every_eigenvector_gives():
    """:func:`laav.refine.top_eigenvectors`: the eigenvectors of the k largest eigenvalues,
    in increasing order, as ``np.linalg.eigh``'s last k columns (to rounding and signs):
    the same projector, orthonormal columns; k above the size gives them all."""
    from laav.refine import top_eigenvectors

    rng = np.random.default_rng(3)
    for D, k in ((60, 4), (9, 4), (4, 4), (3, 4), (30, 1)):
        X = rng.normal(size=(D, 5)) @ rng.normal(size=(5, 200)) * 30 + rng.normal(size=(D, 200))
        M = X @ X.T
        U = top_eigenvectors(M, k)
        want = np.linalg.eigh(M)[1][:, -k:]
        assert U.shape == want.shape == (D, min(k, D))
        np.testing.assert_allclose(U.T @ U, np.eye(U.shape[1]), atol=1e-12)
        np.testing.assert_allclose(U @ U.T, want @ want.T, atol=1e-10)
        # each column an eigenvector of its eigenvalue, in increasing order
        lam = np.einsum("ij,ij->j", U, M @ U)
        assert np.all(np.diff(lam) >= 0)
        np.testing.assert_allclose(M @ U, U * lam, atol=1e-8 * lam.max())


def test_top_eigenvectors_refuses_k_0_and_falls_back_to_every_eigenvector(monkeypatch):
    """k < 1 is an error (np.linalg.eigh(M)[1][:, -0:] gave every column); should LAPACK's
    call fail (info != 0), every eigenvector is computed instead: the same subspace."""
    from scipy.linalg import lapack

    from laav.refine import top_eigenvectors

    M = np.diag([1.0, 5.0, 2.0, 9.0])
    with pytest.raises(ValueError, match="k = 0"):
        top_eigenvectors(M, 0)
    want = top_eigenvectors(M, 2)
    np.testing.assert_allclose(np.abs(want), np.eye(4)[:, [1, 3]], atol=1e-12)
    real = lapack.dsyevr
    monkeypatch.setattr(lapack, "dsyevr", lambda *a, **k: (*real(*a, **k)[:4], 1))
    np.testing.assert_allclose(np.abs(top_eigenvectors(M, 2)), np.abs(want), atol=1e-12)


def test_trajectory_matrix_is_the_tracks_from_their_bounding_boxs_corner():
    """Columns are trajectories (rows x_0, y_0, x_1, ...) less the smallest x and the
    smallest y over every frame; on incomplete tracks the corner of the visible entries,
    hidden entries 0."""
    from laav.refine import _trajectory_matrix_masked, trajectory_matrix

    rng = np.random.default_rng(4)
    pts = rng.uniform(-50.0, 700.0, (7, 40, 2))
    W = trajectory_matrix(pts)
    corner = pts.min(axis=(0, 1))
    assert W.shape == (14, 40)
    np.testing.assert_array_equal(W[0::2], pts[..., 0] - corner[0])
    np.testing.assert_array_equal(W[1::2], pts[..., 1] - corner[1])
    vis = rng.random((7, 40)) < 0.6
    pts_hidden = np.where(vis[..., None], pts, 1e6)  # hidden entries are never read
    Wm = _trajectory_matrix_masked(pts_hidden, vis)
    seen = np.where(vis[..., None], pts, np.inf).min(axis=(0, 1))
    np.testing.assert_array_equal(Wm[0::2], np.where(vis, pts[..., 0] - seen[0], 0.0))
    np.testing.assert_array_equal(Wm[1::2], np.where(vis, pts[..., 1] - seen[1], 0.0))
