"""Ours, beyond both papers: polishing a candidate labelling, and choosing among several.

:func:`laav.random_voting` ends every trial it returns with these steps (each a setting;
``docs/ALGORITHM.md`` has what each measured):

* **Refinement** (``rv_refine``). Every motion fits robust fundamental matrices on its own
  points over a fixed spread of frame pairs; points their own motion does not explain
  move to the motion with the smallest mean Sampson distance (:func:`laav.refine.refine_labels`).
* **Joint reassignment** (``rv_reassign``). Every point moves to the motion whose robust
  rank-4 trajectory subspace *and* fundamental matrices explain it best together
  (:func:`laav.refine.reassign_labels`). :class:`Polished` is a labelling after both.
* **Model selection** (``rv_select="joint"``, :meth:`laav.LaavParams.with_plain_rv`;
  ``"subspace"`` before; :func:`select`). Voting can converge on, or end at, a wrong
  partition, and the epipolar fit cannot tell (a static background and a translating
  object satisfy one fundamental matrix). Candidate labellings are compared after
  refinement and reassignment by :func:`laav.joint.joint_score` per point (lossy coding
  length + ``coarse_epipolar_weight`` x epipolar cost; with ``"subspace"``, and on
  incomplete data, after refinement by :func:`laav.refine.subspace_cost`) plus
  ``rv_select_agreement`` times their mean disagreement with the other candidates. Plain
  RV with no converged trial chooses among the consensus and its trials; LAAV's
  fine-tuning then also runs plain RV beside the informed trial (:func:`plain_run`; two
  more runs when they disagree on more than :data:`ARBITRATE_ABOVE` of the points) and
  chooses among all; on incomplete tracks LAAV's coarse labels themselves are a candidate
  too (``rv_coarse_candidate``, :func:`coarse_candidate`: Random Voting can drift away
  from right coarse labels there).

The default's own candidates (``rv_select="laav"``) are :mod:`laav.own_chain`'s; they are
polished and built into a :class:`~laav.voting_result.Voting` here too (:func:`finish`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._interrupt import check as check_interrupt
from .joint import joint_score, unit2
from .metrics import misclassification_rate
from .params import LaavParams
from .refine import assign_jointly, reassign_labels, refine_labels, subspace_cost
from .rv import consensus, consensus_seed, run_trials
from .voting_result import Voting

__all__ = ["Polished", "finish", "select", "plain_run", "plain_candidates", "with_informed",
           "coarse_candidate", "SELECTION_FIELDS", "NOT_PLAIN_FIELDS"]

#: Fields outside ``rv_*`` that the fine-tuning reads: the joint score's (the selection of
#: ``rv_select="joint"`` and ``"laav"``). A memo of voting results must key on them too.
SELECTION_FIELDS = ("coarse_epipolar_weight", "coding_eps")
#: ``rv_*`` fields that plain Random Voting's runs and their polished candidates do not read
#: (LAAV's fine-tuning does): a cache of plain RV may leave them out of its key.
NOT_PLAIN_FIELDS = ("rv_coarse_candidate", "rv_descent", "rv_select_descent", "rv_missing_trials",
                    "rv_descent_from_trial", "rv_missing_gate", "rv_outlier_veto")


#: In LAAV's fine-tuning with model selection, when the informed trial and plain RV's
#: converged trial disagree on more than this share of the points, two more plain RV
#: runs join the candidates, so that the selection's agreement term can arbitrate.
ARBITRATE_ABOVE = 0.05


#: How many values of the selection's fields keep their polished plain-RV candidates in a
#: plain-RV memo (a slider over ``coding_eps`` would otherwise add one set per value).
POLISHED_KEPT = 2


def polished_memo(plain_memo: dict, params: LaavParams) -> dict:
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


def coarse_candidate(points, C, params, init, labels0, votes0, mk) -> tuple:
    """LAAV's coarse labels ``init`` (P,) on incomplete tracks (``mk``: the masks of
    missing data, ``laav.voting._Masks``) as a candidate
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


def plain_run(points, C, params, rng, streams, memo, k, masks=None):
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


def with_informed(voting: Voting, first: tuple, extra) -> Voting:
    """``voting`` with LAAV's informed trial's own trace attached, and the weight of the
    subspace votes it ran with (``extra``: its :class:`~laav.subspace_votes.SubspaceVotes`,
    or None: 0)."""
    return dataclasses.replace(voting, informed_changed=first[2], informed_margin=first[3],
                               informed_converged=bool(first[5]),
                               informed_label_trace=first[6].dense() if len(first) > 6 else None,
                               informed_subspace_weight=0.0 if extra is None else extra.weight)


class Polished:
    """A candidate labelling refined (:func:`refine_labels`) and, on demand, jointly
    reassigned (:func:`reassign_labels`), with its selection cost (:meth:`cost`: the
    joint score of the reassigned labelling, or the subspace cost of the refined one;
    see :func:`select`)."""

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


def finish(points, C, params, best, trials, initialised, selected, polished=None,
           costs=None, mk=None, score="") -> Voting:
    """The :class:`~laav.voting_result.Voting` of the returned trial ``best`` (in
    :func:`laav.rv.run_trials`' tuple form), polished (or ``polished``, a :class:`Polished`
    of it), ``trials`` every trial run, ``selected`` its candidate's name."""
    labels, votes, changed, margin, _its, conv = best[:6]
    labels, refined, reassigned = (Polished(points, C, params, labels, mk) if polished is None
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


def plain_candidates(converged, trials, C, rng, prefix=""):
    """Plain RV's candidate labellings: its converged trial, else the consensus and every trial."""
    if converged is not None:
        return [(prefix + "trial", converged)]
    return ([(prefix + "consensus", consensus(trials, C, rng))]
            + [(f"{prefix}trial {k}", t) for k, t in enumerate(trials)])


def partition_key(labels: np.ndarray) -> bytes:
    """The same bytes for two labellings that are one partition under renamed labels."""
    _, first, inverse = np.unique(labels, return_index=True, return_inverse=True)
    order = np.argsort(np.argsort(first))  # labels renamed by first appearance
    return order[inverse].astype(np.int64).tobytes()


def select(points, C, params, candidates, trials, initialised, polished=None, mk=None,
            own=None) -> Voting:
    """Polish every candidate labelling and return the one of lowest selection score.

    Every candidate is refined (:func:`refine_labels`) and, when the score, the agreement
    term or its win needs it, jointly reassigned (:func:`reassign_labels`). The score is the
    candidate's own cost (:meth:`Polished.cost`: with ``rv_select="joint"``
    (:meth:`LaavParams.with_plain_rv`; plain RV alone also under the default ``"laav"``),
    :func:`joint_score` per point of the reassigned labelling; with ``"subspace"`` the
    refined labelling's :func:`subspace_cost`) plus ``rv_select_agreement`` times its mean
    disagreement (misclassification rate) with the other polished candidates, when there
    are more than two: among many unconverged trials, the labelling the others agree with
    is the safer pick. When no candidate has a finite joint score (every one leaves a
    motion under 8 points), their subspace costs decide. ``own``: LAAV's informed candidate
    already polished (by :func:`laav.voting.informed_preview`), used for it. (For ``"subspace"``, the cost is
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
        key = partition_key(cand[0])
        if key not in done:
            check_interrupt()  # a caller's stop request, between polishes (plain RV's 11)
            # plain RV's candidates from the memo; LAAV's own is polished afresh, so that a
            # plain one of the same partition takes its label names, as in a fresh run
            if polished is not None and key in polished and name.startswith("plain"):
                done[key] = polished[key]
            elif name == "informed" and own is not None:  # polished by informed_preview
                done[key] = (own, own.cost())
            else:
                pol = Polished(points, C, params, cand[0], mk)
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
    return finish(points, C, params, cand, trials, initialised, selected=name,
                   polished=pol, costs=costs, mk=mk, score=score)
