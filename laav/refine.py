"""Labelling refinement and scoring after voting: epipolar and trajectory-subspace fits.

Random Voting fits one fundamental matrix per motion and frame pair at a time; what it
returns is noisy near the boundaries between motions. The functions here look at every
frame at once:

* :func:`motion_distances` / :func:`refine_labels`: robust fundamental matrices per
  motion over a spread of frame pairs; points their own motion does not explain move.
* :func:`subspace_cost`: how well rank-5 trajectory subspaces explain a labelling (used
  to choose between candidate labellings, see :mod:`laav.selection`).
* :func:`subspace_residuals` / :func:`reassign_labels`: every point goes to the motion
  whose robust trajectory subspace *and* fundamental matrices explain it best together.

**Units.** Residuals here are squared distances (Sampson distances, squared subspace
residuals), so the few absolute constants (a cap, floors, the scale inside a log) are in
px^2 of the pixel scale the defaults were tuned on (Hopkins155). Every function takes
``unit2``, the square of one such pixel in the coordinates' units, and multiplies those
constants by it: scaling the coordinates by ``s`` and ``unit2`` by ``s^2`` gives the same
result. :mod:`laav.voting` passes ``unit2 = 2 / rv_lambda`` (1 at the default
``rv_lambda = 2 / px^2``, where the constants are unchanged).

**Missing data.** :func:`motion_distances`, :func:`refine_labels`, :func:`subspace_cost`,
:func:`subspace_residuals` and :func:`reassign_labels` take ``visible`` (F, P): every fit
then uses the visible entries only (``docs/ALGORITHM.md``, "Missing data").
"""

from __future__ import annotations

import numpy as np

from ._median import median
from .geometry import FundamentalFitter, sampson_distance

__all__ = ["labelling_cost", "subspace_cost", "motion_distances", "refine_labels",
           "subspace_residuals", "reassign_labels", "assign_by_subspace", "assign_jointly",
           "frame_pairs",
           "trajectory_matrix"]

#: Rank of the trajectory subspaces of :func:`subspace_cost` (affine camera: 4, plus one
#: for perspective and tracking noise; 5 measured best of 4..8, see benchmarks/TUNING.md).
SUBSPACE_RANK = 5
#: Squared residual scale (px^2, times ``unit2``) inside the log of :func:`subspace_cost`:
#: 0.1 px, below Hopkins155's tracking noise, so the cost is close to a mean log residual
#: (measured against 0.001..16 px^2, see benchmarks/TUNING.md).
SUBSPACE_SCALE2 = 0.01
#: Cap (px^2, times ``unit2``) on one frame pair's Sampson distance in
#: :func:`motion_distances`: a point 100 px off counts as 100 px off, whatever the pair.
SAMPSON_CAP = 1e4
#: Floor (px^2, times ``unit2``) added to both distances inside the logs of
#: :func:`reassign_labels`: keeps a perfect fit's log finite.
REASSIGN_FLOOR = 1e-4
#: Floor (px^2, times ``unit2``; px, times ``sqrt(unit2)``, for RMS residuals) added to
#: medians before dividing by them: keeps a perfect fit from dividing by zero.
TINY2 = 1e-9
#: Rank of the robust trajectory subspaces of :func:`reassign_labels` (the affine
#: camera's 4; 5 and 6 measured worse there, see benchmarks/TUNING.md).
REASSIGN_RANK = 4
#: Weight of the epipolar term against the subspace term in :func:`reassign_labels`
#: (0.3 / 0.5 / 0.7 / 1.0 measured, 0.5 best, see benchmarks/TUNING.md).
REASSIGN_EPIPOLAR_WEIGHT = 0.5


def trajectory_matrix(points: np.ndarray) -> np.ndarray:
    """The trajectories as columns, relative to the corner of their bounding box.

    Linear subspace fits through an origin (:func:`subspace_residuals`, the coding length
    of :mod:`laav.coding`, :mod:`laav.motions`) depend on where the origin is. It is put
    at the smallest x and the smallest y of all points over all frames: it moves with the
    points, so translating the coordinates changes nothing (and a distant origin costs no
    digits), and for tracks that fill the image it is about the image corner, the origin
    of the pixel coordinates the defaults were tuned on (Hopkins155). Against the image
    corner itself (the input's origin), on Hopkins155 with the defaults, seed 0: 149 of
    155 sequences keep their labels, mean error 0.577 % -> 0.572 %; the centroid of all
    points as origin measured worse (0.780 %, 46 sequences changed).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)

    Returns
    -------
    W : ndarray of shape (2F, P)
        Rows ``x_0, y_0, x_1, y_1, ...``; column ``p`` is point ``p``'s trajectory.
    """
    F, P, _ = points.shape
    return np.transpose(points - _corner(points), (0, 2, 1)).reshape(2 * F, P)


def _corner(points: np.ndarray) -> np.ndarray:
    """``points.min(axis=(0, 1))``, (2,): the same values (a minimum does not depend on the
    order it is taken in, but for the sign of a zero when both +0 and -0 are there: at most
    the sign of a zero entry of the matrix), one coordinate at a time: 30x faster on
    Hopkins155's arrays, where numpy's reduction over the leading axes ran its inner loop
    over the two coordinates."""
    return np.array([points[..., 0].min(), points[..., 1].min()])


def _trajectory_matrix_masked(points: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """:func:`trajectory_matrix` on incomplete data: the origin at the corner of the
    visible points' bounding box; hidden entries 0 (never read: the fits mask them)."""
    F, P, _ = points.shape
    corner = np.array([np.where(visible, points[..., c], np.inf).min() for c in (0, 1)])  # (as _corner)
    W = np.where(visible[..., None], points - corner, 0.0)
    return np.transpose(W, (0, 2, 1)).reshape(2 * F, P)


def frame_pairs(n_frames: int, n_pairs: int, rng: np.random.Generator | None = None) -> np.ndarray:
    """Frame pairs ``(l, r)`` at least ``max(1, F // 3)`` frames apart.

    With ``rng`` the pairs are drawn at random (with replacement); without it they are a
    deterministic spread: the first frame against the last and evenly spaced pairs between.

    Returns
    -------
    pairs : ndarray of shape (n_pairs, 2), int64
    """
    F = n_frames
    gap = max(1, F // 3)
    if rng is None:
        left = np.round(np.linspace(0, F - 1 - gap, n_pairs)).astype(np.int64)
        right = np.minimum(left + gap, F - 1)
        if n_pairs > 1:  # the widest baseline is always among them
            left[0], right[0] = 0, F - 1
        return np.stack([left, right], axis=1)
    left = rng.integers(0, F - gap, size=n_pairs)
    right = left + gap + np.floor(rng.random(n_pairs) * (F - gap - left)).astype(np.int64)
    pairs = np.stack([left, np.minimum(right, F - 1)], axis=1)
    flip = rng.random(n_pairs) < 0.5
    pairs[flip] = pairs[flip][:, ::-1]
    return pairs.astype(np.int64)


def labelling_cost(points: np.ndarray, labels: np.ndarray, n_motions: int, n_pairs: int = 8,
                   unit2: float = 1.0) -> float:
    """How badly the motions' fundamental matrices explain a labelling (lower is better).

    Mean over points of ``log(1 + d / unit2)``, with ``d`` the point's mean Sampson
    distance (px^2) to its own motion (:func:`motion_distances`); ``inf`` when a motion
    has < 8 points.
    """
    D = motion_distances(points, labels, n_motions, frame_pairs(points.shape[0], n_pairs), unit2)
    own = D[labels, np.arange(labels.size)]
    return float(np.mean(np.log1p(own / unit2))) if np.isfinite(own).all() else float("inf")


def subspace_cost(points: np.ndarray, labels: np.ndarray, n_motions: int,
                  rank: int = SUBSPACE_RANK, scale2: float = SUBSPACE_SCALE2,
                  unit2: float = 1.0, *, visible: np.ndarray | None = None) -> float:
    """How badly low-rank trajectory subspaces explain a labelling (lower is better).

    Under an affine camera the trajectories of one rigid motion, each stacked as a 2F
    vector, span a linear subspace of dimension at most 4. Every motion's points get
    their best rank-``rank`` subspace (:func:`subspace_residuals` with one, unweighted,
    round); a point's residual ``r`` is its distance to that subspace as an RMS over
    frames (px). The cost is the mean over points of ``log(1 + r^2 / (scale2 unit2))``. Unlike
    :func:`labelling_cost` (epipolar), it uses every frame at once and tells a static
    background from a translating object, which the same fundamental matrix can both
    satisfy.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    rank : int
    scale2 : float
        px^2.
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    visible : ndarray of shape (F, P), bool, optional
        Missing data: the subspaces and residuals of :func:`subspace_residuals` with the
        mask (one round, unweighted).

    Returns
    -------
    float
        ``inf`` when a motion has ``rank + 1`` points or fewer.
    """
    R = subspace_residuals(points, labels, n_motions, rank, rounds=1, unit2=unit2,
                           visible=visible)
    if R is None:
        return float("inf")
    own = R[labels, np.arange(labels.size)]
    return float(np.mean(np.log1p(own / (scale2 * unit2))))


def _masked_median(x: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Median over the last axis of the entries with ``mask``; (..., n) -> (..., 1); 0 for
    rows without any."""
    out = np.zeros(x.shape[:-1] + (1,))
    rows = mask.any(axis=-1)
    if rows.any():
        out[rows, 0] = np.nanmedian(np.where(mask[rows], x[rows], np.nan), axis=-1)
    return out


def _motion_distances_masked(points, labels, n_motions, pairs, visible, unit2):
    """:func:`motion_distances` on incomplete data (see there)."""
    x1 = points[pairs[:, 0]]  # (K, P, 2), hidden entries filled
    x2 = points[pairs[:, 1]]
    V = visible[pairs[:, 0]] & visible[pairs[:, 1]]  # (K, P)
    D = np.full((n_motions, points.shape[1]), np.inf)
    for g in range(n_motions):
        mem = np.flatnonzero(labels == g)
        if mem.size < 8:
            continue
        m1, m2, mv = x1[:, mem], x2[:, mem], V[:, mem]
        fit = mv.sum(axis=1) >= 8  # the frame pairs this motion has a matrix for
        if not fit.any():
            continue
        m1, m2, mv = m1[fit], m2[fit], mv[fit]
        fitter = FundamentalFitter(m1, m2, mv)  # one normalisation for the three fits
        Fm = fitter.fit()
        for _ in range(2):
            dm = sampson_distance(Fm, m1, m2)
            w = 1.0 / (1.0 + dm / (_masked_median(dm, mv) * 4.0 + TINY2 * unit2))
            Fm = fitter.fit(w)
        d = np.minimum(sampson_distance(Fm, x1[fit], x2[fit]), SAMPSON_CAP * unit2)  # (K', P)
        use = V[fit]
        n = use.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            D[g] = np.where(n > 0, np.where(use, d, 0.0).sum(axis=0) / n, np.inf)
    return D


def motion_distances(points: np.ndarray, labels: np.ndarray, n_motions: int,
                     pairs: np.ndarray, unit2: float = 1.0,
                     visible: np.ndarray | None = None, *, fits: dict | None = None) -> np.ndarray:
    """Mean Sampson distance (px^2) of every point to every motion's fundamental matrices.

    Each motion fits one F per frame pair on its own points by iteratively reweighted
    least squares (weights ``1 / (1 + d / (4 median d))``, three rounds). A frame pair's
    distance counts at most :data:`SAMPSON_CAP` ``unit2``.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    pairs : ndarray of shape (K, 2)
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    visible : ndarray of shape (F, P), bool, optional
        Missing data (``points`` finite everywhere, hidden entries filled): a motion
        fits its matrix for a frame pair on its members visible in both frames, and only
        where there are 8 or more; a point's distance is the mean over the frame pairs it
        is visible in and the motion has a matrix for (``inf`` when there is none).
    fits : dict, optional
        Complete data: a memo of the motions fitted so far on these ``points`` (any pairs
        and ``unit2``, which are in its keys), filled as it goes: a motion whose members
        were fitted before is not fitted again (the same numbers; several candidate
        labellings of one selection share most motions). :func:`fit_memo` makes one.

    Returns
    -------
    D : ndarray of shape (C, P); ``inf`` for a motion with fewer than 8 points.
    """
    if visible is not None:
        return _motion_distances_masked(points, labels, n_motions, pairs, visible, unit2)
    x1 = points[pairs[:, 0]]  # (K, P, 2)
    x2 = points[pairs[:, 1]]
    D = np.full((n_motions, points.shape[1]), np.inf)
    for g in range(n_motions):
        mem = np.flatnonzero(labels == g)
        if mem.size < 8:
            continue
        key = None if fits is None else ("epipolar", pairs.tobytes(), float(unit2), mem.tobytes())
        row = None if key is None else _memo(fits, points).get(key)
        if row is None:
            # a new array, never handed out: D[g] = row copies it
            row = capped_mean(pair_distances(x1, x2, mem, TINY2 * unit2), unit2)
            if key is not None:
                fits[key] = row
        D[g] = row
    return D


class _FitMemo(dict):
    """Motion fits by key (see :func:`fit_memo`), for one array of points (``points``)."""

    def __init__(self, points: np.ndarray):
        super().__init__()
        self.points = points


def fit_memo(points: np.ndarray) -> dict:
    """An empty memo for the ``fits`` of :func:`motion_distances`,
    :func:`subspace_residuals`, :func:`refine_labels` and :func:`reassign_labels` (and
    :func:`laav.joint.joint_descent`) on ``points`` (F, P, 2), the very array they are then
    called with (another raises ``ValueError``): kept by the caller for as long as it
    compares labellings of them. It holds one row of P floats per motion fitted (about 60
    for LAAV's candidates of a three-motion sequence), the selection's principal
    trajectories (``laav.own_chain.projection``), and, for :mod:`laav.joint`, each labelling
    scored (its joint score, its (C, P) distances and its coding statistics) and each
    descent's result (a copy of its labels): 0.4 MB on a 543-point three-motion sequence. It
    is not bounded: make one per comparison, not per session."""
    return _FitMemo(points)


def _memo(fits: dict, points: np.ndarray) -> dict:
    """``fits``, checked to be :func:`fit_memo` of ``points``."""
    if getattr(fits, "points", None) is not points:
        raise ValueError("fits: a fit_memo(points) of the points these fits are for")
    return fits


def pair_distances(x1: np.ndarray, x2: np.ndarray, members: np.ndarray,
                   floor2: float) -> np.ndarray:
    """Sampson distances (K, P) of every point to one motion's robust fundamental matrix
    of each frame pair: fitted on its ``members`` (>= 8 indices) by :func:`motion_distances`'
    reweighted least squares, ``floor2`` (px^2) added to the median in the weights.
    ``x1``, ``x2`` (K, P, 2): the points in each pair's two frames."""
    m1, m2 = x1[:, members], x2[:, members]
    fitter = FundamentalFitter(m1, m2)  # one normalisation for the three fits
    Fm = fitter.fit()  # (K, 3, 3)
    for _ in range(2):
        dm = sampson_distance(Fm, m1, m2)  # (K, n)
        w = 1.0 / (1.0 + dm / (median(dm, axis=1, keepdims=True) * 4.0 + floor2))
        Fm = fitter.fit(w)
    return sampson_distance(Fm, x1, x2)


def capped_mean(d: np.ndarray, unit2: float = 1.0) -> np.ndarray:
    """:func:`motion_distances`' distance of every point from its per-pair distances
    ``d`` (K, P): the mean over the pairs, each capped at :data:`SAMPSON_CAP` ``unit2``."""
    return np.add.reduce(np.minimum(d, SAMPSON_CAP * unit2), axis=0) / d.shape[0]


def refine_labels(points: np.ndarray, labels: np.ndarray, n_motions: int,
                  n_pairs: int = 12, rounds: int = 3, outlier: float = 6.0,
                  return_distances: bool = False, unit2: float = 1.0, *,
                  visible: np.ndarray | None = None, pairs: np.ndarray | None = None,
                  fits: dict | None = None) -> tuple:
    """Move points that their own motion does not explain to the motion that does.

    A point moves only when its distance to its own motion (:func:`motion_distances`,
    in units of that motion's median over its members) exceeds ``outlier`` and another
    motion's normalised distance is smaller. The guard matters: the fundamental matrix
    of a nearly degenerate motion (a car translating, a small planar patch) is poorly
    determined and can pass close to other motions' points, so "nearest F" alone moves
    correct points.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    n_pairs : int
        Frame pairs (a deterministic spread, see :func:`frame_pairs`).
    rounds : int
    outlier : float
    return_distances : bool
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    visible : ndarray of shape (F, P), bool, optional
        Missing data: :func:`motion_distances` with the mask, over ``pairs`` (then
        required: :func:`laav._visibility.cover_pairs`, which every point is visible in
        one of); a motion's scale is the median over its members' finite distances.
    pairs : ndarray of shape (K, 2), optional
        The frame pairs (default: ``frame_pairs(F, n_pairs)``).
    fits : dict, optional
        :func:`fit_memo`: motions fitted before are not fitted again (complete data).

    Returns
    -------
    labels : ndarray of shape (P,)
    n_changed : int
    distances : ndarray of shape (C, P) or None
        Only with ``return_distances``: :func:`motion_distances` of the returned labels
        (None when the last round moved points), for :func:`reassign_labels` to reuse.
    """
    if pairs is None:
        pairs = frame_pairs(points.shape[0], n_pairs)
    D = None
    start = labels.copy()
    cur = labels.copy()
    idx = np.arange(cur.size)
    for _ in range(rounds):
        D = motion_distances(points, cur, n_motions, pairs, unit2, visible, fits=fits)
        if visible is None:
            scale = np.array([median(D[g, cur == g]) if np.isfinite(D[g]).all() else np.inf
                              for g in range(n_motions)]) + TINY2 * unit2
        else:
            scale = np.array([_finite_median(D[g, cur == g])
                              for g in range(n_motions)]) + TINY2 * unit2
        with np.errstate(invalid="ignore"):  # inf / inf for a motion too small to fit
            N = np.where(np.isfinite(D), D / scale[:, None], np.inf)
        own = N[cur, idx]
        best = N.argmin(axis=0)
        move = (own > outlier) & (best != cur)
        if not move.any():
            break
        cur = np.where(move, best, cur)
        D = None  # computed for the labels before this move
    if return_distances:
        return cur, int((cur != start).sum()), D
    return cur, int((cur != start).sum())


def _finite_median(x: np.ndarray) -> float:
    """Median of the finite entries of ``x``; inf when there is none."""
    x = x[np.isfinite(x)]
    return float(median(x)) if x.size else np.inf


def top_eigenvectors(M: np.ndarray, k: int) -> np.ndarray:
    """The eigenvectors (D, k) of the ``k`` largest eigenvalues of the symmetric ``M``
    (D, D), in increasing order of their eigenvalue (``np.linalg.eigh(M)[1][:, -k:]``, to
    rounding and signs): LAPACK's relatively robust representations for those ``k`` alone,
    about 1.5x faster than every eigenvector at D = 60."""
    from scipy.linalg import lapack  # lazy: off `import laav`

    D = M.shape[0]
    if k < 1 or D < 1:
        raise ValueError(f"top_eigenvectors: k = {k} of a {D} x {D} matrix (k and D must be >= 1)")
    lo = max(1, D - k + 1)
    # the lower triangle, as np.linalg.eigh reads it (M is symmetric only to rounding)
    w, z, found, _, info = lapack.dsyevr(M, compute_v=1, range="I", il=lo, iu=D, lower=1)
    if info != 0 or found != D - lo + 1:
        return np.linalg.eigh(M)[1][:, -k:]
    return z[:, :found]


def robust_subspace(X: np.ndarray, xn2: np.ndarray, rank: int, rounds: int, tiny: float,
                    n_frames: int = 1) -> np.ndarray:
    """The robust rank-``rank`` linear subspace (D, rank) of the columns ``X`` (D, n), their
    squared norms ``xn2`` (n,): ``rounds`` weighted principal-subspace fits
    (:func:`top_eigenvectors` of ``X diag(w^2) X^T``), the weights ``1 / (1 + (r / 2 median
    r)^2)`` from the residuals ``r`` of the previous fit (RMS over ``n_frames``; ``tiny``
    in r's unit added to the median). :func:`subspace_residuals`' fit, and the motion-count
    profile's (:mod:`laav.motions`, ``n_frames`` 1)."""
    Xw = X  # the points, scaled by the squared IRLS weights from the second round on
    for k in range(rounds):
        U = top_eigenvectors(Xw @ X.T, rank)  # principal subspace, weighted
        if k + 1 < rounds:
            proj = U.T @ X
            r = np.sqrt(np.maximum(xn2 - np.einsum("ij,ij->j", proj, proj), 0.0) / n_frames)
            Xw = X * (1.0 / (1.0 + (r / (2.0 * median(r) + tiny)) ** 2)) ** 2
    return U


def subspace_residuals(points: np.ndarray, labels: np.ndarray, n_motions: int,
                       rank: int = REASSIGN_RANK, rounds: int = 5,
                       unit2: float = 1.0, *,
                       visible: np.ndarray | None = None, shared_frames: bool = False,
                       fits: dict | None = None) -> np.ndarray | None:
    """Squared distance (px^2, mean over frames) of every point to every motion's subspace.

    Each motion's trajectories (2F vectors) get a rank-``rank`` linear subspace fitted by
    iteratively reweighted least squares: ``rounds`` weighted principal-subspace fits,
    with weights ``1 / (1 + (r / 2 median r)^2)`` from the residuals ``r`` of the
    previous fit, so the few points wrongly labelled into the motion barely tilt it
    (an unweighted fit is pulled towards them, and moving points by it is worse than
    not moving them, see benchmarks/TUNING.md). The subspaces pass through the corner of
    the points' bounding box (:func:`trajectory_matrix`), not the coordinates' origin.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    rank : int
    rounds : int
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    visible : ndarray of shape (F, P), bool, optional
        Missing data (``points`` finite everywhere, hidden entries filled): each
        motion's subspace is fitted on the visible entries of its members only, by
        alternating least squares (per-point coefficients, per-row basis) swept until it
        stops gaining (``_ALS_TOL``), started from the principal subspace with every
        unseen entry guessed from the point's nearest seen frame and its motion's mean
        translation (``_impute_by_translation``), with the same reweighting; the origin
        is the corner of the visible points' bounding box; a point's residual is that of
        its least-squares fit on its visible rows, per visible frame. A point seen in
        ``rank / 2`` frames or fewer is fitted exactly by every subspace (residual 0
        everywhere: no evidence).
    shared_frames : bool
        Missing data, for choosing a point's motion: judge every point only on the frames
        where every motion's basis is determined (:data:`DETERMINED_FACTOR` ``x rank`` of
        its members seen there), so that all motions judge a point on the same frames; a
        point seen in ``rank / 2`` of those or fewer is judged on all its visible frames.
        Not for comparing labellings (:func:`subspace_cost`): each labelling would be
        judged on its own frames.
    fits : dict, optional
        :func:`fit_memo`: motions fitted before are not fitted again (complete data).

    Returns
    -------
    R : ndarray of shape (C, P), or None when a motion has ``rank + 1`` points or fewer.
    """
    if visible is not None:
        return _subspace_residuals_masked(points, labels, n_motions, rank, rounds, visible, unit2,
                                          shared_frames)
    F, P, _ = points.shape
    tiny = TINY2 * np.sqrt(unit2)  # px: the IRLS residuals are RMS distances
    W = trajectory_matrix(points)  # the origin at the points' corner (see there)
    norm2 = np.einsum("ij,ij->j", W, W)  # |x|^2 per point; residual^2 = |x|^2 - |U^T x|^2
    R = np.empty((n_motions, P))
    for g in range(n_motions):
        mem = labels == g
        if np.count_nonzero(mem) <= rank + 1:
            return None
        key = None if fits is None else ("subspace", rank, rounds, float(unit2), mem.tobytes())
        if key is not None and key in _memo(fits, points):
            R[g] = fits[key]
            continue
        U = robust_subspace(W[:, mem], norm2[mem], rank, rounds, tiny, F)
        proj = U.T @ W
        R[g] = np.maximum(norm2 - np.einsum("ij,ij->j", proj, proj), 0.0) / F
        if key is not None:
            fits[key] = R[g].copy()  # a copy: R goes to the caller
    return R


#: Missing data: a motion's rank-r subspace basis is determined in a frame when at least
#: this many times r of its members are seen there (set a priori, not tuned: twice the
#: unknowns of the frame's basis row per coordinate, as a fundamental matrix's 8 points are
#: about its 8 unknowns); :func:`subspace_residuals` judges points on the frames where every
#: motion's basis is determined.
DETERMINED_FACTOR = 2

#: The masked subspace fits' alternating least squares sweeps until one sweep lowers the
#: (weighted) squared residual by less than this share of it, at most ``_ALS_MAX`` sweeps per
#: round. Alternating least squares converges linearly and slowly; a fixed 12 sweeps left
#: the fit far from its minimum often enough that the cost of two candidate labellings
#: differed more by how far each fit had got than by the labellings (benchmarks/TUNING.md,
#: "Missing data: the masked subspace fits"). At 1e-4 the selection cost is within 0.005 of
#: its converged value for 90 % of Hopkins155's candidate labellings at 40 % missing.
_ALS_TOL, _ALS_MAX = 1e-4, 200


def _impute_by_translation(X: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``X`` (D = 2F, n; rows ``x_0, y_0, x_1, ...``) with every unseen entry guessed: the
    column's position in its nearest seen frame (the earlier of two as near), moved by the
    mean displacement between the two frames of the columns seen in both (none: not moved).
    Only the start of the masked fits; a column seen nowhere gets 0."""
    D, n = X.shape
    F = D // 2
    vis = M[0::2] > 0  # (F, n)
    v = vis.astype(np.float64)
    shared = v @ v.T  # (F, F): columns seen in both frames
    fr = np.arange(F)[:, None]
    last = np.maximum.accumulate(np.where(vis, fr, -1), axis=0)  # latest seen frame <= f
    nxt = np.flip(np.minimum.accumulate(np.flip(np.where(vis, fr, F), axis=0), axis=0), axis=0)
    d_last = np.where(last >= 0, fr - last, F + 1)
    d_next = np.where(nxt < F, nxt - fr, F + 1)
    near = np.where(d_last <= d_next, last, nxt)  # (F, n), nearest seen frame
    ok = vis.any(axis=0)[None, :] & (near >= 0) & (near < F)
    near = np.where(ok, near, 0)
    cols = np.broadcast_to(np.arange(n), (F, n))
    rows = np.broadcast_to(fr, (F, n))
    out = np.empty_like(X)
    for c in range(2):  # x rows, then y rows
        Xc = X[c::2]
        T = (v * Xc) @ v.T  # T[f, g]: sum of x_f over the columns seen in f and g
        move = np.where(shared > 0, (T - T.T) / np.maximum(shared, 1.0), 0.0)  # mean x_f - x_g
        guess = np.where(ok, Xc[near, cols] + move[rows, near], 0.0)
        out[c::2] = np.where(vis, Xc, guess)
    return out


def _project_masked(U: np.ndarray, MX: np.ndarray, M: np.ndarray,
                    residuals: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """Least-squares coefficients ``V`` (n, r) of columns ``X`` (D, n) on the basis ``U``
    (D, r) over each column's rows ``M`` (D, n, 0/1), given ``MX = M * X``, and the squared
    residuals (n,) (None unless ``residuals``)."""
    r = U.shape[1]
    G = (M.T @ (U[:, :, None] * U[:, None, :]).reshape(-1, r * r)).reshape(-1, r, r)
    G[:, np.arange(r), np.arange(r)] += 1e-9 * (np.trace(G, axis1=1, axis2=2)[:, None] + 1e-12)
    V = np.linalg.solve(G, (MX.T @ U)[..., None])[..., 0]
    if not residuals:
        return V, None
    res = _masked_residual(U, V, MX, M)
    return V, np.einsum("dn,dn->n", res, res)


def _masked_residual(U: np.ndarray, V: np.ndarray, MX: np.ndarray, M: np.ndarray) -> np.ndarray:
    """``MX - M * (U @ V.T)`` (D, n), in one new array: the same numbers as that expression,
    without its two (D, n) temporaries, whose allocation and first touch cost more than the
    arithmetic at thousands of tracks (a seed move at 5,000 tracks makes ~3,000 of them)."""
    res = U @ V.T
    res *= M
    return np.subtract(MX, res, out=res)


def _fit_subspace_masked(X, M, rank, rounds, tiny, tol=_ALS_TOL, max_sweeps=_ALS_MAX):
    """Robust rank-``rank`` linear subspace of columns ``X`` (D, n) seen on rows ``M``
    (D, n, 0/1): alternating least squares (coefficients per column, basis per row) on the
    seen entries only, started from the principal subspace of ``X`` with its unseen entries
    guessed by :func:`_impute_by_translation`, until a sweep lowers the squared residual by
    less than ``tol`` of it (at most ``max_sweeps``); then ``rounds - 1`` reweighting rounds
    as :func:`subspace_residuals` (weights ``1 / (1 + (r / 2 median r)^2)``, squared), each
    swept to the same test, warm-started. Returns the basis (D, rank), orthonormal."""
    D, n = X.shape
    X0 = _impute_by_translation(X, M)
    U = top_eigenvectors(X0 @ X0.T, rank)
    cnt = np.maximum(M.sum(axis=0) / 2.0, 1.0)  # frames seen per column
    w = np.ones(n)
    eye = np.eye(rank)
    MX = M * X  # the same in every sweep; M * w * X below equals MX * w bit for bit (M is 0/1)
    for k in range(rounds):
        WM, WMX = M * w, MX * w  # (D, n)
        before = np.inf
        for _ in range(max_sweeps):
            V, _ = _project_masked(U, MX, M, residuals=False)
            H = (WM @ (V[:, :, None] * V[:, None, :]).reshape(n, -1)).reshape(D, rank, rank)
            H += 1e-9 * (np.trace(H, axis1=1, axis2=2)[:, None, None] + 1e-12) * eye
            c = WMX @ V
            U = np.linalg.solve(H, c[..., None])[..., 0]
            res = _masked_residual(U, V, MX, M)  # this sweep's residual (before the re-orthonormalising)
            after = float(np.einsum("dn,dn,n->", res, res, w))
            U = np.linalg.qr(U)[0]
            if before - after <= tol * after:
                break
            before = after
        if k + 1 < rounds:
            _, r2 = _project_masked(U, MX, M)
            r = np.sqrt(r2 / cnt)
            w = (1.0 / (1.0 + (r / (2.0 * median(r) + tiny)) ** 2)) ** 2
    return U


def _subspace_residuals_masked(points, labels, n_motions, rank, rounds, visible, unit2,
                               shared_frames=False):
    """:func:`subspace_residuals` on incomplete data (see there)."""
    F, P, _ = points.shape
    W = _trajectory_matrix_masked(points, visible)  # the origin at the visible points' corner
    M = np.repeat(visible, 2, axis=0).astype(np.float64)  # (2F, P): x and y rows of a frame
    MW = M * W
    bases = []
    shared = np.ones(F, dtype=bool)  # with shared_frames: where every motion's basis is determined
    for g in range(n_motions):
        mem = labels == g
        if mem.sum() <= rank + 1:
            return None
        bases.append(_fit_subspace_masked(W[:, mem], M[:, mem], rank, rounds,
                                          TINY2 * np.sqrt(unit2)))
        if shared_frames:
            shared &= visible[:, mem].sum(axis=1) >= DETERMINED_FACTOR * rank
    # every motion judges a point on the same frames: its visible ones where each basis row
    # is determined (a row fitted on fewer members is whatever the fit left there, and a
    # point seen in that frame would be far from that motion for no reason of its own)
    if not shared.all():
        vis = visible & shared[:, None]
        # a point seen in rank / 2 of them or fewer would be fitted exactly by every motion
        # (no evidence): it is judged on all the frames it is seen in instead
        few = 2 * vis.sum(axis=0) <= rank
        vis[:, few] = visible[:, few]
        M = np.repeat(vis, 2, axis=0).astype(np.float64)
        MW = M * W
        cnt = vis.sum(axis=0)
    else:
        cnt = visible.sum(axis=0)
    R = np.empty((n_motions, P))
    for g, U in enumerate(bases):
        _, r2 = _project_masked(U, MW, M)
        R[g] = np.maximum(r2, 0.0) / cnt
    return R


def _masked_scores(R: np.ndarray, D: np.ndarray, eps: float, epipolar_weight: float,
                   informative: np.ndarray) -> np.ndarray:
    """Missing data: the scores (C, P) of :func:`reassign_labels`' rule, each point's motions
    compared on the evidence they share. ``R`` (C, P) subspace residuals, ``D`` (C, P) mean
    Sampson distances, ``inf`` where a motion has no matrix for a point's frame pairs;
    ``informative`` (P,) bool: the point is seen in more than rank / 2 frames (else every
    subspace fits it exactly and its ``R`` is rounding noise).

    A point that some motions have an epipolar distance for and others not is scored by the
    subspaces alone: a motion's missing matrix (fewer than 8 of its points seen in the pairs
    the point is seen in) says nothing against it, and ``log(inf)`` would rule it out (a
    point seen only late in the sequence, where its own motion is thinly tracked, went to
    another motion although its own subspace fitted it 2,000 times better). A point no
    motion has a distance for scores ``inf`` everywhere (the callers' rules decide)."""
    with np.errstate(divide="ignore"):
        score = np.log(R + eps) + epipolar_weight * np.log(D + eps)
    finite = np.isfinite(D)
    # (a point seen in too few frames for the subspaces: the epipolar distances it has decide)
    partial = finite.any(axis=0) & ~finite.all(axis=0) & informative
    score[:, partial] = np.log(R[:, partial] + eps)
    return score


def reassign_labels(points: np.ndarray, labels: np.ndarray, n_motions: int,
                    rank: int = REASSIGN_RANK, epipolar_weight: float = REASSIGN_EPIPOLAR_WEIGHT,
                    rounds: int = 2, min_size: int = 8,
                    distances: np.ndarray | None = None,
                    unit2: float = 1.0, *, visible: np.ndarray | None = None,
                    pairs: np.ndarray | None = None,
                    fits: dict | None = None) -> tuple[np.ndarray, int]:
    """Move every point to the motion that its trajectory subspace and epipolar fit favour.

    The score of point ``p`` for motion ``g`` is ``log(r_gp + eps) + epipolar_weight *
    log(d_gp + eps)``, with ``r`` its squared distance to ``g``'s robust rank-``rank``
    trajectory subspace (:func:`subspace_residuals`), ``d`` its mean Sampson distance to
    ``g``'s robust fundamental matrices over 12 frame pairs (:func:`motion_distances`),
    and ``eps`` = :data:`REASSIGN_FLOOR` ``unit2`` (1e-4 px^2); the point takes the
    motion of lowest score. Repeated
    ``rounds`` times (or until nothing moves).

    Why both: either alone errs where the other does not. Under perspective the subspace
    of a rigid motion is not exactly rank 4 and near-degenerate motions (translations,
    planes) share subspaces; the fundamental matrix of a near-degenerate motion passes
    close to other motions' points. A point both fits explain is almost always right.
    Measured on Hopkins155 as the last step of voting, seeds 0-1 (tuning) / 2-4 (held
    out): LAAV 0.84 -> 0.49 % / 0.98 -> 0.56 %, plain RV 1.00 -> 0.66 % / 1.15 -> 0.77 %;
    the subspace alone, unweighted fits, ranks 5 and 6, and other weights were each
    worse (benchmarks/TUNING.md).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    rank : int
    epipolar_weight : float
    rounds : int
    min_size : int
        A round that would leave a motion with fewer points is not taken.
    distances : ndarray of shape (C, P), optional
        :func:`motion_distances` of ``labels`` over ``frame_pairs(F, 12)``, when already
        known (from :func:`refine_labels`, with the same ``unit2``); saves the first
        round's fits.
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    visible : ndarray of shape (F, P), bool, optional
        Missing data: both terms with the mask (:func:`subspace_residuals` fitted on the
        visible entries, :func:`motion_distances` over ``pairs``); a point that only some
        motions have a finite epipolar distance for is scored by the subspaces alone (the
        motions compared on the evidence they share), and a point without any keeps its
        label.
    pairs : ndarray of shape (K, 2), optional
        The frame pairs of the epipolar term (default ``frame_pairs(F, 12)``).
    fits : dict, optional
        :func:`fit_memo`: motions fitted before are not fitted again (complete data).

    Returns
    -------
    labels : ndarray of shape (P,)
    n_changed : int
    """
    start = np.asarray(labels, dtype=np.int64)
    cur = start
    if n_motions < 2:
        return cur.copy(), 0
    if visible is not None:
        return _reassign_masked(points, start, n_motions, rank, epipolar_weight, rounds,
                                min_size, distances, visible, pairs, unit2)
    pairs = frame_pairs(points.shape[0], 12)
    for _ in range(rounds):
        R = subspace_residuals(points, cur, n_motions, rank, unit2=unit2, fits=fits)
        if R is None:
            break
        D = distances if distances is not None and cur is start else motion_distances(
            points, cur, n_motions, pairs, unit2, fits=fits)
        if not np.isfinite(D).all():
            break
        eps = REASSIGN_FLOOR * unit2
        score = np.log(R + eps) + epipolar_weight * np.log(D + eps)
        new = score.argmin(axis=0)
        if (new == cur).all() or np.bincount(new, minlength=n_motions).min() < min_size:
            break
        cur = new
    return cur.copy(), int((cur != start).sum())


def _reassign_masked(points, start, n_motions, rank, epipolar_weight, rounds, min_size,
                     distances, visible, pairs, unit2):
    """:func:`reassign_labels` on incomplete data (see there)."""
    cur = start
    for _ in range(rounds):
        R = subspace_residuals(points, cur, n_motions, rank, unit2=unit2, visible=visible,
                               shared_frames=True)
        if R is None:
            break
        D = distances if distances is not None and cur is start else motion_distances(
            points, cur, n_motions, pairs, unit2, visible)
        score = _masked_scores(R, D, REASSIGN_FLOOR * unit2, epipolar_weight,
                               2 * visible.sum(axis=0) > rank)
        known = np.isfinite(score).any(axis=0)
        new = np.where(known, score.argmin(axis=0), cur)
        if (new == cur).all() or np.bincount(new, minlength=n_motions).min() < min_size:
            break
        cur = new
    return cur.copy(), int((cur != start).sum())


def assign_by_subspace(points: np.ndarray, labels: np.ndarray, n_motions: int,
                       visible: np.ndarray, targets: np.ndarray, min_frames: int,
                       rank: int = REASSIGN_RANK, unit2: float = 1.0) -> np.ndarray:
    """Labels for the points ``targets`` from the motions of the labelled points.

    Each motion's robust rank-``rank`` trajectory subspace is fitted on the visible entries
    of its labelled points (:func:`subspace_residuals` with the mask; ``-1`` points take
    no part); a target point goes to the motion whose subspace fits its visible
    coordinates with the least residual per frame. For the points of incomplete data that
    no voting frame pair sees (:mod:`laav.voting`): the subspaces use every frame at once,
    so a point seen over a short stretch of the sequence is still placed.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Hidden entries filled (finite).
    labels : ndarray of shape (P,)
        ``-1`` for the points to leave out of the fits (the targets among them).
    n_motions : int
    visible : ndarray of shape (F, P), bool
    targets : ndarray of int
    min_frames : int
        Targets visible in fewer frames keep ``-1``.
    rank : int
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).

    Returns
    -------
    ndarray of shape (len(targets),), int64: a motion, or ``-1`` (too few frames, or a
    motion with ``rank + 1`` points or fewer to fit).
    """
    targets = np.asarray(targets, dtype=np.int64)
    out = np.full(targets.size, -1, dtype=np.int64)
    enough = visible[:, targets].sum(axis=0) >= min_frames
    if not enough.any():
        return out
    if n_motions == 1:
        out[enough] = 0
        return out
    R = subspace_residuals(points, labels, n_motions, rank, unit2=unit2, visible=visible,
                           shared_frames=True)
    if R is None:
        return out
    out[enough] = R[:, targets[enough]].argmin(axis=0)
    return out


def assign_jointly(points: np.ndarray, labels: np.ndarray, n_motions: int,
                   targets: np.ndarray, unit2: float = 1.0, *,
                   rank: int = REASSIGN_RANK, epipolar_weight: float = REASSIGN_EPIPOLAR_WEIGHT,
                   visible: np.ndarray | None = None, pairs: np.ndarray | None = None,
                   min_frames: int = 4) -> np.ndarray:
    """Labels for the points ``targets`` by the rule of :func:`reassign_labels`, one round.

    The motions' robust rank-``rank`` trajectory subspaces and robust fundamental matrices
    are fitted on the labelled points (``-1`` points, the targets among them, take no
    part); a target goes to the motion of least ``log(r + eps) + epipolar_weight *
    log(d + eps)`` (see :func:`reassign_labels`). For the points left out of Random Voting
    when there are more than ``rv_max_points`` (:mod:`laav.voting`).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Hidden entries filled (finite) when ``visible`` is given.
    labels : ndarray of shape (P,)
        ``-1`` for the points to leave out of the fits.
    n_motions : int
    targets : ndarray of int
    unit2 : float
        Squared pixel in the coordinates' units (see the module docstring).
    rank, epipolar_weight : as :func:`reassign_labels`.
    visible : ndarray of shape (F, P), bool, optional
        Missing data: both fits on the visible entries (as :func:`reassign_labels`); a
        target only some motions have a finite epipolar distance for is scored by the
        subspaces alone (as :func:`reassign_labels`), and one no motion has a distance for is
        placed by the subspaces alone when seen in ``min_frames`` frames or more, else
        gets ``-1``.
    pairs : ndarray of shape (K, 2), optional
        The epipolar term's frame pairs (default ``frame_pairs(F, 12)``).
    min_frames : int

    Returns
    -------
    ndarray of shape (len(targets),), int64: a motion, or ``-1`` (missing data only, see
    ``visible``; or when no motion has enough labelled points to fit).
    """
    targets = np.asarray(targets, dtype=np.int64)
    out = np.full(targets.size, -1, dtype=np.int64)
    if targets.size == 0:
        return out
    if n_motions == 1:
        out[:] = 0 if visible is None else np.where(
            visible[:, targets].sum(axis=0) >= min_frames, 0, -1)
        return out
    if pairs is None:
        pairs = frame_pairs(points.shape[0], 12)
    R = subspace_residuals(points, labels, n_motions, rank, unit2=unit2, visible=visible,
                           shared_frames=True)
    D = motion_distances(points, labels, n_motions, pairs, unit2, visible)[:, targets]
    eps = REASSIGN_FLOOR * unit2
    if visible is not None and R is not None:  # compared on the evidence they share
        score = _masked_scores(R[:, targets], D, eps, epipolar_weight,
                               2 * visible[:, targets].sum(axis=0) > rank)
    else:
        with np.errstate(divide="ignore"):
            score = epipolar_weight * np.log(D + eps)  # inf where a motion has no matrix
            if R is not None:
                score = score + np.log(R[:, targets] + eps)
    known = np.isfinite(score).any(axis=0)
    out[known] = score[:, known].argmin(axis=0)
    if visible is not None and R is not None:  # no epipolar evidence: the subspaces alone
        alone = ~known & (visible[:, targets].sum(axis=0) >= min_frames)
        out[alone] = R[:, targets[alone]].argmin(axis=0)
    return out
