"""The joint score of a whole labelling, and the descent that lowers it (ours, not the paper's).

LAAV's own chain (``rv_select="laav"``, the default) compares its candidate labellings by
:func:`joint_score`: the lossy coding length of every motion's trajectories
(:mod:`laav.coding`) plus ``coarse_epipolar_weight`` times an epipolar cost. The candidate
kept is the result of voting, refinement and joint reassignment, none of which minimises
that score: on Hopkins155 (seeds 0-1, 310 runs) ground truth scores lower than the
labelling returned in 27 of the 31 runs more than 1 % wrong (by 48-742 nats), so what they
lack is not a better score but a labelling nearer its minimum.

**The descent** (:func:`joint_descent`, ``rv_descent``): single points move to another
motion while that lowers the joint score. Each sweep computes, for every point and every
other motion, the change a move of that point alone makes: exactly for the coding length
(each motion's coding length from its sufficient statistics, :mod:`laav.coding`, the
point's trajectory taken out of one group and added to the other: a rank-one change of
the group's scatter, so one factorisation per motion serves every point,
:func:`laav.coding.coding_lengths_one_moved`) and with the motions'
fundamental matrices of the sweep's labelling held fixed for the epipolar cost. The
points whose best move lowers the score all move at once if the exact joint score of the
result is lower; else the better half of them, a quarter, a tenth, the best one; the
descent stops when not even that lowers the exact score, or after
:data:`DESCENT_SWEEPS` sweeps. No motion drops below 8 points (where the score is
infinite). The exact score of the labelling returned is never higher than the start's.
With ``max_moves`` it moves at most that many points: the selection scores each of LAAV's
candidates so (``rv_select_descent``) before comparing them.

Nothing in it was tuned: the halving schedule, the sweep cap and the 8-point floor were
set before it was measured (``benchmarks/TUNING.md``, "Descent on the joint score").
"""

from __future__ import annotations

import numpy as np

from .params import LaavParams
from .refine import _memo, frame_pairs, motion_distances

__all__ = ["joint_score", "joint_descent", "unit2", "JOINT_PAIRS", "DESCENT_SWEEPS"]

#: Epipolar frame pairs of :func:`joint_score` (as the joint merge's, ``laav.coarse``).
JOINT_PAIRS = 8
#: Most sweeps of :func:`joint_descent`.
DESCENT_SWEEPS = 10
#: Fewest points of a motion: below, :func:`joint_score` is infinite.
MIN_MOTION_POINTS = 8
#: The shares of the improving moves a sweep tries, best first (then the best move alone).
_SHARES = (1.0, 0.5, 0.25, 0.1)
#: A move must promise more than this (nats) and the exact score fall by more than
#: ``_SCORE_MIN``: far above the scores' rounding (about 1e-11 nats at 2e4), far below any
#: real change (a point's coding length is nats).
_GAIN_MIN, _SCORE_MIN = 1e-6, 1e-9


def unit2(params: LaavParams) -> float:
    """Squared pixel of :mod:`laav.refine`'s constants, in squared coordinate units.

    ``default rv_lambda / rv_lambda``: 1.0 exactly at the default ``rv_lambda`` (2 / px^2,
    tuned on Hopkins155 pixels), so there the constants are the tuned ones;
    ``s^2`` when ``rv_lambda`` is scaled by ``1 / s^2`` for coordinates scaled by ``s``.
    """
    return LaavParams.rv_lambda / params.rv_lambda


def joint_score(points: np.ndarray, labels: np.ndarray, n_motions: int,
                params: LaavParams, *, fits: dict | None = None,
                projected: np.ndarray | None = None) -> float:
    """The joint merge's score of a whole labelling (lower is better).

    Lossy coding length (nats, distortion ``coding_eps``) of every motion's trajectories
    (:mod:`laav.coding`) plus ``coarse_epipolar_weight`` times the epipolar cost: the sum
    over points of ``log(1 + d)``, ``d`` the point's mean Sampson distance to its own
    motion's robust fundamental matrices over 8 frame pairs, in units of
    :func:`unit2`. ``inf`` when a motion has fewer than 8 points.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (P,)
    n_motions : int
    params : LaavParams
        Uses ``coding_eps``, ``coarse_epipolar_weight`` and ``rv_lambda``.
    fits : dict, optional
        :func:`laav.refine.fit_memo` of ``points``: motions fitted before, and whole
        labellings scored before (with these ``params`` fields), are read back.
    projected : ndarray of shape (K, P), optional
        The points' :func:`laav.coding.principal_trajectories`, when already computed (the
        same numbers as computing it here). With ``fits`` it must be exactly that (as
        ``laav.own_chain.projection`` keeps it): the memo's keys do not hold it.
    """
    return _score_and_distances(points, labels, n_motions, params, projected, fits)[0]


def _score_and_distances(points, labels, n_motions, params, projected=None,
                         fits=None) -> tuple[float, np.ndarray | None]:
    """:func:`joint_score` and the distances (C, P) of every point to every motion's
    matrices it computed (None when a motion has fewer than 8 points). ``projected``: the
    points' :func:`laav.coding.principal_trajectories`, when already computed; ``fits``:
    :func:`laav.refine.fit_memo`, where the pair is kept (the distances then read-only) and
    read back for the same labels, ``n_motions`` and :func:`_score_fields`."""
    from .coding import labelling_coding_length

    labels = np.asarray(labels, dtype=np.int64)
    if np.bincount(labels, minlength=n_motions).min() < MIN_MOTION_POINTS:
        return float("inf"), None
    u2 = unit2(params)
    key = None if fits is None else ("joint", labels.tobytes(), int(n_motions), _score_fields(params))
    if key is not None and key in _memo(fits, points):  # scored before: the same numbers
        return fits[key]
    st = None if projected is None else _stats(projected, labels, n_motions, 2 * points.shape[0], fits)
    coding = labelling_coding_length(points, labels, n_motions, params.coding_eps, projected, st)
    D = motion_distances(points, labels, n_motions, frame_pairs(points.shape[0], JOINT_PAIRS), u2,
                         fits=fits)
    own = D[labels, np.arange(labels.size)]
    if not np.isfinite(own).all():
        out = float("inf"), D
    else:
        out = coding + params.coarse_epipolar_weight * float(np.log1p(own / u2).sum()), D
    if key is not None:
        D.flags.writeable = False  # (read back by later calls: nobody may change it)
        fits[key] = out
    return out


def _stats(projected: np.ndarray, labels: np.ndarray, C: int, dim: int, fits: dict | None):
    """:func:`laav.coding.stats_of` (a ``ModelStats``) of ``labels`` (P,) int64 over the
    projected trajectories ``projected`` (K, P), ``dim`` = 2F, kept in the memo ``fits`` when
    given: a descent's sweep reads the stats its accepted trial's score computed."""
    from .coding import stats_of

    if fits is None:
        return stats_of(projected, labels, C, dim)
    key = ("stats", labels.tobytes(), int(C), int(dim))
    if key not in fits:
        st = fits[key] = stats_of(projected, labels, C, dim)
        for a in (st.count, st.total, st.scatter):  # (read back by later calls, as the distances)
            a.flags.writeable = False
    return fits[key]


def _score_fields(params: LaavParams) -> tuple:
    """What :func:`joint_score` reads of ``params``: part of its memo keys."""
    return (float(params.coding_eps), float(params.coarse_epipolar_weight), float(params.rv_lambda))


def _move_gains(projected: np.ndarray, labels: np.ndarray, C: int, dim: int, eps: float,
                epi: np.ndarray, weight: float, fits: dict | None = None) -> np.ndarray:
    """(P, C): the joint score's change when each point alone moves to each motion (``inf``
    for its own motion and for points of a motion at the 8-point floor). ``projected``
    (K, P): the trajectories in the coding length's principal directions
    (:func:`laav.coding.principal_trajectories`); ``epi`` (C, P): each point's
    ``log(1 + d)`` under each motion's matrices; ``fits``: the memo :func:`_stats` reads."""
    from .coding import coding_lengths, coding_lengths_one_moved

    P = labels.size
    st = _stats(projected, labels, C, dim, fits)
    count, total, scatter = st.count, st.total, st.scatter
    now = coding_lengths(count, total, scatter, dim, eps)  # (C,)
    X = projected.T  # (P, K)
    a = labels
    out = np.empty(P)  # each point's own motion without it, less that motion's length now
    for g in range(C):
        mine = a == g
        if mine.any():
            out[mine] = (coding_lengths_one_moved(count[g], total[g], scatter[g], X[mine], dim, eps, -1)
                         - now[g])
    gain = np.empty((P, C))
    for b in range(C):
        into = coding_lengths_one_moved(count[b], total[b], scatter[b], X, dim, eps, +1)
        gain[:, b] = out + (into - now[b]) + weight * (epi[b] - epi[a, np.arange(P)])
    gain[np.arange(P), a] = np.inf
    gain[count[a] <= MIN_MOTION_POINTS] = np.inf
    return gain


def joint_descent(points: np.ndarray, labels: np.ndarray, n_motions: int,
                  params: LaavParams, max_sweeps: int = DESCENT_SWEEPS,
                  max_moves: int | None = None, *, projected: np.ndarray | None = None,
                  return_score: bool = False, fits: dict | None = None) -> tuple:
    """Move single points between motions while :func:`joint_score` decreases (module
    docstring).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Complete tracks.
    labels : ndarray of shape (P,)
        The start, in ``0 .. n_motions-1``.
    n_motions : int
    params : LaavParams
        Uses ``coding_eps``, ``coarse_epipolar_weight`` and ``rv_lambda``.
    max_sweeps : int
    max_moves : int, optional
        At most this many points end with a label other than the start's: a sweep takes
        its moves best first up to the first that would go over it (a point moved already
        may move again without counting twice), so the descent stops once the limit is
        reached and the best move left is a new point's. None: no limit. The selection's
        cleaning of its candidates (``rv_select_descent``) sets it.
    projected : ndarray of shape (K, P), optional
        :func:`laav.coding.principal_trajectories` of ``points``, when already computed
        (several descents on the same points: the same numbers, one SVD).
    return_score : bool
        Also return the :func:`joint_score` of the labels returned (computed on the way).
    fits : dict, optional
        :func:`laav.refine.fit_memo`: motions whose fundamental matrices were fitted
        before (by another descent on the same points, or earlier in this one) are not
        fitted again, labellings scored before are not scored again, and a descent from the
        same start with the same ``max_sweeps``, ``max_moves`` and ``params`` fields returns
        the first one's result (a copy); the same numbers. With ``projected``, see
        :func:`joint_score`.

    Returns
    -------
    labels : ndarray of shape (P,), int64
        Never of higher joint score than the start (the start itself when no move helps,
        or when the start's score is infinite).
    moved : int
        Points whose label differs from the start's.
    score : float
        With ``return_score``: :func:`joint_score` of ``labels`` (the same number).
    """
    start = np.asarray(labels, dtype=np.int64)
    C = int(n_motions)

    def out(L, best):
        moved = int(np.count_nonzero(L != start))
        return (L, moved, best) if return_score else (L, moved)

    if C < 2:
        return out(start.copy(), joint_score(points, start, C, params) if return_score else None)
    key = None if fits is None else ("descent", start.tobytes(), C, _score_fields(params),
                                     int(max_sweeps), None if max_moves is None else int(max_moves))
    if key is not None and key in _memo(fits, points):  # the same descent ran before: its result
        L, best = fits[key]
        return out(L.copy(), best)
    L, best = _descend(points, start, C, params, max_sweeps, max_moves, projected, fits)
    if key is not None:
        fits[key] = (L.copy(), best)
    return out(L, best)


def _descend(points, start, C, params, max_sweeps, max_moves, projected, fits) -> tuple:
    """:func:`joint_descent`'s sweeps from ``start`` (P,) int64, ``points`` (F, P, 2),
    C >= 2 motions (the other arguments as there): ``(labels (P,) int64, joint score)``."""
    from .coding import principal_trajectories

    # (K, P): one projection for every score below
    proj = principal_trajectories(points) if projected is None else projected
    best, D = _score_and_distances(points, start, C, params, proj, fits)
    if not np.isfinite(best):
        return start.copy(), best
    F = points.shape[0]
    u2 = unit2(params)
    L = start.copy()
    for _ in range(max_sweeps):
        epi = np.log1p(D / u2)  # (C, P): the matrices of L's motions, as its score took them
        gain = _move_gains(proj, L, C, 2 * F, params.coding_eps, epi, params.coarse_epipolar_weight,
                           fits)
        gain = np.nan_to_num(gain, nan=np.inf, posinf=np.inf)  # a NaN is no move
        to = np.argmin(gain, axis=1)
        g = gain[np.arange(L.size), to]
        order = np.flatnonzero(g < -_GAIN_MIN)
        order = order[np.argsort(g[order], kind="stable")]  # the best moves first
        if max_moves is not None:  # the best moves that keep within max_moves moved points
            fresh = L[order] == start[order]  # these would add one; the others none
            order = order[np.cumsum(fresh) <= max_moves - np.count_nonzero(L != start)]
        if order.size == 0:
            break
        sizes = sorted({max(1, int(np.ceil(s * order.size))) for s in _SHARES} | {1}, reverse=True)
        for n in sizes:
            trial = L.copy()
            trial[order[:n]] = to[order[:n]]
            score, dist = _score_and_distances(points, trial, C, params, proj, fits)
            if score < best - _SCORE_MIN:
                L, best, D = trial, score, dist
                break
        else:
            break  # not even the best single move lowers the exact score
    return L, best
