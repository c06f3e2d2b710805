"""Card 4 · Fine-tuning (Random Voting): how LAAV's informed start converges, beside plain
Random Voting from a random start."""

from __future__ import annotations

import panel as pn
from bokeh.core.properties import value
from bokeh.models import ColumnDataSource, Legend, LogAxis
from bokeh.plotting import figure

from .. import views as V
from .base import Markdown, card, flex, set_data

RV_TOOLS = "pan,wheel_zoom,reset"
#: The charts' width (px): two fit side by side beside the guided tour's panel at 1280 px.
RV_FIG_WIDTH = 400
#: The error chart's title with and without ground truth.
ERROR_TITLES = {True: "Error per iteration (vs ground truth)",
                False: "Points off the trial's last labels"}
#: The error plot's y axis when not every point voted: ``{k}`` of ``{p}`` points (in the
#: title, beside the toolbar, "(the K of P points that voted)" was cut off).
VOTED_AXIS = "% of the {k} voted (of {p})"


def legend_above(fig) -> None:
    """``fig``'s legend in one row between its title and the plot: inside the plot, in any
    corner, it covered part of a curve (plain RV's error runs at 20-60 % across the whole
    width of the chart while LAAV's is near 0)."""
    leg = fig.legend[0]
    fig.center = [c for c in fig.center if not isinstance(c, Legend)]
    leg.orientation = "horizontal"
    leg.location = "top_left"
    leg.label_text_font_size = "8pt"
    leg.padding = leg.margin = 2
    leg.spacing = 12
    leg.glyph_width = 18
    leg.border_line_alpha = 0
    fig.add_layout(leg, "above")


class RVView:
    """Error, labels changed and mean vote margin per iteration, for both runs; a summary."""

    def __init__(self) -> None:
        self.plain = None  # the plain-RV run drawn (None until it arrives)
        self._drawn = None  # what the card shows: (sequence, LAAV's voting, plain RV's, pending)
        empty_rv = {"iteration": [], "changed": [], "changed_plot": [], "margin": []}
        self.src_rv_laav = ColumnDataSource(dict(empty_rv))
        self.src_rv_plain = ColumnDataSource(dict(empty_rv))
        # the paper's Fig. 3 in one run: LAAV's trial starts near the answer, plain RV at
        # random (row 0 of each trial's label trace, laav.Voting.label_trace)
        self.src_err_laav = ColumnDataSource({"iteration": [], "error": []})
        self.src_err_plain = ColumnDataSource({"iteration": [], "error": []})
        self.fig_error = figure(title=ERROR_TITLES[True], width=RV_FIG_WIDTH, height=235, tools=RV_TOOLS,
                                toolbar_location="above")
        self.fig_error.line("iteration", "error", source=self.src_err_laav, line_width=2.5,
                            color="#222222", legend_label=V.RV_OWN_NAMES[False])
        self.fig_error.line("iteration", "error", source=self.src_err_plain, line_width=2,
                            color="#8C8C8C", line_dash="dashed", legend_label=V.RV_PLAIN_NAME)
        self.fig_error.xaxis.axis_label = "Random Voting iteration (0 = the start)"
        self.fig_error.yaxis.axis_label = "% of points"
        self.fig_error.title.text_font_size = "11pt"
        self.fig_changed = figure(title="Labels changed per iteration", width=RV_FIG_WIDTH, height=235,
                                  y_axis_type="log", tools=RV_TOOLS, toolbar_location="above")
        self.fig_margin = figure(title="Mean vote margin per iteration", width=RV_FIG_WIDTH, height=235,
                                 tools=RV_TOOLS, toolbar_location="above")
        for fig in (self.fig_error, self.fig_changed, self.fig_margin):
            fig.toolbar.logo = None  # (bokeh's coloured logo: colours mean motions on this page)
        for fig, col, ylab in ((self.fig_changed, "changed_plot", "labels changed (0 drawn as ½)"),
                               (self.fig_margin, "margin", "(best − 2nd best) / sum of votes")):
            # neutral greys: colours mean motions on this page
            fig.line("iteration", col, source=self.src_rv_laav, line_width=2.5, color="#222222",
                     legend_label=V.RV_OWN_NAMES[False])
            fig.line("iteration", col, source=self.src_rv_plain, line_width=2, color="#8C8C8C",
                     line_dash="dashed", legend_label=V.RV_PLAIN_NAME)
            fig.xaxis.axis_label = "Random Voting iteration"
            fig.yaxis.axis_label = ylab
            fig.title.text_font_size = "11pt"
        for fig in (self.fig_error, self.fig_changed, self.fig_margin):
            legend_above(fig)
        assert isinstance(self.fig_changed.yaxis[0], LogAxis)
        self.rv_md = Markdown("", sizing_mode="stretch_width", max_width=820, margin=(0, 10))
        self.card = card("4 · Fine-tuning (Random Voting): LAAV's start vs plain RV",
                         flex(pn.pane.Bokeh(self.fig_error), pn.pane.Bokeh(self.fig_changed),
                              pn.pane.Bokeh(self.fig_margin)),
                         self.rv_md)

    def draw(self, seq, laav_voting, plain, pending: bool = False, own_chain: bool = False) -> None:
        """``seq``: the sequence (its ground truth scores the error chart); ``pending``:
        ``laav_voting`` is a preview, LAAV's own trial before plain RV and the selection
        (:attr:`explorer.state.ExplorerState.on_preview`), with ``own_chain`` before the
        missing-motion starts of LAAV's own chain. The same runs again (a λ or
        colour change that left the fine-tuning as it was) are not drawn again."""
        drawn = (seq, laav_voting, plain, (bool(pending), bool(own_chain)))
        if self._drawn is not None and all(a is b for a, b in zip(drawn[:3], self._drawn[:3])) \
                and drawn[3] == self._drawn[3]:
            return
        self._drawn = drawn
        set_data(self.src_rv_laav, V.rv_sources(laav_voting))
        set_data(self.src_rv_plain, V.rv_sources(plain))
        own, other = V.rv_error_sources(seq, laav_voting), V.rv_error_sources(seq, plain)
        drawn = own["error"].size or other["error"].size or plain is None
        shown = laav_voting if laav_voting is not None else plain
        some = shown is not None and shown.voted is not None and shown.voted.size < seq.n_points
        self.fig_error.title.text = ERROR_TITLES[seq.labels is not None] + (
            "" if drawn else ": not recorded (no trial ran)")
        self.fig_error.yaxis.axis_label = (VOTED_AXIS.format(k=shown.voted.size, p=seq.n_points)
                                           if some else "% of points")
        set_data(self.src_err_laav, own)
        set_data(self.src_err_plain, other)
        self.plain = plain
        self.rv_md.object = V.rv_summary(laav_voting, plain, pending=pending, truth=seq.labels,
                                         own=own_chain)
        own = V.own_trial_name(laav_voting)
        for fig in (self.fig_error, self.fig_changed, self.fig_margin):
            item = fig.legend.items[0]
            if getattr(item.label, "value", None) != own:
                item.label = value(own)
