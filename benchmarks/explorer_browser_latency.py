"""Latency a person feels in the explorer: from a control's release to the views redrawn,
measured in real Chromium.

Starts the real command (``python -m explorer.cli [FILE] --no-browser --port N``) as a
fresh process, loads the page in Debian's Chromium (``/usr/bin/chromium``, via Playwright;
Chromium is launched before the command, so its own start-up is not counted) and measures,
in the page's own clock:

- ``first_result_kb``, ``<control>_kb_median``: what the page's websockets received until
  the first result, and per move until 300 ms after its redraw (KiB);
- ``first_points_s`` / ``first_result_s``: seconds from starting the command to the
  trajectories drawn in the frame view / to the first segmentation shown (the status line
  reads "Showing …");
- ``lambda_ms_median``, ``radius_ms_median`` (R1 and R2), ``seed_ms_median``,
  ``frame_ms_median``: from a slider's release (its value set in the page, as a released
  drag sets it) until the page shows the new result: the status line names the new value
  (the app updates every view and the status in one document change, so they arrive
  together), or for the frame until the frame view's title shows the new frame AND the
  points' glyph in the page holds that frame's coordinates (the renderer's view, i.e. what
  bokeh draws, compared with the sequence's x of each point shown; a video falls back to
  "the glyph holds its source's new x"), then two animation frames so that the browser has
  drawn them. The frame move is thus timed to the redraw, whichever side computes it;
- a move whose result needs more than LAAV's own trial (plain RV afresh with
  ``with_plain_rv()``; in the default chain the missed-motion trials its gate lets through)
  first shows a *preview* (LAAV's own fine-tuning, the status line saying what is still
  computing; ``ExplorerState.on_preview``): the ``<control>_ms`` wait for the result itself, and
  ``<control>_preview_ms_median`` is the time to the preview on screen (``<control>_previews``:
  how many moves had one);
- ``scroll_paint_ms``: a plot off screen is painted when it comes into view
  (``explorer/cards/onscreen.py``): after the moves, from scrolling card 4's first plot (the
  fine-tuning's error per iteration, below the fold) to the top of the view until the plots
  on screen are painted (no paint left waiting, their views ready, two animation frames);
  ``scroll_paint_plots_waiting``: how many of the plots then on screen had a paint waiting
  (0: nothing was left for the scroll);
- ``<control>_compute_ms_median``: of those, the server's computation (the status line's
  "computed in N ms"); ``<control>_patched_ms_median``: from the release until the page
  had received the document patch with the new status line (for the frame: the first
  patch), before bokeh handles it (the rest, to the redraw, is the page's own work: bokeh
  applying the patch and drawing).

Each control is moved ``--repeats`` times between two values (the seed to a new one each
time, 1, 3, 5, ...: a seed shown before is served from what the explorer kept, plain RV's
runs or a whole result, and the next seed may have been computed while idle; either would
time a cache), ``--settle`` seconds (default
0.3) after the previous move's redraw (what a person looking at the result leaves; the
explorer computes the next seed while idle). Prints ONE JSON line and
writes it, with date, machine and commit, to ``--out`` (default
``bench-out/explorer_browser_latency.md``). Usage::

    python benchmarks/explorer_browser_latency.py [--repeats 3] [--out REPORT.md] [--only frame,...]
        [--settle 0.3] [--view3d] [FILE] [-- COMMAND OPTIONS]

``--view3d`` unfolds the 3-D card first (``view3d_host``: the host its iframe addresses). The
moves are still timed on the 2-D views; the 3-D view follows them on its own.

``FILE`` may be a video or a folder of frames (``laav-explore`` tracks it first; its frames
are then drawn behind the points, which a frame move sends along). ``--only`` measures some
controls only (names as in the JSON: lambda, radius, seed, frame); options after ``--`` go to
the command (e.g. ``-- --motions 3`` for tracks without ground truth).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

from _machine import write_json_report  # this folder, on sys.path

from explorer.cards.status import PREVIEW_STATUS
from explorer.cli import _free_port

REPO = Path(__file__).resolve().parents[1]
CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]

#: State of the page: the status line's text, the frame view's title, trajectories drawn.
JS_STATE = """() => {
  const out = {status: '', frame_title: '', points: 0};
  if (!(window.Bokeh && Bokeh.documents.length > 0)) return out;
  for (const m of Bokeh.documents[0].all_models) {
    if (typeof m.text === 'string' && m.text.includes('Showing')) out.status = m.text;
    if (m.type === 'Title' && /^frame \\d+ of/.test(m.text)) out.frame_title = m.text;
    if (m.type === 'ColumnDataSource' && m.data.index !== undefined) out.points = m.data.index.length;
  }
  return out;
}"""

#: The frame view's points in the page: the source's point indices and x, and what the
#: points renderer's glyph view holds (the data bokeh draws), or null before the page is up.
JS_POINTS = """() => {
  if (!(window.Bokeh && Bokeh.documents.length > 0 && Bokeh.index)) return null;
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure' && m.type !== 'Plot') continue;
    if (!(m.title && /^frame \\d+ of/.test(m.title.text))) continue;
    for (const r of m.renderers) {
      const d = r.data_source ? r.data_source.data : null;
      if (!d || d.index === undefined || d.marker === undefined) continue;
      const v = Bokeh.index.find_one(r);
      if (!v) return null;
      return {index: Array.from(d.index), src_x: Array.from(d.x), glyph_x: Array.from(v.glyph.x || [])};
    }
  }
  return null;
}"""

#: Set a slider as a released drag does, then wait until ``test(state)`` holds and two
#: animation frames have passed; [milliseconds (page clock), the status line], or -1 after 60 s.
#: For the frame, ``xs`` is the frame's x of every point (null: unknown, e.g. a video):
#: the points' glyph must hold them (else: must hold its source's x, changed by the move).
JS_MOVE = """async ([prefix, value, kind, marker, xs]) => {
  const PREVIEW = """ + json.dumps(PREVIEW_STATUS) + """;
  const state = """ + JS_STATE + """;
  const points = """ + JS_POINTS + """;
  let slider = null;
  for (const m of Bokeh.documents[0].all_models) {
    if ((m.type === 'Slider' || m.type.endsWith('Player')) && typeof m.title === 'string'
        && m.title.startsWith(prefix)) slider = m;
  }
  if (slider === null) return -2;  // no such control
  const frame = () => new Promise(r => requestAnimationFrame(() => r()));
  const before = kind === 'frame' ? points() : null;
  const drawn = () => {
    const p = points();
    if (p === null || p.glyph_x.length !== p.index.length || p.index.length === 0) return false;
    for (let k = 0; k < p.index.length; k++) {
      const want = xs !== null ? xs[p.index[k]] : p.src_x[k];
      if (!(Math.abs(p.glyph_x[k] - want) <= 1e-3)) return false;
    }
    if (xs === null && before !== null && before.src_x.length === p.src_x.length &&
        before.src_x.every((x, k) => x === p.src_x[k])) return false;
    return true;
  };
  const t0 = performance.now();
  let first = -1;  // the first view of the new value: a preview's, or the result's
  let doneAt = -1;
  slider.value = value; slider.value_throttled = value;
  while (true) {
    const s = state(), now = performance.now() - t0;
    if (kind !== 'frame' && first < 0 && s.status.includes(marker)) first = now;
    const done = kind === 'frame' ? s.frame_title.startsWith(marker) && drawn()
      : s.status.includes(marker) && !s.status.includes(PREVIEW);
    if (done) { doneAt = now; break; }
    if (performance.now() - t0 > 60000) return -1;
    await frame();
  }
  await frame(); await frame();
  const got = (window.__laavPatches || []).filter(
    p => p[0] >= t0 && (kind === 'frame' || (p[1] && !p[2])));
  return [performance.now() - t0, state().status, got.length ? got[0][0] - t0 : -1,
          first >= 0 && first < doneAt ? first : -1];
}"""

#: Records (page clock) when each bokeh PATCH-DOC message has fully arrived, before bokeh
#: handles its last frame, and whether it changes the status line. A bokeh message is a
#: header (with ``msgtype`` and ``num_buffers``), metadata, content, then an id frame and a
#: binary frame per buffer.
JS_RECORD_PATCHES = """(() => {
  const PREVIEW = """ + json.dumps(PREVIEW_STATUS) + """;
  const Base = window.WebSocket;
  window.__laavPatches = [];
  window.WebSocket = function (...args) {
    const ws = new Base(...args);
    let left = 0;  // frames still to come of the patch being received
    let status = false;  // the patch changes the status line
    let preview = false;  // ... to a preview's
    ws.addEventListener('message', (ev) => {
      if (left > 0) {
        left -= 1;
        if (typeof ev.data === 'string' && ev.data.includes('Showing')) status = true;
        if (typeof ev.data === 'string' && ev.data.includes(PREVIEW)) preview = true;
        if (left === 0) window.__laavPatches.push([performance.now(), status, preview]);
        return;
      }
      if (typeof ev.data === 'string' && ev.data.includes('"msgtype": "PATCH-DOC"')) {
        const m = ev.data.match(/"num_buffers": (\\d+)/);
        left = 2 + 2 * (m ? Number(m[1]) : 0);
        status = preview = false;
      }
    });
    return ws;
  };
  window.WebSocket.prototype = Base.prototype;
  Object.assign(window.WebSocket, {CONNECTING: 0, OPEN: 1, CLOSING: 2, CLOSED: 3});
})()"""

#: Scroll the plot whose title starts with ``text`` to the top of the viewport, then wait
#: until no plot on screen has a paint left for when it is seen (``explorer/cards/onscreen.py``)
#: and every such plot's view is ready, plus two animation frames; [milliseconds, how many
#: plots on screen had a paint waiting], or -1 after 10 s (-2: no such plot). Then back to
#: the frame view.
JS_SCROLL_PAINT = """async (text) => {
  const frame = () => new Promise(r => requestAnimationFrame(() => r()));
  const views = (pred) => {
    const out = [];
    for (const m of Bokeh.documents[0].all_models) {
      if (m.type !== 'Figure' && m.type !== 'Plot') continue;
      const v = Bokeh.index.find_one(m);
      if (v && v.el && pred(m, v)) out.push(v);
    }
    return out;
  };
  const titled = (t) => views((m) => m.title && t.test(String(m.title.text)));
  const [head] = titled(new RegExp('^' + text)), [first] = titled(/^frame \\d+ of/);
  if (!head) return -2;
  const plots = () => views((m, v) => {
    const r = v.el.getBoundingClientRect();
    return r.height > 0 && r.bottom > 0 && r.top < window.innerHeight;
  });
  const t0 = performance.now();
  head.el.scrollIntoView({block: 'start'});
  await frame();
  const waiting = plots().filter(v => v._laav_deferred).length;
  while (plots().some(v => v._laav_deferred)) {
    if (performance.now() - t0 > 10000) return -1;
    await frame();
  }
  await Promise.all(plots().map(v => v.ready));
  await frame(); await frame();
  const ms = performance.now() - t0;
  if (first) first.el.scrollIntoView({block: 'center'});
  return [ms, waiting];
}"""


#: (name in the JSON, slider title prefix, kind, two values, status marker for a value)
CONTROLS = [
    ("lambda", "λ", "status", (3.0, 2.5), lambda v: f"λ = {v:g}"),
    ("radius", "R1", "status", (22.0, 18.0), lambda v: f"R1 = {v:g}"),
    ("radius", "R2", "status", (44.0, 36.0), lambda v: f"R2 = {v:g}"),
    ("seed", "seed", "status", (1, 2), lambda v: f"seed = {v:g}"),
    ("frame", "frame", "frame", (3, 7), lambda v: f"frame {v:g} of"),
]


def _sequence_of(file: str | None):
    """The sequence the command shows (None for a video: tracked by the command only)."""
    import laav
    from explorer.demo import demo_sequence
    from explorer.video import is_video

    if file is None:
        return demo_sequence()
    return None if is_video(file) else laav.load_sequence(file)


def frame_x(seq, frame: int) -> list | None:
    """Every point's x in ``frame`` (NaN as null: not seen there), or None without a sequence."""
    if seq is None:
        return None
    x = seq.points[int(frame), :, 0].astype(float)
    return [None if x_ != x_ else x_ for x_ in x.tolist()]


def wait_listening(port: int, proc, deadline: float) -> None:
    """Until the command ``proc`` (a ``subprocess.Popen``) listens on ``port`` of 127.0.0.1;
    RuntimeError when it ends first or ``deadline`` (``time.monotonic()``) passes. The page is
    opened once the server listens, as laav-explore opens the browser; until then a plain
    connect is tried (not a navigation: Chromium's failed loads every 50 ms, each drawing an
    error page, took a core from the starting command: panel's import took 2.0-2.9 s instead
    of 0.8-1.2 s)."""
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            if time.monotonic() > deadline or proc.poll() is not None:
                raise RuntimeError(f"the command did not listen on port {port}") from None
            time.sleep(0.02)


def measure(file: str | None, repeats: int, only: list[str] | None = None,
            extra: list[str] | None = None, settle: float = 0.3, view3d: bool = False) -> dict:
    from playwright import sync_api

    port = _free_port("127.0.0.1")
    cmd = [sys.executable, "-m", "explorer.cli", *([file] if file else []), "--no-browser",
           "--port", str(port), *(extra or [])]
    controls = [c for c in CONTROLS if only is None or c[0] in only]
    seq = _sequence_of(file)
    env = dict(os.environ, PYTHONPATH=str(REPO))
    out: dict = {"file": file or "bundled demo", **({"options": " ".join(extra)} if extra else {}),
                 **({"view3d": "open"} if view3d else {})}
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
        proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL)
        t_cmd = time.monotonic()
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            page.add_init_script(JS_RECORD_PATCHES)
            received = [0]  # bytes the page's websockets received (bokeh's and, if shown, viser's)
            page.on("websocket", lambda ws: ws.on("framereceived", lambda f: received.__setitem__(
                0, received[0] + len(f if isinstance(f, (bytes, bytearray)) else f.encode()))))
            deadline = t_cmd + 300  # a video is tracked before the server starts
            wait_listening(port, proc, deadline)
            # (the first request may wait for the prebuilt explorer: up to the deadline)
            page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded",
                      timeout=max(1000.0, 1000 * (deadline - time.monotonic())))
            page.wait_for_function("() => (" + JS_STATE + ")().points > 0", timeout=120000, polling=20)
            out["first_points_s"] = round(time.monotonic() - t_cmd, 2)
            page.wait_for_function("() => (" + JS_STATE + ")().status.length > 0", timeout=120000,
                                   polling=20)
            out["first_result_s"] = round(time.monotonic() - t_cmd, 2)
            out["first_result_kb"] = round(received[0] / 1024, 1)
            page.wait_for_timeout(1000)  # the lazily added cards arrive after the first result
            if view3d:  # the 3-D card unfolded, its scene drawn, before the moves
                page.locator(".card-header", has_text="3-D space-time view").first.click()
                page.frame_locator("iframe").locator("canvas").first.wait_for(timeout=120000)
                out["view3d_host"] = page.locator("iframe").first.get_attribute("src").split("/")[2]
                page.wait_for_timeout(3000)
            runs: dict = {}
            sent: dict = {}  # bytes received per move, until 300 ms after the redraw
            server: dict = {}  # the compute time the status line reports, per move
            wire: dict = {}  # from the release to the result's patch received
            previews: dict = {}  # from the release to a preview on screen, where one came
            for rep in range(repeats):
                for name, prefix, kind, values, marker in controls:
                    for v in values:
                        if name == "seed":  # a seed never shown nor computed ahead: 1, 3, 5, ...
                            v = 1 + 2 * (len(values) * rep + values.index(v))
                        xs = frame_x(seq, v) if kind == "frame" else None
                        b0 = received[0]
                        ms = page.evaluate(JS_MOVE, [prefix, v, kind, marker(v), xs])
                        ms, status, last, first = (ms, "", -1, -1) if not isinstance(ms, list) else ms
                        if first >= 0:  # a preview came first (drawn, not yet the result)
                            previews.setdefault(name, []).append(first)
                        if last >= 0:
                            wire.setdefault(name, []).append(last)
                        if kind == "status":  # the server's share: "computed in N ms" of the line
                            m = re.search(r"computed in (\d+) ms", status)
                            if m:
                                server.setdefault(name, []).append(int(m.group(1)))
                        # (what the server sends after the redraw; --settle: a person looking)
                        page.wait_for_timeout(max(300, int(1000 * settle)))
                        sent.setdefault(name, []).append(received[0] - b0)
                        if ms < 0:
                            raise RuntimeError(f"{prefix} = {v}: no result in the page ({ms})")
                        runs.setdefault(name, []).append(round(ms, 1))
            if "radius" in runs:  # card 4's plots, below the fold, after the last move
                got = page.evaluate(JS_SCROLL_PAINT, "Error per iteration")
                if isinstance(got, list):
                    out["scroll_paint_ms"], out["scroll_paint_plots_waiting"] = round(got[0], 1), got[1]
            for name, values in runs.items():
                out[f"{name}_ms_median"] = round(statistics.median(values), 1)
                out[f"{name}_ms"] = values
                out[f"{name}_kb_median"] = round(statistics.median(sent[name]) / 1024, 1)
                if previews.get(name):
                    out[f"{name}_preview_ms_median"] = round(statistics.median(previews[name]), 1)
                    out[f"{name}_previews"] = len(previews[name])
                if wire.get(name):
                    out[f"{name}_patched_ms_median"] = round(statistics.median(wire[name]), 1)
                if server.get(name):
                    out[f"{name}_compute_ms_median"] = statistics.median(server[name])
        finally:
            proc.terminate()
            proc.wait(30)
            browser.close()
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("file", nargs="?", help="sequence file (default: the bundled demo)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="bench-out/explorer_browser_latency.md")
    ap.add_argument("--only", default=None, help="comma-separated controls: lambda,radius,seed,frame")
    ap.add_argument("--settle", type=float, default=0.3,
                    help="seconds between a move's redraw and the next move (a person looking)")
    ap.add_argument("--view3d", action="store_true",
                    help="unfold the 3-D card (its viser scene in an iframe) before the moves")
    argv = sys.argv[1:] if argv is None else list(argv)
    extra = argv[argv.index("--") + 1:] if "--" in argv else []
    args = ap.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    only = args.only.split(",") if args.only else None
    result = measure(args.file, args.repeats, only, extra, args.settle, args.view3d)
    result["settle_s"] = args.settle
    write_json_report(args.out, "Explorer latency in Chromium, control release to views redrawn",
                      f"{result['file']}, {args.repeats} moves of each control between two values, "
                      "viewport 1280x800, headless Chromium (software WebGL)", result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
