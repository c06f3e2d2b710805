"""The epipolar check of card 3: two fine models' points in frames l and r, and the lines
in frame r of a fundamental matrix the merge itself used for the pair (its sample of median
distance, ``Coarse.vote_samples``), with the sample's features ringed.

Its own controls: the pair of fine models (j, k).
"""

from __future__ import annotations

import numpy as np
import panel as pn
from bokeh.models import ColumnDataSource, Legend

from .. import views as V
from .base import Host, Markdown, fit_image_figure, flex, image_figure, set_data

#: px the caption never goes under (:class:`EpipolarPanel`): with the pending caption as
#: long as the fitted one (:func:`epipolar_caption`), the page keeps its height while a
#: result's votes are fitted.
CAPTION_MIN_HEIGHT = 150


class EpipolarPanel:
    """Pick two fine models; see whether one rigid motion explains both."""

    def __init__(self, host: Host, extent) -> None:
        self.host = host
        self.w_pair_j = pn.widgets.Select(label="epipolar check: j", options=["f1"], width=105)
        self.w_pair_k = pn.widgets.Select(label="and k", options=["f1"], width=105)
        self.w_pair_j.param.watch(self._on_pair, "value")
        self.w_pair_k.param.watch(self._on_pair, "value")

        empty_p = {"x": [], "y": [], "color": [], "model": [], "marker": []}
        self.src_epi_l = ColumnDataSource(dict(empty_p))
        self.src_epi_r = ColumnDataSource(dict(empty_p))
        self.src_epi_lines = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": [], "color": []})
        self.src_sample_l = ColumnDataSource({"x": [], "y": []})
        self.src_sample_r = ColumnDataSource({"x": [], "y": []})
        self.fig_l = image_figure("frame l", 200, extent, toolbar_location=None, tools="")
        self.fig_r = image_figure("frame r with epipolar lines", 200, extent, toolbar_location=None,
                                  tools="")
        self.fig_r.x_range = self.fig_l.x_range
        self.fig_r.y_range = self.fig_l.y_range
        for fig, src in ((self.fig_l, self.src_epi_l), (self.fig_r, self.src_epi_r)):
            fig.scatter("x", "y", source=src, size=6, marker="marker", fill_color="color",
                        line_color="color", legend_field="model")
            leg = fig.legend[0]
            fig.center = [c for c in fig.center if not isinstance(c, Legend)]
            leg.orientation = "horizontal"
            leg.label_text_font_size = "8pt"
            leg.padding = 2
            leg.margin = 2
            fig.add_layout(leg, "below")
            fig.title.text_font_size = "10pt"
        self.fig_r.segment("x0", "y0", "x1", "y1", source=self.src_epi_lines, line_color="color",
                           line_alpha=0.55, line_width=1)
        for fig, src in ((self.fig_l, self.src_sample_l), (self.fig_r, self.src_sample_r)):
            fig.scatter("x", "y", source=src, size=10, fill_alpha=0, line_color="black",
                        line_width=1.5)

        # the page below must not move up and back while a result's votes are fitted: that
        # cost the browser a layout of every plot per move (CAPTION_MIN_HEIGHT)
        self.caption = Markdown("", sizing_mode="stretch_width", max_width=800, margin=(0, 10),
                                min_height=CAPTION_MIN_HEIGHT)
        self.layout = pn.Column(pn.Row(self.w_pair_j, self.w_pair_k),
                                flex(pn.pane.Bokeh(self.fig_l), pn.pane.Bokeh(self.fig_r)),
                                self.caption, max_width=580, sizing_mode="stretch_width")

    def fit(self, seq) -> None:
        fit_image_figure(self.fig_l, seq.extent())  # fig_r shares its ranges
        self.fig_r.frame_height = self.fig_l.frame_height

    def set_models(self, res) -> None:
        """Offer ``res``'s fine models; a new set starts at the pair f1, f2. k is offered
        every model but j (a model is never voted against itself)."""
        n = int(np.asarray(res.coarse.fine_to_coarse).size)
        opts = [f"f{j + 1}" for j in range(max(n, 1))]
        if list(self.w_pair_j.options) != opts:
            self.w_pair_j.options = opts
            self.w_pair_j.value = opts[0]
            self._offer_k(opts[min(1, len(opts) - 1)])

    def _offer_k(self, want: str) -> None:
        """k's options: every model but j's; ``want`` if offered, else the first."""
        opts = [o for o in self.w_pair_j.options if o != self.w_pair_j.value] or list(self.w_pair_j.options)
        if list(self.w_pair_k.options) != opts:
            self.w_pair_k.options = opts
        self.w_pair_k.value = want if want in opts else opts[0]

    def pair(self) -> tuple[int, int]:
        def idx(w):
            try:
                return int(str(w.value)[1:]) - 1
            except ValueError:
                return 0
        return idx(self.w_pair_j), idx(self.w_pair_k)

    def draw(self, seq, res) -> None:
        j, k = self.pair()
        d = V.epipolar_sources(seq, res, j, k, fit_votes=False)  # (once fitted, drawn again)
        set_data(self.src_epi_l, d["left"])
        set_data(self.src_epi_r, d["right"])
        set_data(self.src_sample_l, d["sample_left"])
        set_data(self.src_sample_r, d["sample_right"])
        set_data(self.src_epi_lines, d["lines"])
        fl, fr = d["frames"]
        self.fig_l.title.text = f"frame l = {fl}: f{j + 1} and f{k + 1}"
        self.fig_r.title.text = f"frame r = {fr}: " + (
            "fitting the vote's F…" if d.get("pending") else "the vote's F")
        self.caption.object = epipolar_caption(d, res, j, k)

    # ------------------------------------------------------------------ callbacks
    def _on_pair(self, event=None) -> None:
        if event is not None and event.obj is self.w_pair_j:  # k never equals j
            self._offer_k(self.w_pair_k.value)
        self.host.schedule(self._pair_now, now_if_on_doc_thread=True)

    def _pair_now(self) -> None:
        h = self.host
        if h.result is None or h.quieted:
            return
        with h.hold():
            self.draw(h.sequence, h.result)


def epipolar_caption(d: dict, res, j: int, k: int) -> str:
    """What the panel shows and how the merge used it, with its numbers."""
    if j == k:
        return "Pick two different fine models: a model is never voted against itself."
    f2c = np.asarray(res.coarse.fine_to_coarse)
    same = "the same motion" if f2c[j] == f2c[k] else "different motions"
    a, b = f"f{j + 1}", f"f{k + 1}"
    method = getattr(res.coarse, "method", "epipolar")
    if not (d["ok"] or d.get("pending")):
        return "No vote for this pair (too few atoms)."
    # while the votes are fitted, the same sentences with "…" for what is not known yet:
    # about the same length, so the caption (and the page below it) keeps its height
    pending = bool(d.get("pending"))
    n = lambda key, fmt: "…" if pending else format(d[key], fmt)  # noqa: E731
    fl, fr = ("…", "…") if pending else d["frames"]
    text = (
        f"The vote for {a}–{b}{' (being fitted)' if pending else ''} drew {d['n_samples']} "
        f"samples: two atoms of each model, one F "
        f"per sample fitted on their features between two frames, distance d = the larger "
        f"of the two models' mean Sampson distances, vote exp(−λ d). **Shown: the sample of "
        f"median d** (frames {fl} → {fr}, its features ringed): "
        f"d = **{n('sample_distance', '.2f')} px²**, vote **{n('sample_vote', '.2f')}**; lines of "
        f"{a} points lie {n('residual_j', '.1f')} px, of {b} points {n('residual_k', '.1f')} px from "
        f"their points. Over all samples: mean d = {n('distance', '.2f')} px², pairwise vote "
        f"**{n('pairwise', '.2f')}**")
    w = res.params.pairwise_weight if res.params.pooled_trials > 0 else 1.0
    if method in ("coding", "joint"):
        return text + _decided(res, j, k, same)
    if pending:  # (the paper's merge fits its votes: not reached there)
        return text + "."
    if w < 1.0:
        text += (f"; co-association of the pooled-voting trials {d['coassociation']:.2f}; "
                 f"Z = {1 - w:.2f} × co-association + {w:.2f} × vote = **{d['affinity']:.2f}**")
    else:
        text += f" = Z {d['affinity']:.2f}"
    return text + f". Spectral clustering of Z put them in {same}."


def _decided(res, j: int, k: int, same: str) -> str:
    """The caption's end under the coding-length or joint merge: what decided the pair (the
    joint merge: its margin for the pair, :func:`explorer.views.joint_margins`, as card 3's
    map shows it)."""
    a, b = f"f{j + 1}", f"f{k + 1}"
    margins = V.joint_margins(res) if res.coarse.method == "joint" else None
    if margins is None:  # the coding merge, or a joint merge that compared no partitions
        who = ("The coding-length merge" if res.coarse.method == "coding" else
               "The joint merge compared no partitions (no more fine models than motions, or "
               "none that gives every motion 8 points), so the partition of least coding length")
        g = float(np.asarray(res.coarse.merge_cost)[j, k])
        return (f". {who} decided, not this vote: joining {a} and {b} adds {g:+.2f} "
                f"nats per point; they went to {same}.")
    m, coding, epi = (float(x[j, k]) for x in margins)
    who = "The joint merge (coding length + epipolar cost of whole partitions) decided, not this vote"
    if not np.isfinite(m):
        return f". {who}: every partition it compared put {a} and {b} in {same}."
    return (f". {who}: of the partitions it compared, the best that splits {a} and {b} scores "
            f"{m:+.1f} nats against the best that joins them (the lower score wins; coding "
            f"length {coding:+.1f}, epipolar {epi:+.1f}), so they went to {same}.")
