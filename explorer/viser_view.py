"""The 3-D space-time view: one viser server per explorer session.

Trajectories are line segments in (x, y, frame); atoms are small spheres (a point cloud of
round points) at their centres in the current frame, joined by the atom-graph edges; the
current frame is a translucent plane that moves with the frame slider. Every explorer
session gets its own server on its own free port, so two browser tabs never share a scene.
viser handles may be edited from any thread.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from contextlib import contextmanager

import numpy as np

import laav

from . import views as V
from .loopback import IPV4_BINDS, hold_ipv6_loopback, netloc

__all__ = ["ViserView"]

#: The frame shown's points (scene units; the box is 4 wide).
POINT_SIZE = 0.05
#: The atoms' centres in the frame shown: dark grey dots smaller than the points.
ATOM_SIZE = 0.035
ATOM_GREY = 40
_JOIN = np.array([33, 102, 172], np.uint8)  # blue: positive cost (join)
_CUT = np.array([214, 39, 40], np.uint8)  # red: negative cost (cut)
_SERVE_LOCK = threading.Lock()

#: Seconds after a 3-D client connects at which viser's own notice "Software WebGL rendering
#: detected" (shown by its client, never closing on its own, over the scene's lower left) is
#: taken away: read once, it covered part of the view for good on a machine without GPU,
#: such as a classroom's (docs/explorer.md says what software rendering costs).
SOFTWARE_NOTICE_S = 10.0
#: The id viser's client (1.1) gives that notice (``BrowserWarning.tsx``).
SOFTWARE_NOTICE_ID = "webgl-software-rendering"


#: :func:`_quiet_viser`'s state: how many threads are inside, and rich's console to put back
#: when the last leaves (one tab's 3-D view may start while another's stops)
_QUIET_LOCK = threading.Lock()
_quiet_depth = 0
_quiet_saved = None


@contextmanager
def _quiet_viser():
    """viser's messages (its start banner, "Server stopped") kept off the user's output.

    viser prints them with ``rich.print``, to rich's global console: in a terminal that is
    standard output, but in Jupyter rich displays them as cell output, past any redirect of
    ``sys.stdout`` (the banner, with the server's address, showed in a notebook's output).
    Inside, rich's global console is a quiet one (not Jupyter's, which ignores ``file``);
    it is put back when the last thread inside leaves (a message another thread prints with
    rich meanwhile is dropped too)."""
    import contextlib
    import io

    global _quiet_depth, _quiet_saved
    try:
        import rich
        from rich.console import Console
    except ImportError:  # (viser needs rich; without it nothing of it prints there)
        rich = None
    if rich is not None:
        with _QUIET_LOCK:
            if _quiet_depth == 0:
                _quiet_saved = getattr(rich, "_console", None)
                rich._console = Console(file=io.StringIO(), quiet=True, force_jupyter=False)
            _quiet_depth += 1
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    finally:
        if rich is not None:
            with _QUIET_LOCK:
                _quiet_depth -= 1
                if _quiet_depth == 0:
                    rich._console, _quiet_saved = _quiet_saved, None


@contextmanager
def _origin_checked(hosts: Iterable[str], token: str):
    """Servers viser starts inside serve their page and websocket only to the page's own
    origin and only under the tab's secret path ``/TOKEN/``.

    viser (1.1) checks neither the ``Origin`` of its websocket nor who asks: any web page the
    user visits, or any other client that can reach the port, could read the scene. While
    this is active, ``websockets``' ``serve`` gets a ``process_request`` that

    - answers 403 to a websocket handshake unless its ``Origin`` is ``http://HOST:PORT``
      with HOST one of ``hosts`` and PORT the port the connection arrived on (the origin of
      the 3-D page, which viser serves itself), and unless its path is ``/TOKEN`` (viser's
      client connects to its page's address without the query and the trailing slash);
    - answers 404 to every HTTP request outside ``/TOKEN/``, and hands the rest to viser's
      own file server with the prefix removed (its client is one self-contained page).

    The token is random per server and reaches only the page of the session that owns it
    (the iframe's address), so another tab, another client or another origin gets nothing.
    """
    import dataclasses
    import hmac
    import http

    import websockets.asyncio.server as ws_server
    from websockets.datastructures import Headers
    from websockets.http11 import Response

    hosts = frozenset(hosts)
    prefix = f"/{token}"
    real = ws_server.serve

    def refuse(status: http.HTTPStatus, text: str) -> Response:
        return Response(status, status.phrase, Headers(), text.encode())

    def serve(*args, process_request=None, **kw):
        def checked(connection, request):
            path = request.path.partition("?")[0]
            head, sep, rest = path[1:].partition("/")
            ok_token = hmac.compare_digest(f"/{head}".encode(), prefix.encode())
            if request.headers.get("Upgrade", "").lower() == "websocket":
                port = connection.local_address[1]
                if request.headers.get("Origin") not in {f"http://{netloc(h, port)}" for h in hosts}:
                    return refuse(http.HTTPStatus.FORBIDDEN, "cross-origin websocket refused\n")
                if not ok_token or rest:
                    return refuse(http.HTTPStatus.FORBIDDEN, "websocket refused: not this view's address\n")
                return process_request(connection, request) if process_request else None
            if not ok_token or not sep:  # /TOKEN without its slash: not the page either
                return refuse(http.HTTPStatus.NOT_FOUND, "not found\n")
            inner = dataclasses.replace(request, path="/" + request.path[len(prefix) + 1:])
            return process_request(connection, inner) if process_request else None

        return real(*args, process_request=checked, **kw)

    with _SERVE_LOCK:
        ws_server.serve = serve
        try:
            yield
        finally:
            ws_server.serve = real


#: Most trail samples the 3-D view draws (seen points x frames; more only when a sequence has
#: over half as many tracks: each keeps its first and last sample): beyond it each track shows
#: every k-th of its samples, its first and its last. Software WebGL (no GPU: headless
#: Chromium, a VM) redraws 10,000 samples as points at no cost measured beside the rest of
#: the scene, 31,000 at 0.3 s of CPU per redraw; the 10,000 steps as screen-space lines cost
#: as much (viser redraws about once a second even when idle).
TRAIL_SAMPLES = 12_000


def trail_samples(visible: np.ndarray, budget: int | None = None) -> np.ndarray:
    """(F, P) bool: the samples the 3-D view's trails show. ``visible`` (F, P): where each
    track is seen. Every seen sample when they are within ``budget``; else, for the smallest
    k that fits, each track's every k-th seen sample, its first and its last (so no track
    loses its trail, however short; ``max(budget, 2 P)`` samples at most). ``budget``:
    :data:`TRAIL_SAMPLES` when None."""
    budget = TRAIL_SAMPLES if budget is None else int(budget)
    vis = np.asarray(visible, dtype=bool)
    total = int(vis.sum())
    if total <= budget:
        return vis.copy()
    rank = np.cumsum(vis, axis=0) - 1  # each seen sample's place in its track
    last = vis.sum(axis=0) - 1  # (P,)

    def keep(k):
        return vis & ((rank % k == 0) | (rank == last[None, :]))

    k = max(2, -(-total // max(budget, 1)))
    while True:
        mask = keep(k)
        if mask.sum() <= budget or k >= vis.shape[0]:
            return mask
        k += 1


def _for_webgl(rgb: np.ndarray) -> np.ndarray:
    """sRGB colours (uint8) as the linear values three.js expects in a line's vertex colour
    buffer: it converts them to sRGB for the screen, so without this every line of the 3-D
    view came out lighter than the same colour in the 2-D views (blue looked cyan). Not for
    point clouds: viser's point shader writes its colours to the screen as they are (given
    linear values, Okabe-Ito orange #E69F00 showed as a red-brown #C75000; measured in
    Chromium, ``tests/test_explorer_browser.py``)."""
    c = np.asarray(rgb, dtype=np.float64) / 255.0
    lin = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
    return np.clip(np.round(lin * 255.0), 0, 255).astype(np.uint8)


def _close_software_notice(client) -> None:
    """Take viser's software-WebGL notice (:data:`SOFTWARE_NOTICE_ID`) off ``client``'s page,
    if it shows (else nothing happens). viser's public API removes only notices its server
    made, so this sends the removal message its client handles for any notice; with another
    viser, or a client gone, it does nothing."""
    from viser import _messages

    remove = getattr(_messages, "RemoveNotificationMessage", None)
    conn = getattr(client, "_websock_connection", None)
    if remove is None or conn is None:
        return
    try:
        conn.queue_message(remove(SOFTWARE_NOTICE_ID))
    except Exception:  # the client has gone, the server has stopped
        pass


class ViserView:
    """A viser server showing one sequence and result.

    Parameters
    ----------
    host : str
        Interface to bind (127.0.0.1 by default; the iframe must be able to reach it).
    port : int
        0 for any free port; read :attr:`port` for the one used.
    on_frame : callable, optional
        Called with the new frame when the viser-side frame slider moves.
    page_hosts : iterable of str, optional
        Host names the browser may use to reach the 3-D page (default: 127.0.0.1,
        localhost and ``host``); its websocket refuses every other origin.

    The page and its websocket are served only under :attr:`path` (``/TOKEN/``, a random
    token per server): embed :meth:`url`, never the bare port.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0,
                 on_frame: Callable[[int], None] | None = None,
                 page_hosts: Iterable[str] | None = None):
        import secrets

        import viser

        host = "0.0.0.0" if host == "" else host  # (viser binds "" as [::] and 0.0.0.0 on two ports)
        hosts = {"127.0.0.1", "localhost", host} if page_hosts is None else set(page_hosts)
        self.token = secrets.token_urlsafe(24)
        # viser binds its server before the constructor returns: the check is in place from the
        # start (and it prints a banner even when quiet)
        with _quiet_viser(), _origin_checked(hosts, self.token):
            self.server = viser.ViserServer(host=host, port=port, verbose=False)
        self.server.gui.configure_theme(show_share_button=False, control_layout="floating",
                                        control_width="small", show_logo=False)
        self.server.scene.set_up_direction("+y")
        #: the loopback names a browser can reach this server by, and whose origin its
        #: websocket accepts (``localhost`` only with [::1] at its port held: hold_ipv6_loopback)
        self._v6_guard = None
        self._timers: list[threading.Timer] = []
        try:
            names = set()
            if host in IPV4_BINDS:
                names.add("127.0.0.1")
                self._v6_guard, safe = hold_ipv6_loopback(self.port)
                if safe:
                    names.add("localhost")
            self.loopback_names = frozenset(names & hosts)
            self._on_frame = on_frame
            self._frame = 0
            self._seq: laav.Sequence | None = None
            self._result: laav.LaavResult | None = None
            self._map = None
            self._plane = None
            self._plane_z = None
            #: per scene node, the arrays last sent (:meth:`_put`): a node whose data did not
            #: change is not sent again (each message makes the 3-D page draw its scene anew,
            #: which software WebGL pays for on the machine's other core)
            self._sent: dict[str, tuple] = {}
            self._frame_box = self.server.gui.add_number("frame", initial_value=0, min=0, max=1, step=1)
            self._frame_box.on_update(self._frame_from_viser)
            self.server.on_client_connect(self._on_client)
        except BaseException:
            self.close()
            raise

    def _on_client(self, client) -> None:
        timer = threading.Timer(SOFTWARE_NOTICE_S, _close_software_notice, (client,))
        timer.daemon = True
        self._timers = [t for t in self._timers if t.is_alive()] + [timer]
        timer.start()

    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def path(self) -> str:
        """The secret path the page and its websocket are served under (``/TOKEN/``)."""
        return f"/{self.token}/"

    def url(self, host: str = "127.0.0.1") -> str:
        """The 3-D page's address for a browser reaching this machine as ``host``."""
        return f"http://{netloc(host, self.port)}{self.path}"

    def _frame_from_viser(self, event) -> None:
        f = int(self._frame_box.value)
        if f != self._frame and self._on_frame is not None:
            self._on_frame(f)

    # ---------------------------------------------------------------- data
    def set_result(self, seq: laav.Sequence, result: laav.LaavResult, colors: np.ndarray,
                   frame: int) -> None:
        """Redraw everything for a new result (``colors``: (P,) hex strings of the points)."""
        scene = self.server.scene
        new_seq = seq is not self._seq
        self._seq, self._result = seq, result
        if new_seq:
            self._map = V.space_time(seq)
            m = self._map
            w, h = m.half_width, m.half_height
            verts = np.array([[-w, -h, 0], [w, -h, 0], [w, h, 0], [-w, h, 0]], np.float32)
            faces = np.array([[0, 1, 2], [0, 2, 3]], np.uint32)
            self._plane = scene.add_mesh_simple("/frame_plane", verts, faces, color=(120, 120, 120),
                                                opacity=0.25, side="double", cast_shadow=False,
                                                receive_shadow=False)
            self._plane_z = None  # (a new plane: its position is sent below)
            self._frame_box.max = max(seq.n_frames - 1, 1)
            depth = m.dz * (seq.n_frames - 1)
            self._draw_axes(seq, w, h, depth)
            self.server.initial_camera.position = (2.6, 2.0, -2.6)
            self.server.initial_camera.look_at = (0.0, 0.0, depth / 2)
        self.set_colors(colors)
        self.set_frame(frame)

    def _draw_axes(self, seq: laav.Sequence, w: float, h: float, depth: float) -> None:
        """Axes from the image's lower left corner at frame 0: x and y along the image's edges
        (pixels, their ranges named) and the frame axis (frames 0 .. F-1) along the depth."""
        scene = self.server.scene
        o = (-w, -h, 0.0)
        ends = ((w, -h, 0.0), (-w, h, 0.0), (-w, -h, depth))
        segs = np.array([[o, e] for e in ends], np.float32)
        scene.add_line_segments("/axes", segs, np.full((3, 2, 3), 90, np.uint8), thickness=1.5,
                                thickness_units="screen")
        x0, x1, y0, y1 = seq.extent()
        F = seq.n_frames
        for name, text, pos in (("x", f"x (px) {x0:.0f} → {x1:.0f}", (w, -h, 0.0)),
                                ("y", f"y (px) {y1:.0f} → {y0:.0f}", (-w, h, 0.0)),
                                ("frame", f"frame 0 → {F - 1}", (-w, -h, depth))):
            scene.add_label(f"/axes/{name}", text, position=pos, font_screen_scale=0.8)

    def set_colors(self, colors: np.ndarray) -> None:
        seq, m = self._seq, self._map
        if seq is None:
            return
        srgb = V.hex_to_rgb(colors)  # (points take sRGB as it is: see _for_webgl)
        self._colors = srgb
        # (sent again only when the samples or their colours changed: _put)
        f, p = np.nonzero(trail_samples(seq.visible))  # the tracked samples shown
        self._put("/trajectories", self.server.scene.add_point_cloud, m(seq.points[f, p], f),
                  srgb[p], point_size=0.016, point_shape="circle", precision="float32")
        self._draw_frame_items()

    def set_frame(self, frame: int) -> None:
        """Move the plane, the current points, the atoms and the graph to ``frame``."""
        if self._seq is None:
            return
        self._frame = int(np.clip(frame, 0, self._seq.n_frames - 1))
        if int(self._frame_box.value) != self._frame:
            self._frame_box.value = self._frame
        self._draw_frame_items()

    def _put(self, name: str, add: Callable, *arrays, **kwargs) -> None:
        """``add(name, *arrays, **kwargs)`` (a ``scene.add_*``) unless the node ``name`` was
        last sent with these very arrays (and the same ``kwargs``)."""
        key = (tuple(np.array(a) for a in arrays), kwargs)
        old = self._sent.get(name)
        if old is not None and old[1] == kwargs and len(old[0]) == len(key[0]) and all(
                a.shape == b.shape and a.dtype == b.dtype and np.array_equal(a, b)
                for a, b in zip(old[0], key[0])):
            return
        self._sent[name] = key
        add(name, *arrays, **kwargs)

    def _remove(self, name: str) -> None:
        if self._sent.pop(name, None) is not None:
            self.server.scene.remove_by_name(name)

    def _draw_frame_items(self) -> None:
        seq, res, m, f = self._seq, self._result, self._map, self._frame
        scene = self.server.scene
        z = float(f * m.dz)
        if z != self._plane_z:
            self._plane.position = (0.0, 0.0, z)
            self._plane_z = z
        vis = V.visible_at(seq, f)  # only the points seen in this frame
        self._put("/points", scene.add_point_cloud, m(seq.points[f, vis], f).astype(np.float32),
                  self._colors[vis], point_size=POINT_SIZE, point_shape="circle", precision="float32")
        pos = np.asarray(res.graph.positions)
        if pos.size:
            centers = m(pos[f], f)
            shown = np.isfinite(centers).all(axis=1)  # an atom with no member seen here: not drawn
            # (smaller than the points, which they covered at 0.09: a point beside an
            # atom's centre still shows round it)
            self._put("/atoms", scene.add_point_cloud, centers[shown].astype(np.float32),
                      np.full((int(shown.sum()), 3), ATOM_GREY, np.uint8),
                      point_size=ATOM_SIZE, point_shape="circle", precision="float32")
            E = np.asarray(res.graph.edges, dtype=np.int64).reshape(-1, 2)
            keep = shown[E[:, 0]] & shown[E[:, 1]] if E.size else np.zeros(0, bool)
            E = E[keep]
            if E.size:
                segs = np.stack([centers[E[:, 0]], centers[E[:, 1]]], axis=1).astype(np.float32)
                col = _for_webgl(np.where((np.asarray(res.graph.costs)[keep] >= 0)[:, None], _JOIN, _CUT))
                self._put("/graph_edges", scene.add_line_segments, segs,
                          np.repeat(col[:, None], 2, axis=1), thickness=2.0, thickness_units="screen")
            else:  # no edge (with both atoms seen here): none drawn, the last result's gone
                self._remove("/graph_edges")
        else:  # no atom at all (a result of another sequence's may be on show)
            self._remove("/atoms")
            self._remove("/graph_edges")

    def close(self) -> None:
        for timer in self._timers:
            timer.cancel()
        try:
            with _quiet_viser():  # viser prints "Server stopped"
                self.server.stop()
        except Exception:
            pass
        if self._v6_guard is not None:  # (after the server: its clients reconnect meanwhile)
            self._v6_guard.close()
            self._v6_guard = None
