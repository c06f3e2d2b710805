"""The result of :func:`laav.random_voting`: :class:`Voting`.

In a module of its own so that the fine-tuning's parts beyond the papers
(:mod:`laav.selection`, :mod:`laav.own_chain`) build it without importing the entry point,
:mod:`laav.voting`, which imports them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Voting"]


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
    skipped_starts : tuple of str
        Ours, ``rv_missing_gate`` > 0: the missing-motion starts whose trials did not run,
        the informed trial's result explaining their new motion (names as in
        :attr:`costs`, without a trial number).
    vetoed : tuple of tuple
        Ours, ``rv_outlier_veto``: one ``(what, points, kept's cost, its cost)`` per choice of
        the joint score that was not made because, over the ``points`` (a count) both
        labellings explain, the labels it would have replaced score lower
        (:func:`laav.own_chain.veto`): ``what`` names a missing-motion start's trial
        (compared with LAAV's informed trial, whose cost is the kept one; the next candidate
        the veto lets through is returned, else the informed trial), ``"the descent"`` (the
        labels before it kept) or ``"the trial's own labels, descended"`` (the polished ones
        kept); empty when none was.
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
    skipped_starts: tuple = ()
    vetoed: tuple = ()
