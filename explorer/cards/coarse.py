"""Card 3 · Fine-to-coarse: the affinity Z of the fine models, which motion each joined, and
the epipolar check of a pair (:mod:`explorer.cards.epipolar`)."""

from __future__ import annotations

import panel as pn
from bokeh.models import ColorBar, ColumnDataSource, FactorRange, LinearColorMapper
from bokeh.palettes import Blues256
from bokeh.plotting import figure

from .. import views as V
from .base import Host, Markdown, card, flex, set_data
from .epipolar import EpipolarPanel


class CoarseView:
    """Z as a heat map, the merge table, and the epipolar panel."""

    def __init__(self, host: Host, extent) -> None:
        self.z_mapper = LinearColorMapper(palette=list(Blues256[::-1]), low=0, high=1)
        self.src_z = ColumnDataSource({"x": [], "y": [], "z": [], "text": [], "text_color": [], "d": [],
                                       "g": [], "j": [], "k": []})
        z = self.fig_z = figure(title="Affinity Z of fine-model pairs", width=320, height=320,
                                x_range=FactorRange(factors=["f1"]), y_range=FactorRange(factors=["f1"]),
                                tools="hover", toolbar_location=None,
                                tooltips=[("pair", "f@j, f@k"), ("Z", "@z{0.00}"),
                                          ("epipolar distance", "@d"),
                                          ("coding length added by merging (nats/point)", "@g")])
        z.rect("x", "y", 1, 1, source=self.src_z, fill_color={"field": "z", "transform": self.z_mapper},
               line_color="white")
        z.text("x", "y", text="text", source=self.src_z, text_align="center", text_baseline="middle",
               text_font_size="9pt", text_color="text_color")
        z.xaxis.major_label_orientation = 0.8
        z.xaxis.axis_label = "fine model → motion it joined"
        z.yaxis.axis_label = "fine model → motion"
        z.grid.visible = False
        z.add_layout(ColorBar(color_mapper=self.z_mapper, width=8, padding=2), "right")
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
        method = res.coarse.method
        if method in ("coding", "joint"):
            # λ enters the joint merge as its epipolar cost's unit (2/λ px², see the text)
            lam = f", λ = {res.params.lam:g}" if method == "joint" else ""
            # (the model count is on the axes: with it the title overran the plot's width)
            self.fig_z.title.text = f"Coding affinity, ε = {res.params.coding_eps:g} px{lam}"
            how = ("ours: " + ("the partition of least coding length decided"
                               if method == "coding" else
                               "of the partitions of least coding length, the one of least "
                               "coding length + epipolar cost (in units of 2/λ px²) decided")
                   + "; the map shows exp(−ΔL), ΔL the nats per point that merging a pair adds;"
                   " the paper's epipolar vote is the paper preset")
        else:
            self.fig_z.title.text = f"Affinity Z (λ = {res.params.lam:g}): {len(factors)} fine models"
            how = "spectral clustering of Z (the paper's epipolar votes)"
        listed = V.shortlist_table(seq, res)  # "" but for the joint merge
        self.merge_md.object = (f"**Which fine model joined which motion** ({how}):\n\n"
                                + V.merge_table(seq, res)
                                + (f"\n\n**Partitions compared** (lower score wins):\n\n{listed}"
                                   if listed else ""))
