"""Card · A/B compare: a pinned result A beside the live result B.

The sidebar's **Pin as A** keeps the result shown (:func:`explorer.compare.pin`); from then
on the card, above card 1, shows A's and B's points in the same frame with the same
colouring (the sidebar's frame and colour-by, except that ground truth, the same on both
sides, becomes each side's final motions; without ground truth B's motions take A's
colours), the points whose final motion differs ringed thinly in both, one legend beside B for
both views (the motions of either side: :func:`explorer.views.legend_points`; the rings), a
table of every stage's error in A and B with the difference, and the settings that differ as
``name: A → B``.
A stays pinned while parameters change; **Unpin** clears it, and so does opening another
sequence (with a message). The card is hidden while nothing is pinned.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import panel as pn
from bokeh.core.properties import value
from bokeh.models import ColumnDataSource, CustomJS

from .. import compare as C
from .. import views as V
from ..fields import fmt_value
from .base import SIDE_W, Host, Markdown, card, fit_image_figure, flex, image_figure, move_legend, set_data
from .frame import EMPTY_POINTS

#: Frame width of each of the two views: side by side from about 1150 px, stacked below.
FRAME_W = 300
#: The title of the legend beside B: it explains A's view too.
LEGEND_TITLE = "A and B"


def ring_label(n: int) -> str:
    """The legend's entry for the rings, ``n`` of them in the frame shown."""
    return f"final motion differs: {int(n)}"


def compare_mode(mode: str) -> str:
    """The colouring of the compare views for the sidebar's colour-by ``mode`` (a
    :data:`explorer.views.COLOR_MODES` key): the same, except that ground truth, which is the
    same on both sides whatever changed, becomes each side's final motions."""
    return "final" if mode == "gt" else mode


def _file_named(seq) -> str:
    """``seq``'s name and the file it came from, ``"synthetic (o.npz)"``; its name alone when it
    came from no file (a sequence made in memory: ``source`` empty or ``<...>``)."""
    src = str(getattr(seq, "source", "") or "")
    if not src or src.startswith("<"):
        return seq.name
    return f"{seq.name} ({Path(src).name})"


class CompareView:
    """The Pin / Unpin buttons (sidebar), the compare card. ``state`` gives the shown
    result's settings and the plain RV runs; ``controls`` the frame and the colour-by."""

    def __init__(self, host: Host, state, controls, extent) -> None:
        self.host, self.state, self.controls = host, state, controls
        self.pinned: C.Pinned | None = None
        self.comparison: C.Comparison | None = None
        self._key = None  # what the comparison and the colours were worked out for
        self._styles = None
        self.w_pin = pn.widgets.Button(label="Pin as A", color="primary", width=130, margin=(5, 10))
        self.w_pin.on_click(lambda e: self.pin())
        self.w_unpin = pn.widgets.Button(label="Unpin", width=110, margin=(5, 5), disabled=True)
        self.w_unpin.on_click(lambda e: self.unpin())
        self.pin_md = Markdown("Pin the result shown as A, change parameters, and compare it "
                               "with the live B above card 1.", width=SIDE_W, margin=(0, 10),
                               styles={"font-size": "0.9em"})
        self.sidebar = [pn.Row(self.w_pin, self.w_unpin, margin=0), self.pin_md]

        self.src = {}
        self.src_changed = {}
        self.figs = {}
        points, rings = {}, {}
        for k in ("A", "B"):
            self.src[k] = ColumnDataSource(dict(EMPTY_POINTS))
            self.src_changed[k] = ColumnDataSource({"x": [], "y": []})
            # (toolbar below, as the frame view's: beside the plot it took the width the legend needs)
            f = self.figs[k] = image_figure(k, FRAME_W, extent, tools="pan,wheel_zoom,box_zoom,reset",
                                            toolbar_location="below")
            if k == "B":  # one zoom and pan for both
                f.x_range, f.y_range = self.figs["A"].x_range, self.figs["A"].y_range
            points[k] = f.scatter("x", "y", source=self.src[k], size=6, fill_color="color", marker="marker",
                                  line_color="#333333", line_width=0.4)
            # thin rings a little wider than a point: where hundreds changed, the points
            # inside stay visible (thick ones merged into one pink blob)
            rings[k] = f.scatter("x", "y", source=self.src_changed[k], marker="circle", size=12, fill_alpha=0,
                                 line_color=V.CHANGED_MARK, line_width=1.3)
        self.fig_a, self.fig_b = self.figs["A"], self.figs["B"]
        # one legend for both views, beside B (the outer side when they are side by side; below
        # A when stacked): the motions of either side (views.legend_points: drawn nowhere in the
        # plot) and the rings; a click on a motion hides or shows the points of both views (all
        # of them: one renderer, as in the frame view), one on the rings' entry both views' rings
        self.src_legend = ColumnDataSource({"x": [], "y": [], "color": [], "marker": [], "label": []})
        key = self.fig_b.scatter("x", "y", source=self.src_legend, size=6, fill_color="color",
                                 marker="marker", line_color="#333333", line_width=0.4, legend_field="label")
        # the ring's entry from a ring drawn nowhere (NaN): its sample is there with no ring in
        # the frame too (an entry with an empty source has none)
        ring_key = self.fig_b.scatter([np.nan], [np.nan], marker="circle", size=12, fill_alpha=0,
                                      line_color=V.CHANGED_MARK, line_width=1.3, legend_label=ring_label(0))
        move_legend(self.fig_b)
        legend = self.fig_b.legend[0]
        legend.title = LEGEND_TITLE
        legend.title_text_font_size = "9pt"
        self._item_ring = legend.items[-1]
        legend.js_on_event("legend_item_click", CustomJS(
            args={"pairs": [[key, [points["A"], points["B"]]], [ring_key, [rings["A"], rings["B"]]]]},
            code="Promise.resolve().then(() => { for (const [p, rs] of pairs) for (const r of rs) "
                 "r.visible = p.visible; });"))
        self.table = Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        self.w_unpin_card = pn.widgets.Button(label="Unpin A", width=100, margin=(6, 10))
        self.w_unpin_card.on_click(lambda e: self.unpin())
        self.inner = card("A/B compare: pinned A beside the live B",
                          flex(pn.pane.Bokeh(self.fig_a), pn.pane.Bokeh(self.fig_b)),
                          self.table, self.w_unpin_card, visible=False)
        # the tour shows and hides this (the outer one); pinning the inner one
        self.card = pn.Column(self.inner, sizing_mode="stretch_width", margin=0)

    # ------------------------------------------------------------------ pin / unpin
    def pin(self) -> bool:
        """Pin the result shown as A (False when there is none yet)."""
        res, seq, settings = self.host.result, self.host.sequence, self.host.settings
        if res is None:
            self.pin_md.object = "Nothing to pin yet: the first result is still being computed."
            return False
        if self.host.previewing:  # LAAV's trial so far: its labels may still change
            self.pin_md.object = ("A preview is shown (LAAV's own trial while the rest of the "
                                  "fine-tuning computes): pin once its result is shown.")
            return False
        self.pinned = C.pin(seq, res, settings, self.state.plain_rv(seq, settings))
        # (a button callback may run outside the document lock: the figures change in a tick)
        self.host.schedule(self.redraw)
        return True

    def unpin(self, message: str | None = None) -> None:
        """Clear A (``message``: why, shown in the sidebar)."""
        self.pinned = self.comparison = self._key = self._styles = None
        with self.host.hold():
            self.inner.visible = False
            self.w_unpin.disabled = True
            self.pin_md.object = message or ("Nothing pinned. Pin the result shown as A, change parameters, "
                                             "and compare it with the live B.")

    def sequence_changed(self, seq) -> str | None:
        """(A new sequence is shown.) Unpin A when it belongs to another sequence; the message
        (Markdown, the names escaped), or None when nothing was pinned."""
        self.fit(seq)
        if self.pinned is None or self.pinned.sequence is seq:
            return None
        old, new = self.pinned.sequence.name, seq.name
        if old == new:  # (two files of one name, e.g. two synthetic ones): their files tell them apart
            old, new = _file_named(self.pinned.sequence), _file_named(seq)
        msg = f"A was unpinned: it belonged to {V.md_text(old)}, and {V.md_text(new)} is shown now."
        self.unpin(msg)
        return msg

    def fit(self, seq) -> None:
        for f in self.figs.values():
            fit_image_figure(f, seq.extent())

    # ------------------------------------------------------------------ drawing
    def redraw(self) -> None:
        """(Document thread.) A and the live B at the frame and colouring shown. The
        comparison and the colours are worked out again only when A, B, a plain RV run or
        the colour-by changed (a frame step just moves the points)."""
        a, res, seq, settings = self.pinned, self.host.result, self.host.sequence, self.host.settings
        if a is None or res is None or a.sequence is not seq:
            return
        a = self.pinned = C.with_plain(a, self.state.plain_rv(a.sequence, a.settings))
        plain_b = self.state.plain_rv(seq, settings)
        mode = compare_mode(self.controls.color_mode)
        key = (a.result, a.plain, res, plain_b, mode)
        if self._key is None or not all(x is y for x, y in zip(key, self._key)):
            b = C.pin(seq, res, settings, plain_b)
            self.comparison = C.compare(a, b)
            ref = None if seq.labels is not None else V.shown_labels(seq, a.result)["final"]
            # one legend for both: both sides grouped, or neither
            rows = V.shared_fine_rows(V.fine_legend_rows(self.fig_b.frame_height, views=2),
                                      a.result, res)
            self._styles = (V.point_style(seq, a.result, mode, a.plain, fine_rows=rows, fine_counts=False),
                            V.point_style(seq, res, mode, plain_b, ref=ref, fine_rows=rows,
                                          fine_counts=False))
            self._key = key
            legend_rows = V.legend_points(*self._styles)
        else:
            legend_rows = None
        comp = self.comparison
        f = int(np.clip(self.host.frame, 0, seq.n_frames - 1))
        xy = seq.points[f]
        changed = np.asarray(comp.changed, dtype=np.int64)
        changed = changed[V.visible_at(seq, f)[changed]]  # only the points seen in this frame
        ring = {"x": xy[changed, 0], "y": xy[changed, 1]}
        what = V.COLOR_LABELS[mode].split(" (")[0]  # "final", not "final (after …)": it fits
        with self.host.hold():
            for k, style in zip(("A", "B"), self._styles):
                set_data(self.src[k], V.points_source(seq, f, style))
                set_data(self.src_changed[k], ring)
            if legend_rows is not None:
                set_data(self.src_legend, legend_rows)
            label = ring_label(changed.size)  # (the rings of this frame, as the frame view counts)
            if self._item_ring.label.value != label:
                self._item_ring.label = value(label)
            self.fig_a.title.text = f"A (pinned) · frame {f} · {what}"
            self.fig_b.title.text = f"B (live) · frame {f} · {what}"
            table = C.comparison_markdown(comp)
            if self.table.object != table:
                self.table.object = table
            self.inner.visible = True
            self.host.complete_page()  # (this card comes with the later ones)
            self.w_unpin.disabled = False
            line = self._pin_line(a)
            if self.pin_md.object != line:
                self.pin_md.object = line

    @staticmethod
    def _pin_line(a: C.Pinned) -> str:
        err = a.errors.get("final")
        e = "" if err is None else f", final error {100 * err:.1f} %"
        s = a.settings
        return (f"**A pinned:** {V.md_text(a.sequence.name)}, seed {s.seed}, C = {s.n_motions}, "
                f"λ = {fmt_value(s.params.lam)}{e}. The compare card is above card 1.")
