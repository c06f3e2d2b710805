"""Card 2 · Multicut graph: the atom graph at the shown frame, and the GAEC replay.

Its own control: the contraction step (a player: Home/End and play step through it).
"""

from __future__ import annotations

import numpy as np
import panel as pn
from bokeh.events import RangesUpdate
from bokeh.models import ColorBar, ColumnDataSource, HoverTool, LinearColorMapper

from .. import views as V
from .base import Host, Markdown, card, fit_image_figure, image_figure, move_legend, set_data
from .live import LiveFrames

#: Atom ids are written beside the nodes up to this many atoms (every Hopkins155 sequence:
#: at most 146 with the defaults), and only those that overlap no other id in any frame at the
#: plot's size, or the middle of a node (:func:`explorer.views.id_layout`; before, all of
#: them, overprinting each other in cars2B's dense clusters). Above it
#: (563 atoms at 5,000 tracks) they overlap into a blot that hides the nodes, and the pass
#: grows as the square of the atoms; a node's hover still gives its id. (The page's frame
#: moves at 5,000 tracks: 142-145 ms median without them, 145-153 ms with, interleaved:
#: within the spread; a JavaScript profile had put the ids' measuring at about 20 ms a move.)
MAX_ATOM_IDS = 200

#: A zoom that changes the plot's scale by more than this factor places the atom ids again
#: (zoomed in, ids that overlapped at the old scale may fit; zoomed out, some no longer do).
RELAYOUT_ZOOM = 1.15

#: The legend samples of the kept and cut edges.
LEGEND_EDGE = "#555555"
#: The legend entries of a replay step (hidden at step 0 and the final step, where they mark
#: nothing).
STEP_ENTRIES = ("contracted at this step", "joined at this step (ringed)")


class GraphView:
    """Atoms as nodes at their seeds' positions in the shown frame, kept / cut edges by cost,
    clusters after a GAEC step coloured by the fine model they end in."""

    def __init__(self, host: Host, extent, live: LiveFrames | None = None) -> None:
        self.host = host
        self.live = live if live is not None else LiveFrames()
        self.specs = V.graph_specs()
        self._tpl_key = None  # (result, step, colours) of the templates kept
        self._tpl_layout = None  # and where their atom ids were placed (views.id_layout)
        self._layout: tuple | None = None  # (result, scale, views.id_layout) kept across steps
        self._tpls: dict = {}
        # a player, not a slider: its range input takes Home/End to the first/last step (the
        # slider's noUiSlider keeps its first range for the End key: it went to step 1), and
        # play steps through the contractions for a class
        self.w_step = pn.widgets.Player(label="GAEC contraction step (rightmost = final fine models)",
                                        start=0, end=1, value=1, interval=600, loop_policy="once",
                                        show_loop_controls=False, value_align="start", scale_buttons=0.8,
                                        width=420)
        self.w_step.param.watch(self._on_step, "value")

        # cost > 0 (join) blue, < 0 (cut) red; without RdBu's three palest shades, which a
        # small cost drew nearly white on the white figure (a teacher's review)
        self.cost_mapper = LinearColorMapper(palette=list(V.EDGE_PALETTE), low=-1, high=1)
        # the colour bar reads a mapper of its own: bokeh's colour bar lays the whole figure
        # out again whenever its mapper colours anything, i.e. at every frame move's edges
        self.bar_mapper = LinearColorMapper(palette=list(V.EDGE_PALETTE), low=-1, high=1)
        # (toolbar below, 390 px: at 1024 px the figure with its legend fits the card only so)
        g = self.fig = image_figure("Atom graph at frame 0", 390, extent, toolbar_location="below")
        empty_e = {"x0": [], "y0": [], "x1": [], "y1": [], "cost": [], "error": [], "a": [], "b": []}
        self.src_joined = ColumnDataSource(dict(empty_e))
        self.src_cut = ColumnDataSource(dict(empty_e))
        self.src_step = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": []})
        self.src_nodes = ColumnDataSource({"x": [], "y": [], "color": [], "cluster": [], "atom": [],
                                           "members": [], "size": [], "label": [], "dx": [],
                                           "align": []})
        self.src_pair = ColumnDataSource({"x": [], "y": [], "color": [], "size": [], "atom": [], "text": [],
                                          "dx": [], "align": []})
        g.segment("x0", "y0", "x1", "y1", source=self.src_step, line_color="#222222", line_alpha=0.35,
                  line_width=10, legend_label="contracted at this step")
        by_cost = {"field": "cost", "transform": self.cost_mapper}
        r_kept = g.segment("x0", "y0", "x1", "y1", source=self.src_joined, line_width=2.5,
                           line_color=by_cost, legend_label="kept by the multicut (solid)")
        r_cut = g.segment("x0", "y0", "x1", "y1", source=self.src_cut, line_width=1.8, line_dash="dashed",
                          line_color=by_cost, legend_label="cut by the multicut (dashed)")
        r_nodes = g.scatter("x", "y", source=self.src_nodes, size="size", fill_color="color",
                            line_color="black", line_width=0.8, legend_label="atom (colour = cluster)")
        # atom ids beside the nodes (only those that overlap no other: views.graph_templates);
        # the pair joined at this step on top of everything, ringed, its ids beside the rings
        # (on a light box: an id stays readable where it crosses an edge; bokeh's text outline
        # is stroked over the digits and hid them)
        halo = {"background_fill_color": "white", "background_fill_alpha": 0.75}
        self.r_ids = g.text("x", "y", text="label", source=self.src_nodes, x_offset="dx", text_align="align",
                            text_baseline="middle", text_font_size="7pt", text_color="#333333", **halo)
        g.scatter("x", "y", source=self.src_pair, size="size", fill_color="color", line_color="#111111",
                  line_width=3, legend_label="joined at this step (ringed)")
        g.text("x", "y", text="text", source=self.src_pair, x_offset="dx", text_align="align",
               text_baseline="middle", text_font_size="8pt", text_font_style="bold", text_color="#111111",
               **halo)
        g.add_tools(HoverTool(renderers=[r_nodes], tooltips=[("atom", "@atom"), ("cluster", "@cluster"),
                                                             ("features", "@members")]))
        g.add_layout(ColorBar(color_mapper=self.bar_mapper, title="edge cost: + join (blue), − cut (red)",
                              orientation="horizontal", height=8, title_text_font_size="9pt",
                              padding=4), "below")
        move_legend(g)
        # a zoom (wheel, box, reset) places the ids again at the new scale
        g.on_event(RangesUpdate, self._on_zoom)

        # the views the page makes at each frame (explorer/cards/live.py)
        live_srcs = (self.src_nodes, self.src_joined, self.src_cut, self.src_step, self.src_pair)
        self.live.repaint_alone(g, [r for r in g.renderers if getattr(r, "data_source", None) in live_srcs])
        for name, src in (("nodes", self.src_nodes), ("joined", self.src_joined), ("cut", self.src_cut),
                          ("step_edge", self.src_step), ("pair", self.src_pair)):
            self.live.add("graph_" + name, src, self.specs[name])
        self.live.detach_legend(g)
        # the solid / dashed entries say what the multicut decided, not the cost's sign (the
        # colour bar's): their samples in a neutral grey, whatever the first edge's cost
        for r in (r_kept, r_cut):
            self.live.stand_in(r).glyph.line_color = LEGEND_EDGE
        # the entries of a replay step, shown only while the slider is before the final step
        # (at it nothing is contracted or joined: they had a label and no sample)
        self._step_items = [it for it in g.legend[0].items
                            if str(getattr(it.label, "value", "")).endswith(STEP_ENTRIES)]
        self.live.add_text("graph_title", g.title, "text")

        self.caption = Markdown("", sizing_mode="stretch_width", max_width=820, margin=(0, 10))
        self.card = card("2 · Multicut graph of atoms → fine models (GAEC replay)",
                         pn.pane.Bokeh(self.fig), self.w_step, self.caption)

    def fit(self, seq) -> None:
        fit_image_figure(self.fig, seq.extent())

    def id_scale(self) -> tuple[float, float]:
        """The plot's pixels per data unit (x, y), as its ranges stand (a zoom the page sent
        included): where the atom ids are placed so as not to overlap."""
        f = self.fig
        return self._scale(f.x_range.start, f.x_range.end, f.y_range.start, f.y_range.end)

    def _scale(self, x0, x1, y0, y1) -> tuple[float, float]:
        """Pixels per data unit (x, y) of the plot showing ``[x0, x1] x [y0, y1]``."""
        f = self.fig
        return (f.frame_width / max(abs(x1 - x0), 1e-9), f.frame_height / max(abs(y1 - y0), 1e-9))

    def id_layout(self, res):
        """Where ``res``'s atom ids may go at the plot's size (:func:`explorer.views.id_layout`),
        kept while the result and the size stay (a replay step only places them); None above
        :data:`MAX_ATOM_IDS` atoms (no ids). A draw at another scale places them again (a frame
        move after a zoom too small for :meth:`_on_zoom`: the exact scale then)."""
        if res.graph.n_nodes > MAX_ATOM_IDS:
            self._layout = None  # (no ids: a zoom has nothing to place again)
            return None
        scale = self.id_scale()
        kept = self._layout
        if kept is None or kept[0] is not res or kept[1] != scale:
            kept = self._layout = (res, scale, V.id_layout(res, scale))
        return kept[2]

    def zoomed(self, scale) -> bool:
        """Whether the plot's scale ``scale`` (px per data unit, (sx, sy)) is far enough from
        the one the shown ids were placed at (:data:`RELAYOUT_ZOOM`) to place them again."""
        kept = self._layout
        if kept is None:
            return False
        ratios = [a / b for a, b in zip(scale, kept[1]) if a > 0 and b > 0]
        return any(max(r, 1.0 / r) > RELAYOUT_ZOOM for r in ratios)

    def to_final_step(self, res) -> None:
        """A new result starts the replay at its final step (a step of another result would
        show contractions that no longer exist)."""
        K = len(res.multicut.contractions)
        self.w_step.end = K + 1
        self.w_step.value = K + 1

    def draw(self, res, frame: int, fine_colors) -> None:
        """Show ``res``'s graph at ``frame`` and the replay's step."""
        if res is None:
            return
        step = int(self.w_step.value)
        key = (res, step, fine_colors)
        layout = self.id_layout(res)
        if (self._tpl_key is None or any(a is not b for a, b in zip(key, self._tpl_key))
                or layout is not self._tpl_layout):
            self._tpls = V.graph_templates(res, step, fine_colors, layout=layout)
            self._tpl_key, self._tpl_layout = key, layout
        track = V.atom_track(res)
        f = int(np.clip(int(frame), 0, max(track[0].shape[0] - 1, 0)))
        d = {k: V.instantiate(t, self.specs[k], *track, f) for k, t in self._tpls.items()}
        live = self.live
        live.set_atoms(res)
        self.r_ids.visible = res.graph.n_nodes <= MAX_ATOM_IDS
        # (step 0, before any contraction, marks nothing either: empty swatches there)
        replaying = 1 <= step <= len(res.multicut.contractions)
        for item in self._step_items:
            if item.visible != replaying:
                item.visible = replaying
        for k, t in self._tpls.items():
            live.template("graph_" + k, t)
        lim = V.cost_limit(res)
        for m in (self.cost_mapper, self.bar_mapper):
            m.low, m.high = -lim, lim
        set_data(self.src_nodes, d["nodes"])
        set_data(self.src_joined, d["joined"])
        set_data(self.src_cut, d["cut"])
        set_data(self.src_step, d["step_edge"])
        set_data(self.src_pair, d["pair"])
        self.fig.title.text = live.text(
            "graph_title", f"{res.graph.n_nodes} atoms, {res.graph.n_edges} edges · frame {{f}} · "
            "{k:graph_nodes.cluster} clusters", f, {"graph_" + k: v for k, v in d.items()})
        seq = self.host.sequence
        if not self.r_ids.visible:
            ids = (f" Atom ids are written up to {MAX_ATOM_IDS} atoms (here {res.graph.n_nodes}: they "
                   "would overlap); hover a node for its id.")
        else:  # (the pair's ids are written with it, not with the nodes)
            left_out = sum(1 for t in self._tpls["nodes"]["label"] if not t) - len(self._tpls["pair"]["text"])
            verb = "is" if left_out == 1 else "are"
            ids = (f" {V.counted(left_out, 'atom id')} that would overlap another id or a node at this zoom "
                   f"{verb} left out: zoom in, or hover a node for its id." if left_out else "")
        self.caption.object = V.replay_caption(res, step, seq is None or seq.is_complete) + ids
        live.commit(f)

    # ------------------------------------------------------------------ callbacks
    def _on_zoom(self, event) -> None:
        """The page's ranges moved: place the ids again when the event's ranges changed the
        scale (a pan does not); the redraw reads the ranges the page sent before its event."""
        try:
            scale = self._scale(event.x0, event.x1, event.y0, event.y1)
        except (AttributeError, TypeError):  # (an event without its ranges)
            return
        if self.zoomed(scale):
            self.host.touch()
            self.host.schedule(self._step_now, now_if_on_doc_thread=True)

    def _on_step(self, event=None) -> None:
        self.host.touch()
        self.host.schedule(self._step_now, now_if_on_doc_thread=True)

    def _step_now(self) -> None:
        h = self.host
        if h.result is None or h.quieted:
            return
        with h.hold(live="draw"):
            self.draw(h.result, h.frame, h.fine_colors)
