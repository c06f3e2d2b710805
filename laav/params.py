"""Parameters of LAAV and Random Voting, validated on construction."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

__all__ = ["LaavParams", "PRESETS", "STAGE_PARAMS", "stages_affected", "PIXEL_PARAMS", "STRENGTH_PARAMS"]

#: Lengths in pixels: for coordinates ``s`` times pixels, multiply these by ``s`` ...
PIXEL_PARAMS = ("r1", "r2", "affine_threshold", "edge_scale", "coding_eps")
#: ... and these strengths (1/px^2) by ``1 / s^2`` (:meth:`LaavParams.scaled`). Every
#: other field is a count, a share or a weight of dimensionless terms.
STRENGTH_PARAMS = ("lam", "rv_lambda")


@dataclass(frozen=True)
class LaavParams:
    """Every tunable of the LAAV pipeline and of Random Voting.

    Distances are in pixels of the input coordinates. Defaults were chosen on Hopkins155
    (see ``benchmarks/TUNING.md`` for the sweeps that chose them).

    Units: the lengths :data:`PIXEL_PARAMS` are in pixels, the strengths
    :data:`STRENGTH_PARAMS` in 1/px^2, every other field is dimensionless. The stages'
    own constants are expressed in these parameters, so coordinates scaled by ``s`` with
    :meth:`scaled` ``(s)`` give the same labels (``docs/ALGORITHM.md``, "Units and scale").

    Parameters
    ----------
    r1 : float
        Inner atom radius (px). Features within ``r1`` of an atom's seed belong to that
        atom only and are never seeds or members of later atoms.
    r2 : float
        Outer atom radius (px), ``r2 > r1``. Candidate members of an atom lie within ``r2``
        of the seed in every frame; the ring ``r1..r2`` may be shared between atoms.
    atom_min_size : int
        Fewest features an atom may have (>= 4: three fix an affine map exactly, the
        fourth is the first one RANSAC can check).
    affine_threshold : float
        RANSAC inlier threshold (px) on a feature's RMS residual over all frames under the
        atom's affine motion model.
    atom_frames : {"all", "pair"}
        Frames an atom's RANSAC judges its features on: ``"all"`` (ours) every frame,
        one affine trajectory; ``"pair"`` (the paper) one random frame pair at least
        ``F // 3`` apart per atom.
    ransac_hypotheses : int
        Minimal samples (seed + 2 neighbours) tried per atom, evaluated as one batch.
    noise_adaptive : bool
        Adapt the residual scales to the tracks' measured pixel noise (ours, issue 12):
        σ̂ is estimated from the data (:func:`laav.noise.estimate_noise`, px) and the
        stages run with :meth:`for_noise` ``(σ̂)``: ``affine_threshold`` becomes
        ``max(affine_threshold, k σ̂)`` (``k`` = 3.35 for ``atom_frames="all"``, the 99 %
        quantile of an inlier's residual under the noise model;
        :func:`laav.noise.threshold_factor`), ``edge_scale`` grows by the same ratio ρ
        and ``lam``, ``rv_lambda`` shrink by ρ². On clean tracks ``k σ̂`` is below
        ``affine_threshold`` and nothing changes. Read by :func:`laav.segment`,
        :class:`laav.Pipeline` and the stage functions ``build_atoms``, ``atom_graph``,
        ``merge_models``; plain Random Voting (:func:`laav.random_voting` called alone)
        runs with the parameters as given.
    graph_neighbors : int
        Each atom is joined to this many nearest atoms besides those it overlaps.
    edge_scale : float
        Forward-backward error (px) at which an edge is neutral (cost 0 before the prior).
    cut_prior : float
        Added to every edge's "cut" side: ``cost = 2 log(edge_scale / error) - cut_prior``.
    fine_models : int or None
        Number of fine motion models the multicut is brought to; None means
        ``fine_per_motion * C``.
    fine_per_motion : int or None
        Fine models per motion when ``fine_models`` is None. None (the default): by the
        merge that runs (:meth:`merge_for`): 4 for the joint merge, 3 for the coding
        merge, 2 for the epipolar merge (the paper's 2C).
    coarse_merge : {"auto", "epipolar", "coding", "joint"}
        How the fine models are merged into C motions: ``"epipolar"`` (the paper's form)
        spectral clustering of the epipolar-vote affinity Z; ``"coding"`` (ours) the
        partition of least lossy coding length of the models' trajectories
        (:mod:`laav.coding`); ``"joint"`` (ours) of the ``coarse_candidates`` partitions
        of least coding length with 8 or more points per motion, the one of least coding
        length + ``coarse_epipolar_weight`` x epipolar cost. The coding and joint merges
        need complete tracks (on incomplete ones the epipolar merge runs, with a
        warning). ``"auto"`` (the default since 2026-12-02): the joint merge on complete
        tracks, the epipolar merge on incomplete ones, without a warning
        (``docs/ALGORITHM.md``, "LAAV's own chain").
    coding_eps : float
        Distortion (px) of the coding length (``coarse_merge="coding"`` or ``"joint"``, and
        the selection's joint score, ``rv_select="joint"`` or ``"laav"``).
    coarse_candidates : int
        ``coarse_merge="joint"``: how many partitions of least coding length (each motion
        with 8 points or more) are re-ranked by their epipolar fit.
    coarse_epipolar_weight : float
        ``coarse_merge="joint"``: weight of the epipolar cost (a sum over the points in
        atoms of ``log(1 + d)``, ``d`` the point's Sampson distance to its motion's robust
        fundamental matrices in units of ``2 / lam``) against the coding length (nats).
        The selection's joint score (``rv_select="joint"`` or ``"laav"``,
        :func:`laav.voting.joint_score`) weighs its epipolar cost over all points by it too.
    lam : float
        Epipolar voting strength lambda of the fine-to-coarse stage (1/px^2).
    coarse_frames : int
        Number of frame pairs used for fine-to-coarse voting (the paper uses 7).
    coarse_samples : int
        Random atom quadruples drawn per model pair and frame pair.
    motion_weight : float
        Weight of the motion-difference term in the fine-to-coarse affinity (0 = off).
    pooled_trials : int
        Trials of model-level (pooled) epipolar voting whose co-association forms Z
        (0 = the paper's pairwise votes only).
    pairwise_weight : float
        Share of the paper's pairwise four-atom epipolar votes in Z, in [0, 1]. Either
        term alone measured the same on Hopkins155 (1.78 % vs 1.80 %, seed 0); the blend
        keeps Z continuous in ``lam`` (the co-association alone moves in steps of
        1/``pooled_trials``, so a λ change often left it unchanged in the explorer).
    rv_lambda : float
        Voting strength of Random Voting (1/px^2).
    rv_alpha : float
        Forgetting factor of Random Voting, ``0 < alpha <= 1``.
    rv_max_iter : int
        Iteration cap per Random Voting trial.
    rv_trials : int
        Most trials of plain Random Voting.
    rv_sample_size : int
        Points per group used to fit each fundamental matrix (>= 8).
    rv_patience : int
        A trial has converged when no label changed for this many iterations.
    rv_label_weight : float
        Initial votes given to atom-labelled features when LAAV initialises Random Voting.
    rv_missing_trials : int
        Ours, with ``rv_select="laav"`` on complete tracks: trials run from each
        missing-motion start (1-100), each on its own random stream (the first on the
        start's, as with one), all candidates of the selection. From the same start a
        trial may grow the missing motion or lose it (2T3RCRT seed 3: 28.7 % with one
        trial, 4.6 % with two). The default 2 was chosen by 5-fold cross-validation grouped
        by video among 1 / 2 / 3 (2 and 3 the same errors on every run; chosen in every
        fold; Hopkins155, 5 seeds: 0.25 -> 0.22 %, held out 0.22 %; three-motion median
        time 0.44 -> 0.54 x plain RV's; ``benchmarks/TUNING.md``, "Two trials per
        missing-motion start").
    rv_missing_gate : float
        Ours, with ``rv_select="laav"``, a speed setting: 0 runs every missing-motion
        start's trials beside the informed trial. Above 0 the informed trial runs and is
        selected alone first, and a start's trials run only when that result leaves at
        least this share of the start's new motion unexplained (farther than 1 px RMS, in
        ``noise_adaptive``'s scaled unit, from its motion's rank-4 trajectory subspace,
        :func:`laav.own_chain.unexplained`). Every start runs when the informed trial did
        not settle, and when the test cannot tell (the median point farther than half the
        threshold from its subspace: pixel noise of about 0.5 px and more); the starts
        skipped are named in ``Voting.skipped_starts``. The default 0.5 (since
        2026-12-05) was chosen by 5-fold cross-validation grouped by video among 0 / 0.25
        / 0.5 / 0.75, ties to the faster; the accuracy is that of 0 within the run-to-run
        noise (Hopkins155, 5 seeds: 0.18 % against 0.19 %, 2 runs better and 1 worse; held
        out 0.19-0.24 % over three fold shuffles; σ = 1 px the same errors), the
        three-motion median time 0.51 -> 0.33 x plain RV's
        (``benchmarks/TUNING.md``, "A gate for the missing-motion starts").
    rv_outlier_veto : bool
        Ours, with ``rv_select="laav"``: a labelling the joint score prefers over all points
        replaces the one it competes with only if it also scores lower on the points both
        explain (:func:`laav.own_chain.veto`): a missing-motion start's candidate against
        LAAV's informed trial (the best-scoring one that passes is kept, else the informed
        trial), and, when they differ on more than ``rv_select_descent`` of
        the points, the descent's result against its start and the trial's own labels
        descended against the polished ones. Tracks that no motion explains (tracking
        failures, drifting tracks) code cheaper as a motion of their own than inside the
        motions they corrupt, so over every point the joint score preferred joining two real
        motions to give them one. Since 2026-12-06; no constant was tuned (an outlier is a
        point farther than 6 times the labelling's median and 1 px^2 from its motion's
        rank-4 subspace, the refinement's factor and the gate's unit), and no Hopkins155
        label moves at σ = 0 (``benchmarks/TUNING.md``, "Outlier tracks"). The choices not
        made are in ``Voting.vetoed``.
    rv_batch : int
        Voting trials run side by side in one batched numpy call (plain RV's random
        starts, and LAAV's informed trial beside them in ``with_plain_rv()`` and on
        incomplete tracks; LAAV's own informed and missing-motion trials, at most
        1 + C(C-1)/2 x ``rv_missing_trials``, which all run to their end, run all side by
        side whatever its value, except that with ``rv_missing_gate`` the informed one runs
        alone first). Speed only: each trial draws from its own random stream and keeps its own
        convergence test, and the trial kept is the same as if they ran one after another,
        so a seed's labels do not depend on it.
    rv_refine : bool
        After voting, reassign each point to the motion whose fundamental matrices (fitted
        on the motion's points over many frame pairs) explain it best.
    rv_reassign : bool
        After the refinement, move every point to the motion whose robust rank-4
        trajectory subspace and fundamental matrices explain it best together
        (:func:`laav.refine.reassign_labels`). With model selection, every candidate
        labelling is polished so before it is scored.
    rv_descent : bool
        Ours, with ``rv_select="laav"`` on complete tracks: the labelling kept then
        descends on the selection's own score, single points moving to another motion
        while :func:`laav.voting.joint_score` decreases (:func:`laav.joint.joint_descent`;
        ``Voting.descended`` counts them; with more than ``rv_max_points`` points it acts on
        the voted subset). Nothing in it was tuned; Hopkins155, 5 seeds: 0.55 -> 0.36 %
        (``benchmarks/TUNING.md``, "Descent on the joint score").
    rv_descent_from_trial : bool
        Ours, with ``rv_descent``: the kept candidate's trial labels, as the trial ended
        (before the refinement and reassignment), descend too, and the lower of the two
        descents' joint scores is returned (``Voting.unpolished``; ``Voting.descended`` then
        counts the points moved from the trial's labels). The refinement and
        reassignment move points by their own rules, not by the score; where they move
        right points (1RT2RTCRT_B seed 4: the trial 8.9 % wrong, polished 11.9 %), the
        score now says so. Nothing tuned; Hopkins155, 5 seeds: 0.22 -> 0.19 %, worst run
        11.9 -> 9.1 %, held out by grouped CV 0.19 % (``benchmarks/TUNING.md``, "The
        descent from the trial's own labels").
    rv_select_descent : float
        Ours, with ``rv_select="laav"`` on complete tracks, when its candidates end on
        different labellings: before they are compared, each candidate descends on the
        joint score (:func:`laav.joint.joint_descent`) moving at most this share of the
        points (rounded up; of the voted subset above ``rv_max_points``), and is scored as
        it then stands; the candidate kept is the polished one, as before (``rv_descent``
        then descends it without a limit). One
        stray trajectory in a small motion can raise a labelling's coding length by about
        1,100 nats, so a right candidate with a few stray points lost to a wrong one; an
        unlimited descent lets wrong candidates overtake (0.59 %). 0: scored as polished
        (before 2026-12-02, late evening). The default 0.03 was chosen by 5-fold
        cross-validation grouped by video among 0 / 0.01 / 0.02 / 0.03 / 0.05 / 0.1 / 1,
        together with ``rv_subspace_weight`` (0.03 and 0.05, the same errors on every run,
        in every fold; Hopkins155, 5 seeds: held out 0.25 %, against 0.43 % held out
        before, ``docs/bench/cv_clean.md``, ``docs/bench/cv_descent.md``;
        ``benchmarks/TUNING.md``, "Cleaning the candidates before the selection").
    rv_subspace_weight : float
        Subspace votes (ours, :class:`laav.subspace_votes.SubspaceVotes`; complete data; LAAV's
        informed trials only, never plain RV's random starts): every voting group also
        fits a rank-4 trajectory subspace to ``rv_subspace_sample`` of its points, and a
        point's vote uses its Sampson distance plus this weight times
        its squared distance to the subspace (px^2 per frame). 0: the epipolar votes of
        Random Voting alone (the RV and LAAV papers, :meth:`paper`). The default 1 was
        chosen for LAAV's own chain by 5-fold cross-validation grouped by source video
        among 0 / 0.3 / 1 / 3 (Hopkins155, 5 seeds: held out 0.62 % before the descent
        on the joint score, 0.43 % with it, ``docs/bench/cv_descent.md``, 0.25 % chosen
        together with ``rv_select_descent``, ``docs/bench/cv_clean.md``; 0 gives 0.76 % on
        all data; LAAV's informed trial converges in 93 % of runs instead of 60 %;
        ``docs/bench/chain_own.md``). :meth:`with_plain_rv` uses 0.3, chosen the same way
        for that chain.
    rv_subspace_sample : int
        Points per group the subspace of the subspace votes is fitted to (8-1000).
    rv_select : {"laav", "none", "joint", "subspace"}
        ``"laav"`` (ours, the default since 2026-12-02): LAAV's own candidates, **no plain
        Random Voting** on complete tracks. The informed trial from the coarse labels, and,
        for every pair of coarse motions, ``rv_missing_trials`` trials from a
        *missing-motion start* (the pair as one motion; the points in no atom that the
        other motions explain worst as the C-th), each refined and reassigned; the one of
        least coding length plus ``coarse_epipolar_weight`` x epipolar cost over all points
        (the joint merge's score) is kept (:func:`laav.voting.joint_score`). On incomplete data it runs as
        ``"subspace"`` (with plain RV: ``docs/ALGORITHM.md``, "Missing data"). Plain Random
        Voting called alone (:func:`laav.random_voting` without ``init_labels``) selects
        among its own trials as with ``"joint"``.
        ``"joint"`` (ours, the default 2026-12-01 to 12-02, :meth:`with_plain_rv`): model
        selection between candidate labellings; plain RV with no converged trial keeps the
        best of the trials and their co-association labelling, and LAAV's fine-tuning
        also runs plain RV (two more runs when the two results disagree on more than 5 %
        of the points) and keeps the best of all. A candidate's score is the joint merge's
        score of its refined and reassigned labelling per point (coding length plus
        ``coarse_epipolar_weight`` x epipolar cost, :func:`laav.voting.joint_score`) plus
        ``rv_select_agreement`` x its mean disagreement with the other candidates. On
        incomplete data (no coding length) it runs as ``"subspace"``.
        ``"subspace"`` (ours, before 2026-12-01): the same, scored by the refined
        labelling's trajectory-subspace cost (:func:`laav.refine.subspace_cost`) and
        agreement. ``"none"`` (the LAAV paper): LAAV's fine-tuning is its informed trial
        alone, converged or not; plain RV with no converged trial ends with the
        co-association labelling.
    rv_select_agreement : float
        Weight (>= 0) of a candidate's mean disagreement (misclassification rate) with
        the other candidates in the selection score, when there are more than two: the
        labelling most others agree with is preferred among costs that are close.
        2.0: chosen under the joint score by 5-fold cross-validation grouped by video
        among 0-4 (in 4 of 5 folds, three fold shuffles; benchmarks/TUNING.md, "The
        selection by the joint score").
    rv_coarse_candidate : bool
        Ours, on incomplete tracks, for the model selection (any ``rv_select`` but
        ``"none"``): LAAV's coarse labels themselves are a candidate beside its
        informed trial and plain RV's, the points in no atom placed by the coarse motions'
        trajectory subspaces and fundamental matrices (:func:`laav.refine.assign_jointly`),
        no voting (``Voting.selected == "coarse"`` when kept). There the informed trial
        seldom converges and Random Voting can drift far from good coarse labels (two
        cranes, 40 % missing: 0 % wrong on the points in atoms, the informed trial 31 %
        after 150 iterations); the selection can now keep them. A third candidate also
        brings in the agreement term (``rv_select_agreement``, used with more than two)
        where LAAV's trial and a converged plain RV trial were the only two: the measured
        effect includes that. Complete tracks are unchanged (there it was measured worse:
        ``docs/ALGORITHM.md``, "Missing data").
    rv_max_points : int or None
        Ours, for thousands of tracks: with more points than this, Random Voting (every
        trial, the refinement, the model selection and the descent) runs on a seeded
        random subset of this many, and every other point then goes to the motion whose
        trajectory subspace and fundamental matrices, fitted on the voted points, explain
        it best (:func:`laav.refine.assign_jointly`, the joint reassignment's rule), then, with
        ``rv_reassign``, the joint reassignment runs over every point. None: every
        point votes (the papers). The fine-to-coarse stage's pooled voting likewise lets
        at most this many atom features vote (:func:`laav.coarse.voting_features`).
        Hopkins155 has at most 556 points, so the default never acts there
        (``docs/ALGORITHM.md``, "Thousands of tracks").

    Validation
    ----------
    Every field is checked on construction against one table (``_BOUNDS`` below): its
    type (numpy scalars are accepted and stored as Python numbers; ``True``/``False``
    are not numbers; NaN and infinity are rejected) and its range. Distances and
    strengths (``r1``, ``r2``, ``affine_threshold``, ``edge_scale``, ``coding_eps``, ``lam``,
    ``rv_lambda``) lie in (0, 1e6] (the strengths, in 1/px^2, in (0, 1e12]: coordinates in
    thousandths of a pixel need 1e6 times the default), ``cut_prior`` in [-1e6, 1e6], the other weights in
    [0, 1e6] (``pairwise_weight`` and ``rv_alpha`` in [0, 1] and (0, 1]). Counts have
    upper bounds that keep one run within seconds and memory within a laptop:
    ``ransac_hypotheses`` <= 1000, ``graph_neighbors`` <= 100, ``fine_models`` <= 1000,
    ``fine_per_motion`` <= 100, ``coarse_candidates`` <= 1000, ``coarse_frames`` <= 100,
    ``coarse_samples`` <= 1000, ``pooled_trials`` <= 100, ``rv_max_iter`` <= 10000,
    ``rv_trials`` <= 100, ``rv_sample_size`` and ``rv_subspace_sample`` in [8, 1000],
    ``rv_patience`` <= 10000, ``rv_batch`` <= 32, ``atom_min_size`` in [4, 10000],
    ``rv_max_points`` in [100, 1e7] or None.
    Also ``r2 > r1``. All problems are reported together in one :class:`ValueError`.
    """

    r1: float = 20.0
    r2: float = 40.0
    atom_min_size: int = 4
    affine_threshold: float = 2.0
    atom_frames: str = "all"
    ransac_hypotheses: int = 24
    noise_adaptive: bool = True
    graph_neighbors: int = 5
    edge_scale: float = 2.0
    cut_prior: float = 0.0
    fine_models: int | None = None
    fine_per_motion: int | None = None
    coarse_merge: str = "auto"
    coding_eps: float = 10.0
    coarse_candidates: int = 10
    coarse_epipolar_weight: float = 2.0
    lam: float = 2.0
    coarse_frames: int = 7
    coarse_samples: int = 8
    motion_weight: float = 0.0
    pooled_trials: int = 8
    pairwise_weight: float = 0.25
    rv_lambda: float = 2.0
    rv_alpha: float = 0.9
    rv_max_iter: int = 150
    rv_trials: int = 10
    rv_sample_size: int = 8
    rv_patience: int = 15
    rv_label_weight: float = 5.0
    rv_missing_trials: int = 2
    rv_missing_gate: float = 0.5
    rv_outlier_veto: bool = True
    rv_batch: int = 2
    rv_refine: bool = True
    rv_reassign: bool = True
    rv_descent: bool = True
    rv_descent_from_trial: bool = True
    rv_select_descent: float = 0.03
    rv_subspace_weight: float = 1.0
    rv_subspace_sample: int = 16
    rv_select: str = "laav"
    rv_select_agreement: float = 2.0
    rv_coarse_candidate: bool = True
    rv_max_points: int | None = 1000

    def __post_init__(self) -> None:
        problems = []
        for name, kind, low, high in _BOUNDS:
            value, why = _check(getattr(self, name), kind, low, high)
            if why:
                problems.append(f"{name} {why}, got {value!r}")
            elif value is not getattr(self, name):  # a numpy scalar, as the Python number
                object.__setattr__(self, name, value)
        if not any(p.startswith(("r1 ", "r2 ")) for p in problems) and not self.r2 > self.r1:
            problems.append(f"r2 must be larger than r1 (got r1={self.r1}, r2={self.r2})")
        if problems:
            raise ValueError("invalid LAAV parameters: " + "; ".join(problems))

    @classmethod
    def paper(cls, **changes) -> LaavParams:
        """Every stage as the LAAV paper writes it (Posner & Hagege), nothing of ours.

        Atoms by RANSAC on one random frame pair each (``atom_frames="pair"``), 2C fine
        models, fine-to-coarse by spectral clustering of the paper's pairwise four-atom
        epipolar votes alone (``coarse_merge="epipolar"``, no pooled voting), and a
        fine-tuning that is Random Voting started from the coarse labels: one informed
        trial, no plain RV run, no model selection, no refinement, no joint
        reassignment and no descent on the joint score, every point voting however many;
        thresholds fixed whatever the noise (``noise_adaptive=False``). ``changes``
        override fields as in :meth:`replace`.
        """
        return cls(atom_frames="pair", fine_per_motion=2, coarse_merge="epipolar", pooled_trials=0,
                   pairwise_weight=1.0, rv_refine=False, rv_reassign=False, rv_descent=False,
                   rv_select_descent=0.0,
                   rv_subspace_weight=0.0, rv_select="none", rv_max_points=None,
                   noise_adaptive=False).replace(**changes)

    @classmethod
    def with_plain_rv(cls, **changes) -> LaavParams:
        """Ours plus plain Random Voting (the default from 2026-12-01 to 2026-12-02): the
        paper's epipolar merge of 2C fine models with pooled voting in Z
        (``coarse_merge="epipolar"``), subspace votes of weight 0.3 in LAAV's informed
        trial, and plain RV's runs beside it, the candidate of least joint score plus
        agreement kept (``rv_select="joint"``). Not LAAV's mechanism (the result is often
        a plain-RV trial), and slower; on Hopkins155 (5 seeds, σ = 0: 0.25 / 0.81 / 0.38 %,
        grouped-CV 0.38 %) the default, with its descent on the joint score, its
        candidates cleaned before the selection, two trials per missing-motion start and
        the unpolished descent, measures 0.19 % on all data and held out (0.19-0.24 %
        held out with its gate for the missing-motion starts); under noise
        (σ = 1 px, seeds 0-1: 0.74 % against 1.23 %) and on ``small_motion``
        this preset is the more accurate (``docs/ALGORITHM.md``, the presets table).
        ``changes`` override fields as in :meth:`replace`."""
        return cls(coarse_merge="epipolar", rv_subspace_weight=0.3,
                   rv_select="joint").replace(**changes)

    @classmethod
    def own_chain(cls, **changes) -> LaavParams:
        """LAAV's own chain (a preset from 2026-11-30, the default since 2026-12-02): the
        joint merge on 4C fine models (``coarse_merge="auto"``), subspace votes of weight 1
        in LAAV's informed trials, LAAV's own candidates and no plain RV
        (``rv_select="laav"``), the one kept descending on the joint score
        (``rv_descent``, since 2026-12-02 evening), its candidates cleaned by a short one
        before they are compared (``rv_select_descent``, since 2026-12-02, late evening), two
        trials from each missing-motion start (``rv_missing_trials``, since 2026-12-03), the
        kept one's unpolished labels descending too (``rv_descent_from_trial``, since
        2026-12-03), the missing-motion starts only where the informed trial's result leaves
        their points unexplained (``rv_missing_gate``, since 2026-12-05), the joint score's
        choices held to the points both labellings explain (``rv_outlier_veto``, since
        2026-12-06). Spelled out, so
        that it stays this chain (and :func:`laav.motions.profile_params`, fitted on it,
        with it) if the default changes.
        ``changes`` override fields as in :meth:`replace`."""
        return cls(coarse_merge="auto", rv_subspace_weight=1.0,
                   rv_select="laav", rv_descent=True, rv_select_descent=0.03,
                   rv_missing_trials=2, rv_descent_from_trial=True,
                   rv_missing_gate=0.5, rv_outlier_veto=True).replace(**changes)

    def scaled(self, s: float) -> LaavParams:
        """The parameters for coordinates ``s`` times larger: lengths (:data:`PIXEL_PARAMS`)
        times ``s``, strengths (:data:`STRENGTH_PARAMS`) divided by ``s^2``.

        ``segment(points * s, C, params.scaled(s))`` gives the labels of
        ``segment(points, C, params)`` (exactly when ``s`` is a power of two; otherwise up to
        rounding, which noise-free data with degenerate samples can amplify).
        """
        if isinstance(s, bool) or not isinstance(s, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(s) and s > 0):
            raise ValueError(f"scale must be a positive finite number, got {s!r}")
        changes = {name: getattr(self, name) * s for name in PIXEL_PARAMS}
        changes.update({name: getattr(self, name) / s ** 2 for name in STRENGTH_PARAMS})
        return self.replace(**changes)

    def for_noise(self, sigma: float) -> LaavParams:
        """The parameters the stages run with on tracks of pixel noise ``sigma`` (px, per
        coordinate; :func:`laav.noise.estimate_noise`), with ``noise_adaptive`` off.

        With ``k`` from :func:`laav.noise.threshold_factor` (for ``atom_frames``; 3.35 for
        ``"all"``) and the ratio ``rho = max(1, k sigma / affine_threshold)``, every scale
        a residual is judged on grows as the residuals do under the noise:
        ``affine_threshold`` and ``edge_scale`` (px) are multiplied by ``rho`` (the
        threshold becomes ``max(affine_threshold, k sigma)``), the strengths ``lam`` and
        ``rv_lambda`` (1/px^2, which also set the px^2 constants of the refinement,
        reassignment and selection, :func:`laav.voting.unit2`) are divided by ``rho^2``.
        The radii ``r1``, ``r2`` and ``coding_eps`` (sizes of the scene, not of the noise)
        and every other field are kept. When ``k sigma <= affine_threshold`` (clean
        tracks) only ``noise_adaptive`` changes, so the labels are those of
        ``noise_adaptive=False`` exactly. Coordinates scaled by ``s`` with :meth:`scaled`
        ``(s)`` scale ``sigma`` by ``s`` and leave ``rho`` as it is.
        """
        from .noise import threshold_factor

        if isinstance(sigma, bool) or not isinstance(sigma, (int, float, np.integer, np.floating)) \
                or not (math.isfinite(sigma) and sigma >= 0):
            raise ValueError(f"sigma must be a finite number >= 0, got {sigma!r}")
        thr = threshold_factor(self.atom_frames) * float(sigma)
        if not thr > self.affine_threshold:
            return self.replace(noise_adaptive=False)
        # at most what keeps the lengths within their bounds (coordinates far off the
        # parameters' pixel scale: their labels are meaningless anyway and warned about)
        rho = min(thr / self.affine_threshold, _BIG / self.affine_threshold,
                  _BIG / self.edge_scale)
        thr = self.affine_threshold * rho
        return self.replace(noise_adaptive=False, affine_threshold=thr,
                            edge_scale=self.edge_scale * rho, lam=self.lam / rho ** 2,
                            rv_lambda=self.rv_lambda / rho ** 2)

    def replace(self, **changes) -> LaavParams:
        """A copy with some fields changed (validated like the original)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ValueError(f"unknown LAAV parameter(s): {sorted(unknown)}")
        return dataclasses.replace(self, **changes)

    def merge_for(self, complete: bool = True) -> str:
        """The coarse merge that runs on complete (or incomplete) tracks: ``coarse_merge``,
        with ``"auto"`` the joint merge on complete tracks and the epipolar merge on
        incomplete ones; the coding and joint merges need complete tracks."""
        if not complete:
            return "epipolar"
        return "joint" if self.coarse_merge == "auto" else self.coarse_merge

    def n_fine(self, n_motions: int, complete: bool = True) -> int:
        """Number of fine models for ``n_motions`` motions: ``fine_models``, else
        ``fine_per_motion`` C, where None means 4, 3 or 2 per motion for the merge that
        runs on complete (or incomplete) tracks (:meth:`merge_for`)."""
        per = self.fine_per_motion
        if per is None:
            per = _FINE_PER_MOTION[self.merge_for(complete)]
        k = per * n_motions if self.fine_models is None else self.fine_models
        if k < n_motions:
            raise ValueError(
                f"fine_models ({k}) must be >= the number of motions ({n_motions})"
            )
        return k

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, text, base: LaavParams | None = None) -> LaavParams:
        """The parameters of a params file: the explorer's export (``{"params": {...},
        "seed": ..., ...}``; its ``sequence``, ``seed`` and ``n_motions`` are not parameters
        and are ignored here) or a bare ``{field: value}`` object, as JSON text (str or
        bytes) or already parsed. A field it does not name keeps ``base``'s
        (default: ``LaavParams()``; e.g. ``LaavParams.paper()`` to start from the paper's).
        Raises ValueError (readable) for a file that is not one, an unknown field or an
        invalid value; ``laav segment --params FILE`` and ``laav-explore --params FILE``
        read it so.

        >>> LaavParams.from_json('{"params": {"r1": 25}, "seed": 3}').r1
        25
        """
        import json

        if not isinstance(text, (str, bytes, bytearray)):
            d = text  # parsed already (anything but an object is refused below)
        else:
            try:
                d = json.loads(text)
            except (ValueError, UnicodeDecodeError) as exc:
                raise ValueError(f"not a JSON file ({exc})") from None
            except RecursionError:  # thousands of nested brackets: no params file
                raise ValueError("not a params file (nested too deeply)") from None
        if not isinstance(d, dict):
            raise ValueError("a params file holds one JSON object")
        fields = d.get("params", d if "params" not in d else None)
        if not isinstance(fields, dict):
            raise ValueError('"params" must be an object of LAAV parameters')
        fields = {k: v for k, v in fields.items() if k not in ("sequence", "seed", "n_motions")}
        unknown = sorted(map(str, set(fields) - {f.name for f in dataclasses.fields(cls)}))
        if unknown:
            raise ValueError(f"unknown LAAV parameter(s): {', '.join(unknown)[:200]}")
        try:
            return (cls() if base is None else base).replace(**fields)
        except TypeError as exc:
            raise ValueError(f"invalid LAAV parameters: {exc}") from None


def as_params(params) -> LaavParams:
    """``params``, or the defaults for None; a clear TypeError for anything else (a dict
    of settings would otherwise fail deep inside a stage)."""
    if params is None:
        return LaavParams()
    if not isinstance(params, LaavParams):
        raise TypeError(f"params must be a LaavParams, e.g. LaavParams(lam=3.0) or "
                        f"LaavParams(**settings), got {type(params).__name__}")
    return params


#: Fine models per motion of each merge when ``fine_per_motion`` is None: the paper's 2C
#: for the epipolar merge; the coding and joint merges measured best with 3C and 4C
#: (benchmarks/TUNING.md, "Stage 4 by coding length", "Stage 4: the joint merge").
_FINE_PER_MOTION = {"epipolar": 2, "coding": 3, "joint": 4}

_BIG = 1e6  # px or 1/px^2: far beyond any image, small enough that squares stay finite
#: Upper bound of the strengths in 1/px^2 (lam, rv_lambda): 1e6 / s^2 for coordinates
#: scaled by s = 1e-3 with the parameters scaled along (issue 16 item 8).
_BIG_STRENGTH = 1e12

#: (field, kind, low, high) for every field, checked by LaavParams.__post_init__. Kinds:
#: "int" / "float" in [low, high]; "float>" in (low, high]; "int|None" also allows None;
#: "bool"; "choice" one of ``low``. Upper bounds on counts keep one run within seconds and
#: memory within a laptop (each multiplies a stage's work or its arrays).
_BOUNDS = (
    ("r1", "float>", 0, _BIG),
    ("r2", "float>", 0, _BIG),
    ("atom_min_size", "int", 4, 10_000),
    ("affine_threshold", "float>", 0, _BIG),
    ("atom_frames", "choice", ("all", "pair"), None),
    ("ransac_hypotheses", "int", 1, 1000),
    ("noise_adaptive", "bool", None, None),
    ("graph_neighbors", "int", 1, 100),
    ("edge_scale", "float>", 0, _BIG),
    ("cut_prior", "float", -_BIG, _BIG),
    ("fine_models", "int|None", 1, 1000),
    ("fine_per_motion", "int|None", 1, 100),
    ("coarse_merge", "choice", ("auto", "coding", "epipolar", "joint"), None),
    ("coding_eps", "float>", 0, _BIG),
    ("coarse_candidates", "int", 1, 1000),
    ("coarse_epipolar_weight", "float", 0, _BIG),
    ("lam", "float>", 0, _BIG_STRENGTH),
    ("coarse_frames", "int", 1, 100),
    ("coarse_samples", "int", 1, 1000),
    ("motion_weight", "float", 0, _BIG),
    ("pooled_trials", "int", 0, 100),
    ("pairwise_weight", "float", 0, 1),
    ("rv_lambda", "float>", 0, _BIG_STRENGTH),
    ("rv_alpha", "float>", 0, 1),
    ("rv_max_iter", "int", 1, 10_000),
    ("rv_trials", "int", 1, 100),
    ("rv_sample_size", "int", 8, 1000),
    ("rv_patience", "int", 1, 10_000),
    ("rv_label_weight", "float", 0, _BIG),
    ("rv_missing_trials", "int", 1, 100),
    ("rv_missing_gate", "float", 0, 1),
    ("rv_outlier_veto", "bool", None, None),
    ("rv_batch", "int", 1, 32),
    ("rv_refine", "bool", None, None),
    ("rv_reassign", "bool", None, None),
    ("rv_descent", "bool", None, None),
    ("rv_descent_from_trial", "bool", None, None),
    ("rv_select_descent", "float", 0, 1),
    ("rv_subspace_weight", "float", 0, _BIG),
    ("rv_subspace_sample", "int", 8, 1000),
    ("rv_select", "choice", ("none", "joint", "subspace", "laav"), None),
    ("rv_select_agreement", "float", 0, _BIG),
    ("rv_coarse_candidate", "bool", None, None),
    ("rv_max_points", "int|None", 100, 10_000_000),
)


def _check(value, kind: str, low, high):
    """``(value, problem)``: numpy scalars become Python numbers; problem is "" when valid."""
    if kind == "bool":
        ok = isinstance(value, (bool, np.bool_))
        return (bool(value), "") if ok else (value, "must be True or False")
    if kind == "choice":
        return value, "" if isinstance(value, str) and value in low else f"must be one of {low}"
    if kind == "int|None":
        if value is None:
            return None, ""
        kind = "int"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        return value, "must be " + ("an integer" if kind == "int" else "a number")
    if kind == "int" and not isinstance(value, (int, np.integer)):
        return value, "must be an integer"
    if isinstance(value, (float, np.floating)):
        value = float(value)
        if not math.isfinite(value):
            return value, "must be a finite number"
    value = int(value) if isinstance(value, np.integer) else value
    above = value > low if kind == "float>" else value >= low
    if not (above and value <= high):
        return value, f"must be in {'(' if kind == 'float>' else '['}{low:g}, {high:g}]"
    return value, ""


#: The named presets, as ``laav segment``, ``laav bench`` and ``laav-explore`` take them
#: (``--preset NAME``): NAME -> a constructor of :class:`LaavParams`.
PRESETS = {"default": LaavParams, "paper": LaavParams.paper,
           "with-plain-rv": LaavParams.with_plain_rv, "own-chain": LaavParams.own_chain}

#: Which parameters each stage reads; a change reruns that stage and all after it.
STAGE_PARAMS: dict[str, frozenset] = {
    "atoms": frozenset({"r1", "r2", "atom_min_size", "affine_threshold", "ransac_hypotheses",
                        "atom_frames", "noise_adaptive"}),
    "graph": frozenset({"graph_neighbors", "edge_scale", "cut_prior"}),
    "multicut": frozenset({"fine_models", "fine_per_motion"}),
    "coarse": frozenset({"coarse_merge", "coding_eps", "coarse_candidates",
                         "coarse_epipolar_weight", "lam", "coarse_frames", "coarse_samples",
                         "motion_weight", "pooled_trials",
                         "pairwise_weight", "rv_max_points"}),
    # every Random Voting setting is named rv_*
    "voting": frozenset(f.name for f in dataclasses.fields(LaavParams) if f.name.startswith("rv_")),
}
STAGES = ("atoms", "graph", "multicut", "coarse", "voting")


def stages_affected(changed: set) -> str | None:
    """The earliest stage whose parameters are in ``changed`` (None if none)."""
    for stage in STAGES:
        if STAGE_PARAMS[stage] & changed:
            return stage
    return None
