"""Estimating the number of motions C when it is not known: :func:`estimate_motions`.

**Profile** (:func:`motion_profile`): LAAV's own segmentation (:class:`laav.Pipeline`, same
seed; atoms and graph computed once, the later stages again for every C) gives one
labelling for every C = 2 .. ``max_motions + 1`` (C = 1: every point in one motion).
Each is scored twice per point: its squared distance to its motion's robust rank-4
trajectory subspace (``residuals``; an affine camera's rigid motion spans 4 dimensions)
and its mean Sampson distance to the nearest motion's fundamental matrices over 12 frame
pairs (``epipolar``). The level of C is the 95 % trimmed mean of each. (Until 2026-11-30
the labellings came from a greedy merge of the multicut's segments by subspace residual,
without Random Voting: cheaper, but right at the true C on only 46 % of the three-motion
sequences, and the test then found 8 of 35 three-motion sequences; ``docs/bench/motions.md``.)

**Decision** (:func:`decide`), a sequential test: start at C = 1 and add a motion while
the test says the next one is real.

* 1 -> 2: a second motion unless one motion's epipolar level is within
  ``ONE_MOTION_RATIO`` x the noise (the squared median residual of the atoms' affine fits).
* C -> C + 1 (C >= 2): add when ``STEP_WEIGHTS . g + STEP_BIAS > 0``, ``g`` the log gains
  (level of C over level of C + 1) of both residuals at this step and the next, read above
  the tracks' measured pixel noise (:func:`noise_corrected`; since 2026-12-06), and the
  lossy coding length per point the step saves (the labellings' trajectories coded group by
  group, as LAAV's joint merge does); a linear (logistic) model-selection criterion, a
  penalty per extra motion in effect.

The constants were fitted on Hopkins155, as it is and with 0.5 and 1 px of pixel noise
added, by ``benchmarks/motions.py``, whose report
(``docs/bench/motions.md``) gives the 5-fold cross-validated accuracy (folds grouped by
source video) and the alternatives measured (eigengap, residual-ratio thresholds, label
stability across seeds, the multicut's own count).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np

from ._sequence import MIN_POINTS, LaavWarning, Sequence, check_degenerate
from ._threads import single_threaded
from .refine import robust_subspace

__all__ = ["MotionCount", "MotionProfile", "motion_profile", "estimate_motions", "complete_window", "decide",
           "profile_levels", "noise_corrected", "noise_floors", "one_motion_check",
           "one_motion_features"]

RANK = 4  # an affine camera's rigid motion spans a 4-dimensional trajectory subspace
#: Fitted by benchmarks/motions.py on all 155 Hopkins155 sequences, seed-0 profiles at pixel
#: noise σ = 0, 0.5 and 1 px (since 2026-12-06; before: σ = 0 only, which called nearly
#: every noisy three-motion sequence two); weights of the noise-corrected log gains
#: (subspace, epipolar) at a step and at the next step, and of the coding length per point
#: saved by the step (:func:`step_features`, :func:`noise_corrected`).
STEP_WEIGHTS = (-0.5946, 2.4186, -0.1674, 0.7111, 0.8341)
STEP_BIAS = -1.6548
#: The levels' noise floors, in units of the tracks' noise variance σ̂²
#: (:func:`laav.noise.estimate_noise`): with N(0, σ²) noise on every coordinate a point's
#: squared distance (per frame) to its motion's rank-4 trajectory subspace is about 2σ²
#: (2F - 4 of 2F dimensions, over F frames), and its Sampson distance to its motion's
#: fundamental matrix about σ² (first order). Set a priori, not fitted.
NOISE_FLOORS = (2.0, 1.0)
#: What is left of a floor (:func:`noise_corrected`): a level at or under its floor counts as
#: this share of it, so that gains among labellings all within the noise stay small. The
#: best of 0.1 / 0.3 / 1 / 3 / no correction on all the data, with the weights
#: (benchmarks/motions.py); inside its cross-validation the folds chose 0.1 four times and 1
#: once (an unstable choice: held out 91.6 / 87.1 / 83.9 % at σ = 0 / 0.5 / 1 px; with 0.3
#: fixed 91.6 / 87.7 / 81.3 %).
FLOOR_SHARE = 0.3
#: One motion when its epipolar level <= this x the atoms' noise level (px^2).
ONE_MOTION_RATIO = 0.05
#: The one-motion check (:func:`one_motion_check`, since 2026-12-06): weights of the step
#: 1 -> 2's :func:`step_features` on noise-corrected levels and of log(e1 / noise), the first
#: step's own statistic; a logistic model of "more than one motion" fitted by
#: benchmarks/motions_one.py on Hopkins155's 155 sequences (more than one motion) and each of
#: their motions alone (one motion: the 134 motions of its 50 full sequences with at least 16
#: points), at pixel noise σ = 0, 0.5 and 1 px. It does not decide C (Hopkins155 would lose
#: 6-34 right estimates: docs/bench/motions_one.md); an estimate of two motions that it calls
#: one is flagged (:attr:`MotionCount.close_call`).
ONE_CHECK_WEIGHTS = (0.3714, 0.6502, -0.3222, 0.1352, 0.2785, 0.6391)
ONE_CHECK_BIAS = 0.1368
#: A step C -> C + 1 (C >= 2) whose score is within this of 0 is a *close call*
#: (:attr:`MotionCount.close_call`): the logistic criterion puts the added motion's chance
#: between 27 and 73 %. A logit of 1, the score's natural unit, not fitted; but the counts
#: below were seen at several margins before it was fixed, so they do not test it held out. On
#: Hopkins155 (the all-data constants; docs/bench/motions_close_calls.md) 17 of 155 estimates
#: were close calls and 5 of them wrong, against 6 wrong among the other 138.
CLOSE_CALL_LOGIT = 1.0
TRIM = 0.95  # share of points (best explained) in a level
#: The estimate runs LAAV on at most this many tracks (a seeded random subset; Hopkins155's
#: sequences have at most 556): it segments the sequence up to four times, and a motion
#: with 3 % of the points still has 30 of them.
MAX_ESTIMATE_POINTS = 1000


#: What the profile's pipeline never runs, whatever the caller's settings: the descent on the
#: joint score and the candidates' cleaning before the selection (``rv_descent``,
#: ``rv_select_descent``, 2026-12-02), a second trial per missing-motion start and the
#: unpolished descent (``rv_missing_trials``, ``rv_descent_from_trial``, 2026-12-03) and the
#: gate for the missing-motion starts (``rv_missing_gate``, 2026-12-05) and its veto
#: (``rv_outlier_veto``, 2026-12-06), added after its constants were fitted.
NOT_FITTED = {"rv_descent": False, "rv_select_descent": 0.0, "rv_missing_trials": 1,
              "rv_descent_from_trial": False, "rv_missing_gate": 0.0, "rv_outlier_veto": False}


def profile_params():
    """The LAAV settings the profile runs with when none are given: those its constants
    (:data:`STEP_WEIGHTS`, :data:`STEP_BIAS`) were fitted with, LAAV's own chain
    (:meth:`laav.LaavParams.own_chain`, the default since 2026-12-02: the joint
    coding-length merge, subspace votes, LAAV's own trials). The count is right more often on its labellings
    (``docs/bench/motions.md``, 2026-12-01: 92.3 % of Hopkins155 held out with the coding
    length feature, 90.3 % without it, against 87.7 % with the settings used before, the
    epipolar merge on 2C fine models with plain RV beside LAAV's trial). Without the
    descent on the joint score, the candidates' cleaning, the second missing-motion
    trials and their gate (:data:`NOT_FITTED`, added after the fit): the profile's labellings stay those
    its constants were fitted on."""
    from .params import LaavParams

    return LaavParams.own_chain(**NOT_FITTED)


@dataclass(frozen=True, eq=False)
class MotionProfile:
    """How well C motions explain the trajectories, for C = 1 .. max_motions + 1."""

    candidates: np.ndarray      # (K,) C values
    residuals: np.ndarray       # (K, P) squared distance (px^2) of each point to its motion
    epipolar: np.ndarray        # (K, P) mean Sampson distance (px^2) to the nearest motion
    labels: np.ndarray          # (K, P) the labelling behind each row (LAAV's, seeded)
    coding: np.ndarray          # (K,) coding length of each labelling, nats per point (NaN: none)
    noise2: float               # px^2: median squared affine residual of the atoms' members
    n_atoms: int
    sigma: float = 0.0          # px: the tracks' noise, laav.noise.estimate_noise


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
        U = robust_subspace(W[:, mem], norm2[mem], rank, rounds, tiny)  # (residuals: not per frame)
        proj = U.T @ W
        R[g] = np.maximum(norm2 - np.einsum("ij,ij->j", proj, proj), 0.0) / (F2 / 2)
    return R


@single_threaded
def motion_profile(seq, max_motions: int = 5, params=None, seed: int = 0,
                   rank: int = RANK) -> MotionProfile:
    """Labellings and residuals for C = 1 .. ``max_motions`` + 1 (see the module doc).

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    max_motions : int
    params : LaavParams, optional
        LAAV's settings (:func:`profile_params` when None).
    seed : int
        LAAV's seed, as :func:`laav.segment`'s.
    rank : int

    Returns
    -------
    MotionProfile
        Rows of ``residuals``, ``epipolar`` and ``labels`` are the candidates; a candidate
        with no labelling (too few points for C motions, or a motion under 8 points) has
        inf rows.
    """
    ctx = _prepare(seq, max_motions, params, seed, rank)
    K = max_motions + 1
    cands = np.arange(1, K + 1)
    R = np.full((K, ctx.P), np.inf)
    E = np.full((K, ctx.P), np.inf)
    L = np.zeros((K, ctx.P), dtype=np.int64)
    B = np.full(K, np.nan)
    for i, C in enumerate(cands):
        got = _evaluate(ctx, int(C))
        if got is not None:
            L[i], R[i], E[i], B[i] = got
    return MotionProfile(cands, R, E, L, B, ctx.noise2, ctx.n_atoms, ctx.sigma)


@dataclass(eq=False)
class _Context:
    pipe: object  # laav.Pipeline at C = 2: atoms and graph, reused for every C
    W: np.ndarray
    norm2: np.ndarray
    noise2: float
    n_atoms: int
    rank: int
    pairs: np.ndarray
    unit2: float
    eps: float  # the coding length's distortion (px): LAAV's coding_eps
    sigma: float  # px: the tracks' noise (laav.noise.estimate_noise)
    results: dict = field(default_factory=dict)  # C -> the LaavResult behind candidate C

    @property
    def P(self) -> int:
        return self.W.shape[1]


def _prepare(seq, max_motions, params, seed, rank) -> _Context:
    """LAAV at C = 2 (its atoms and graph serve every C) and the trajectory matrix."""
    from .noise import estimate_noise
    from .pipeline import Pipeline
    from .refine import frame_pairs, trajectory_matrix
    from .voting import unit2

    if not isinstance(seq, Sequence):
        seq = Sequence(np.asarray(seq, dtype=np.float64))
    with warnings.catch_warnings():  # a candidate's warnings are not the caller's
        warnings.simplefilter("ignore", LaavWarning)
        # never the descent nor the cleaning (NOT_FITTED): the profile's constants were
        # fitted on labellings without them, whatever the caller's settings
        try:  # (the pipeline below would say "for 2 motions": the caller asked for "auto")
            check_degenerate(seq, 2)
        except ValueError:  # its one refusal: fewer than 2 distinct trajectories
            raise ValueError(f"{seq.source}: fewer than 2 distinct trajectories: nothing to "
                             "estimate the number of motions from (it compares one motion with "
                             "a 2-motion labelling)") from None
        pipe = Pipeline(seq, 2, profile_params() if params is None
                        else params.replace(**NOT_FITTED), seed)
    atoms = pipe.result.atoms
    res = [np.ravel(r) for r in atoms.residuals if np.size(r)]
    noise2 = float(np.median(np.concatenate(res)) ** 2) if res else 0.0
    W = trajectory_matrix(seq.points)  # origin at the points' corner: translation-free
    norm2 = np.einsum("ij,ij->j", W, W)
    return _Context(pipe, W, norm2, noise2, atoms.n_atoms, rank, frame_pairs(seq.n_frames, 12),
                    unit2(pipe.params), float(pipe.params.coding_eps),
                    float(estimate_noise(seq.points)))


def _evaluate(ctx: _Context, C: int):
    """(labels, subspace residuals, epipolar distances, coding length per point) of candidate
    C: LAAV's labels with C motions; None when there is no such labelling (too few points,
    a motion under 8)."""
    from .coding import labelling_coding_length
    from .refine import motion_distances

    if C == 1:
        lab = np.zeros(ctx.P, dtype=np.int64)
    else:
        if C * MIN_POINTS > ctx.P:
            return None
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", LaavWarning)
                ctx.results[C] = ctx.pipe.update(n_motions=C)
            lab = ctx.results[C].labels
        except ValueError:  # the sequence cannot hold C motions (degenerate-input checks)
            return None
        if (lab < 0).any() or np.bincount(lab, minlength=C).min() < MIN_POINTS:
            return None
    R = _group_residuals(ctx.W, ctx.norm2, lab, C, ctx.rank, unit2=ctx.unit2).min(axis=0)
    Dm = motion_distances(ctx.pipe.seq.points, lab, C, ctx.pairs, ctx.unit2)
    E = np.where(np.isfinite(Dm), Dm, np.inf).min(axis=0)
    P = lab.size
    return lab, R, E, labelling_coding_length(ctx.pipe.seq.points, lab, C, ctx.eps) / P


def profile_levels(residuals: np.ndarray, epipolar: np.ndarray, unit2: float = 1.0, *,
                   coding=None) -> np.ndarray:
    """(3, K): log of the trimmed mean of each candidate's subspace and epipolar residuals,
    floored at 1e-6 px^2 times ``unit2`` (:mod:`laav.refine`), and its coding length per
    point (``coding``, (K,) nats; NaN rows when not given). NaN where a candidate could not
    be formed."""
    out = np.full((3, residuals.shape[0]), np.nan)
    for i, rows in enumerate((residuals, epipolar)):
        for c, r in enumerate(rows):
            if np.isfinite(r).all() and r.size:
                k = max(1, int(TRIM * r.size))
                out[i, c] = np.log(np.mean(np.sort(r)[:k]) + 1e-6 * unit2)
    if coding is not None:
        out[2] = np.where(np.isfinite(out[:2]).all(axis=0), np.asarray(coding, dtype=float), np.nan)
    return out


def _column(levels):
    """Candidate C (1-based) -> its (3,) levels (NaN when unknown), from a (3, K) array
    or from such a function."""
    if callable(levels):
        return levels
    levels = np.asarray(levels, dtype=float)

    def col(c):
        return levels[:, c - 1] if 1 <= c <= levels.shape[1] else np.full(levels.shape[0], np.nan)
    return col


def step_features(levels, C: int) -> np.ndarray:
    """(5,) gains of the step C -> C + 1: the log gains of the subspace and epipolar levels
    from C to C + 1, the same from C + 1 to C + 2, and the coding length per point saved
    from C to C + 1 (0 where unknown).

    ``levels``: (3, K) array of :func:`profile_levels`, or a function of C giving its column.
    """
    col = _column(levels)

    def gain(c):
        a, b = col(c), col(c + 1)
        return a - b if np.isfinite(a).all() and np.isfinite(b).all() else np.zeros(3)
    g, g1 = gain(C), gain(C + 1)
    return np.array([g[0], g[1], g1[0], g1[1], g[2]])


def noise_floors(sigma: float) -> tuple[float, float]:
    """(subspace, epipolar) noise floors (px^2) of the levels for tracks of noise ``sigma`` px:
    :data:`NOISE_FLOORS` x ``sigma``^2."""
    return NOISE_FLOORS[0] * sigma ** 2, NOISE_FLOORS[1] * sigma ** 2


def noise_corrected(levels, floors=(0.0, 0.0), share=None):
    """``levels`` ((3, K) of :func:`profile_levels`, or a function of C giving its column)
    with the noise taken out of its two residual levels: each level ``l = log(m)`` becomes
    ``log(max(m - f, 0) + share f)``, ``f`` its floor (``floors``, px^2, e.g.
    :func:`noise_floors`). Under pixel noise every candidate's level sits near the floor,
    so the log gains between labellings shrink towards 0 whatever they explain; measured
    above the floor they keep their size. ``share``: :data:`FLOOR_SHARE` when None.
    Unchanged where a floor is 0; NaN stays NaN."""
    share = FLOOR_SHARE if share is None else share
    if not any(f > 0 for f in floors):
        return levels
    col = _column(levels)

    def corrected(c):
        v = np.array(col(c), dtype=float)
        for i, f in enumerate(floors):
            if f > 0 and np.isfinite(v[i]):
                v[i] = np.log(max(np.exp(v[i]) - f, 0.0) + share * f)
        return v
    if callable(levels):
        return corrected
    K = np.asarray(levels).shape[1]
    return np.stack([corrected(c) for c in range(1, K + 1)], axis=1)


def one_motion_check(levels, noise2: float, sigma: float = 0.0, weights=None, bias=None) -> float:
    """Logit that the tracks hold more than one motion, from the step 1 -> 2 as a whole: the
    five :func:`step_features` of the step on the levels :func:`noise_corrected` for the
    tracks' noise ``sigma`` (px), and the one-motion test's own statistic, log of one motion's
    epipolar level over ``noise2`` (px^2; :func:`decide`). ``levels``: (3, K) of
    :func:`profile_levels` or a function of C giving its column (C = 1, 2 and 3 are read).
    Weights :data:`ONE_CHECK_WEIGHTS`, :data:`ONE_CHECK_BIAS` unless given. NaN when C = 1 or
    2 has no labelling.

    Unlike :func:`decide`'s first step, whose ratio holds on noise-free synthetic tracks only
    (it calls 4 of 130 of Hopkins155's motions taken alone one motion, none with 0.5 px of
    noise added), this was fitted on real single motions, noisy ones included; see
    :data:`ONE_CHECK_WEIGHTS`.
    """
    x = one_motion_features(levels, noise2, sigma)
    if not np.isfinite(x).all():
        return float("nan")
    w = np.asarray(ONE_CHECK_WEIGHTS if weights is None else weights, dtype=float)
    return float(w @ x + (ONE_CHECK_BIAS if bias is None else bias))


def one_motion_features(levels, noise2: float, sigma: float = 0.0) -> np.ndarray:
    """(6,) what :func:`one_motion_check` weighs (its arguments): the step 1 -> 2's
    :func:`step_features` on the noise-corrected levels, then log(e1 / ``noise2``); NaN
    when C = 1 or 2 has no labelling, or without an atoms' noise level (``noise2`` 0: atoms
    with no residual, as on motions of 16-25 points; the log ratio was then ~29, worth
    +5.5 to the logit)."""
    col = _column(levels)
    if not (noise2 > 0 and np.isfinite(col(1)).all() and np.isfinite(col(2)).all()):
        return np.full(6, np.nan)
    steps = _column(noise_corrected(col, noise_floors(sigma)))
    return np.r_[step_features(steps, 1), col(1)[1] - np.log(noise2)]  # (the levels are logs)


def decide(levels, noise2: float, max_motions: int, weights=None, bias=None,
           one_motion_ratio=None, unit2: float = 1.0, sigma: float = 0.0,
           floor_share=None) -> tuple[int, np.ndarray, str]:
    """The sequential test: (C, score of each step C -> C + 1, why).

    ``levels``: (3, K) array of :func:`profile_levels` (K >= ``max_motions`` + 1), or a
    function of C giving its column, called only for the candidates a step needs (C, C + 1
    and C + 2). Step scores are > 0 where the test adds a motion: for 1 -> 2 the log of one
    motion's epipolar level over ``one_motion_ratio`` x ``noise2``, for later steps the
    linear score; NaN for steps not reached. ``unit2`` scales the 1e-12 px^2 floors of
    the first step's logs (:mod:`laav.refine`). ``sigma`` (px, the tracks' noise): the later
    steps read the levels :func:`noise_corrected` for it (``floor_share``: its ``share``,
    :data:`FLOOR_SHARE` when None); the one-motion step reads them as they are.
    """
    col = _column(levels)
    steps = _column(noise_corrected(col, noise_floors(sigma), floor_share))
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
        g = step_features(steps, C)
        scores[C - 1] = float(w @ g + b)
        if scores[C - 1] <= 0:
            above = f" above the noise (σ̂ = {sigma:.2g} px)" if sigma >= 0.1 else ""
            return C, scores, (f"going to {C + 1} motions gains too little (log gains{above} "
                               f"subspace {g[0]:.2f}, epipolar {g[1]:.2f}, coding length {g[4]:.2f} "
                               f"nats per point; step score {scores[C - 1]:.2f} <= 0)")
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
    coding_length : tuple of float
        Per candidate: the lossy coding length of the trajectories grouped by its labelling
        (nats per point, distortion ``coding_eps``); NaN as the levels.
    step_scores : tuple of float
        Per step C -> C + 1 (C = 1 .. ``max_motions`` - 1): > 0 where a motion was
        added; NaN for steps not reached.
    noise : float
        The atoms' noise level (px^2) the one-motion test compares with.
    reason : str
        Why the test stopped at ``n_motions``.
    seed : int
    seconds : float
    sigma : float
        The tracks' pixel noise (px, :func:`laav.noise.estimate_noise`) the later steps
        took out of the levels (:func:`noise_corrected`).
    one_motion_score : float
        For an estimate of two motions, the one-motion check's logit that there is more
        than one (:func:`one_motion_check`); NaN otherwise, or when it cannot be formed. At
        or below 0 the estimate is flagged (:attr:`close_call`: compare C = 1). The check
        reads the candidates C = 1-3: with ``max_motions`` 2 their levels are evaluated for
        it (LAAV at C = 3 once more) and shown.
    """

    n_motions: int
    candidates: tuple
    subspace_level: tuple
    epipolar_level: tuple
    coding_length: tuple
    step_scores: tuple
    noise: float
    reason: str
    seed: int = 0
    seconds: float = 0.0
    sigma: float = 0.0
    one_motion_score: float = float("nan")

    @property
    def deciding_step(self) -> tuple[int, float] | None:
        """``(C, score)`` of the step C -> C + 1 (C >= 2, scored by the logistic criterion)
        nearest to 0 among the two that decided: the last motion added and the step the test
        stopped at; None when neither was scored (C = 1, or no labelling with C + 1 motions)."""
        C, st = self.n_motions, self.step_scores
        steps = [(c, float(st[c - 1])) for c in (C - 1, C)
                 if c >= 2 and c - 1 < len(st) and np.isfinite(st[c - 1])]
        return min(steps, key=lambda cs: abs(cs[1])) if steps else None

    @property
    def close_call(self) -> str:
        """A sentence when the estimate was a close call (:data:`CLOSE_CALL_LOGIT`): which C
        to compare, with the criterion's chance for the motion in question; and one when an
        estimate of two motions is one the one-motion check calls one
        (:attr:`one_motion_score` <= 0): compare C = 1. "" otherwise."""
        said = []
        step = self.deciding_step
        if step is not None and abs(step[1]) < CLOSE_CALL_LOGIT:
            c, score = step
            chance = 100.0 / (1.0 + np.exp(-score))
            other = c + 1 if c == self.n_motions else c
            said.append(f"a close call: the test gave motion {c + 1} a {chance:.0f} % chance "
                        f"(step score {score:+.2f}); compare C = {other}")
        one = self.one_motion_score
        if self.n_motions == 2 and np.isfinite(one) and one <= 0:
            chance = 100.0 / (1.0 + np.exp(-one))
            said.append(f"one motion may explain the tracks: the one-motion check gave a second "
                        f"motion a {chance:.0f} % chance (score {one:+.2f}); compare C = 1")
        return "; ".join(said)

    def explain(self) -> str:
        """:attr:`reason`, and :attr:`close_call` when it is one."""
        return self.reason + (f"; {self.close_call}" if self.close_call else "")


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
        For the LAAV runs of the profile (:func:`profile_params` otherwise: the settings
        its constants were fitted with).

    Returns
    -------
    MotionCount

    Raises
    ------
    ValueError
        For a bad ``max_motions`` or too few points (fewer than 8 per motion of C = 2;
        a smaller sequence has C = 1 only if said so), fewer than 2 distinct trajectories;
        on a sequence with missing entries, when fewer than 16 tracks are seen in every frame
        of a stretch of frames.

    Notes
    -----
    On incomplete data the estimate runs on the tracks seen in every frame
    (:meth:`Sequence.complete`): the profile fits whole trajectories. The ``reason`` says
    so and how many tracks that was; a motion none of whose tracks is complete is missed.
    """
    return _estimate_motions(seq_or_points, max_motions, random_state, params)[0]


#: Shortest stretch of frames (or the whole sequence when shorter) the count is estimated
#: on when no track spans every frame (incomplete tracks); set a priori.
MIN_WINDOW_FRAMES = 10
#: Stretch lengths tried on incomplete tracks: at most this many, spread geometrically.
_WINDOW_LENGTHS = 24


def complete_window(visible: np.ndarray, min_tracks: int = 2 * MIN_POINTS,
                    min_frames: int = MIN_WINDOW_FRAMES) -> tuple[int, int, np.ndarray] | None:
    """The stretch of frames ``[start, stop)`` and the tracks seen in every one of its frames
    that hold the most entries (tracks x frames), among stretches of at least
    ``min(min_frames, F)`` frames seen whole by at least ``min_tracks`` tracks.

    ``visible``: (F, P) bool. Returns ``(start, stop, tracks)`` (tracks: int indices), or
    None when no stretch qualifies. The whole sequence wins whenever its complete tracks
    hold the most entries. Deterministic; ties go to the longer, then the earlier stretch.
    """
    vis = np.asarray(visible, dtype=bool)
    F, P = vis.shape
    lo = min(int(min_frames), F)
    cs = np.zeros((F + 1, P), dtype=np.int32)
    np.cumsum(vis, axis=0, out=cs[1:])
    lengths = np.unique(np.round(np.geomspace(lo, F, min(_WINDOW_LENGTHS, F - lo + 1))).astype(int))
    best = None  # (entries, length, -start)
    for L in lengths[::-1]:  # longest first: a tie keeps the longer stretch
        n = ((cs[L:] - cs[:-L]) == L).sum(axis=1)  # (F - L + 1,) tracks seen throughout
        a = int(np.argmax(n))  # the earliest of the best starts
        if n[a] >= min_tracks and (best is None or n[a] * L > best[0]):
            best = (int(n[a]) * int(L), int(L), a)
    if best is None:
        return None
    _, L, a = best
    return a, a + L, np.flatnonzero(cs[a + L] - cs[a] == L)


def _complete_window(seq: Sequence) -> tuple[Sequence, str]:
    """``seq`` cut to :func:`complete_window` (complete tracks), and the reason's note; a
    ``ValueError`` naming the file when no stretch has enough tracks."""
    P, F = seq.n_points, seq.n_frames
    got = complete_window(seq.visible)
    if got is None:
        lo = min(MIN_WINDOW_FRAMES, F)
        vis = seq.visible
        most = max(int(vis[a:a + lo].all(axis=0).sum()) for a in range(F - lo + 1))
        seen = (f"only {most} of the {P} tracks are seen in every frame" if lo == F else
                f"at most {most} of the {P} tracks are seen in every frame of a stretch of {lo} frames")
        raise ValueError(
            f"{seq.source}: {seen}; estimating the "
            f"number of motions fits whole trajectories and needs at least {2 * MIN_POINTS} "
            f"such tracks: give C (--motions N)")
    a, b, idx = got
    sub = seq.subset(idx)  # seen in every frame of a .. b - 1: complete there
    cut = Sequence(points=sub.points[a:b], labels=sub.labels, name=seq.name,
                   image_size=seq.image_size, source=seq.source)
    where = "every frame" if (a, b) == (0, F) else f"frames {a}-{b - 1} ({b - a} of {F})"
    return cut, (f"; estimated on the {idx.size} of {P} tracks seen in {where} (the estimate fits "
                 "whole trajectories; a motion none of whose tracks spans them is not counted)")


def _estimate_motions(seq_or_points, max_motions, random_state, params):
    """:func:`estimate_motions`, and LAAV's result with the estimated C when the estimate ran
    on the whole sequence (else None): :func:`laav.segment` with ``"auto"`` takes it instead
    of segmenting again (the same labels: :meth:`laav.Pipeline.update`)."""
    import time

    from ._random import as_seed

    if isinstance(max_motions, bool) or not isinstance(max_motions, (int, np.integer)) or max_motions < 1:
        raise ValueError(f"max_motions must be an integer >= 1, got {max_motions!r}")
    max_motions = int(max_motions)
    if not isinstance(seq_or_points, Sequence):
        seq_or_points = Sequence(np.asarray(seq_or_points, dtype=np.float64))
    whole = seq_or_points
    basis = ""
    if not seq_or_points.is_complete:
        # the profile fits whole trajectories (rank-4 subspaces): on incomplete data it runs on
        # the stretch of frames and the tracks seen in all of it that hold the most entries
        # (a motion none of whose tracks spans the stretch is then not counted: said in the
        # reason)
        seq_or_points, basis = _complete_window(seq_or_points)
    seed = as_seed(random_state)
    if seq_or_points.n_points > MAX_ESTIMATE_POINTS:
        # counting the motions needs no more tracks than this, and runs LAAV up to four times
        P_all = seq_or_points.n_points
        keep = np.sort(np.random.default_rng(seed).choice(
            P_all, MAX_ESTIMATE_POINTS, replace=False))
        seq_or_points = seq_or_points.subset(keep)
        basis += (f"; estimated on {MAX_ESTIMATE_POINTS} of the {P_all} tracks, drawn at random "
                  "(seeded)")
    P = seq_or_points.n_points
    if P < 2 * MIN_POINTS:
        raise ValueError(f"{seq_or_points.source}: {P} points are too few to estimate the number "
                         f"of motions (needs at least {2 * MIN_POINTS}: {MIN_POINTS} per motion of two)")
    max_motions = min(max_motions, P // MIN_POINTS)
    t = time.perf_counter()
    C, scores, levels, noise2, sigma, why, results, one = _estimate(seq_or_points, max_motions, params, seed)
    count = MotionCount(
        n_motions=int(C), candidates=tuple(range(1, max_motions + 2)),
        subspace_level=tuple(float(v) for v in np.exp(levels[0])),
        epipolar_level=tuple(float(v) for v in np.exp(levels[1])),
        coding_length=tuple(float(v) for v in levels[2]),
        step_scores=tuple(float(v) for v in scores), noise=noise2, reason=why + basis,
        seed=seed, seconds=time.perf_counter() - t, sigma=sigma, one_motion_score=one)
    # LAAV's result at the estimate, when it was computed on the caller's whole sequence with
    # the caller's settings: not with profile_params(), for a caller who gave none, nor when
    # the profile turned off what its constants were not fitted with (NOT_FITTED), which the
    # caller's result must have
    same = params is not None and params == params.replace(**NOT_FITTED)
    return count, (results.get(int(C)) if seq_or_points is whole and same else None)


@single_threaded
def _estimate(seq, max_motions, params, seed):
    """The profile's candidates evaluated only as the sequential test reaches them."""
    ctx = _prepare(seq, max_motions, params, seed, RANK)
    K = max_motions + 1
    levels = np.full((3, K), np.nan)
    done = set()

    def col(c):
        if not 1 <= c <= K:
            return np.full(3, np.nan)
        if c not in done:
            done.add(c)
            got = _evaluate(ctx, c)
            if got is not None:
                levels[:, c - 1] = profile_levels(got[1][None], got[2][None], ctx.unit2,
                                                  coding=[got[3]])[:, 0]
        return levels[:, c - 1]

    C, scores, why = decide(col, ctx.noise2, max_motions, unit2=ctx.unit2, sigma=ctx.sigma)
    # (two motions: the check reads C = 1-3, which the test has evaluated unless max_motions is 2)
    one = one_motion_check(col, ctx.noise2, ctx.sigma) if C == 2 else float("nan")
    return C, scores, levels, float(ctx.noise2), float(ctx.sigma), why, ctx.results, one
