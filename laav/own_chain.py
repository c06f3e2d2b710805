"""Ours, beyond both papers: LAAV's own candidates (``rv_select="laav"``, the default on
complete tracks; no plain Random Voting).

The informed trial (the LAAV paper's fine-tuning, from the coarse labels) and
``rv_missing_trials`` (2) trials per pair of coarse motions from a *missing-motion start*
(:func:`missing_motion_start`: two coarse motions joined, the points in no atom that no
remaining motion explains made a motion of their own), each on its own random stream, run
side by side (:func:`informed_side_by_side`), each refined and reassigned
(:class:`laav.selection.Polished`), the one of least :func:`laav.joint.joint_score` kept
(:func:`own_candidates`; when they differ, each is scored after its best moves of at most
``rv_select_descent`` of the points, so that a few stray points do not decide), which then
descends on that score (``rv_descent``, :func:`laav.joint.joint_descent`: single points move
while the score decreases), from its polished labels and from its trial's own, the lower
kept (``rv_descent_from_trial``). With ``rv_missing_gate`` (the default) the informed trial
runs and is selected alone first, and a start's trials run only where that result leaves its
new motion unexplained (:func:`unexplained`). With ``rv_outlier_veto`` (the default) a
missing-motion candidate, the descent's result and the unpolished labels replace the labels
they compete with only if they also score lower on the points both explain (:func:`veto`):
outlier tracks must not buy a motion. With a
:class:`laav.helper.VotingHelper`, half of the trials run in its process (:func:`candidates`;
the same labels).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import selection  # (looked up there: one patch of selection.Polished covers every path)
from ._interrupt import check as check_interrupt
from .coding import principal_trajectories
from .joint import joint_descent, joint_score, unit2
from .params import LaavParams
from .refine import _memo, fit_memo
from .subspace_votes import SubspaceVotes, votes_with_subspace
from .voting_result import Voting

__all__ = ["own_candidates", "missing_motion_start", "candidate_part", "veto", "outlier_points",
           "MISSING_MOTION_QUANTILE", "VETO_OUTLIER_FACTOR"]


#: A missing-motion start (``rv_select="laav"``) takes the points in no atom whose best
#: subspace distance exceeds this quantile of the covered points' own distances.
MISSING_MOTION_QUANTILE = 0.95


def missing_motion_start(points: np.ndarray, init: np.ndarray, n_motions: int, g: int, h: int,
                         params: LaavParams, min_points: int) -> np.ndarray | None:
    """A start for the case where one motion has no atom (``rv_select="laav"``).

    Coarse motions ``g`` and ``h`` become one; the points in no atom (``init`` -1) whose
    squared distance to every remaining motion's robust rank-4 trajectory subspace
    (:func:`laav.refine.subspace_residuals`) exceeds the :data:`MISSING_MOTION_QUANTILE`
    of the covered points' own become motion ``n_motions - 1``. Returns labels (P,)
    with -1 for the other uncovered points, or None when fewer than ``min_points``
    points qualify (or a motion is too small to fit).
    """
    from .refine import subspace_residuals

    C = n_motions
    L = np.where(init == h, g, init)
    L = np.where(L > h, L - 1, L)  # C - 1 motions, -1 outside the atoms
    R = subspace_residuals(points, L, C - 1, unit2=unit2(params))
    if R is None:
        return None
    cov = L >= 0
    own = R[L[cov], np.flatnonzero(cov)]
    new = ~cov & (R.min(axis=0) > np.quantile(own, MISSING_MOTION_QUANTILE))
    if new.sum() < min_points:
        return None
    return np.where(new, C - 1, L)


def own_candidates(points, C, params, rng, init, labels0, votes0, helper=None,
                   preview=None) -> Voting:
    """``rv_select="laav"``: LAAV's informed trial and its missing-motion starts
    (``rv_missing_trials`` trials each), each polished, the one of least
    :func:`joint_score` kept and descended (with ``rv_descent_from_trial`` from its polished
    and its unpolished labels, the lower kept; see :class:`LaavParams`).

    With ``rv_missing_gate`` > 0 the informed trial runs first and is selected alone; a
    missing-motion start's trials then run only when that result leaves at least that share
    of the start's new motion unexplained (:func:`unexplained`); the starts not run are named
    in ``Voting.skipped_starts``. A start that runs gives the candidates it gives without the
    gate (each trial on its own stream), so when every start runs the labels are the gate's
    off labels. ``preview`` (a callable, for a live view) is given the informed trial's
    result alone when some start runs, before its trials do (see
    :func:`laav.voting.random_voting`)."""
    P = points.shape[1]
    pairs = [(g, h) for g in range(C) for h in range(g + 1, C)]
    streams = rng.spawn(1 + len(pairs))  # [coarse start, one per pair]
    informed = ("informed", labels0, votes0, streams[0], init >= 0)
    groups = []  # per missing-motion start: (name, its new motion (P,) bool, its trials' starts)
    for (g, h), stream in zip(pairs, streams[1:]):
        start = missing_motion_start(points, init, C, g, h, params,
                                     max(8, params.rv_sample_size))
        if start is None:
            continue
        known2 = start >= 0
        # the first trial on the pair's own stream, as with one trial; the others on
        # streams spawned from it (spawning draws nothing: the first trial is unchanged)
        more = stream.spawn(params.rv_missing_trials - 1)
        group = []
        for k, trial_rng in enumerate([stream] + more, start=1):
            lab = np.where(known2, start, trial_rng.integers(0, C, P))
            vot = np.zeros((P, C))
            vot[np.arange(P), lab] = np.where(known2, params.rv_label_weight, 0.0)
            name = f"missing motion ({g}+{h})" + (f", trial {k}" if k > 1 else "")
            group.append((name, lab, vot, trial_rng, known2))
        groups.append((f"missing motion ({g}+{h})", start == C - 1, group))
    starts = [informed] + [s for *_, group in groups for s in group]
    uses = [votes_with_subspace(params, known) for *_, known in starts]
    extra = (SubspaceVotes(points, params.rv_subspace_weight, params.rv_subspace_sample)
             if any(uses) else None)  # one for every trial that uses it: the same term
    if params.rv_missing_gate <= 0 or not groups:
        part = candidates(points, C, params, [s[1:4] for s in starts], extra, uses, helper)
        return _select(points, C, params, starts, part, extra, uses)
    # ours (rv_missing_gate): the informed trial alone first, the starts it leaves unexplained
    # then (all of them when it did not settle: a trial still changing explains nothing)
    first = candidates(points, C, params, [informed[1:4]], extra, uses[:1], helper)
    alone = _select(points, C, params, [informed], first, extra, uses[:1])
    far = unexplained(points, alone.labels, C, params, first[3]) if alone.informed_converged else None
    run = [far is None or far[new].sum() >= params.rv_missing_gate * new.sum()
           for _, new, _ in groups]
    skipped = tuple(name for (name, *_), r in zip(groups, run) if not r)
    if not any(run):
        return dataclasses.replace(alone, skipped_starts=skipped)
    if preview is not None:  # (a live view draws LAAV's own trial while the starts run)
        preview(dataclasses.replace(alone, skipped_starts=skipped))
    more = [s for (*_, group), r in zip(groups, run) if r for s in group]
    more_uses = [votes_with_subspace(params, known) for *_, known in more]
    rest = candidates(points, C, params, [s[1:4] for s in more], extra, more_uses, helper)
    both = ([*first[0], *rest[0]], {**rest[1], **first[1]}, {**rest[2], **first[2]}, first[3])
    out = _select(points, C, params, [informed, *more], both, extra, uses[:1] + more_uses)
    return dataclasses.replace(out, skipped_starts=skipped)


#: ``rv_missing_gate``: a point is unexplained when its squared distance (mean over frames) to
#: its own motion's robust rank-4 trajectory subspace exceeds this many squared pixels.
UNEXPLAINED_PX2 = 1.0
#: ... and the test is used only when the median point lies within this share of that
#: threshold: under pixel noise (σ = 1 px) the points of a missed motion lie as close to the
#: found motions as every other point does, and the test cannot tell them apart.
UNEXPLAINED_FLOOR = 0.5


def _own_distances(points, labels, n_motions, params, fits=None) -> np.ndarray | None:
    """(P,) each point's squared distance (mean over frames, in ``unit2``) to its own motion's
    robust rank-4 trajectory subspace (:func:`laav.refine.subspace_residuals`; NaN for a point
    labelled -1), or None when a motion is too small to fit."""
    from .refine import subspace_residuals

    R = subspace_residuals(points, labels, n_motions, unit2=unit2(params), fits=fits)
    if R is None:
        return None
    own = np.full(labels.size, np.nan)
    on = labels >= 0
    own[on] = R[labels[on], np.flatnonzero(on)]
    return own


def unexplained(points, labels, n_motions, params, fits=None) -> np.ndarray | None:
    """(P,) bool: the points ``labels`` (P,) leave unexplained, farther than
    :data:`UNEXPLAINED_PX2` (squared pixels, ``unit2``) from their motion's robust rank-4
    trajectory subspace (:func:`laav.refine.subspace_residuals`, with the memo ``fits``); all
    of them when a motion is too small to fit. None when the test cannot tell: the median
    point's distance is above :data:`UNEXPLAINED_FLOOR` of the threshold (pixel noise)."""
    own = _own_distances(points, labels, n_motions, params, fits)
    if own is None:
        return np.ones(labels.size, dtype=bool)
    threshold = UNEXPLAINED_PX2 * unit2(params)
    if np.nanmedian(own) > UNEXPLAINED_FLOOR * threshold:  # the test has no power here
        return None
    return own > threshold


#: ``rv_outlier_veto``: a point is an outlier of a labelling when its squared distance to its
#: own motion's robust rank-4 trajectory subspace exceeds this many times the labelling's
#: median point's (the refinement's outlier factor, ``laav.refine.refine_labels``: set a
#: priori, not tuned), and :data:`UNEXPLAINED_PX2`.
VETO_OUTLIER_FACTOR = 6.0


def outlier_points(points, labels, n_motions, params, fits=None) -> np.ndarray:
    """(P,) bool: the points of ``labels`` (P,) farther from their own motion's robust rank-4
    trajectory subspace than :data:`VETO_OUTLIER_FACTOR` times the median point and than
    :data:`UNEXPLAINED_PX2` (in ``noise_adaptive``'s scaled unit; none when a motion is too
    small to fit). The median moves the threshold with pixel noise; the floor keeps a point
    its motion explains within a pixel, where noise-free tracks put the median far below
    what perspective leaves."""
    own = _own_distances(points, labels, n_motions, params, fits)
    if own is None:
        return np.zeros(labels.size, dtype=bool)
    return own > max(VETO_OUTLIER_FACTOR * np.nanmedian(own), UNEXPLAINED_PX2 * unit2(params))


def veto(points, C, params, kept, other, fits=None) -> tuple | None:
    """Ours (``rv_outlier_veto``): two labellings (P,) compared on the points both explain:
    ``kept`` (LAAV's informed trial's, or the labels before a descent) and ``other`` (a
    missing-motion candidate, or the descent's result), which the joint score prefers over
    all points.

    A point is left out when it is an outlier (:func:`outlier_points`) of both labellings,
    and so are the points of a motion that keeps fewer than 8 of the rest in either (a
    fundamental matrix needs 8). Each labelling is then scored there as the selection
    scores it over all points (:func:`cleaned_costs`: the joint score after its best moves
    of at most ``rv_select_descent`` of them), its motions numbered anew. Tracks that no
    motion explains, a group of tracking failures, code cheaper as a motion of their own
    than inside the motions they corrupt, so over every point the joint score could prefer
    a labelling that joins two real motions to give them one (a missing-motion start, or
    the descent moving a hundred points); on the points both explain, the join must pay for
    itself. A missing motion one of them explains (a rigid object the atoms missed) stays
    in the comparison.

    Returns ``(points compared, kept's cost, other's cost)``, or None when nothing is left
    out (the comparison over all points stands) or fewer than 16 points remain.
    """
    P = points.shape[1]
    keep = ~(outlier_points(points, kept, C, params, fits)
             & outlier_points(points, other, C, params, fits))
    while True:  # the points of motions too small to fit, until none is left in either
        small = np.zeros(P, dtype=bool)
        for labels in (kept, other):
            small |= keep & (np.bincount(labels[keep], minlength=C)[labels] < 8)
        if not small.any():
            break
        keep &= ~small
    idx = np.flatnonzero(keep)
    if idx.size == P or idx.size < 16:
        return None
    sub = np.ascontiguousarray(points[:, idx])
    most = int(np.ceil(params.rv_select_descent * idx.size))  # 0: the joint score itself
    costs = []
    for labels in (kept, other):  # (cleaned_costs, but each with its own motion count)
        present, lab = np.unique(labels[idx], return_inverse=True)
        costs.append(joint_descent(sub, lab, present.size, params, max_moves=most,
                                   return_score=True)[2])
    return int(idx.size), float(costs[0]), float(costs[1])


def _select(points, C, params, starts, part, extra, uses) -> Voting:
    """The selection among ``starts``' candidates (:func:`own_candidates`), from their
    :func:`candidates` ``part`` (results, polished, cleaned costs, memo of fits)."""
    results, finished, cost, fits = part
    cost = dict(cost)
    first, first_extra = results[0], extra if uses[0] else None
    trials = list(results)
    polished = {key: _Finished(f) for key, f in finished.items()}
    finals = {key: f[0] for key, f in finished.items()}
    clean = params.rv_select_descent > 0 and len({f.tobytes() for f in finals.values()}) > 1
    proj = None
    if clean:  # ours: each scored after its best moves of a few points (rv_select_descent)
        proj = projection(points, fits)  # one projection for every descent here
        missing = {key: f for key, f in finals.items() if key not in cost}
        cost.update(cleaned_costs(points, C, params, missing, fits, proj))
    else:
        proj = projection(points, fits)
        cost = {key: joint_score(points, f, C, params, fits=fits, projected=proj)
                for key, f in finals.items()}
    entries = [(name, res, polished[res[0].tobytes()], cost[res[0].tobytes()])
               for (name, *_), res in zip(starts, results)]
    scores = np.array([e[3] for e in entries])
    k = int(np.argmin(scores))  # the first of equal scores: the coarse start
    vetoed = []  # ours (rv_outlier_veto): choices of the joint score that outliers made
    if k > 0 and entries[0][0] == "informed":  # a missing-motion candidate won
        informed = finals[entries[0][1][0].tobytes()]
        # the candidates below the informed trial, best first (stable: equal scores in
        # start order): the first the veto lets through is kept, else the informed trial
        for j in np.argsort(scores, kind="stable"):
            if j == 0 or scores[j] >= scores[0]:
                k = 0
                break
            no = _vetoed(points, C, params, informed, finals[entries[j][1][0].tobytes()], fits,
                         entries[j][0], always=True)
            if no is None:
                k = int(j)
                break
            vetoed.append(no)
    name, res, pol, _ = entries[k]
    costs = {e[0]: float(e[3]) for e in entries}
    out = selection.finish(points, C, params, res, trials, True, name, polished=pol, costs=costs,
                  score="joint-cleaned" if clean else "joint-sum")
    if params.rv_descent:  # ours: the kept labelling descends on the same score
        trial = np.asarray(res[0], dtype=np.int64)
        # ours: the trial's own labels descend too, unless the polish left them as they were
        both = params.rv_descent_from_trial and not np.array_equal(trial, out.labels)
        kept = out.labels
        labels, moved, score = joint_descent(points, kept, C, params, projected=proj,
                                             fits=fits, return_score=True)
        no = _vetoed(points, C, params, kept, labels, fits, "the descent")
        if no is not None:  # it re-labelled so that outlier tracks code cheaper: not kept
            vetoed.append(no)
            labels, moved = kept, 0
            score = joint_score(points, kept, C, params, fits=fits, projected=proj)
        if both:
            raw, raw_moved, raw_score = joint_descent(points, trial, C, params, projected=proj,
                                                      fits=fits, return_score=True)
            no = (_vetoed(points, C, params, labels, raw, fits, "the trial's own labels, descended")
                  if raw_score < score else None)
            if no is not None:
                vetoed.append(no)
            elif raw_score < score:  # the refinement and reassignment are not kept
                out = dataclasses.replace(out, refined=0, reassigned=0, unpolished=True)
                labels, moved = raw, raw_moved
                # (a veto of the polished labels' descent no longer says what was returned)
                vetoed = [v for v in vetoed if v[0] != "the descent"]
        out = dataclasses.replace(out, labels=labels, descended=moved)
    if vetoed:
        out = dataclasses.replace(out, vetoed=tuple(vetoed))
    return selection.with_informed(out, first, first_extra)


def _vetoed(points, C, params, kept, new, fits, what: str, always: bool = False) -> tuple | None:
    """Ours (``rv_outlier_veto``): the veto entry ``(what, points compared, kept's cost, new's
    cost)`` when ``new`` (P,), which the joint score prefers over all points to ``kept``
    (P,), scores higher on the points both explain (:func:`veto`); None when ``new`` may
    replace ``kept``. Checked when ``always`` (a missing-motion candidate over the informed
    trial) or when the two differ on more points than the selection's cleaning moves
    (``rv_select_descent``, and at least the 8 a motion needs): fewer cannot buy outliers a
    motion."""
    if not params.rv_outlier_veto:
        return None
    if not always:
        most = max(8, int(np.ceil(params.rv_select_descent * kept.size)))
        if np.count_nonzero(kept != new) <= most:
            return None
    check = veto(points, C, params, kept, new, fits)
    if check is not None and check[1] < check[2]:
        return (what, *check)
    return None


def informed_side_by_side(points, params, starts, extra, uses) -> list:
    """LAAV's informed trials from several ``starts`` ((labels0, votes0, generator) each),
    side by side as :func:`laav.rv.run_trials` runs trials: one batched numpy call per
    iteration, each trial on its own generator and convergence test, so the results (in
    :func:`laav.rv.run_trials`' tuple form, in ``starts`` order) are those of running them
    one after another. ``extra``: the subspace votes, for the starts whose ``uses`` (bool
    each) is true; the trials of each kind share a batch. Every trial runs to its end (no
    trial is cancelled, unlike plain RV's), so all of a kind run at once, whatever
    ``rv_batch``: one call per iteration instead of one per ``rv_batch`` trials (voting
    15-17 % faster than 2 at a time on the demo and six Hopkins155 sequences)."""
    from .rv import _step, _Trial

    trials = [_Trial(lab.copy(), vot.copy(), False, "informed", stream)
              for lab, vot, stream in starts]
    for with_extra in dict.fromkeys(uses):
        active = [t for t, u in zip(trials, uses) if u == with_extra]
        while active:
            check_interrupt()  # a caller's stop request, once per iteration
            _step(points, active, params, None, extra if with_extra else None)
            active = [t for t in active if not t.done]
    return [t.result() for t in trials]


def projection(points: np.ndarray, fits: dict) -> np.ndarray:
    """:func:`principal_trajectories` (K, P) of ``points``, made once per ``fits``
    (:func:`fit_memo` of ``points``): the selection's costs, scores and descents all read
    the same SVD (computing it again gave the same numbers, at ~2 ms a time)."""
    key = ("projection",)  # (beside the memo's motion fits: no motion key is a 1-tuple)
    if fits is None:  # (no memo: made anew each time)
        return principal_trajectories(points)
    fits = _memo(fits, points)  # a memo of these very points (else ValueError)
    if key not in fits:
        fits[key] = principal_trajectories(points)
    return fits[key]


class _Finished:
    """A candidate polished elsewhere (:func:`candidate_part`): its :meth:`laav.selection.Polished.final`."""

    def __init__(self, final: tuple):
        self._final = final

    def final(self) -> tuple:
        return self._final


def cleaned_costs(points, C, params, finals: dict, fits, proj) -> dict:
    """The selection's cleaned cost (``rv_select_descent``) of every labelling of ``finals``:
    its joint score after its best moves of at most that share of the points."""
    most = int(np.ceil(params.rv_select_descent * points.shape[1]))
    return {key: joint_descent(points, f, C, params, max_moves=most, projected=proj,
                               return_score=True, fits=fits)[2] for key, f in finals.items()}


def candidate_part(points, C, params, starts, extra, uses, always_cost: bool = False) -> tuple:
    """Some of LAAV's own candidates (:func:`own_candidates`): the trials of ``starts``
    side by side (:func:`informed_side_by_side`), every distinct trial labelling polished
    (refinement and reassignment), and, with ``rv_select_descent``, their cleaned costs
    when ``always_cost`` or when their polished labellings differ (as the selection needs
    them then). Returns (results, {key: polished (labels, refined, reassigned)},
    {key: cleaned cost}, the memo of motion fits), keys the trial labels' bytes."""
    results = informed_side_by_side(points, params, starts, extra, uses)
    fits = fit_memo(points)  # candidates share most motions: each motion's fits made once (same numbers)
    finished: dict = {}
    for res in results:
        key = res[0].tobytes()  # trials that end on the same labels share their polish
        if key not in finished:
            check_interrupt()  # a caller's stop request, between polishes
            finished[key] = selection.Polished(points, C, params, res[0], fits=fits).final()
    cost: dict = {}
    if params.rv_select_descent > 0 and (
            always_cost or len({f[0].tobytes() for f in finished.values()}) > 1):
        cost = cleaned_costs(points, C, params, {k: f[0] for k, f in finished.items()}, fits,
                              projection(points, fits))
    return results, finished, cost, fits


def candidates(points, C, params, starts, extra, uses, helper) -> tuple:
    """:func:`candidate_part` of every start; with a ``helper``
    (:class:`laav.helper.VotingHelper`), every other start's part (the informed trial stays
    here) runs in its process meanwhile, costs included: the same numbers, each trial
    drawing from its own stream and ending by its own test, each polish and cost a function
    of the trial's labels alone."""
    theirs = list(range(1, len(starts), 2))
    # (an array sent to the process arrives C-contiguous: sums over a strided one could
    # round otherwise, so such points stay here)
    if helper is None or not theirs or not points.flags.c_contiguous:
        return candidate_part(points, C, params, starts, extra, uses)
    mine = list(range(0, len(starts), 2))
    part = lambda ks: ([starts[k] for k in ks], extra, [uses[k] for k in ks])  # noqa: E731
    handle = helper.submit((points, C, params, *part(theirs), True))
    if handle is None:  # closed or broken: all here
        return candidate_part(points, C, params, starts, extra, uses)
    try:
        here = candidate_part(points, C, params, *part(mine))
    except BaseException:
        helper.stop(handle)
        raise
    there = helper.result(handle, check_interrupt)
    if there is None:  # its process died: its part here (their streams were never drawn here)
        there = candidate_part(points, C, params, *part(theirs), True)
    results = [None] * len(starts)
    for ks, res in ((mine, here[0]), (theirs, there[0])):
        for k, r in zip(ks, res):
            results[k] = r
    return results, {**there[1], **here[1]}, {**there[2], **here[2]}, here[3]
