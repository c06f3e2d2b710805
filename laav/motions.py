"""Estimating the number of motions C when it is not known: :func:`estimate_motions`.

**Profile** (:func:`motion_profile`, one pass, no Random Voting). LAAV's atoms, graph
and minimum cost multicut (its own segments, at least ``max_motions + 1``) give fine
models; these are merged greedily, always the pair whose union adds the least residual
to a rank-4 trajectory subspace (an affine camera's rigid motion spans 4 dimensions),
which yields one labelling for every C = 1 .. ``max_motions + 1``. Each is polished
(k-subspaces, then :func:`laav.refine.reassign_labels`) and scored twice per point: its
squared distance to its motion's robust rank-4 subspace (``residuals``) and its mean
Sampson distance to the nearest motion's fundamental matrices over 12 frame pairs
(``epipolar``). The level of C is the 95 % trimmed mean of each.

**Decision** (:func:`decide`), a sequential test: start at C = 1 and add a motion while
the test says the next one is real.

* 1 -> 2: a second motion unless one motion's epipolar level is within
  ``ONE_MOTION_RATIO`` x the noise (the squared median residual of the atoms' affine fits).
* C -> C + 1 (C >= 2): add when ``STEP_WEIGHTS . g + STEP_BIAS > 0``, ``g`` the log gains
  (level of C over level of C + 1) of both residuals at this step and the next; a linear
  (logistic) model-selection criterion, a penalty per extra motion in effect.

The constants were fitted on Hopkins155 by ``benchmarks/motions.py``, whose report
(``docs/bench/motions.md``) gives the 5-fold cross-validated accuracy (folds grouped by
source video) and the alternatives measured (eigengap, residual-ratio thresholds, label
stability across seeds, the multicut's own count).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._sequence import MIN_POINTS, Sequence
from ._threads import single_threaded

__all__ = ["MotionCount", "MotionProfile", "motion_profile", "estimate_motions", "decide",
           "profile_levels"]

RANK = 4  # an affine camera's rigid motion spans a 4-dimensional trajectory subspace
#: Fitted by benchmarks/motions.py on all 155 Hopkins155 sequences (seed 0 profiles);
#: weights of the log gains (subspace, epipolar) at a step and at the next step.
STEP_WEIGHTS = (0.5485, 1.0168, 1.2177, 0.8958)
STEP_BIAS = -3.2326
#: One motion when its epipolar level <= this x the atoms' noise level (px^2).
ONE_MOTION_RATIO = 0.05
TRIM = 0.95  # share of points (best explained) in a level


@dataclass(frozen=True, eq=False)
class MotionProfile:
    """How well C motions explain the trajectories, for C = 1 .. max_motions + 1."""

    candidates: np.ndarray      # (K,) C values
    residuals: np.ndarray       # (K, P) squared distance (px^2) of each point to its motion
    epipolar: np.ndarray        # (K, P) mean Sampson distance (px^2) to the nearest motion
    labels: np.ndarray          # (K, P) the labelling behind each row
    merge_costs: np.ndarray     # (K,) residual increase of the merge that left C groups
    noise2: float               # px^2: median squared affine residual of the atoms' members
    n_segments: int             # segments of the multicut itself
    n_atoms: int
    fine_cost: np.ndarray       # (M, M) pairwise merge cost of the fine models (px^2 total)
    fine_sizes: np.ndarray      # (M,) points per fine model


def _tail_sum(S: np.ndarray, rank: int) -> float:
    """Residual sum of squares of the best rank-``rank`` subspace of scatter matrix ``S``."""
    ev = np.linalg.eigvalsh(S)
    return float(max(ev[:-rank].sum(), 0.0)) if ev.size > rank else 0.0


def _group_residuals(W, norm2, labels, n_groups, rank, rounds=3, min_size=MIN_POINTS, unit2=1.0):
    """(n_groups, P) squared residuals (px^2, per frame) to each group's robust subspace;
    inf rows for groups with fewer than ``min_size`` points. ``unit2``: as in
    :mod:`laav.refine` (the IRLS median's floor is 1e-12 px times ``sqrt(unit2)``)."""
    tiny = 1e-12 * np.sqrt(unit2)
    F2, P = W.shape
    R = np.full((n_groups, P), np.inf)
    for g in range(n_groups):
        mem = labels == g
        if mem.sum() < max(min_size, rank + 1):
            continue
        X, xn2 = W[:, mem], norm2[mem]
        Xw = X
        for k in range(rounds):
            U = np.linalg.eigh(Xw @ X.T)[1][:, -rank:]
            if k + 1 < rounds:
                proj = U.T @ X
                r = np.sqrt(np.maximum(xn2 - np.einsum("ij,ij->j", proj, proj), 0.0))
                Xw = X * (1.0 / (1.0 + (r / (2.0 * np.median(r) + tiny)) ** 2)) ** 2
        proj = U.T @ W
        R[g] = np.maximum(norm2 - np.einsum("ij,ij->j", proj, proj), 0.0) / (F2 / 2)
    return R


def _polish(W, norm2, labels, n_groups, rank, rounds=3, unit2=1.0):
    """k-subspaces from ``labels`` (-1 = unlabelled): every point to its nearest subspace."""
    cur = labels
    R = _group_residuals(W, norm2, cur, n_groups, rank, unit2=unit2)
    for _ in range(rounds):
        if not np.isfinite(R).any():
            break
        new = R.argmin(axis=0)
        if np.array_equal(new, cur):
            break
        cur = new
        R = _group_residuals(W, norm2, cur, n_groups, rank, unit2=unit2)
    if not np.isfinite(R).any():
        return cur, np.full(labels.size, np.inf)
    return cur, R.min(axis=0)


@single_threaded
def motion_profile(seq, max_motions: int = 5, params=None, seed: int = 0,
                   rank: int = RANK) -> MotionProfile:
    """Labellings and residuals for C = 1 .. ``max_motions`` + 1 (see the module doc).

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    max_motions : int
    params : LaavParams, optional
        Atoms and graph settings (default preset).
    seed : int
        Seeds the atoms as :func:`laav.segment` does.
    rank : int

    Returns
    -------
    MotionProfile
        Rows of ``residuals``, ``epipolar`` and ``labels`` are the candidates; a candidate
        with no labelling (fewer fine models than C, or a group under 8 points) has inf
        rows.
    """
    ctx = _prepare(seq, max_motions, params, seed, rank)
    K = max_motions + 1
    cands = np.arange(1, K + 1)
    R = np.full((K, ctx.P), np.inf)
    E = np.full((K, ctx.P), np.inf)
    L = np.zeros((K, ctx.P), dtype=np.int64)
    for i, C in enumerate(cands):
        got = _evaluate(ctx, int(C))
        if got is not None:
            L[i], R[i], E[i] = got
    mcost = np.array([ctx.paid.get(int(C), np.nan) for C in cands])
    return MotionProfile(cands, R, E, L, mcost, ctx.noise2, ctx.n_segments, ctx.n_atoms,
                         ctx.fine_cost, ctx.fine_sizes)


@dataclass(eq=False)
class _Context:
    pts: np.ndarray
    W: np.ndarray
    norm2: np.ndarray
    point_fine: np.ndarray
    states: dict
    paid: dict
    noise2: float
    n_segments: int
    n_atoms: int
    fine_cost: np.ndarray
    fine_sizes: np.ndarray
    rank: int
    pairs: np.ndarray
    unit2: float

    @property
    def P(self) -> int:
        return self.pts.shape[1]


def _prepare(seq, max_motions, params, seed, rank) -> _Context:
    """Atoms, graph, multicut and the greedy merges: everything before the candidates."""
    from .atoms import Neighbourhoods, build_atoms
    from .coarse import point_labels_from_atoms
    from .graph import atom_graph
    from .multicut import solve_multicut
    from .params import LaavParams
    from .pipeline import _stage_rngs
    from .refine import frame_pairs, trajectory_matrix
    from .voting import unit2

    if not isinstance(seq, Sequence):
        seq = Sequence(np.asarray(seq, dtype=np.float64))
    p = LaavParams() if params is None else params
    pts = seq.points
    F, P, _ = pts.shape
    rng = np.random.default_rng(_stage_rngs(seed)["atoms"])
    D = Neighbourhoods(pts)
    atoms = build_atoms(seq, p, rng, D)
    graph = atom_graph(seq, atoms, p, D)
    kmin = max_motions + 1
    mc = solve_multicut(graph, kmin)
    fine = mc.multicut_labels if mc.n_segments > kmin else mc.atom_labels
    M = int(fine.max()) + 1 if fine.size else 0
    point_fine = point_labels_from_atoms(atoms, fine) if M else np.full(P, -1)
    res = [np.ravel(r) for r in atoms.residuals if np.size(r)]
    noise2 = float(np.median(np.concatenate(res)) ** 2) if res else 0.0
    W = trajectory_matrix(pts)  # origin at the points' corner: translation-free
    norm2 = np.einsum("ij,ij->j", W, W)
    # merge costs in the span of the leading directions (C motions span at most 4C)
    d = min(2 * F, rank * (max_motions + 1) + rank)
    U0 = np.linalg.svd(W, full_matrices=False)[0][:, :d]
    states, paid, fine_cost, sizes = _greedy_merge(U0.T @ W, point_fine, M, rank, max_motions + 1)
    return _Context(pts, W, norm2, point_fine, states, paid, noise2, mc.n_segments,
                    atoms.n_atoms, fine_cost, sizes, rank, frame_pairs(F, 12), unit2(p))


def _evaluate(ctx: _Context, C: int):
    """(labels, subspace residuals, epipolar distances) of candidate C, None if it has no
    labelling."""
    from .refine import motion_distances, reassign_labels

    if C not in ctx.states:
        return None
    lab0 = np.full(ctx.P, -1, dtype=np.int64)
    for k, fines in enumerate(ctx.states[C]):
        lab0[np.isin(ctx.point_fine, fines)] = k
    lab, _ = _polish(ctx.W, ctx.norm2, lab0, C, ctx.rank, unit2=ctx.unit2)
    if C > 1 and np.bincount(lab, minlength=C).min() >= MIN_POINTS:
        lab, _ = reassign_labels(ctx.pts, lab, C, rounds=2, min_size=MIN_POINTS, unit2=ctx.unit2)
    R = _group_residuals(ctx.W, ctx.norm2, lab, C, ctx.rank, unit2=ctx.unit2).min(axis=0)
    Dm = motion_distances(ctx.pts, lab, C, ctx.pairs, ctx.unit2)
    E = np.where(np.isfinite(Dm), Dm, np.inf).min(axis=0)
    return lab, R, E



def _greedy_merge(Wp, point_fine, n_fine, rank, n_keep):
    """Merge fine models two at a time, always the pair whose union's rank-``rank`` fit
    adds the least residual (groups under MIN_POINTS points first, into their cheapest
    partner). Returns the groups (lists of fine models) present when n <= ``n_keep``
    remained, the cost of the merge that left n, the fine models' pairwise costs and sizes."""
    groups = {g: np.flatnonzero(point_fine == g) for g in range(n_fine)}
    groups = {g: m for g, m in groups.items() if m.size}
    S = {g: Wp[:, m] @ Wp[:, m].T for g, m in groups.items()}
    cost = {g: _tail_sum(S[g], rank) for g in groups}
    keys = sorted(groups)
    sizes = np.array([groups[g].size for g in keys])
    pair = {}
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            pair[(a, b)] = _tail_sum(S[a] + S[b], rank) - cost[a] - cost[b]
    fine_cost = np.zeros((len(keys), len(keys)))
    for (a, b), c in pair.items():
        fine_cost[keys.index(a), keys.index(b)] = fine_cost[keys.index(b), keys.index(a)] = c
    members = {g: [g] for g in groups}
    states, paid = {}, {}
    while True:
        small = [g for g in groups if groups[g].size < MIN_POINTS]
        if small and len(groups) > 1:
            s = min(small, key=lambda g: groups[g].size)
            (a, b), c = min(((k, v) for k, v in pair.items() if s in k), key=lambda kv: kv[1])
        else:
            if len(groups) <= n_keep:
                states[len(groups)] = [list(v) for v in members.values()]
            if len(groups) <= 1:
                break
            (a, b), c = min(pair.items(), key=lambda kv: kv[1])
            if len(groups) <= n_keep + 1:
                paid[len(groups) - 1] = c
        groups[a] = np.concatenate([groups[a], groups.pop(b)])
        S[a] = S[a] + S.pop(b)
        cost[a] = _tail_sum(S[a], rank)
        cost.pop(b)
        members[a] += members.pop(b)
        pair = {k: v for k, v in pair.items() if a not in k and b not in k}
        for g in groups:
            if g != a:
                pair[(min(a, g), max(a, g))] = _tail_sum(S[a] + S[g], rank) - cost[a] - cost[g]
    return states, paid, fine_cost, sizes


def profile_levels(residuals: np.ndarray, epipolar: np.ndarray, unit2: float = 1.0) -> np.ndarray:
    """(2, K) log of the trimmed mean of each candidate's subspace and epipolar residuals
    (NaN where a candidate could not be formed), floored at 1e-6 px^2 times ``unit2``
    (:mod:`laav.refine`)."""
    out = np.full((2, residuals.shape[0]), np.nan)
    for i, rows in enumerate((residuals, epipolar)):
        for c, r in enumerate(rows):
            if np.isfinite(r).all() and r.size:
                k = max(1, int(TRIM * r.size))
                out[i, c] = np.log(np.mean(np.sort(r)[:k]) + 1e-6 * unit2)
    return out


def _column(levels):
    """Candidate C (1-based) -> its (2,) log levels (NaN when unknown), from a (2, K) array
    or from such a function."""
    if callable(levels):
        return levels
    levels = np.asarray(levels, dtype=float)

    def col(c):
        return levels[:, c - 1] if 1 <= c <= levels.shape[1] else np.full(2, np.nan)
    return col


def step_features(levels, C: int) -> np.ndarray:
    """Log gains of going from C to C + 1 and from C + 1 to C + 2 (0 where unknown).

    ``levels``: (2, K) array of :func:`profile_levels`, or a function of C giving its column.
    """
    col = _column(levels)

    def gain(c):
        a, b = col(c), col(c + 1)
        return a - b if np.isfinite(a).all() and np.isfinite(b).all() else np.zeros(2)
    return np.concatenate([gain(C), gain(C + 1)])


def decide(levels, noise2: float, max_motions: int, weights=None, bias=None,
           one_motion_ratio=None, unit2: float = 1.0) -> tuple[int, np.ndarray, str]:
    """The sequential test: (C, score of each step C -> C + 1, why).

    ``levels``: (2, K) array of :func:`profile_levels` (K >= ``max_motions`` + 1), or a
    function of C giving its column, called only for the candidates a step needs (C, C + 1
    and C + 2). Step scores are > 0 where the test adds a motion: for 1 -> 2 the log of one
    motion's epipolar level over ``one_motion_ratio`` x ``noise2``, for later steps the
    linear score; NaN for steps not reached. ``unit2`` scales the 1e-12 px^2 floors of
    the first step's logs (:mod:`laav.refine`).
    """
    col = _column(levels)
    w = np.asarray(STEP_WEIGHTS if weights is None else weights, dtype=float)
    b = STEP_BIAS if bias is None else bias
    k1 = ONE_MOTION_RATIO if one_motion_ratio is None else one_motion_ratio
    scores = np.full(max(max_motions - 1, 0), np.nan)
    if max_motions < 2:
        return 1, scores, "max_motions is 1"
    e1 = float(np.exp(col(1)[1]))
    tiny = 1e-12 * unit2
    scores[0] = float(np.log(e1 + tiny) - np.log(k1 * noise2 + tiny))
    if scores[0] <= 0:
        return 1, scores, (f"one motion explains the points: epipolar level {e1:.3g} px^2 <= "
                           f"{k1:g} x noise {noise2:.3g} px^2")
    C = 2
    while C < max_motions:
        if not np.isfinite(col(C + 1)).all():
            return C, scores, f"no labelling with {C + 1} motions of >= {MIN_POINTS} points each"
        g = step_features(col, C)
        scores[C - 1] = float(w @ g + b)
        if scores[C - 1] <= 0:
            return C, scores, (f"going to {C + 1} motions gains too little (log gains subspace "
                               f"{g[0]:.2f}, epipolar {g[1]:.2f}; step score {scores[C - 1]:.2f} <= 0)")
        C += 1
    return C, scores, f"every step up to max_motions = {max_motions} gained enough"


@dataclass(frozen=True)
class MotionCount:
    """The estimated number of motions and why.

    Attributes
    ----------
    n_motions : int
        The estimate.
    candidates : tuple of int
        C = 1 .. ``max_motions`` + 1, the labellings scored.
    subspace_level, epipolar_level : tuple of float
        Per candidate: 95 % trimmed mean squared distance (px^2) of the points to their
        motion's rank-4 trajectory subspace, and mean Sampson distance (px^2) to the
        nearest motion's fundamental matrices. NaN: not needed by the test (candidates are
        evaluated only as far as the test goes: C + 2 at most) or no labelling with that
        many motions.
    step_scores : tuple of float
        Per step C -> C + 1 (C = 1 .. ``max_motions`` - 1): > 0 where a motion was
        added; NaN for steps not reached.
    noise : float
        The atoms' noise level (px^2) the one-motion test compares with.
    reason : str
        Why the test stopped at ``n_motions``.
    seed : int
    seconds : float
    """

    n_motions: int
    candidates: tuple
    subspace_level: tuple
    epipolar_level: tuple
    step_scores: tuple
    noise: float
    reason: str
    seed: int = 0
    seconds: float = 0.0


def estimate_motions(seq_or_points, max_motions: int = 5, random_state=0, params=None) -> MotionCount:
    """Estimate the number of independent motions C of a sequence.

    Parameters
    ----------
    seq_or_points : Sequence or ndarray of shape (F, P, 2)
    max_motions : int, >= 1
        Largest C considered.
    random_state : None, int, numpy Generator or RandomState
        Seeds the atoms (as ``segment``'s ``random_state``); 0 by default.
    params : LaavParams, optional
        For the atoms and the graph (the default preset otherwise).

    Returns
    -------
    MotionCount

    Raises
    ------
    ValueError
        For a bad ``max_motions`` or too few points (fewer than 8 per motion of C = 2;
        a smaller sequence has C = 1 only if said so); on a sequence with missing entries,
        when fewer than 16 tracks are seen in every frame.

    Notes
    -----
    On incomplete data the estimate runs on the tracks seen in every frame
    (:meth:`Sequence.complete`): the profile fits whole trajectories. The ``reason`` says
    so and how many tracks that was; a motion none of whose tracks is complete is missed.
    """
    import time

    from ._random import as_seed

    if isinstance(max_motions, bool) or not isinstance(max_motions, (int, np.integer)) or max_motions < 1:
        raise ValueError(f"max_motions must be an integer >= 1, got {max_motions!r}")
    max_motions = int(max_motions)
    if not isinstance(seq_or_points, Sequence):
        seq_or_points = Sequence(np.asarray(seq_or_points, dtype=np.float64))
    basis = ""
    if not seq_or_points.is_complete:
        # the profile fits whole trajectories (rank-4 subspaces): on incomplete data it runs on
        # the tracks seen in every frame, when they are enough (a motion every one of whose
        # tracks is broken is then not counted: said in the reason)
        full = np.flatnonzero(seq_or_points.visible.all(axis=0))
        P_all = seq_or_points.n_points
        if full.size < 2 * MIN_POINTS:
            raise ValueError(
                f"{seq_or_points.source}: only {full.size} of the {P_all} tracks are seen in every frame; "
                f"estimating the number of motions fits whole trajectories and needs at least "
                f"{2 * MIN_POINTS} complete tracks: give C (--motions N)")
        seq_or_points = seq_or_points.subset(full)
        basis = (f"; estimated on the {full.size} of {P_all} tracks seen in every frame (the estimate "
                 "fits whole trajectories; a motion none of whose tracks is complete is not counted)")
    P = seq_or_points.n_points
    if P < 2 * MIN_POINTS:
        raise ValueError(f"{seq_or_points.source}: {P} points are too few to estimate the number "
                         f"of motions (needs at least {2 * MIN_POINTS}: {MIN_POINTS} per motion of two)")
    max_motions = min(max_motions, P // MIN_POINTS)
    seed = as_seed(random_state)
    t = time.perf_counter()
    C, scores, levels, noise2, why = _estimate(seq_or_points, max_motions, params, seed)
    return MotionCount(
        n_motions=int(C), candidates=tuple(range(1, max_motions + 2)),
        subspace_level=tuple(float(v) for v in np.exp(levels[0])),
        epipolar_level=tuple(float(v) for v in np.exp(levels[1])),
        step_scores=tuple(float(v) for v in scores), noise=noise2, reason=why + basis,
        seed=seed, seconds=time.perf_counter() - t)


@single_threaded
def _estimate(seq, max_motions, params, seed):
    """The profile's candidates evaluated only as the sequential test reaches them."""
    ctx = _prepare(seq, max_motions, params, seed, RANK)
    K = max_motions + 1
    levels = np.full((2, K), np.nan)
    done = set()

    def col(c):
        if not 1 <= c <= K:
            return np.full(2, np.nan)
        if c not in done:
            done.add(c)
            got = _evaluate(ctx, c)
            if got is not None:
                levels[:, c - 1] = profile_levels(got[1][None], got[2][None], ctx.unit2)[:, 0]
        return levels[:, c - 1]

    C, scores, why = decide(col, ctx.noise2, max_motions, unit2=ctx.unit2)
    return C, scores, levels, float(ctx.noise2), why
