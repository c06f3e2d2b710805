"""The tracks' pixel noise, measured from the data, and the thresholds it implies.

LAAV's pixel constants that judge residuals (the atoms' RANSAC threshold
``affine_threshold`` and the graph's neutral error ``edge_scale``, 2 px each) were chosen
on Hopkins155's clean tracks. Under Gaussian pixel noise of standard deviation σ the
residual of a feature under its own atom's affine motion is about 2σ to 3σ, so at
σ = 1 px most features fail a 2 px test and the atoms cover few points (issue 12).

With ``LaavParams(noise_adaptive=True)`` the pipeline measures σ (:func:`estimate_noise`)
and runs with :meth:`laav.LaavParams.for_noise`: the threshold becomes
``max(affine_threshold, k σ̂)`` with ``k`` the 99 % quantile of an inlier's residual under
the noise model (:func:`threshold_factor`), ``edge_scale`` is multiplied by the same
ratio ρ, and the voting strengths ``lam`` and ``rv_lambda`` (1/px², so the Sampson
distances they weigh, px², grow as ρ²) are divided by ρ². On clean tracks ``k σ̂`` stays
below the threshold, so nothing changes there (every label is identical).

**The estimate** is model-free enough to be near 0 on clean tracks, whatever the
motions: between two *consecutive* frames every small neighbourhood moves by an affine
map to well below a pixel, so the residual of a point under the least-squares affine map
of its ``n_neighbors`` nearest points (itself included) is noise, not motion. With
``y = x A + t`` (row vectors, ``x`` in frame ``f``, ``y`` in frame ``f + 1``) and i.i.d.
N(0, σ²) noise on every coordinate, coordinate ``c`` of the residual has variance
``σ² (1 + |A_:c|²) (1 - h)`` (``h`` the point's leverage), so the standardised squared
residual ``z = Σ_c r_c² / ((1 + |A_:c|²) (1 - h))`` is σ² χ²₂, whose median is
``2 ln 2 σ²``. The median over every point and frame pair is robust to the
neighbourhoods that straddle two motions, to tracking failures and to the few frames
with fast non-affine motion.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["estimate_noise", "threshold_factor", "adapted_params", "NOISE_QUANTILE", "NOISE_NEIGHBORS",
           "NOISE_PAIRS"]

#: An inlier of an atom passes the noise-adapted threshold with this probability under
#: the noise model (set a priori, not tuned).
NOISE_QUANTILE = 0.99
#: Points per local affine fit of :func:`estimate_noise` (itself included): small enough
#: that a neighbourhood is one motion nearly everywhere, enough that the fit (3 numbers
#: per coordinate) leaves 5 degrees of freedom.
NOISE_NEIGHBORS = 8
#: Most consecutive frame pairs :func:`estimate_noise` reads (evenly spaced): enough for
#: a stable median, bounded work on long sequences.
NOISE_PAIRS = 24


def _chi2_2_quantile(q: float) -> float:
    """Quantile ``q`` of the chi-square distribution with 2 degrees of freedom."""
    return -2.0 * math.log1p(-q)


def threshold_factor(atom_frames: str = "all", quantile: float = NOISE_QUANTILE) -> float:
    """``k``: an inlier's residual, in units of σ, that ``quantile`` of inliers stay below.

    The atom residual a feature is judged on is, with noise ``e_f ~ N(0, σ² I_2)`` on its
    position in frame ``f`` and a near-rigid local map (``A_f ≈`` a rotation):

    * ``atom_frames="all"``: the RMS over all frames of ``A_f e_0 - e_f`` (the maps start
      at frame 0, where the residual is 0). Over many frames its square is
      ``|e_0|² + 2σ²``: ``k = sqrt(χ²₂(q) + 2)``, 3.35 at q = 0.99.
    * ``atom_frames="pair"``: one frame pair, ``|A e_l - e_r|²`` is ``2σ² χ²₂``:
      ``k = sqrt(2 χ²₂(q))``, 4.29 at q = 0.99.

    The fit's own error (about 3 / n of the variance for an atom of n features) is left
    out: it is small for atoms of 10 or more features and makes the test stricter.
    """
    c = _chi2_2_quantile(quantile)
    if atom_frames == "pair":
        return math.sqrt(2.0 * c)
    return math.sqrt(c + 2.0)


#: Most (frame pair, point, neighbour) entries one batched pass of :func:`estimate_noise`
#: holds (about 20 arrays of this many floats: ~160 MB at the bound).
_BATCH_ENTRIES = 1 << 20


def _frame_pairs(F: int, max_pairs: int) -> np.ndarray:
    """Up to ``max_pairs`` first frames ``f`` of consecutive pairs ``(f, f + 1)``, evenly
    spaced."""
    if F < 2:
        return np.zeros(0, dtype=np.int64)
    n = min(F - 1, max_pairs)
    return np.unique(np.round(np.linspace(0, F - 2, n)).astype(np.int64))


def _neighbours(a: np.ndarray, k: int) -> np.ndarray:
    """(n, k): each point's ``k`` nearest among ``a`` (n, 2), itself first (a duplicate
    point may come first: the same coordinates, the same residual)."""
    from scipy.spatial import cKDTree  # lazy: off `import laav`

    return cKDTree(a).query(a, k=k)[1]


def _centred(coord: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """One coordinate of the centred neighbourhoods, (B, n, k): ``coord`` (B n,) one
    coordinate of the points, ``rows`` (B, n, k) the indices of each neighbourhood in it.

    ``X - X.mean(axis=-2, keepdims=True)`` of the neighbourhoods ``X`` (B, n, k, 2) bit
    for bit, a coordinate at a time, several times faster: numpy's mean adds the k
    neighbours one after another (its inner loop running over the 2 coordinates, which
    is what makes it slow), and so does the loop below, in the same order (checked on
    every Hopkins155 sequence).
    """
    x = np.take(coord, rows)  # (B, n, k), contiguous
    total = x[..., 0]
    for j in range(1, x.shape[-1]):
        total = total + x[..., j]
    return x - (total / x.shape[-1])[..., None]


def _standardised_residuals(a: np.ndarray, b: np.ndarray, nbr: np.ndarray) -> np.ndarray:
    """The standardised squared residuals ``z`` (module docstring) of the points whose fit
    is well posed, pair after pair.

    ``a``, ``b`` (B, n, 2): the points of B frame pairs in frames ``f`` and ``f + 1``;
    ``nbr`` (B, n, k) their neighbourhoods (:func:`_neighbours` of ``a``). The pairs are
    fitted side by side, but every number is computed as for one pair alone (element-wise
    operations, and reductions over an axis of length k with the same memory layout), so
    the batch moves no bit.
    """
    B, n, k = nbr.shape
    rows = nbr + (n * np.arange(B))[:, None, None]  # into the B n points of a and b
    a, b = a.reshape(-1, 2), b.reshape(-1, 2)
    # centred neighbourhoods, by coordinate (B, n, k)
    x0, x1, y0, y1 = (_centred(np.ascontiguousarray(v[:, c]), rows) for v in (a, b) for c in (0, 1))
    gxx, gxy, gyy = (x0 * x0).sum(-1), (x0 * x1).sum(-1), (x1 * x1).sum(-1)  # G = X^T X
    det = gxx * gyy - gxy * gxy
    tr = gxx + gyy
    ok = det > 1e-6 * tr * tr  # not (nearly) collinear; scale-free
    # A = G^-1 X^T Y (y ≈ x A, row vectors), entry by entry
    b00, b01 = (x0 * y0).sum(-1), (x0 * y1).sum(-1)
    b10, b11 = (x1 * y0).sum(-1), (x1 * y1).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):  # (not ok: dropped)
        a00 = (gyy * b00 - gxy * b10) / det
        a01 = (gyy * b01 - gxy * b11) / det
        a10 = (gxx * b10 - gxy * b00) / det
        a11 = (gxx * b11 - gxy * b01) / det
        # the point itself (its own neighbour 0), centred, its residual and leverage
        p0, p1, q0, q1 = x0[..., 0], x1[..., 0], y0[..., 0], y1[..., 0]
        r0 = q0 - (p0 * a00 + p1 * a10)
        r1 = q1 - (p0 * a01 + p1 * a11)
        h = 1.0 / k + (gyy * p0 * p0 - 2.0 * gxy * p0 * p1 + gxx * p1 * p1) / det
        z = (r0 * r0 / (1.0 + a00 * a00 + a10 * a10)
             + r1 * r1 / (1.0 + a01 * a01 + a11 * a11)) / (1.0 - h)
        good = ok & (h < 0.9)
    return z[good]


def estimate_noise(points: np.ndarray, visible: np.ndarray | None = None, *,
                   n_neighbors: int = NOISE_NEIGHBORS, max_pairs: int = NOISE_PAIRS) -> float:
    """Robust estimate of the tracks' pixel noise σ (px, per coordinate).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Pixel coordinates of P trajectories over F frames.
    visible : ndarray of shape (F, P), bool, optional
        Missing data: a pair ``(f, f + 1)`` uses the points seen in both frames; hidden
        coordinates are never read.
    n_neighbors : int
        Points per local affine fit (itself included; >= 4).
    max_pairs : int
        Most consecutive frame pairs read (evenly spaced).

    Returns
    -------
    float
        σ̂ in px: ``sqrt(median(z) / (2 ln 2))`` over every point and pair (module
        docstring); 0.0 when no fit is possible (fewer than ``n_neighbors`` points in every
        pair, one frame, or every neighbourhood degenerate). Deterministic (no random
        draw); coordinates scaled by a power of two scale it exactly.
    """
    points = np.asarray(points, dtype=np.float64)
    F, P, _ = points.shape
    k = int(n_neighbors)
    if k < 4:
        raise ValueError(f"n_neighbors must be >= 4, got {n_neighbors!r}")
    pairs = _frame_pairs(F, max_pairs)
    zs = []
    if visible is None:  # every pair has all P points: batched passes over the pairs
        # at most about _BATCH_ENTRIES (pair, point, neighbour) entries a pass: one pass on
        # sequences of hundreds of tracks, bounded temporaries on 50,000 (each pair is
        # computed on its own: the same numbers in any batching)
        per = max(1, _BATCH_ENTRIES // max(P * k, 1))
        for lo in range(0, pairs.size if P >= k else 0, per):
            sel = pairs[lo:lo + per]
            a, b = points[sel], points[sel + 1]  # (pairs, P, 2)
            zs.append(_standardised_residuals(a, b, np.stack([_neighbours(x, k) for x in a])))
    else:
        for f in pairs:
            idx = np.flatnonzero(visible[f] & visible[f + 1])
            if idx.size < k:
                continue
            a = points[f, idx]  # (n, 2)
            b = points[f + 1, idx]
            zs.append(_standardised_residuals(a[None], b[None], _neighbours(a, k)[None]))
    if not zs:
        return 0.0
    z = np.concatenate(zs)
    if z.size == 0:
        return 0.0
    return float(math.sqrt(float(np.median(z)) / (2.0 * math.log(2.0))))


def adapted_params(points: np.ndarray, params, visible: np.ndarray | None = None):
    """``(params the stages run with, σ̂)``: with ``params.noise_adaptive``,
    :meth:`~laav.LaavParams.for_noise` of :func:`estimate_noise` ``(points, visible)`` and
    that estimate (px); otherwise ``(params, None)`` unchanged.

    ``points`` (F, P, 2) px, ``visible`` (F, P) bool or None (complete data).
    """
    if not params.noise_adaptive:
        return params, None
    sigma = estimate_noise(points, visible)
    return params.for_noise(sigma), sigma
