"""Two-view geometry: normalised 8-point F, Sampson distance, affine fits (laav.geometry)."""

from __future__ import annotations

import numpy as np
import pytest

from laav.geometry import (
    apply_affine,
    epipolar_lines,
    fit_affine,
    fit_fundamental,
    hartley_normalization,
    sampson_distance,
)


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def two_view_scene(n=40, seed=0):
    """Noise-free pixel correspondences of a rigid 3D point cloud seen by two pinhole cameras.

    Returns x1, x2 (n, 2) and the true fundamental matrix (unit Frobenius norm).
    """
    rng = np.random.default_rng(seed)
    X = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-1.5, 1.5, n), rng.uniform(5, 10, n)])
    K = np.array([[700.0, 0, 320], [0, 700.0, 240], [0, 0, 1]])
    R = _rotation(rng.normal(size=3), rng.uniform(0.05, 0.15))
    t = np.array([rng.uniform(0.5, 1.0), rng.uniform(-0.2, 0.2), rng.uniform(-0.3, 0.3)])

    def project(P):
        h = P @ K.T
        return h[:, :2] / h[:, 2:]

    x1 = project(X)
    x2 = project(X @ R.T + t)
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    Kinv = np.linalg.inv(K)
    F = Kinv.T @ tx @ R @ Kinv
    return x1, x2, F / np.linalg.norm(F)


def _same_up_to_scale(A, B):
    A = A / np.linalg.norm(A)
    B = B / np.linalg.norm(B)
    return min(np.abs(A - B).max(), np.abs(A + B).max())


@pytest.mark.parametrize("seed", range(5))
def test_eight_point_on_exact_rigid_correspondences(seed):
    x1, x2, F_true = two_view_scene(40, seed)
    F = fit_fundamental(x1, x2)
    assert F.shape == (3, 3)
    assert 0.5 <= np.linalg.norm(F) < 1.0  # scaled by a power of two (exact), see fit_fundamental
    d = sampson_distance(F, x1, x2)
    assert d.max() < 1e-6, f"max Sampson distance {d.max():.3g} px^2"
    s = np.linalg.svd(F, compute_uv=False)
    assert s[2] < 1e-12 * s[0], f"not rank 2: singular values {s}"
    # algebraic residual of the homogeneous epipolar constraint
    h1 = np.column_stack([x1, np.ones(len(x1))])
    h2 = np.column_stack([x2, np.ones(len(x2))])
    alg = np.einsum("ni,ij,nj->n", h2, F, h1)
    assert np.abs(alg).max() < 1e-8
    assert _same_up_to_scale(F, F_true) < 1e-6


@pytest.mark.parametrize("seed", range(3))
def test_eight_point_agrees_with_opencv(seed):
    cv2 = pytest.importorskip("cv2")
    x1, x2, _ = two_view_scene(24, seed)
    Fcv, _ = cv2.findFundamentalMat(x1, x2, cv2.FM_8POINT)
    assert Fcv is not None and Fcv.shape == (3, 3)
    F = fit_fundamental(x1, x2)
    # OpenCV scales F so that F[2, 2] = 1 and loses a few digits doing so (its F is
    # ~3e-5 off the true F for seed 1 while ours is 1e-12 off), hence the tolerance.
    assert _same_up_to_scale(F, Fcv) < 1e-4
    assert sampson_distance(Fcv, x1, x2).max() < 1e-6
    assert sampson_distance(F, x1, x2).max() < 1e-6


def test_sampson_distance_matches_hand_computation():
    rng = np.random.default_rng(3)
    F = rng.normal(size=(3, 3))
    x1 = rng.uniform(0, 640, (7, 2))
    x2 = rng.uniform(0, 480, (7, 2))
    d = sampson_distance(F, x1, x2)
    for k in range(7):
        a = np.array([x1[k, 0], x1[k, 1], 1.0])
        b = np.array([x2[k, 0], x2[k, 1], 1.0])
        Fa = F @ a
        Ftb = F.T @ b
        expect = (b @ F @ a) ** 2 / (Fa[0] ** 2 + Fa[1] ** 2 + Ftb[0] ** 2 + Ftb[1] ** 2)
        assert d[k] == pytest.approx(expect, rel=1e-10)
    # a point exactly on its epipolar line has distance 0; moving it by delta px
    # perpendicular to the line gives about delta^2 / 2 (two-sided first-order distance)
    x1, x2, Ft = two_view_scene(10, 1)
    assert sampson_distance(Ft, x1, x2).max() < 1e-8
    line = epipolar_lines(Ft, x1)
    moved = x2 + 0.5 * line[:, :2]
    d = sampson_distance(Ft, x1, moved)
    assert np.all(d > 0.02) and np.all(d < 0.25 + 1e-9)


def test_epipolar_lines_are_unit_and_contain_the_match():
    x1, x2, F = two_view_scene(15, 2)
    lines = epipolar_lines(F, x1)
    assert np.allclose(np.hypot(lines[:, 0], lines[:, 1]), 1.0)
    dist = np.abs(lines[:, 0] * x2[:, 0] + lines[:, 1] * x2[:, 1] + lines[:, 2])
    assert dist.max() < 1e-6


def test_fit_fundamental_batched_equals_looped():
    rng = np.random.default_rng(7)
    x1 = rng.uniform(0, 640, (3, 4, 12, 2))
    x2 = x1 + rng.normal(0, 5, x1.shape)
    w = rng.uniform(0.1, 2.0, x1.shape[:-1])
    Fb = fit_fundamental(x1, x2)
    Fw = fit_fundamental(x1, x2, w)
    db = sampson_distance(Fb, x1, x2)
    for i in range(3):
        for j in range(4):
            Fl = fit_fundamental(x1[i, j], x2[i, j])
            assert _same_up_to_scale(Fb[i, j], Fl) < 1e-9
            assert _same_up_to_scale(Fw[i, j], fit_fundamental(x1[i, j], x2[i, j], w[i, j])) < 1e-9
            assert np.allclose(db[i, j], sampson_distance(Fl, x1[i, j], x2[i, j]), rtol=1e-8)


def test_sampson_distance_broadcasts_F_against_points():
    rng = np.random.default_rng(8)
    F = rng.normal(size=(5, 3, 3))
    x1 = rng.uniform(0, 640, (30, 2))
    x2 = rng.uniform(0, 640, (30, 2))
    d = sampson_distance(F, x1[None], x2[None])
    assert d.shape == (5, 30)
    for c in range(5):
        assert np.allclose(d[c], sampson_distance(F[c], x1, x2))


def test_weights_select_the_equations():
    """Zero weights drop correspondences: F fitted on the rest is unchanged."""
    x1, x2, F_true = two_view_scene(30, 4)
    rng = np.random.default_rng(0)
    bad2 = x2.copy()
    bad2[:8] += rng.normal(0, 30, (8, 2))
    w = np.ones(30)
    w[:8] = 0.0
    F = fit_fundamental(x1, bad2, w)
    assert _same_up_to_scale(F, F_true) < 1e-6


def test_hartley_normalization():
    rng = np.random.default_rng(1)
    x = rng.uniform(100, 500, (2, 20, 2))
    T = hartley_normalization(x)
    h = np.concatenate([x, np.ones(x.shape[:-1] + (1,))], axis=-1) @ np.swapaxes(T, -1, -2)
    y = h[..., :2]
    assert np.allclose(y.mean(axis=-2), 0.0, atol=1e-12)
    assert np.allclose(np.sqrt((y ** 2).sum(-1).mean(-1)), np.sqrt(2.0))


@pytest.mark.parametrize("n", [3, 5, 20])
def test_fit_affine_recovers_a_known_map(n):
    rng = np.random.default_rng(n)
    src = rng.uniform(0, 640, (n, 2))
    A = np.concatenate([np.eye(2)[None] + rng.normal(0, 0.2, (6, 2, 2)),
                        rng.normal(0, 30, (6, 2, 1))], axis=-1)  # (F, 2, 3)
    dst = np.stack([src @ A[f, :, :2].T + A[f, :, 2] for f in range(6)])
    est = fit_affine(src, dst)
    assert est.shape == (6, 2, 3)
    assert np.allclose(est, A, atol=1e-8)
    assert np.allclose(apply_affine(est, src[None]), dst, atol=1e-6)


@pytest.mark.parametrize("offset", [0.0, 1000.0, 3840.0])
def test_fit_affine_is_least_squares_at_any_image_position(offset):
    """Regression: fit_affine solved raw-pixel normal equations with a trace-scaled ridge;
    its predictions were 0.013 px off least squares at 640-px coordinates, 4 px at +1000 px
    and 25 px at +3840 px (a 4K frame), which changed which features became atom members."""
    rng = np.random.default_rng(11)
    centre = np.array([500.0, 350.0]) + offset
    src = centre + rng.uniform(-40, 40, (9, 2))  # an atom-sized patch
    dst = np.stack([src @ (np.eye(2) + rng.normal(0, 0.05, (2, 2))).T + rng.normal(0, 20, 2)
                    for _ in range(8)]) + rng.normal(0, 1.0, (8, 9, 2))
    A = fit_affine(src, dst)
    X = np.column_stack([src, np.ones(9)])
    ref = np.stack([X @ np.linalg.lstsq(X, dst[f], rcond=None)[0] for f in range(8)])
    assert np.abs(apply_affine(A, src[None]) - ref).max() < 1e-6


def test_fit_affine_collinear_points_still_fit():
    src = np.column_stack([np.linspace(100, 140, 6), np.linspace(200, 220, 6)])
    A_true = np.array([[[1.1, 0.2, 5.0], [-0.1, 0.9, -3.0]]])
    dst = apply_affine(A_true, src[None])
    A = fit_affine(src, dst)
    assert np.all(np.isfinite(A))
    # the tiny ridge that keeps the collinear system solvable costs ~1e-5 px here
    assert np.abs(apply_affine(A, src[None]) - dst).max() < 1e-4


def test_inverse_sym3_matches_lapack_with_the_ridge():
    """The cofactor inverse of the affine fits' normal matrix equals LAPACK's inverse of the
    same ridged matrix (to rounding) on well-spread point sets, and falls back to it on
    nearly collinear ones (where cofactors would lose digits)."""
    from laav.geometry import _inverse_sym3

    rng = np.random.default_rng(3)
    for spread in (1.0, 1e-2, 1e-5, 0.0):  # from well spread to exactly collinear
        for _ in range(20):
            n = int(rng.integers(3, 40))
            t = rng.standard_normal(n)
            x = np.column_stack([t, 0.5 * t + spread * rng.standard_normal(n), np.ones(n)])
            G = x.T @ x
            ridged = G + 1e-12 * (np.trace(G) + 1.0) * np.eye(3)
            expect = np.linalg.inv(ridged)
            got = _inverse_sym3(G)
            assert np.abs(got - expect).max() <= 1e-9 * np.abs(expect).max()
            assert np.allclose(got, got.T, rtol=0, atol=1e-9 * np.abs(got).max())
