"""``laav-explore [FILE | VIDEO] [--motions C|auto] [--preset NAME] [--params P.JSON]
[--param NAME=VALUE ...] [--port N] [--host H] [--max-upload SIZE] [--no-browser] [tracking options]``.

A VIDEO (anything OpenCV opens) or a folder of frames, told apart from a sequence file by
content (:func:`explorer.video.is_video`), is tracked first, before the server starts (the
tracker's progress bar on a terminal; ``laav track``'s options: ``--stride``,
``--track-points`` for its ``--max-points``, ``--max-frames``, ...): every track it keeps is
used, incomplete ones included (``--complete-only``: only those seen in every frame), C is
``--motions`` or estimated (``laav.estimate_motions``, on the tracks seen in every frame), and
the frame view draws the video's frames behind the points. A FILE with incomplete tracks is
segmented as it is (``--complete-only`` keeps its full tracks). Every view draws a point only
where it is seen. A video that cannot be used (unreadable, no features, too few tracks for C) exits
with code 2 and one line on stderr.

The page address carries its state: ``/?r1=25&seed=3`` opens with R1 = 25 and seed 3 (keys:
every :class:`laav.LaavParams` field, ``seed``, ``motions``, ``frame``, ``color``, ``tour``,
``sequence``), and moving
a control updates it, so a copied address shows the same view. ``--params`` loads a
``params.json`` exported by the page; ``--param`` sets one parameter (repeatable, applied last);
``--preset paper`` (or ``with-plain-rv``) starts from :meth:`laav.LaavParams.paper` (or
:meth:`~laav.LaavParams.with_plain_rv`) instead of the defaults, before both (``own-chain``,
the defaults since 2026-12-02, is accepted as ``default``).

Serves the explorer page (panel) with its embedded 3-D view (viser, one server per browser
tab on a free port) from one process, prints the URL and opens the browser. Exit codes:
0 after Ctrl-C, 2 for bad arguments or an unreadable FILE (a message, never a traceback).

``--host``: the page's interface (default 127.0.0.1, this machine only). The 3-D view of
each tab is a separate viser server on another free port of the same interface, which the
page embeds (an iframe) under a random path only that tab's page is given; a remote browser
must be able to reach those ports too. With a
non-loopback host the command prints the address other machines can use, a warning that
the app is open to the network, and the address of each tab's 3-D view when it starts.

``--max-upload SIZE`` (default 50MB; ``20MB``, ``750KB``, ``2GB``): the largest file the page
accepts. The browser refuses a larger one before sending it and the server checks again as
it arrives, before any parsing. Uploads travel in 1 MB messages, so the page's websocket
limit (:data:`WEBSOCKET_MAX_MESSAGE`) does not depend on it.
"""

from __future__ import annotations

import argparse
import gc
import ipaddress
import socket
import sys
import threading
import time
import webbrowser
from concurrent.futures import Future

import laav

__all__ = ["main", "build_parser", "app_factory", "page_hosts", "DEFAULT_PORT", "WEBSOCKET_MAX_MESSAGE",
           "serve_options"]

DEFAULT_PORT = 5006
#: Largest websocket message the page's server takes (bokeh's default, 20 MB). An upload
#: travels in chunks of ``files.UPLOAD_CHUNK`` (1 MB), every other message is small: a file of
#: any size up to --max-upload fits, and a client sending more is disconnected, alone.
WEBSOCKET_MAX_MESSAGE = 20 * 1024 * 1024
_ANY = ("0.0.0.0", "", "::")
#: Seconds after which ``laav-explore`` lets the garbage collector run again even when no
#: tab has completed its page (see :class:`_StartupGC`).
STARTUP_GC_MAX_S = 30.0
_LOOPBACK = ("127.0.0.1", "localhost", "::1")


def page_hosts(host: str) -> list[str]:
    """Host names a browser may use to reach a server bound to ``host``.

    Both websockets (the page's and the 3-D view's) accept only these origins. For a
    wildcard bind: this machine's name, full name and addresses besides the loopback ones.
    """
    names = ["127.0.0.1", "localhost"]
    if host in _ANY:
        name = socket.gethostname()
        names += [name, socket.getfqdn()]
        try:
            names += [ai[4][0] for ai in socket.getaddrinfo(name, None, socket.AF_INET)]
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:  # sends nothing
                s.connect(("10.255.255.255", 1))
                names.append(s.getsockname()[0])  # the address of the default route
        except OSError:
            pass
    elif host not in names:
        names.append(host)
    return list(dict.fromkeys(names))


def serve_options() -> dict:
    """Keyword arguments for ``pn.serve`` that every server of the explorer needs (and the
    page without MathJax: :func:`no_mathjax`)."""
    from .sizes import UPLOAD_CHUNK

    assert 2 * UPLOAD_CHUNK < WEBSOCKET_MAX_MESSAGE  # a chunk and its message's framing fit
    no_mathjax()
    return {"websocket_max_message_size": WEBSOCKET_MAX_MESSAGE}


def no_session_validation() -> None:
    """``laav-explore``'s server (:func:`main`, for the whole process): each tab's document is
    served without bokeh's integrity checks of its models (0.10-0.13 s of the first page's
    0.6-0.7 s on the server, measured on the demo, 2026-12-05: every model's references
    walked and checked, before the page's HTML is sent), unless ``BOKEH_VALIDATE_DOC`` is
    set. The checks only log warnings (bokeh's validation level is "none"); the tests run
    them on the explorer's whole document instead (``tests/test_explorer.py``,
    ``test_the_page_passes_bokehs_integrity_checks``)."""
    import os

    from bokeh.settings import settings

    if "BOKEH_VALIDATE_DOC" not in os.environ:
        settings.perform_document_validation.set_value(False)


def no_mathjax() -> None:
    """Serve the page without bokeh's MathJax bundle (1.8 MB of JavaScript, a third of the
    page's, parsed before anything is drawn).

    Panel adds it to every page with a Markdown or HTML pane, in case the text holds TeX;
    the explorer's texts hold none, and a sequence or file name that looks like TeX should be
    shown as typed anyway. Panel has no setting for it: its resource check is replaced
    (``panel.io.resources._panel_use_mathjax``; nothing happens if a later panel renames it,
    the page then just loads MathJax again). Bokeh's own check (TeX in an axis label, a
    slider's title, ...) still applies."""
    from panel.io import resources

    if hasattr(resources, "_panel_use_mathjax"):
        resources._panel_use_mathjax = lambda roots: False


def _size(text: str) -> int:
    from .sizes import parse_size

    try:
        return parse_size(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _motions(text: str):
    if text.strip().lower() == "auto":
        return "auto"
    try:
        v = int(text)
    except ValueError:
        v = 0
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer or 'auto', got {text!r}")
    return v


def build_parser() -> argparse.ArgumentParser:
    from laav.cli import add_track_arguments

    p = argparse.ArgumentParser(
        prog="laav-explore",
        description="Explore every stage of LAAV motion segmentation live in the browser.",
        epilog="Without FILE the bundled demo sequence is shown. For a FILE without ground-truth "
               "labels C is estimated unless --motions gives it. A VIDEO is tracked first (C "
               "estimated unless --motions gives it).")
    p.add_argument("file", nargs="?", metavar="FILE | VIDEO",
                   help="Hopkins155 *_truth.mat, KT3DMoSeg .mat, a .npz with points (F, P, 2) [and "
                        "labels, visible], a tracks CSV (track,frame,x,y[,label]), or a folder holding one; "
                        "or a video (anything OpenCV opens) or a folder of frames, to track first")
    p.add_argument("--motions", "-C", type=_motions, metavar="C",
                   help="number of motions C, or auto to estimate it (default: from the ground truth; "
                        "without one, and for a video: auto)")
    p.add_argument("--port", type=int, metavar="N",
                   help=f"port of the page (default {DEFAULT_PORT}, or a free one if it is taken)")
    p.add_argument("--host", default="127.0.0.1",
                   help="interface to bind (default 127.0.0.1: this machine only; 0.0.0.0: every "
                        "interface, open to the network; each tab's 3-D view uses another free port)")
    p.add_argument("--seed", type=int, default=None, help="seed of the random stages (default 0, or the "
                   "one in --params)")
    p.add_argument("--preset", choices=tuple(laav.params.PRESETS), default="default",
                   help="parameters to start from: ours, LAAV's own chain (default; own-chain is "
                        "the same), the paper's stages (LaavParams.paper()) or ours with plain "
                        "RV beside LAAV's trial (LaavParams.with_plain_rv()); --params and "
                        "--param change them")
    p.add_argument("--params", metavar="P.JSON",
                   help="parameters to start with: a params.json exported by the explorer")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE",
                   help="set one LaavParams field, e.g. --param lam=3 (repeatable; after --params)")
    p.add_argument("--max-upload", type=_size, default="50MB", metavar="SIZE",
                   help="largest file the page accepts, e.g. 20MB, 750KB, 2GB (default 50MB); checked "
                        "in the browser before sending and on the server before any parsing")
    p.add_argument("--no-browser", action="store_true", help="do not open a browser")
    p.add_argument("--max-points", type=int, default=None, metavar="N",
                   help=f"refuse a FILE with more than N points (default {laav.io.MAX_POINTS:,}; "
                        "time and memory grow about linearly; docs/bench/scale.md)")
    p.add_argument("--complete-only", action="store_true",
                   help="keep only the tracks visible in every frame (by default incomplete tracks are "
                        "segmented too and drawn only where seen); the page numbers the kept points "
                        "0..K-1, its labels CSV as the file does (like laav segment --complete-only)")
    tr = p.add_argument_group("tracking a VIDEO (the options of laav track; every track it keeps is "
                              "used, --complete-only: only those seen in every frame)")
    add_track_arguments(tr, rename={"--max-points": "--track-points"})
    return p


def _port_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        # like the server itself: connections of an earlier run in TIME_WAIT do not count
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host if host not in ("", "0.0.0.0") else "0.0.0.0", port))
        except OSError:
            return False
    return True


def _free_port(host: str) -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host if host not in ("", "0.0.0.0") else "0.0.0.0", 0))
        return int(s.getsockname()[1])


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback  # 127.x, ::1
    except ValueError:
        pass
    try:
        return ipaddress.ip_address(socket.gethostbyname(host)).is_loopback  # a name
    except (OSError, ValueError):
        return host == "localhost"


def _reachable_name(host: str) -> str:
    """The address other machines use for a server bound to ``host``."""
    if host not in ("0.0.0.0", "", "::"):
        return host
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("192.0.2.1", 9))  # no packet is sent: this only picks the outgoing interface
            return s.getsockname()[0]
        except OSError:
            return socket.gethostname()


class _StartupGC:
    """Python's cyclic garbage collector held off while ``laav-explore`` starts.

    Importing panel and building the first page make hundreds of thousands of long-lived
    objects, and each full collection walks all of them: in a traced start on the 2-core VM
    the server's process made three full collections (73, 84 and 128 ms) before the points
    were drawn and one of about 200 ms after the first result, where a first slider move
    lands (docs/bench/explorer_startup_2026-12-03.md). Held off until a tab's page is
    complete (or :data:`STARTUP_GC_MAX_S` at the latest). What the imports made is frozen
    (:meth:`imported`, :func:`gc.freeze`: modules live as long as the server, and are never
    walked again); the explorers are not (a tab's cycles are collected once it closes).
    Reference counting frees everything that is not in a cycle meanwhile."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._on = gc.isenabled()
        gc.disable()
        self._timer = threading.Timer(STARTUP_GC_MAX_S, self.end)
        self._timer.daemon = True
        self._timer.start()

    def imported(self) -> None:
        """(After the imports, before any page is built.) Freeze what exists."""
        gc.freeze()

    def end(self) -> None:
        """Let the collector run again (once; any thread)."""
        with self._lock:
            on, self._on = self._on, None
        if on is None:
            return
        self._timer.cancel()
        if on:
            gc.enable()


def app_factory(seq: laav.Sequence, n_motions: int | None, seed: int = 0, host: str = "127.0.0.1",
                created: list | None = None, viser: bool = True, prebuild: bool = False,
                hosts: list[str] | None = None, announce_viser: bool = False,
                params: laav.LaavParams | None = None, max_upload: int | None = None, video=None,
                warm=None, seeds_ahead: bool = False, on_first_page=None, origin=None,
                on_built=None):
    """The per-session page builder for ``pn.serve``: one :class:`Explorer` per browser tab.

    Page first: a session's pipeline starts once its page is on screen (``pn.state.onload``,
    or after 3 s at the latest), so the first page does not wait behind the computation (the
    first tab's is usually done by then: the command computes it in a child process, ``warm``).
    ``prebuild`` builds the first tab's explorer now, in a background thread, while the
    server starts and the browser opens. ``created`` (optional list) receives every
    Explorer built (tests and benchmarks use it). ``hosts``: see :func:`page_hosts` (its
    value for ``host`` by default). ``announce_viser`` prints the address of every tab's
    3-D view once its server is up (the CLI does for a non-loopback host).
    A session whose address carries settings (``/?r1=25&seed=3``) starts with them
    (validated; problems shown on the page as text). ``max_upload``: the largest upload in
    bytes (default :data:`explorer.sizes.DEFAULT_MAX_UPLOAD`); serve with
    :func:`serve_options`. ``video``: the :class:`explorer.video.Video` ``seq`` was tracked
    from (its frames, shared read-only by every tab, go behind the points). ``warm``: the
    first tab's pipeline and plain RV for ``seq`` computed elsewhere (:func:`explorer.warm.first_results`;
    only the first explorer built takes them). ``seeds_ahead``: every tab computes the next
    seed's result while idle (:class:`explorer.state.ExplorerState`; the command turns it on).
    ``on_first_page``: called, on the server's thread, when a tab's page is complete
    (:attr:`Explorer.on_page_complete`; it must do its work once). ``on_built``: called when
    a tab's page has been built, before it is sent (it must do its work once). ``origin``: how
    ``seq`` came from its file (:class:`explorer.state.Origin`), for every tab.
    """
    iframe_host = None if host in _ANY else host
    hosts = page_hosts(host) if hosts is None else hosts
    spare: list = []
    lock = threading.Lock()

    warm_left = [warm]  # for the first explorer built only

    def build():
        from .app import Explorer
        from .sizes import DEFAULT_MAX_UPLOAD

        with lock:
            first, warm_left[0] = warm_left[0], None
        return Explorer(seq, n_motions, params=params, seed=seed, viser=viser, viser_host=host,
                        iframe_host=iframe_host, start=False, page_hosts=hosts,
                        max_upload=DEFAULT_MAX_UPLOAD if max_upload is None else max_upload,
                        video=video, pipeline=None if first is None else first.pipeline,
                        plain_rv=None if first is None else first.plain_rv, seeds_ahead=seeds_ahead,
                        preview=None if first is None else first.preview, origin=origin)

    if prebuild:
        fut: Future = Future()

        def run():
            try:
                fut.set_result(build())
            except BaseException as exc:  # noqa: BLE001 - the session builds its own then
                fut.set_exception(exc)

        threading.Thread(target=run, name="laav-explore-prebuild", daemon=True).start()
        spare.append(fut)

    def make_app():
        import panel as pn

        with lock:
            pre = spare.pop() if spare else None
        ex = None
        if pre is not None:
            try:
                ex = pre.result(timeout=60)
                ex.attach_session()
            except Exception:  # build a fresh one below
                ex = None
        if ex is None:
            ex = build()
        ex.apply_query(dict(pn.state.session_args or {}))  # before the first computation starts
        ex.on_page_complete = on_first_page  # (the first tab to complete its page ends it)
        if created is not None:
            created.append(ex)
        if announce_viser:
            # (on loopback the 3-D server starts at the card's first unfold; here with the
            # session's first computation, so that its address is printed when the tab opens)
            ex.view3d.eager = True

            def announce():  # where a remote browser must reach this tab's 3-D view
                deadline = time.monotonic() + 600  # it starts with the session (ex.start)
                while ex.view3d.thread is None and not ex.view3d.closed and time.monotonic() < deadline:
                    time.sleep(0.2)
                ex.view3d.wait(120)
                if ex.viser is not None:
                    # the port only: its page answers under the tab's secret path alone
                    print(f"laav-explore: a tab's 3-D view is served at "
                          f"http://{_reachable_name(host)}:{ex.viser.port}/ (under a secret path "
                          "only that tab's page knows)", flush=True)

            threading.Thread(target=announce, name="laav-explore-announce", daemon=True).start()
        # (on the server's event loop: the workers stop at their next check, not waited for)
        pn.state.on_session_destroyed(lambda ctx: ex.close(timeout=None))
        pn.state.onload(ex.start)
        doc = pn.state.curdoc
        if doc is not None:
            doc.add_timeout_callback(ex.start, 3000)  # no document_ready (e.g. a script client)
        # the header shows the sequence in a pane that follows uploads; the tab's title is set
        # to the shown sequence with every result of a new one
        page = ex.template("LAAV explorer")
        if on_built is not None:
            on_built()
        return page

    def close_unclaimed(timeout: float = 30.0) -> None:
        """Stop a prebuilt explorer no session took (at server shutdown)."""
        with lock:
            left = list(spare)
            spare.clear()
        for fut in left:
            try:
                fut.result(timeout=timeout).close()
            except Exception:
                pass

    make_app.close_unclaimed = close_unclaimed
    return make_app


def _fail(parser: argparse.ArgumentParser | None, msg: str) -> int:
    """Exit code 2 with the message (after the usage line when ``parser`` is given: bad arguments)."""
    if parser is not None:
        parser.print_usage(sys.stderr)
    print(f"laav-explore: error: {msg}", file=sys.stderr)
    return 2


def _say(text: str) -> None:
    print(f"laav-explore: {text}", flush=True)


def main(argv: list[str] | None = None) -> int:
    """``laav-explore``: LAAV's warnings as one line each (``laav-explore: warning: ...``)."""
    from laav.cli import warnings_as_lines

    with warnings_as_lines("laav-explore"):
        return _main(argv)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse already printed the message
        return int(exc.code or 0)
    if args.port is not None and not 0 <= args.port <= 65535:
        return _fail(parser, f"--port must be between 0 and 65535, got {args.port}")
    if args.max_points is not None and args.max_points < 1:
        return _fail(parser, f"--max-points must be at least 1, got {args.max_points}")
    # before any tracking: a busy port is said at once
    if args.port is None:
        port = DEFAULT_PORT if _port_free(args.host, DEFAULT_PORT) else _free_port(args.host)
    else:
        port = args.port if args.port else _free_port(args.host)
        if not _port_free(args.host, port):
            return _fail(parser, f"port {port} on {args.host} is already in use; pick another with --port")
    video = None
    kept = note = estimate = None  # how the sequence came from the file (state.Origin)
    if args.file is not None:
        from .video import damaged_sequence, is_video

        damaged = damaged_sequence(args.file)
        if damaged:  # (a real video named .csv is still tracked: content decides)
            return _fail(None, f"{args.file}: not a readable {damaged} file (binary content of no "
                               "sequence format, and no video's either)")
        if is_video(args.file):
            import os

            from laav.cli import track_options

            from .video import VideoError, open_video

            # FFmpeg's own log lines (e.g. "moov atom not found") would add to the one-line error
            os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
            try:
                video = open_video(args.file, args.motions, track_options=track_options(args),
                                   progress=None, max_points=args.max_points, log=_say,
                                   complete_only=args.complete_only)
            except VideoError as exc:
                return _fail(None, str(exc))
            _say(video.frames.describe() + " (drawn behind the points)")
    try:
        if video is not None:
            seq = video.sequence
        elif args.file is None:
            from .demo import demo_sequence
            seq = demo_sequence()
        else:
            if _is_params_file(args.file):  # (the page's upload box takes one; here it is --params)
                return _fail(None, f"{args.file}: a params file (JSON), not a sequence: give the "
                                   f"sequence as FILE and this with --params {args.file}")
            seq = laav.load_sequence(args.file, isolated=True, max_points=args.max_points)
            hint = laav.io.layout_warning(seq)
            if hint:
                print(f"laav-explore: warning: {hint}", file=sys.stderr)
        if args.complete_only and not seq.is_complete:
            missing = 100 * (1 - seq.visible_share)
            n_file = seq.n_points
            seq, kept = seq.complete()
            note = (f"--complete-only: kept the {kept.size} of {n_file} tracks seen in every frame "
                    f"({missing:.1f} % of the entries were missing); the labels CSV numbers them "
                    "as the file does")
            print(note, file=sys.stderr)
        elif not seq.is_complete and video is None:  # (a video's own line says it)
            _say(f"{seq.n_points} tracks, {100 * seq.visible_share:.1f} % of the entries visible "
                 "(incomplete tracks: drawn only where seen; --complete-only keeps the full ones)")
        if video is None and args.file is not None:  # a tracks CSV's own track ids, for the exports
            import numpy as np

            from laav.io import point_numbers

            ids = point_numbers(seq, kept)
            kept = None if np.array_equal(ids, np.arange(seq.n_points)) else ids
    except (laav.SequenceError, FileNotFoundError) as exc:
        return _fail(None, str(exc))  # a file's problem, not the arguments': no usage block
    if video is not None:
        C = video.n_motions
    elif args.motions == "auto" or (args.motions is None and seq.labels is None):
        # no ground truth and no --motions: C is estimated (issue 14 item 7)
        try:
            count = laav.estimate_motions(seq)
        except ValueError as exc:
            return _fail(None, f"--motions auto: {exc}")
        C = count.n_motions
        estimate = count
        _say(f"C = {C} estimated ({count.explain()})")
    else:
        C = args.motions if args.motions is not None else seq.n_motions
    from .state import Settings, check_motions, parse_settings, settings_from_json

    given = args.motions not in (None, "auto")
    try:  # (before --param: a C the points cannot hold is this argument's or the file's fault;
        # a --params file may set another C, and the last check below judges that)
        if given or args.params is None:
            check_motions(seq, C)
    except ValueError as exc:
        if given:
            return _fail(parser, f"--motions: {exc}")
        whose = "the estimated C" if estimate is not None else f"{seq.name}'s ground truth"
        return _fail(None, f"{whose}: {exc}; give a smaller C with --motions")

    start = laav.params.PRESETS[args.preset]()
    from .state import SEED_MAX

    if args.seed is not None and not 0 <= args.seed <= SEED_MAX:
        return _fail(parser, f"--seed must be a whole number between 0 and {SEED_MAX}, got {args.seed}")
    settings = Settings(start, 0 if args.seed is None else args.seed, C)
    if args.params is not None:
        try:
            with open(args.params, "rb") as fh:
                loaded = settings_from_json(fh.read(), seq, settings, defaults=start)
        except OSError as exc:
            return _fail(parser, f"--params {args.params}: {exc.strerror or exc}")
        except ValueError as exc:
            return _fail(parser, f"--params {args.params}: {exc}")
        # the file's seed and C, unless given on the command line
        settings = Settings(loaded.params, loaded.seed if args.seed is None else args.seed,
                            C if args.motions is not None else loaded.n_motions)
    if args.param:
        pairs = {}
        for item in args.param:
            name, sep, val = item.partition("=")
            if not sep or not name.strip():
                return _fail(parser, f"--param takes NAME=VALUE, got {item!r}")
            if name.strip() in ("seed", "motions"):
                return _fail(parser, f"--param sets LaavParams fields; use --seed / --motions for {name!r}")
            if name.strip() in ("frame", "color", "tour", "sequence"):
                return _fail(parser, f"--param sets LaavParams fields; {name.strip()!r} is the page "
                                     "address's")
            pairs[name.strip()] = val
        settings, _, problems = parse_settings(pairs, seq, settings)
        if problems:
            return _fail(parser, "--param: " + "; ".join(problems))
    from .state import check_settings

    try:  # a bad --seed (or the file's) is a bad argument, not a page that never computes
        check_settings(seq, settings)
    except ValueError as exc:
        return _fail(parser, str(exc))
    C = settings.n_motions
    # the first result, computed from now on in a child process (not in this one: the page
    # being served would wait for the GIL); the first tab's explorer takes it
    from .state import Origin
    from .warm import first_results

    origin = Origin(None if estimate is None else estimate.n_motions,
                    "" if estimate is None else estimate.explain(), kept, note or "")
    built = threading.Event()  # the first page is built: the first result's state may be read
    first = first_results(seq, C, settings.params, settings.seed, hold=built)
    startup_gc = _StartupGC()  # (after the fork: the child holds its own off, explorer.warm)
    try:
        return _serve(args, seq, C, settings, port, video, first, startup_gc, parser, origin, built)
    finally:
        startup_gc.end()  # (at once if nothing did it before: the server has stopped)


def _is_params_file(path) -> bool:
    """Whether ``path`` holds a params.json (:func:`explorer.state.is_params_json`, as the
    upload box tells one)."""
    from .state import is_params_json

    try:
        with open(path, "rb") as fh:
            return is_params_json(fh.read(4096))
    except OSError:  # (load_sequence says what is wrong with the path)
        return False


def _serve(args, seq, C, settings, port, video, first, startup_gc, parser, origin=None,
           built: threading.Event | None = None) -> int:
    """:func:`main`'s server: serve until stopped (Ctrl-C)."""
    import panel as pn

    from .loopback import IPV4_BINDS, hold_ipv6_loopback, netloc

    startup_gc.imported()
    no_session_validation()
    hosts = page_hosts(args.host)
    origins = [netloc(h, port) for h in hosts]  # the page's websocket: its own origin only
    try:
        factory = app_factory(seq, C, settings.seed, args.host, prebuild=True, hosts=hosts,
                              announce_viser=not _is_loopback(args.host), params=settings.params,
                              max_upload=args.max_upload, video=video, warm=first, seeds_ahead=True,
                              on_first_page=startup_gc.end, origin=origin,
                              on_built=None if built is None else built.set)
        server = pn.serve({"/": factory}, port=port, address=args.host, websocket_origin=origins,
                          show=False, start=False, title=f"LAAV explorer: {laav.safe_name(seq.name)}",
                          verbose=False, **serve_options())
    except OSError as exc:
        return _fail(parser, f"cannot listen on {args.host}:{port}: {exc}")
    local = _is_loopback(args.host)
    url = f"http://{netloc(args.host if local else _reachable_name(args.host), port)}/"
    print(f"laav-explore: {seq.name} ({seq.n_points} points, {seq.n_frames} frames, C = {C}) at {url}",
          flush=True)
    if not local:
        print(f"laav-explore: warning: --host {args.host} opens the app to the network: anyone who can "
              f"reach this machine can use it and read the sequence (each tab's 3-D view is served on "
              f"another free port of {args.host}, printed when the tab opens); use 127.0.0.1 for this "
              f"machine only", flush=True)
    print("laav-explore: press Ctrl-C to stop", flush=True)
    # a browser tries http://localhost:PORT at [::1] first: held, no other program can listen
    # there (the page's server is on IPv4 only), as for the 3-D view (loopback)
    guard = hold_ipv6_loopback(port)[0] if args.host in IPV4_BINDS else None
    server.start()
    if not args.no_browser:
        server.io_loop.add_callback(lambda: webbrowser.open(url))
    try:
        server.io_loop.start()
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        factory.close_unclaimed()
        if guard is not None:
            guard.close()
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
