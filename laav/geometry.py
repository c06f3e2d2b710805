"""Batched two-view geometry: affine fits, normalised 8-point fundamental matrices, Sampson.

Every function works on stacks (leading batch axes) so that many hypotheses are fitted
and scored in one numpy call instead of a Python loop.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "hartley_normalization",
    "fit_fundamental",
    "FundamentalFitter",
    "sampson_distance",
    "fit_affine",
    "fit_affine_leverage",
    "fit_affine_masked",
    "apply_affine",
    "affine_residuals",
    "epipolar_lines",
]


def _centre_scale(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid ``c`` (..., 2) and Hartley scale ``s`` (...) of point sets ``x`` (..., n, 2).

    Written with ``np.add.reduce`` rather than ``mean`` (the same arithmetic, bit for bit)
    because it runs once per group and voting iteration, where the call overhead counts.
    """
    n = x.shape[-2]
    c = np.add.reduce(x, axis=-2) / n
    dx, dy = x[..., 0] - c[..., None, 0], x[..., 1] - c[..., None, 1]
    # dx^2 + dy^2 is the sum over the coordinate axis, bit for bit (numpy's reduce over an
    # axis of length 2 costs several times more)
    d = np.sqrt(np.add.reduce(dx * dx + dy * dy, axis=-1) / n)
    return c, np.sqrt(2.0) / np.maximum(d, 1e-12)


def _similarity(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    T = np.zeros(s.shape + (3, 3))
    T[..., 0, 0] = s
    T[..., 1, 1] = s
    T[..., 0, 2] = -s * c[..., 0]
    T[..., 1, 2] = -s * c[..., 1]
    T[..., 2, 2] = 1.0
    return T


def hartley_normalization(x: np.ndarray) -> np.ndarray:
    """Similarity transforms that move points to zero mean and RMS distance sqrt(2).

    Parameters
    ----------
    x : ndarray of shape (..., n, 2)

    Returns
    -------
    T : ndarray of shape (..., 3, 3)
    """
    return _similarity(*_centre_scale(x))


def _centre_scale_masked(x: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_centre_scale` over the points with ``mask`` (..., n) True only."""
    m = mask.astype(np.float64)
    n = np.maximum(np.add.reduce(m, axis=-1), 1.0)
    c = np.einsum("...nk,...n->...k", x, m) / n[..., None]
    dx, dy = x[..., 0] - c[..., None, 0], x[..., 1] - c[..., None, 1]
    d = np.sqrt(np.add.reduce((dx * dx + dy * dy) * m, axis=-1) / n)
    return c, np.sqrt(2.0) / np.maximum(d, 1e-12)


def fit_fundamental(x1: np.ndarray, x2: np.ndarray, weights: np.ndarray | None = None,
                    mask: np.ndarray | None = None) -> np.ndarray:
    """Normalised 8-point algorithm (Hartley), batched, with rank-2 enforcement.

    Parameters
    ----------
    x1, x2 : ndarray of shape (..., n, 2)
        Corresponding pixel coordinates in the first and second view, n >= 8.
    weights : ndarray of shape (..., n), optional
        Non-negative weights of the equations (weighted least squares).
    mask : ndarray of shape (..., n), bool, optional
        Missing data: only the correspondences with ``mask`` True are used, for the
        Hartley normalisation too (the others must hold finite values, e.g. 0; they are
        never read otherwise). None (default): all.

    Returns
    -------
    F : ndarray of shape (..., 3, 3)
        Fundamental matrices, ``x2^T F x1 = 0``, divided by the power of two that brings
        their Frobenius norm into [0.5, 1) (exact, unlike dividing by the norm: see the
        code).
    """
    return FundamentalFitter(x1, x2, mask).fit(weights)


class FundamentalFitter:
    """:func:`fit_fundamental` of fixed correspondences, for several weightings.

    The Hartley normalisation and the unweighted design matrix depend on the points (and
    ``mask``) only, so reweighted least squares (:func:`laav.refine.pair_distances`) builds
    them once: ``FundamentalFitter(x1, x2, mask).fit(w)`` is ``fit_fundamental(x1, x2, w,
    mask)`` bit for bit (the same operations on the same arrays, only not repeated).

    Parameters
    ----------
    x1, x2 : ndarray of shape (..., n, 2)
    mask : ndarray of shape (..., n), bool, optional
        As in :func:`fit_fundamental`.

    Attributes
    ----------
    A : ndarray of shape (..., n, 9)
        The unweighted design matrix, in normalised coordinates.
    T : ndarray of shape (2, ..., 3, 3)
        The Hartley normalisations of the first and the second view.
    """

    def __init__(self, x1: np.ndarray, x2: np.ndarray, mask: np.ndarray | None = None):
        # both views at once: one normalisation, one design product (fewer numpy calls:
        # this runs once per voting iteration, where call overhead is most of the cost)
        if x1.shape != x2.shape:
            x1, x2 = np.broadcast_arrays(x1, x2)
        self.batch = x1.shape[:-2]
        xs = np.stack([x1, x2])  # (2, ..., n, 2)
        if mask is None:
            c, s = _centre_scale(xs)
        else:
            mask = np.broadcast_to(mask, x1.shape[:-1])
            c, s = _centre_scale_masked(xs, np.stack([mask, mask]))
        self.mask = mask
        ab = xs * s[..., None, None] + (-s[..., None] * c)[..., None, :]  # T x, written out
        h = np.concatenate([ab, np.ones(ab.shape[:-1] + (1,))], axis=-1)  # homogeneous (2, ..., n, 3)
        # rows of the design: (bx ax, bx ay, bx, by ax, by ay, by, ax, ay, 1)
        self.A = (h[1][..., :, None] * h[0][..., None, :]).reshape(h.shape[1:-1] + (9,))
        self.T = _similarity(c, s)  # (2, ..., 3, 3)

    def fit(self, weights: np.ndarray | None = None) -> np.ndarray:
        """F (..., 3, 3) of the equations weighted by ``weights`` (..., n) (None: all 1, or
        the mask's)."""
        if self.mask is not None:
            weights = self.mask if weights is None else np.where(self.mask, weights, 0.0)
        A = self.A
        if weights is not None:
            A = A * np.sqrt(np.maximum(weights, 0.0))[..., None]
        M = np.swapaxes(A, -1, -2) @ A
        _, vecs = np.linalg.eigh(M)
        f = vecs[..., :, 0].reshape(self.batch + (3, 3))
        U, S, Vt = np.linalg.svd(f)
        S[..., 2] = 0.0
        f = (U * S[..., None, :]) @ Vt
        T = self.T
        F = np.swapaxes(T[1], -1, -2) @ f @ T[0]
        # Frobenius norm brought into [0.5, 1) by a power of two, not to exactly 1. Scaling
        # the coordinates by a power of two s scales T's entries by powers of two, so F's
        # entries change by exact powers of two and Sampson distances by exactly s^2, bit
        # for bit; dividing by the norm itself would round differently at every scale
        # (noise-free data, whose degenerate 8-point samples make the fit ill-posed, turn
        # that into other labels).
        # (the Frobenius norm as np.linalg.norm computes it, bit for bit, without its call
        # overhead: this runs at every voting iteration and every robust fit)
        _, e = np.frexp(np.sqrt(np.add.reduce(F * F, axis=(-2, -1), keepdims=True)))
        return np.ldexp(F, -e)


def sampson_distance(F: np.ndarray, x1: np.ndarray, x2: np.ndarray) -> np.ndarray:
    """First-order geometric (Sampson) distance of correspondences to ``F``, in px^2.

    ``d = (x2^T F x1)^2 / ((F x1)_1^2 + (F x1)_2^2 + (F^T x2)_1^2 + (F^T x2)_2^2)``

    Parameters
    ----------
    F : ndarray of shape (..., 3, 3)
    x1, x2 : ndarray of shape (..., n, 2)
        Broadcast against the batch axes of ``F``.

    Returns
    -------
    d : ndarray of shape (..., n)
    """
    # points as rows (..., 2, n): the products below then run over contiguous rows
    t1 = np.swapaxes(x1, -1, -2)
    t2 = np.swapaxes(x2, -1, -2)
    Fx1 = F[..., :, :2] @ t1 + F[..., :, 2:]  # (..., 3, n)
    Ftx2 = np.swapaxes(F[..., :2, :2], -1, -2) @ t2 + F[..., 2, :2, None]  # (..., 2, n)
    a, b = Fx1[..., 0, :], Fx1[..., 1, :]
    p, q = Ftx2[..., 0, :], Ftx2[..., 1, :]
    num = (t2[..., 0, :] * a + t2[..., 1, :] * b + Fx1[..., 2, :]) ** 2
    den = a ** 2 + b ** 2 + p ** 2 + q ** 2
    return num / np.maximum(den, 1e-300)


def epipolar_lines(F: np.ndarray, x1: np.ndarray) -> np.ndarray:
    """Epipolar lines ``l = F x1`` in the second view, scaled so ``a^2 + b^2 = 1``.

    Parameters
    ----------
    F : ndarray of shape (3, 3)
    x1 : ndarray of shape (n, 2)

    Returns
    -------
    lines : ndarray of shape (n, 3)
        ``(a, b, c)`` with ``a x + b y + c = 0``.
    """
    l = x1 @ F[:, :2].T + F[:, 2]
    return l / np.maximum(np.hypot(l[:, :1], l[:, 1:2]), 1e-300)


def fit_affine(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Least-squares affine maps from ``src`` to every frame of ``dst``.

    Parameters
    ----------
    src : ndarray of shape (n, 2)
        Coordinates in the reference frame, n >= 3.
    dst : ndarray of shape (F, n, 2)
        Coordinates of the same points in F frames.

    Returns
    -------
    A : ndarray of shape (F, 2, 3)
        ``dst[f] ~= src @ A[f, :, :2].T + A[f, :, 2]``.
    """
    return fit_affine_leverage(src, dst)[0]


def _inverse_sym3(G: np.ndarray) -> np.ndarray:
    """Inverse of the symmetric 3 x 3 ``G`` plus the ridge ``1e-12 (trace G + 1)`` on its
    diagonal (which keeps collinear sets solvable), by cofactors in Python floats when it
    is well conditioned: a numpy call for one 3 x 3 matrix costs more than the arithmetic
    (a seed's RANSAC fits one to three of them)."""
    (a, b, c), (_, d, e), (_, _, f) = G.tolist()
    ridge = 1e-12 * (a + d + f + 1.0)
    a, d, f = a + ridge, d + ridge, f + ridge
    c00, c01, c02 = d * f - e * e, c * e - b * f, b * e - c * d
    c11, c12, c22 = a * f - c * c, b * c - a * e, a * d - b * b
    det = a * c00 + b * c01 + c * c02
    # det <= a d f (Hadamard); far below it (nearly collinear points) cofactors lose the
    # digits that LU with pivoting keeps: LAPACK's way then
    if not det > 1e-6 * a * d * f:
        return np.linalg.inv(np.array([[a, b, c], [b, d, e], [c, e, f]]))
    k = 1.0 / det
    return np.array([[c00 * k, c01 * k, c02 * k], [c01 * k, c11 * k, c12 * k],
                     [c02 * k, c12 * k, c22 * k]])


def fit_affine_leverage(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_affine`, and the leverage ``h`` (n,) of every point in the fit.

    ``h`` is the diagonal of the hat matrix of the (shared) design: a point's residual
    divided by ``1 - h`` is its residual under the fit without it.
    """
    # Solve in centred, scaled coordinates: the normal equations of raw pixel coordinates
    # are ill-conditioned (and a ridge scaled by their trace biases the fit), which put
    # predictions ~0.01 px off least squares for 640-px images and pixels off for
    # coordinates in the thousands.
    # (written for call overhead, the same numbers: one Python loop in the atoms calls it
    # once or twice per seed)
    n = src.shape[0]
    c = np.add.reduce(src, axis=0) / n  # np.mean bit for bit, less overhead
    dev = src - c
    d = np.sqrt(np.add.reduce((dev ** 2).sum(-1)) / n)
    s = 1.0 / max(d, 1e-12)
    X = np.empty((n, 3))  # homogeneous, normalised
    X[:, :2] = dev * s
    X[:, 2] = 1.0
    P = _inverse_sym3(X.T @ X) @ X.T  # (3, n)
    sol = np.einsum("kn,fnd->fdk", P, dst)  # (F, 2, 3), normalised src
    lin = sol[..., :2] * s
    out = np.empty_like(sol)
    out[..., :2] = lin
    out[..., 2] = sol[..., 2] - lin @ c
    return out, np.einsum("ik,ki->i", X, P)


def fit_affine_masked(src: np.ndarray, dst: np.ndarray, weights: np.ndarray,
                      min_points: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`fit_affine_leverage` for missing data: each frame on its own points.

    The map to frame ``f`` is fitted by least squares on the points with ``weights[f]``
    True only (the same centring and scaling of ``src`` as :func:`fit_affine_leverage`,
    from all ``n`` points); a frame with fewer than ``min_points`` of them has no map.

    Parameters
    ----------
    src : ndarray of shape (n, 2)
        Coordinates in the reference frame (every point must have them).
    dst : ndarray of shape (F, n, 2)
        Coordinates in every frame; entries with ``weights`` False are never read (give
        finite values there, e.g. 0, so that the products stay finite).
    weights : ndarray of shape (F, n), bool
        Which points each frame's map is fitted on (visible and wanted).
    min_points : int

    Returns
    -------
    A : ndarray of shape (F, 2, 3)
        NaN in the frames without a map.
    h : ndarray of shape (F, n)
        Leverage of each point in each frame's fit (the hat matrix's diagonal for a point
        fitted there; for the others, what it would add); NaN in frames without a map.
    defined : ndarray of shape (F,), bool
        The frames with a map.
    """
    n = src.shape[0]
    c = np.add.reduce(src, axis=0) / n
    d = np.sqrt(np.add.reduce(((src - c) ** 2).sum(-1)) / n)
    s = 1.0 / max(d, 1e-12)
    X = np.hstack([(src - c) * s, np.ones((n, 1))])  # (n, 3)
    w = np.asarray(weights, dtype=np.float64)  # (F, n)
    G = np.einsum("fn,ni,nj->fij", w, X, X)  # (F, 3, 3)
    tr = np.trace(G, axis1=1, axis2=2)
    G[:, np.arange(3), np.arange(3)] += 1e-12 * (tr + 1.0)[:, None]
    defined = w.sum(axis=1) >= min_points
    Ginv = np.linalg.inv(G)
    dst = np.where(w[..., None] > 0, dst, 0.0)
    rhs = np.einsum("fn,ni,fnd->fid", w, X, dst)  # (F, 3, 2)
    sol = np.swapaxes(Ginv @ rhs, 1, 2)  # (F, 2, 3), normalised src
    lin = sol[..., :2] * s
    out = np.empty_like(sol)
    out[..., :2] = lin
    out[..., 2] = sol[..., 2] - lin @ c
    h = np.einsum("ni,fij,nj->fn", X, Ginv, X)
    out[~defined] = np.nan
    h[~defined] = np.nan
    return out, h, defined


def apply_affine(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Apply affine maps ``A`` (..., 2, 3) to points ``x`` (..., n, 2)."""
    px, py = affine_residuals(A, x, np.zeros(2))
    return np.stack([px, py], axis=-1)


def affine_residuals(A: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Components of ``A x - y`` for affine maps ``A`` (..., 2 or 3, 3), points ``x`` and
    ``y`` (..., n, 2), broadcast like matrix products over the leading axes.

    Written out per coordinate: for stacks of many small maps (RANSAC hypotheses x frames,
    atom pairs x frame pairs) this is twice as fast as a batched matmul of (n, 2) by (2, 2)
    blocks; results agree with it to ~1e-13 px (the summation order differs).

    Returns
    -------
    dx, dy : ndarray of shape (..., n)
    """
    A = A[..., None]  # (..., rows, 3, 1): broadcast against the n points
    x0, x1 = x[..., 0], x[..., 1]
    dx = A[..., 0, 0, :] * x0 + A[..., 0, 1, :] * x1 + A[..., 0, 2, :] - y[..., 0]
    dy = A[..., 1, 0, :] * x0 + A[..., 1, 1, :] * x1 + A[..., 1, 2, :] - y[..., 1]
    return dx, dy
