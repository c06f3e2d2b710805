"""LAAV's fine-tuning: the public entry to Random Voting, and where each part lives.

:func:`random_voting` runs the paper's Random Voting (Jung et al. 2014; :mod:`laav.rv`, one
short module) either as plain RV (random starts) or as LAAV's fine-tuning (one *informed*
trial started from the coarse labels, as the LAAV paper says), and hands over to the steps
beyond both papers, each a named setting (``docs/ALGORITHM.md`` has the table with what
each measured):

* :mod:`laav.own_chain`: **LAAV's own candidates** (``rv_select="laav"``, the default
  since 2026-12-02; no plain RV on complete tracks): the informed trial and trials from
  *missing-motion starts*, side by side, the one of least joint score kept and descended.
  On incomplete tracks the default runs as ``"subspace"`` below.
* :mod:`laav.selection`: the **polish** of every labelling returned (refinement
  ``rv_refine``, joint reassignment ``rv_reassign``) and **model selection** with plain RV
  beside the informed trial (``rv_select="joint"``, :meth:`LaavParams.with_plain_rv`, the
  default 2026-12-01 to 12-02; ``"subspace"`` before, and on incomplete tracks).
* :mod:`laav.subspace_votes`: the subspace term of the informed trials' votes.
* here: the entry's checks, the informed start (:func:`informed_preview` too), more than
  ``rv_max_points`` points (a seeded subset votes) and missing data (masked voting). With
  ``rv_select="none"`` (:meth:`LaavParams.paper`) the fine-tuning is the informed trial
  alone, converged or not, and plain RV ends with the consensus when no trial converged.

The refinement, reassignment and selection compare squared distances with a few absolute
constants (:mod:`laav.refine`); they are in units of ``1 / rv_lambda`` (the squared
distance at which a vote fades), so that scaling the coordinates by ``s`` and
``rv_lambda`` by ``1 / s^2`` gives the same labels (:func:`unit2`). The joint score's
coding length has its own distortion ``coding_eps`` in px: scale it by ``s`` too
(:meth:`LaavParams.scaled` scales both).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from . import own_chain, selection
from ._random import check_seed, resolve_seed
from ._sequence import Sequence, as_points, check_degenerate, warn_missing_motions
from ._threads import single_threaded
from .joint import joint_score, unit2
from .metrics import misclassification_rate
from .own_chain import (  # noqa: F401 (re-exported, as before the split)
    MISSING_MOTION_QUANTILE,
    candidate_part,
    missing_motion_start,
)
from .params import LaavParams, as_params
from .refine import (
    assign_by_subspace,
    assign_jointly,
    frame_pairs,
    labelling_cost,
    motion_distances,
    reassign_labels,
    refine_labels,
    subspace_cost,
)
from .rv import consensus, run_trials, vote
from .selection import NOT_PLAIN_FIELDS, POLISHED_KEPT, SELECTION_FIELDS  # noqa: F401
from .subspace_votes import (  # noqa: F401 (SUBSPACE_VOTES_MIN_START re-exported)
    SUBSPACE_VOTES_MIN_START,
    for_informed_trial,
)
from .voting_result import Voting

__all__ = ["Voting", "random_voting", "vote", "refine_labels", "motion_distances", "frame_pairs",
           "labelling_cost", "subspace_cost", "reassign_labels", "joint_score",
           "missing_motion_start", "informed_preview", "SELECTION_FIELDS", "NOT_PLAIN_FIELDS"]


@single_threaded  # one BLAS/OpenMP thread, restored after (laav/_threads.py)
def random_voting(seq: Sequence | np.ndarray, n_motions: int, params: LaavParams | None = None,
                  seed: int | np.random.Generator | None = 0, init_labels: np.ndarray | None = None,
                  weights: np.ndarray | None = None, *, random_state=None,
                  plain_memo: dict | None = None, visible: np.ndarray | None = None,
                  check_input: bool = True, helper=None, preview=None) -> Voting:
    """Segment trajectories into ``n_motions`` rigid motions by Random Voting.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    n_motions : int
        C, the number of motions.
    params : LaavParams, optional
        Uses the ``rv_*`` fields, and with ``rv_select`` ``"laav"`` (the default) or
        ``"joint"`` also ``coding_eps`` and ``coarse_epipolar_weight``
        (:data:`SELECTION_FIELDS`). Defaults
        to ``LaavParams()``.
    seed : int or numpy.random.Generator
        An int in [0, 2**63) (anything else is a ValueError) or a generator. Same seed,
        same labels.
    random_state : None, int, numpy.random.Generator or RandomState, optional
        scikit-learn style alternative to ``seed``, used instead of it when given (an int
        is the seed itself, a generator gives one draw). None (default): ``seed`` is used.
    init_labels : ndarray of shape (P,), optional
        Start labels (LAAV fine-tuning); ``-1`` marks unlabelled points, which start at
        random. None gives plain RV from random partitions.
    weights : ndarray of shape (P,), optional
        Initial votes of each point for its start label (default ``rv_label_weight`` for
        labelled points, 0 otherwise). Only with ``init_labels``.
    plain_memo : dict, optional
        Speed only, for callers that rerun the fine-tuning with new ``init_labels`` (as
        :class:`laav.Pipeline` does when λ or the radii change): an empty dict at first,
        then the same dict again for the same points, C, seed and ``rv_*`` settings. Plain
        RV's runs and their polished candidates (which do not depend on ``init_labels``)
        are kept in it and reused, the candidates' costs per value of the fields the joint
        score reads (:data:`SELECTION_FIELDS`), and the last informed trial and its polish,
        keyed on their start (so that :func:`informed_preview` and this call run them
        once); the labels are identical to a run without it.
    visible : ndarray of shape (F, P), bool, optional
        For an array ``seq`` with missing entries (a :class:`Sequence` carries its own).
        When an entry is hidden, the missing-data variant runs (``docs/ALGORITHM.md``,
        "Missing data"): points that no usable frame pair sees are placed by the motions'
        trajectory subspaces when seen in at least 4 frames, else get label -1, with the
        reason in ``unlabelled_code``; hidden coordinates are never read.
    check_input : bool
        Plain RV only: warn about degenerate input (coordinates' spread, a distant origin,
        duplicate tracks) and about a result with a single label. False for callers that
        made those checks themselves (:func:`laav.segment` when no atom formed), so that
        each warning is given once.
    helper : laav.helper.VotingHelper, optional
        Speed only: LAAV's own trials (``rv_select="laav"`` on complete tracks) run half
        in the helper's process, half here (with ``rv_missing_gate`` the informed trial
        alone here first); the labels are those without it.
    preview : callable, optional
        For a live view: with ``rv_select="laav"`` on complete tracks, when the missing-motion
        gate (``rv_missing_gate``) lets some start through, called (in this thread) with the
        :class:`Voting` of LAAV's informed trial alone, polished, selected and descended
        (what is returned when the gate lets none through; ``skipped_starts`` names the
        starts not run), before those starts' trials run. Not called otherwise; the labels
        returned are the same with or without it.

    Returns
    -------
    Voting

    Raises
    ------
    ValueError
        For bad arguments; on incomplete data also when no two frames share enough
        visible points (``max(8, rv_sample_size)`` per motion).
    """
    from ._visibility import visibility

    points = as_points(seq)
    if points.ndim != 3 or points.shape[2] != 2:
        raise ValueError(f"points must have shape (F, P, 2), got {points.shape}")
    F, P, _ = points.shape
    vis = visibility(seq, visible)
    if vis is None and not np.isfinite(points).all():
        raise ValueError("points contain NaN or infinite coordinates")
    if vis is not None and not np.isfinite(points[vis]).all():
        raise ValueError("points contain NaN or infinite coordinates where they are visible")
    if (not isinstance(n_motions, (int, np.integer)) or isinstance(n_motions, bool)
            or n_motions < 1):
        raise ValueError(f"n_motions must be a positive integer, got {n_motions!r}")
    C = int(n_motions)
    if C > P:
        raise ValueError(f"cannot split {P} points into {C} motions")
    params = as_params(params)
    if init_labels is None and weights is not None:
        raise ValueError("weights are the votes of the start labels: give init_labels too")
    if C > 1 and params.rv_sample_size > P:
        raise ValueError(f"rv_sample_size ({params.rv_sample_size}) exceeds the number of "
                         f"points ({P})")
    if init_labels is None and check_input:  # plain RV, an entry point: segment()'s checks
        check_degenerate(seq, C, visible=None if isinstance(seq, Sequence) else vis)
    seed = resolve_seed(seed, random_state)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(check_seed(seed))
    if C == 1 or F < 2:
        lab = np.zeros(P, dtype=np.int64)
        return Voting(lab, np.ones((P, 1)), np.zeros(0, np.int64), np.zeros(0), 0, 0, True,
                      (), init_labels is not None, 0,
                      unlabelled_code=None if vis is None else np.zeros(P, np.int8))
    if params.rv_max_points is not None and P > params.rv_max_points:
        return _subset_voting(seq, points, vis, C, params, rng, init_labels, weights,
                              plain_memo, check_input, helper)
    if vis is not None:
        return _masked_voting(seq, points, vis, C, params, rng, init_labels, weights, plain_memo,
                              check_input)
    select = params.rv_select != "none"  # plain RV: "laav" selects as "joint"

    if init_labels is None:  # plain RV
        _, best, trials, ended = run_trials(points, C, params, rng)
        return _plain_result(seq, points, C, params, rng, best, trials, ended, select,
                             warn=check_input)
    return _fine_tuning(points, C, params, rng, init_labels, weights, select, plain_memo,
                        helper=helper, preview=preview)


def _start_arrays(init_labels, weights, P: int):
    """``init_labels`` and ``weights`` as int64 / float64 arrays (or None), checked to be
    of shape (P,)."""
    init = None if init_labels is None else np.asarray(init_labels, dtype=np.int64)
    w = None if weights is None else np.asarray(weights, dtype=np.float64)
    if init is not None and init.shape != (P,):
        raise ValueError(f"init_labels must have shape ({P},), got {init.shape}")
    if w is not None and w.shape != (P,):
        raise ValueError(f"weights must have shape ({P},), got {w.shape}")
    return init, w


def _subset_voting(seq, points, vis, C, params, rng, init_labels, weights, plain_memo,
                   warn, helper=None) -> Voting:
    """:func:`random_voting` with more than ``rv_max_points`` points: every step of voting
    on a seeded random subset of that many, then every other point placed by the motions
    fitted on the voted ones (:func:`laav.refine.assign_jointly`), and, with
    ``rv_reassign``, the joint reassignment once more over every point. A point left
    unlabelled (missing data: no frame pair and too few frames) gets code 1."""
    from ._visibility import MIN_ASSIGN_FRAMES, NO_FRAME_PAIR, cover_pairs, filled, pair_pool

    P = points.shape[1]
    init, w = _start_arrays(init_labels, weights, P)
    idx = np.sort(rng.spawn(1)[0].choice(P, params.rv_max_points, replace=False))
    try:
        out = random_voting(points[:, idx], C, params.replace(rv_max_points=None), rng,
                            None if init is None else init[idx], None if w is None else w[idx],
                            plain_memo=plain_memo, visible=None if vis is None else vis[:, idx],
                            check_input=False, helper=helper)
    except ValueError as err:  # the subset is an array: name the sequence's file instead
        raise ValueError(_named(seq, err)) from None
    labels = np.full(P, -1, dtype=np.int64)
    labels[idx] = out.labels
    rest = np.setdiff1d(np.arange(P), idx)
    kw = {}
    if vis is not None:
        pool = pair_pool(vis, max(8, params.rv_sample_size) * C)
        points = filled(points, vis)
        kw = {"visible": vis, "pairs": cover_pairs(vis, pool, 12)}
    labels[rest] = assign_jointly(points, labels, C, rest, unit2(params),
                                  min_frames=MIN_ASSIGN_FRAMES, **kw)
    moved = 0
    if params.rv_reassign:  # as the voting's own last step, now over every point
        labels, moved = reassign_labels(points, labels, C, unit2=unit2(params), **kw)
    votes = np.zeros((P, C))
    votes[idx] = out.votes
    code = None if vis is None else np.where(labels >= 0, 0, NO_FRAME_PAIR).astype(np.int8)
    result = dataclasses.replace(out, labels=labels, votes=votes, unlabelled_code=code,
                                 reassigned=out.reassigned + moved, voted=_voted(idx, out, P))
    if init_labels is None and warn:
        warn_missing_motions(seq, labels, C)
    return result


def _named(seq, err: ValueError) -> str:
    """``err``'s message naming ``seq``'s source (once: an inner call on an array said
    ``<array>``)."""
    msg, src = str(err), getattr(seq, "source", "<array>")
    if msg.startswith("<array>: "):
        msg = msg[len("<array>: "):]
    return msg if msg.startswith(f"{src}: ") else f"{src}: {msg}"


def _voted(idx: np.ndarray, inner: Voting, P: int) -> np.ndarray | None:
    """The points (of the caller's P) a voting run on ``points[:, idx]`` voted with (None:
    all of them)."""
    idx = np.asarray(idx, dtype=np.int64)
    if inner.voted is None:
        return None if idx.size == P else idx
    return idx[inner.voted]


def _plain_result(seq, points, C, params, rng, best, trials, ended, select, mk=None,
                  warn=True) -> Voting:
    """Plain RV's result from its trials: the converged one, else a selection or the
    consensus. ``mk`` (missing data): a :class:`_Masks`; the caller then warns. ``warn``:
    about a single label (``check_input`` of :func:`random_voting`)."""
    if best is not None:
        out = selection.finish(points, C, params, best, trials, False, "trial", mk=mk)
    elif select:  # no trial converged: the consensus or one of the trials
        out = selection.select(points, C, params,
                               selection.plain_candidates(None, ended, C, rng), trials,
                               initialised=False, mk=mk)
    else:
        out = selection.finish(points, C, params, consensus(ended, C, rng), trials, False,
                               "consensus", mk=mk)
    if mk is None and warn:
        warn_missing_motions(seq, out.labels, C)
    return out


def _informed_start(points, C, params, rng, init_labels, weights):
    """LAAV's start from ``init_labels`` (P,): (init (P,), labels0 (P,), votes0 (P, C)), the
    points without a label drawn at random from ``rng`` (the fine-tuning's first draw)."""
    P = points.shape[1]
    init = np.asarray(init_labels, dtype=np.int64)
    if init.shape != (P,):
        raise ValueError(f"init_labels must have shape ({P},), got {init.shape}")
    if init.max() >= C:
        raise ValueError(f"init_labels has label {init.max()} but n_motions is {C}")
    known = init >= 0
    if weights is None:
        w = np.where(known, params.rv_label_weight, 0.0)
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (P,):
            raise ValueError(f"weights must have shape ({P},), got {w.shape}")
    labels0 = np.where(known, init, rng.integers(0, C, P))
    votes0 = np.zeros((P, C))
    votes0[np.arange(P), labels0] = np.where(known, w, 0.0)
    return init, labels0, votes0


class _Weight(tuple):
    """What :func:`laav.selection.with_informed` reads of an informed trial's subspace votes
    (their ``weight``), kept in a memo without their (2F, P) subspace matrix."""

    weight = property(lambda self: self[0])


def _first_trial(points, C, params, stream, labels0, votes0, known, masks, memo):
    """The selection's informed trial on ``stream`` (the first of the fine-tuning's
    spawned streams) from ``labels0`` (P,) with ``votes0`` (P, C), ``known`` (P,) the
    points with a start label: (its end, the trials run, its subspace votes or None).
    With ``memo`` (the caller's ``plain_memo``) the last one computed is kept and reused
    for the same start: :func:`informed_preview` computes it first, the fine-tuning then
    reuses it."""
    key = (known.tobytes(), labels0.tobytes(), votes0.tobytes(), masks is None)
    hit = None if memo is None else memo.get("informed")
    if hit is not None and hit[0] == key:
        return hit[1]
    extra = for_informed_trial(points, params, known, masks)  # ours: subspace votes
    first, _, trials, _ = run_trials(points, C, params, None, (labels0, votes0), n_plain=0,
                                     streams=[stream], masks=masks, extra=extra)
    kept = None if extra is None else _Weight((extra.weight,))
    if memo is not None:
        memo["informed"] = (key, (first, trials, kept))
    return first, trials, kept


def informed_preview(points: np.ndarray, n_motions: int, params: LaavParams,
                     rng: np.random.Generator, init_labels: np.ndarray,
                     plain_memo: dict | None = None) -> Voting | None:
    """LAAV's own fine-tuning as the selection with plain RV (``rv_select`` ``"joint"`` or
    ``"subspace"``, :meth:`LaavParams.with_plain_rv`) starts it, before plain Random
    Voting runs: the informed trial from ``init_labels`` on the same random stream
    (``rng`` a generator in the state :func:`random_voting` would receive), refined and
    reassigned: the selection's candidate ``"informed"``, the labels returned whenever
    the selection keeps it. For a live view to draw while plain RV and the selection
    compute (:meth:`laav.Pipeline.update`'s ``preview``).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Complete tracks.
    n_motions : int
    params : LaavParams
    rng : numpy.random.Generator
    init_labels : ndarray of shape (P,)
        The coarse labels (``-1``: no label).
    plain_memo : dict, optional
        The dict :func:`random_voting` will then get: the trial is kept in it and not run
        again there.

    Returns
    -------
    Voting or None
        ``selected="informed"``, no costs (nothing was compared yet); None where the
        fine-tuning has no plain RV to wait for (``rv_select`` ``"none"`` or ``"laav"``,
        one motion) or runs another way (more than ``rv_max_points`` points), and for
        arguments :func:`random_voting` refuses.
    """
    C = int(n_motions)
    P = points.shape[1]
    if (params.rv_select in ("none", "laav") or C < 2 or points.shape[0] < 2
            or params.rv_sample_size > P  # (random_voting then says what is wrong)
            or (params.rv_max_points is not None and P > params.rv_max_points)):
        return None
    init, labels0, votes0 = _informed_start(points, C, params, rng, init_labels, None)
    streams = rng.spawn(1 + params.rv_trials)  # as _fine_tuning: [informed, plain 0, ...]
    first, trials, extra = _first_trial(points, C, params, streams[0], labels0, votes0,
                                        init >= 0, None, plain_memo)
    pol = selection.Polished(points, C, params, first[0])
    if plain_memo is not None:  # the selection's own polish of this candidate: not done again
        plain_memo["informed polished"] = (_own_key(first[0], params), pol)
    out = selection.finish(points, C, params, first, trials, True, "informed", polished=pol)
    return selection.with_informed(out, first, extra)


def _own_key(labels: np.ndarray, params: LaavParams) -> tuple:
    """What LAAV's polished informed candidate depends on beyond the ``plain_memo``'s own
    key (seed, C, ``rv_*``): its labels and the selection's fields."""
    return (labels.tobytes(),) + tuple(getattr(params, f) for f in SELECTION_FIELDS)


def _fine_tuning(points, C, params, rng, init_labels, weights, select, plain_memo,
                 mk=None, helper=None, preview=None) -> Voting:
    """LAAV's fine-tuning: the informed trial started from ``init_labels`` and, with the
    selection, plain RV's runs beside it (:mod:`laav.selection`), or with ``rv_select="laav"``
    on complete tracks LAAV's own candidates (:mod:`laav.own_chain`). ``mk`` (missing
    data): a :class:`_Masks`."""
    masks = None if mk is None else (mk.visible, mk.pool)
    init, labels0, votes0 = _informed_start(points, C, params, rng, init_labels, weights)
    known = init >= 0
    if params.rv_select == "laav" and mk is None:
        return own_chain.own_candidates(points, C, params, rng, init, labels0, votes0, helper,
                                        preview)
    if not select:  # the LAAV paper's fine-tuning: the informed trial alone
        extra = for_informed_trial(points, params, known, masks)  # ours: subspace votes
        first, _, trials, _ = run_trials(points, C, params, rng, (labels0, votes0), n_plain=0,
                                         masks=masks, extra=extra)
        out = selection.finish(points, C, params, first, trials, True, "informed", mk=mk)
        return selection.with_informed(out, first, extra)
    # LAAV's start against plain RV: keep the labelling of lower selection score. The
    # informed trial and plain RV's trials each draw from their own generator, so they run
    # apart; plain RV's runs do not depend on the start and may come from ``plain_memo``.
    streams = rng.spawn(1 + params.rv_trials)  # [informed, plain 0, plain 1, ...]
    first, trials, extra = _first_trial(points, C, params, streams[0], labels0, votes0, known,
                                        masks, plain_memo)
    plain, more, cands = selection.plain_run(points, C, params, rng, streams, plain_memo, 1, masks)
    trials, cands = trials + more, [("informed", first)] + cands
    if plain is not None and misclassification_rate(first[0], plain[0]) > selection.ARBITRATE_ABOVE:
        # LAAV's start and plain RV disagree: two more plain RV runs arbitrate
        for k in (2, 3):
            _, more, kc = selection.plain_run(points, C, params, rng,
                                              rng.spawn(1 + params.rv_trials), plain_memo, k,
                                              masks)
            trials, cands = trials + more, cands + kc
    if params.rv_coarse_candidate and mk is not None and known.any():
        # ours, on incomplete tracks: the coarse labels themselves (see selection.coarse_candidate)
        cands.append(("coarse", selection.coarse_candidate(points, C, params, init, labels0,
                                                           votes0, mk)))
    # the polished candidates' costs read the selection's fields too: keyed on them, so a
    # caller may keep the memo across changes of those (plain RV's runs stay valid)
    polished = None if plain_memo is None else selection.polished_memo(plain_memo, params)
    own = None if plain_memo is None or mk is not None else plain_memo.get("informed polished")
    own = own[1] if own is not None and own[0] == _own_key(first[0], params) else None
    out = selection.select(points, C, params, cands, trials, initialised=True,
                           polished=polished, mk=mk, own=own)
    return selection.with_informed(out, first, extra)


class _Masks:
    """Missing data, for the voting of the points some frame pair can decide.

    Attributes
    ----------
    visible : ndarray of shape (F, K), bool
    pool : ndarray of shape (M, 2), int64
        The frame pairs voting draws from (:func:`laav._visibility.pair_pool`).
    pairs : ndarray of shape (L, 2), int64
        The refinement's and the selection's frame pairs
        (:func:`laav._visibility.cover_pairs`, 12 spread + cover).
    """

    def __init__(self, visible, pool):
        from ._visibility import cover_pairs

        self.visible, self.pool = visible, pool
        self.pairs = cover_pairs(visible, pool, 12)


def _masked_voting(seq, points, vis, C, params, rng, init_labels, weights, plain_memo,
                   warn=True) -> Voting:
    """:func:`random_voting` on incomplete data (``docs/ALGORITHM.md``, "Missing data").

    The frame pairs are :func:`laav._visibility.pair_pool`'s (at least ``max(8,
    rv_sample_size)`` points per motion seen in both frames); the points no pool pair sees
    take no part in the voting, and afterwards go to the motion whose trajectory subspace
    fits them best (:func:`laav.refine.assign_by_subspace`) when they are seen in at least
    :data:`laav._visibility.MIN_ASSIGN_FRAMES` frames, else get label -1 (code 1 of
    :data:`laav._visibility.UNLABELLED_REASONS`); the others are segmented as on complete
    data, with every step masked: voting
    (:func:`laav.rv.run_trials` with ``masks``), refinement and reassignment over
    :func:`laav._visibility.cover_pairs`, subspaces (reassignment, model selection)
    fitted on the visible entries (:func:`laav.refine.subspace_residuals` with the mask).
    """
    from ._visibility import MIN_ASSIGN_FRAMES, NO_FRAME_PAIR, decidable, filled, pair_pool

    P = points.shape[1]
    try:
        pool = pair_pool(vis, max(8, params.rv_sample_size) * C)
    except ValueError as err:  # none qualifies: say which file
        raise ValueError(_named(seq, err)) from None
    keep = decidable(vis, pool)  # at least the points of one pool pair: enough to vote
    idx = np.flatnonzero(keep)
    sub_vis = vis[:, idx]
    sub = filled(points[:, idx], sub_vis)
    init, w = _start_arrays(init_labels, weights, P)
    mk = _Masks(sub_vis, pool)
    select = params.rv_select != "none"  # incomplete data: "joint" and "laav" as "subspace"
    if init is None:  # plain RV
        _, best, trials, ended = run_trials(sub, C, params, rng, masks=(mk.visible, mk.pool))
        out = _plain_result(seq, sub, C, params, rng, best, trials, ended, select, mk)
    else:
        out = _fine_tuning(sub, C, params, rng, init[idx], None if w is None else w[idx], select,
                           plain_memo, mk)
    labels = np.full(P, -1, dtype=np.int64)
    labels[idx] = out.labels
    rest = np.flatnonzero(~keep)
    if rest.size:  # no vote reaches them: the motions' trajectory subspaces place them
        labels[rest] = assign_by_subspace(filled(points, vis), labels, C, vis, rest,
                                          MIN_ASSIGN_FRAMES, unit2=unit2(params))
    votes = np.zeros((P, C))
    votes[idx] = out.votes
    code = np.where(labels >= 0, 0, NO_FRAME_PAIR).astype(np.int8)
    result = dataclasses.replace(out, labels=labels, votes=votes, unlabelled_code=code,
                                 voted=_voted(idx, out, P))
    if init_labels is None and warn:
        warn_missing_motions(seq, labels, C)
    return result


