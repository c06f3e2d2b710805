"""Card 3 · Fine-to-coarse: the affinity Z of the fine models, which motion each joined, and
the epipolar check of a pair (:mod:`explorer.cards.epipolar`)."""

from __future__ import annotations

import panel as pn
from bokeh.models import ColorBar, ColumnDataSource, FactorRange, FixedTicker, LinearColorMapper
from bokeh.palettes import Blues256
from bokeh.plotting import figure

from .. import views as V
from .base import Host, Markdown, card, flex, set_data
from .epipolar import EpipolarPanel

#: Z (0-1): white to blue. The joint merge's margins: :data:`explorer.views.MARGIN_PALETTE`.
Z_PALETTE = list(Blues256[::-1])
MARGIN_PALETTE, UNDECIDED = list(V.MARGIN_PALETTE), V.UNDECIDED
Z_TICKS = (0.0, 0.2, 0.4, 0.6, 0.8, 1.0)
#: The heat map's plot area (px, square): its cells are this divided by the number of fine
#: models, and the numbers written in them sized to fit (:func:`explorer.views.cell_font_px`).
Z_FRAME = 224
Z_TOOLTIPS = [("pair", "f@j, f@k"), ("Z", "@z{0.00}"), ("epipolar distance", "@d"),
              ("coding length added by merging (nats/point)", "@g")]
MARGIN_TOOLTIPS = [("pair", "f@j, f@k"), ("score margin (nats; > 0: joined)", "@m{+0.0}"),
                   ("of which coding length", "@ml{+0.0}"), ("of which epipolar cost", "@me{+0.0}"),
                   ("epipolar distance", "@d")]


class CoarseView:
    """Z (or the joint merge's decision margins) as a heat map, the merge table, and the
    epipolar panel."""

    def __init__(self, host: Host, extent) -> None:
        self.z_mapper = LinearColorMapper(palette=Z_PALETTE, low=0, high=1, nan_color=UNDECIDED)
        self.src_z = ColumnDataSource({"x": [], "y": [], "z": [], "text": [], "text_color": [], "d": [],
                                       "g": [], "j": [], "k": [], "m": [], "ml": [], "me": []})
        z = self.fig_z = figure(title="Affinity Z of fine-model pairs", frame_width=Z_FRAME,
                                frame_height=Z_FRAME,
                                x_range=FactorRange(factors=["f1"]), y_range=FactorRange(factors=["f1"]),
                                tools="hover", toolbar_location=None, tooltips=Z_TOOLTIPS)
        self.z_hover = z.hover[0] if isinstance(z.hover, list) else z.hover
        z.rect("x", "y", 1, 1, source=self.src_z, fill_color={"field": "z", "transform": self.z_mapper},
               line_color="white")
        # the joint merge's close calls outlined: a pair decided by a few nats reads as nearly
        # white on the margins' log scale, beside the strong blues of the easy pairs, though a
        # close call is where a merge fails (cars2B seed 5: f1 and f2 split by 1.1 nats)
        self.src_close = ColumnDataSource({"x": [], "y": []})
        z.rect("x", "y", 0.86, 0.86, source=self.src_close, fill_alpha=0, line_color="#000000",
               line_width=2)
        self.z_text = z.text("x", "y", text="text", source=self.src_z, text_align="center",
                             text_baseline="middle", text_font_size="12px", text_color="text_color")
        z.xaxis.major_label_orientation = 0.8
        z.xaxis.axis_label = "fine model → motion it joined"
        z.yaxis.axis_label = "fine model → motion"
        z.grid.visible = False
        # one ticker for both scales, its ticks changed: BokehJS reads a colour bar's ticker
        # once, when the bar's view is made (a ticker swapped later is ignored), and a model
        # new to the document makes bokeh walk its whole graph
        self.z_ticker = FixedTicker(ticks=list(Z_TICKS))
        self.z_bar = ColorBar(color_mapper=self.z_mapper, width=8, padding=2, ticker=self.z_ticker)
        z.add_layout(self.z_bar, "right")
        # the tables take the width the heat map leaves (at least 340 px; below it when narrower)
        self.merge_md = Markdown("", min_width=340, sizing_mode="stretch_width", margin=(0, 6),
                                 styles={"flex": "1 1 340px"})
        self.epipolar = EpipolarPanel(host, extent)
        self.card = card("3 · Fine-to-coarse: fine models merged into motions",
                         flex(pn.pane.Bokeh(self.fig_z), self.merge_md, self.epipolar.layout))

    def fit(self, seq) -> None:
        self.epipolar.fit(seq)

    def draw(self, seq, res) -> None:
        """Z and the merge table of ``res`` (the epipolar panel draws separately)."""
        data, factors = V.z_sources(res, seq, fit_votes=False)  # (d: once fitted, drawn again)
        self.fig_z.x_range.factors = factors or ["–"]
        self.fig_z.y_range.factors = list(reversed(factors)) or ["–"]
        set_data(self.src_z, data)
        self._numbers(data["text"], len(factors))
        method = res.coarse.method
        margins = V.shows_margins(res)
        close = V.close_calls(data)  # (none where Z is shown: no margins there)
        set_data(self.src_close, {"x": data["x"][close], "y": data["y"][close]})
        self._scale(margins, data["z"])
        single = method == "joint" and not margins  # no partitions compared (see Coarse.shortlist)
        if margins:
            # (the model count is on the axes: with it the title overran the plot's width)
            self.fig_z.title.text = f"Joint merge margins (nats), {V.lam_label(res)}"
            w = res.params.coarse_epipolar_weight
            how = (f"ours: of the partitions of least coding length (ε = {res.params.coding_eps:g} px), "
                   "the one of least coding length "
                   f"+ {w:g} × epipolar cost (in units of 2/λ px²) decided. The map shows, for each "
                   "pair, what decided it: the least score of a compared partition that splits the "
                   "two minus the least of one that joins them, in nats (blue: joining won by that "
                   "much; orange: splitting won; grey: every partition compared agrees; outlined in "
                   f"black: decided by less than {V.CLOSE_CALL_NATS:g} nats, the close calls); hover "
                   "for its coding-length and epipolar parts. The paper's epipolar vote is the paper "
                   "preset")
        elif method == "coding" or single:
            self.fig_z.title.text = f"Coding affinity, ε = {res.params.coding_eps:g} px"
            decided = ("the joint merge compared no partitions (no more fine models than motions, or "
                       "none that gives every motion 8 points), so the partition of least coding "
                       "length decided" if single else "the partition of least coding length decided")
            how = (f"ours: {decided}; the map shows exp(−ΔL), ΔL the nats per point that merging a "
                   "pair adds; the paper's epipolar vote is the paper preset")
        else:
            self.fig_z.title.text = f"Affinity Z ({V.lam_label(res)}): {len(factors)} fine models"
            how = "spectral clustering of Z (the paper's epipolar votes)"
        listed = V.shortlist_table(seq, res)  # "" but for the joint merge
        self.merge_md.object = (f"**Which fine model joined which motion** ({how}):\n\n"
                                + V.merge_table(seq, res)
                                + (f"\n\n**Partitions compared** (lower score wins):\n\n{listed}"
                                   if listed else ""))

    def _numbers(self, texts, n: int) -> None:
        """The numbers in the cells at a size that fits them (overlapping digits of the next
        cells at 9 pt before: ``-991`` on a map of 8 models), or none where they cannot be read
        (the colour and the hover tell the value)."""
        px = V.cell_font_px(texts, Z_FRAME / max(n, 1))
        size = f"{px or 12}px"
        if self.z_text.glyph.text_font_size != size:
            self.z_text.glyph.text_font_size = size
        if self.z_text.visible != bool(px):
            self.z_text.visible = bool(px)

    def _scale(self, margins: bool, z) -> None:
        """The colour scale: Z in [0, 1], or the margins' signed log, symmetric, its colour
        bar labelled in nats up to its ends (:func:`explorer.views.margin_ticks`)."""
        if not margins:
            scale = dict(palette=Z_PALETTE, low=0, high=1, ticks=list(Z_TICKS), labels={},
                         tooltips=Z_TOOLTIPS)
        else:
            top = V.margin_top(z)
            where, labels = V.margin_ticks(top)
            scale = dict(palette=MARGIN_PALETTE, low=-top, high=top, ticks=where,
                         labels=dict(zip(where, labels)), tooltips=MARGIN_TOOLTIPS)
        # only what changed: bokeh validates a value before comparing it (the 256 or 512
        # colours of a palette: ~6 ms a result), and sends every change to the page
        for model, attr, key in ((self.z_mapper, "palette", "palette"), (self.z_mapper, "low", "low"),
                                 (self.z_mapper, "high", "high"), (self.z_ticker, "ticks", "ticks"),
                                 (self.z_bar, "major_label_overrides", "labels"),
                                 (self.z_hover, "tooltips", "tooltips")):
            if getattr(model, attr) != scale[key]:
                setattr(model, attr, scale[key])
