"""The 3-D space-time view: a viser server of its own (:mod:`explorer.viser_view`), shown in
an iframe in a collapsible card.

The server starts in its own thread when the card is first unfolded: importing viser and
starting its server hold the interpreter ~0.45 s, which had landed on the first result (and,
started a moment after it, on the first slider move), and a session that never opens the
3-D view does not pay it. The card starts folded, and the
iframe is on the page only while the card is unfolded (and a result is shown): a 3-D client
redraws its WebGL scene at least once a second, and in a software-rendered browser every
redraw holds its renderer's main thread for hundreds of milliseconds (the 2-D views then wait;
docs/bench/explorer_browser_latency.md). While folded, the scene is not updated either;
unfolding sends it the result, colours and frame shown. Open, the iframe is addressed by the
loopback's other name (:func:`iframe_host`), so that browsers that isolate sites render it in
a process of its own, beside the page's.
"""

from __future__ import annotations

import html
import threading
import urllib.parse

import panel as pn

from .. import views as V
from ..loopback import LOOPBACK_ALIAS
from .base import FOLD_ARROW, HTML, Host, Markdown

PLACEHOLDER = ('<div style="width:100%;height:440px;border:1px solid #ccc;border-radius:4px;'
               'display:flex;align-items:center;justify-content:center;color:#666">'
               "The 3-D view opens with the first result…</div>")


#: The card's pane while its server starts (unfolded for the first time).
STARTING = PLACEHOLDER.replace("opens with the first result", "is starting")

def iframe_host(page_host: str | None, configured: str | None, names=frozenset()) -> str:
    """The host name the 3-D view's iframe addresses its server by.

    ``page_host``: the name the browser reached the page at (its request's ``Host``, without
    the port; None when unknown, e.g. in a notebook); ``configured``: the name the server was
    given for the iframe (None: the page's); ``names``: the loopback names the 3-D server is
    safely reachable by and whose origin its websocket accepts
    (:attr:`explorer.viser_view.ViserView.loopback_names`).

    A page at one loopback name gets the iframe at the other (127.0.0.1 <-> localhost) when
    that name is in ``names``: browsers count the two as different *sites*, and those
    that isolate sites (Chromium, Firefox) then render the iframe in a process of its own. In
    the page's process, viser's software-rendered WebGL redraws (every one read back on the
    main thread) held the page's: with the 3-D view open, frame moves took 344-475 ms and λ
    moves 409-680 ms, against 85-149 and 155-163 ms with the iframe in a process of its own
    (1R2RCT_A, headless Chromium without GPU, two interleaved pairs of runs;
    docs/bench/explorer_browser_latency_2026-12-06b.md). Otherwise the configured name, else
    the page's, else 127.0.0.1 (as before).
    """
    other = LOOPBACK_ALIAS.get(page_host or "")
    if other is not None and other in names:
        return other
    return configured or page_host or "127.0.0.1"


#: The card's title: one line at 1024 px (the main area's 682 px). With "(viser)" after "view"
#: it wrapped onto a second line there; the iframe's own title still names viser.
TITLE = "3-D space-time view: trajectories along the frame axis, atoms and their graph"


#: How to read the 3-D view (below it): what each mark is, in the words of the 2-D cards.
CAPTION = ("Image x and y across, the frames along the depth (the axes start at the image's "
           "lower left corner in frame 0). Small dots: every tracked position of every point, "
           "coloured as card 1's points; the grey plane: the frame shown, its points drawn "
           "large; dark grey dots: the atoms' centres in that frame, joined by the graph's "
           "edges (blue: positive cost, favouring a join; red: negative, a cut). Drag to turn, "
           "scroll to zoom; the frame box at the top right moves the frame, as the frame "
           "slider does.")


class View3D:
    """The 3-D card and its viser server (``viser``: None until started, or when off).

    ``iframe_host``: the host name the browser uses to reach the server (None: the page's
    own host), except that a page at a loopback name gets the other one where it reaches the
    server (:func:`iframe_host`); ``page_hosts``: the page origins its websocket accepts;
    ``on_frame``: called with a frame picked in the 3-D view (from viser's thread)."""

    def __init__(self, host: Host, want: bool, viser_host: str, page_hosts, iframe_host, on_frame) -> None:
        self.host = host
        self.viser = None
        self.want = bool(want)
        self.thread: threading.Thread | None = None
        self.closed = False
        self.error: str | None = None
        self._viser_host = viser_host
        self._page_hosts = page_hosts
        self._iframe_host = iframe_host
        self._on_frame = on_frame
        self.iframe_shown = False
        self.stale = False  # folded: the scene has not been given the shown result/colours/frame
        self._started = False  # the server's start has ended (``viser`` set, or ``error``)
        #: start the server with the first computation, not at the first unfold (a remote
        #: page's address is printed then: ``laav-explore --host``)
        self.eager = False
        if self.want:
            self.pane = HTML(PLACEHOLDER, height=440, margin=0, sizing_mode="stretch_width")
        else:
            self.pane = Markdown(f"*{V.md_text('the 3-D view is switched off')}*",
                                 sizing_mode="stretch_width", height=60)
        self.caption = Markdown(CAPTION if self.want else "", sizing_mode="stretch_width",
                                margin=(4, 10))
        self.card = pn.Card(self.pane, self.caption, title=TITLE, collapsible=True, collapsed=True,
                            margin=(6, 6), sizing_mode="stretch_width", stylesheets=[FOLD_ARROW])
        self.card.param.watch(self._on_fold, "collapsed")

    @property
    def unfolded(self) -> bool:
        return not self.card.collapsed

    def _on_fold(self, event=None) -> None:
        self.host.schedule(self._fold_now, now_if_on_doc_thread=True)

    def _fold_now(self) -> None:
        """(Document thread.) Unfolded: the iframe and the shown state; folded: no iframe
        (its client stops drawing) and no scene updates."""
        if not self.want or self.closed:
            return
        if self.unfolded:
            self.start()  # (the first unfold starts the server; show() waits for it)
            self.show()
        elif self.iframe_shown:
            self.iframe_shown = False
            self.pane.object = PLACEHOLDER.replace("opens with the first result", "is folded away")

    def start(self) -> None:
        """Start the server in its thread (idempotent; nothing when the view is off)."""
        if self.want and self.thread is None and not self.closed:
            self.thread = threading.Thread(target=self._start_server, name="laav-explore-viser",
                                           daemon=True)
            self.thread.start()

    def _start_server(self) -> None:
        try:
            from ..viser_view import ViserView

            view = ViserView(host=self._viser_host, on_frame=self._on_frame, page_hosts=self._page_hosts)
        except Exception as exc:  # the 2-D views still work without it
            self.error = f"the 3-D view could not start: {exc}"
            self._started = True  # (before show() runs: it may run here, in this thread)
            self.host.schedule(self.show)
            return
        if self.closed:
            view.close()
            self._started = True
        else:
            self.viser = view
            self._started = True
            # a result applied while the server was still starting (a slow, loaded machine)
            # did not reach it: show the view and send the shown result now
            self.host.schedule(self.show)

    def show(self, send: bool = True) -> None:
        """(Document thread.) Put the 3-D view on the page once its server has started (or
        failed) and a result is shown; with ``send``, also give it the shown result."""
        h = self.host
        if not self.want or h.result is None or self.closed or not self.unfolded:
            return
        if self.viser is None and not self._started:
            self.start()  # (unfolded: the server starts now if it has not)
            if not self.iframe_shown:
                self.pane.object = STARTING
            return  # still starting: _start_server calls again when done
        if not self.iframe_shown:
            self.iframe_shown = True
            self.pane.object = self.iframe_html() if self.viser is not None else (
                f"<p><i>{html.escape(self.error or 'the 3-D view did not start')}</i></p>")
            self.caption.visible = self.viser is not None  # (nothing to read without it)
        if send and self.viser is not None and (self.stale or self.viser._result is not h.result):
            self.stale = False
            self.viser.set_result(h.sequence, h.result, h.style["color"], h.frame)

    def show_first(self) -> None:
        """(Document thread, with the first result.) The iframe, once the server is up (not
        waited for: while it starts the card says so, and its start shows it when done)."""
        if self.want and not self.iframe_shown and self.unfolded:
            self.show(send=False)

    def draw(self, seq, res, colors, frame: int, new_seq: bool) -> None:
        """Give the server a new result (the whole scene for a new sequence, else the colours)."""
        if self.viser is None:
            return
        if not self.unfolded:
            self.stale = True
            return
        if new_seq or self.viser._result is None:
            self.viser.set_result(seq, res, colors, frame)
        else:
            self.viser._seq = seq
            self.viser._result = res
            self.viser.set_colors(colors)

    def set_frame(self, frame: int) -> None:
        if self.viser is not None:
            if not self.unfolded:
                self.stale = True
                return
            self.viser.set_frame(int(frame))

    def set_colors(self, colors) -> None:
        if self.viser is not None:
            if not self.unfolded:
                self.stale = True
                return
            self.viser.set_colors(colors)

    def reattach(self) -> None:
        """The page's host may have changed (an explorer adopted by a server session)."""
        if self.viser is not None and self.iframe_shown:
            self.pane.object = self.iframe_html()

    def iframe_html(self) -> str:
        hdr = (pn.state.headers or {}).get("Host", "") if pn.state.curdoc else ""
        try:
            page = urllib.parse.urlsplit("//" + hdr).hostname if hdr else None  # ([::1]:80 -> ::1)
        except ValueError:  # a malformed Host: as if unknown
            page = None
        host = iframe_host(page, self._iframe_host, self.viser.loopback_names)
        # the tab's secret path: the 3-D server answers nothing else (see viser_view)
        return (f'<iframe src="{html.escape(self.viser.url(host))}" title="LAAV 3-D view (viser)" '
                'style="width:100%;height:440px;border:1px solid #ccc;border-radius:4px;'
                'box-sizing:border-box"></iframe>')

    def wait(self, timeout: float = 30.0) -> bool:
        """Let the server finish starting, if it is starting; False if it has not by then."""
        t = self.thread
        if t is not None and t.is_alive():
            t.join(timeout)
        return t is None or not t.is_alive()

    def close(self) -> None:
        self.closed = True
        self.wait()
        if self.viser is not None:
            self.viser.close()
