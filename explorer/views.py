"""Pure functions from a :class:`laav.LaavResult` (and a sequence) to plot data.

Nothing here imports panel, bokeh or viser, and nothing here runs any part of the
algorithm: every number drawn comes from the stage dataclasses (or, for scores, from
:func:`laav.misclassification_rate` / :func:`laav.confusion_matrix`). Each ``*_sources``
function returns plain dicts of numpy arrays, ready for ``ColumnDataSource.data = ...``.
"""

from __future__ import annotations

import itertools
import math
import re

import numpy as np

import laav
from laav.geometry import epipolar_lines
from laav.metrics import DISAGREEMENT_WARN, matched_counts
from laav.noise import threshold_factor

__all__ = [
    "COLOR_MODES", "TRUTH_MODES", "PLAIN_MODES", "COLOR_LABELS", "ERROR_STAGE", "stage_errors",
    "MOTION_COLORS", "MOTION_MARKERS", "ATOM_COLORS", "UNLABELLED", "ERROR_MARK", "DIFFERS_MARK", "UNSEEN",
    "UNSEEN_MARKER", "UNSEEN_LABEL", "visible_at", "incomplete_note", "result_notes", "counted",
    "NO_ATOM", "NO_ATOM_DARK", "NO_ATOM_SIZE", "cross_colors", "CHANGED_MARK", "DISAGREEMENT_WARN",
    "LEGEND_ROW_PX", "LEGEND_OTHER_ROWS", "fine_legend_rows", "n_fine_models", "shared_fine_rows",
    "disagreement_line", "disagreement_warning",
    "motion_color", "motion_marker", "shade", "fine_motions", "fine_colors",
    "align_labels", "shown_labels", "point_style", "plain_differs", "labelling_distance", "raw_style",
    "points_source", "frame_sources", "graph_sources", "TRAIL", "frame_specs", "frame_templates",
    "points_template", "legend_points", "graph_specs",
    "graph_templates", "atom_sizes", "label_clashes", "id_layout", "pair_id_sides", "id_boxes", "ID_FONT_PX",
    "PAIR_ID_FONT_PX", "ID_CLEAR",
    "instantiate", "point_track", "atom_track", "fill_text", "lam_label",
    "replay_labels",
    "replay_caption", "fine_count", "fine_count_note", "z_sources", "joint_margins", "shows_margins",
    "signed_log", "margin_top", "margin_ticks", "margin_text", "cell_font_px", "MARGIN_PALETTE",
    "own_chain_preview", "preview_note",
    "UNDECIDED",
    "merge_table", "epipolar_sources",
    "votes_fitted",
    "rv_sources", "rv_error_sources", "trace_errors",
    "rv_summary", "stage_numbers", "numbers_markdown", "labels_table", "hex_to_rgb",
    "space_time", "cost_limit", "md_text", "CLOSE_CALL_NATS", "close_calls",
]

#: Colour-by choices (label shown in the widget -> key).
COLOR_MODES = {
    "ground truth": "gt",
    "atoms": "atoms",
    "fine models": "fine",
    "coarse (atoms merged)": "coarse",
    "final (after Random Voting)": "final",
    "plain RV (random start)": "plain",
    "errors: fine models": "errors_fine",
    "errors: coarse": "errors_coarse",
    "errors: final": "errors",
    "errors: plain RV": "errors_plain",
    "differences: final vs plain RV": "vs_plain",
}
#: The colour modes that draw plain RV's labels (the final labels until it is computed).
PLAIN_MODES = ("plain", "errors_plain", "vs_plain")
#: The colour modes that need ground truth (not offered for a sequence without it).
TRUTH_MODES = frozenset(mode for mode in COLOR_MODES.values() if mode == "gt" or mode.startswith("errors"))
#: A colour mode's label in the page (COLOR_MODES inverted).
COLOR_LABELS = {mode: label for label, mode in COLOR_MODES.items()}
#: The stage whose errors a colour mode marks (black rings / black points).
ERROR_STAGE = {"gt": "final", "atoms": "final", "fine": "fine", "coarse": "coarse", "final": "final",
               "plain": "plain", "errors_fine": "fine", "errors_coarse": "coarse", "errors": "final",
               "errors_plain": "plain", "vs_plain": "final"}

#: One colour per motion, everywhere (frame view, 3-D view, fine models as its shades): Okabe-Ito
#: colours, the subset and order whose pairs stay apart under simulated deuteranopia (CIE Lab
#: ΔE >= 24.9 after Machado et al. 2009, severity 1; tests/test_explorer.py checks it).
#: Motions beyond five repeat a colour with another marker shape.
MOTION_COLORS = ("#0072B2", "#D55E00", "#009E73", "#F0E442", "#56B4E9")
#: One marker shape per motion (bokeh marker names), so motions differ by more than colour.
MOTION_MARKERS = ("circle", "square", "triangle", "diamond", "inverted_triangle", "hex")
#: Atoms (the "atoms" colour mode only: an atom is no motion) cycle through these muted
#: tones, never a motion colour and never a grey (grey is the points in no atom).
ATOM_COLORS = ("#332288", "#882255", "#B07AA1", "#9C755F", "#76B7B2", "#999933", "#D4A6C8",
               "#DDCC77", "#A0CBE8", "#CC6677")
#: Shades of a motion colour for the fine models that joined it: >0 mixes in white, <0 black.
FINE_SHADES = (0.0, 0.5, -0.45, 0.72, -0.65, 0.28, -0.25, 0.85)
UNLABELLED = "#C7C7C7"
#: The atom graph's edge costs, red (< 0: cut) to blue (> 0: join): ColorBrewer's RdBu
#: without its three palest shades, which drew a small cost nearly white on white.
EDGE_PALETTE = ("#67001f", "#b2182b", "#d6604d", "#f4a582", "#92c5de", "#4393c3", "#2166ac", "#053061")
#: Points the final stage leaves unlabelled (-1: seen too briefly to decide, missing data
#: only; ``LaavResult.unlabelled_code``): a neutral grey, their own marker and legend entry.
UNSEEN = "#9A9A9A"
UNSEEN_MARKER = "circle_x"
UNSEEN_LABEL = "unlabelled: seen too briefly"
#: Misclassified points are ringed in black (not red: a red ring vanishes on green points
#: for deuteranopes; black stays apart from every motion colour, ΔE >= 56 simulated).
ERROR_MARK = "#000000"
CORRECT = "#BBBBBB"
#: Features in no atom: a cross inside the point it marks (:data:`NO_ATOM_SIZE` against the
#: points' 7 px), white on a dark fill and dark grey (:data:`NO_ATOM_DARK`) on a light one
#: (:func:`cross_colors`: the grey of the atoms, fine and coarse colourings, the pale error
#: colourings, the yellow and sky-blue motions), so that it shows on every fill and the
#: point's colour shows round it. A dark grey cross alone vanished inside navy points; one
#: wide enough to show round them hid the colours of the demo's 127 points in no atom. The
#: legend draws it dark.
NO_ATOM = "#FFFFFF"
NO_ATOM_DARK = "#222222"
NO_ATOM_SIZE = 5
#: A fill this light (0-255, ITU-R 601 luma) or lighter takes the dark cross.
CROSS_DARK_FROM = 140.0


def cross_colors(fill) -> np.ndarray:
    """The cross of each point in no atom (:data:`NO_ATOM`) for its fill colours ``fill``
    (``#rrggbb``, (n,)): white on a dark fill, :data:`NO_ATOM_DARK` on a light one."""
    fill = np.asarray(fill)
    if fill.size == 0:
        return np.zeros(0, "U7")
    rgb = hex_to_rgb(fill.astype(str)).astype(float)
    luma = rgb @ np.array([0.299, 0.587, 0.114])
    return np.where(luma >= CROSS_DARK_FROM, NO_ATOM_DARK, NO_ATOM)
#: Points whose final motion changed with the last recompute: a large reddish-purple ring
#: (Okabe-Ito; no motion uses it).
CHANGED_MARK = "#CC79A7"
#: Points LAAV's final labels and plain RV's label differently (colouring ``vs_plain``):
#: Okabe-Ito orange, no motion's colour and not black, which the misclassified rings drawn
#: over them mean (ΔE 73 from the grey of the others, 103 from black, deuteranopia simulated).
DIFFERS_MARK = "#E69F00"


_MD_PUNCT = re.compile(r"([!-/:-@\[-`{-~])")  # every ASCII punctuation character
_CONTROL = re.compile(r"[\x00-\x1f\x7f\u2028\u2029]+")


def md_text(text) -> str:
    """``text`` (a file or sequence name, a message quoting one) as literal Markdown text.

    Every ASCII punctuation character is backslash-escaped (CommonMark allows it for all of
    them), so ``<``/``>`` cannot open HTML, ``[``/``!``/``(`` cannot make a link or image,
    ``$`` no math and ``*``/``_``/``#``/`` ` `` no formatting; line breaks and other control
    characters become one space (no block structure). The page then shows the string as typed.
    """
    return _MD_PUNCT.sub(r"\\\1", _CONTROL.sub(" ", str(text)))


def hex_to_rgb(colors) -> np.ndarray:
    """``["#rrggbb", ...]`` -> uint8 array of shape (n, 3)."""
    arr = np.asarray(colors, dtype="U7")
    if arr.size == 0:
        return np.zeros((0, 3), np.uint8)
    raw = np.char.lstrip(arr, "#")
    ints = np.array([int(h, 16) for h in raw.tolist()], dtype=np.int64)
    return np.stack([(ints >> 16) & 255, (ints >> 8) & 255, ints & 255], axis=1).astype(np.uint8)


#: Margin around a sequence's pixel extent in its 2-D views, as a share of its larger side:
#: a point on the image border (tracks reach it) is drawn whole, with its rings, not cut in
#: half by the plot's edge.
VIEW_MARGIN = 0.025


def view_extent(extent) -> tuple[float, float, float, float]:
    """``extent`` (x0, x1, y0, y1), a sequence's :meth:`laav.Sequence.extent`, widened by
    :data:`VIEW_MARGIN` on every side: what the 2-D views show."""
    x0, x1, y0, y1 = extent
    m = VIEW_MARGIN * max(x1 - x0, y1 - y0, 1e-9)
    return x0 - m, x1 + m, y0 - m, y1 + m


def visible_at(seq: laav.Sequence, frame: int) -> np.ndarray:
    """(P,) bool: the points ``seq`` sees in ``frame`` (all of them on complete data).
    Every view draws only these; hidden coordinates (possibly NaN) are never read."""
    if seq.is_complete:
        return np.ones(seq.n_points, dtype=bool)
    return np.asarray(seq.visible[int(frame)], dtype=bool)


def _unlabelled(result: laav.LaavResult) -> np.ndarray:
    """(P,) bool: the points the final stage left unlabelled (seen too briefly)."""
    return np.asarray(result.unlabelled_code) > 0


def counted(n: int, noun: str) -> str:
    """``1 motion``, ``2 motions``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def result_notes(result: laav.LaavResult) -> list[str]:
    """Markdown notes on a result that says more about the data or the settings than about
    the method (what ``laav`` warns of, which a page does not show): motions asked for that
    got no point, and a run in which no atom formed (the fine-tuning then starts from
    random labels: plain Random Voting)."""
    notes = []
    C = result.n_motions
    used = np.unique(result.labels[result.labels >= 0]).size
    if C > 1 and used < C:
        notes.append(f"**Only {used} of the {C} motions asked for got points:** fewer motions "
                     f"may fit these tracks (try C = {max(used, 1)}).")
    if C > 1 and result.atoms.n_atoms == 0:
        p = result.params
        notes.append(f"**No atom formed** with R1 = {p.r1:g}, R2 = {p.r2:g} px: the fine-tuning "
                     "started from random labels (plain Random Voting, not LAAV); larger radii "
                     "or a larger affine threshold let atoms form.")
    return notes


def incomplete_note(seq: laav.Sequence, result: laav.LaavResult | None = None,
                    counts: bool = True) -> str:
    """Markdown for the page note on an incomplete sequence ("" when complete): how many
    tracks, what share of the entries is visible (unless ``counts`` is False: a video's
    summary says it already), how many points the final stage left unlabelled (seen too
    briefly; counted as errors)."""
    if seq.is_complete:
        return ""
    n_full = int(np.count_nonzero(seq.visible.all(axis=0)))
    text = ""
    if counts:
        text = (f"Incomplete tracks: {seq.n_points} tracks over {seq.n_frames} frames, "
                f"{100 * seq.visible_share:.1f} % of the entries visible ({n_full} tracks seen in every "
                "frame); every view draws a point only where it is seen.")
    if result is not None:
        n_un = int(np.count_nonzero(result.unlabelled_code))
        if n_un:
            text += (f"{' ' if text else ''}{n_un} point{'s' if n_un != 1 else ''} "
                     f"{'are' if n_un != 1 else 'is'} "
                     f"*{UNSEEN_LABEL}* (label -1, grey ⊗"
                     + ("; counted as errors)." if seq.labels is not None else ")."))
    return text


def _palette(labels: np.ndarray, palette) -> np.ndarray:
    pal = np.asarray(palette, dtype="U7")
    out = np.full(labels.shape, UNLABELLED, dtype="U7")
    ok = labels >= 0
    out[ok] = pal[labels[ok] % pal.size]
    return out


def motion_color(m: int) -> str:
    """Colour of (0-based) motion ``m``."""
    return MOTION_COLORS[int(m) % len(MOTION_COLORS)]


def motion_marker(m: int) -> str:
    """Marker shape of (0-based) motion ``m``."""
    return MOTION_MARKERS[int(m) % len(MOTION_MARKERS)]


def shade(color: str, t: float) -> str:
    """``color`` mixed with white (``t`` > 0) or black (``t`` < 0) by ``|t|``."""
    rgb = hex_to_rgb([color])[0].astype(float)
    target = 255.0 if t > 0 else 0.0
    out = np.clip(np.round(rgb + abs(t) * (target - rgb)), 0, 255).astype(int)
    return "#{:02X}{:02X}{:02X}".format(*out)


def _motion_palette(labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Colours and markers of motion labels (-1: unlabelled grey circle)."""
    labels = np.asarray(labels, dtype=np.int64)
    col = np.full(labels.shape, UNLABELLED, dtype="U7")
    mk = np.full(labels.shape, "circle", dtype=object)
    ok = labels >= 0
    col[ok] = np.asarray(MOTION_COLORS, dtype="U7")[labels[ok] % len(MOTION_COLORS)]
    mk[ok] = np.asarray(MOTION_MARKERS, dtype=object)[labels[ok] % len(MOTION_MARKERS)]
    return col, mk


def align_labels(pred: np.ndarray, ref: np.ndarray | None) -> np.ndarray:
    """Rename ``pred``'s labels to agree with ``ref`` as far as possible (for stable colours).

    The best one-to-one matching (on the points labelled in both) maps predicted labels to
    reference labels; unmatched predicted labels get the smallest numbers no matched one
    took (so C motions stay named 1..C when the reference has fewer: a coarse stage that
    put every covered point in one motion named the other final motion "motion 3" at C = 2).
    ``-1`` stays ``-1``.
    """
    pred = np.asarray(pred, dtype=np.int64)
    if ref is None:
        return pred.copy()
    ref = np.asarray(ref, dtype=np.int64)
    both = (pred >= 0) & (ref >= 0)
    out = np.full_like(pred, -1)
    if not both.any():
        return pred.copy()
    mapping = laav.best_label_map(ref[both], pred[both])
    free = (k for k in itertools.count() if k not in set(mapping.values()))
    for p in np.unique(pred[pred >= 0]).tolist():
        if p not in mapping:
            mapping[p] = next(free)
    lab = pred >= 0
    lut = np.full(int(pred.max()) + 1, -1, dtype=np.int64)
    for p, t in mapping.items():
        lut[p] = t
    out[lab] = lut[pred[lab]]
    return out


def _aligned(seq: laav.Sequence, result: laav.LaavResult, ref=None) -> dict:
    """Coarse and final labels renamed to match the ground truth (or, without one, ``ref``
    when given, else each other)."""
    gt = seq.labels
    base = gt if gt is not None else ref
    coarse = align_labels(result.coarse.point_labels, base)
    final = align_labels(result.labels, base if base is not None else coarse)
    return {"gt": gt, "coarse": coarse, "final": final}


def stage_name(stage: str) -> str:
    """A stage of :data:`ERROR_STAGE` as the page names it: ``"plain RV"`` for ``"plain"``
    (plain Random Voting is no stage of LAAV's), the stage itself otherwise."""
    return "plain RV" if stage == "plain" else stage


def shown_labels(seq: laav.Sequence, result: laav.LaavResult, ref=None) -> dict:
    """The coarse and final labels as the views number (and colour) them: matched to the
    ground truth; without one to ``ref`` (another result's shown final labels, so two
    results side by side use the same colour for the same motion), else the final labels
    to the coarse ones. Keys ``gt``, ``coarse``, ``final``."""
    return _aligned(seq, result, ref)


def fine_motions(seq: laav.Sequence, result: laav.LaavResult, ref=None) -> np.ndarray:
    """The (0-based) motion each fine model joined, numbered like the coarse colours
    (the coarse labels aligned with the ground truth, or ``ref``: :func:`shown_labels`)."""
    f2c = np.asarray(result.coarse.fine_to_coarse, dtype=np.int64)
    if f2c.size == 0:
        return f2c
    coarse_al = _aligned(seq, result, ref)["coarse"]
    raw = np.asarray(result.coarse.point_labels)
    ren = {}
    for m in np.unique(raw[raw >= 0]).tolist():
        ren[m] = int(np.bincount(coarse_al[raw == m]).argmax())
    return np.array([ren.get(int(m), int(m)) for m in f2c.tolist()], dtype=np.int64)


def fine_colors(seq: laav.Sequence, result: laav.LaavResult, ref=None) -> np.ndarray:
    """Colour of each fine model: a shade of the colour of the motion it joined (the first
    fine model of a motion gets the motion's own colour, the next ones lighter / darker)."""
    mot = fine_motions(seq, result, ref)
    out = np.empty(mot.size, dtype="U7")
    seen: dict = {}
    for j, m in enumerate(mot.tolist()):
        r = seen.get(m, 0)
        seen[m] = r + 1
        out[j] = shade(motion_color(m), FINE_SHADES[r % len(FINE_SHADES)])
    return out


def stage_errors(seq: laav.Sequence, result: laav.LaavResult, stage: str,
                 plain: laav.Voting | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Which points ``stage`` got wrong, and which it labelled at all.

    ``fine``: a point is wrong when its fine model's majority true motion is not its own
    (a fine model counts as one motion; over-segmentation is no error); ``coarse``: its
    motion after the fine-to-coarse merge, matched to the truth; ``final`` and ``plain``
    (plain RV from a random start, ``plain`` given): the same for every point. Points a
    stage leaves out (in no atom) are neither. Without ground truth (or plain RV not
    computed yet) nothing is wrong and nothing is scored.
    """
    P = seq.n_points
    gt = seq.labels
    none = np.zeros(P, dtype=bool)
    if gt is None:
        return none, none
    gt = np.asarray(gt, dtype=np.int64)
    if stage == "fine":
        lab = np.asarray(result.coarse.fine_point_labels, dtype=np.int64)
        ok = lab >= 0
        wrong = none.copy()
        for f in np.unique(lab[ok]).tolist():
            sel = lab == f
            wrong[sel] = gt[sel] != np.bincount(gt[sel]).argmax()
        return wrong, ok
    if stage == "coarse":
        lab = _aligned(seq, result)["coarse"]
        ok = lab >= 0
        return ok & (lab != gt), ok
    if stage == "final":
        return _aligned(seq, result)["final"] != gt, ~none
    if stage == "plain":
        if plain is None:
            return none, none
        return align_labels(plain.labels, gt) != gt, ~none
    raise ValueError(f"unknown stage {stage!r}")


#: px a legend row takes beside a frame view (9 pt labels, spacing 0: bokeh's 20 px glyphs).
LEGEND_ROW_PX = 20
#: A frame view's legend rows that are not the fine models' (atom R2, atom R1, no fine model,
#: in no atom, changed motion, misclassified).
LEGEND_OTHER_ROWS = 6


def fine_legend_rows(frame_height: int, views: int = 1) -> int:
    """How many fine models a frame view's legend can list one by one (:func:`point_style`'s
    ``fine_rows``): the rows that fit beside a frame ``frame_height`` px tall (the legend, to
    the plot's right, may reach the toolbar's bottom, about 60 px below the frame) less the
    other rows; ``views``: how many views' models share the legend (the A/B compare: 2)."""
    rows = (int(frame_height) + 60) // LEGEND_ROW_PX - LEGEND_OTHER_ROWS
    return max(rows // max(int(views), 1), 0)


def n_fine_models(result: laav.LaavResult) -> int:
    """How many fine models label points (the rows the "fine" legend lists one by one)."""
    lab = np.asarray(result.coarse.fine_point_labels)
    return int(np.unique(lab[lab >= 0]).size)


def shared_fine_rows(rows: int, *results: laav.LaavResult) -> int:
    """:func:`point_style`'s ``fine_rows`` for views sharing one legend (the A/B compare):
    ``rows`` when every result's fine models fit in them, else -1 (every side grouped, so the
    legend never mixes a side's rows per model with another's per motion)."""
    return rows if max((n_fine_models(r) for r in results), default=0) <= rows else -1


def point_style(seq: laav.Sequence, result: laav.LaavResult, mode: str,
                plain: laav.Voting | None = None, ref=None, fine_rows: int | None = None,
                fine_counts: bool = True) -> dict:
    """Colour, marker and legend label of every point for a colour-by ``mode`` (see COLOR_MODES).

    Motions have one colour and marker shape each (:data:`MOTION_COLORS`,
    :data:`MOTION_MARKERS`) in every mode; a fine model is drawn as a shade of the motion
    it joined, with that motion's marker.

    Returns
    -------
    dict with ``color`` (P,) hex strings, ``marker`` (P,) bokeh marker names, ``label`` (P,)
    legend strings, ``misclassified`` (P,) bool: the points the mode's stage got wrong
    (:data:`ERROR_STAGE`, :func:`stage_errors`; all False without ground truth), ``stage``
    (that stage), ``note`` (str, empty unless the mode cannot be shown as asked), ``mode``
    (the mode drawn: ``"final"`` when ground truth is asked for and missing).
    ``ref``: without ground truth, the labels the motions are matched to (their colours;
    see :func:`shown_labels`). ``detail`` (P,): a point's own text for a hover where the
    legend groups, else "" (the label says it): with more fine models than ``fine_rows`` (the
    rows the legend has for them, :func:`fine_legend_rows`) the "fine" mode's legend has a
    row per motion ("motion 2: 6 fine models") instead of one per fine model, which then
    overflowed the plot, and ``detail`` keeps "fine model 5 → motion 2". Without
    ``fine_counts`` such a row says "motion 2: its fine models" (the A/B compare's legend,
    shared by two results whose counts differ).
    """
    P = seq.n_points
    al = _aligned(seq, result, ref)
    gt = al["gt"]
    note = ""
    detail = None  # (the label, unless the legend groups: see above)
    marker = np.full(P, "circle", dtype=object)
    if mode in PLAIN_MODES and plain is None:
        note = "plain RV is still computing: showing the final labels until it is ready"
        mode = "errors" if mode == "errors_plain" else "final"
    if mode in TRUTH_MODES and gt is None:
        note = "this sequence has no ground truth: showing the final labels"
        mode = "final"
    stage = ERROR_STAGE[mode]
    wrong, scored = stage_errors(seq, result, stage, plain)
    if mode == "gt":
        lab = gt
        color, marker = _motion_palette(lab)
        label = np.char.add("motion ", (lab + 1).astype("U3"))
    elif mode == "atoms":
        owner = np.asarray(result.atoms.owner)
        # features in an atom's ring only: colour by the first atom that holds them
        first = owner.copy()
        for i, m in enumerate(result.atoms.members):
            sel = m[first[m] < 0]
            first[sel] = i
        color = _palette(first, ATOM_COLORS)
        # one legend entry: the points in no atom have the × mark's own entry ("in no atom: N")
        label = np.full(P, "point (colour = its atom)")
    elif mode == "fine":
        lab = np.asarray(result.coarse.fine_point_labels, dtype=np.int64)
        fc, mot = fine_colors(seq, result, ref), fine_motions(seq, result, ref)
        ok = lab >= 0
        joined = np.full(P, -1, dtype=np.int64)
        joined[ok] = mot[lab[ok]]
        color = np.full(P, UNLABELLED, dtype="U7")
        color[ok] = fc[lab[ok]]
        _, marker = _motion_palette(joined)
        label = np.array([f"fine model {f + 1} → motion {m + 1}" if f >= 0 else "no fine model"
                          for f, m in zip(lab.tolist(), joined.tolist())], dtype=object)
        if fine_rows is not None and n_fine_models(result) > fine_rows:  # a legend row per motion
            detail = label
            per = {int(m): np.unique(lab[ok & (joined == m)]).size for m in np.unique(joined[ok])}
            label = np.array([(f"motion {m + 1}: {per[m]} fine model{'' if per[m] == 1 else 's'}"
                               if fine_counts else f"motion {m + 1}: its fine models")
                              if f >= 0 else "no fine model"
                              for f, m in zip(lab.tolist(), joined.tolist())], dtype=object)
    elif mode in ("coarse", "final", "plain"):
        lab = al[mode] if mode != "plain" else align_labels(plain.labels, gt if gt is not None
                                                             else al["final"])
        color, marker = _motion_palette(lab)
        # (the coarse stage's -1: in no atom, which the x overlay counts; a name of its own here)
        label = np.where(lab >= 0, np.char.add("motion ", (lab + 1).astype("U3")), "no coarse motion")
        if mode != "coarse":  # -1 after the voting: seen too briefly to decide (missing data)
            un = lab < 0
            color = np.where(un, UNSEEN, color).astype("U7")
            marker = np.where(un, UNSEEN_MARKER, marker).astype(object)
            label = np.where(un, UNSEEN_LABEL, label)
    elif mode == "vs_plain":  # where the final labels and plain RV's differ (no truth needed)
        fin = al["final"]
        differ = plain_differs(fin, plain.labels)
        color = np.where(differ, DIFFERS_MARK, CORRECT).astype("U7")
        _, marker = _motion_palette(fin)  # the final motion's shape
        label = np.where(differ, "differs from plain RV", "same as plain RV")
    elif mode.startswith("errors"):
        color = np.where(wrong, ERROR_MARK, np.where(scored, CORRECT, "#EEEEEE")).astype("U7")
        label = np.where(wrong, f"misclassified ({stage_name(stage)})",
                         np.where(scored, f"correct ({stage_name(stage)})", "not labelled at this stage"))
        un = _unlabelled(result) if stage == "final" else (
            np.asarray(plain.labels) < 0 if stage == "plain" and plain is not None else None)
        if un is not None and un.any():  # an error too (as the metrics count it), own marker
            marker = np.where(un, UNSEEN_MARKER, marker).astype(object)
            label = np.where(un, f"{UNSEEN_LABEL} (an error)", label)
    else:
        raise ValueError(f"unknown colour mode {mode!r}")
    label = np.asarray(label).astype(str)
    detail = np.full(P, "", dtype=object) if detail is None else np.asarray(detail).astype(object)
    return {"color": np.asarray(color, dtype="U7"), "marker": np.asarray(marker, dtype=object),
            "label": label, "detail": detail, "misclassified": wrong, "stage": stage,
            "note": note, "mode": mode}


def plain_differs(final: np.ndarray, plain: np.ndarray) -> np.ndarray:
    """(P,) bool: the points whose final label and plain RV's (or any two labellings') differ
    once the second's motions are renamed to match the first's (:func:`align_labels`, the
    best one-to-one matching on the points both label). A point only one of them leaves
    unlabelled (-1) differs; one both leave (seen too briefly, which depends on the tracks
    alone), not."""
    final = np.asarray(final, dtype=np.int64)
    other = align_labels(plain, final)
    return ((final != other) | (final < 0) | (other < 0)) & ((final >= 0) | (other >= 0))


#: The share of the points two labellings label differently (card 5's number; it counts the
#: points the differences colouring, :func:`plain_differs`, marks).
labelling_distance = laav.labelling_distance


def raw_style(seq: laav.Sequence) -> dict:
    """The points' style before any result: the ground truth's colours and shapes (grey
    circles without one), as :func:`point_style` colours them in the ``gt`` mode."""
    P = seq.n_points
    if seq.labels is None:
        return {"color": np.full(P, UNLABELLED, dtype="U7"), "marker": np.full(P, "circle", dtype=object),
                "label": np.full(P, "not segmented yet").astype(str)}
    lab = np.asarray(seq.labels, dtype=np.int64)
    color, marker = _motion_palette(lab)
    return {"color": np.asarray(color, dtype="U7"), "marker": np.asarray(marker, dtype=object),
            "label": np.asarray(np.char.add("motion ", (lab + 1).astype("U3"))).astype(str)}


# ---------------------------------------------------------------------- frame templates
# A view that follows the frame (the frame view's points, trails, atoms and marks; the
# graph's nodes and edges) is described once per result by a *template* per data source:
# rows anchored to one or two tracked ids (``_a``, ``_b``: points, or atoms for the graph)
# with the columns that do not depend on the frame; a *spec* says how a frame's rows are
# made from it. :func:`instantiate` makes the rows of one frame; the page runs the same rules
# in JavaScript (explorer/cards/live.py) so that a frame move is drawn without the server.

#: Frames of trail behind each point in the frame view.
TRAIL = 5


def trail_alpha(age: int, trail: int = TRAIL) -> float:
    """Opacity of a trail step ``age`` frames back (1 = the last step)."""
    return 0.85 - 0.7 * (age - 1) / max(trail, 1)


_AT = {"x": ["_a", 0], "y": ["_a", 1]}
_SEGMENT = {"x0": ["_a", 0], "y0": ["_a", 1], "x1": ["_b", 0], "y1": ["_b", 1]}


def frame_specs(trail: int = TRAIL) -> dict:
    """How each source of the frame view is made from its template at a frame
    (:func:`instantiate`); JSON-able: the page runs the same rules.

    A spec: ``track`` (``points`` or ``atoms``), ``coords`` (column -> [anchor, 0 for x / 1
    for y]) and ``blocks``: each block adds the template's rows with the anchors taken ``da``
    / ``db`` frames from the frame shown (a row is kept when its anchors are seen there),
    with the block's ``const`` columns. The trails are one block per step back (the oldest
    first), between frames f - k and f - k + 1."""
    one = [{}]
    return {
        "points": {"track": "points", "coords": _AT, "blocks": one},
        "trails": {"track": "points", "coords": _SEGMENT,
                   "blocks": [{"da": -k, "db": 1 - k, "const": {"alpha": trail_alpha(k, trail)}}
                              for k in range(trail, 0, -1)]},
        "atoms": {"track": "points", "coords": _AT, "blocks": one},
        "unassigned": {"track": "points", "coords": _AT, "blocks": one},
        "errors": {"track": "points", "coords": _AT, "blocks": one},
        "changed": {"track": "points", "coords": _AT, "blocks": one},
    }


def graph_specs() -> dict:
    """The multicut graph's sources (:func:`graph_templates`), as :func:`frame_specs`."""
    one = [{}]
    return {"nodes": {"track": "atoms", "coords": _AT, "blocks": one},
            "joined": {"track": "atoms", "coords": _SEGMENT, "blocks": one},
            "cut": {"track": "atoms", "coords": _SEGMENT, "blocks": one},
            "step_edge": {"track": "atoms", "coords": _SEGMENT, "blocks": one},
            "pair": {"track": "atoms", "coords": _AT, "blocks": one}}


def point_track(seq: laav.Sequence) -> tuple[np.ndarray, np.ndarray | None]:
    """The points' positions (F, P, 2) and where each is seen (F, P) bool, None when complete."""
    return seq.points, (None if seq.is_complete else np.asarray(seq.visible, dtype=bool))


def atom_track(result: laav.LaavResult) -> tuple[np.ndarray, np.ndarray | None]:
    """The atoms' centres (F, N, 2) (``AtomGraph.positions``; NaN where no member is seen)
    and where each is drawn: where its centre is finite."""
    pos = np.asarray(result.graph.positions, dtype=float)
    if pos.ndim != 3 or pos.shape[2:] != (2,):  # no atoms
        pos = np.zeros((max(pos.shape[0] if pos.ndim else 0, 1), 0, 2))
    return pos, np.isfinite(pos).all(axis=2)


def instantiate(tpl: dict, spec: dict, xy: np.ndarray, visible: np.ndarray | None, frame: int) -> dict:
    """The rows of template ``tpl`` (``_a``, optional ``_b``: ids into the track; other keys:
    columns) at ``frame`` by ``spec`` (:func:`frame_specs`), on the track ``xy`` (F, N, 2)
    seen where ``visible`` (F, N) (None: everywhere). ``frame`` is clipped to the track."""
    F = xy.shape[0]
    f = int(np.clip(frame, 0, F - 1)) if F else 0
    a = np.asarray(tpl["_a"], dtype=np.int64)
    b = np.asarray(tpl["_b"], dtype=np.int64) if "_b" in tpl else None
    keeps = []  # (block, frame of a, frame of b, kept rows)
    for blk in spec["blocks"]:
        fa, fb = f + int(blk.get("da", 0)), f + int(blk.get("db", 0))
        if not 0 <= fa < F or (b is not None and not 0 <= fb < F):
            continue
        keep = np.ones(a.size, dtype=bool) if visible is None else visible[fa][a]
        if b is not None and visible is not None:
            keep &= visible[fb][b]
        keeps.append((blk, fa, fb, np.flatnonzero(keep)))
    out = {}
    for col, (anchor, dim) in spec["coords"].items():
        ids = a if anchor == "_a" else b
        parts = [xy[fa if anchor == "_a" else fb, ids[k], int(dim)] for _, fa, fb, k in keeps]
        out[col] = np.concatenate(parts) if parts else np.zeros(0)
    for name in dict.fromkeys(n for blk in spec["blocks"] for n in blk.get("const", {})):
        parts = [np.full(k.size, blk.get("const", {}).get(name, np.nan)) for blk, _, _, k in keeps]
        out[name] = np.concatenate(parts) if parts else np.zeros(0)
    for name, col in tpl.items():
        if name in ("_a", "_b"):
            continue
        col = np.asarray(col)
        out[name] = np.concatenate([col[k] for _, _, _, k in keeps]) if keeps else col[:0]
    return out


_FIELD = re.compile(r"\{(f|n|k)(?::(\w+)(?:\.(\w+))?)?\}")


def fill_text(fmt: str, frame: int, sources: dict) -> str:
    """A view's text at a frame: ``{f}`` the frame, ``{n:src}`` the rows of ``sources[src]``,
    ``{k:src.col}`` the distinct values of that column (the page fills them the same way)."""
    def sub(m):
        kind, name, col = m.groups()
        if kind == "f":
            return str(int(frame))
        d = sources[name]
        if kind == "n":
            return str(len(next(iter(d.values()))) if d else 0)
        return str(len(np.unique(np.asarray(d[col]))))
    return _FIELD.sub(sub, fmt)


def label_order(labels) -> np.ndarray:
    """Indices (P,) that sort legend labels (P,) with their numbers read as numbers, so that
    a legend lists "fine model 2" before "fine model 10"; stable (equal labels keep their
    order)."""
    labels = np.asarray(labels).astype(str)
    uniq, inv = np.unique(labels, return_inverse=True)
    rank = np.empty(uniq.size, dtype=np.int64)
    rank[sorted(range(uniq.size), key=lambda i: _natural_key(uniq[i]))] = np.arange(uniq.size)
    return np.argsort(rank[inv.reshape(-1)], kind="stable")


def _natural_key(text: str) -> list:
    """``text`` split into its runs of digits (as ints) and the text between (as str):
    "fine model 10 → motion 2" -> ["fine model ", 10, " → motion ", 2, ""]."""
    return [int(t) if i % 2 else t for i, t in enumerate(_DIGITS.split(text))]


_DIGITS = re.compile(r"(\d+)")


def points_template(style: dict) -> dict:
    """The frame view's points (x, y, color, marker, label, detail, index) as a template: in label
    order (:func:`label_order`) so that the legend lists "motion 1, motion 2, ..., motion
    10" in order."""
    color = style["color"]
    order = label_order(style["label"])
    marker = style.get("marker")
    marker = np.full(color.shape, "circle", dtype=object) if marker is None else marker
    detail = style.get("detail")
    detail = np.full(color.shape, "", dtype=object) if detail is None else np.asarray(detail, dtype=object)
    return {"_a": order.astype(np.int32), "color": color[order], "marker": marker[order],
            "label": style["label"][order], "detail": detail[order], "index": order}


def points_source(seq: laav.Sequence, frame: int, style: dict) -> dict:
    """The frame view's points at ``frame`` (x, y, color, marker, label, index), in label
    order so that the legend lists "motion 1, motion 2, ..." in order; only the points
    visible in ``frame`` (:func:`visible_at`). Needs no result:
    with :func:`raw_style` it draws the raw points before anything is computed."""
    return instantiate(points_template(style), frame_specs()["points"], *point_track(seq), frame)


def legend_points(*styles: dict) -> dict:
    """One legend for views drawn with several point styles (:func:`point_style`; the A/B
    compare's two views): a row per legend label that any of them has, with that label's
    colour and marker (its first point's, as a frame view's legend draws it), in the frame
    view's order (:func:`points_template`: "motion 1, motion 2, ..."), at no position (NaN:
    drawn only in a legend). Keys: x, y, color, marker, label."""
    tpls = [points_template(s) for s in styles]
    label = np.concatenate([np.asarray(t["label"]).astype(str) for t in tpls] or [np.zeros(0, "U1")])
    color = np.concatenate([np.asarray(t["color"], dtype="U7") for t in tpls] or [np.zeros(0, "U7")])
    marker = np.concatenate([np.asarray(t["marker"], dtype=object) for t in tpls]
                            or [np.zeros(0, dtype=object)])
    _, first = np.unique(label, return_index=True)
    first = first[label_order(label[first])]  # the frame view's order (:func:`label_order`)
    nan = np.full(first.size, np.nan)
    return {"x": nan, "y": nan.copy(), "color": color[first], "marker": marker[first], "label": label[first]}


def frame_templates(seq: laav.Sequence, result: laav.LaavResult, style: dict, moved=None) -> dict:
    """The frame view's templates (see :func:`frame_specs`): ``points``, ``trails`` (each
    point's steps, in its colour), ``atoms`` (at their seeds: r1, r2, color, atom),
    ``unassigned``, ``errors`` (misclassified points), ``changed`` (``moved``: indices of
    points whose final motion changed with the last recompute)."""
    color = style["color"]
    ids = np.arange(seq.n_points, dtype=np.int32)
    atoms = result.atoms
    seeds = np.asarray(atoms.seeds, dtype=np.int64)
    un = np.asarray(atoms.unassigned, dtype=np.int64)
    mv = np.zeros(0, np.int64) if moved is None else np.asarray(moved, dtype=np.int64)
    return {
        "points": points_template(style),
        "trails": {"_a": ids, "_b": ids, "color": color},
        "atoms": {"_a": seeds.astype(np.int32), "r1": np.full(seeds.size, float(atoms.r1)),
                  "r2": np.full(seeds.size, float(atoms.r2)),
                  "color": color[seeds] if seeds.size else np.zeros(0, "U7"),
                  "atom": np.arange(seeds.size)},
        "unassigned": {"_a": un.astype(np.int32), "cross": cross_colors(color[un])},
        "errors": {"_a": np.flatnonzero(style["misclassified"]).astype(np.int32)},
        "changed": {"_a": mv.astype(np.int32)},
    }


def frame_sources(seq: laav.Sequence, result: laav.LaavResult, frame: int, style: dict,
                  trail: int = TRAIL, moved=None) -> dict:
    """Data of the frame view at ``frame``.

    ``moved``: indices of points whose final motion changed with the last recompute
    (``changed``: their x, y).

    Keys: ``points`` (x, y, color, label, index), ``trails`` (x0, y0, x1, y1, color,
    alpha: the last ``trail`` frames, fading), ``atoms`` (x, y at the seeds, r1, r2,
    color, atom), ``unassigned`` (x, y, cross: :func:`cross_colors`), ``errors`` (x, y: misclassified points).

    On incomplete data everything is drawn only where it is seen: points, marks and atom
    seeds visible in ``frame``, trail steps between two consecutive frames both visible
    (a gap breaks the trail). (:func:`frame_templates` at ``frame``.)
    """
    specs, track = frame_specs(trail), point_track(seq)
    return {k: instantiate(t, specs[k], *track, frame)
            for k, t in frame_templates(seq, result, style, moved).items()}


# ---------------------------------------------------------------------- multicut graph
def replay_roots(result: laav.LaavResult, step: int) -> np.ndarray:
    """The cluster of each atom after the first ``step`` GAEC contractions, named by its
    root: the atom that was kept at every contraction the cluster took part in."""
    mc = result.multicut
    n = result.graph.n_nodes
    parent = np.arange(n)

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for kept, merged in np.asarray(mc.contractions[:step]).reshape(-1, 2).tolist():
        a, b = find(kept), find(merged)
        if a != b:
            parent[b] = a
    return np.array([find(i) for i in range(n)], dtype=np.int64)


def replay_labels(result: laav.LaavResult, step: int) -> np.ndarray:
    """Cluster of each atom after replaying the first ``step`` GAEC contractions.

    ``step`` beyond the number of contractions gives the final fine models
    (``Multicut.atom_labels``: GAEC, then Kernighan-Lin, then the count brought to 2C).
    Clusters are numbered by size, largest first.
    """
    mc = result.multicut
    n = result.graph.n_nodes
    K = len(mc.contractions)
    if step > K:
        return np.asarray(mc.atom_labels, dtype=np.int64)
    roots = replay_roots(result, step)
    if n == 0:
        return roots
    uniq, inv, counts = np.unique(roots, return_inverse=True, return_counts=True)
    order = np.argsort(-counts, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    return rank[inv.ravel()]


def fine_count(params: laav.LaavParams, n_motions: int, complete: bool = True) -> str:
    """How many fine models the multicut is brought to: a multiple of C where it is one
    (``"2C"``, ``"4C"``), else the number."""
    n = params.n_fine(n_motions, complete)
    return f"{n // n_motions}C" if n_motions and n % n_motions == 0 else str(n)


def fine_count_note(params: laav.LaavParams, n_motions: int, complete: bool = True) -> str:
    """:func:`fine_count`, and whether that is the paper's 2C."""
    k = fine_count(params, n_motions, complete)
    if k == "2C":
        return "2C, the paper's"
    if params.fine_models is not None or params.fine_per_motion is not None:
        return f"{k}, as set; the paper: 2C"
    return f"{k}: ours for the {params.merge_for(complete)} merge; the paper: 2C"


def replay_caption(result: laav.LaavResult, step: int, complete: bool = True) -> str:
    """The caption under the multicut replay at GAEC step ``step`` (beyond the last: the
    final fine models); ``complete`` whether the tracks are (the fine count depends on it)."""
    mc = result.multicut
    K = len(mc.contractions)
    n = result.graph.n_nodes
    if step > K:
        how = fine_count_note(result.params, result.n_motions, complete)
        return (f"**Final fine models:** {mc.n_models} (GAEC, then Kernighan–Lin moves, then merged or "
                f"split to {how}). Dashed edges are cut. Drag the step slider left to replay GAEC.")
    if step == 0:
        return (f"**GAEC step 0 / {K}:** every one of the {n} atoms is its own cluster. GAEC repeatedly "
                f"joins the two clusters linked by the largest positive total cost.")
    kept, merged = np.asarray(mc.contractions[step - 1]).tolist()
    return (f"**GAEC step {step} / {K}:** joined atoms {kept} and {merged} (ringed, on top; "
            f"cost {float(mc.contraction_costs[step - 1]):+.2f}); {n - step} clusters. Atom {merged}'s "
            f"cluster took the colour of atom {kept}'s; no other atom changed colour. Dashed edges run "
            f"between clusters; a cluster's colour is the final fine model its first atom ends in.")


def cost_limit(result: laav.LaavResult) -> float:
    """Symmetric colour-scale limit for edge costs (95th percentile of |cost|)."""
    c = np.abs(np.asarray(result.graph.costs, dtype=float))
    if c.size == 0:
        return 1.0
    return float(max(np.percentile(c, 95), 1e-6))


#: The atom ids beside the graph's nodes: font sizes (px) of an id (7 pt) and of the ids of
#: the pair joined at a replay step (8 pt, bold), the room between an id and its node's edge
#: (px; the pair's: its ring's), the room left between two ids (px), and a digit's width (em;
#: bokeh's text font, Helvetica or its metric twins; bold: 0.556 too).
ID_FONT_PX = 7 * 96 / 72
PAIR_ID_FONT_PX = 8 * 96 / 72
ID_MARGIN_PX = 2.0
ID_GAP_PX = 2.0
#: The part of a node an id must leave clear, as a share of its radius: the square inside
#: the circle (an id may graze a node's rim; over its middle, ids hid the nodes they named).
ID_CLEAR = 0.5 ** 0.5
_DIGIT_EM = 0.556


def atom_sizes(result: laav.LaavResult) -> tuple[np.ndarray, np.ndarray]:
    """Each atom's member count (N,) and its node's size across in the graph view (px, (N,)):
    what the nodes are drawn with and what the ids are placed around."""
    sizes = np.array([len(m) for m in result.atoms.members], dtype=float)
    return sizes, 7 + 2.0 * np.sqrt(sizes)


def _id_width(ids, font_px: float) -> np.ndarray:
    """Width (px) of each id ``ids`` (n,) written at ``font_px``: its digits, (n,)."""
    return np.array([len(str(i)) for i in np.asarray(ids).tolist()], dtype=float) * _DIGIT_EM * font_px


def label_clashes(xy: np.ndarray, visible: np.ndarray | None, scale, atoms_a, boxes_a, atoms_b, boxes_b,
                  gap: float = ID_GAP_PX) -> np.ndarray:
    """Which labels of a plot come within ``gap`` px of which others, in any frame: (A, B) bool.

    Label ``k`` of set A sits beside atom ``atoms_a[k]`` of the track ``xy`` (F, N, 2) (data
    units; NaN where not drawn), seen where ``visible`` (F, N) (None: wherever finite), in the
    box ``boxes_a[k]`` = (left, top, right, bottom) px from the atom's centre on the screen (y
    down); set B likewise; ``scale`` = (sx, sy): the plot's pixels per data unit. Two labels
    clash when both atoms are drawn in a frame and their boxes come that near there: every
    frame counts, as the page draws each from the same labels without the server. Cost: F
    (A, B) comparisons."""
    a, b = np.asarray(atoms_a, dtype=np.int64), np.asarray(atoms_b, dtype=np.int64)
    ba, bb = np.asarray(boxes_a, dtype=float).reshape(-1, 4), np.asarray(boxes_b, dtype=float).reshape(-1, 4)
    clash = np.zeros((a.size, b.size), dtype=bool)
    if a.size == 0 or b.size == 0:
        return clash
    sx, sy = (abs(float(v)) for v in scale)
    for f in range(xy.shape[0]):
        xa, ya, xb, yb = xy[f, a, 0] * sx, xy[f, a, 1] * sy, xy[f, b, 0] * sx, xy[f, b, 1] * sy
        sa, sb = np.isfinite(xa) & np.isfinite(ya), np.isfinite(xb) & np.isfinite(yb)
        if visible is not None:
            sa &= np.asarray(visible[f], dtype=bool)[a]
            sb &= np.asarray(visible[f], dtype=bool)[b]
        if not sa.any() or not sb.any():
            continue
        clash |= ((xa + ba[:, 0])[:, None] < (xb + bb[:, 2] + gap)[None, :]) \
            & ((xb + bb[:, 0])[None, :] < (xa + ba[:, 2] + gap)[:, None]) \
            & ((ya + ba[:, 1])[:, None] < (yb + bb[:, 3] + gap)[None, :]) \
            & ((yb + bb[:, 1])[None, :] < (ya + ba[:, 3] + gap)[:, None]) & sa[:, None] & sb[None, :]
    return clash


def id_layout(result: laav.LaavResult, scale) -> dict:
    """Where the multicut graph's atom ids may be written at the plot's ``scale`` (px per data
    unit, (sx, sy)): the part of :func:`graph_templates`'s placement that no replay step
    changes (a card keeps it while the result and the plot's size stay).

    Each atom's id has two places, right of its node and left of it (:func:`id_boxes`), taken
    in this order: every atom's right place, the larger atoms first (then by id), then every
    left one the same way. Returns ``atoms``, ``dx``, ``align``, ``boxes`` (per place),
    ``blocked`` (a place that covers the middle of a node in some frame: the square inside
    its circle, so an id may graze a node's rim but never hide it; :data:`ID_CLEAR`) and
    ``clash`` (the places that overlap each other: :func:`label_clashes`)."""
    xy, seen = atom_track(result)
    n = result.graph.n_nodes
    sizes, node_px = atom_sizes(result)
    ids = np.arange(n)
    order = ids[np.lexsort((ids, -sizes))] if n else ids
    atoms = np.r_[order, order]
    sides = np.r_[np.ones(n), -np.ones(n)]
    dx, boxes = id_boxes(node_px[atoms], sides, atoms, ID_FONT_PX)
    r = ID_CLEAR * node_px / 2
    over_node = label_clashes(xy, seen, scale, atoms, boxes, ids, np.c_[-r, -r, r, r], gap=0.0)
    return {"scale": tuple(scale), "atoms": atoms, "dx": dx, "align": np.where(sides > 0, "left", "right"),
            "boxes": boxes, "blocked": over_node.any(axis=1),
            "clash": label_clashes(xy, seen, scale, atoms, boxes, atoms, boxes)}


def pair_id_sides(xy: np.ndarray, pair) -> np.ndarray:
    """The side of its node each of a replay step's two atoms has its id on: -1 left, +1
    right; the atom further left (on average over the frames where both are drawn) to the
    left, so that the two ids point away from each other (the pair is mostly neighbours)."""
    k, m = (int(i) for i in pair)
    dx = xy[:, m, 0] - xy[:, k, 0]
    dx = dx[np.isfinite(dx)]
    right = dx.size == 0 or float(dx.mean()) >= 0  # (m right of k)
    return np.array([-1.0, 1.0] if right else [1.0, -1.0])


def id_boxes(sizes_px: np.ndarray, sides: np.ndarray, ids, font_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Where the ids ``ids`` (n,) of nodes ``sizes_px`` (n,) across (px) are written: beside
    the node, vertically centred, on its right (``sides`` (n,) +1) or left (-1),
    :data:`ID_MARGIN_PX` from its edge. Returns the text's x offsets (n,) (px from the node's
    centre: its start on the right, its end on the left) and the boxes (n, 4) (left, top,
    right, bottom; px from the centre, y down) for :func:`label_clashes`."""
    w = _id_width(ids, font_px)
    dx = np.asarray(sides, dtype=float) * (np.asarray(sizes_px, dtype=float) / 2 + ID_MARGIN_PX)
    left = np.where(dx > 0, dx, dx - w)
    half = np.full(w.size, font_px / 2)
    return dx, np.c_[left, -half, left + w, half]


def graph_templates(result: laav.LaavResult, step: int, colors=None, scale=None, layout=None) -> dict:
    """The multicut graph view after ``step`` GAEC contractions as templates on the atoms'
    track (:func:`graph_specs`, :func:`atom_track`); see :func:`graph_sources`.

    ``scale``: the plot's pixels per data unit (sx, sy): only the atom ids that overlap no
    other id, and no node's middle, in any frame at that size are written, each right of its
    node or else left of it (:func:`id_layout`; ``layout``: that, computed before for this
    result and scale), after the ids of the pair joined at the step, which are always written;
    None: every id, right of its node."""
    g = result.graph
    n = g.n_nodes
    lab = replay_labels(result, step)
    sizes, node_px = atom_sizes(result)
    final = np.asarray(result.multicut.atom_labels, dtype=np.int64)
    pal = np.asarray(colors if colors is not None and len(colors) else ATOM_COLORS, dtype="U7")
    K = len(result.multicut.contractions)
    owner = final if step > K else final[replay_roots(result, step)] if final.size else final
    node_color = pal[owner % pal.size] if owner.size else np.zeros(0, "U7")
    ids = np.arange(n, dtype=np.int32)
    label = np.array([str(i) for i in range(n)], dtype=object)
    pair = np.asarray(result.multicut.contractions[step - 1], dtype=np.int64) if 0 < step <= K else None
    xy, seen = atom_track(result)
    # each id right of its node (x offset: dx, the text's side: align), vertically centred on it
    label_dx, _ = id_boxes(node_px, np.ones(n), ids, ID_FONT_PX)
    label_align = np.full(n, "left", dtype=object)
    if pair is not None:
        # the pair's ids are written with it, on top, bold and on the sides facing away from
        # each other (past its rings, 3 px wide: the nodes' own ids would be under them)
        pair_px = node_px[pair] + 6
        pair_dx, pair_boxes = id_boxes(pair_px + 3, pair_id_sides(xy, pair), pair, PAIR_ID_FONT_PX)
        label[pair] = ""
    if layout is None and scale is not None and n:
        layout = id_layout(result, scale)
    if layout is not None and n:
        # greedy: each place in the layout's order is taken unless it would overlap a node's
        # middle, the pair's ids or an id placed before, or its atom's id is placed already
        at, clash = layout["atoms"], layout["clash"]
        blocked = layout["blocked"].copy()
        if pair is not None:
            blocked |= np.isin(at, pair)
            blocked |= label_clashes(xy, seen, layout["scale"], pair, pair_boxes, at,
                                     layout["boxes"]).any(axis=0)
        placed = np.zeros(n, dtype=bool)
        for k in range(at.size):
            if not blocked[k] and not placed[at[k]]:
                placed[at[k]] = True
                blocked |= clash[k]
                label_dx[at[k]], label_align[at[k]] = layout["dx"][k], layout["align"][k]
        label[~placed] = ""
    nodes = {"_a": ids, "color": node_color, "cluster": lab + 1, "atom": np.arange(n),
             "members": sizes.astype(int), "size": node_px, "label": label, "dx": label_dx,
             "align": label_align}
    E = np.asarray(g.edges, dtype=np.int64).reshape(-1, 2)
    cut = np.asarray(result.multicut.cut, bool) if step > K else (lab[E[:, 0]] != lab[E[:, 1]])

    def edges(mask):
        e = E[mask]
        return {"_a": e[:, 0].astype(np.int32), "_b": e[:, 1].astype(np.int32),
                "cost": np.asarray(g.costs, dtype=float)[mask], "error": np.asarray(g.errors)[mask],
                "a": e[:, 0], "b": e[:, 1]}

    out = {"nodes": nodes, "joined": edges(~cut), "cut": edges(cut)}
    if pair is not None:
        k, m = pair.tolist()
        out["step_edge"] = {"_a": np.array([k], np.int32), "_b": np.array([m], np.int32)}
        # the two atoms joined at this step, drawn again on top of the others, ringed, with
        # their ids beside the rings (text, dx: px from the centre, align: the text's side)
        out["pair"] = {"_a": np.array([k, m], np.int32), "color": node_color[[k, m]], "size": pair_px,
                       "atom": np.array([k, m], dtype=int), "text": np.array([str(k), str(m)], dtype=object),
                       "dx": pair_dx, "align": np.where(pair_dx > 0, "left", "right").astype(object)}
    else:
        e = np.zeros(0, np.int32)
        out["step_edge"] = {"_a": e, "_b": e}
        none = np.zeros(0, dtype=object)
        out["pair"] = {"_a": e, "color": np.zeros(0, "U7"), "size": np.zeros(0), "atom": np.zeros(0, int),
                       "text": none, "dx": np.zeros(0), "align": none.copy()}
    return out


def graph_sources(result: laav.LaavResult, frame: int, step: int, colors=None, scale=None,
                  layout=None) -> dict:
    """Data of the multicut graph view at ``frame`` after ``step`` GAEC contractions.

    ``colors``: colour of each final fine model (:func:`fine_colors`). An atom is drawn in
    the colour of its final fine model; a cluster during the replay in the colour of its
    root atom's (:func:`replay_roots`): a contraction recolours only the merged cluster.

    Keys: ``nodes`` (x, y, color, cluster, atom, size, members, label: the atom id written
    beside it, "" for none: the pair's, and with ``scale`` those that would overlap another,
    see :func:`graph_templates`; dx, align: its x offset, px, and side), ``joined`` and ``cut`` edges (x0, y0,
    x1, y1, cost, error), ``step_edge`` (the contraction of this step), ``pair`` (x, y, color,
    size, atom: its two atoms, text, dx, align: their ids, beside their rings; empty at step 0
    and after the last contraction). On incomplete data only the atoms with a centre in ``frame`` (a member
    seen there; ``AtomGraph.positions`` is NaN otherwise) and the edges between two of them
    are drawn. (:func:`graph_templates` at ``frame``.)
    """
    specs, track = graph_specs(), atom_track(result)
    return {k: instantiate(t, specs[k], *track, frame)
            for k, t in graph_templates(result, step, colors, scale, layout).items()}


# ---------------------------------------------------------------------- coarse merges
def _model_factors(result: laav.LaavResult) -> list:
    f2c = np.asarray(result.coarse.fine_to_coarse)
    return [f"f{j + 1}→M{int(m) + 1}" for j, m in enumerate(f2c.tolist())]


#: Most fine models whose Z values are written in the heat map's cells (9 models overlap).
Z_TEXT_MAX = 8
#: Widths in em of the characters a cell's number is written with, in bokeh's text font
#: (``helvetica``: Helvetica, Arial or Liberation Sans, which share these widths); any other
#: character as wide as a digit.
_CHAR_EM = {"-": 0.333, ".": 0.278, "+": 0.584, "k": 0.5}


def cell_font_px(texts, cell_px: float, largest: int = 12, smallest: int = 8) -> int:
    """The font size (px) at which the widest of ``texts`` fits a heat-map cell ``cell_px``
    wide with a margin on either side, at most ``largest``; 0 when that is below
    ``smallest`` (then no number is written: the colour and the hover tell it)."""
    widest = max((sum(_CHAR_EM.get(c, 0.556) for c in str(t)) for t in texts if t), default=0.0)
    if widest == 0:
        return largest
    px = int(min(largest, 0.85 * cell_px / widest, 0.7 * cell_px))
    return px if px >= smallest else 0


def votes_fitted(result: laav.LaavResult) -> bool:
    """Whether ``result``'s pairwise epipolar votes are fitted (``Coarse.pairwise``): the
    default merge leaves them to be fitted when first read, which the cards that draw them
    do not do on the page's thread (the app has them fitted after the result is shown:
    ``ExplorerState.fit_votes``)."""
    co = result.coarse
    return co is None or co.pairwise.fitted  # (never waits for a fit in progress)


def joint_margins(result: laav.LaavResult) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """What decided each pair of fine models in the joint merge (``coarse_merge="joint"``;
    None for the other merges): (margin, its coding-length part, its epipolar part), each
    (n_fine, n_fine), in nats.

    The margin of fine models j and k is the least score (coding length +
    ``coarse_epipolar_weight`` x epipolar cost) of a compared partition that puts them in two
    motions minus the least of one that puts them in one: > 0, joining them won (the chosen
    partition joins them), < 0, splitting them won. Its parts are the two partitions'
    differences in coding length and in weighted epipolar cost. NaN on the diagonal and where
    every partition compared agrees on the pair (nothing was decided there).

    "Compared": the partitions the shortlist scored, all of them in the explorer (its
    pipelines score the whole shortlist, :func:`explorer.state.explorer_pipeline`). A
    shortlist cut short (``Shortlist.complete`` False, e.g. ``laav.segment``'s) leaves out
    partitions whose coding length alone exceeds the best score: the signs stay right, a
    margin may be larger than over the whole shortlist, and a pair only those partitions
    decide reads as undecided."""
    if not shows_margins(result):
        return None
    sl = result.coarse.shortlist
    a = np.asarray(sl.assign)  # (K, n)
    n = a.shape[1]
    together = a[:, :, None] == a[:, None, :]  # (K, n, n)
    score = np.asarray(sl.score, dtype=float)[:, None, None]
    s_join = np.where(together, score, np.inf)
    s_split = np.where(together, np.inf, score)
    k_join, k_split = s_join.argmin(axis=0), s_split.argmin(axis=0)
    contested = np.isfinite(s_join.min(axis=0)) & np.isfinite(s_split.min(axis=0))
    contested[np.diag_indices(n)] = False
    L = np.asarray(sl.coding_length, dtype=float)
    E = result.params.coarse_epipolar_weight * np.asarray(sl.epipolar_cost, dtype=float)
    part = lambda v: np.where(contested, v[k_split] - v[k_join], np.nan)  # noqa: E731
    return part(L + E), part(L), part(E)


#: A joint-merge margin below this many nats is a close call: card 3 outlines its cell (on the
#: map's log scale it is nearly white, like the pairs nothing decided).
CLOSE_CALL_NATS = 10.0
#: The joint merge's margin map colours ``sign(m) log10(1 + |m|)`` (m in nats): decisions by
#: a few nats and by thousands both read; its colour bar is labelled in nats, at 0 and ±10,
#: ±100, ... up to its ends (:func:`margin_top`, :func:`margin_ticks`).
#: Its palette, 256 colours: dark orange (splitting won) through white to dark blue (joining
#: won), told apart under the common colour blindnesses (the ends of ColorBrewer's Oranges
#: and Blues); :data:`UNDECIDED` where every partition compared agrees.
MARGIN_ANCHORS = ("#7f2704", "#f16913", "#fdd0a2", "#ffffff", "#c6dbef", "#4292c6", "#08306b")
UNDECIDED = "#d9d9d9"


def _ramp(anchors, n: int) -> tuple:
    """``n`` colours evenly through ``anchors`` (hex), interpolated in RGB."""
    rgb = hex_to_rgb(list(anchors)).astype(float)
    t = np.linspace(0.0, len(anchors) - 1.0, n)
    k = np.minimum(t.astype(int), len(anchors) - 2)
    f = (t - k)[:, None]
    out = np.rint(rgb[k] * (1 - f) + rgb[k + 1] * f).astype(int)
    return tuple(f"#{r:02x}{g:02x}{b:02x}" for r, g, b in out.tolist())


MARGIN_PALETTE = _ramp(MARGIN_ANCHORS, 256)


def signed_log(m: np.ndarray) -> np.ndarray:
    """``sign(m) log10(1 + |m|)``: the margin map's colour value."""
    m = np.asarray(m, dtype=float)
    return np.sign(m) * np.log10(1.0 + np.abs(m))


def shows_margins(result: laav.LaavResult) -> bool:
    """Whether card 3's map is the joint merge's decision margins (:func:`joint_margins`:
    the joint merge compared partitions), else the affinity Z."""
    return getattr(result.coarse, "shortlist", None) is not None


def margin_ticks(top: float) -> tuple[list, list]:
    """The margin map's colour-bar ticks within ``[-top, top]`` (colour values,
    :func:`signed_log`), 0 and ±10, ±100, ... nats, and their labels in nats."""
    decades = [10 ** k for k in range(1, 16) if signed_log(10 ** k) <= top + 1e-9]
    ticks = [-t for t in reversed(decades)] + [0] + decades
    return [float(signed_log(t)) for t in ticks], [f"{t:+d}" if t else "0" for t in ticks]


def margin_top(z) -> float:
    """The margin map's colour range ``[-top, top]`` for colour values ``z``
    (:func:`signed_log`): that of the first of 10, 100, 1000, ... nats that no value
    passes, so the colour bar ends at a labelled tick and no value lies beyond it (ending
    at the largest value, it ended past its last label: ±100 on a map of ±991)."""
    z = np.asarray(z, dtype=float)
    z = z[np.isfinite(z)]  # (an infinite margin has no decade: the bar ends at the finite ones')
    big = min(float(np.max(np.abs(z))), 300.0) if z.size else 0.0
    nats = 10.0 ** big - 1.0  # (signed_log undone)
    decade = 10.0 ** max(1, math.ceil(math.log10(nats) - 1e-9)) if nats > 10 else 10.0
    return float(signed_log(decade))


def margin_text(m: float) -> str:
    """A margin (nats) as written in its cell, in four characters below 100,000 nats:
    ``991``, ``-38``, ``1.2k``, ``-12k`` (``-100k`` beyond; the sign of a negative one only:
    the colour tells it too, and the hover gives it exactly); "" for NaN."""
    if not np.isfinite(m):
        return ""
    a, sign = abs(m), "-" if round(m) < 0 else ""
    if round(a) < 1000:
        return f"{sign}{a:.0f}"
    if a < 9950:
        return f"{sign}{a / 1000:.1f}k"
    return f"{sign}{a / 1000:.0f}k"


def close_calls(cells: dict) -> np.ndarray:
    """Which cells of :func:`z_sources` (``cells``, with the joint merge's margins ``m``) are
    close calls: a pair of two fine models decided by less than :data:`CLOSE_CALL_NATS`
    (bool, one per cell; none where ``m`` is NaN: Z shown, or nothing decided there)."""
    m = np.asarray(cells["m"], dtype=float)
    pair = np.asarray(cells["x"]) != np.asarray(cells["y"])
    with np.errstate(invalid="ignore"):
        return np.isfinite(m) & (np.abs(m) < CLOSE_CALL_NATS) & pair


def z_sources(result: laav.LaavResult, seq: laav.Sequence | None = None,
              fit_votes: bool = True) -> tuple[dict, list]:
    """Heat-map cells of card 3 (n_fine x n_fine) and the axis factors. ``z``, the colour:
    the affinity Z of the paper's epipolar merge and of the coding merge, or for the joint
    merge (which builds no Z) its decision margins (:func:`joint_margins`, ``m``, with the
    coding-length part ``ml`` and the epipolar part ``me``; ``z`` is :func:`signed_log` of
    ``m``, NaN where the partitions compared agree); ``d`` the pair's epipolar distance, ``g``
    the coding length merging it adds (nats per point).

    Factors read ``f3→M1``: fine model 3 merged into motion 1 (motions numbered like the
    coarse colours when ``seq`` has ground truth). Without ``fit_votes``, ``d`` is NaN while
    the votes are not fitted (:func:`votes_fitted`)."""
    Z = np.asarray(result.coarse.affinity, dtype=float)
    n = Z.shape[0]
    margins = joint_margins(result) if n else None
    if margins is None:
        m = ml = me = np.full((n, n), np.nan)
        shown, text = Z, [f"{v:.2f}" for v in Z.ravel()]
        dark = Z.ravel() > 0.55
    else:
        m, ml, me = margins
        shown = signed_log(m)
        text = [margin_text(v) for v in m.ravel()]
        dark = np.nan_to_num(np.abs(shown.ravel()), nan=0.0) > 0.55 * margin_top(shown)
    f2c = np.asarray(result.coarse.fine_to_coarse, dtype=np.int64)
    if seq is not None and n:
        f2c = fine_motions(seq, result)  # name motions like the aligned coarse labels
    factors = [f"f{j + 1}→M{int(m) + 1}" for j, m in enumerate(f2c.tolist())]
    jj, kk = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    jj, kk = jj.ravel(), kk.ravel()
    fac = np.asarray(factors, dtype=object)
    data = {"x": fac[kk] if n else np.zeros(0, object), "y": fac[jj] if n else np.zeros(0, object),
            # the values written in the cells up to Z_TEXT_MAX models (beyond, they overlap:
            # the colour and the hover tell them)
            "z": shown.ravel(), "text": np.array([t if n <= Z_TEXT_MAX else "" for t in text], dtype=object),
            "text_color": np.where(dark, "white", "black"),
            "m": m.ravel(), "ml": ml.ravel(), "me": me.ravel(),
            "d": (np.asarray(result.coarse.epipolar_distance, float).ravel()
                  if fit_votes or votes_fitted(result) else np.full(n * n, np.nan)),
            "g": (np.zeros(n * n) if result.coarse.merge_cost is None
                  else np.asarray(result.coarse.merge_cost, float).ravel()),
            "j": jj + 1, "k": kk + 1}
    return data, factors


def merge_table(seq: laav.Sequence, result: laav.LaavResult) -> str:
    """Markdown table: each fine model, its atoms and points, the motion it joined and, with
    ground truth, the true motion most of its points belong to (and what share of them)."""
    f2c = np.asarray(result.coarse.fine_to_coarse, dtype=np.int64)
    fine = np.asarray(result.coarse.fine_point_labels)
    atom_lab = np.asarray(result.multicut.atom_labels)
    factors = z_sources(result, seq, fit_votes=False)[1]
    gt = seq.labels
    truth = gt is not None
    head = "| fine model | atoms | points | merged into |" + (" true motion |" if truth else "")
    rows = [head, "|---|---|---|---|" + ("---|" if truth else "")]
    for j in range(f2c.size):
        motion = factors[j].split("→")[1]
        row = f"| f{j + 1} | {int((atom_lab == j).sum())} | {int((fine == j).sum())} | motion {motion[1:]} |"
        if truth:
            sel = fine == j
            if sel.any():
                counts = np.bincount(np.asarray(gt)[sel])
                m = int(counts.argmax())
                share = 100.0 * counts[m] / sel.sum()
                agree = "" if m == int(motion[1:]) - 1 else " ✗"
                row += f" motion {m + 1} ({share:.0f} %){agree} |"
            else:
                row += " – |"
        rows.append(row)
    if f2c.size == 0:
        rows.append("| – | 0 | 0 | (no atoms formed) |" + (" – |" if truth else ""))
    return "\n".join(rows)


def shortlist_table(seq: laav.Sequence, result: laav.LaavResult, rows: int = 5) -> str:
    """Markdown table of the joint merge's shortlist (``coarse_merge="joint"``): the first
    ``rows`` partitions by score, each as its groups of fine models, with its coding length,
    epipolar cost and score (and, with ground truth, its error on the points in atoms);
    "" for the other merges."""
    sl = getattr(result.coarse, "shortlist", None)
    if sl is None:
        return ""
    w = result.params.coarse_epipolar_weight
    fine = np.asarray(result.coarse.fine_point_labels)
    cov = fine >= 0
    truth = seq.labels is not None
    head = ("| partition (fine models per motion) | coding length | epipolar cost | "
            f"score = L + {w:g} E |" + (" error on atom points |" if truth else ""))
    out = [head, "|---|---|---|---|" + ("---|" if truth else "")]
    best = sl.score.min()
    for i in np.argsort(sl.score, kind="stable")[:rows]:
        a = np.asarray(sl.assign[i])
        groups = " / ".join(",".join(f"f{j + 1}" for j in np.flatnonzero(a == c))
                            for c in range(int(a.max()) + 1))
        mark = " **← chosen**" if i == sl.chosen else f" (+{sl.score[i] - best:.1f})"
        row = (f"| {groups}{mark} | {sl.coding_length[i]:.1f} | {sl.epipolar_cost[i]:.1f} | "
               f"{sl.score[i]:.1f} |")
        if truth:
            err = laav.misclassification_rate(np.asarray(seq.labels)[cov], a[fine[cov]])
            row += f" {100 * err:.1f} % |"
        out.append(row)
    return "\n".join(out)


def _clip_lines(lines: np.ndarray, extent) -> tuple[np.ndarray, ...]:
    """End points of the lines ``a x + b y + c = 0`` across the box ``extent``."""
    x0, x1, y0, y1 = extent
    a, b, c = lines[:, 0], lines[:, 1], lines[:, 2]
    steep = np.abs(b) < np.abs(a)
    with np.errstate(divide="ignore", invalid="ignore"):
        # mostly horizontal: intersect x = x0 and x = x1
        ya = -(a * x0 + c) / b
        yb = -(a * x1 + c) / b
        # mostly vertical: intersect y = y0 and y = y1
        xa = -(b * y0 + c) / a
        xb = -(b * y1 + c) / a
    X0 = np.where(steep, xa, x0)
    Y0 = np.where(steep, y0, ya)
    X1 = np.where(steep, xb, x1)
    Y1 = np.where(steep, y1, yb)
    return X0, Y0, X1, Y1


def _pair_points(seq: laav.Sequence, result: laav.LaavResult, j: int, k: int, fl: int,
                 fr: int) -> tuple:
    """Fine models ``j`` and ``k``'s points seen in frames ``fl`` and ``fr``: (fine labels
    (P,), their indices, seen in both (P,) bool, the two models' colours, the frame-``fl``
    and frame-``fr`` sources (x, y, color, model))."""
    fine = np.asarray(result.coarse.fine_point_labels)
    both = visible_at(seq, fl) & visible_at(seq, fr)  # missing data: only points seen in both frames
    idx = np.flatnonzero(((fine == j) | (fine == k)) & both)
    fc = fine_colors(seq, result)
    cj, ck = fc[j], fc[k]
    cols = np.where(fine[idx] == j, cj, ck).astype("U7")
    model = np.where(fine[idx] == j, f"fine model f{j + 1}", f"fine model f{k + 1}").astype(object)
    # each model with the marker of the motion it joined, numbered as card 1 numbers it
    mot = fine_motions(seq, result)
    mj, mk = (motion_marker(mot[m]) if 0 <= m < mot.size else MOTION_MARKERS[0] for m in (j, k))
    marker = np.where(fine[idx] == j, mj, mk).astype(object)
    pts = seq.points
    return (fine, idx, both, (cj, ck),
            {"x": pts[fl, idx, 0], "y": pts[fl, idx, 1], "color": cols, "model": model, "marker": marker},
            {"x": pts[fr, idx, 0], "y": pts[fr, idx, 1], "color": cols, "model": model, "marker": marker})


def epipolar_sources(seq: laav.Sequence, result: laav.LaavResult, j: int, k: int,
                     max_lines: int = 30, rng_seed: int = 0, fit_votes: bool = True) -> dict:
    """Epipolar check of fine models ``j`` and ``k`` with a fundamental matrix the merge
    itself used: the pair's sample of median distance (``Coarse.vote_samples``).

    Keys: ``left`` and ``right`` (x, y, color, model, marker: the two models' points in the
    sample's frame l and frame r, each with the marker of the motion it joined),
    ``sample_left`` / ``sample_right`` (x, y: the features
    the F was fitted on), ``lines`` (x0, y0, x1, y1, color: epipolar lines in frame r of
    the sample's features and of up to ``max_lines`` other points of the two models; on
    incomplete data only points seen in both frames l and r),
    ``frames`` (l, r), ``distance`` (``Coarse.epipolar_distance[j, k]``, mean over every
    sample), ``sample_distance`` (this sample's: the larger of the two models' mean Sampson
    distances over its features, px^2), ``sample_vote`` (``exp(-lam sample_distance)``),
    ``pairwise`` / ``coassociation`` / ``affinity`` (the terms of Z for the pair),
    ``n_samples``, ``residual`` (mean distance in px of the drawn frame-r points to their
    lines; ``residual_j`` / ``residual_k`` per model), ``ok`` (False for j == k — a model
    is never voted against itself — or when the pair has no sample), ``pending`` (without
    ``fit_votes``: the votes are not fitted yet, :func:`votes_fitted`; only ``left`` and
    ``right`` are drawn then, in the first and last frames).
    """
    co = result.coarse
    n = np.asarray(co.fine_to_coarse).size
    e = np.zeros(0)
    empty = {"x": e, "y": e, "color": np.zeros(0, "U7"), "model": np.zeros(0, object),
             "marker": np.zeros(0, object)}
    nan = float("nan")
    blank = {"left": empty, "right": empty, "sample_left": {"x": e, "y": e},
             "sample_right": {"x": e, "y": e},
             "lines": {"x0": e, "y0": e, "x1": e, "y1": e, "color": np.zeros(0, "U7")},
             "frames": (0, seq.n_frames - 1), "distance": nan, "sample_distance": nan,
             "sample_vote": nan, "pairwise": nan, "coassociation": nan, "affinity": nan,
             "n_samples": 0, "residual": nan, "residual_j": nan, "residual_k": nan,
             "ok": False, "pending": False}
    pair = 0 <= j < n and 0 <= k < n and j != k
    n_samples = int(len(co.frame_pairs) * result.params.coarse_samples)  # behind every pair's vote
    if not fit_votes and not votes_fitted(result):
        # the pair's points already, in the first and last frames: the plots, their legends
        # and so the page keep their size until the votes arrive (no relayout meanwhile)
        if not pair:
            return dict(blank, pending=True)
        *_, left, right = _pair_points(seq, result, j, k, *blank["frames"])
        return dict(blank, pending=True, left=left, right=right, n_samples=n_samples)
    vs = co.vote_samples
    if not pair or vs is None:
        return blank
    fl, fr = (int(v) for v in vs.frames[j, k])
    if fl < 0:
        return blank
    fine, idx, both, (cj, ck), left, right = _pair_points(seq, result, j, k, fl, fr)
    pts = seq.points
    F = np.asarray(vs.fundamental[j, k])
    sample = np.asarray(vs.points[j, k])
    half = sample.size // 2
    u = np.unique(sample)
    u = u[both[u]]  # the stage samples only features seen in both frames; never draw others

    def term(a):
        return nan if a is None else float(np.asarray(a)[j, k])

    out = dict(blank, frames=(fl, fr), left=left, right=right,
               sample_left={"x": pts[fl, u, 0], "y": pts[fl, u, 1]},
               sample_right={"x": pts[fr, u, 0], "y": pts[fr, u, 1]},
               distance=term(co.epipolar_distance), sample_distance=float(vs.distance[j, k]),
               # (the λ the merge used: scaled for the noise on noisy tracks, lam_label)
               sample_vote=float(np.exp(-result.run_params.lam * vs.distance[j, k])),
               pairwise=term(co.pairwise_vote), coassociation=term(co.coassociation),
               affinity=term(co.affinity),
               n_samples=n_samples)
    # lines: the sample's own features, then others of both models, the same number each
    rng = np.random.default_rng(rng_seed)
    own_model = np.concatenate([np.full(half, j), np.full(sample.size - half, k)])
    first = {int(f): int(m) for f, m in zip(sample, own_model)}
    pick = [u]
    for m in (j, k):
        cand = np.setdiff1d(idx[fine[idx] == m], u)
        take = min(cand.size, max(0, (max_lines - u.size) // 2))
        pick.append(rng.choice(cand, take, replace=False))
    sel = np.concatenate(pick)
    line_model = np.array([first.get(int(f), fine[f]) for f in sel])
    lines = epipolar_lines(F, pts[fl, sel])
    X0, Y0, X1, Y1 = _clip_lines(lines, seq.extent())
    resid = np.abs(lines[:, 0] * pts[fr, sel, 0] + lines[:, 1] * pts[fr, sel, 1] + lines[:, 2])
    out["lines"] = {"x0": X0, "y0": Y0, "x1": X1, "y1": Y1,
                    "color": np.where(line_model == j, cj, ck).astype("U7")}
    out["residual"] = float(resid.mean()) if resid.size else nan
    in_j = line_model == j
    out["residual_j"] = float(resid[in_j].mean()) if in_j.any() else nan
    out["residual_k"] = float(resid[~in_j].mean()) if (~in_j).any() else nan
    out["ok"] = True
    return out


# ---------------------------------------------------------------------- RV convergence
#: The names of Random Voting's two runs in card 4 and the PNG export: LAAV's own trial (by
#: whether it voted with our subspace term: the two curves then differ in their votes, not
#: only in their start) and plain RV.
RV_OWN_NAMES = {False: "LAAV's informed trial", True: "LAAV's trial + subspace votes (ours)"}
RV_PLAIN_NAME = "plain RV (random start)"


def own_trial_name(voting) -> str:
    """:data:`RV_OWN_NAMES` for LAAV's fine-tuning ``voting`` (a ``laav.Voting`` or None)."""
    return RV_OWN_NAMES[voting is not None and (voting.informed_subspace_weight or 0) > 0]


def rv_sources(voting: laav.Voting | None) -> dict:
    """Per-iteration label changes and vote margin of a :class:`laav.Voting`: for LAAV's
    fine-tuning its own informed trial's (``informed_*``), whichever candidate it returned."""
    if voting is None:
        e = np.zeros(0)
        return {"iteration": e, "changed": e, "changed_plot": e, "margin": e}
    own = voting.informed_changed is not None
    ch = np.asarray(voting.informed_changed if own else voting.changed, dtype=float)
    it = np.arange(1, ch.size + 1)
    # changes are drawn on a log axis: show 0 as 0.5 (below the "1" tick)
    return {"iteration": it, "changed": ch, "changed_plot": np.where(ch > 0, ch, 0.5),
            "margin": np.asarray(voting.informed_margin if own else voting.margin, dtype=float)}


def trace_errors(trace: np.ndarray, truth: np.ndarray | None) -> np.ndarray:
    """Per row of a label trace (T, P): the misclassification rate against ``truth`` (P,)
    (the best one-to-one matching of labels, per row: :func:`laav.misclassification_rate`,
    over the points with a true label), or without ``truth`` the share of points whose
    label differs from the last row's (the trial's own end; one trial numbers its labels
    the same way throughout). Every row's confusion matrix is counted at once: calling
    :func:`laav.misclassification_rate` per row took ~10 ms of each result's apply on the
    demo (two traces, 205 rows), this ~1 ms; the explorer's tests check the two agree."""
    trace = np.asarray(trace)
    if trace.size == 0:
        return np.zeros(trace.shape[0])
    if truth is None:
        return (trace != trace[-1]).mean(axis=1)
    truth = np.asarray(truth)
    ok = truth >= 0
    tr, gt = trace[:, ok], truth[ok]
    C, K = int(tr.max()) + 1, int(gt.max()) + 1
    # every row's confusion matrix at once: counts of (row, label, true label), in int32
    # while it fits (the trace is int8: no int64 copy of it)
    idx = np.int32 if tr.shape[0] * C * K < 2**31 else np.int64
    flat = (np.arange(tr.shape[0], dtype=idx)[:, None] * C + tr.astype(idx)) * K + gt.astype(idx)
    counts = np.bincount(flat.ravel(), minlength=tr.shape[0] * C * K).reshape(-1, C, K)
    right = matched_counts(counts)
    return 1.0 - right / max(gt.size, 1)


def rv_error_sources(seq: laav.Sequence, voting: laav.Voting | None) -> dict:
    """Error per iteration of the trial the RV card draws (LAAV's informed trial, whichever
    candidate was returned; plain RV's returned trial): ``iteration`` 0 (the start) to T,
    ``error`` in % (:func:`trace_errors`: against the ground truth, else against the
    trial's own last labels) over the points that voted (``Voting.voted``: all of them, a
    seeded subset above ``rv_max_points`` points, or on incomplete tracks those some voting
    frame pair sees). Empty when no trial ran (the coarse labels returned)."""
    empty = {"iteration": np.zeros(0), "error": np.zeros(0)}
    if voting is None:
        return empty
    own = voting.informed_changed is not None
    trace = voting.informed_label_trace if own else voting.label_trace
    voted = np.arange(seq.n_points) if voting.voted is None else voting.voted
    if trace is None or trace.ndim != 2 or trace.shape[1] != voted.size:
        return empty
    truth = None if seq.labels is None else np.asarray(seq.labels)[voted]
    return {"iteration": np.arange(trace.shape[0]), "error": 100.0 * trace_errors(trace, truth)}


def _rv_line(voting: laav.Voting | None, what: str) -> str:
    if voting is None:
        return f"**{what}:** computing…"
    if np.shape(voting.votes)[-1:] == (1,) and voting.n_iterations == 0:
        # C = 1: no trial ran (it said "0 iterations, converged" before)
        return f"**{what}:** C = 1, every point in the one motion: nothing to vote on, no trial ran."
    per = [int(t) for t in voting.trial_iterations]
    own = voting.informed_changed is not None  # LAAV: describe its own informed trial
    done = voting.informed_converged if own else voting.converged
    n_it = len(voting.informed_changed) if own else len(voting.changed)
    conv = ("converged (no label changed for the patience window)" if done
            else "**not converged** (hit the iteration cap)")
    trials = ""
    if voting.n_trials > 1:
        if per and len(set(per)) == 1:
            trials = f"; {voting.n_trials} trials of {per[0]} iterations each"
        else:
            shown = ", ".join(map(str, per[:6])) + (", …" if len(per) > 6 else "")
            trials = f"; {voting.n_trials} trials ({shown} iterations)"
        if own:  # LAAV's: its informed trial, then the others it was compared with (ours)
            trials += ": the informed one first, then " + other_trials(voting)
    if own and voting.skipped_starts:  # ours: starts whose trials did not run, and why
        n = len(voting.skipped_starts)
        trials += (f"; {n} missing-motion start{'s' if n > 1 else ''} skipped: the informed "
                   "trial's labels already explain the points "
                   f"{'each' if n > 1 else 'it'} would make a motion (ours, `rv_missing_gate`)")
    moved = [f"refinement {voting.refined}"] if voting.refined else []
    if voting.unpolished:  # ours: the trial's own labels descended lower than the polished
        moved.append(f"the descent on the joint score from the trial's own labels "
                     f"{voting.descended}")
        if voting.reassigned:  # above rv_max_points: the reassignment over every point, after
            moved.append(f"then the reassignment over every point {voting.reassigned}")
    else:
        if voting.reassigned:
            moved.append(f"joint reassignment {voting.reassigned}")
        if voting.descended:  # ours: single moves down the selection's own score
            moved.append(f"the descent on the joint score (ours, `rv_descent`) {voting.descended}")
    extra = f"; points moved by {' and '.join(moved)}" if moved else ""
    if voting.unpolished:
        extra += ("; **the refinement and reassignment were dropped**: the trial's own labels, "
                  "descended, scored lower (ours, `rv_descent_from_trial`)")
    returned = ""
    if voting.initialised and voting.selected.startswith("missing motion"):
        # LAAV's own trial, from another start of ours: say which, and why
        start, _, k = voting.selected.partition(", trial ")
        several = k or any(n.startswith(start + ", trial ") for n in (voting.costs or {}))
        which = f"trial {k or 1} (of `rv_missing_trials`)" if several else "trial"
        returned = (f"; **returned the {which} from the {md_text(start)} start, not the "
                    "coarse labels' trial** (ours, not in the paper: two coarse motions as one, "
                    "the points in no atom that no motion explains as the C-th); its coding "
                    f"length + epipolar cost was lower; {voting.n_iterations} voting iterations "
                    f"in all, the coarse labels' trial {per[0] if per else 0}")
    elif voting.initialised and voting.selected == "coarse":
        # LAAV's own coarse labels, not voted on: say so, and why
        returned = ("; **returned LAAV's coarse labels, not its informed trial** (the points in no "
                    "atom placed by the coarse motions' subspaces and epipolar fits, no voting): "
                    "the model selection (ours, not in the paper) preferred them, Random Voting "
                    f"having moved away from them; {voting.n_iterations} voting iterations in "
                    f"all, LAAV's informed trial {per[0] if per else 0}")
    elif voting.initialised and voting.selected != "informed":
        # the labels shown are not LAAV's own trial: say whose they are, and why
        returned = (f"; **returned {md_text(voting.selected)}, not LAAV's informed trial**: the model "
                    f"selection (ours, not in the paper) preferred it; {voting.n_iterations} voting "
                    f"iterations in all, LAAV's informed trial {per[0] if per else 0}")
    returned += _vetoed_words(voting.vetoed)
    return (f"**{what}:** {n_it} iterations, {conv}{_votes(voting)}{trials}{extra}{returned}"
            f"{_selection(voting)}.")


def _vetoed_words(vetoed: tuple) -> str:
    """``Voting.vetoed`` (ours, ``rv_outlier_veto``) for the RV card: the missing-motion
    candidates passed over and the descents not kept, each with its cost and that of what it
    would have replaced over the points both explain, and the reason once; "" when nothing
    was vetoed."""
    parts = []
    starts = [v for v in vetoed if v[0].startswith("missing motion")]
    if starts:
        each = "; ".join(f"{md_text(kind)}: {its:,.0f} against {kept:,.0f} over {n} points"
                         for kind, n, kept, its in starts)
        parts.append(f"**passed over {len(starts)} missing-motion candidate"
                     f"{'s' if len(starts) > 1 else ''}** ({each}; LAAV's informed trial's cost second)")
    for kind, n, kept, its in vetoed:
        if not kind.startswith("missing motion"):
            before, lost = (("the labels before the descent", "its result") if kind == "the descent"
                            else ("the polished labels", md_text(kind)))
            parts.append(f"**kept {before}, not {lost}** ({its:,.0f} against {kept:,.0f} over "
                         f"{n} points)")
    if not parts:
        return ""
    return ("; " + "; ".join(parts) + ": each scored lower over all points than what it would have "
            "replaced but higher over the points both explain, so the points neither explains, "
            "outlier tracks, would have bought a motion (ours, `rv_outlier_veto`)")


def other_trial_counts(voting: laav.Voting) -> tuple[int, int]:
    """What LAAV's fine-tuning ran beside its informed trial (ours, not the paper's), from
    the candidates' names (``Voting.costs``): (trials from missing-motion starts, the default
    on complete tracks; plain RV's trials, ``with_plain_rv()`` and the default on incomplete
    tracks)."""
    missing = sum(str(n).startswith("missing motion") for n in (voting.costs or {}))
    return missing, max(0, int(voting.n_trials) - 1 - missing)


def other_trials(voting: laav.Voting) -> str:
    """:func:`other_trial_counts` in words ("" when nothing else ran)."""
    missing, plain = other_trial_counts(voting)
    parts = ([f"{missing} from starts that look for a missed motion"] if missing else []) + (
        [f"{plain} of plain RV from random starts, compared with it"] if plain else [])
    return " and ".join(parts) + " (ours)" if parts else ""


def _votes(voting: laav.Voting) -> str:
    """How LAAV's informed trial voted: the RV paper's epipolar votes, or ours with the
    subspace term (a departure from the paper, named as such)."""
    w = voting.informed_subspace_weight
    if w is None:
        return ""
    if w > 0:
        return (f"; votes: Sampson distance + {w:g} × squared distance to the group's rank-4 "
                "trajectory subspace (ours, `rv_subspace_weight`; the paper: Sampson alone)")
    return "; votes: Sampson distance alone (the RV paper's)"


#: What the model selection scored candidates by (``Voting.score``), in words.
_SCORES = {"joint": "coding length + epipolar cost per point, + disagreement with the others",
           "subspace": "trajectory-subspace cost, + disagreement with the others",
           "joint-sum": "coding length + epipolar cost of the whole labelling",
           "joint-cleaned": ("coding length + epipolar cost of the whole labelling, each after its "
                             "best moves of a few points (`rv_select_descent`)")}


#: The unit of each score (``Voting.score``): whole labellings in nats (the default's own
#: candidates), or nats per point plus the agreement term (plain RV's trials, and LAAV's
#: with ``with_plain_rv()``): the numbers of two lines need not be on one scale.
_SCORE_UNITS = {"joint": " per point", "joint-sum": " nats", "joint-cleaned": " nats"}


def _selection(voting: laav.Voting) -> str:
    """Which candidate labelling the selection kept, and the candidates' scores.

    Only the public ``selected`` (a name, shown as text whatever it is), ``costs``
    (name -> score), ``score`` (what scored them; ``"joint-cleaned"``: each candidate after
    its cleaning) and ``descended`` (the kept labels moved after scoring) are read; the
    name kept need not be among the scored candidates, and nothing assumes how the
    algorithm chose (e.g. the lowest score).
    """
    costs = dict(voting.costs or {})
    kept = voting.selected
    if len(costs) < 2:
        return ""
    name = md_text(kept) if kept else "(unnamed)"
    unit = _SCORE_UNITS.get(voting.score, "")
    score = f" (score {float(costs[kept]):.2f}{unit})" if kept in costs else ""
    if score and voting.score == "joint-cleaned":  # scored after a few moves of its own
        score = score[:-1] + ", after its cleaning" + (
            "; the labels returned: its trial's own labels after the full descent, unpolished)"
            if voting.unpolished else
            "; the labels returned: the candidate after the full descent)" if voting.descended else ")")
    elif score and voting.descended:  # the labels returned moved after scoring
        score = score[:-1] + ", before the descent on the joint score)"
    by = _SCORES.get(voting.score, "")
    by = f"; scored by {by} (ours)" if by else ""
    others = [(k, v) for k, v in costs.items() if k != kept]
    if len(others) <= 2:
        listed = ", ".join(f"{md_text(k)} {float(v):.2f}{unit}" for k, v in others)
        return f"; kept the *{name}* labelling{score}; other candidates: {listed}{by}"
    return f"; kept *{name}*{score} of {len(costs)} scored candidates{by}"


#: The Random Voting card's line under a preview (:attr:`ExplorerState.on_preview`).
PREVIEW_NOTE = ("*LAAV's own trial, shown first: plain RV's runs and the model selection (ours) "
                "are still computing, and may replace these labels.*")
#: ... under a preview of LAAV's own chain (``rv_select="laav"``): the informed trial alone,
#: while the missing-motion starts its result leaves unexplained run (``rv_missing_gate``).
PREVIEW_NOTE_OWN = ("*LAAV's informed trial, shown first: the trials for a missed motion (ours) "
                    "are still computing (its result leaves some motion's points unexplained, or "
                    "the trial did not settle), and may replace these labels.*")


def own_chain_preview(result: laav.LaavResult) -> bool:
    """Whether a preview of ``result`` is LAAV's own chain's (``rv_select="laav"``: its trials
    for a missed motion still to come) rather than the informed trial before plain RV's runs
    (:meth:`laav.Pipeline.update`'s ``preview``)."""
    return result.params.rv_select == "laav"


def preview_note(own: bool) -> str:
    """The line a card shows above a preview: :data:`PREVIEW_NOTE_OWN` for LAAV's own chain
    (``own``, :func:`own_chain_preview`), else :data:`PREVIEW_NOTE`."""
    return PREVIEW_NOTE_OWN if own else PREVIEW_NOTE


def rv_summary(fine_tuning: laav.Voting | None, plain: laav.Voting | None,
               pending: bool = False, truth: np.ndarray | None = None, own: bool = False) -> str:
    """Markdown: LAAV's fine-tuning beside plain RV, with their iteration counts, and
    whether they end at the same segmentation (:func:`rv_verdict`; ``truth``: the
    sequence's ground truth, or None); ``pending``: ``fine_tuning`` is a preview
    (:data:`PREVIEW_NOTE`; with ``own``, LAAV's own chain's: :data:`PREVIEW_NOTE_OWN`)."""
    verdict = None if pending else rv_verdict(fine_tuning, plain, truth)
    return (_rv_line(fine_tuning, "LAAV fine-tuning (RV started from the coarse labels)") + "  \n"
            + (preview_note(own) + "  \n" if pending else "")
            + _rv_line(plain, "Plain RV (random starts; the same sequence, RV settings and polish, "
                              "ours)") + "  \n"
            + (verdict + "  \n" if verdict else "")
            + RV_ERROR_NOTE)


#: Final labellings apart on at most this share of the points count as the same segmentation
#: in the RV card (a few boundary points).
SAME_SEGMENTATION = 0.01


def rv_verdict(fine_tuning: laav.Voting | None, plain: laav.Voting | None,
               truth: np.ndarray | None = None) -> str | None:
    """Whether LAAV's final labels and plain RV's are the same segmentation (None until both
    are there). When they are not, it says that converging is not being right: which run
    converged tells how it voted, not which labelling is wrong (a trial from a wrong start
    can settle, one from the right labels can still be moving at the iteration cap); the
    ground truth's errors when there is one, else where to look."""
    if fine_tuning is None or plain is None:
        return None
    a, b = np.asarray(fine_tuning.labels), np.asarray(plain.labels)
    if a.shape != b.shape or a.size == 0:
        return None
    differ = plain_differs(a, b)
    n, d = int(differ.sum()), float(differ.mean())
    if d <= SAME_SEGMENTATION:
        return (f"**Both end at the same segmentation**: their final labels differ on {n} of the "
                f"{a.size} points.")
    text = (f"**The two end apart: their final labels differ on {n} of the {a.size} points "
            f"({_pct(d)})**")
    lesson = ". Converging means the labels stopped changing, not that they are right"
    if truth is not None and np.shape(truth) == a.shape:
        e_a, e_b = laav.misclassification_rate(truth, a), laav.misclassification_rate(truth, b)
        own_conv = fine_tuning.converged  # (the kept candidate's trial: its labels are scored)
        # the lesson only where this run teaches it: the run that settled is the worse one
        misleads = (own_conv and not plain.converged and e_a > e_b) or (
            plain.converged and not own_conv and e_b > e_a)
        return (text + (lesson if misleads else "")
                + f": against the ground truth, LAAV is {_pct(e_a)} wrong, plain RV {_pct(e_b)}.")
    return text + lesson + (f"; without a ground truth, colour points by *{COLOR_LABELS['vs_plain']}* "
                            "to see where they differ, and judge which motion those points follow.")


#: What the RV card's error chart draws.
RV_ERROR_NOTE = ("*Error per iteration:* each trial's own voting labels, iteration 0 its start "
                 "(LAAV's informed trial: the coarse labels, each labelled point starting with extra "
                 "votes for its label, the paper's additional weight, `rv_label_weight`; the points "
                 "in no atom at random. Plain RV: the trial it returned, or the last of its trials "
                 "when it returned their consensus; every point at random at the start; its votes "
                 "are reset once, at iteration 15, as the RV paper does, hence its jump there), "
                 "before the refinement, reassignment and descent that give the final labels. "
                 "Without ground truth: the share of points not yet at the trial's last labels.")


# ---------------------------------------------------------------------- numbers
def _many_to_one_error(gt: np.ndarray, pred: np.ndarray) -> float:
    """Error when each predicted group counts as the true motion most of its points have
    (over-segmentation is not an error)."""
    counts, _, _ = laav.confusion_matrix(gt, pred)
    return 1.0 - counts.max(axis=0).sum() / max(gt.size, 1)


def stage_numbers(seq: laav.Sequence, result: laav.LaavResult, plain: laav.Voting | None = None) -> dict:
    """Scores and counts of one result.

    ``error_fine`` / ``error_coarse`` are measured on the points inside atoms only
    (``coverage`` of them); ``error_final`` on all points; ``error_plain``: plain RV from a
    random start (``plain``, with the same sequence, C, seed and RV settings) on all points.
    Errors are None without ground truth (``error_plain`` also before plain RV is given).
    ``error_plain_trial``: the RV paper's own result, plain RV's settled trial's labels before
    our polish, on the points that voted (None when no trial settled).
    ``plain_iterations`` / ``plain_converged`` describe that run; ``plain_disagreement``: the
    share of points LAAV's final labels and plain RV's label differently, motions matched one
    to one (:func:`labelling_distance`), with or without ground truth: on tracks without one
    it is the page's main check of the result. ``timings_ms`` per stage,
    ``total_ms``. ``n_unlabelled``: points the final stage left unlabelled (-1, seen too
    briefly; missing data only), counted as errors in ``error_final`` as
    :func:`laav.misclassification_rate` does; ``visible_share`` of the sequence's entries.
    ``noise_sigma`` (px, None without ``noise_adaptive``), ``noise_changes``: the
    fields the noise-adaptive scales changed, ``{name: (set, ran with)}`` (empty on clean
    tracks), and ``noise_k``, the threshold factor k of ``k σ̂``.
    """
    gt = seq.labels
    st = result.stage_labels()
    covered = np.asarray(st["coarse"]) >= 0
    out = {
        "n_points": seq.n_points, "n_frames": seq.n_frames, "n_motions": result.n_motions,
        "n_atoms": int(result.atoms.n_atoms), "coverage": float(result.atoms.coverage),
        "n_covered": int(covered.sum()), "n_unassigned": int(np.asarray(result.atoms.unassigned).size),
        "n_edges": int(result.graph.n_edges), "n_fine": int(result.multicut.n_models),
        "n_unlabelled": int(np.count_nonzero(result.unlabelled_code)),
        "visible_share": float(seq.visible_share),
        "error_fine": None, "error_coarse": None, "error_final": None,
        "timings_ms": {k: 1000.0 * float(v) for k, v in result.timings.items()},
    }
    out["total_ms"] = float(sum(out["timings_ms"].values()))
    if gt is not None:
        if covered.any():
            out["error_fine"] = _many_to_one_error(gt[covered], np.asarray(st["fine"])[covered])
            out["error_coarse"] = float(laav.misclassification_rate(gt[covered],
                                                                    np.asarray(st["coarse"])[covered]))
        out["error_final"] = float(laav.misclassification_rate(gt, np.asarray(st["final"])))
    out.update(_noise_numbers(result))
    out["error_plain"] = None
    out["plain_iterations"] = None if plain is None else len(plain.changed)
    out["plain_converged"] = None if plain is None else bool(plain.converged)
    out["plain_disagreement"] = None if plain is None else labelling_distance(st["final"], plain.labels)
    out["error_plain_trial"] = None
    if gt is not None and plain is not None:
        out["error_plain"] = float(laav.misclassification_rate(gt, np.asarray(plain.labels)))
        if plain.converged:  # the RV paper's result: the settled trial's own labels, unpolished
            own = rv_error_sources(seq, plain)["error"]
            out["error_plain_trial"] = float(own[-1]) / 100 if own.size else None
    return out


def lam_label(result: laav.LaavResult) -> str:
    """``λ = ...`` as the stages ran it: with ``noise_adaptive`` on noisy tracks the λ set is
    scaled for the measured noise (:attr:`laav.LaavResult.run_params`), and card 3's merge
    used the scaled one: ``λ = 0.755 (noise-scaled)`` (the numbers card names the λ set)."""
    ran = result.run_params.lam
    return f"λ = {ran:g}" if ran == result.params.lam else f"λ = {ran:.3g} (noise-scaled)"


def _noise_numbers(result: laav.LaavResult) -> dict:
    """The measured pixel noise and what ``noise_adaptive`` changed for it (stage_numbers)."""
    if result.noise_sigma is None:
        return {"noise_sigma": None, "noise_changes": {}}
    set_, ran = result.params.to_dict(), result.run_params.to_dict()
    changes = {k: (v, ran[k]) for k, v in set_.items() if k != "noise_adaptive" and ran[k] != v}
    return {"noise_sigma": float(result.noise_sigma), "noise_changes": changes,
            "noise_k": threshold_factor(result.params.atom_frames)}


def noise_line(num: dict) -> str | None:
    """One sentence on the measured pixel noise and the scales it set (None when not
    measured, ``noise_adaptive`` off)."""
    sigma = num.get("noise_sigma")
    if sigma is None:
        return None
    ch = num.get("noise_changes") or {}
    if not ch:
        return (f"σ̂ = {sigma:.2f} px measured; thresholds as set "
                f"({num.get('noise_k', 3.35):.2f} σ̂ ≤ affine_threshold, `noise_adaptive`)")
    parts = ", ".join(f"{k} {a:g} → {b:.3g}" for k, (a, b) in ch.items())
    return f"σ̂ = {sigma:.2f} px measured; **scales widened for the noise**: {parts} (`noise_adaptive`)"


def _pct(v) -> str:
    return "–" if v is None else f"{100 * v:.1f} %"


def _ms(t: dict, stage: str) -> str:
    """A stage time for display; a stage reused from the previous run (0 s) reads "reused"."""
    v = float(t.get(stage, 0.0))
    return "reused" if v == 0 else f"{v:.0f} ms"


def _plain_trial_note(num: dict) -> str:
    """The RV paper's own result beside plain RV's polished one (the Numbers card): the
    settled trial's labels before our refinement, reassignment and selection ("" when no
    trial settled: the labels are then our consensus of them, or without ground truth)."""
    e = num.get("error_plain_trial")
    return "" if e is None else f"; its settled trial's own labels, the RV paper's result: {_pct(e)}"


def _plain_result(num: dict) -> str:
    it = num.get("plain_iterations")
    if it is None:
        return "computing…"
    return f"{it} iterations, " + ("converged" if num.get("plain_converged") else "hit the iteration cap")


def _warns(num: dict) -> bool:
    """No ground truth, and LAAV and plain RV apart on more than :data:`DISAGREEMENT_WARN`."""
    d = num.get("plain_disagreement")
    return d is not None and d > DISAGREEMENT_WARN and num.get("error_final") is None


def _share_count(num: dict) -> int:
    """The points behind ``num``'s ``plain_disagreement`` (a share of ``n_points``)."""
    return int(round(num["plain_disagreement"] * num["n_points"]))


def disagreement_line(num: dict) -> str | None:
    """One sentence on how far LAAV's final labels and plain RV's differ (None before plain
    RV is computed); above :data:`DISAGREEMENT_WARN` of the points, without ground truth, a
    hint where to look (:func:`disagreement_warning` is the status line's short form)."""
    d = num.get("plain_disagreement")
    if d is None:
        return None
    n = _share_count(num)
    text = (f"They label {n} of the {num['n_points']} points differently ({_pct(d)}; motions "
            f"matched one to one, both with C = {num['n_motions']}, so it says nothing of C itself)")
    if _warns(num):
        text += (". Without a ground truth this is a warning sign: at least one of the two is wrong "
                 f"on {_pct(d / 2)} or more of the points. Compare them: colour points by "
                 f"*{COLOR_LABELS['vs_plain']}* (orange where they differ) or by *{COLOR_LABELS['plain']}*")
    return text


def disagreement_warning(num: dict) -> str | None:
    """The status line's warning when LAAV and plain RV disagree on more than
    :data:`DISAGREEMENT_WARN` of the points of a sequence without ground truth (None
    otherwise, and before plain RV is computed)."""
    if not _warns(num):
        return None
    d, n = num["plain_disagreement"], _share_count(num)
    return (f"**LAAV and plain RV disagree on {_pct(d)} of the points** ({n} of {num['n_points']}). "
            "Without a ground truth this is the sign that at least one of them is wrong here: "
            f"card 5 says more; colouring points by *{COLOR_LABELS['vs_plain']}* shows where they "
            f"differ, by *{COLOR_LABELS['plain']}* plain RV's labels.")


def numbers_markdown(num: dict) -> str:
    """The numbers view as a Markdown table (one row per stage)."""
    t = num["timings_ms"]
    cov = f"{num['n_covered']} of {num['n_points']} points in atoms ({100 * num['coverage']:.0f} %)"
    n_un = int(num.get("n_unlabelled", 0))
    if n_un:
        scored = num["error_final"] is not None
        labelled = (f"{num['n_points'] - n_un} of {num['n_points']} points labelled; **{n_un} "
                    f"{UNSEEN_LABEL}** (label -1{', counted as errors' if scored else ''})")
    else:
        labelled = f"all {num['n_points']} points labelled"
    final_note = ("(all points; unlabelled ones count as errors)" if n_un and num["error_final"] is not None
                  else "(all points)")
    truth = "error vs ground truth" if num["error_final"] is not None else "error (needs a ground truth)"
    rows = [
        f"| stage | result | {truth} | time |",
        "|---|---|---|---|",
        f"| 1 atoms | {num['n_atoms']} atoms; {cov} | – | {_ms(t, 'atoms')} |",
        f"| 2 atom graph | {num['n_edges']} edges | – | {_ms(t, 'graph')} |",
        f"| 2 multicut | {num['n_fine']} fine models | {_pct(num['error_fine'])} "
        f"(points in atoms; a fine model counts as its majority motion) | {_ms(t, 'multicut')} |",
        f"| 3 fine → coarse | {counted(num['n_motions'], 'motion')} | {_pct(num['error_coarse'])} "
        "(points in atoms) | "
        f"{_ms(t, 'coarse')} |",
        f"| 4 Random Voting | {labelled} | **{_pct(num['error_final'])}** "
        f"{final_note} | {_ms(t, 'voting')} |",
        f"| sum of the stages (the status line's time adds the app's own work) | | | "
        f"{num['total_ms']:.0f} ms |",
        f"| *plain RV* (random starts; same C, seed, RV settings and polish) | {_plain_result(num)} | "
        f"{_pct(num.get('error_plain'))} (all points){_plain_trial_note(num)} | |",
    ]
    dis = disagreement_line(num)
    if dis:
        rows.append(f"| *LAAV against plain RV* | {dis} | | |")
    noise = noise_line(num)
    if noise:
        rows.append(f"| *pixel noise* | {noise} | | |")
    share = num.get("visible_share", 1.0)
    if share < 1.0:
        rows.append(f"| *input* | {num['n_points']} tracks x {num['n_frames']} frames, "
                    f"{100 * share:.1f} % of the entries visible (incomplete tracks) | | |")
    return "\n".join(rows)


def labels_table(seq: laav.Sequence, result: laav.LaavResult,
                 point_ids: np.ndarray | None = None) -> str:
    """CSV text, one row per point; labels are 0-based like ``laav segment``'s file.

    Columns: ``point`` (0-based; with ``point_ids`` (P,), the file's number of each point,
    as ``laav segment --complete-only`` writes it), ``label`` (final motion: the same two
    columns as ``laav segment --out``), ``x0``, ``y0`` (position in frame 0; empty when the
    point is not seen there), ``ground_truth`` (empty without), ``owner_atom`` (the atom
    whose R1 core holds it, -1 for none: a point only in atoms' R1-R2 rings, or in no
    atom), ``fine_model``, ``coarse_motion`` (-1: the stage left the point out, i.e. it is
    in no atom), ``atoms`` (how many atoms hold the point; 0: in no atom), ``page_motion``
    (the motion the page's views name the point's final label by, "motion N", 1-based:
    matched to the ground truth's numbering when there is one, so that a right label reads
    as its ``ground_truth`` + 1; empty for a point left unlabelled). New columns come last,
    so that the columns before them keep their places.
    """
    st = result.stage_labels()
    shown = shown_labels(seq, result)["final"]
    owner = np.asarray(result.atoms.owner)
    n_atoms = result.atoms.membership().sum(axis=0)  # (P,)
    ids = np.arange(seq.n_points) if point_ids is None else np.asarray(point_ids)
    if ids.shape != (seq.n_points,):
        raise ValueError(f"point_ids: {ids.shape[0]} numbers for {seq.n_points} points")
    gt = seq.labels
    lines = ["point,label,x0,y0,ground_truth,owner_atom,fine_model,coarse_motion,atoms,page_motion"]
    p0 = seq.points[0]
    v0 = visible_at(seq, 0)
    for i in range(seq.n_points):
        g = "" if gt is None else str(int(gt[i]))
        xy0 = f"{p0[i, 0]:.3f},{p0[i, 1]:.3f}" if v0[i] else ","
        page = "" if shown[i] < 0 else str(int(shown[i]) + 1)
        lines.append(f"{int(ids[i])},{int(st['final'][i])},{xy0},{g},{int(owner[i])},"
                     f"{int(st['fine'][i])},{int(st['coarse'][i])},{int(n_atoms[i])},{page}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------- 3-D
def space_time(seq: laav.Sequence, depth: float = 1.0):
    """Map pixel coordinates and frame numbers to a 3-D box for the viser view.

    Returns a function ``f(xy (..., 2), frame (...)) -> (..., 3) float32`` putting the image
    centre on the axis, image y up (pixel y points down) and time along +z, with the image's
    larger side 4 units long and the whole sequence ``4 * depth`` units deep.
    """
    x0, x1, y0, y1 = seq.extent()
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    s = 4.0 / max(x1 - x0, y1 - y0, 1e-9)
    dz = 4.0 * depth / max(seq.n_frames - 1, 1)

    def f(xy, frame):
        xy = np.asarray(xy, dtype=np.float64)
        fr = np.broadcast_to(np.asarray(frame, dtype=np.float64), xy.shape[:-1])
        return np.stack([(xy[..., 0] - cx) * s, -(xy[..., 1] - cy) * s, fr * dz], axis=-1).astype(np.float32)

    f.half_width = (x1 - x0) * s / 2
    f.half_height = (y1 - y0) * s / 2
    f.dz = dz
    return f
