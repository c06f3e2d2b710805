"""Parameters of LAAV and Random Voting, validated on construction."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

__all__ = ["LaavParams", "STAGE_PARAMS", "stages_affected"]


@dataclass(frozen=True)
class LaavParams:
    """Every tunable of the LAAV pipeline and of Random Voting.

    Distances are in pixels of the input coordinates. Defaults were chosen on Hopkins155
    (see ``benchmarks/TUNING.md`` for the sweeps that chose them).

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
    ransac_hypotheses : int
        Minimal samples (seed + 2 neighbours) tried per atom, evaluated as one batch.
    graph_neighbors : int
        Each atom is joined to this many nearest atoms besides those it overlaps.
    edge_scale : float
        Forward-backward error (px) at which an edge is neutral (cost 0 before the prior).
    cut_prior : float
        Added to every edge's "cut" side: ``cost = 2 log(edge_scale / error) - cut_prior``.
    fine_models : int or None
        Number of fine motion models the multicut is brought to; None means ``2 C``.
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
        A trial has converged when labels stay (nearly) unchanged this many iterations.
    rv_label_weight : float
        Initial votes given to atom-labelled features when LAAV initialises Random Voting.
    rv_batch : int
        Voting trials run side by side in one batched numpy call (LAAV's informed trial
        with plain RV's random starts). Speed only: each trial draws from its own random
        stream and keeps its own convergence test, and the trial kept is the same as if
        they ran one after another, so a seed's labels do not depend on it.
    rv_refine : bool
        After voting, reassign each point to the motion whose fundamental matrices (fitted
        on the motion's points over many frame pairs) explain it best.
    rv_reassign : bool
        After the refinement, move every point to the motion whose robust rank-4
        trajectory subspace and fundamental matrices explain it best together
        (:func:`laav.refine.reassign_labels`). With model selection, every candidate
        labelling is polished so before it is scored.
    rv_select : {"none", "subspace"}
        ``"subspace"`` (ours): model selection between candidate labellings by their
        trajectory-subspace cost (:func:`laav.refine.subspace_cost`) and agreement;
        plain RV with no converged trial keeps the best of the trials and their
        co-association labelling, and LAAV's fine-tuning also runs plain RV (two more
        runs when the two results disagree on more than 5 % of the points) and keeps the
        best of all. ``"none"`` (the LAAV paper): LAAV's fine-tuning is its informed
        trial alone, converged or not; plain RV with no converged trial ends with the
        co-association labelling.
    rv_select_agreement : float
        Weight (>= 0) of a candidate's mean disagreement (misclassification rate) with
        the other candidates in the selection score, when there are more than two: the
        labelling most others agree with is preferred among costs that are close.
        2.0 measured best of 0.5-6 once candidates are reassigned (benchmarks/TUNING.md).
    """

    r1: float = 20.0
    r2: float = 40.0
    atom_min_size: int = 4
    affine_threshold: float = 2.0
    ransac_hypotheses: int = 24
    graph_neighbors: int = 5
    edge_scale: float = 2.0
    cut_prior: float = 0.0
    fine_models: int | None = None
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
    rv_batch: int = 2
    rv_refine: bool = True
    rv_reassign: bool = True
    rv_select: str = "subspace"
    rv_select_agreement: float = 2.0

    def __post_init__(self) -> None:
        problems = []

        def need(ok: bool, msg: str) -> None:
            if not ok:
                problems.append(msg)

        for name in ("r1", "r2", "affine_threshold", "edge_scale", "lam", "rv_lambda",
                     "rv_alpha", "rv_label_weight", "motion_weight", "cut_prior",
                     "rv_select_agreement"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or isinstance(v, bool) or v != v:
                problems.append(f"{name} must be a number, got {v!r}")
        for name in ("atom_min_size", "ransac_hypotheses", "graph_neighbors", "coarse_frames",
                     "coarse_samples", "rv_max_iter", "rv_trials", "rv_sample_size",
                     "rv_patience", "rv_batch"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool):
                problems.append(f"{name} must be an integer, got {v!r}")
        for name in ("rv_refine", "rv_reassign"):
            v = getattr(self, name)
            if not isinstance(v, bool):
                problems.append(f"{name} must be True or False, got {v!r}")
        if problems:
            raise ValueError("invalid LAAV parameters: " + "; ".join(problems))
        need(self.r1 > 0, f"r1 must be > 0 px, got {self.r1}")
        need(self.r2 > self.r1, f"r2 must be larger than r1 (got r1={self.r1}, r2={self.r2})")
        need(self.atom_min_size >= 4, f"atom_min_size must be >= 4, got {self.atom_min_size}")
        need(self.affine_threshold > 0, "affine_threshold must be > 0 px")
        need(self.ransac_hypotheses >= 1, "ransac_hypotheses must be >= 1")
        need(self.graph_neighbors >= 1, "graph_neighbors must be >= 1")
        need(self.edge_scale > 0, "edge_scale must be > 0 px")
        need(self.fine_models is None or (isinstance(self.fine_models, int)
                                          and self.fine_models >= 1),
             f"fine_models must be None or a positive integer, got {self.fine_models!r}")
        need(self.lam > 0, f"lam (lambda) must be > 0, got {self.lam}")
        need(self.coarse_frames >= 1, "coarse_frames must be >= 1")
        need(self.coarse_samples >= 1, "coarse_samples must be >= 1")
        need(self.motion_weight >= 0, "motion_weight must be >= 0")
        need(isinstance(self.pooled_trials, int) and self.pooled_trials >= 0, "pooled_trials must be >= 0")
        need(0 <= self.pairwise_weight <= 1, "pairwise_weight must be in [0, 1]")
        need(self.rv_lambda > 0, f"rv_lambda must be > 0, got {self.rv_lambda}")
        need(0 < self.rv_alpha <= 1, f"rv_alpha must satisfy 0 < alpha <= 1, got {self.rv_alpha}")
        need(self.rv_max_iter >= 1, "rv_max_iter must be >= 1")
        need(self.rv_trials >= 1, "rv_trials must be >= 1")
        need(self.rv_sample_size >= 8, "rv_sample_size must be >= 8 (8-point algorithm)")
        need(self.rv_patience >= 1, "rv_patience must be >= 1")
        need(self.rv_label_weight >= 0, "rv_label_weight must be >= 0")
        need(self.rv_batch >= 1, f"rv_batch must be >= 1, got {self.rv_batch}")
        need(0 <= self.rv_select_agreement < float("inf"),
             f"rv_select_agreement must be finite and >= 0, got {self.rv_select_agreement}")
        need(self.rv_select in ("none", "subspace"),
             f"rv_select must be 'none' or 'subspace', got {self.rv_select!r}")
        if problems:
            raise ValueError("invalid LAAV parameters: " + "; ".join(problems))

    @classmethod
    def paper(cls, **changes) -> LaavParams:
        """Every stage as the LAAV paper writes it (Posner & Hagege), nothing of ours.

        Fine-to-coarse by the paper's pairwise four-atom epipolar votes alone (no pooled
        voting), and a fine-tuning that is Random Voting started from the coarse labels:
        one informed trial, no plain RV run, no model selection, no refinement and no
        joint reassignment. ``changes`` override fields as in :meth:`replace`.
        """
        return cls(pooled_trials=0, pairwise_weight=1.0, rv_refine=False, rv_reassign=False,
                   rv_select="none").replace(**changes)

    def replace(self, **changes) -> LaavParams:
        """A copy with some fields changed (validated like the original)."""
        unknown = set(changes) - {f.name for f in dataclasses.fields(self)}
        if unknown:
            raise ValueError(f"unknown LAAV parameter(s): {sorted(unknown)}")
        return dataclasses.replace(self, **changes)

    def n_fine(self, n_motions: int) -> int:
        """Number of fine models for ``n_motions`` motions (``fine_models`` or 2 C)."""
        k = 2 * n_motions if self.fine_models is None else self.fine_models
        if k < n_motions:
            raise ValueError(
                f"fine_models ({k}) must be >= the number of motions ({n_motions})"
            )
        return k

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


#: Which parameters each stage reads; a change reruns that stage and all after it.
STAGE_PARAMS: dict[str, frozenset] = {
    "atoms": frozenset({"r1", "r2", "atom_min_size", "affine_threshold", "ransac_hypotheses"}),
    "graph": frozenset({"graph_neighbors", "edge_scale", "cut_prior"}),
    "multicut": frozenset({"fine_models"}),
    "coarse": frozenset({"lam", "coarse_frames", "coarse_samples", "motion_weight", "pooled_trials",
                         "pairwise_weight"}),
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
