"""Card 1 · Atoms: the points of one frame with their trails, atoms, error and change rings.

Its own controls: which layers are drawn (the checkboxes sit in the sidebar's View section)
and, for a sequence tracked from a video (:mod:`explorer.video`), whether that frame of the
video is drawn behind the points (a small grey copy, one byte per pixel over the wire, sent
only when the frame changes).
"""

from __future__ import annotations

import numpy as np
import panel as pn
from bokeh.core.properties import value
from bokeh.models import ColumnDataSource, HoverTool, LinearColorMapper
from bokeh.palettes import Greys256

from .. import views as V
from .base import Host, Markdown, card, fit_image_figure, image_figure, move_legend, set_data
from .live import LiveFrames

EMPTY_POINTS = {"x": [], "y": [], "color": [], "marker": [], "label": [], "detail": [], "index": []}
#: The layers a checkbox shows or hides, in the sidebar's order.
LAYERS = ["trails (last 5 frames)", "atom circles (R1 solid, R2 dashed)",
          "features in no atom (×)", "misclassified (black ring)", "changed motion (purple ring)"]
#: The layer only a sequence with ground truth can show (not offered without one).
TRUTH_LAYER = LAYERS[3]
EMPTY_IMAGE = {"image": [], "x": [], "y": [], "dw": [], "dh": []}
#: Opacity of the video frame over the white figure: light enough for the motion colours.
BACKGROUND_ALPHA = 0.55


class FrameView:
    """The frame view: points, trails (last 5 frames), atom circles, the marks; a caption."""

    def __init__(self, host: Host, extent, live: LiveFrames | None = None) -> None:
        self.host = host
        self.live = live if live is not None else LiveFrames()
        self.specs = V.frame_specs()
        self._tpl_key = None  # (sequence, result, style, moved) of the templates kept
        self._tpls: dict = {}
        self.w_layers = pn.widgets.CheckBoxGroup(options=list(LAYERS), value=list(LAYERS), inline=False)
        self.w_layers.param.watch(self._on_layers, "value")
        self._errors_on = True  # the misclassified layer ticked, while a sequence without truth hides it

        self.src_points = ColumnDataSource(dict(EMPTY_POINTS))
        self.src_trails = ColumnDataSource({"x0": [], "y0": [], "x1": [], "y1": [], "color": [], "alpha": []})
        self.src_atoms = ColumnDataSource({"x": [], "y": [], "r1": [], "r2": [], "color": [], "atom": []})
        self.src_unassigned = ColumnDataSource({"x": [], "y": [], "cross": []})
        self.src_errors = ColumnDataSource({"x": [], "y": []})
        self.src_changed = ColumnDataSource({"x": [], "y": []})
        self.src_background = ColumnDataSource(dict(EMPTY_IMAGE))
        self.video = None  # explorer.video.Video whose frames go behind its sequence's points
        self.w_background = pn.widgets.Checkbox(label="video frame behind the points", value=True,
                                                visible=False)
        self.w_background.param.watch(self._on_background, "value")
        # (toolbar below: at 1024 px the figure with its legend fits the card only so; above,
        # beside the title, it folded its tools into a menu)
        f = self.fig = image_figure("Points at frame 0", 410, extent, toolbar_location="below")
        # row 0 of the image at y = -0.5 (the top: the y axis points down), under everything
        self.r_background = f.image("image", x="x", y="y", dw="dw", dh="dh", source=self.src_background,
                                    color_mapper=LinearColorMapper(Greys256, low=0, high=255),
                                    global_alpha=BACKGROUND_ALPHA, level="image", visible=False)
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
        # a cross inside each point, white or dark by its fill (views.cross_colors; the legend's
        # dark, below)
        self.r_unassigned = f.scatter("x", "y", source=self.src_unassigned, marker="x", size=V.NO_ATOM_SIZE,
                                      line_color="cross", line_width=1.3, legend_label="in no atom")
        self.r_changed = f.scatter("x", "y", source=self.src_changed, marker="circle", size=21,
                                   fill_alpha=0, line_color=V.CHANGED_MARK, line_width=2.5,
                                   legend_label="changed motion")
        self.r_errors = f.scatter("x", "y", source=self.src_errors, marker="circle", size=15,
                                  fill_alpha=0, line_color=V.ERROR_MARK, line_width=2.5,
                                  legend_label="misclassified")
        # (detail: a point's fine model where the legend lists them per motion, else "")
        f.add_tools(HoverTool(renderers=[self.r_points],
                              tooltips=[("point", "@index"), ("", "@label"), ("", "@detail")]))
        move_legend(f)
        items = {getattr(it.label, "value", None): it for it in f.legend[0].items}
        self._item_unassigned = items.get("in no atom")
        self._item_errors = items.get("misclassified")
        self._item_changed = items.get("changed motion")

        # the views the page makes at each frame (explorer/cards/live.py)
        self.live.repaint_alone(f, [self.r_trails, self.r_r2, self.r_r1, self.r_points,
                                    self.r_unassigned, self.r_changed, self.r_errors])
        for name in self.specs:
            self.live.add("frame_" + name, getattr(self, "src_" + name), self.specs[name])
        self.live.detach_legend(f)
        # the legend's cross dark and larger (its stand-in, drawn only there)
        key = self.live.stand_in(self.r_unassigned)
        assert key is not self.r_unassigned, "the unassigned view has no legend stand-in"
        key.glyph.update(line_color=V.NO_ATOM_DARK, size=2 * V.NO_ATOM_SIZE, line_width=1.6)
        # the R2 circle's swatch as dark as R1's (drawn at 0.35, as in the plot, it was barely
        # visible in the legend)
        self.live.stand_in(self.r_r2).glyph.update(line_alpha=0.8)
        self.live.add_text("frame_title", f.title, "text")
        leg = f.legend[0]
        self.live.add_text("frame_unassigned", self._item_unassigned, "label", legend=leg)
        self.live.add_text("frame_changed", self._item_changed, "label", legend=leg)
        self.live.add_text("frame_errors", self._item_errors, "label", legend=leg)

        self._caption = ""  # the caption of the last result, without the background's sentence
        self.caption = Markdown("", sizing_mode="stretch_width", max_width=900, margin=(0, 10))
        self.card = card("1 · Atoms: points, trails and atoms in one frame", pn.pane.Bokeh(self.fig),
                         self.caption)

    def fine_rows(self) -> int:
        """How many fine models the legend lists one by one (views.fine_legend_rows)."""
        return V.fine_legend_rows(self.fig.frame_height)

    def fit(self, seq) -> None:
        fit_image_figure(self.fig, seq.extent())
        self.w_background.visible = self._frames_of(seq) is not None
        self.fit_truth(seq)

    def set_video(self, video) -> None:
        """Draw ``video``'s frames (an :class:`explorer.video.Video`) behind its sequence's points."""
        self.video = video
        self.w_background.visible = video is not None

    def _frames_of(self, seq):
        v = self.video
        return v.frames if v is not None and seq is v.sequence else None

    def draw_background(self, seq, frame: int) -> bool:
        """The video's frame ``frame`` behind the points (when ``seq`` is the video's and the
        toggle is on); only the image column changes, so only it is sent. True when drawn."""
        frames = self._frames_of(seq)
        img = frames.get(frame) if frames is not None and self.w_background.value else None
        shown = img is not None
        if shown:
            set_data(self.src_background, {"image": [img], **{k: [v] for k, v in frames.placement.items()}})
        self.r_background.visible = shown
        self.fig.xgrid.visible = self.fig.ygrid.visible = not shown
        return shown

    def _background_text(self, seq, frame: int) -> str:
        frames = self._frames_of(seq)
        if frames is None:
            return ""
        if not self.w_background.value:
            return " The video frame behind the points is hidden (View: video frame)."
        if frames.get(frame) is None:
            return (f" No copy of video frame {int(frame)} is kept (one frame in {frames.step}, to bound "
                    "memory), so none is drawn behind the points.")
        h, w = frames.shape
        return f" Behind the points: the video's frame {int(frame)}, grey, at {w}x{h} px."

    def draw_raw(self, seq, frame: int = 0) -> None:
        """The raw points of ``seq`` at ``frame`` (ground-truth colours, or grey), before any
        result: the page shows the trajectories while the first computation runs."""
        set_data(self.src_points, V.points_source(seq, frame, V.raw_style(seq)))
        self.draw_background(seq, frame)
        self.fig.title.text = f"frame {int(frame)} of {seq.n_frames - 1} · segmenting…"

    def draw(self, seq, res, frame: int, style: dict, moved, color_label: str) -> None:
        """Show ``res`` at ``frame``, coloured by ``style`` (:func:`views.point_style`); the
        page gets the templates too (:class:`~.live.LiveFrames`) and makes the other frames."""
        if res is None:
            return
        f = int(np.clip(int(frame), 0, seq.n_frames - 1))
        key = (seq, res, style, moved)
        if self._tpl_key is None or any(a is not b for a, b in zip(key, self._tpl_key)):
            self._tpls = V.frame_templates(seq, res, style, moved)
            self._tpl_key = key
        track = V.point_track(seq)
        d = {k: V.instantiate(t, self.specs[k], *track, f) for k, t in self._tpls.items()}
        live = self.live
        live.set_sequence(seq)
        for k, t in self._tpls.items():
            live.template("frame_" + k, t)
        named = {"frame_" + k: v for k, v in d.items()}
        set_data(self.src_points, d["points"])
        set_data(self.src_trails, d["trails"])
        set_data(self.src_atoms, d["atoms"])
        set_data(self.src_unassigned, d["unassigned"])
        set_data(self.src_errors, d["errors"])
        set_data(self.src_changed, d["changed"])
        self.draw_background(seq, f)
        title = f"frame {{f}} of {seq.n_frames - 1} · colour: {color_label}"
        self.fig.title.text = live.text("frame_title", title, f, named)
        if self._item_unassigned is not None:
            self._item_unassigned.label = value(live.text(
                "frame_unassigned", "in no atom: {n:frame_unassigned}", f, named))
        if self._item_changed is not None:
            self._item_changed.label = value(live.text("frame_changed", "changed motion: {n:frame_changed}",
                                                       f, named))
        stage = style.get("stage", "final")
        if self._item_errors is not None:
            self._item_errors.label = value(live.text(
                "frame_errors", f"misclassified ({V.stage_name(stage)}): {{n:frame_errors}}"
                if seq.labels is not None
                else "misclassified: (no truth)", f, named))
        by = V.stage_name(stage) if stage == "plain" else f"the {stage} stage"
        errors = (f"{V.counted(int(style['misclassified'].sum()), 'point')} misclassified by {by} (black "
                  "ring; the colour-by choice picks the stage)" if seq.labels is not None else
                  "no ground truth, so no point is marked misclassified")
        self._caption = (
            f"{res.atoms.n_atoms} atoms (R1 = {res.atoms.r1:g} px solid, R2 = {res.atoms.r2:g} px dashed, "
            f"drawn at their seeds); {V.counted(np.asarray(res.atoms.unassigned).size, 'feature')} in no "
            "atom (×); "
            f"{errors}"
            # (incomplete tracks: a frame shows only the points seen in it, and so does its legend)
            + ("" if seq.is_complete else "; these counts are over every frame, the legend's over "
               "the points seen in this one")
            + ". Click legend entries to hide them.")
        self.caption.object = self._caption + self._background_text(seq, f)
        live.commit(f)

    # ------------------------------------------------------------------ callbacks
    def _on_background(self, event=None) -> None:
        self.host.schedule(self._background_now, now_if_on_doc_thread=True)

    def _background_now(self) -> None:
        seq = self.host.sequence
        with self.host.hold():
            self.draw_background(seq, self.host.frame)
            if self._caption:
                self.caption.object = self._caption + self._background_text(seq, self.host.frame)

    def fit_truth(self, seq) -> None:
        """Offer the misclassified layer only for a sequence with ground truth (without one it
        marks nothing); whether it is ticked is kept for the next sequence with a truth."""
        has_truth = seq.labels is not None
        if (TRUTH_LAYER in self.w_layers.options) == has_truth:
            return
        if has_truth:
            on = set(self.w_layers.value) | ({TRUTH_LAYER} if self._errors_on else set())
            self.w_layers.options = list(LAYERS)
            self.w_layers.value = [n for n in LAYERS if n in on]
        else:
            self._errors_on = TRUTH_LAYER in self.w_layers.value
            self.w_layers.value = [n for n in self.w_layers.value if n != TRUTH_LAYER]
            self.w_layers.options = [n for n in LAYERS if n != TRUTH_LAYER]

    @property
    def error_rings(self) -> bool:
        """Whether the misclassified rings are on: their layer ticked, or for a sequence
        without ground truth (the layer not offered) the choice kept for the next one."""
        if TRUTH_LAYER in self.w_layers.options:
            return TRUTH_LAYER in self.w_layers.value
        return self._errors_on

    @error_rings.setter
    def error_rings(self, on: bool) -> None:
        """Tick or untick the misclassified layer alone (kept for later without a truth)."""
        if TRUTH_LAYER not in self.w_layers.options:
            self._errors_on = bool(on)
        elif self.error_rings != bool(on):
            keep = (set(self.w_layers.value) - {TRUTH_LAYER}) | ({TRUTH_LAYER} if on else set())
            self.w_layers.value = [v for v in self.w_layers.options if v in keep]

    def _on_layers(self, event=None) -> None:
        self.host.schedule(self._layers_now, now_if_on_doc_thread=True)

    def _layers_now(self) -> None:
        on = set(self.w_layers.value)
        for rs, layer in (((self.r_trails,), 0), ((self.r_r1, self.r_r2), 1), ((self.r_unassigned,), 2),
                          ((self.r_errors,), 3), ((self.r_changed,), 4)):
            for r in rs:  # the renderer and its legend entry's stand-in (live.py)
                r.visible = self.live.stand_in(r).visible = LAYERS[layer] in on
