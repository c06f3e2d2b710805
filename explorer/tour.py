"""The guided tour's steps and texts, in one place for review (no GUI imports).

The tour (:mod:`explorer.cards.tour`) shows one stage at a time (the result, stage 5, in two
steps: its labels in the frame view, then its numbers): its card, highlighted,
under a panel with the step's title and two sentences in large type, for a class. Each
text says what the code does with the default parameters (``LaavParams()``); where the
paper does otherwise it names the ``paper`` preset (``LaavParams.paper()``).

``cards`` names the cards a step shows (``frame``, ``view3d``, ``graph``, ``coarse``,
``rv``, ``numbers``; the first is the one highlighted), ``color`` the frame view's
colour-by (a :data:`explorer.views.COLOR_MODES` key; ``color_no_truth`` instead for a
sequence without ground truth; None leaves it as it is); ``error_rings`` shows (True) or hides
(False) the frame view's misclassified rings at that step (None: as before the tour): hidden on
the atoms, shown on the result; ``card_title`` replaces the highlighted card's title while the
step is shown (the frame view is card 1, the atoms', and also the result's view). A text follows
the result shown (:meth:`TourStep.text_for`): ``{fine}`` is its number of fine models (``3C``,
``2C``) and ``{paper_fine}`` says whether that is the paper's 2C; ``text_epipolar`` /
``text_joint`` replace the text for the merge that decided, ``text_pair`` for atoms checked on
one frame pair (the paper's). A step with
``facts="rv"`` ends with what the result shown did (:func:`fine_tuning_facts`: how LAAV's trial
started and ended, plain RV's trials), so the paper's claim is read beside this run.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

import laav

from .views import fine_count, other_trial_counts, rv_error_sources

__all__ = ["TourStep", "TOUR", "fine_tuning_facts"]


@dataclass(frozen=True)
class TourStep:
    title: str
    text: str
    cards: tuple[str, ...]
    color: str | None = None
    color_no_truth: str | None = None
    text_epipolar: str | None = None
    text_joint: str | None = None
    text_pair: str | None = None
    facts: str | None = None
    error_rings: bool | None = None
    card_title: str | None = None

    def text_for(self, params, n_motions: int, complete: bool = True) -> str:
        """The text for a result of ``params`` (a :class:`laav.LaavParams`) with C =
        ``n_motions`` on complete (or incomplete) tracks: the merge it used, its number of
        fine models."""
        merge = params.merge_for(complete)
        text = {"epipolar": self.text_epipolar, "joint": self.text_joint}.get(merge)
        if params.atom_frames == "pair" and self.text_pair:
            text = self.text_pair
        text = text or self.text
        fine = fine_count(params, n_motions, complete)
        return (text.replace("{fine}", fine)
                .replace("{paper_fine}", ", as the paper does" if fine == "2C" else " (the paper: 2C)"))


TOUR: tuple[TourStep, ...] = (
    TourStep(
        "1 · Atoms: small groups that move as one",
        "Each atom grows around a random seed feature: RANSAC keeps the neighbours within R2 that one "
        "affine motion carries through every frame (the paper checks one random frame pair). Features "
        "within R1 belong to that atom alone, the ring out to R2 may be shared, and features no atom "
        "takes (crossed) wait for stage 4.",
        ("frame",), color="atoms", color_no_truth="atoms", error_rings=False,
        # the text when atoms are checked on one frame pair (atom_frames = "pair", the paper's)
        text_pair=(
            "Each atom grows around a random seed feature: RANSAC keeps the neighbours within R2 that "
            "one affine motion carries between one random frame pair, as the paper does. Features "
            "within R1 belong to that atom alone, the ring out to R2 may be shared, and features no "
            "atom takes (crossed) wait for stage 4.")),
    TourStep(
        "2 · Multicut: cutting the atom graph into fine models",
        "Atoms become the nodes of a graph, an edge blue when one atom's affine motion carries the "
        "other's features forward and back well (its cost favours joining them), red when it does "
        "not. A minimum cost multicut (greedy contraction, replayed by the step slider under the "
        "graph) cuts edges (dashed), and its segments are merged or split to {fine} fine models, "
        "on purpose more than the C motions{paper_fine}.",
        ("graph",), color="fine", color_no_truth="fine"),
    TourStep(
        "3 · Fine-to-coarse: merging fine models into C motions",
        "The fine models are grouped into C motions by coding length: the grouping whose "
        "trajectories take the fewest nats (a unit of information, like bits) to describe wins. The "
        "paper instead lets pairs of fine models vote with epipolar geometry and splits the votes by "
        "spectral clustering (the paper preset).",
        ("coarse",), color="coarse", color_no_truth="coarse",
        # the text when the epipolar merge decided (coarse_merge = "epipolar", the paper's)
        text_epipolar=(
            "Pairs of fine models vote with epipolar geometry: one fundamental matrix fitted to both "
            "explains both when they move as one rigid body. Spectral clustering splits these votes "
            "into C motions, as the paper does."),
        # the text when the joint merge decided (coarse_merge = "auto", the default, or "joint")
        text_joint=(
            "The fine models are grouped into C motions by the joint merge: of the groupings whose "
            "trajectories take the fewest nats (a unit of information, like bits) to describe, the one "
            "whose fundamental matrices best explain its points wins. The map shows how many nats "
            "joining (blue) or splitting (orange) "
            "each pair of fine models won.")),
    TourStep(
        "4 · Fine-tuning: Random Voting labels every point",
        "Random Voting starts from the coarse labels (labelled points start with extra votes): "
        "each iteration, every motion fits a fundamental matrix on "
        "a random frame pair and every point votes for the motions that fit it. The paper's claim: "
        "started near the answer, it settles sooner than plain Random Voting from random starts.",
        ("rv",), color="final", color_no_truth="final", facts="rv"),
    # the result's two cards are two steps: each is 520-540 px high, and the main area beside the
    # tour's panel has about 600 of a projector's 768-800 (one card at a time fits, not both)
    TourStep(
        "5a · Result: one motion per point",
        "Every point now belongs to one of the C motions, one colour each, in every frame (the frame "
        "slider in the sidebar plays them). With ground truth the frame view rings the misassigned ones "
        "in black, and the next step gives every stage's error.",
        ("frame",), color="final", color_no_truth="final", error_rings=True,
        card_title="5a · Result: every point's motion in one frame"),
    TourStep(
        "5b · Numbers: every stage's error",
        "With ground truth the Numbers card gives every stage's error (the share of points misassigned "
        "under the best matching of motions), plain Random Voting's beside them; without, each "
        "stage's result and time. Atoms, the merge "
        "and the voting are random: after the tour, the Seed sweep card's button runs seeds 0-9 to "
        "show whether a result is typical or a bad draw.",
        ("numbers",), color="final", color_no_truth="final", error_rings=True),
)


def _in_words(candidate: str) -> str:
    """A plain RV candidate's name (:func:`laav.selection`'s ``plain [k ]trial[ i]`` /
    ``plain [k ]consensus``) in words; any other name as it is."""
    m = re.fullmatch(r"plain(?: (\d+))? (trial|consensus)(?: (\d+))?", candidate)
    if m is None:
        return candidate
    run, what, i = m.groups()
    words = ("plain RV's consensus of its trials" if what == "consensus"
             else f"plain RV's trial {i}" if i else "plain RV's settled trial")
    return words + (f" (its run {run})" if run else "")


def fine_tuning_facts(seq, voting, plain, searching: bool = False) -> str:
    """What this result's fine-tuning did, in a sentence or two for tour step 4: how far
    from the answer LAAV's informed trial started (against the ground truth, else against
    its own last labels) and whether it settled or ran to the iteration cap; plain RV's
    trials the same way (``plain`` None: still computing); the departures of ours the
    trial used (subspace votes, missing-motion trials), named. ``voting``: the result's
    :class:`laav.Voting` (None: nothing yet). ``searching``: ``voting`` is the preview of
    LAAV's own chain, its trials for a missed motion still computing (said so, and not
    that no search was needed)."""
    if voting is None or voting.informed_changed is None:
        return ""
    n = len(voting.informed_changed)
    err = rv_error_sources(seq, voting)["error"]
    truth = seq.labels is not None
    what = "wrong" if truth else "off its last labels"
    start = f"started {err[0]:.0f} % {what} and " if err.size else ""
    ended = (f"settled after {n} iterations" if voting.informed_converged
             else f"was still changing at the {n}-iteration cap")
    if truth and err.size:  # settling is not being right: where it ended
        ended = (f"settled at {_pct(err[-1])} after {n} iterations" if voting.informed_converged
                 else f"{ended} ({_pct(err[-1])} wrong)")
    text = f"This run: LAAV's trial {start}{ended}"
    if plain is None:
        text += "; plain RV: computing."
    else:
        per = [int(t) for t in plain.trial_iterations] or [int(plain.n_iterations)]
        if plain.converged:
            text += (f"; plain RV ran {len(per)} trials until one settled" if len(per) > 1
                     else f"; plain RV's trial settled after {per[0]} iterations")
        else:
            text += (f"; plain RV's {len(per)} trials all hit the {max(per)}-iteration cap"
                     if len(per) > 1 else f"; plain RV hit the {per[0]}-iteration cap")
        text += f" ({int(plain.n_iterations)} in all)"
        text += (f", {_pct(100 * laav.misclassification_rate(seq.labels, plain.labels))} wrong."
                 if truth else ".")
    returned = voting.selected
    if returned != "informed" and not returned.startswith("missing motion"):
        whose = "LAAV's coarse labels" if returned == "coarse" else "those of " + _in_words(returned)
        text += (f" The labels returned are {whose}, not this trial's: our selection (not in the "
                 "paper) scored them better.")
    ours = []
    if (voting.informed_subspace_weight or 0) > 0:
        ours.append("subspace votes")
    missing, plain_trials = other_trial_counts(voting)
    if missing:
        ours.append(f"{missing} trials for a missed motion"
                    + ("; one of them, not this trial, gave the labels returned (it scored better)"
                       if returned.startswith("missing motion") else ""))
    if plain_trials:
        ours.append(f"{plain_trials} plain RV trials it was compared with")
    if ours:
        text += " Ours, not the paper's: " + ", ".join(ours)
        # (what did not run is not in that list; the RV card says which starts and why)
        text += ("; no search for a missed motion needed."
                 if voting.skipped_starts and not missing and not searching else ".")
    elif voting.skipped_starts and not searching:
        text += " No search for a missed motion needed (ours)."
    if searching:
        text += (" The trials for a missed motion (ours) are still computing: their labels may "
                 "replace these.")
    elif truth:  # the labels returned (the status line's error), when they are not the trial's
        final = 100 * laav.misclassification_rate(seq.labels, voting.labels)
        own = returned == "informed" and voting.voted is None  # the trial's error on all points
        if not own:
            text += f" The labels returned: {_pct(final)} wrong."
        elif _pct(final) != _pct(err[-1] if err.size else np.nan):
            text += f" Returned after our last steps: {_pct(final)} wrong."
        if plain is not None:  # never a win the run contradicts: say when plain RV did better
            theirs = 100 * laav.misclassification_rate(seq.labels, plain.labels)
            if final > theirs + 0.5:  # (both errors are said above: plain RV's, the labels returned)
                text += " Plain RV did better here"
                # why, when the trial returned stayed near a start that was far off
                stayed = own and err.size and err[0] > 5.0 and err[-1] > 0.5 * err[0]
                text += (": a start near a wrong answer settles there (step 3's coarse labels)."
                         if stayed else ".")
    return text


def _pct(v: float) -> str:
    """An error in % as the status line writes it (one decimal)."""
    return f"{v:.1f} %"
