"""The guided tour's steps and texts, in one place for review (no GUI imports).

The tour (:mod:`explorer.cards.tour`) shows one stage at a time: its card, highlighted,
under a panel with the step's title and two sentences in large type, for a class. Each
text says what the code does with the default parameters (``LaavParams()``); where the
paper does otherwise it names the ``paper`` preset (``LaavParams.paper()``).

``cards`` names the cards a step shows (``frame``, ``view3d``, ``graph``, ``coarse``,
``rv``, ``numbers``; the first is the one highlighted), ``color`` the frame view's
colour-by (a :data:`explorer.views.COLOR_MODES` key; ``color_no_truth`` instead for a
sequence without ground truth; None leaves it as it is). A text follows the result shown
(:meth:`TourStep.text_for`): ``{fine}`` is its number of fine models (``3C``, ``2C``), and
``text_epipolar`` replaces the text when the paper's epipolar merge decided.
"""

from __future__ import annotations

from dataclasses import dataclass

from .views import fine_count

__all__ = ["TourStep", "TOUR"]


@dataclass(frozen=True)
class TourStep:
    title: str
    text: str
    cards: tuple[str, ...]
    color: str | None = None
    color_no_truth: str | None = None
    text_epipolar: str | None = None
    text_joint: str | None = None

    def text_for(self, params, n_motions: int, complete: bool = True) -> str:
        """The text for a result of ``params`` (a :class:`laav.LaavParams`) with C =
        ``n_motions`` on complete (or incomplete) tracks: the merge it used, its number of
        fine models."""
        merge = params.merge_for(complete)
        text = {"epipolar": self.text_epipolar, "joint": self.text_joint}.get(merge)
        text = text or self.text
        return text.replace("{fine}", fine_count(params, n_motions, complete))


TOUR: tuple[TourStep, ...] = (
    TourStep(
        "1 · Atoms: small groups that move as one",
        "Each atom grows around a random seed feature: RANSAC keeps the neighbours within the outer "
        "radius R2 that one affine motion carries through every frame. Features within R1 of the seed "
        "belong to that atom alone, the ring out to R2 may be shared with other atoms, and features no "
        "atom takes (grey crosses) wait for stage 4.",
        ("frame",), color="atoms", color_no_truth="atoms"),
    TourStep(
        "2 · Multicut: cutting the atom graph into fine models",
        "Atoms become nodes of a graph whose edges join overlapping and nearby atoms, blue when one "
        "atom's affine motion carries the other's features forward and back well (join), red when it "
        "does not (cut). A minimum cost multicut (greedy contraction, replayed by the slider, then "
        "Kernighan-Lin) cuts the graph, and its segments are merged or split to {fine} fine models, on "
        "purpose more than the C motions.",
        ("graph",)),
    TourStep(
        "3 · Fine-to-coarse: merging fine models into C motions",
        "The fine models are grouped into C motions by coding length: the grouping whose trajectories "
        "take the fewest bits to describe (up to a distortion ε) wins, since two motions coded as one "
        "need an extra coordinate for every point. The paper instead lets pairs of fine models vote "
        "with epipolar geometry and splits their affinity Z by spectral clustering: that is the paper "
        "preset (coarse_merge = epipolar).",
        ("coarse",),
        # the text when the epipolar merge decided (coarse_merge = "epipolar", the paper's)
        text_epipolar=(
            "Pairs of fine models vote with epipolar geometry: one fundamental matrix fitted to atoms of "
            "both explains both when they move as one rigid body, and the votes form the affinity Z. "
            "Spectral clustering splits Z into C motions, as the paper does; the option coarse_merge = "
            "coding instead picks the grouping whose trajectories take the fewest bits to describe."),
        # the text when the joint merge decided (coarse_merge = "auto", the default, or "joint")
        text_joint=(
            "The fine models are grouped into C motions by the joint merge: of the groupings whose "
            "trajectories take the fewest bits to describe (up to a distortion ε), with at least 8 "
            "points per motion, the one whose motions' fundamental matrices also explain their points "
            "best wins. The map colours each pair of fine models by how many nats joining (blue) or "
            "splitting (orange) them won: coding length separates motions that share epipolar geometry "
            "(a truck and the background it drives across), the epipolar cost groupings that mix "
            "independent motions.")),
    TourStep(
        "4 · Fine-tuning: Random Voting labels every point",
        "Random Voting starts from the coarse labels: in each iteration every motion fits a "
        "fundamental matrix to a few of its points on a random pair of frames, and every point votes "
        "for the motions whose epipolar geometry fits it, older votes fading by α; the first chart "
        "shows each run's error per iteration: started from the coarse labels it begins near the "
        "answer, from a random start far from it (the paper's claim: faster convergence). This labels the "
        "features no atom took and can undo a wrong merge; by default the informed run's votes also "
        "weigh each point's distance to the motion's trajectory subspace, runs from starts that give "
        "a motion the atoms missed its own label go beside it, and the labelling of least coding "
        "length + epipolar cost is kept (the paper: epipolar votes, the informed run alone); on "
        "complete tracks plain Random Voting runs here only for the comparison.",
        ("rv",)),
    TourStep(
        "5 · Result: one motion per point, and its error",
        "Every point now belongs to one of the C motions; with ground truth, the error is the share "
        "of points misassigned under the best matching of motions to true labels, shown here for "
        "every stage. Atoms, the merge and the voting are random, so the seed sweep below the cards "
        "runs seeds 0-9 to show whether a result is typical or a bad draw.",
        ("numbers", "frame"), color="errors", color_no_truth="final"),
)
