"""The explorer page: widgets -> :class:`~explorer.state.ExplorerState`, results -> views.

One :class:`Explorer` per browser session (``pn.serve`` is given a function), so tabs are
independent. Threads: widget callbacks run on the document's thread; results arrive from
the state's worker thread and are applied on the document's thread through
``doc.add_next_tick_callback`` (raw bokeh models must not be edited from other threads),
all views in one go under ``pn.io.hold``. Without a server document (tests, benchmarks,
notebooks) results are applied directly, under a lock.
"""

from __future__ import annotations

import html
import io
import tempfile
import threading
import time
import urllib.parse
from contextlib import contextmanager
from functools import partial
from pathlib import Path

import numpy as np
import panel as pn
from bokeh.core.properties import value
from bokeh.models import (
    ColorBar,
    ColumnDataSource,
    FactorRange,
    HoverTool,
    Legend,
    LinearColorMapper,
    LogAxis,
    Range1d,
)
from bokeh.palettes import Blues256, RdBu11
from bokeh.plotting import figure
from panel.io.state import set_curdoc

import laav
from laav import LaavParams

from . import export
from . import views as V
from .state import ExplorerState, Settings, non_defaults, parse_settings, query_of, settings_from_json

__all__ = ["Explorer", "PARAM_SLIDERS"]

#: Parameter sliders: LaavParams field -> (label, type, start, end, step).
PARAM_SLIDERS = {
    "r1": ("R1 — inner atom radius (px)", float, 2.0, 100.0, 1.0),
    "r2": ("R2 — outer atom radius (px)", float, 4.0, 160.0, 1.0),
    "lam": ("λ — epipolar voting strength (1/px²)", float, 0.1, 10.0, 0.1),
    "fine_models": ("2C — fine models of the multicut", int, 1, 12, 1),
    "rv_alpha": ("RV α — forgetting factor", float, 0.5, 1.0, 0.01),
    "rv_max_iter": ("RV iteration cap", int, 10, 500, 10),
}

_TOOLS = "pan,wheel_zoom,box_zoom,reset,save"
#: Width of the sidebar's widgets (the sidebar is SIDE_W + 35 px wide). With it, every card
#: fits the main area at 1024 px (checked at 1024x768 and 1280x800 in the browser tests).
SIDE_W = 265
_RV_TOOLS = "pan,wheel_zoom,reset"
_EMPTY_PTS = {"x": [], "y": [], "color": [], "marker": [], "label": [], "index": []}


def _card(title: str, *objs, **kw) -> pn.Card:
    kw.setdefault("sizing_mode", "stretch_width")
    return pn.Card(*objs, title=title, collapsible=False, margin=(6, 6), **kw)


def _flex(*objs, **kw) -> pn.FlexBox:
    """Parts side by side while they fit, wrapped below each other when not."""
    kw.setdefault("sizing_mode", "stretch_width")
    return pn.FlexBox(*objs, flex_wrap="wrap", align_items="flex-start", **kw)


def _image_figure(title: str, frame_width: int, extent, **kw):
    """A bokeh figure in pixel coordinates with the y axis pointing down."""
    x0, x1, y0, y1 = extent
    fh = int(round(frame_width * (y1 - y0) / max(x1 - x0, 1e-9)))
    kw.setdefault("toolbar_location", "right")
    kw.setdefault("tools", _TOOLS)
    fig = figure(title=title, frame_width=frame_width, frame_height=max(fh, 80),
                 x_range=Range1d(x0, x1), y_range=Range1d(y1, y0), match_aspect=True, **kw)
    fig.xaxis.axis_label = "x (px)"
    fig.yaxis.axis_label = "y (px, pointing down)"
    fig.title.text_font_size = "11pt"
    return fig


class Explorer:
    """The LAAV explorer for one sequence (one per browser session).

    Parameters
    ----------
    seq : laav.Sequence
    n_motions : int, optional
        C; required when ``seq`` has no ground truth.
    params : laav.LaavParams, optional
    seed : int
    viser : bool
        Start a viser server for the 3-D view (one per explorer, on a free port).
    viser_host : str
        Interface the viser server binds.
    iframe_host : str, optional
        Host name the browser uses to reach the viser server (default: ``viser_host``,
        or the page's own host when built inside a server session).
    page_hosts : list of str, optional
        Every host name the browser may use for the page; the 3-D view's websocket accepts
        only these origins (default: 127.0.0.1, localhost and ``viser_host``).
    pipeline : Future or laav.Pipeline, optional
        A warm pipeline for exactly these settings (see :class:`ExplorerState`).
    start : bool
        Start computing at once; else call ``explorer.start()`` (the server does so
        once the page is on screen, so the first page is not slowed down by the pipeline).

    Examples
    --------
    >>> Explorer.from_file("cars1_truth.mat")        # doctest: +SKIP  (displays in Jupyter)
    """

    def __init__(self, seq: laav.Sequence, n_motions: int | None = None,
                 params: LaavParams | None = None, seed: int = 0, *, viser: bool = True,
                 viser_host: str = "127.0.0.1", iframe_host: str | None = None, pipeline=None,
                 start: bool = True, page_hosts=None):
        self.state = ExplorerState(seq, n_motions, params, seed, pipeline=pipeline, autostart=False)
        self._session_doc = None
        self._doc_thread = threading.get_ident()
        self._capture_session()
        self._defaults = LaavParams()
        self._suppress = 0
        self._switching = False  # a new sequence is being read or computed (see _lock_for_upload)
        self._apply_lock = threading.RLock()
        self._applied = threading.Condition()
        self.applied_generation = 0
        self.applied_plain_key = None
        self.result: laav.LaavResult | None = None
        self.sequence: laav.Sequence = seq
        self._style = None
        self._fine_colors = None
        self._moved = None
        self.change = None
        self._shown_key = None
        self._plain: laav.Voting | None = None
        self._seq_shown: laav.Sequence | None = None
        # The 3-D view's server starts with the first computation (``start``), in its own
        # thread: importing viser and starting its server (~0.4 s) stays off the page's load.
        self.viser = None
        self._want_viser = bool(viser)
        self._viser_host = viser_host
        self._page_hosts = page_hosts
        self._viser_thread: threading.Thread | None = None
        self._closed = False
        self._iframe_host = iframe_host or (viser_host if viser_host not in ("0.0.0.0", "::") else None)
        self._build_widgets()
        self._build_figures()
        self._build_layout()
        self.state.on_result = self._on_result
        self.state.on_error = self._on_error
        self.state.on_busy = self._on_busy
        self.state.on_plain_rv = self._on_plain_rv
        if start:
            self.start()

    def start(self) -> None:
        """Start the first computation and, alongside it, the 3-D view's server (idempotent)."""
        if self._want_viser and self._viser_thread is None:
            self._viser_thread = threading.Thread(target=self._start_viser, name="laav-explore-viser",
                                                  daemon=True)
            self._viser_thread.start()
        self.state.start()

    def _start_viser(self) -> None:
        try:
            from .viser_view import ViserView

            view = ViserView(host=self._viser_host, on_frame=self._frame_from_viser,
                             page_hosts=self._page_hosts)
        except Exception as exc:  # the 2-D views still work without it
            self._viser_error = f"the 3-D view could not start: {exc}"
            self._schedule(self._show_viser)
            return
        if self._closed:
            view.close()
        else:
            self.viser = view
            # a result applied while the server was still starting (a slow, loaded machine)
            # did not reach it: show the view and send the shown result now
            self._schedule(self._show_viser)

    def _show_viser(self, send: bool = True) -> None:
        """(Document thread.) Put the 3-D view on the page once its server has started (or
        failed) and a result is shown; with ``send``, also give it the shown result."""
        if not self._want_viser or self.result is None or self._closed:
            return
        if self.viser is None and self._viser_thread is not None and self._viser_thread.is_alive():
            return  # still starting: _start_viser calls again when done
        if not self._iframe_shown:
            self._iframe_shown = True
            self.viser_pane.object = self._iframe_html() if self.viser is not None else (
                f"<p><i>{html.escape(getattr(self, '_viser_error', 'the 3-D view did not start'))}"
                "</i></p>")
        if send and self.viser is not None and self.viser._result is not self.result:
            self.viser.set_result(self.sequence, self.result, self._style["color"], self.w_frame.value)

    def _wait_viser(self, timeout: float = 30.0) -> None:
        """Let the 3-D view's server finish starting (it normally has, before the first result)."""
        t = self._viser_thread
        if t is not None and t.is_alive():
            t.join(timeout)

    def _capture_session(self) -> None:
        # Built (or claimed) inside a server session: from now on results go through this
        # document's event loop (the figures join the document while the page is being built,
        # and a worker thread must never touch them during that).
        cur = pn.state.curdoc
        self._session_doc = cur if cur is not None and cur.session_context is not None else None
        self._location = pn.state.location if self._session_doc is not None else None
        self._doc_thread = threading.get_ident()  # the session's event-loop thread

    def attach_session(self) -> None:
        """Adopt the current server session (for an explorer built ahead of time, outside it)."""
        with self._apply_lock:  # an apply running now finishes first; later ones are scheduled
            self._capture_session()
            if self.viser is not None and self._iframe_shown:
                self.viser_pane.object = self._iframe_html()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_file(cls, path, n_motions: int | None = None, **kw) -> Explorer:
        """Explorer for a Hopkins ``*_truth.mat`` or ``.npz`` file (see :func:`laav.load_sequence`)."""
        return cls(laav.load_sequence(path), n_motions, **kw)

    @classmethod
    def demo(cls, **kw) -> Explorer:
        """Explorer for the bundled demo sequence."""
        from .demo import demo_sequence
        return cls(demo_sequence(), **kw)

    # ------------------------------------------------------------------ widgets
    def _build_widgets(self) -> None:
        seq, st = self.sequence, self.state.target
        p = st.params
        self.w_frame = pn.widgets.Player(label="frame", start=0, end=max(seq.n_frames - 1, 1), value=0,
                                         loop_policy="loop", interval=250, width=SIDE_W,
                                         show_loop_controls=False, value_align="start",
                                         scale_buttons=0.8)
        self.w_color = pn.widgets.Select(label="Colour points by", options=list(V.COLOR_MODES),
                                         value="ground truth" if seq.labels is not None
                                         else "final (after Random Voting)", width=SIDE_W)
        self._layer_names = ["trails (last 5 frames)", "atom circles (R1 solid, R2 dashed)",
                             "features in no atom (×)", "misclassified (black ring)",
                             "changed motion (purple ring)"]
        self.w_layers = pn.widgets.CheckBoxGroup(options=self._layer_names, value=list(self._layer_names),
                                                 inline=False)
        self.w_params: dict = {}
        for name, (label, typ, lo, hi, step) in PARAM_SLIDERS.items():
            default = getattr(self._defaults, name)
            if name == "fine_models":
                value = p.n_fine(st.n_motions)
                hi = max(hi, 4 * st.n_motions)
                w = pn.widgets.IntSlider(label=label, start=lo, end=hi, step=step, value=value,
                                                 width=SIDE_W)
            elif typ is int:
                w = pn.widgets.IntSlider(label=label, start=lo, end=max(hi, 2 * default),
                                                 step=step, value=int(getattr(p, name)), width=SIDE_W)
            else:
                w = pn.widgets.FloatSlider(label=label, start=lo, end=max(hi, 2.0 * default)
                                                   if name != "rv_alpha" else hi, step=step,
                                                   value=float(getattr(p, name)), width=SIDE_W)
            w.param.watch(self._on_param, "value")
            self.w_params[name] = w
        self.w_seed = pn.widgets.IntSlider(label="seed (random stages)", start=0, end=99,
                                                   value=st.seed, width=SIDE_W)
        self.w_seed.param.watch(self._on_param, "value")
        # C: at least 1 and at most the number of points (the browser's box clamps to these)
        self.w_motions = pn.widgets.IntInput(label="C — number of motions", start=1, end=seq.n_points,
                                             value=st.n_motions, width=140)
        self.w_motions.param.watch(self._on_param, "value")
        self.w_upload = pn.widgets.FileInput(accept=".mat,.npz,.csv,.json", multiple=False, width=SIDE_W)
        self.w_upload.param.watch(self._on_upload, "value")
        self.w_reset = pn.widgets.Button(label="Reset parameters to defaults", color="warning",
                                         width=SIDE_W)
        self.w_reset.on_click(self._on_reset)
        self.w_dl_csv = pn.widgets.FileDownload(callback=self._export_csv, filename="labels.csv",
                                                label="Labels (CSV)", color="primary",
                                                embed=False, width=SIDE_W)
        self.w_dl_json = pn.widgets.FileDownload(callback=self._export_json, filename="params.json",
                                                 label="Parameters (JSON)", color="primary",
                                                 embed=False, width=SIDE_W)
        self.w_dl_png = pn.widgets.FileDownload(callback=self._export_png, filename="views.png",
                                                label="Views (PNG)", color="primary",
                                                embed=False, width=SIDE_W)
        # a player, not a slider: its range input takes Home/End to the first/last step (the
        # slider's noUiSlider keeps its first range for the End key: it went to step 1), and
        # play steps through the contractions for a class
        self.w_step = pn.widgets.Player(label="GAEC contraction step (rightmost = final fine models)",
                                        start=0, end=1, value=1, interval=600, loop_policy="once",
                                        show_loop_controls=False, value_align="start", scale_buttons=0.8,
                                        width=420)
        self.w_pair_j = pn.widgets.Select(label="epipolar check: j", options=["f1"], width=105)
        self.w_pair_k = pn.widgets.Select(label="and k", options=["f1"], width=105)
        self.w_frame.param.watch(self._on_frame, "value")
        self.w_color.param.watch(self._on_color, "value")
        self.w_layers.param.watch(self._on_layers, "value")
        self.w_step.param.watch(self._on_step, "value")
        self.w_pair_j.param.watch(self._on_pair, "value")
        self.w_pair_k.param.watch(self._on_pair, "value")

    # ------------------------------------------------------------------ figures
    def _build_figures(self) -> None:
        ext = self.sequence.extent()
        # 1 frame view
        self.src_points = ColumnDataSource(dict(_EMPTY_PTS))
        self.src_trails = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": [], "color": [], "alpha": []})
        self.src_atoms = ColumnDataSource({"x": [], "y": [], "r1": [], "r2": [], "color": [], "atom": []})
        self.src_unassigned = ColumnDataSource({"x": [], "y": []})
        self.src_errors = ColumnDataSource({"x": [], "y": []})
        self.src_changed = ColumnDataSource({"x": [], "y": []})
        f = self.fig_frame = _image_figure("Points at frame 0", 410, ext)
        self.r_trails = f.segment("x0", "y0", "x1", "y1", source=self.src_trails, line_color="color",
                                  line_alpha="alpha", line_width=1.5)
        self.r_r2 = f.circle("x", "y", radius="r2", source=self.src_atoms, fill_alpha=0, line_color="color",
                             line_alpha=0.35, line_dash="dashed", line_width=1, legend_label="atom R2")
        self.r_r1 = f.circle("x", "y", radius="r1", source=self.src_atoms, fill_alpha=0.06,
                             fill_color="color", line_color="color", line_alpha=0.7, line_width=1.2,
                             legend_label="atom R1")
        # one colour and marker shape per motion (views.MOTION_COLORS / MOTION_MARKERS)
        self.r_points = f.scatter("x", "y", source=self.src_points, size=7, fill_color="color",
                                  marker="marker", line_color="#333333", line_width=0.4,
                                  legend_field="label")
        self.r_unassigned = f.scatter("x", "y", source=self.src_unassigned, marker="x", size=7,
                                      line_color=V.NO_ATOM, line_width=1.5, legend_label="in no atom")
        self.r_changed = f.scatter("x", "y", source=self.src_changed, marker="circle", size=21,
                                   fill_alpha=0, line_color=V.CHANGED_MARK, line_width=2.5,
                                   legend_label="changed motion")
        self.r_errors = f.scatter("x", "y", source=self.src_errors, marker="circle", size=15,
                                  fill_alpha=0, line_color=V.ERROR_MARK, line_width=2.5,
                                  legend_label="misclassified")
        f.add_tools(HoverTool(renderers=[self.r_points], tooltips=[("point", "@index"), ("", "@label")]))
        self._move_legend(f)
        items = {getattr(it.label, "value", None): it for it in f.legend[0].items}
        self._item_unassigned = items.get("in no atom")
        self._item_errors = items.get("misclassified")
        self._item_changed = items.get("changed motion")

        # 2 multicut graph
        # RdBu11 runs blue -> red; cost > 0 (join) is blue
        self.cost_mapper = LinearColorMapper(palette=list(RdBu11)[::-1], low=-1, high=1)
        g = self.fig_graph = _image_figure("Atom graph at frame 0", 410, ext)
        empty_e = {"x0": [], "y0": [], "x1": [], "y1": [], "cost": [], "error": [], "a": [], "b": []}
        self.src_joined = ColumnDataSource(dict(empty_e))
        self.src_cut = ColumnDataSource(dict(empty_e))
        self.src_step = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": []})
        self.src_nodes = ColumnDataSource({"x": [], "y": [], "color": [], "cluster": [], "atom": [],
                                           "members": [], "size": [], "label": []})
        self.src_pair = ColumnDataSource({"x": [], "y": [], "color": [], "size": [], "atom": []})
        g.segment("x0", "y0", "x1", "y1", source=self.src_step, line_color="#222222", line_alpha=0.35,
                  line_width=10, legend_label="contracted at this step")
        by_cost = {"field": "cost", "transform": self.cost_mapper}
        g.segment("x0", "y0", "x1", "y1", source=self.src_joined, line_width=2.5, line_color=by_cost,
                  legend_label="kept edge (solid)")
        g.segment("x0", "y0", "x1", "y1", source=self.src_cut, line_width=1.8, line_dash="dashed",
                  line_color=by_cost, legend_label="cut edge (dashed)")
        r_nodes = g.scatter("x", "y", source=self.src_nodes, size="size", fill_color="color",
                            line_color="black", line_width=0.8, legend_label="atom (colour = cluster)")
        # atom ids beside the nodes; the pair joined at this step on top of everything, ringed
        g.text("x", "y", text="label", source=self.src_nodes, x_offset=6, y_offset=-4,
               text_font_size="7pt", text_color="#333333")
        g.scatter("x", "y", source=self.src_pair, size="size", fill_color="color", line_color="#111111",
                  line_width=3, legend_label="joined at this step (ringed)")
        g.add_tools(HoverTool(renderers=[r_nodes], tooltips=[("atom", "@atom"), ("cluster", "@cluster"),
                                                             ("features", "@members")]))
        g.add_layout(ColorBar(color_mapper=self.cost_mapper, title="edge cost: + join (blue), − cut (red)",
                              orientation="horizontal", height=8, title_text_font_size="9pt",
                              padding=4), "below")
        self._move_legend(g)

        # 3 coarse merges
        self.z_mapper = LinearColorMapper(palette=list(Blues256[::-1]), low=0, high=1)
        self.src_z = ColumnDataSource({"x": [], "y": [], "z": [], "text": [], "text_color": [], "d": [],
                                       "j": [], "k": []})
        z = self.fig_z = figure(title="Affinity Z of fine-model pairs", width=320, height=320,
                                x_range=FactorRange(factors=["f1"]), y_range=FactorRange(factors=["f1"]),
                                tools="hover", toolbar_location=None,
                                tooltips=[("pair", "f@j, f@k"), ("Z", "@text"), ("epipolar distance", "@d")])
        z.rect("x", "y", 1, 1, source=self.src_z, fill_color={"field": "z", "transform": self.z_mapper},
               line_color="white")
        z.text("x", "y", text="text", source=self.src_z, text_align="center", text_baseline="middle",
               text_font_size="9pt", text_color="text_color")
        z.xaxis.major_label_orientation = 0.8
        z.xaxis.axis_label = "fine model → motion it joined"
        z.yaxis.axis_label = "fine model → motion"
        z.grid.visible = False
        z.add_layout(ColorBar(color_mapper=self.z_mapper, width=8, padding=2), "right")
        self.z_pane_title = z.title
        empty_p = {"x": [], "y": [], "color": [], "model": []}
        self.src_epi_l = ColumnDataSource(dict(empty_p))
        self.src_epi_r = ColumnDataSource(dict(empty_p))
        self.src_epi_lines = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": [], "color": []})
        self.fig_epi_l = _image_figure("frame l", 200, ext, toolbar_location=None, tools="")
        self.fig_epi_r = _image_figure("frame r with epipolar lines", 200, ext, toolbar_location=None,
                                       tools="")
        self.fig_epi_r.x_range = self.fig_epi_l.x_range
        self.fig_epi_r.y_range = self.fig_epi_l.y_range
        for fig, src in ((self.fig_epi_l, self.src_epi_l), (self.fig_epi_r, self.src_epi_r)):
            fig.scatter("x", "y", source=src, size=5, fill_color="color", line_color="color",
                        legend_field="model")
            leg = fig.legend[0]
            fig.center = [c for c in fig.center if not isinstance(c, Legend)]
            leg.orientation = "horizontal"
            leg.label_text_font_size = "8pt"
            leg.padding = 2
            leg.margin = 2
            fig.add_layout(leg, "below")
            fig.title.text_font_size = "10pt"
        self.fig_epi_r.segment("x0", "y0", "x1", "y1", source=self.src_epi_lines, line_color="color",
                               line_alpha=0.55, line_width=1)

        # 4 RV convergence
        empty_rv = {"iteration": [], "changed": [], "changed_plot": [], "margin": []}
        self.src_rv_laav = ColumnDataSource(dict(empty_rv))
        self.src_rv_plain = ColumnDataSource(dict(empty_rv))
        self.fig_rv_changed = figure(title="Labels changed per iteration", width=440, height=235,
                                     y_axis_type="log", tools=_RV_TOOLS, toolbar_location="above")
        self.fig_rv_margin = figure(title="Mean vote margin per iteration", width=440, height=235,
                                    tools=_RV_TOOLS, toolbar_location="above")
        for fig, col, ylab in ((self.fig_rv_changed, "changed_plot", "labels changed (0 drawn as ½)"),
                               (self.fig_rv_margin, "margin", "(best − 2nd best) / sum of votes")):
            # neutral greys: colours mean motions on this page
            fig.line("iteration", col, source=self.src_rv_laav, line_width=2.5, color="#222222",
                     legend_label="LAAV's informed trial")
            fig.line("iteration", col, source=self.src_rv_plain, line_width=2, color="#8C8C8C",
                     line_dash="dashed", legend_label="plain RV (random start)")
            fig.xaxis.axis_label = "Random Voting iteration"
            fig.yaxis.axis_label = ylab
            fig.legend.location = "top_right" if col == "changed_plot" else "bottom_right"
            fig.legend.background_fill_alpha = 0.7
            fig.title.text_font_size = "11pt"
        assert isinstance(self.fig_rv_changed.yaxis[0], LogAxis)

    @staticmethod
    def _move_legend(fig) -> None:
        leg = fig.legend[0]
        fig.renderers  # noqa: B018 (legend already built)
        fig.center = [c for c in fig.center if not isinstance(c, Legend)]
        leg.location = "top_left"
        leg.label_text_font_size = "9pt"
        leg.spacing = 0
        leg.padding = 4
        leg.click_policy = "hide"
        fig.add_layout(leg, "right")

    # ------------------------------------------------------------------ layout
    def _build_layout(self) -> None:
        seq = self.sequence
        self.alert = pn.pane.Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                                   margin=(4, 6))
        self.note = pn.pane.Alert("", alert_type="info", visible=False, sizing_mode="stretch_width",
                                  margin=(4, 6))
        # problems with the settings a shared URL carried (kept until the next URL)
        self.url_alert = pn.pane.Alert("", alert_type="warning", visible=False, sizing_mode="stretch_width",
                                       margin=(4, 6))
        self.spinner = pn.indicators.LoadingSpinner(value=True, size=22, margin=(8, 6))
        self._status_text = "Computing the first result…"
        self.status = pn.pane.Markdown(self._status_text, margin=(4, 6),
                                       sizing_mode="stretch_width")
        self.change_md = pn.pane.Markdown("", margin=(0, 10), visible=False, sizing_mode="stretch_width")
        self.seq_info = pn.pane.Markdown(self._seq_text(seq), width=SIDE_W, margin=(0, 10))
        # the sequence shown, in the page header (the template's own title is fixed at load)
        # the browser tab's title follows the sequence shown (bokeh's document title is sent
        # once, with the page): a hidden box whose value the page copies into document.title
        self._tab_title = pn.widgets.TextInput(value="", visible=False, margin=0, width=0)
        self._tab_title.jscallback(value="document.title = cb_obj.value")
        self.header_name = pn.pane.Markdown(self._header_text(seq), margin=(0, 10),
                                            styles={"color": "white", "font-size": "1.25em"})
        self.numbers = pn.pane.Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        self.graph_caption = pn.pane.Markdown("", sizing_mode="stretch_width", max_width=820, margin=(0, 10))
        self.merge_md = pn.pane.Markdown("", width=340, margin=(0, 6))
        self.epi_caption = pn.pane.Markdown("", sizing_mode="stretch_width", max_width=800, margin=(0, 10))
        self.rv_md = pn.pane.Markdown("", sizing_mode="stretch_width", max_width=820, margin=(0, 10))
        self.frame_caption = pn.pane.Markdown("", sizing_mode="stretch_width", max_width=900, margin=(0, 10))
        if self._want_viser:
            # the iframe is set with the first result: the 3-D client's WebGL loop then does not
            # compete with the first computation (it is costly in software-rendered browsers)
            self._iframe_shown = False
            self.viser_pane = pn.pane.HTML(
                '<div style="width:100%;height:440px;border:1px solid #ccc;border-radius:4px;'
                'display:flex;align-items:center;justify-content:center;color:#666">'
                "The 3-D view opens with the first result…</div>", height=440, margin=0,
                sizing_mode="stretch_width", max_width=900)
        else:
            msg = getattr(self, "_viser_error", "the 3-D view is switched off")
            self.viser_pane = pn.pane.Markdown(f"*{V.md_text(msg)}*", sizing_mode="stretch_width",
                                               height=60)
        self.sidebar = [
            pn.pane.Markdown("### Sequence", margin=(0, 10)), self.seq_info,
            pn.pane.Markdown("Open another sequence (`.mat`, `.npz` or tracks `.csv`), or a `params.json` "
                             "exported here:", margin=(0, 10)),
            self.w_upload, self.w_motions,
            pn.pane.Markdown("### View", margin=(0, 10)), self.w_frame, self.w_color, self.w_layers,
            pn.pane.Markdown("### Parameters", margin=(0, 10)),
            *self.w_params.values(), self.w_seed, self.w_reset,
            pn.pane.Markdown("### Export", margin=(0, 10)), self.w_dl_csv, self.w_dl_json, self.w_dl_png,
            self._tab_title,
        ]
        # cards in the order of the stages; each lays its parts out in a wrapping FlexBox, so
        # they sit side by side on a wide screen and stack on a projector (1024 px)
        self.v_frame = _card("1 · Atoms: points, trails and atoms in one frame",
                             pn.pane.Bokeh(self.fig_frame), self.frame_caption)
        self.v_viser = pn.Card(self.viser_pane, title="3-D space-time view (viser): trajectories along the "
                               "frame axis, atoms and their graph", collapsible=True, collapsed=False,
                               margin=(6, 6), sizing_mode="stretch_width")
        self.v_graph = _card("2 · Multicut graph of atoms → fine models (GAEC replay)",
                             pn.pane.Bokeh(self.fig_graph), self.w_step, self.graph_caption)
        self.v_coarse = _card(
            "3 · Fine-to-coarse: fine models merged into motions",
            _flex(pn.pane.Bokeh(self.fig_z), self.merge_md,
                  pn.Column(pn.Row(self.w_pair_j, self.w_pair_k),
                            _flex(pn.pane.Bokeh(self.fig_epi_l), pn.pane.Bokeh(self.fig_epi_r)),
                            self.epi_caption, max_width=580, sizing_mode="stretch_width")))
        self.v_rv = _card("4 · Fine-tuning (Random Voting): LAAV's start vs plain RV",
                          _flex(pn.pane.Bokeh(self.fig_rv_changed), pn.pane.Bokeh(self.fig_rv_margin)),
                          self.rv_md)
        self.v_numbers = _card("5 · Final labels and numbers: every stage against the ground truth",
                               self.numbers)
        self.main = [
            pn.Column(pn.Row(self.spinner, self.status, sizing_mode="stretch_width"), self.change_md,
                      sizing_mode="stretch_width"), self.alert, self.url_alert, self.note,
            self.v_frame, self.v_viser, self.v_graph, self.v_coarse, self.v_rv, self.v_numbers,
        ]

    def _iframe_html(self) -> str:
        host = self._iframe_host
        if host is None:
            hdr = (pn.state.headers or {}).get("Host", "") if pn.state.curdoc else ""
            host = hdr.rsplit(":", 1)[0] if hdr else "127.0.0.1"
        return (f'<iframe src="http://{host}:{self.viser.port}/" title="LAAV 3-D view (viser)" '
                'style="width:100%;height:440px;border:1px solid #ccc;border-radius:4px;'
                'box-sizing:border-box"></iframe>')

    @staticmethod
    def _header_text(seq: laav.Sequence) -> str:
        return f"{V.md_text(seq.name)} · {seq.n_points} points, {seq.n_frames} frames"

    @staticmethod
    def _seq_text(seq: laav.Sequence) -> str:
        gt = f"{seq.n_motions} motions in the ground truth" if seq.labels is not None else \
            "**no ground truth** (set C below)"
        return f"**{V.md_text(seq.name)}**: {seq.n_points} points, {seq.n_frames} frames, {gt}."

    def template(self, title: str = "LAAV explorer", lazy: bool | None = None):
        """The page (a BootstrapTemplate: loads all its resources from the server).

        ``lazy`` (default: when served) sends the atoms and 3-D cards first and adds the
        later stages' cards (graph, fine-to-coarse, RV, numbers) once the page has loaded, so
        the page appears sooner.
        """
        n_first = 6  # status, alerts, note, atoms card, 3-D card
        if lazy is None:
            lazy = self._session_doc is not None
        main = pn.Column(*(self.main[:n_first] if lazy else self.main), sizing_mode="stretch_width")
        if lazy:
            rest = self.main[n_first:]
            pn.state.onload(lambda: main.extend(rest))
        self.main_column = main
        # one root per area: every extra document root costs a full model walk on page load.
        # The header's button folds the sidebar away.
        return pn.template.BootstrapTemplate(
            title=title, sidebar=[pn.Column(*self.sidebar, sizing_mode="stretch_width")],
            header=[self.header_name], main=[main], sidebar_width=SIDE_W + 35, header_background="#2c4a66")

    def panel(self) -> pn.viewable.Viewable:
        """The whole explorer as one panel layout (for notebooks)."""
        return pn.Row(pn.Column(*self.sidebar, width=SIDE_W + 30), pn.Column(*self.main, width=760))

    def _repr_mimebundle_(self, include=None, exclude=None):
        return self.panel()._repr_mimebundle_(include, exclude)

    def servable(self, title: str = "LAAV explorer"):
        return self.template(title).servable()

    # ------------------------------------------------------------------ threading
    def _doc(self):
        return self._session_doc or self.fig_frame.document

    def _schedule(self, fn, *args, now_if_on_doc_thread: bool = False) -> None:
        """Run ``fn(*args)`` on the document's thread (or now, under a lock, without a server)."""
        doc = self._doc()
        on_doc_thread = self._session_doc is not None and threading.get_ident() == self._doc_thread
        if doc is not None and doc.session_context is not None and not (now_if_on_doc_thread
                                                                         and on_doc_thread):
            try:
                doc.add_next_tick_callback(partial(self._locked, fn, *args))
                return
            except Exception:  # the session is gone
                return
        self._locked(fn, *args)

    def _locked(self, fn, *args) -> None:
        # panel applies pane changes at once only for the document it is processing
        # (pn.state.curdoc); otherwise it defers them, and a deferred change could land
        # outside our batch
        with self._apply_lock, set_curdoc(self._session_doc):
            try:
                fn(*args)
            except Exception:
                import traceback
                traceback.print_exc()

    @contextmanager
    def _hold(self):
        """Send all model changes made inside as one batch (bokeh's own document hold; the
        callers run on the document's thread, under its lock)."""
        doc = self._doc()
        if doc is None or doc.session_context is None or doc.callbacks.hold_value is not None:
            yield
            return
        doc.hold("combine")
        try:
            yield
        finally:
            doc.unhold()

    # state hooks (worker threads)
    def _on_result(self, result, seq, settings, gen) -> None:
        self._schedule(self._apply_result, result, seq, settings, gen)

    def _on_error(self, message: str) -> None:
        self._schedule(self._show_error, message)

    def _on_busy(self, busy: bool) -> None:
        self._schedule(self._show_busy, busy)

    def _on_plain_rv(self, voting, key) -> None:
        self._schedule(self._apply_plain_rv, voting, key)

    def _frame_from_viser(self, frame: int) -> None:
        self._schedule(setattr, self.w_frame, "value", int(frame))

    # ------------------------------------------------------------------ applying results
    def _apply_result(self, result, seq, settings, gen) -> None:
        if gen < self.applied_generation:
            return
        t0 = time.perf_counter()
        new_seq = seq is not self._seq_shown
        self._suppress += 1
        try:
            with self._hold():
                if new_seq:
                    self._set_sequence_widgets(seq, settings)
                self.result, self.sequence = result, seq
                self.change = self.state.change_of(result) if not new_seq else None
                self._moved = None if self.change is None else self.change.moved
                plain = self.state.plain_rv()
                self._style = V.point_style(seq, result, V.COLOR_MODES[self.w_color.value], plain)
                self._fine_colors = V.fine_colors(seq, result)
                # a new result starts the replay at its final step (a step of another result
                # would show contractions that no longer exist)
                K = len(result.multicut.contractions)
                self.w_step.end = K + 1
                self.w_step.value = K + 1
                n = int(np.asarray(result.coarse.fine_to_coarse).size)
                opts = [f"f{j + 1}" for j in range(max(n, 1))]
                if list(self.w_pair_j.options) != opts:
                    self.w_pair_j.options, self.w_pair_k.options = opts, opts
                    self.w_pair_j.value, self.w_pair_k.value = opts[0], opts[min(1, len(opts) - 1)]
                self._draw_frame()
                self._draw_graph()
                self._draw_coarse()
                self._draw_epipolar()
                self._draw_rv(result.voting, self.state.plain_rv())
                num = V.stage_numbers(seq, result, plain)
                self.numbers.object = V.numbers_markdown(num)
                self.alert.visible = self.state.error is not None
                notes = [n for n in (self._style["note"],) if n]
                if seq.labels is None:
                    notes.append(f"{V.md_text(seq.name)} has no ground truth: errors cannot be scored; C = "
                                 f"{settings.n_motions} is taken from the C box.")
                self.note.object = "  \n".join(notes)
                self.note.visible = bool(notes)
                ef = num["error_final"]
                err = "" if ef is None else f" — final error **{100 * ef:.1f} %**"
                changed = non_defaults(settings, self.state.default_motions(seq))
                self.status.object = self._status_text = (
                    f"Showing {V.md_text(seq.name)}{err} (computed in "
                    f"{1000 * self.state.compute_seconds:.0f} ms). "
                    + (f"Not at the defaults: {V.md_text(', '.join(changed))}." if changed
                       else "All settings at their defaults."))
                self.change_md.object = ("" if self.change is None else
                                         f"**What changed:** {V.md_text(self.change.text())}")
                self.change_md.visible = self.change is not None
                if self._want_viser and not self._iframe_shown:
                    self._wait_viser(5.0)  # normally done long before; else _show_viser follows
                    self._show_viser(send=False)
            if self.viser is not None:
                if new_seq or self.viser._result is None:
                    self.viser.set_result(seq, result, self._style["color"], self.w_frame.value)
                else:
                    self.viser._seq = seq
                    self.viser._result = result
                    self.viser.set_colors(self._style["color"])
            self._seq_shown = seq
            self._sync_url()
        finally:
            self._suppress -= 1
        self.apply_seconds = time.perf_counter() - t0
        with self._applied:
            self.applied_generation = gen
            self._applied.notify_all()

    def _set_sequence_widgets(self, seq, settings) -> None:
        x0, x1, y0, y1 = seq.extent()
        for fig in (self.fig_frame, self.fig_graph, self.fig_epi_l):
            fig.x_range.start, fig.x_range.end = x0, x1
            fig.y_range.start, fig.y_range.end = y1, y0
            fw = fig.frame_width
            fig.frame_height = max(int(round(fw * (y1 - y0) / max(x1 - x0, 1e-9))), 80)
        self.fig_epi_r.frame_height = self.fig_epi_l.frame_height
        self.w_frame.end = max(seq.n_frames - 1, 1)
        if self.w_frame.value > seq.n_frames - 1:
            self.w_frame.value = 0
        self.w_motions.value = settings.n_motions
        self._lock_for_upload(False)
        fm = self.w_params["fine_models"]
        fm.end = max(fm.end, 4 * settings.n_motions)
        self.seq_info.object = self._seq_text(seq)
        self.header_name.object = self._header_text(seq)
        self.w_motions.end = seq.n_points
        self._tab_title.value = f"LAAV explorer: {laav.safe_name(seq.name)}"  # the browser tab
        for w, ext in ((self.w_dl_csv, "labels.csv"), (self.w_dl_json, "params.json"),
                       (self.w_dl_png, "views.png")):
            w.filename = f"{laav.safe_name(seq.name)}_{ext}"
        mode = V.COLOR_MODES[self.w_color.value]
        if seq.labels is None and (mode == "gt" or mode.startswith("errors")):
            self.w_color.value = "final (after Random Voting)"
        elif seq.labels is not None and self._seq_shown is not None and self.sequence.labels is None:
            self.w_color.value = "ground truth"
        self._sync_param_widgets(settings)

    def _sync_param_widgets(self, settings) -> None:
        """After a load, show the settings actually used (never after a slider move: the
        widgets may already be ahead of the result being applied)."""
        p = settings.params
        for name, w in self.w_params.items():
            v = p.n_fine(settings.n_motions) if name == "fine_models" else getattr(p, name)
            if self.state.error is None and w.value != v:
                w.value = v
        if self.state.error is None and self.w_seed.value != settings.seed:
            self.w_seed.value = settings.seed

    def _draw_frame(self) -> None:
        res, seq = self.result, self.sequence
        if res is None:
            return
        f = int(self.w_frame.value)
        d = V.frame_sources(seq, res, f, self._style, moved=self._moved)
        self.src_points.data = d["points"]
        self.src_trails.data = d["trails"]
        self.src_atoms.data = d["atoms"]
        self.src_unassigned.data = d["unassigned"]
        self.src_errors.data = d["errors"]
        self.src_changed.data = d["changed"]
        self.fig_frame.title.text = f"frame {f} of {seq.n_frames - 1} · colour: {self.w_color.value}"
        n_un, n_bad = len(d["unassigned"]["x"]), len(d["errors"]["x"])
        if self._item_unassigned is not None:
            self._item_unassigned.label = value(f"in no atom: {n_un}")
        if self._item_changed is not None:
            n_mv = len(d["changed"]["x"])
            self._item_changed.label = value(f"changed motion: {n_mv}")
        stage = self._style.get("stage", "final")
        if self._item_errors is not None:
            self._item_errors.label = value(f"misclassified ({stage}): {n_bad}" if seq.labels is not None
                                            else "misclassified: (no truth)")
        self.frame_caption.object = (
            f"{res.atoms.n_atoms} atoms (R1 = {res.atoms.r1:g} px solid, R2 = {res.atoms.r2:g} px dashed, "
            f"drawn at their seeds); {np.asarray(res.atoms.unassigned).size} features in no atom (×); "
            f"{int(self._style['misclassified'].sum())} points misclassified by the {stage} stage (black "
            "ring; the colour-by choice picks the stage). Click legend entries to hide them.")

    def _draw_graph(self) -> None:
        res = self.result
        if res is None:
            return
        f, step = int(self.w_frame.value), int(self.w_step.value)
        d = V.graph_sources(res, f, step, self._fine_colors)
        lim = V.cost_limit(res)
        self.cost_mapper.low, self.cost_mapper.high = -lim, lim
        self.src_nodes.data = d["nodes"]
        self.src_joined.data = d["joined"]
        self.src_cut.data = d["cut"]
        self.src_step.data = d["step_edge"]
        self.src_pair.data = d["pair"]
        self.fig_graph.title.text = (f"{res.graph.n_nodes} atoms, {res.graph.n_edges} edges · frame {f} · "
                                     f"{len(np.unique(d['nodes']['cluster']))} clusters")
        self.graph_caption.object = V.replay_caption(res, step)

    def _draw_coarse(self) -> None:
        res, seq = self.result, self.sequence
        data, factors = V.z_sources(res, seq)
        self.fig_z.x_range.factors = factors or ["–"]
        self.fig_z.y_range.factors = list(reversed(factors)) or ["–"]
        self.src_z.data = data
        self.fig_z.title.text = f"Affinity Z (λ = {res.params.lam:g}): {len(factors)} fine models"
        self.merge_md.object = ("**Which fine model joined which motion** (spectral clustering of Z):\n\n"
                                + V.merge_table(seq, res))

    def _pair(self) -> tuple[int, int]:
        def idx(w):
            try:
                return int(str(w.value)[1:]) - 1
            except ValueError:
                return 0
        return idx(self.w_pair_j), idx(self.w_pair_k)

    def _draw_epipolar(self) -> None:
        res, seq = self.result, self.sequence
        j, k = self._pair()
        d = V.epipolar_sources(seq, res, j, k)
        self.src_epi_l.data = d["left"]
        self.src_epi_r.data = d["right"]
        self.src_epi_lines.data = d["lines"]
        fl, fr = d["frames"]
        self.fig_epi_l.title.text = f"frame l = {fl}: f{j + 1} and f{k + 1}"
        self.fig_epi_r.title.text = f"frame r = {fr}: lines of F(f{j + 1}, f{k + 1})"
        if not d["ok"]:
            self.epi_caption.object = "No fundamental matrix for this pair (too few points)."
            return
        f2c = np.asarray(res.coarse.fine_to_coarse)
        same = "the same motion" if f2c[j] == f2c[k] else "different motions"
        self.epi_caption.object = (
            f"One F is fitted on all points of f{j + 1} and f{k + 1} between frames {fl} and {fr}; each "
            f"frame-l point gives a line in frame r. If one rigid motion explains both models, their "
            f"frame-r points lie on their lines. Mean distance to the lines: f{j + 1} "
            f"**{d['residual_j']:.1f} px**, f{k + 1} **{d['residual_k']:.1f} px** (mean epipolar distance "
            f"behind Z: {d['distance']:.1f} px²). Spectral clustering put them in {same}.")

    def _draw_rv(self, laav_voting, plain) -> None:
        self.src_rv_laav.data = V.rv_sources(laav_voting)
        self.src_rv_plain.data = V.rv_sources(plain)
        self._plain = plain
        self.rv_md.object = V.rv_summary(laav_voting, plain)

    def _apply_plain_rv(self, voting, key) -> None:
        if self.result is None or key != self.state.plain_rv_key():
            return
        with self._hold():
            self._draw_rv(self.result.voting, voting)
            self.numbers.object = V.numbers_markdown(V.stage_numbers(self.sequence, self.result, voting))
            if V.COLOR_MODES[self.w_color.value] in ("plain", "errors_plain"):
                self._color_now()
        with self._applied:
            self.applied_plain_key = key
            self._applied.notify_all()

    def _lock_for_upload(self, locked: bool) -> None:
        """While another sequence is read and first computed, the C box (which belongs to the
        sequence) is locked and slider moves keep the C of the sequence being loaded."""
        self._switching = locked
        self.w_motions.disabled = locked
        if not locked and self.status.object.startswith("Reading "):
            self.status.object = self._status_text  # the read failed: back to what is shown

    def _show_error(self, message: str) -> None:
        self._lock_for_upload(False)
        self.alert.object = f"**Cannot use these settings:** {V.md_text(message)}"
        self.alert.visible = True

    def _show_busy(self, busy: bool) -> None:
        self.spinner.value = bool(busy)
        if busy and self.result is not None:
            self.status.object = "Recomputing… (the views keep the last result until the new one is ready)"

    # ------------------------------------------------------------------ widget callbacks
    def _widget_params(self) -> dict:
        out = {}
        C = int(self.w_motions.value or 1)
        for name, w in self.w_params.items():
            v = w.value
            if name == "fine_models":
                v = None if int(v) == 2 * C and self._defaults.fine_models is None else int(v)
            elif isinstance(getattr(self._defaults, name), float):
                v = float(v)
            else:
                v = int(v)
            out[name] = v
        return out

    def _on_param(self, event=None) -> None:
        if self._suppress:
            return
        if event is not None and event.obj is self.w_motions:
            fm = self.w_params["fine_models"]
            old = event.old if isinstance(event.old, int) else None
            if old is not None and fm.value == 2 * old:
                self._suppress += 1
                fm.end = max(fm.end, 4 * int(event.new or 1))
                fm.value = 2 * int(event.new or 1)
                self._suppress -= 1
        C = None if self._switching or self.w_motions.value is None else int(self.w_motions.value)
        self.state.request(params=self._widget_params(), seed=int(self.w_seed.value), n_motions=C)

    def _on_reset(self, event=None) -> None:
        """Every parameter (with or without a control here), and the seed, to its default."""
        d = self._defaults
        self._suppress += 1
        try:
            C = int(self.w_motions.value or 1)
            for name, w in self.w_params.items():
                w.value = d.n_fine(C) if name == "fine_models" else getattr(d, name)
            self.w_seed.value = 0
        finally:
            self._suppress -= 1
        C = None if self._switching or self.w_motions.value is None else int(self.w_motions.value)
        self.state.request(params={**d.to_dict(), **self._widget_params()}, seed=0, n_motions=C)

    def _on_frame(self, event=None) -> None:
        self._schedule(self._frame_now, now_if_on_doc_thread=True)

    def _frame_now(self) -> None:
        if self.result is None or self._suppress:
            return
        with self._hold():
            self._draw_frame()
            self._draw_graph()
            self._sync_url()
        if self.viser is not None:
            self.viser.set_frame(int(self.w_frame.value))

    def _on_color(self, event=None) -> None:
        self._schedule(self._color_now, now_if_on_doc_thread=True)

    def _color_now(self) -> None:
        if self.result is None:
            return
        self._style = V.point_style(self.sequence, self.result, V.COLOR_MODES[self.w_color.value],
                                    self.state.plain_rv())
        with self._hold():
            self._draw_frame()
            self.note.object = self._style["note"]
            self.note.visible = bool(self._style["note"])
            self._sync_url()
        if self.viser is not None:
            self.viser.set_colors(self._style["color"])

    def _on_layers(self, event=None) -> None:
        self._schedule(self._layers_now, now_if_on_doc_thread=True)

    def _layers_now(self) -> None:
        on = set(self.w_layers.value)
        names = self._layer_names
        self.r_trails.visible = names[0] in on
        self.r_r1.visible = self.r_r2.visible = names[1] in on
        self.r_unassigned.visible = names[2] in on
        self.r_errors.visible = names[3] in on
        self.r_changed.visible = names[4] in on

    def _on_step(self, event=None) -> None:
        self._schedule(self._step_now, now_if_on_doc_thread=True)

    def _step_now(self) -> None:
        if self.result is None or self._suppress:
            return
        with self._hold():
            self._draw_graph()

    def _on_pair(self, event=None) -> None:
        self._schedule(self._pair_now, now_if_on_doc_thread=True)

    def _pair_now(self) -> None:
        if self.result is None or self._suppress:
            return
        with self._hold():
            self._draw_epipolar()

    # ------------------------------------------------------------------ shared state (URL, params.json)
    def _default_color(self, seq=None) -> str:
        seq = self.sequence if seq is None else seq
        return "gt" if seq.labels is not None else "final"

    def _show_settings(self, settings: Settings) -> None:
        """Put ``settings`` on the controls without triggering a computation."""
        self._suppress += 1
        try:
            C = settings.n_motions
            fm = self.w_params["fine_models"]
            fm.end = max(fm.end, 4 * C, settings.params.n_fine(C))
            for name, w in self.w_params.items():
                v = settings.params.n_fine(C) if name == "fine_models" else getattr(settings.params, name)
                if name != "fine_models":
                    w.start, w.end = min(w.start, v), max(w.end, v)
                w.value = v
            self.w_seed.end = max(self.w_seed.end, settings.seed)
            self.w_seed.value = settings.seed
            self.w_motions.value = C
        finally:
            self._suppress -= 1

    def apply_query(self, pairs: dict) -> list[str]:
        """Take the settings and view a page URL's query carries (see :data:`state.URL_KEYS`).

        Every value is validated (:func:`state.parse_settings`); what cannot be used is
        listed in a warning on the page, as text, and the rest is applied. Before
        :meth:`start` the first computation uses them; afterwards they are requested."""
        pairs = {k: v for k, v in pairs.items() if not str(k).startswith("bokeh")}
        if not pairs:
            return []
        new, view, problems = parse_settings(pairs, self.sequence, self.state.target)
        if not self.state._started:
            self.state.retarget(new)
        else:
            self.state.request(params=new.params.to_dict(), seed=new.seed, n_motions=new.n_motions)
        self._show_settings(new)
        modes = {v: k for k, v in V.COLOR_MODES.items()}
        if "color" in view:
            self.w_color.value = modes[view["color"]]
        if "frame" in view:
            self.w_frame.value = view["frame"]
        self.url_alert.object = ("" if not problems else "**Some settings in the page address were not "
                                 "used:** " + "; ".join(V.md_text(m) for m in problems))
        self.url_alert.visible = bool(problems)
        return problems

    def query(self) -> dict[str, str]:
        """The URL query of what the page shows now (only what differs from the defaults)."""
        return query_of(self.state.settings, self.state.default_motions(), int(self.w_frame.value),
                        V.COLOR_MODES[self.w_color.value], self._default_color())

    def _sync_url(self) -> None:
        """(Document thread.) The page address carries the shown state (pushState, no reload)."""
        loc = self._location
        if loc is None or self.result is None:
            return
        q = self.query()
        search = "?" + urllib.parse.urlencode(q) if q else ""
        if loc.search != search:
            loc.search = search

    def load_params(self, data: bytes | str, filename: str = "params.json") -> bool:
        """Apply a params.json (as exported here). False, and a message, when it is not valid."""
        try:
            new = settings_from_json(data, self.sequence, self.state.target)
        except ValueError as exc:
            self.state.report(f"{Path(filename).name}: {exc} — nothing was changed")
            return False
        self._schedule(self._show_settings, new)
        return self.state.request(params=new.params.to_dict(), seed=new.seed,
                                  n_motions=new.n_motions) is not None

    def _on_upload(self, event=None) -> None:
        data, name = self.w_upload.value, self.w_upload.filename or "upload"
        if data is None:
            return
        if len(data) == 0:
            self.state.report(f"{Path(name).name} is empty (0 bytes): nothing was loaded")
            return
        if data.lstrip()[:1] == b"{":  # a params.json (a sequence file never starts so)
            self.load_params(data, name)
            return
        if self._session_doc is None:
            self.load_bytes(data, name)
            return
        self._lock_for_upload(True)
        # reading (a MAT file is parsed in a child process) must not block the page
        self.status.object = f"Reading {V.md_text(Path(name).name)}…"
        threading.Thread(target=self.load_bytes, args=(data, name), name="laav-explore-upload",
                         daemon=True).start()

    def load_bytes(self, data: bytes, filename: str) -> bool:
        """Load an uploaded ``.mat`` / ``.npz`` (bytes). Returns False (and shows why) on failure."""
        base = Path(filename).name or "upload"
        C = int(self.w_motions.value or 1)  # read before locking: the C for a file without labels
        self._switching = True
        if not self._load_bytes(data, base, C):
            self._schedule(self._lock_for_upload, False)
            return False
        return True

    def _load_bytes(self, data: bytes, base: str, C: int) -> bool:
        try:
            with tempfile.TemporaryDirectory(prefix="laav-explore-") as d:
                p = Path(d) / laav.safe_name(base, "upload")
                p.write_bytes(data)
                try:
                    # the format comes from the content, whatever the name says; MAT content
                    # is parsed in a child process (scipy's reader can crash the interpreter
                    # on some damaged files, and an upload must never do that)
                    seq = laav.load_sequence(p, isolated=True)
                    laav.require_complete(seq)  # the last good result stays (issue 14)
                except laav.SequenceError as exc:
                    self.state.report(str(exc).replace(str(p), base)
                                      + " — still showing the last valid result")
                    return False
        except Exception as exc:  # never let an upload kill the session
            self.state.report(f"{base}: could not be read ({type(exc).__name__}: {exc})")
            return False
        return self.state.load(seq, None if seq.labels is not None else C) is not None

    # ------------------------------------------------------------------ exports
    def _need_result(self):
        if self.result is None:
            raise RuntimeError("no result yet")
        return self.sequence, self.result

    def _export_csv(self):
        seq, res = self._need_result()
        return io.StringIO(export.labels_csv(seq, res))

    def _export_json(self):
        seq, res = self._need_result()
        return io.StringIO(export.params_json(seq, res))

    def _export_png(self):
        seq, res = self._need_result()
        return io.BytesIO(export.views_png(seq, res, int(self.w_frame.value),
                                           V.COLOR_MODES[self.w_color.value], int(self.w_step.value),
                                           self._plain))

    # ------------------------------------------------------------------ testing / teardown
    def wait(self, timeout: float = 60.0, plain_rv: bool = False) -> bool:
        """Block until the newest request's result (or error) is on the views."""
        deadline = time.monotonic() + timeout
        if not self.state.wait(timeout):
            return False
        with self._applied:
            while self.applied_generation < self.state.published_generation:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._applied.wait(left)
            if plain_rv:
                while self.applied_plain_key != self.state.plain_rv_key():
                    left = deadline - time.monotonic()
                    if left <= 0:
                        return False
                    self._applied.wait(left)
        return True

    def close(self) -> None:
        self._closed = True
        self.state.close()
        self._wait_viser()
        if self.viser is not None:
            self.viser.close()
