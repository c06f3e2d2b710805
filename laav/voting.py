"""LAAV's fine-tuning and everything this project adds to Random Voting.

The paper's Random Voting (Jung et al. 2014) is :mod:`laav.rv`. This module is the
public entry point, :func:`random_voting`, which runs it either as plain RV (random
starts) or as LAAV's fine-tuning (one *informed* trial started from the coarse labels,
as the LAAV paper says), and then the steps beyond both papers, each a named setting
(``docs/ALGORITHM.md`` has the table with what each measured):

* **Refinement** (``rv_refine``). Every motion fits robust fundamental matrices on its own
  points over a fixed spread of frame pairs; points their own motion does not explain
  move to the motion with the smallest mean Sampson distance (:func:`refine_labels`).
* **Joint reassignment** (``rv_reassign``). Every point moves to the motion whose robust
  rank-4 trajectory subspace *and* fundamental matrices explain it best together
  (:func:`laav.refine.reassign_labels`).
* **LAAV's own candidates** (``rv_select="laav"``, the default since 2026-12-02; no plain
  RV on complete tracks): the informed trial and ``rv_missing_trials`` (2) trials per pair
  of coarse motions from a *missing-motion start* (:func:`missing_motion_start`), each on its
  own random stream, run side by side, each refined
  and reassigned, the one of least :func:`joint_score` kept (:func:`_own_candidates`;
  when they differ, each is scored after its best moves of at most ``rv_select_descent``
  of the points, so that a few stray points do not decide), which then descends on that
  score (``rv_descent``, :func:`laav.joint.joint_descent`: single points move while the
  score decreases), from its polished labels and from its trial's own, the lower kept
  (``rv_descent_from_trial``). On incomplete tracks it runs as ``"subspace"`` below.
* **Model selection** (``rv_select="joint"``, :meth:`LaavParams.with_plain_rv`, the
  default 2026-12-01 to 12-02; ``"subspace"`` before). Voting can converge on, or end at,
  a wrong partition, and the epipolar fit cannot tell (a static background and a
  translating object satisfy one fundamental matrix). Candidate labellings are compared
  after refinement and reassignment by :func:`joint_score` per point (lossy coding length
  + ``coarse_epipolar_weight`` x epipolar cost; with ``"subspace"``, and on incomplete
  data, after refinement by :func:`subspace_cost`) plus ``rv_select_agreement`` times
  their mean disagreement with the other candidates. Plain RV with no converged trial
  chooses among the consensus and its trials; LAAV's fine-tuning then also runs plain RV
  beside the informed trial (two more runs when they disagree on more than 5 % of the
  points) and chooses among all; on incomplete tracks LAAV's coarse labels themselves are
  a candidate too (``rv_coarse_candidate``, :func:`_coarse_candidate`: Random Voting can
  drift away from right coarse labels there). With ``rv_select="none"``
  (:meth:`LaavParams.paper`) the fine-tuning is the informed trial alone, converged or
  not, and plain RV ends with the consensus when no trial converged.

The refinement, reassignment and selection compare squared distances with a few absolute
constants (:mod:`laav.refine`); they are in units of ``1 / rv_lambda`` (the squared
distance at which a vote fades), so that scaling the coordinates by ``s`` and
``rv_lambda`` by ``1 / s^2`` gives the same labels (:func:`unit2`). The joint score's
coding length has its own distortion ``coding_eps`` in px: scale it by ``s`` too
(:meth:`LaavParams.scaled` scales both).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from ._interrupt import check as check_interrupt
from ._random import resolve_seed
from ._sequence import Sequence, as_points, check_degenerate, warn_missing_motions
from ._threads import single_threaded
from .coding import principal_trajectories
from .joint import joint_descent, joint_score, unit2
from .metrics import misclassification_rate
from .params import LaavParams, as_params
from .refine import (
    _memo,
    assign_by_subspace,
    assign_jointly,
    fit_memo,
    frame_pairs,
    labelling_cost,
    motion_distances,
    reassign_labels,
    refine_labels,
    subspace_cost,
)
from .rv import consensus, consensus_seed, run_trials, vote
from .subspace_votes import (  # noqa: F401 (SUBSPACE_VOTES_MIN_START re-exported)
    SUBSPACE_VOTES_MIN_START,
    SubspaceVotes,
    for_informed_trial,
    votes_with_subspace,
)

__all__ = ["Voting", "random_voting", "vote", "refine_labels", "motion_distances", "frame_pairs",
           "labelling_cost", "subspace_cost", "reassign_labels", "joint_score",
           "missing_motion_start", "informed_preview"]

#: In LAAV's fine-tuning with model selection, when the informed trial and plain RV's
#: converged trial disagree on more than this share of the points, two more plain RV
#: runs join the candidates, so that the selection's agreement term can arbitrate.
_ARBITRATE_ABOVE = 0.05


#: Fields outside ``rv_*`` that the fine-tuning reads: the joint score's (the selection of
#: ``rv_select="joint"`` and ``"laav"``). A memo of voting results must key on them too.
SELECTION_FIELDS = ("coarse_epipolar_weight", "coding_eps")
#: ``rv_*`` fields that plain Random Voting's runs and their polished candidates do not read
#: (LAAV's fine-tuning does): a cache of plain RV may leave them out of its key.
NOT_PLAIN_FIELDS = ("rv_coarse_candidate", "rv_descent", "rv_select_descent", "rv_missing_trials",
                    "rv_descent_from_trial")


@dataclass(frozen=True, eq=False)
class Voting:
    """Result of Random Voting.

    Attributes
    ----------
    labels : ndarray of shape (P,), int64
        Final motion label of every point, in ``0 .. C-1``; on incomplete tracks -1 for a
        point seen too briefly to decide (``unlabelled_code``).
    votes : ndarray of shape (P, C)
        Vote histogram of the returned trial at its end (for ``selected == "coarse"``, no
        trial: the informed start's votes, zero for the points in no atom).
    changed : ndarray of shape (T,), int64
        Number of labels changed at each iteration of the returned trial (empty for
        ``"coarse"``, with ``margin`` empty and ``converged`` False).
    margin : ndarray of shape (T,)
        Mean normalised vote margin (best minus second best over their sum) per iteration.
    n_iterations : int
        Every voting iteration the result rests on: summed over all trials of every run
        (LAAV's informed trial, plain RV's trials, cancelled ones included; with
        ``plain_memo``, plain RV's were performed by the call that filled it).
    n_trials : int
        Trials run.
    converged : bool
        Whether the returned trial met the convergence test.
    trial_iterations : tuple of int
        Iterations of each trial.
    initialised : bool
        True when started from given labels (LAAV fine-tuning), False for plain RV.
    refined : int
        Points whose label the final refinement changed.
    reassigned : int
        Points whose label the joint reassignment then changed (``rv_reassign``).
    descended : int
        Points whose label the descent on the joint score then changed (``rv_descent``,
        with ``rv_select="laav"`` on complete tracks; :func:`laav.joint.joint_descent`).
    unpolished : bool
        True when the labels returned descend from the kept trial's own labels, the
        refinement and reassignment dropped because that descent scored lower
        (``rv_descent_from_trial``); ``refined`` is then 0, ``descended`` counts the points
        moved from the trial's labels, and ``reassigned`` too is 0, except above
        ``rv_max_points`` points, where it counts the reassignment over every point that
        follows the voted subset's descent.
    selected : str
        Which candidate labelling was returned: ``"trial"`` (a converged trial),
        ``"consensus"`` (co-association of unconverged trials), ``"trial k"`` (the k-th
        unconverged trial, by the selection's score), ``"informed"`` (LAAV's start); in LAAV's
        fine-tuning the plain RV candidates are named ``"plain trial"``, ``"plain
        consensus"``, ``"plain trial k"`` (``"plain 2 …"``, ``"plain 3 …"`` for the
        arbitrating runs), ``"coarse"`` the coarse labels themselves (incomplete tracks,
        ``rv_coarse_candidate``), and with ``rv_select="laav"`` ``"missing motion (g+h)"``
        the (first) trial from that start, ``"missing motion (g+h), trial k"`` its k-th
        (``rv_missing_trials``).
    informed_changed, informed_margin : ndarray of shape (T0,) or None
        LAAV's informed trial's own trace (labels changed, mean margin per iteration),
        whichever candidate was returned; None for plain RV.
    label_trace : ndarray of shape (T + 1, P'), int8 (int32 above 127 motions), or None
        The returned trial's labels at its start (row 0: for LAAV's trial the coarse
        labels, the points in no atom at random; for plain RV random) and after each of
        its T iterations (before the refinement and reassignment), over the points that
        voted: P' = P unless ``voted`` says which (more than ``rv_max_points`` points: a
        seeded subset voted; incomplete tracks: the points some voting frame pair sees).
        A record for the explorer's error-per-iteration chart: ``changed[t]`` is the
        number of points whose label differs between rows t and t + 1. For a consensus,
        the last trial's (as ``changed`` and ``margin`` are); None for ``"coarse"``.
    informed_label_trace : ndarray of shape (T0 + 1, P'), int8, or None
        The same for LAAV's informed trial, whichever candidate was returned; None for
        plain RV.
    voted : ndarray of shape (P',), int64, or None
        The points the voting ran on, in the order of the traces' columns (and of
        ``votes`` before it was spread over every point); None when every point voted.
    informed_converged : bool or None
        Whether LAAV's informed trial met the convergence test; None for plain RV.
    informed_subspace_weight : float or None
        The subspace votes' weight in LAAV's informed trial (``rv_subspace_weight``, ours;
        0 when it voted as Random Voting does: the paper preset, missing data, or a start
        labelling under :data:`SUBSPACE_VOTES_MIN_START` of the points); None for plain RV
        and when no voting ran (C = 1, or fewer than 2 frames).
    unlabelled_code : ndarray of shape (P,), int8, or None
        Missing data only (None on complete data): why each point has label -1, a key of
        :data:`laav._visibility.UNLABELLED_REASONS` (1: seen too briefly, no voting frame
        pair sees it); 0 for a labelled point.
    costs : dict of str -> float
        Selection score of each candidate compared (empty without ``rv_select``): its own
        cost (:attr:`score`) plus ``rv_select_agreement`` times its mean disagreement with
        the other candidates (when there are more than two).
    score : str
        What the candidates' own cost was: ``"joint"`` (coding length + epipolar cost per
        point of the reassigned labels, :func:`joint_score`), ``"subspace"`` (the refined
        labels' :func:`subspace_cost`), ``"joint-sum"`` (``rv_select="laav"``: the whole
        labelling's :func:`joint_score`, no agreement term), ``"joint-cleaned"`` (the same,
        each candidate scored after its best moves of at most ``rv_select_descent`` of the
        points), or ``""`` when nothing was compared.
    """

    labels: np.ndarray
    votes: np.ndarray
    changed: np.ndarray
    margin: np.ndarray
    n_iterations: int
    n_trials: int
    converged: bool
    trial_iterations: tuple = field(default=())
    initialised: bool = False
    refined: int = 0
    selected: str = "trial"
    reassigned: int = 0
    costs: dict = field(default_factory=dict)
    descended: int = 0
    unpolished: bool = False
    informed_changed: np.ndarray | None = None
    informed_margin: np.ndarray | None = None
    informed_converged: bool | None = None
    informed_subspace_weight: float | None = None
    unlabelled_code: np.ndarray | None = None
    score: str = ""
    label_trace: np.ndarray | None = field(default=None, repr=False)
    informed_label_trace: np.ndarray | None = field(default=None, repr=False)
    voted: np.ndarray | None = field(default=None, repr=False)


@single_threaded  # one BLAS/OpenMP thread, restored after (laav/_threads.py)
def random_voting(seq: Sequence | np.ndarray, n_motions: int, params: LaavParams | None = None,
                  seed: int | np.random.Generator | None = 0, init_labels: np.ndarray | None = None,
                  weights: np.ndarray | None = None, *, random_state=None,
                  plain_memo: dict | None = None, visible: np.ndarray | None = None,
                  check_input: bool = True, helper=None) -> Voting:
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
        Same seed, same labels.
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
        in the helper's process, half here; the labels are those without it.

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
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
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
                        helper=helper)


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
        out = _finish(points, C, params, best, trials, False, "trial", mk=mk)
    elif select:  # no trial converged: the consensus or one of the trials
        out = _select(points, C, params, _plain_candidates(None, ended, C, rng), trials,
                      initialised=False, mk=mk)
    else:
        out = _finish(points, C, params, consensus(ended, C, rng), trials, False, "consensus",
                      mk=mk)
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
    """What :func:`_with_informed` reads of an informed trial's subspace votes (their
    ``weight``), kept in a memo without their (2F, P) subspace matrix."""

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
    pol = _Polished(points, C, params, first[0])
    if plain_memo is not None:  # the selection's own polish of this candidate: not done again
        plain_memo["informed polished"] = (_own_key(first[0], params), pol)
    return _with_informed(_finish(points, C, params, first, trials, True, "informed",
                                  polished=pol), first, extra)


def _own_key(labels: np.ndarray, params: LaavParams) -> tuple:
    """What LAAV's polished informed candidate depends on beyond the ``plain_memo``'s own
    key (seed, C, ``rv_*``): its labels and the selection's fields."""
    return (labels.tobytes(),) + tuple(getattr(params, f) for f in SELECTION_FIELDS)


def _fine_tuning(points, C, params, rng, init_labels, weights, select, plain_memo,
                 mk=None, helper=None) -> Voting:
    """LAAV's fine-tuning: the informed trial started from ``init_labels`` and, with the
    selection, plain RV's runs beside it (see the module docstring). ``mk`` (missing
    data): a :class:`_Masks`."""
    masks = None if mk is None else (mk.visible, mk.pool)
    init, labels0, votes0 = _informed_start(points, C, params, rng, init_labels, weights)
    known = init >= 0
    if params.rv_select == "laav" and mk is None:
        return _own_candidates(points, C, params, rng, init, labels0, votes0, helper)
    if not select:  # the LAAV paper's fine-tuning: the informed trial alone
        extra = for_informed_trial(points, params, known, masks)  # ours: subspace votes
        first, _, trials, _ = run_trials(points, C, params, rng, (labels0, votes0), n_plain=0,
                                         masks=masks, extra=extra)
        return _with_informed(_finish(points, C, params, first, trials, True, "informed", mk=mk),
                              first, extra)
    # LAAV's start against plain RV: keep the labelling of lower selection score. The
    # informed trial and plain RV's trials each draw from their own generator, so they run
    # apart; plain RV's runs do not depend on the start and may come from ``plain_memo``.
    streams = rng.spawn(1 + params.rv_trials)  # [informed, plain 0, plain 1, ...]
    first, trials, extra = _first_trial(points, C, params, streams[0], labels0, votes0, known,
                                        masks, plain_memo)
    plain, more, cands = _plain_run(points, C, params, rng, streams, plain_memo, 1, masks)
    trials, cands = trials + more, [("informed", first)] + cands
    if plain is not None and misclassification_rate(first[0], plain[0]) > _ARBITRATE_ABOVE:
        # LAAV's start and plain RV disagree: two more plain RV runs arbitrate
        for k in (2, 3):
            _, more, kc = _plain_run(points, C, params, rng, rng.spawn(1 + params.rv_trials),
                                     plain_memo, k, masks)
            trials, cands = trials + more, cands + kc
    if params.rv_coarse_candidate and mk is not None and known.any():
        # ours, on incomplete tracks: the coarse labels themselves (see _coarse_candidate)
        cands.append(("coarse", _coarse_candidate(points, C, params, init, labels0, votes0, mk)))
    # the polished candidates' costs read the selection's fields too: keyed on them, so a
    # caller may keep the memo across changes of those (plain RV's runs stay valid)
    polished = None if plain_memo is None else _polished_memo(plain_memo, params)
    own = None if plain_memo is None or mk is not None else plain_memo.get("informed polished")
    own = own[1] if own is not None and own[0] == _own_key(first[0], params) else None
    return _with_informed(_select(points, C, params, cands, trials, initialised=True,
                                  polished=polished, mk=mk, own=own), first, extra)


#: How many values of the selection's fields keep their polished plain-RV candidates in a
#: plain-RV memo (a slider over ``coding_eps`` would otherwise add one set per value).
POLISHED_KEPT = 2


def _polished_memo(plain_memo: dict, params: LaavParams) -> dict:
    """The polished candidates of ``plain_memo`` for the selection's present fields, the
    most recent :data:`POLISHED_KEPT` sets kept (the others are recomputed if asked again,
    to the same costs)."""
    key = ("polished",) + tuple(getattr(params, f) for f in SELECTION_FIELDS)
    polished = plain_memo.pop(key, {})
    plain_memo[key] = polished  # the most recent last
    sets = [k for k in plain_memo if isinstance(k, tuple) and k[:1] == ("polished",)]
    for k in sets[:-POLISHED_KEPT]:
        del plain_memo[k]
    return polished


def _coarse_candidate(points, C, params, init, labels0, votes0, mk: _Masks) -> tuple:
    """LAAV's coarse labels ``init`` (P,) on incomplete tracks (``mk``) as a candidate
    labelling of the selection (ours, ``rv_coarse_candidate``), in :func:`laav.rv.run_trials`'
    form with no voting: the points in no atom (-1) go to the motion whose trajectory
    subspace and fundamental matrices, fitted on the coarse labels' visible entries, explain
    them best (:func:`laav.refine.assign_jointly`); a point it cannot place keeps its label
    of the informed start ``labels0``. ``votes0`` (P, C): the informed start's votes."""
    labels = init.copy()
    rest = np.flatnonzero(init < 0)
    if rest.size:
        labels[rest] = assign_jointly(points, init, C, rest, unit2(params), min_frames=2,
                                      visible=mk.visible, pairs=mk.pairs)
    labels = np.where(labels >= 0, labels, labels0)
    return labels, votes0, np.zeros(0, dtype=np.int64), np.zeros(0), 0, False


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


def _own_candidates(points, C, params, rng, init, labels0, votes0, helper=None) -> Voting:
    """``rv_select="laav"``: LAAV's informed trial and its missing-motion starts
    (``rv_missing_trials`` trials each), each polished, the one of least
    :func:`joint_score` kept and descended (with ``rv_descent_from_trial`` from its polished
    and its unpolished labels, the lower kept; see :class:`LaavParams`)."""
    P = points.shape[1]
    pairs = [(g, h) for g in range(C) for h in range(g + 1, C)]
    streams = rng.spawn(1 + len(pairs))  # [coarse start, one per pair]
    starts = [("informed", labels0, votes0, streams[0], init >= 0)]
    for (g, h), stream in zip(pairs, streams[1:]):
        start = missing_motion_start(points, init, C, g, h, params,
                                     max(8, params.rv_sample_size))
        if start is None:
            continue
        known2 = start >= 0
        # the first trial on the pair's own stream, as with one trial; the others on
        # streams spawned from it (spawning draws nothing: the first trial is unchanged)
        more = stream.spawn(params.rv_missing_trials - 1)
        for k, trial_rng in enumerate([stream] + more, start=1):
            lab = np.where(known2, start, trial_rng.integers(0, C, P))
            vot = np.zeros((P, C))
            vot[np.arange(P), lab] = np.where(known2, params.rv_label_weight, 0.0)
            name = f"missing motion ({g}+{h})" + (f", trial {k}" if k > 1 else "")
            starts.append((name, lab, vot, trial_rng, known2))
    uses = [votes_with_subspace(params, known) for *_, known in starts]
    extra = (SubspaceVotes(points, params.rv_subspace_weight, params.rv_subspace_sample)
             if any(uses) else None)  # one for every trial that uses it: the same term
    results, finished, cost, fits = _candidates(points, C, params, [s[1:4] for s in starts], extra,
                                                uses, helper)
    first, first_extra = results[0], extra if uses[0] else None
    trials = list(results)
    polished = {key: _Finished(f) for key, f in finished.items()}
    finals = {key: f[0] for key, f in finished.items()}
    clean = params.rv_select_descent > 0 and len({f.tobytes() for f in finals.values()}) > 1
    proj = None
    if clean:  # ours: each scored after its best moves of a few points (rv_select_descent)
        proj = _projection(points, fits)  # one projection for every descent here
        missing = {key: f for key, f in finals.items() if key not in cost}
        cost.update(_cleaned_costs(points, C, params, missing, fits, proj))
    else:
        proj = _projection(points, fits)
        cost = {key: joint_score(points, f, C, params, fits=fits, projected=proj)
                for key, f in finals.items()}
    entries = [(name, res, polished[res[0].tobytes()], cost[res[0].tobytes()])
               for (name, *_), res in zip(starts, results)]
    scores = np.array([e[3] for e in entries])
    k = int(np.argmin(scores))  # the first of equal scores: the coarse start
    name, res, pol, _ = entries[k]
    costs = {e[0]: float(e[3]) for e in entries}
    out = _finish(points, C, params, res, trials, True, name, polished=pol, costs=costs,
                  score="joint-cleaned" if clean else "joint-sum")
    if params.rv_descent:  # ours: the kept labelling descends on the same score
        trial = np.asarray(res[0], dtype=np.int64)
        # ours: the trial's own labels descend too, unless the polish left them as they were
        both = params.rv_descent_from_trial and not np.array_equal(trial, out.labels)
        labels, moved, score = joint_descent(points, out.labels, C, params, projected=proj,
                                             fits=fits, return_score=True)
        if both:
            raw, raw_moved, raw_score = joint_descent(points, trial, C, params, projected=proj,
                                                      fits=fits, return_score=True)
            if raw_score < score:  # the refinement and reassignment are not kept
                out = dataclasses.replace(out, refined=0, reassigned=0, unpolished=True)
                labels, moved = raw, raw_moved
        out = dataclasses.replace(out, labels=labels, descended=moved)
    return _with_informed(out, first, first_extra)


def _informed_side_by_side(points, params, starts, extra, uses) -> list:
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


def _projection(points: np.ndarray, fits: dict) -> np.ndarray:
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
    """A candidate polished elsewhere (:func:`candidate_part`): its :meth:`_Polished.final`."""

    def __init__(self, final: tuple):
        self._final = final

    def final(self) -> tuple:
        return self._final


def _cleaned_costs(points, C, params, finals: dict, fits, proj) -> dict:
    """The selection's cleaned cost (``rv_select_descent``) of every labelling of ``finals``:
    its joint score after its best moves of at most that share of the points."""
    most = int(np.ceil(params.rv_select_descent * points.shape[1]))
    return {key: joint_descent(points, f, C, params, max_moves=most, projected=proj,
                               return_score=True, fits=fits)[2] for key, f in finals.items()}


def candidate_part(points, C, params, starts, extra, uses, always_cost: bool = False) -> tuple:
    """Some of LAAV's own candidates (:func:`_own_candidates`): the trials of ``starts``
    side by side (:func:`_informed_side_by_side`), every distinct trial labelling polished
    (refinement and reassignment), and, with ``rv_select_descent``, their cleaned costs
    when ``always_cost`` or when their polished labellings differ (as the selection needs
    them then). Returns (results, {key: polished (labels, refined, reassigned)},
    {key: cleaned cost}, the memo of motion fits), keys the trial labels' bytes."""
    results = _informed_side_by_side(points, params, starts, extra, uses)
    fits = fit_memo(points)  # candidates share most motions: each motion's fits made once (same numbers)
    finished: dict = {}
    for res in results:
        key = res[0].tobytes()  # trials that end on the same labels share their polish
        if key not in finished:
            check_interrupt()  # a caller's stop request, between polishes
            finished[key] = _Polished(points, C, params, res[0], fits=fits).final()
    cost: dict = {}
    if params.rv_select_descent > 0 and (
            always_cost or len({f[0].tobytes() for f in finished.values()}) > 1):
        cost = _cleaned_costs(points, C, params, {k: f[0] for k, f in finished.items()}, fits,
                              _projection(points, fits))
    return results, finished, cost, fits


def _candidates(points, C, params, starts, extra, uses, helper) -> tuple:
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


def _plain_run(points, C, params, rng, streams, memo, k, masks=None):
    """Plain RV's k-th run of LAAV's fine-tuning on ``streams`` (``[unused, plain 0, ...]``):
    (its converged trial or None, every trial it ran, its candidate labellings).

    With ``memo`` (a dict kept by the caller for one sequence, C, seed and ``rv_*``
    settings) a run is computed once: plain RV does not depend on LAAV's start. Its one
    draw from ``rng`` (the consensus's seed) is then made again, so that every later draw
    is what a fresh run would make: the labels are identical either way. ``masks``:
    missing data, as :func:`laav.rv.run_trials` takes them.
    """
    hit = None if memo is None else memo.get(("run", k))
    if hit is None:
        _, conv, trials, ended = run_trials(points, C, params, None, streams=streams, masks=masks)
        cons = consensus(ended, C, rng) if conv is None else None
        hit = (conv, trials, ended, cons)
        if memo is not None:
            memo[("run", k)] = hit
    elif hit[0] is None:
        consensus_seed(rng)
    conv, trials, ended, cons = hit
    prefix = "plain " if k == 1 else f"plain {k} "
    if conv is not None:
        return conv, trials, [(prefix + "trial", conv)]
    return None, trials, ([(prefix + "consensus", cons)]
                          + [(f"{prefix}trial {i}", t) for i, t in enumerate(ended)])


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


def _with_informed(voting: Voting, first: tuple, extra) -> Voting:
    """``voting`` with LAAV's informed trial's own trace attached, and the weight of the
    subspace votes it ran with (``extra``: its :class:`~laav.subspace_votes.SubspaceVotes`,
    or None: 0)."""
    return dataclasses.replace(voting, informed_changed=first[2], informed_margin=first[3],
                               informed_converged=bool(first[5]),
                               informed_label_trace=first[6].dense() if len(first) > 6 else None,
                               informed_subspace_weight=0.0 if extra is None else extra.weight)


class _Polished:
    """A candidate labelling refined (:func:`refine_labels`) and, on demand, jointly
    reassigned (:func:`reassign_labels`), with its selection cost (:meth:`cost`: the
    joint score of the reassigned labelling, or the subspace cost of the refined one;
    see :func:`_select`)."""

    def __init__(self, points, C, params, labels, mk=None, fits=None):
        self.points, self.C, self.params, self.mk = points, C, params, mk
        # complete data: the selection's memo of motion fits (laav.refine.fit_memo), if any
        self._kw = {"fits": fits} if mk is None else {"visible": mk.visible, "pairs": mk.pairs}
        self.refined, self._distances = 0, None
        if params.rv_refine:
            labels, self.refined, self._distances = refine_labels(
                points, labels, C, return_distances=True, unit2=unit2(params), **self._kw)
        self.refined_labels = labels
        self._final = self._cost = None
        #: the cost :meth:`cost` takes (``Voting.score``): the joint score needs whole tracks
        self.kind = "joint" if mk is None and params.rv_select in ("joint", "laav") else "subspace"

    def cost(self) -> float:
        """The selection's own cost of this candidate (lower is better): with
        ``rv_select="joint"`` on complete data, :func:`joint_score` of the final labelling
        per point (``inf`` when a motion has fewer than 8 points); otherwise (and on
        incomplete data, where the coding length is not defined) :func:`subspace_cost`
        of the refined labelling."""
        if self._cost is None:
            check_interrupt()  # a caller's stop request (laav._interrupt), before the score
            if self.kind == "joint":
                self._cost = joint_score(self.points, self.final()[0], self.C,
                                         self.params) / self.points.shape[1]
            else:
                self._cost = self.subspace()
        return self._cost

    def subspace(self) -> float:
        """:func:`subspace_cost` of the refined labelling (on incomplete data, subspaces
        fitted on the visible entries)."""
        kw = {} if self.mk is None else {"visible": self.mk.visible}
        return subspace_cost(self.points, self.refined_labels, self.C, unit2=unit2(self.params),
                             **kw)

    def final(self) -> tuple[np.ndarray, int, int]:
        """(labels, points moved by the refinement, points moved by the reassignment)."""
        if self._final is None:
            labels, moved = self.refined_labels, 0
            if self.params.rv_reassign:
                check_interrupt()  # a caller's stop request, before the reassignment
                labels, moved = reassign_labels(self.points, labels, self.C,
                                                distances=self._distances,
                                                unit2=unit2(self.params), **self._kw)
            self._final = (labels, self.refined, moved)
        return self._final


def _finish(points, C, params, best, trials, initialised, selected, polished=None,
            costs=None, mk=None, score="") -> Voting:
    labels, votes, changed, margin, _its, conv = best[:6]
    labels, refined, reassigned = (_Polished(points, C, params, labels, mk) if polished is None
                                   else polished).final()
    return Voting(
        labels=np.asarray(labels, dtype=np.int64),
        votes=votes,
        changed=changed,
        margin=margin,
        n_iterations=int(sum(t[4] for t in trials)),
        n_trials=len(trials),
        converged=bool(conv),
        trial_iterations=tuple(int(t[4]) for t in trials),
        initialised=initialised,
        refined=refined,
        selected=selected,
        costs=dict(costs or {}),
        reassigned=reassigned,
        score=score,
        label_trace=best[6].dense() if len(best) > 6 else None,
    )


def _plain_candidates(converged, trials, C, rng, prefix=""):
    """Plain RV's candidate labellings: its converged trial, else the consensus and every trial."""
    if converged is not None:
        return [(prefix + "trial", converged)]
    return ([(prefix + "consensus", consensus(trials, C, rng))]
            + [(f"{prefix}trial {k}", t) for k, t in enumerate(trials)])


def _partition_key(labels: np.ndarray) -> bytes:
    """The same bytes for two labellings that are one partition under renamed labels."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))  # labels renamed by first appearance
    return order[inverse].astype(np.int64).tobytes()


def _select(points, C, params, candidates, trials, initialised, polished=None, mk=None,
            own=None) -> Voting:
    """Polish every candidate labelling and return the one of lowest selection score.

    Every candidate is refined (:func:`refine_labels`) and, when the score, the agreement
    term or its win needs it, jointly reassigned (:func:`reassign_labels`). The score is the
    candidate's own cost (:meth:`_Polished.cost`: with ``rv_select="joint"``
    (:meth:`LaavParams.with_plain_rv`; plain RV alone also under the default ``"laav"``),
    :func:`joint_score` per point of the reassigned labelling; with ``"subspace"`` the
    refined labelling's :func:`subspace_cost`) plus ``rv_select_agreement`` times its mean
    disagreement (misclassification rate) with the other polished candidates, when there
    are more than two: among many unconverged trials, the labelling the others agree with
    is the safer pick. When no candidate has a finite joint score (every one leaves a
    motion under 8 points), their subspace costs decide. ``own``: LAAV's informed candidate
    already polished (by :func:`informed_preview`), used for it. (For ``"subspace"``, the cost is
    taken before the reassignment, which fits rank-4
    subspaces and so makes every candidate's subspace cost alike; the agreement after it,
    where candidates that differ only by boundary points agree. Measured on Hopkins155,
    10 seeds, weight 2, against cost and agreement both before or both after: LAAV
    0.59 % against 0.65 % / 0.59 %, plain RV 0.55 % against 0.64 % / 0.58 %;
    benchmarks/TUNING.md.)
    """
    n = len(candidates)
    done: dict = {}  # candidates that are the same partition (often) are polished once
    entries = []
    for name, cand in candidates:
        key = _partition_key(cand[0])
        if key not in done:
            check_interrupt()  # a caller's stop request, between polishes (plain RV's 11)
            # plain RV's candidates from the memo; LAAV's own is polished afresh, so that a
            # plain one of the same partition takes its label names, as in a fresh run
            if polished is not None and key in polished and name.startswith("plain"):
                done[key] = polished[key]
            elif name == "informed" and own is not None:  # polished by informed_preview
                done[key] = (own, own.cost())
            else:
                pol = _Polished(points, C, params, cand[0], mk)
                done[key] = (pol, pol.cost())
                if polished is not None and name.startswith("plain"):
                    polished[key] = done[key]  # plain RV's: the same on every rerun
        entries.append((name, cand) + done[key])
    scores = np.array([e[3] for e in entries])
    score = entries[0][2].kind
    if not np.isfinite(scores).any():  # joint: every candidate has a motion under 8 points
        scores, score = np.array([e[2].subspace() for e in entries]), "subspace"
    if n > 2 and params.rv_select_agreement > 0:
        D = np.zeros((n, n))
        for i in range(n):
            for j in range(i + 1, n):
                D[i, j] = D[j, i] = misclassification_rate(entries[i][2].final()[0],
                                                           entries[j][2].final()[0])
        with np.errstate(invalid="ignore"):  # inf cost stays inf
            scores = scores + params.rv_select_agreement * D.sum(1) / (n - 1)
    k = int(np.argmin(scores))  # the first of equal scores: LAAV's start, then the consensus
    name, cand, pol, _ = entries[k]
    costs = {e[0]: float(v) for e, v in zip(entries, scores)}
    return _finish(points, C, params, cand, trials, initialised, selected=name,
                   polished=pol, costs=costs, mk=mk, score=score)
