"""The explorer page: widgets -> :class:`~explorer.state.ExplorerState`, results -> views.

The page is made of cards, each in its own module of :mod:`explorer.cards` with its
widgets, figures, drawing and callbacks; :class:`Explorer` composes them, passes each
result to them and keeps the page address in step.

One :class:`Explorer` per browser session (``pn.serve`` is given a function), so tabs are
independent. Threads: widget callbacks run on the document's thread; results arrive from
the state's worker thread and are applied on the document's thread through
``doc.add_next_tick_callback`` (raw bokeh models must not be edited from other threads),
all views in one go under ``pn.io.hold``. Without a server document (tests, benchmarks,
notebooks) results are applied directly, under a lock.
"""

from __future__ import annotations

import dataclasses
import threading
import time
import weakref
from operator import attrgetter

import panel as pn

import laav
from laav import LaavParams

from . import views as V
from .address import PageAddress
from .cards.advanced import AdvancedPanel
from .cards.base import SIDE_W, Markdown
from .cards.coarse import CoarseView
from .cards.compare import CompareView
from .cards.controls import FINE_PER_MOTION_END, PARAM_SLIDERS, Controls
from .cards.files import DEFAULT_MAX_UPLOAD, Files
from .cards.frame import FrameView
from .cards.graph import GraphView
from .cards.live import LiveFrames
from .cards.numbers import NumbersView
from .cards.onscreen import paint_on_screen_script
from .cards.rv import RVView
from .cards.status import StatusBar
from .cards.sweep import SweepView
from .cards.tour import TourView
from .cards.view3d import View3D
from .session import DocumentSession
from .state import (
    ExplorerState,
    Origin,
    non_defaults,
)

__all__ = ["Explorer", "PARAM_SLIDERS", "SIDE_W", "REST_AFTER_S"]

#: Seconds after the page has loaded at which the later cards are added even without a
#: result (a long first computation; see :meth:`Explorer.template`).
REST_AFTER_S = 3.0

#: Seconds between a result applied and the later cards sent (when they are still to come):
#: time for the page to draw that result first. Sent at once, their ~300 new models took the
#: page ~0.7 s to build and lay out before it showed the result's status line (demo, headless
#: Chromium on the 2-core VM, 8 interleaved starts each: first result 4.12-5.49 s, median 4.46,
#: against 4.72-6.23 s, median 5.2; the later cards came sooner too).
REST_GAP_S = 0.4

#: Seconds a computation runs before the status line's spinner and "Recomputing…" show: a
#: shorter one shows its result only. Shown at once, they were two document changes before
#: every move's computation and one after it, each a message the server wrote (the page's
#: ~800 models indexed for each: bokeh's PATCH-DOC) and the page applied and laid out, on
#: moves whose computation took 5 ms (a λ move on the demo).
BUSY_SHOW_AFTER_S = 0.25

#: Seconds the frame rests before the page address takes it (``frame=``; while the player
#: plays, once it pauses). The address is a document change the server sends after every frame
#: move and the page applies; the page draws a frame move itself (``cards/live.py``), and that
#: message landed among the next animation frames of a scrub or of the player (1R2RCT_A,
#: headless Chromium, 16 moves 300 ms apart, four interleaved pairs of runs: median frame move
#: 2.3-6.2 ms lower with the address sent once the frame rests, in each pair; the address then
#: came 250 ms later; docs/bench/explorer_browser_latency_2026-12-06b.md).
FRAME_ADDRESS_REST_S = 0.25

#: The cards' widgets, sources and panes that tests, benchmarks and notebooks reach on the
#: explorer itself (the same objects): name -> where it lives.
SHORTCUTS = {
    **{n: f"controls.{n}" for n in ("w_frame", "w_color", "w_params", "w_seed", "w_motions", "w_reset")},
    **{n: f"files.{n}" for n in ("w_upload", "w_dl_csv", "w_dl_json", "w_dl_png", "seq_info")},
    **{n: f"status_bar.{n}" for n in ("alert", "note", "url_alert", "check_alert", "status", "change_md")},
    **{n: f"frame_view.{n}" for n in ("w_layers", "src_points", "src_atoms", "src_errors", "src_changed",
                                      "r_changed")},
    "fig_frame": "frame_view.fig", "frame_caption": "frame_view.caption",
    **{n: f"graph_view.{n}" for n in ("w_step", "src_nodes", "src_cut", "src_pair")},
    "fig_graph": "graph_view.fig", "graph_caption": "graph_view.caption",
    **{n: f"coarse_view.{n}" for n in ("src_z", "fig_z")},
    **{n: f"rv_view.{n}" for n in ("src_rv_laav", "src_rv_plain", "rv_md")},
    "numbers": "numbers_view.numbers",
    "viser_pane": "view3d.pane",
    # the cards in page order
    "v_frame": "frame_view.card", "v_viser": "view3d.card", "v_graph": "graph_view.card",
    "v_coarse": "coarse_view.card", "v_rv": "rv_view.card", "v_numbers": "numbers_view.card",
}


def _keep_panel_queue_moving() -> None:
    """Mend a race in panel's queue of messages (panel 1.9, ``panel.io.document``).

    ``unlocked`` queues a batch's message when bokeh is writing to the socket and schedules
    ``_dispatch_msgs`` to send the queue. A dispatch that is still awaiting its writes when
    another batch is queued then clears the queue's flag on its way out, and the dispatch
    scheduled for the new batch returns at once on seeing no flag: that message stays queued
    until some later batch comes (a result's address change never reached the page in one CI
    run: ``test_url_carries_the_state``). Wrapped: a dispatch that finds messages waiting
    sends them whatever the flag."""
    import panel.io.document as pdoc

    if getattr(pdoc._dispatch_msgs, "_laav_mended", False):
        return
    original = pdoc._dispatch_msgs

    async def _dispatch_msgs(doc):
        if doc not in pdoc._WRITE_BLOCK and pdoc._WRITE_MSGS.get(doc):
            pdoc._WRITE_BLOCK[doc] = True  # messages left behind by a dispatch that ended
        return await original(doc)

    _dispatch_msgs._laav_mended = True
    pdoc._dispatch_msgs = _dispatch_msgs  # looked up by name where panel schedules it


_keep_panel_queue_moving()

#: The upload box's library, FilePond, paints through one loop that asks for an animation
#: frame 60 times a second for as long as the page is open (``window.__framePainter``;
#: FilePond itself switches to a timer only while the page is hidden). Every such frame
#: makes the browser recompute style, layout and paint and commit a frame: on the 2-core VM
#: the idle page took 121 ms of its main thread per second (plus ~80 ms of compositor
#: threads) for nothing, time every result and frame move then shared. Once the document
#: is ready, this routes that one loop's frame requests to a timer at the same rate, as
#: FilePond does for a hidden page: its readers and writers still run 60 times a second, but
#: the browser makes a frame only when one of them changes something (idle main thread 121
#: -> 17 ms per second, measured in headless Chromium). Every other caller keeps the real
#: ``requestAnimationFrame``.
JS_THROTTLE_FILEPOND = r"""
if (window.__laavPainterThrottled) return;
window.__laavPainterThrottled = true;
const raf = window.requestAnimationFrame.bind(window);
const caf = window.cancelAnimationFrame.bind(window);
const pond = new WeakMap();  // callback -> is FilePond's painter loop
const timers = new Map();  // our id -> timeout id
let next = -1;  // our ids are negative: never one of the browser's
const isPond = (cb) => {
  if (typeof cb !== 'function') return false;
  let v = pond.get(cb);
  if (v === undefined) {
    v = String(cb).includes('.readers.forEach(') && String(cb).includes('.writers.forEach(');
    pond.set(cb, v);
  }
  return v;
};
window.requestAnimationFrame = (cb) => {
  if (!isPond(cb)) return raf(cb);
  const id = next--;
  timers.set(id, setTimeout(() => { timers.delete(id); cb(performance.now()); }, 1000 / 60));
  return id;
};
window.cancelAnimationFrame = (id) => {
  if (timers.has(id)) { clearTimeout(timers.get(id)); timers.delete(id); return; }
  caf(id);
};
"""


class _Template(pn.template.BootstrapTemplate):
    """The page's template, its document built with bokeh's model index frozen.

    Building the page's document (about 870 models) made bokeh walk every model of the
    document again after each root added and each JavaScript link panel attached (14 walks,
    0.6 s of the 1.4 s it took on the demo, measured in-process); frozen, it walks once at
    the end: the page's HTML is served that much sooner."""

    #: CustomJS scripts run when the served page's document is ready (the app's own:
    #: :meth:`Explorer.template`)
    ready_scripts: tuple = ()

    def server_doc(self, doc=None, title=None, location=True):
        # (panel's Location is kept: its template embeds it; the address is written by the
        # status bar's own box, StatusBar.address)
        if doc is None:  # panel finds the document itself
            doc = super().server_doc(doc, title, location)
        else:
            with doc.models.freeze():
                doc = super().server_doc(doc, title, location)
        from bokeh.models import CustomJS

        doc.js_on_event("document_ready", CustomJS(code=JS_THROTTLE_FILEPOND))
        for script in self.ready_scripts:
            doc.js_on_event("document_ready", script)
        return doc


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
        or the page's own host when built inside a server session); a page at a loopback
        name gets the other loopback name where it reaches the server (a process of its own
        for the 3-D view: :func:`explorer.cards.view3d.iframe_host`).
    page_hosts : list of str, optional
        Every host name the browser may use for the page; the 3-D view's websocket accepts
        only these origins (default: 127.0.0.1, localhost and ``viser_host``).
    pipeline : Future or laav.Pipeline, optional
        A warm pipeline for ``seq`` (see :class:`ExplorerState`).
    plain_rv : Future, optional
        Plain RV's run for these settings, computed elsewhere (see :class:`ExplorerState`).
    preview : Future, optional
        The warm pipeline's preview (see :class:`ExplorerState`).
    seeds_ahead : bool
        Compute the next seed's result while idle, so that a step of the seed slider shows
        it at once (see :class:`ExplorerState`; ``laav-explore`` turns it on).
    start : bool
        Start computing at once; else call ``explorer.start()`` (the server does so
        once the page is on screen, so the first page is not slowed down by the pipeline).
    max_upload : int
        Largest upload accepted, in bytes (``laav-explore --max-upload``).
    video : explorer.video.Video, optional
        The tracked video ``seq`` comes from (:func:`explorer.video.open_video`): its frames
        are drawn behind the points, and the page says how the tracks were made.
    origin : explorer.state.Origin, optional
        How ``seq`` came from its file (``laav-explore FILE``: C estimated, tracks dropped by
        ``--complete-only``): what the page's note says about it, and the file's point
        numbers in the labels CSV.

    Examples
    --------
    >>> Explorer.from_file("cars1_truth.mat")        # doctest: +SKIP  (displays in Jupyter)
    >>> Explorer.from_file("clip.mp4")               # doctest: +SKIP  (tracks it first)
    """

    def __init__(self, seq: laav.Sequence, n_motions: int | None = None,
                 params: LaavParams | None = None, seed: int = 0, *, viser: bool = True,
                 viser_host: str = "127.0.0.1", iframe_host: str | None = None, pipeline=None,
                 start: bool = True, page_hosts=None, max_upload: int = DEFAULT_MAX_UPLOAD, video=None,
                 plain_rv=None, seeds_ahead: bool = False, preview=None, origin=None):
        if video is not None and video.sequence is not seq:
            raise ValueError("video must be the one seq was tracked from (video.sequence is seq)")
        self.video = video
        #: how the sequences opened came from their files (:class:`explorer.state.Origin`);
        #: weak keys: a replaced upload's sequence is freed
        self._origins = weakref.WeakKeyDictionary()
        self._origin_lock = threading.Lock()  # (uploads add from their own thread)
        if video is not None and video.motion_count is not None:  # a video's C was estimated
            origin = dataclasses.replace(origin or Origin(), motions_estimate=video.n_motions,
                                         motions_reason=video.motion_count.explain())
        if origin is not None:
            self.add_origin(seq, origin)
        self.state = ExplorerState(seq, n_motions, params, seed, pipeline=pipeline, autostart=False,
                                   plain_rv=plain_rv, seeds_ahead=seeds_ahead, preview=preview)
        self._seeds_ahead = seeds_ahead  # (held back while a lazy page is still being completed)
        #: the page's document, its thread and the batching of changes (explorer.session)
        self.session = DocumentSession(lambda: self.frame_view.fig.document, lambda: self.live)
        self._defaults = LaavParams()
        #: the state's busy period (a token; None: idle), for BUSY_SHOW_AFTER_S
        self._busy_period: object | None = None
        self._busy_lock = threading.Lock()
        self._applied = threading.Condition()
        self.applied_generation = 0
        self.applied_plain_key = None
        #: the views show a preview (LAAV's own fine-tuning; the result is on its way)
        self.previewing = False
        #: the result shown whose drawn votes are being fitted (ExplorerState.fit_votes;
        #: card 3 draws them when they arrive), or None
        self.votes_pending = None
        self._unpinned_note = None  # the compare card's note when a sequence is opened
        self._data_notes: list[str] = []  # the note's lines about the data shown (data_notes)
        # what the views show: the result, its sequence, the point colours
        # (views.point_style), the fine models' colours, the points whose motion changed
        self.result: laav.LaavResult | None = None
        self.sequence: laav.Sequence = seq
        #: the page address and params.json (explorer.address)
        self.address = PageAddress(self, seq)
        self._frame_address_timer = None  # the pending address after a frame move
        self.settings = self.state.target  # (of the result shown, once there is one)
        self.style = None
        self.fine_colors = None
        self.moved = None
        self.change = None
        self._seq_shown: laav.Sequence | None = None
        self._rest: dict | None = None  # the later cards, until they are on the page (template)
        #: called once (document thread) when the served page is complete: its later cards
        #: added (``laav-explore`` then lets Python's garbage collector run again)
        self.on_page_complete = None
        self.main_column = self.sidebar_column = None

        ext = seq.extent()
        self.controls = Controls(self, self.state, seq, self._defaults)
        self.status_bar = StatusBar(seq)
        self.files = Files(self, self.state, self.controls, self.status_bar, seq, self._png_view,
                           max_upload=max_upload)
        # the views that follow the frame, made by the page itself at each frame move
        self.live = LiveFrames()
        self.frame_view = FrameView(self, ext, self.live)
        self.frame_view.set_video(video)
        self.frame_view.draw_raw(seq)  # in the first page already: the points before any compute
        if video is not None:  # how the tracks were made, from the first page on
            self.status_bar.show_note(V.md_text(video.summary()))
        # the 3-D view's server starts at its card's first unfold (``View3D.start``)
        self.view3d = View3D(self, viser, viser_host, page_hosts,
                             iframe_host or (viser_host if viser_host not in ("0.0.0.0", "::") else None),
                             on_frame=self._frame_from_viser)
        self.graph_view = GraphView(self, ext, self.live)
        self.coarse_view = CoarseView(self, ext)
        self.rv_view = RVView()
        self.numbers_view = NumbersView()
        self.sweep_view = SweepView(self, self.state, self.controls)
        self.advanced = AdvancedPanel(self, self.state, self.controls)
        self.compare = CompareView(self, self.state, self.controls, ext)
        self.tour = TourView(self, self.controls, {
            "frame": self.frame_view.card, "view3d": self.view3d.card, "graph": self.graph_view.card,
            "coarse": self.coarse_view.card, "rv": self.rv_view.card, "numbers": self.numbers_view.card,
            "sweep": self.sweep_view.card, "compare": self.compare.card})
        # the view controls that redraw more than one card
        self.controls.w_frame.param.watch(self._on_frame, "value")
        self.live.link(self.controls.w_frame)
        self.controls.w_color.param.watch(self._on_color, "value")
        for name, where in SHORTCUTS.items():
            setattr(self, name, attrgetter(where)(self))
        self._compose()

        self.state.on_result = self._on_result
        self.state.on_preview = self._on_preview
        self.state.on_error = self._on_error
        self.state.on_busy = self._on_busy
        self.state.on_plain_rv = self._on_plain_rv
        self.state.on_votes = self._on_votes
        self.state.on_target = self._on_target
        if start:
            self.start()

    def start(self) -> None:
        """Start the first computation (idempotent); the 3-D view's server starts when its
        card is first unfolded (:class:`~explorer.cards.view3d.View3D`), or now when
        ``view3d.eager``."""
        if self.view3d.eager:
            self.view3d.start()
        self.state.start()
        self.files.arm()  # the upload box's browser-side checks, the progress line
        if self._rest is None:  # (with lazy cards: once they are on the page)
            self.state.preload()

    @property
    def viser(self):
        """The 3-D view's :class:`~explorer.viser_view.ViserView` (None until it has started)."""
        return self.view3d.viser

    def attach_session(self) -> None:
        """Adopt the current server session (for an explorer built ahead of time, outside it)."""
        with self.session.apply_lock:  # an apply running now finishes first; later ones are scheduled
            self.session.capture()
            self.view3d.reattach()

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_file(cls, path, n_motions: int | None = None, **kw) -> Explorer:
        """Explorer for a sequence file (Hopkins ``*_truth.mat``, KT3DMoSeg ``.mat``, ``.npz``,
        tracks ``.csv``: see :func:`laav.load_sequence`), or for a video or a folder of frames
        (told apart by content, :func:`explorer.video.is_video`), which
        :meth:`from_video` tracks first."""
        from .video import is_video

        if is_video(path):
            return cls.from_video(path, n_motions, **kw)
        return cls(laav.load_sequence(path), n_motions, **kw)

    @classmethod
    def from_video(cls, path, n_motions: int | str | None = None, *, track: dict | None = None,
                   progress: bool | None = True, complete_only: bool = False, **kw) -> Explorer:
        """Track a video (or a folder of frames), keep every track the tracker keeps (only those
        seen in every frame with ``complete_only``), and explore them with the video's frames
        behind the points.

        ``n_motions``: C, or None / ``"auto"`` to estimate it (:func:`laav.estimate_motions`).
        ``track``: keyword arguments of :func:`laav.track.track` (``stride``, ``max_points``,
        ``max_frames``, ...). ``progress``: the tracker's progress bar (in a notebook, in the
        cell). Raises :class:`explorer.video.VideoError` (one line) for a video that cannot be
        used. Tracking runs here, before the explorer is built.
        """
        from .video import open_video

        video = open_video(path, n_motions, track_options=track, progress=progress,
                           complete_only=complete_only)
        return cls(video.sequence, video.n_motions, video=video, **kw)

    @classmethod
    def demo(cls, **kw) -> Explorer:
        """Explorer for the bundled demo sequence."""
        from .demo import demo_sequence
        return cls(demo_sequence(), **kw)

    # ------------------------------------------------------------------ layout
    def _compose(self) -> None:
        c, f, s = self.controls, self.files, self.status_bar

        def heading(text):
            return Markdown(f"### {text}", margin=(0, 10))

        # the tour's panel heads the sidebar (hidden until a tour starts): beside the step's
        # card, as slides put text beside a figure (see explorer/cards/tour.py)
        self.sidebar = [
            self.tour.panel, heading("Sequence"), f.seq_info,
            Markdown("Open another sequence (`.mat`, `.npz` or tracks `.csv`), or a `params.json` "
                     "exported here (a video is tracked on the command line only: "
                     "`laav-explore VIDEO`):", margin=(0, 10)),
            f.w_upload, f.upload_hint, c.w_motions,
            heading("View"), self.tour.w_start, c.w_frame, c.w_color, self.frame_view.w_layers,
            self.frame_view.w_background,
            heading("Parameters"), *c.w_params.values(), c.w_seed, c.w_reset, self.advanced.card,
            heading("Compare"), *self.compare.sidebar,
            heading("Export"), *f.downloads,
            s.tab_title, s.address, f.w_refused,
        ]
        s.line.insert(1, f.progress)  # long work: its progress and a Cancel button
        # cards in the order of the stages; each lays its parts out in a wrapping FlexBox, so
        # they sit side by side on a wide screen and stack on a projector (1024 px)
        self.main = [
            s.line, s.alert, s.check_alert, s.url_alert, s.note, self.compare.card,
            self.frame_view.card, self.view3d.card, self.graph_view.card, self.coarse_view.card,
            self.rv_view.card, self.numbers_view.card, self.sweep_view.card,
        ]

    def template(self, title: str = "LAAV explorer", lazy: bool | None = None):
        """The page (a BootstrapTemplate: loads all its resources from the server).

        ``lazy`` (default: when served) sends the atoms and 3-D cards first and adds the
        later stages' cards (graph, fine-to-coarse, RV, numbers) once the page has loaded and
        the first result is shown (:data:`REST_GAP_S` after it is applied; or
        :data:`REST_AFTER_S` after the page loaded, whichever comes first), so that the page
        and then the first result appear sooner: the browser draws those cards once, with
        their data, after the status line and the points. The compare card, hidden until
        asked for, comes with them (:meth:`complete_page`); the tour's panel, hidden in the
        sidebar, comes with the first page.
        """
        n_first = self.main.index(self.view3d.card) + 1  # status, alerts, note, atoms, 3-D
        if lazy is None:
            lazy = self.session.on_server
        # the compare card is hidden until asked for: it comes with the later cards (or at
        # once when asked for first: :meth:`complete_page`)
        hidden = (id(self.compare.card),)
        first = [c for c in self.main[:n_first] if not (lazy and id(c) in hidden)]
        main = pn.Column(*(first if lazy else self.main), sizing_mode="stretch_width")
        self.main_column = main
        # (the tour's panel, hidden, is sent with the first sidebar: put in front of it later,
        # it made bokeh lay the whole sidebar out again, which blurs a box being typed in)
        self.sidebar_column = pn.Column(*self.sidebar, sizing_mode="stretch_width")
        self._rest = None
        self._rest_timer = None  # the pending _add_rest_after
        if lazy:
            self._rest = {"cards": [c for c in self.main if all(c is not f for f in first)],
                          "loaded": False}
            pn.state.onload(self._page_loaded)
            self.state.seeds_ahead = False  # not while the page is being completed (_add_rest)
        # one root per area: every extra document root costs a full model walk on page load.
        # The header's button folds the sidebar away. No panel busy indicator: it turned on
        # and off around every change from the page (two more messages per move, each making
        # the browser lay the whole page out again; the frame player had been exempted);
        # the status line's own spinner shows a computation.
        page = _Template(
            title=title, sidebar=[self.sidebar_column],
            header=[self.status_bar.header_name], main=[main], sidebar_width=SIDE_W + 35,
            header_background="#2c4a66", busy_indicator=None)
        page.ready_scripts = (
            self.live.clip_script(),  # overlay glyphs clipped to their frame
            paint_on_screen_script(self.frame_view.fig),  # plots off screen painted when seen
        )
        return page

    def _page_loaded(self) -> None:
        """(Document thread.) The page is on screen: the later cards follow the first result
        (or come after :data:`REST_AFTER_S` without one)."""
        if self._rest is None:
            return
        self._rest["loaded"] = True
        shown = self.result is not None or self.state.error is not None
        self._add_rest_after(REST_GAP_S if shown else REST_AFTER_S)

    def _add_rest_after(self, seconds: float) -> None:
        """(Document thread.) :meth:`_add_rest` in ``seconds`` (now without a server),
        replacing a timer set before (the 3 s one must not fire just after a result)."""
        self._rest_timer = self._after(self._rest_timer, self._add_rest, seconds)

    def _add_rest(self) -> None:
        """(Document thread.) The later stages' cards onto the page, once (see :meth:`template`);
        then the pipeline's first-use imports, if still to do (:meth:`ExplorerState.preload`)."""
        rest = self._rest
        if rest is None or not rest["loaded"]:
            return
        self._rest = None
        self.main_column.objects = list(self.main)  # (in stage order; those shown are kept)
        done, self.on_page_complete = self.on_page_complete, None
        if done is not None:
            done()
        self.state.preload()
        if self._seeds_ahead:  # the page is complete: the next seed may be computed now
            self.state.seeds_ahead = True
            self.state.compute_ahead()

    def complete_page(self) -> None:
        """(Document thread.) The later cards onto the page now, if still to come (the tour
        or a pin asks for its card before they came)."""
        if self._rest is not None:
            self._rest["loaded"] = True
            self._add_rest()

    def panel(self) -> pn.viewable.Viewable:
        """The whole explorer as one panel layout (for notebooks)."""
        return pn.Row(pn.Column(*self.sidebar, width=SIDE_W + 30), pn.Column(*self.main, width=760))

    def _repr_mimebundle_(self, include=None, exclude=None):
        return self.panel()._repr_mimebundle_(include, exclude)

    def servable(self, title: str = "LAAV explorer"):
        return self.template(title).servable()

    # ------------------------------------------------------------------ threading (the cards' host)
    # (explorer.session.DocumentSession: what the cards' Host protocol names, delegated)
    @property
    def on_server(self) -> bool:
        """Built in (or adopted by) a server session."""
        return self.session.on_server

    @property
    def quieted(self) -> bool:
        """The app is putting values on widgets (see :meth:`quiet`): callbacks do nothing."""
        return self.session.quieted

    def quiet(self):
        """Widget changes made inside request and redraw nothing (a context manager)."""
        return self.session.quiet()

    def _doc(self):
        return self.session.doc()

    def _served_doc(self):
        return self.session.served_doc()

    def _after(self, old, fn, seconds: float):
        return self.session.after(old, fn, seconds)

    def schedule(self, fn, *args, now_if_on_doc_thread: bool = False) -> None:
        """Run ``fn(*args)`` on the document's thread (or now, under a lock, without a server)."""
        self.session.schedule(fn, *args, now_if_on_doc_thread=now_if_on_doc_thread)

    def hold(self, freeze: bool = False, live: str | None = None):
        """The model changes made inside go out as one batch (a context manager; see
        :meth:`explorer.session.DocumentSession.hold`)."""
        return self.session.hold(freeze, live)

    @property
    def frame(self) -> int:
        """The frame shown."""
        return int(self.controls.w_frame.value)

    # state hooks (worker threads)
    def _on_result(self, result, seq, settings, gen) -> None:
        self.schedule(self._apply_result, result, seq, settings, gen)

    def _on_preview(self, result, seq, settings, gen) -> None:
        self.schedule(self._apply_result, result, seq, settings, gen, True)

    def _on_error(self, message: str) -> None:
        self.schedule(self._show_error, message)

    def _on_busy(self, busy: bool) -> None:
        self.sweep_view.settings_changed()  # other parameters, C or sequence: the sweep stops
        with self._busy_lock:
            if busy and self._busy_period is not None:
                return  # busy already: its spinner shows, or will when its time has passed
            period = self._busy_period = object() if busy else None
        if not busy or BUSY_SHOW_AFTER_S <= 0:
            self.schedule(self._show_busy, busy)
            return
        timer = threading.Timer(BUSY_SHOW_AFTER_S, self._busy_for_long, (period,))
        timer.daemon = True
        timer.start()

    def _busy_for_long(self, period: object) -> None:
        """(A timer's thread.) The busy ``period`` has lasted BUSY_SHOW_AFTER_S: shown, if it
        has not ended."""
        if self._busy_period is period:
            self.schedule(self._show_busy, True)

    def _on_plain_rv(self, voting, key) -> None:
        self.schedule(self._apply_plain_rv, voting, key)

    def _on_votes(self, result, dropped: bool = False) -> None:
        self.schedule(self._apply_votes, result, dropped)

    def _on_target(self, settings) -> None:
        self.schedule(self.advanced.show, settings, now_if_on_doc_thread=True)

    def _frame_from_viser(self, frame: int) -> None:
        self.schedule(setattr, self.controls.w_frame, "value", int(frame))

    # ------------------------------------------------------------------ results -> cards
    def _apply_result(self, result, seq, settings, gen, preview: bool = False) -> None:
        """Every card to ``result``. A ``preview`` (LAAV's own fine-tuning while the rest of
        the fine-tuning computes; :attr:`ExplorerState.on_preview`) is drawn as a result, its
        status line saying so, and is not yet the applied generation (:meth:`wait`); a
        preview for a request a newer one (or a cancel) has replaced is not drawn (its
        result will not come, and a cancel's :meth:`restore_result` may have run already)."""
        if gen < self.applied_generation or (preview and gen == self.applied_generation):
            return
        if preview and gen < self.state.generation:
            return
        was_preview, self.previewing = self.previewing, preview
        t0 = time.perf_counter()
        new_seq = seq is not self._seq_shown
        with self.quiet():
            with self.hold(freeze=new_seq, live="draw"):
                self.files.exports_ready(not preview)  # (with previewing, before any drawing)
                unpinned = None
                if new_seq:
                    self._set_sequence(seq, settings)
                    unpinned = self.compare.sequence_changed(seq)
                elif was_preview:  # the preview opened this sequence: its note stays
                    unpinned = self._unpinned_note
                self._unpinned_note = unpinned
                self.result, self.sequence, self.settings = result, seq, settings
                self.change = self.state.change_of(result) if not new_seq else None
                self.moved = None if self.change is None else self.change.moved
                plain = self.state.plain_rv(seq, settings)  # (a preview's: not computed yet)
                self.style = V.point_style(seq, result, self.controls.color_mode, plain,
                                           fine_rows=self.frame_view.fine_rows())
                self.fine_colors = V.fine_colors(seq, result)
                self.graph_view.to_final_step(result)
                self.coarse_view.epipolar.set_models(result)
                self._draw_frame()
                self.graph_view.draw(result, self.frame, self.fine_colors)
                self.coarse_view.draw(seq, result)
                self.coarse_view.epipolar.draw(seq, result)
                own = preview and V.own_chain_preview(result)  # (its missed-motion trials to come)
                self.rv_view.draw(seq, result.voting, plain, pending=preview, own_chain=own)
                self.tour.refresh()
                num = self.numbers_view.draw(seq, result, plain,
                                             pending=V.preview_note(own) if preview else None)
                if plain is not None or new_seq:  # (else the last check stays until plain RV
                    self.status_bar.show_check(num)  # is back: the page does not jump twice)
                s = self.status_bar
                s.alert.visible = self.state.error is not None
                data_notes = []  # about the data: kept when the colour mode changes
                if self.video is not None and seq is self.video.sequence:
                    data_notes.append(V.md_text(self.video.summary(settings.n_motions))
                                      + " No ground truth: errors cannot be scored.")
                elif seq.labels is None:
                    data_notes.append(f"{V.md_text(seq.name)} has no ground truth: errors cannot be scored; "
                                      + V.md_text(self.origin_of(seq).motions_note(settings.n_motions)))
                data_notes.append(V.md_text(self.origin_of(seq).note))
                if not seq.is_complete:
                    data_notes.append(V.incomplete_note(seq, result, counts=not (
                        self.video is not None and seq is self.video.sequence)))
                data_notes += V.result_notes(result)
                self._data_notes = [n for n in data_notes if n]
                self.show_notes(unpinned, self.address.note_for(gen))
                # a preview's time: its own stages' (what this change reran, or the warm child)
                s.show_result(seq, num["error_final"], sum(result.timings.values()) if preview
                              else self.state.compute_seconds,
                              non_defaults(settings, self._usual_motions(seq), seq.is_complete),
                              self.change, ahead=self.state.computed_ahead(result), preview=preview,
                              own=own)
                self.view3d.show_first()
                self.compare.redraw()
            self.view3d.draw(seq, result, self.style["color"], self.controls.w_frame.value, new_seq)
            self._seq_shown = seq
            self._sync_url()
        self.apply_seconds = time.perf_counter() - t0
        # card 3's votes: fitted now that the result is on its way to the page (drawn then)
        with self._applied:
            self.votes_pending = result if self.state.fit_votes(result) is not None else None
        if not preview:
            self.files.result_shown(seq)
        if self._rest is not None and self._rest["loaded"]:  # the later cards: after this result
            self._add_rest_after(REST_GAP_S)
        if preview:
            return
        with self._applied:
            self.applied_generation = gen
            self._applied.notify_all()

    def _set_sequence(self, seq, settings) -> None:
        """(Inside :meth:`_apply_result`.) Every card to a new sequence, the controls to the
        settings it is computed with."""
        for view in (self.frame_view, self.graph_view, self.coarse_view):
            view.fit(seq)
        c = self.controls
        c.fit_frames(seq)
        c.w_motions.value = settings.n_motions
        self.lock_for_upload(False)
        fm = c.w_params["fine_models"]
        fm.end = max(fm.end, FINE_PER_MOTION_END * settings.n_motions)
        self.files.show_sequence(seq)
        self.status_bar.show_sequence(seq)
        self.sweep_view.show_sequence(seq)
        self.files.name_downloads(seq)
        c.fit_color(seq, self._seq_shown)
        c.sync_to(settings)

    def _draw_frame(self) -> None:
        # the colouring drawn (the final labels when ground truth was asked for and is missing)
        shown = V.COLOR_LABELS.get(self.style.get("mode"))
        self.frame_view.draw(self.sequence, self.result, self.frame, self.style, self.moved,
                             shown or self.controls.w_color.value)

    def _apply_votes(self, result, dropped: bool = False) -> None:
        """Card 3 draws ``result``'s votes, fitted (:meth:`ExplorerState.fit_votes`), if it
        is still the result shown; a fit ``dropped`` for a newer request is asked again
        while it is (the newer request may never show a result: cancelled, or failed)."""
        if dropped:
            with self._applied:
                if result is self.result and self.votes_pending is result:
                    self.votes_pending = result if self.state.fit_votes(result) is not None else None
                    if self.votes_pending is not None:
                        return
            # (else fitted meanwhile, or no longer shown: drawn as it is, or not at all)
        if result is self.result:
            with self.hold():
                self.coarse_view.draw(self.sequence, result)
                self.coarse_view.epipolar.draw(self.sequence, result)
        with self._applied:
            if self.votes_pending is result:
                self.votes_pending = None
            self._applied.notify_all()

    def _apply_plain_rv(self, voting, key) -> None:
        if self.result is None or key != self.state.plain_rv_key():
            return
        with self.hold():
            self.rv_view.draw(self.sequence, self.result.voting, voting)
            self.tour.refresh()
            self.status_bar.show_check(self.numbers_view.draw(self.sequence, self.result, voting))
            if self.controls.color_mode in V.PLAIN_MODES:
                self._color_now()
            else:
                self.compare.redraw()  # plain RV's error in the compare table
        with self._applied:
            self.applied_plain_key = key
            self._applied.notify_all()

    def lock_for_upload(self, locked: bool) -> None:
        """While another sequence is read and first computed, the C box is locked (see
        :meth:`Controls.lock_motions`); unlocked after a failed read, the status line is back."""
        self.controls.lock_motions(locked)
        if not locked:
            self.status_bar.end_reading()

    def _show_busy(self, busy: bool) -> None:
        if busy and self._busy_period is None:
            return  # (scheduled by the timer just as the period ended)
        # a preview's line stays: it says what is still computing, where "Recomputing… (the
        # views keep the last result …)" would be wrong (the timer often fires just after it)
        self.status_bar.show_busy(busy, self.result is not None and not self.previewing)

    def _show_error(self, message: str) -> None:
        if self._rest is not None and self._rest["loaded"]:
            self.schedule(self._add_rest)
        self.lock_for_upload(False)
        self.restore_result()
        self.files.not_opened()
        self.status_bar.show_error(message)

    @property
    def data_notes(self) -> list[str]:
        """The page's notes about the data shown (Markdown): incomplete tracks, where C came
        from, what the result says about itself; kept when the colouring changes."""
        return list(self._data_notes)

    def show_notes(self, *lines) -> None:
        """(Document thread.) The page's note: the colouring's (when it cannot be shown as
        asked), then ``lines`` (Markdown; empty ones skipped), then :attr:`data_notes`."""
        style_note = self.style["note"] if self.style else None
        self.status_bar.show_note("  \n".join([n for n in (style_note, *lines) if n] + self.data_notes))

    def origin_of(self, seq: laav.Sequence) -> Origin:
        """How ``seq`` came from its file (an empty :class:`Origin` when nothing is known)."""
        with self._origin_lock:
            return self._origins.get(seq, Origin())

    def add_origin(self, seq: laav.Sequence, origin: Origin) -> None:
        """Remember how ``seq`` came from its file (for as long as ``seq`` lives)."""
        with self._origin_lock:
            self._origins[seq] = origin

    def restore_result(self) -> None:
        """(Document thread.) After a cancel or a failure: a preview shown (whose result will
        not come) gives way to the last result again."""
        if not self.previewing:
            return
        if self.state.result is not None:
            self._apply_result(self.state.result, self.state.sequence, self.state.settings,
                               self.applied_generation)
        else:  # a first computation's preview: nothing else to show; it stays, said to be one
            self.status_bar.preview_abandoned()  # (the exports and the pin still refuse it)

    # ------------------------------------------------------------------ view controls
    def _on_frame(self, event=None) -> None:
        self.touch()
        self.schedule(self._frame_now, now_if_on_doc_thread=True)

    def touch(self) -> None:
        """A person moved a view control (a frame, a colouring, the replay's step): the next
        seed is not computed ahead beside it (:meth:`ExplorerState.touch`)."""
        if not self.quieted:
            self.state.touch()

    def _frame_now(self) -> None:
        if self.result is None or self.quieted:
            return
        with self.hold(live="frame"):
            self._draw_frame()
            self.graph_view.draw(self.result, self.frame, self.fine_colors)
            self.compare.redraw()
        # the address once the frame rests (FRAME_ADDRESS_REST_S): nothing else is sent
        self._frame_address_timer = self._after(self._frame_address_timer, self._frame_rested,
                                                FRAME_ADDRESS_REST_S)
        self.view3d.set_frame(self.frame)

    def _frame_rested(self) -> None:
        self._frame_address_timer = None
        if self.controls.w_frame.direction and self._served_doc() is not None:
            # the player plays: the address once it pauses
            self._frame_address_timer = self._after(None, self._frame_rested, FRAME_ADDRESS_REST_S)
            return
        with self.hold():
            self._sync_url()

    def _on_color(self, event=None) -> None:
        self.touch()
        self.schedule(self._color_now, now_if_on_doc_thread=True)

    def _color_now(self) -> None:
        if self.result is None:
            return
        self.style = V.point_style(self.sequence, self.result, self.controls.color_mode,
                                   self.state.plain_rv(self.sequence, self.settings),
                                   fine_rows=self.frame_view.fine_rows())
        with self.hold(live="draw"):
            self._draw_frame()
            self.compare.redraw()
            self.show_notes()
            self._sync_url()
        self.view3d.set_colors(self.style["color"])

    # ------------------------------------------------------------------ shared state (URL, params.json)
    def _usual_motions(self, seq: laav.Sequence) -> int | None:
        """The C the status line counts as the default for ``seq``: its ground truth's, else
        the estimated one (a file without ground truth); None when C was given (no default)."""
        C = self.state.default_motions(seq)
        return C if C is not None else self.origin_of(seq).motions_estimate

    def _default_color(self, seq=None) -> str:
        seq = self.sequence if seq is None else seq
        return "gt" if seq.labels is not None else "final"

    def apply_query(self, pairs: dict) -> list[str]:
        """Take the settings and view a page URL's query carries (:class:`PageAddress`)."""
        return self.address.apply_query(pairs)

    def query(self, asked: bool = False) -> dict[str, str]:
        """The URL query of what the page shows now (:meth:`PageAddress.query`)."""
        return self.address.query(asked)

    def _sync_url(self) -> None:
        self.address.sync()

    def load_params(self, data: bytes | str, filename: str = "params.json") -> bool:
        """Apply a params.json (as exported here). False, and a message, when it is not valid."""
        return self.address.load_params(data, filename)

    def load_bytes(self, data: bytes, filename: str) -> bool:
        """Load an uploaded ``.mat`` / ``.npz`` (bytes). Returns False (and shows why) on failure."""
        return self.files.load_bytes(data, filename)

    def _png_view(self):
        """What the PNG export shows: frame, colour mode, GAEC step, plain RV's run."""
        return (self.controls.w_frame.value, self.controls.color_mode, self.graph_view.w_step.value,
                self.rv_view.plain)

    # ------------------------------------------------------------------ testing / teardown
    def wait(self, timeout: float = 60.0, plain_rv: bool = False) -> bool:
        """Block until the newest request's result (or error) is on the views, card 3's
        votes drawn (:meth:`ExplorerState.fit_votes`) and the 3-D view's server, if starting, up."""
        deadline = time.monotonic() + timeout
        if not self.state.wait(timeout):
            return False
        with self._applied:
            while (self.applied_generation < self.state.published_generation
                   or (self.votes_pending is not None and self.votes_pending is self.result)):
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
        return self.view3d.wait(max(0.0, deadline - time.monotonic()))  # (started by an unfold)

    def close(self, timeout: float | None = 10.0) -> bool:
        """Stop the computations and the 3-D view's server. The worker threads are joined
        for up to ``timeout`` seconds (None: not waited for, as when a page's session ends
        on the server's event loop). True when they have all ended."""
        self.view3d.closed = True  # a 3-D server still starting closes itself
        self.sweep_view.close()
        ended = self.state.close(timeout)
        self.view3d.close()
        self._drop_page_scripts()
        return ended

    def _drop_page_scripts(self) -> None:
        """Unregister the page scripts attached to this explorer's widgets (``jscallback``):
        panel keeps them in a class-wide registry whose entries reach back to their widget
        through the cards, so that no closed tab's explorer was ever freed."""
        from panel.links import Callback

        mine = {id(o) for root in (*self.sidebar, *self.main) for o in root.select()}
        for source, callbacks in list(Callback.registry.items()):
            if id(source) in mine:
                for cb in list(callbacks):
                    cb.unwatch()
