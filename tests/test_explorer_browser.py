"""The explorer in headless Chromium (Debian's /usr/bin/chromium, never a downloaded one).

Serves the app with ``pn.serve(threaded=True)`` on a free port, loads it with Playwright,
fails on any request that leaves 127.0.0.1/localhost, moves the λ slider in the page,
checks that the views changed (in the server's explorer and in the browser's bokeh models:
titles are drawn on a canvas), that an impossible R1 shows a message, that a second tab is
independent, and saves screenshots (``$LAAV_EXPLORER_SHOTS`` or pytest's tmp dir).
"""

from __future__ import annotations

import json
import os
import socket
import time
from contextlib import contextmanager
from pathlib import Path

import pytest

pytestmark = [pytest.mark.browser, pytest.mark.slow]

CHROMIUM = Path("/usr/bin/chromium")
if not CHROMIUM.exists():
    pytest.skip("Debian's chromium is not installed (apt-get install -y chromium)", allow_module_level=True)
sync_api = pytest.importorskip("playwright.sync_api")
pn = pytest.importorskip("panel")

import numpy as np  # noqa: E402
from conftest import hold_computation, two_motion_sequence  # noqa: E402

import laav  # noqa: E402
from explorer import app as app_module  # noqa: E402
from explorer import views as V  # noqa: E402
from explorer.cards.status import PREVIEW_STATUS  # noqa: E402
from explorer.cli import app_factory, serve_options  # noqa: E402

ARGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]
LOCAL = ("http://127.0.0.1", "ws://127.0.0.1", "http://localhost", "ws://localhost", "data:", "blob:",
         "about:")

JS_SOURCES = """() => {
  const PREVIEW = """ + json.dumps(PREVIEW_STATUS) + """;
  const out = {};
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type === 'ColumnDataSource' && m.data.z !== undefined) out.z = Array.from(m.data.z);
    if (m.type === 'ColumnDataSource' && m.data.index !== undefined) out.points = m.data.index.length;
    if (m.type === 'ColumnDataSource' && m.data.r1 !== undefined) out.r1 = Array.from(m.data.r1);
    if (m.type === 'Title' && (m.text.startsWith('Affinity Z') || m.text.startsWith('Coding affinity')
                               || m.text.startsWith('Joint merge')))
      out.ztitle = m.text;
    // a result's status line (not a preview's, which a result follows)
    if (typeof m.text === 'string' && m.text.includes('Showing') && !m.text.includes(PREVIEW))
      out.status = m.text;
  }
  return out;
}"""

#: The WebGL renderer's name in a frame (as viser's client reads it), "" when unknown.
JS_WEBGL_RENDERER = """() => {
  const c = document.createElement('canvas'), gl = c.getContext('webgl2') || c.getContext('webgl');
  const ext = gl && gl.getExtension('WEBGL_debug_renderer_info');
  return ext ? String(gl.getParameter(ext.UNMASKED_RENDERER_WEBGL)) : '';
}"""

JS_SET_SLIDER = """([prefix, value]) => {
  for (const m of Bokeh.documents[0].all_models) {
    if ((m.type === 'Slider' || m.type.endsWith('Player')) && typeof m.title === 'string'
        && m.title.startsWith(prefix)) {
      m.value = value; m.value_throttled = value; return m.title;
    }
  }
  return null;
}"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_listening(port: int, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            socket.create_connection(("127.0.0.1", port), 0.2).close()
            return
        except OSError:
            time.sleep(0.05)
    raise TimeoutError(f"nothing listens on port {port}")


def _sequence() -> laav.Sequence:
    """A small two-motion sequence (fast to segment, so the test stays short)."""
    return two_motion_sequence(0, P=140, F=12, name="browser_test")


def _wait_for(pred, timeout: float, what: str, page=None):
    """Poll ``pred`` until it is true. Give ``page`` when ``pred`` reads anything Playwright
    records from events (websocket frames, dialogs): the sync API delivers events only while
    one of its calls runs, never during ``time.sleep``, so waiting is done by the page."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        v = pred()
        if v:
            return v
        if page is not None:
            page.wait_for_timeout(100)
        else:
            time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


@contextmanager
def _served(seq, viser: bool = True, max_upload: int | None = None, video=None,
            seeds_ahead: bool = False):
    """The app for ``seq`` on a free loopback port and a headless Chromium:
    ``(port, browser, created)``, ``created`` listing each session's Explorer; the server
    stopped, the browser and the explorers closed afterwards. Served as ``laav-explore``
    serves it (:func:`explorer.cli.serve_options`). ``video``: the tracked video ``seq`` is.
    ``seeds_ahead``: as ``laav-explore`` serves it, the next seed computed while idle."""
    created: list = []
    port = _free_port()
    C = None if video is None else video.n_motions
    server = pn.serve({"/": app_factory(seq, C, created=created, viser=viser, max_upload=max_upload,
                                        video=video, seeds_ahead=seeds_ahead)},
                      port=port, address="127.0.0.1", websocket_origin=[f"127.0.0.1:{port}"], show=False,
                      threaded=True, verbose=False, **serve_options())
    try:
        _wait_listening(port)
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
            try:
                yield port, browser, created
            finally:
                browser.close()
    finally:
        server.stop()
        for ex in created:
            ex.close()


def test_explorer_in_chromium(tmp_path):
    shots = Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    seq = _sequence()
    outside: list[str] = []
    sockets: list[str] = []
    js_errors: list[str] = []
    with _served(seq, viser=True) as (port, browser, created):
        context = browser.new_context(viewport={"width": 1600, "height": 1000})

        def route(r):
            url = r.request.url
            if url.startswith(LOCAL):
                r.continue_()
            else:
                outside.append(url)
                r.abort()

        context.route("**/*", route)
        page = context.new_page()
        received: set[str] = set()

        def on_socket(ws):
            sockets.append(ws.url)
            ws.on("framereceived", lambda _: received.add(ws.url))

        page.on("websocket", on_socket)
        page.on("pageerror", lambda e: js_errors.append(str(e)))
        page.on("console", lambda m: js_errors.append(m.text) if m.type == "error" else None)
        t0 = time.monotonic()
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex = _wait_for(lambda: created[0] if created else None, 10, "the session's explorer")
        assert ex.wait(60), "the first result did not arrive"
        page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=20000)
        page.wait_for_function("(" + JS_SOURCES + ")().status !== undefined", timeout=20000)
        load_s = time.monotonic() - t0
        before = page.evaluate(JS_SOURCES)
        assert before["points"] == seq.n_points
        page.screenshot(path=str(shots / "explorer_loaded.png"))

        # move λ in the page: the server recomputes and the browser's Z changes
        lam0 = ex.result.params.lam
        atoms0 = ex.result.atoms
        target = round(lam0 * 2 + 0.5, 1)
        assert page.evaluate(JS_SET_SLIDER, ["λ", target]) is not None
        _wait_for(lambda: ex.result.params.lam == target and ex.wait(1), 60, "the λ result")
        assert ex.result.atoms is atoms0
        _wait_for(lambda: f"λ = {target:g}" in page.evaluate(JS_SOURCES).get("ztitle", ""), 20,
                  "the Z title in the browser")
        # one line says what the change did (and the status names λ: it is off its default)
        page.get_by_text(f"What changed: λ {lam0:g} → {target:g}").first.wait_for(timeout=20000)
        page.get_by_text(f"λ = {target:g}").first.wait_for(timeout=20000)
        after = page.evaluate(JS_SOURCES)
        # the browser shows the new result's map (Z, or the joint merge's margins; whether or
        # not λ moved it on this sequence)
        want = V.z_sources(ex.result, seq, fit_votes=False)[0]["z"]
        assert after["z"] == pytest.approx(list(want), nan_ok=True)
        assert after["r1"] == before["r1"], "atoms changed with λ"

        # an impossible setting (fewer fine models than motions) shows a message in the
        # page and keeps the result
        res = ex.result
        assert page.evaluate(JS_SET_SLIDER, ["fine models", 1]) is not None
        page.get_by_text("Not used: fine_models (1) must be >=").first.wait_for(timeout=20000)
        assert ex.result is res
        # C typed as "2.5": refused with a message (an integer box in the page read "25")
        box = page.get_by_label("C — number of motions")
        box.fill("2.5")
        box.press("Enter")
        page.get_by_text("must be a positive integer, got 2.5").first.wait_for(timeout=20000)
        assert ex.result is res and ex.controls.w_motions.value == res.n_motions
        # the box shows the C in use again (so that the next change of another control is
        # not refused with it)
        _wait_for(lambda: box.input_value() in (str(res.n_motions), f"{res.n_motions}.0"), 20,
                  "the C box back at the C in use", page=page)

        # the 3-D view is served by this process on 127.0.0.1, started and connected once
        # its card is unfolded (it starts folded)
        assert ex.viser is None and "<iframe" not in ex.viser_pane.object
        page.locator(".card-header", has_text="3-D space-time view").first.click()
        viser = _wait_for(lambda: ex.viser, 60, "the 3-D view's server")
        # (its origin check lets its own page in: the scene arrives). Its client loads
        # with the first result and renders in software: slow on a loaded machine
        _wait_for(lambda: any(f":{viser.port}" in u for u in received), 90, "viser's scene",
                  page=page)
        assert f":{viser.port}/" in ex.viser_pane.object
        page.wait_for_timeout(1500)  # let the scene draw for the screenshot
        page.screenshot(path=str(shots / "explorer_after_lambda.png"))

        # a second tab gets its own explorer, unaffected by the first
        page2 = context.new_page()
        page2.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        ex2 = _wait_for(lambda: created[1] if len(created) > 1 else None, 30, "a second session")
        assert ex2.wait(60)
        # its own 3-D server, started when its card is unfolded
        assert ex2.viser is None
        page2.locator(".card-header", has_text="3-D space-time view").first.click()
        viser2 = _wait_for(lambda: ex2.viser, 60, "the second tab's 3-D server")
        assert ex2 is not ex and viser2.port != viser.port
        assert ex2.result.params.lam == laav.LaavParams().lam
        assert ex2.result.params.r1 == laav.LaavParams().r1
        page2.close()
    assert not outside, f"requests left 127.0.0.1: {outside}"
    assert not js_errors, f"JavaScript errors in the page: {js_errors[:5]}"
    print(f"page with first result in {load_s:.1f} s; screenshots in {shots}")


# every element a payload could create (bokeh and panel draw inside shadow roots: walk them)
JS_INJECTED = """() => {
  const out = {imgs: 0, scripts: 0, svgs: 0};
  const walk = (root) => {
    for (const el of root.querySelectorAll('*')) {
      const tag = el.tagName.toLowerCase();
      const src = el.getAttribute('src');
      if (tag === 'img' && (el.hasAttribute('onerror') || src === 'x' || src === 'y')) out.imgs++;
      if (tag === 'script' && el.textContent.includes('alert(')) out.scripts++;
      if (tag === 'svg' && el.hasAttribute('onload')) out.svgs++;
      if (el.shadowRoot) walk(el.shadowRoot);
    }
  };
  walk(document);
  return out;
}"""


#: Over one idle second: animation frames asked for through the browser, and those the
#: explorer routed to a timer (FilePond's painter loop: explorer.app.JS_THROTTLE_FILEPOND).
JS_FRAME_REQUESTS = """async () => {
  // idle means after the style sheets of the later cards have loaded: panel asks for a
  // frame when each loads (one-off; on a slow machine they were still loading here)
  const links = () => {
    const out = [];
    const visit = (root) => {
      for (const el of root.querySelectorAll('*')) {
        if (el.tagName === 'LINK' && el.rel === 'stylesheet') out.push(el);
        if (el.shadowRoot) visit(el.shadowRoot);
      }
    };
    visit(document);
    return out;
  };
  const pause = (ms) => new Promise(r => setTimeout(r, ms));
  for (let t = 0; t < 100 && links().some(l => l.sheet === null); t++) await pause(100);
  await new Promise(r => setTimeout(r, 200));
  const f = window.requestAnimationFrame;
  let real = 0, routed = 0;
  window.requestAnimationFrame = (cb) => { const id = f(cb); if (id < 0) routed++; else real++; return id; };
  await new Promise(r => setTimeout(r, 1000));
  window.requestAnimationFrame = f;
  // the status line's spinner (hidden while idle): its turning animation, paused
  let spin = null;
  const visit = (root) => {
    for (const el of root.querySelectorAll('*')) {
      if (el.shadowRoot && typeof el.className === 'string' && el.className.includes('loader spin')) {
        const d = el.shadowRoot.querySelector('div');
        if (d) { const a = getComputedStyle(d, '::after'); spin = [a.animationName, a.animationPlayState]; }
      }
      if (el.shadowRoot) visit(el.shadowRoot);
    }
  };
  visit(document);
  return {real, routed, throttled: window.__laavPainterThrottled === true, spin};
}"""


def test_hostile_names_are_shown_as_text(tmp_path):
    """File names and names stored in files carry HTML/script payloads: they show as text.
    The upload box works with its painter loop on a timer: an idle page asks for almost no
    animation frames (FilePond asked for 60 a second, for ever), and the hidden spinner
    does not turn (the compositor drew 60 frames a second for it)."""
    import numpy as np

    stored = "<script>alert(2)</script><img src=x onerror=alert(3)>"
    seq = _sequence()
    start = laav.Sequence(seq.points, seq.labels, name="<img src=x onerror=alert(5)>")
    up = laav.Sequence(seq.points[:, ::-1], seq.labels[::-1], name=stored)
    npz = laav.save_sequence(up, tmp_path / "up.npz").read_bytes()
    bad_mat = b"MATLAB 5.0 MAT-file" + bytes(200)  # a broken MAT file
    dialogs: list[str] = []
    with _served(start, viser=False) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1400, "height": 900})
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex = _wait_for(lambda: created[0] if created else None, 10, "the session's explorer")
        assert ex.wait(60)
        page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=20000)
        page.wait_for_timeout(1500)  # the page settled
        frames = page.evaluate(JS_FRAME_REQUESTS)
        assert frames["throttled"] and frames["routed"] >= 20 and frames["real"] <= 10, frames
        assert frames["spin"] == ["spin", "paused"], frames  # hidden, and not turning

        # a valid .npz: the file name and the stored name both carry payloads
        page.set_input_files("input[type=file]", files=[{
            "name": "<img src=x onerror=alert(1)>.npz", "mimeType": "application/octet-stream",
            "buffer": npz}])
        _wait_for(lambda: ex.sequence.name == stored and ex.wait(1), 60, "the uploaded sequence")
        page.get_by_text(stored).first.wait_for(timeout=20000)  # status line and sequence info
        assert ex.w_dl_csv.filename == "script_alert_2_script_img_src_x_onerror_alert_3__labels.csv"

        # a broken MAT file whose name carries a payload: the message quotes it as text
        page.set_input_files("input[type=file]", files=[{
            "name": "<img src=y onerror=alert(4)>.mat", "mimeType": "application/octet-stream",
            "buffer": bad_mat}])
        # (the upload box lists the name as soon as it is dropped: wait for the server's
        # refusal, which comes after the box has sent the file and the server parsed it)
        _wait_for(lambda: ex.alert.visible and "alert(4)" in ex.alert.object.replace("\\", ""), 90,
                  "the refusal of the broken file", page)
        page.get_by_text("<img src=y onerror=alert(4)>.mat").first.wait_for(timeout=30000)
        assert ex.sequence.name == stored  # the last good result is kept
        # and the status line no longer says "Reading …" (it shows the kept result again)
        _wait_for(lambda: ex.status.object.startswith("Showing"), 20, "the status line back")
        # the upload box is emptied: it said "Upload complete" for the file not used
        page.wait_for_function("(" + JS_UPLOAD_FILES + ")() === 0", timeout=20000)
        page.wait_for_timeout(1000)  # let any image error handler fire (and its dialog arrive)
        assert page.evaluate(JS_INJECTED) == {"imgs": 0, "scripts": 0, "svgs": 0}
        # the header and the tab name the sequence shown (the upload), as text
        page.get_by_text(f"{stored} · {up.n_points} points").first.wait_for(timeout=20000)
        safe = laav.safe_name(stored)
        page.wait_for_function(f"document.title === 'LAAV explorer: {safe}'", timeout=20000)
        assert "<" not in page.title() and "alert(5)" not in page.title()
    assert not dialogs, f"a payload ran: {dialogs}"
    assert np.all(np.isfinite(ex.result.labels))


# the right edge of every element drawn on the page (shadow roots included), against the viewport
JS_OVERFLOW = """() => {
  const W = window.innerWidth;
  const over = [];
  let right = 0;
  const name = (el) => `${el.tagName.toLowerCase()}.${String(el.className).slice(0, 40)}`;
  // clip: the right edge of the nearest ancestor that hides or scrolls its overflow
  const visit = (el, clip) => {
    const st = getComputedStyle(el);
    if (st.display === 'none') return;
    const r = el.getBoundingClientRect();
    const shown = r.width > 0 && r.height > 0 && st.visibility !== 'hidden';
    if (shown) {
      right = Math.max(right, r.right);
      if (r.right > W + 0.5) over.push(`${name(el)} right=${Math.round(r.right)}`);
      else if (r.right > clip + 1 && el.children.length === 0 && el.textContent.trim()) {
        over.push(`cut-off text "${el.textContent.trim().slice(0, 40)}" right=${Math.round(r.right)}`);
      }
    }
    let c = clip;
    if (shown && ['hidden', 'clip', 'auto', 'scroll'].includes(st.overflowX)) c = Math.min(c, r.right);
    for (const k of el.children) visit(k, c);
    if (el.shadowRoot) for (const k of el.shadowRoot.children) visit(k, c);
  };
  visit(document.documentElement, W);
  return {width: W, right: Math.round(right), scrollWidth: document.scrollingElement.scrollWidth,
          over: over.slice(0, 15), n_over: over.length};
}"""

# the titles of the page's cards, in document order
JS_CARD_TITLES = """() => {
  const out = [];
  const walk = (root) => {
    for (const el of root.querySelectorAll('*')) {
      if (el.classList && el.classList.contains('card-title')) {
        const h = (el.shadowRoot || el).querySelector('h3');
        out.push((h ? h.textContent : el.textContent).trim());
      }
      if (el.shadowRoot) walk(el.shadowRoot);
    }
  };
  walk(document);
  return out;
}"""


def _first_page(port: int, browser, created: list):
    """The served app's first page at 1280x800, and its session's explorer: (page, ex)."""
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
    page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
    return page, _wait_for(lambda: created[0] if created else None, 30, "the explorer")


def _settled(page, js: str, timeout: float = 30.0):
    """``page.evaluate(js)`` once it gives the same value twice, 300 ms apart (layout done)."""
    last = page.evaluate(js)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        page.wait_for_timeout(300)
        now = page.evaluate(js)
        if now == last:
            return now
        last = now
    raise AssertionError("the page layout kept changing")


#: The heights (px) of the card titles starting with the given text against their line
#: height: how many lines each takes.
JS_TITLE_LINES = """(start) => {
  const out = [];
  const walk = (root) => {
    for (const el of root.querySelectorAll('h3')) {
      const r = el.getBoundingClientRect();
      if (el.textContent.trim().startsWith(start) && r.height > 0)
        out.push(r.height / parseFloat(getComputedStyle(el).lineHeight));
    }
    for (const el of root.querySelectorAll('*')) if (el.shadowRoot) walk(el.shadowRoot);
  };
  walk(document);
  return out;
}"""


def test_layout_fits_a_projector(tmp_path, monkeypatch):
    """At 1280x800 and 1024x768 nothing reaches past the right edge and nothing scrolls
    sideways; the cards run in stage order; the 3-D card and the sidebar fold away; viser's
    notice of software WebGL (headless Chromium has no GPU) goes away on its own."""
    from explorer import viser_view

    monkeypatch.setattr(viser_view, "SOFTWARE_NOTICE_S", 8.0)
    shots = Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    seq = _sequence()
    with _served(seq, viser=True) as (port, browser, created):
        for i, (w, h) in enumerate(((1280, 800), (1024, 768))):
            page = browser.new_page(viewport={"width": w, "height": h})
            page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
            page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
            ex = _wait_for(lambda i=i: created[i] if len(created) > i else None, 30, "the explorer")
            assert ex.wait(60)
            page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=30000)
            page.wait_for_function(f"({JS_CARD_TITLES})().length >= 6", timeout=30000)
            # the 3-D card starts folded (its server not started); unfolded, its iframe must
            # fit as well
            assert ex.viser is None
            page.locator(".card-header", has_text="3-D space-time view").first.click()
            viser = _wait_for(lambda ex=ex: ex.viser, 60, "the 3-D view's server")
            page.frame_locator("iframe").locator("body").wait_for(timeout=60000)
            # the iframe at the loopback's other name (the page is at 127.0.0.1): another site,
            # which Chromium renders in a process of its own (an out-of-process frame target)
            src = page.locator("iframe").first.get_attribute("src")
            assert src.startswith(f"http://localhost:{viser.port}/"), src
            cdp = page.context.new_cdp_session(page)
            targets = cdp.send("Target.getTargets")["targetInfos"]
            assert any(t["type"] == "iframe" and t["url"].startswith(src) for t in targets), targets
            cdp.detach()
            if i == 0:  # viser's notice of software WebGL: shown, then taken away
                notice = page.frame_locator("iframe").get_by_text("Software WebGL rendering detected")
                # (the renderer viser judges by: without a GPU, as in CI, a software one)
                renderer = page.frame_locator("iframe").locator("body").evaluate(JS_WEBGL_RENDERER)
                assert renderer, "no WebGL renderer name in the 3-D frame"
                if any(k in renderer.lower() for k in ("swiftshader", "llvmpipe", "softpipe", "software")):
                    notice.wait_for(timeout=60000)
                    notice.wait_for(state="hidden", timeout=60000)
                else:  # a GPU: no notice
                    assert not notice.is_visible(), renderer
            m = _settled(page, JS_OVERFLOW)
            page.screenshot(path=str(shots / f"layout_{w}x{h}.png"))
            assert m["width"] == w
            assert m["n_over"] == 0 and m["right"] <= w, f"{w}x{h}: cut off at the right: {m}"
            assert m["scrollWidth"] <= w, f"{w}x{h}: the page scrolls sideways: {m}"
            titles = page.evaluate(JS_CARD_TITLES)
            order = [t.split(" ·")[0] for t in titles if " · " in t]
            assert order == ["1", "2", "3", "4", "5"], titles
            assert [t.split(":")[0] for t in titles if " · " in t] == [
                "1 · Atoms", "2 · Multicut graph of atoms → fine models (GAEC replay)",
                "3 · Fine-to-coarse", "4 · Fine-tuning (Random Voting)",
                "5 · Final labels and numbers"]
            assert any(t.startswith("3-D") for t in titles)
            # the 3-D card's title on one line (at 1024 it wrapped onto two)
            lines = page.evaluate(JS_TITLE_LINES, "3-D space-time view")
            assert lines and all(n < 1.5 for n in lines), (w, lines)
            # the 3-D view spans its card (it stopped ~40 px short at 1280 px: a max width)
            span = page.evaluate(JS_IFRAME_IN_CARD)
            assert span is not None and span["card"] - span["iframe"] <= 24, (w, span)
            if i == 1:
                # the 3-D card folds away (and back)
                iframe = page.locator(f"iframe[src*=':{viser.port}/']")
                assert iframe.is_visible()
                page.locator(".card-header", has_text="3-D space-time view").first.click()
                iframe.wait_for(state="hidden", timeout=10000)
                _wait_for(lambda ex=ex: ex.v_viser.collapsed, 10, "the 3-D card to fold")
                # the sidebar folds away: the main area gets its width
                sidebar = page.locator("#sidebar")
                assert sidebar.is_visible()
                page.locator("#sidebar-toggle").click()
                sidebar.wait_for(state="hidden", timeout=10000)
                m2 = _settled(page, JS_OVERFLOW)
                assert m2["n_over"] == 0 and m2["scrollWidth"] <= w
                page.screenshot(path=str(shots / f"layout_{w}x{h}_folded.png"))
            page.close()


def test_url_carries_the_state(tmp_path, monkeypatch):
    """``/?r1=25&seed=3&frame=4&color=final`` opens that state; moving a control updates the
    address; bad values are named as text on the page (no script runs); params.json uploads."""
    import json

    seq = _sequence()
    dialogs: list[str] = []
    with _served(seq, viser=False) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.goto(f"http://127.0.0.1:{port}/?r1=25&seed=3&frame=4&color=final",
                  wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex = _wait_for(lambda: created[0] if created else None, 30, "the explorer")
        assert ex.wait(60)
        assert (ex.result.params.r1, ex.result.seed, ex.w_frame.value) == (25.0, 3, 4)
        assert ex.w_color.value.startswith("final")
        page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=30000)
        # the browser's R1 slider shows it too
        r1 = page.evaluate("""() => { for (const m of Bokeh.documents[0].all_models)
            if (m.type === 'Slider' && String(m.title).startsWith('R1')) return m.value; }""")
        assert r1 == 25
        # the C box has no bounds in the page (its spinner neither clamped nor sent a value
        # past them: a typed 0 showed and did nothing); the state refuses it (below)
        lims = page.evaluate("""() => {
          for (const m of Bokeh.documents[0].all_models)
            if (m.type === 'Spinner' && String(m.title).startsWith('C ')) return [m.low, m.high];
        }""")
        assert lims == [None, None]
        # moving λ updates the address (no reload: the same session), replacing it: a change
        # of settings is no history entry (Back would change the address, not the page)
        entries = page.evaluate("history.length")
        assert page.evaluate(JS_SET_SLIDER, ["λ", 3.5]) is not None
        page.wait_for_function("location.search.includes('lam=3.5')", timeout=30000)
        assert page.evaluate("history.length") == entries
        q = dict(x.split("=") for x in page.evaluate("location.search")[1:].split("&"))
        assert q == {"r1": "25", "lam": "3.5", "seed": "3", "frame": "4", "color": "final"}
        assert len(created) == 1
        # frame moves (drawn by the page) send the address only once the frame rests: two
        # moves in a row, then the last frame's address (a long rest here: a loaded machine
        # must not take it for a send)
        monkeypatch.setattr(app_module, "FRAME_ADDRESS_REST_S", 4.0)
        for f in (6, 7):
            assert page.evaluate(JS_SET_SLIDER, ["frame", f]) is not None
            page.wait_for_function(f"""[...Bokeh.documents[0].all_models].some(
                m => m.type === 'Title' && String(m.text).startsWith('frame {f} of'))""", timeout=30000)
        _wait_for(lambda: ex.w_frame.value == 7, 30, "the server to learn the frame")
        assert "frame=4" in page.evaluate("location.search")  # not sent yet
        assert "frame=4" in ex.status_bar.address.value
        page.wait_for_function("location.search.includes('frame=7')", timeout=30000)
        # while the player plays (a step every 250 ms, each resting longer than the 0.1 s
        # here), the address waits; once it pauses, the frame it stopped at
        monkeypatch.setattr(app_module, "FRAME_ADDRESS_REST_S", 0.1)
        js_player = """(d) => { for (const m of Bokeh.documents[0].all_models)
            if (m.type.endsWith('Player')) m.direction = d; }"""
        page.evaluate(js_player, 1)
        _wait_for(lambda: ex.w_frame.value not in (7, 8, 9), 30, "the player to play")
        assert "frame=7" in page.evaluate("location.search")
        page.evaluate(js_player, 0)
        _wait_for(lambda: ex.w_frame.direction == 0, 30, "the player to pause")
        page.wait_for_function(f"location.search.includes('frame={ex.w_frame.value}')", timeout=30000)
        monkeypatch.undo()
        # a params.json upload (as exported) loads back
        d = json.loads(ex.files.export_json().getvalue())
        d["params"]["r1"], d["seed"] = 30.0, 1
        page.set_input_files("input[type=file]", files=[{
            "name": "params.json", "mimeType": "application/json", "buffer": json.dumps(d).encode()}])
        _wait_for(lambda: ex.result.params.r1 == 30.0 and ex.result.seed == 1 and ex.wait(1), 60,
                  "the uploaded parameters")
        page.wait_for_function(
            "location.search.includes('r1=30') && location.search.includes('seed=1')", timeout=30000)
        page.close()

        # bad values: a message naming them, as text; the rest applied
        bad = "<img src=x onerror=alert(1)>"
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.goto(f"http://127.0.0.1:{port}/?lam={bad}&r1=abc&seed=2&%3Cscript%3Ealert(2)%3C/script%3E=1",
                  wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex2 = _wait_for(lambda: created[1] if len(created) > 1 else None, 30, "the second explorer")
        assert ex2.wait(60)
        assert ex2.result.seed == 2 and ex2.result.params.r1 == 20.0
        page.get_by_text(f"lam must be a number, got '{bad}'").first.wait_for(timeout=20000)
        page.get_by_text("r1 must be a number, got 'abc'").first.wait_for(timeout=20000)
        page.get_by_text("unknown setting '<script>alert(2)</script>'").first.wait_for(timeout=20000)
        # the address keeps what was used, only
        page.wait_for_function("location.search === '?seed=2'", timeout=20000)
        page.wait_for_timeout(1000)  # let any error handler fire (and its dialog arrive)
        assert page.evaluate(JS_INJECTED) == {"imgs": 0, "scripts": 0, "svgs": 0}
        page.close()

        # nothing usable: the address is cleaned to none (the first result's query is "")
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(f"http://127.0.0.1:{port}/?r1=abc", wait_until="domcontentloaded")
        ex3 = _wait_for(lambda: created[2] if len(created) > 2 else None, 30, "the third explorer")
        assert ex3.wait(60)
        page.wait_for_function("location.search === ''", timeout=20000)
        # C = 0 typed in the page's C box (its first visible text box: the tour's hidden key
        # box comes before it): a message, the result kept
        res3 = ex3.result
        box = page.locator("input.bk-input[type=text]:visible").first
        assert box.input_value() == str(res3.n_motions)
        box.fill("0")
        box.press("Enter")
        page.get_by_text("the number of motions C must be a positive integer, got 0").first.wait_for(
            timeout=20000)
        assert ex3.wait(30) and ex3.result is res3
    assert not dialogs, f"a payload ran: {dialogs}"


def test_gaec_replay_keys_reach_both_ends():
    """The replay's Home/End keys go to step 0 and to the final step, also after a new result
    changed the number of steps (the old slider's End key went to step 1)."""
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, ex = _first_page(port, browser, created)
        assert ex.wait(60)

        def replay_input():
            # the replay's range input (CSS locators pierce shadow roots); its max follows
            rng = page.locator(f"input[type=range][max='{ex.w_step.end}']")
            rng.first.wait_for(timeout=30000)
            assert rng.count() == 1  # the frame player's max differs here
            return rng

        for _ in range(2):
            K1 = ex.w_step.end
            assert K1 == len(ex.result.multicut.contractions) + 1 and ex.w_step.value == K1
            box = replay_input()
            box.focus()
            page.keyboard.press("Home")
            _wait_for(lambda: ex.w_step.value == 0, 20, "step 0", page=page)
            page.keyboard.press("End")
            _wait_for(lambda K1=K1: ex.w_step.value == K1, 20, "the final step", page=page)
            # a new result with another number of contractions
            before = K1
            ex.w_params["r1"].value = 14.0 if ex.w_params["r1"].value != 14.0 else 26.0
            assert ex.wait(60)
            _wait_for(lambda: ex.result.params.r1 == ex.w_params["r1"].value, 30, "the R1 result")
            if ex.w_step.end != before:
                break
        assert ex.w_step.end != before, "R1 did not change the number of GAEC steps"
        K2 = ex.w_step.end
        box = replay_input()
        box.focus()
        page.keyboard.press("Home")
        _wait_for(lambda: ex.w_step.value == 0, 20, "step 0", page=page)
        page.keyboard.press("End")
        _wait_for(lambda: ex.w_step.value == K2, 20, "the new final step", page=page)


def _npz_bytes(seq, pad: int = 0) -> bytes:
    import io

    import numpy as np

    buf = io.BytesIO()
    extra = {"padding": np.zeros(pad, np.uint8)} if pad else {}
    np.savez(buf, points=seq.points, labels=seq.labels, name=seq.name, **extra)
    return buf.getvalue()


def _big_sequence(P: int = 3000, F: int = 30) -> laav.Sequence:
    """3,000 points each moving its own way (a first computation of ~2 s on one core;
    :func:`conftest.hold_computation` makes it last until cancelled)."""
    import numpy as np

    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 500, (1, P, 2)) + np.linspace(0, 1, F)[:, None, None] * rng.normal(0, 30, (1, P, 2))
    return laav.Sequence(pts, np.r_[np.zeros(P // 2, int), np.ones(P - P // 2, int)], name="big_one")


def test_uploads_past_the_limit_and_long_work(tmp_path, monkeypatch):
    """``--max-upload 24MB``: a 25 MB file is refused in the browser (never sent) with a
    message naming it, its size and the limit, and the page keeps working; an empty file
    says so; a valid 22 MB file (past the old ~15 MB death and bokeh's 20 MB message limit)
    loads; a long first computation shows progress and Cancel keeps the last result."""
    shots = Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    hold_computation(monkeypatch, "big_one")  # long until cancelled, on any machine
    seq = _sequence()
    js_errors: list[str] = []
    with _served(seq, viser=False, max_upload=24_000_000) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.on("pageerror", lambda e: js_errors.append(str(e)))
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex = _wait_for(lambda: created[0] if created else None, 30, "the explorer")
        assert ex.wait(60)
        page.wait_for_function("(" + JS_SOURCES + ")().points > 0", timeout=30000)
        page.get_by_text("Up to 24 MB").first.wait_for(timeout=20000)
        res = ex.result

        # over the limit: the browser does not send it, the page names it, size and limit
        page.set_input_files("input[type=file]", files=[{
            "name": "too big.npz", "mimeType": "application/octet-stream", "buffer": bytes(25_000_000)}])
        page.get_by_text("too big.npz (25 MB) is larger than the upload limit of 24 MB and was not "
                         "sent").first.wait_for(timeout=30000)
        page.get_by_text("File is too large").first.wait_for(timeout=10000)  # the box's own
        page.screenshot(path=str(shots / "upload_too_big.png"))
        assert ex.files._parts == {} and ex.result is res  # not one chunk arrived
        # the page still responds: a slider move recomputes
        assert page.evaluate(JS_SET_SLIDER, ["λ", 4.5]) is not None
        _wait_for(lambda: ex.result.params.lam == 4.5 and ex.wait(1), 60, "the λ result")

        # an empty file
        page.set_input_files("input[type=file]", files=[{
            "name": "empty.npz", "mimeType": "application/octet-stream", "buffer": b""}])
        page.get_by_text("empty.npz is empty (0 bytes): nothing was loaded").first.wait_for(timeout=30000)
        assert ex.sequence is seq

        # a valid file of 22 MB: in 1 MB messages, past the old limits
        other = _sequence()
        other = laav.Sequence(other.points[:, ::-1], other.labels[::-1], name="padded_22MB")
        base = len(_npz_bytes(other, pad=1000)) - 1000
        data = _npz_bytes(other, pad=22_000_000 - base)
        assert len(data) == 22_000_000
        page.set_input_files("input[type=file]", files=[{
            "name": "padded.npz", "mimeType": "application/octet-stream", "buffer": data}])
        _wait_for(lambda: ex.sequence.name == "padded_22MB" and ex.wait(1), 120, "the 22 MB upload")
        page.get_by_text("Showing padded_22MB").first.wait_for(timeout=30000)
        res = ex.result

        # a long first computation: progress, then Cancel keeps the last result
        page.set_input_files("input[type=file]", files=[{
            "name": "big_one.npz", "mimeType": "application/octet-stream",
            "buffer": _npz_bytes(_big_sequence())}])
        page.get_by_text("Computing the first result for big_one").first.wait_for(timeout=60000)
        page.screenshot(path=str(shots / "upload_progress.png"))
        page.locator("button", has_text="Cancel").last.click()
        page.get_by_text("Cancelled the first computation of big_one").first.wait_for(timeout=30000)
        page.get_by_text("still showing padded_22MB with its last result").first.wait_for(timeout=10000)
        assert ex.wait(30) and ex.result is res and ex.sequence.name == "padded_22MB"
        page.screenshot(path=str(shots / "upload_cancelled.png"))
        assert page.evaluate(JS_SET_SLIDER, ["λ", 2.5]) is not None
        _wait_for(lambda: ex.result.params.lam == 2.5 and ex.wait(1), 60, "a result after cancelling")
        assert ex.sequence.name == "padded_22MB"
    assert not js_errors, js_errors[:5]


#: The width of the page's iframe (the 3-D view) and of the card holding it, in px; null
#: when either is not found. Searches open shadow roots.
JS_IFRAME_IN_CARD = """() => {
  const all = [];
  const walk = (root) => { for (const el of root.querySelectorAll('*')) {
    all.push(el); if (el.shadowRoot) walk(el.shadowRoot); } };
  walk(document);
  const frame = all.find(el => el.tagName === 'IFRAME');
  let card = frame;
  while (card && !(card.classList && card.classList.contains('card'))) card = card.parentNode || card.host;
  if (!frame || !card) return null;
  return {iframe: frame.getBoundingClientRect().width, card: card.getBoundingClientRect().width};
}"""


#: How many files the page's upload box lists (its FilePond), -1 before it is up.
JS_UPLOAD_FILES = """() => {
  for (const m of Bokeh.documents[0].all_models) {
    const v = Bokeh.index.find_one(m);
    if (v && v._file_pond) return v._file_pond.getFiles().length;
  }
  return -1;
}"""


#: Where the frame view draws the points ``pts`` ([[x, y], ...], image coordinates), in page
#: pixels (from the plot's own scales), and the shape of the background image it holds.
JS_PROJECT = """(pts) => {
  let plot = null, shape = null;
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type === 'Figure' && m.title && /^frame \\d+ of/.test(m.title.text)) plot = m;
    if (m.type === 'ColumnDataSource' && m.data.image !== undefined && m.data.dw !== undefined
        && m.data.image.length) shape = Array.from(m.data.image[0].shape);
  }
  const view = Bokeh.index.find_one(plot);
  const r = view.el.getBoundingClientRect();
  const fx = view.frame.x_scale, fy = view.frame.y_scale;
  return {shape: shape, pts: pts.map(([x, y]) => [r.left + fx.compute(x), r.top + fy.compute(y)])};
}"""

JS_SET_FRAME = """(value) => {
  for (const m of Bokeh.documents[0].all_models)
    if (m.type.endsWith('Player') && m.title === 'frame') {
      m.value = value; m.value_throttled = value; return true;
    }
  return false;
}"""


def test_video_frames_lie_under_their_points_in_chromium(tmp_path):
    """The frame view's background in the page: frames coded by layer (the clip's masks:
    background, rectangle, disc as three grey levels), downscaled 2x, drawn behind the real
    tracks. With every other layer hidden, the screenshot's pixel under each complete track
    (projected by the plot's own scales) has its true layer's grey, at frame 0 and after
    scrubbing to frame 12: the image is not flipped (the y axis points down) nor offset, and
    it follows the frame."""
    import dataclasses

    import numpy as np
    from PIL import Image

    from explorer.video import FrameCache, open_video
    from laav.synthetic_video import load_clip

    clip_dir = Path(__file__).resolve().parents[1] / "assets" / "two_objects"
    clip = load_clip(clip_dir)
    # the complete tracks: every point has a position in the frames checked
    video = open_video(clip_dir, 3, progress=False, complete_only=True)
    coded = FrameCache(max_width=160)
    for t, m in enumerate(clip.masks):
        coded.add(t, m.astype(np.uint8) * 127)
    video = dataclasses.replace(video, frames=coded)
    seq = video.sequence
    from explorer.cards.frame import BACKGROUND_ALPHA

    level = 255 - BACKGROUND_ALPHA * (255 - np.array([0, 127, 254]))  # over the white figure
    outside: list[str] = []
    with _served(seq, viser=False, video=video) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.route("**/*", lambda r: r.continue_() if r.request.url.startswith(LOCAL)
                   else (outside.append(r.request.url), r.abort()))
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=60000)
        ex = _wait_for(lambda: created[0] if created else None, 30, "the session's explorer")
        assert ex.wait(120), "the first result did not arrive"
        fv = ex.frame_view

        def background_only():
            for r in fv.fig.renderers:
                r.visible = r is fv.r_background

        for frame in (0, 12):
            if frame:
                assert page.evaluate(JS_SET_FRAME, frame)
                _wait_for(lambda f=frame: ex.frame == f, 30, "the frame to change on the server")
            ex.schedule(background_only)  # a redraw shows the points again
            page.wait_for_function(
                f"(() => {{ for (const m of Bokeh.documents[0].all_models) if (m.type === 'Figure' && "
                f"m.title && m.title.text.startsWith('frame {frame} of')) return m.renderers.filter("
                "r => r.visible).length === 1; return false; })()", timeout=30000)
            page.wait_for_timeout(800)  # drawn
            got = page.evaluate(JS_PROJECT, seq.points[frame].tolist())
            assert got["shape"] == [120, 160]
            shot = tmp_path / f"video_frame_{frame}.png"
            page.screenshot(path=str(shot))
            grey = np.asarray(Image.open(shot).convert("L"), dtype=float)
            xy = np.floor(np.array(got["pts"])).astype(int)
            seen = grey[xy[:, 1], xy[:, 0]]
            layer = clip.masks[frame][np.round(seq.points[frame, :, 1]).astype(int),
                                      np.round(seq.points[frame, :, 0]).astype(int)]
            for k in range(3):
                ok = np.abs(seen[layer == k] - level[k]) <= 12
                assert (layer == k).sum() >= 10 and ok.mean() >= 0.95, (frame, k, ok.mean(),
                                                                        seen[layer == k][:8])
        page.close()
    assert not outside, f"requests left 127.0.0.1: {outside}"


# the frame view's points (the compare card's two sources of the same layout stay empty
# until a result is pinned)
JS_FRAME_POINTS = """() => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type === 'ColumnDataSource' && m.data.index !== undefined && m.data.marker !== undefined
        && m.data.index.length > 0)
      return {n: m.data.index.length, index: Array.from(m.data.index), x: Array.from(m.data.x)};
  }
  return null;
}"""

JS_SET_PLAYER = """(value) => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.loop_policy !== undefined && m.value !== undefined) { m.value = value; return true; }
  }
  return false;
}"""


def _frame_reached(ex, f: int, page) -> bool:
    try:
        _wait_for(lambda: ex.w_frame.value == f, 5, "the frame", page=page)
        return True
    except AssertionError:
        return False


def test_incomplete_sequence_in_chromium_draws_only_visible_points(tmp_path):
    """An occluded sequence (30 % hidden, NaN there): the frame view in the browser holds at
    frames 1 and 6 exactly the points visible there, different numbers of them."""
    from test_explorer_incomplete import occluded_sequence

    shots = Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path))
    shots.mkdir(parents=True, exist_ok=True)
    seq = occluded_sequence()
    want = {f: int(seq.visible[f].sum()) for f in (1, 6)}
    assert want[1] != want[6]
    js_errors: list[str] = []
    with _served(seq, viser=False) as (port, browser, created):
        context = browser.new_context(viewport={"width": 1280, "height": 800})
        context.route("**/*", lambda r: r.continue_() if r.request.url.startswith(LOCAL) else r.abort())
        page = context.new_page()
        page.on("pageerror", lambda e: js_errors.append(str(e)))
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        page.wait_for_function("window.Bokeh && Bokeh.documents.length > 0", timeout=30000)
        ex = _wait_for(lambda: created[0] if created else None, 10, "the session's explorer")
        assert ex.wait(120), "the first result did not arrive"
        for f in (1, 6):
            if not page.evaluate(JS_SET_PLAYER, f) or not _frame_reached(ex, f, page):
                ex.w_frame.value = f  # the server's slider (panel values are thread-safe)
            got = _wait_for(lambda f=f: (lambda d: d if d and d["n"] == want[f] else None)(
                page.evaluate(JS_FRAME_POINTS)), 30, f"the points of frame {f}", page=page)
            assert seq.visible[f, got["index"]].all()
            assert all(x == x for x in got["x"])  # no NaN reached the page
            page.screenshot(path=str(shots / f"explorer_incomplete_frame{f}.png"))
    assert not js_errors, js_errors


def test_a_seed_step_shows_the_next_seed_computed_while_idle():
    """As ``laav-explore`` serves it: once the page is complete and the result shown, the
    next seed is computed while idle; moving the seed slider there shows it at once, said
    on the status line, with the labels a fresh computation gives."""
    seq = _sequence()
    with _served(seq, viser=False, seeds_ahead=True) as (port, browser, created):
        page, ex = _first_page(port, browser, created)
        assert ex.wait(60) and ex.result.seed == 0
        st = ex.state
        _wait_for(lambda: any(k[1].seed == 1 for k in st._ahead) and st.plain_rv(
            settings=st.settings.__class__(st.settings.params, 1, st.settings.n_motions)) is not None,
            120, "seed 1 computed ahead", page=page)
        assert page.evaluate(JS_SET_SLIDER, ["seed", 1]) is not None
        page.get_by_text("ahead, while idle").first.wait_for(timeout=30000)
        assert ex.result.seed == 1 and st.ahead_used == 1
        np.testing.assert_array_equal(ex.result.labels, laav.segment(seq, ex.result.n_motions, seed=1).labels)


JS_WATCH_EPIPOLAR = """() => {
  // card 3's epipolar caption and its two plots' legends: every size they take from now on
  // (watched only once all three are on the page; returns how many there are)
  const found = [];
  const add = (m, what) => {
    const v = Bokeh.index.find_one(m);
    if (v && v.el) found.push([v.el, what]);
  };
  for (const m of Bokeh.documents[0].all_models) {
    const t = typeof m.text === 'string' ? m.text : '';
    if (t.includes('The vote for f')) add(m, 'caption');
    if ((m.type === 'Figure' || m.type === 'Plot') && m.title && /^frame [lr] = /.test(m.title.text))
      for (const r of m.below) if (r.type === 'Legend') add(r, 'legend');
  }
  if (found.length !== 3) return found.length;
  window.__epi = [];
  const ro = new ResizeObserver((entries) => {
    for (const e of entries) window.__epi.push([e.target.__what, Math.round(e.contentRect.height)]);
  });
  for (const [el, what] of found) { el.__what = what; ro.observe(el); }
  return 3;
}"""


#: Tops (px in the window) of the status line, the "What changed" line (when it has text)
#: and card 1's title.
JS_STATUS_TOPS = """() => { const out = {};
  const top = el => el.getBoundingClientRect().top;
  const walk = root => { for (const el of root.querySelectorAll('*')) {
    const text = (el.shadowRoot || el).textContent;
    if (el.classList && el.classList.contains('card-title') && text.includes('1 · Atoms')) out.card = top(el);
    if (el.tagName === 'P' && text.startsWith('Showing')) out.status = top(el);
    if (el.tagName === 'P' && text.startsWith('What changed')) out.change = top(el);
    if (el.shadowRoot) walk(el.shadowRoot); } };
  walk(document); return out; }"""


def test_what_changed_line_moves_no_card(tmp_path):
    """The "What changed" line keeps its place before the first change: when a change fills
    it, card 1 below stays where it was (it came in with ``display``, and every card below
    moved down by 41 px). At 1024 px the status line wraps once a setting is off its
    default: it kept the room for its second line, and card 1 stays where it was too."""
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page = browser.new_page(viewport={"width": 1024, "height": 768})
        page.goto(f"http://127.0.0.1:{port}/", wait_until="domcontentloaded")
        ex = _wait_for(lambda: created[0] if created else None, 30, "the explorer")
        assert ex.wait(60)
        page.wait_for_function("(" + JS_SOURCES + ")().status !== undefined", timeout=30000)
        before = _settled(page, JS_STATUS_TOPS)
        assert "card" in before and "change" not in before, before
        assert page.evaluate(JS_SET_SLIDER, ["λ", 4.5]) is not None
        page.get_by_text("What changed: λ").first.wait_for(timeout=30000)
        after = _settled(page, JS_STATUS_TOPS)
        page.screenshot(path=str(Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path)) / "what_changed.png"))
        assert after["status"] < after["change"] < after["card"], after
        assert after["card"] == pytest.approx(before["card"], abs=0.5), (before, after)
        # settings off their defaults make the status line wrap at 1024 px: it had a second
        # line's room from the start (STATUS_ROOM, at any width), so the cards stay where they are
        for name, value in (("R1", 23.0), ("R2", 41.0), ("seed", 3)):
            assert page.evaluate(JS_SET_SLIDER, [name, value]) is not None
            page.get_by_text(f"What changed: {name}").first.wait_for(timeout=30000)
        later = _settled(page, JS_STATUS_TOPS)
        # the status text's own height (its lines, not the room kept for them)
        lines = page.evaluate("""() => { let out = null;
          const walk = root => { for (const el of root.querySelectorAll('*')) {
            const text = (el.shadowRoot || el).textContent;
            if (el.tagName === 'P' && text.startsWith('Showing')) {
              const r = document.createRange(); r.selectNodeContents(el);
              out = [r.getBoundingClientRect().height, parseFloat(getComputedStyle(el).lineHeight)]; }
            if (el.shadowRoot) walk(el.shadowRoot); } };
          walk(document); return out; }""")
        assert lines[0] > 1.5 * lines[1], lines  # it wraps now (what the test is about)
        assert later["card"] == pytest.approx(before["card"], abs=0.5), (before, later)


#: Card 3's heat map as the page draws it: the widest number written in a cell (measured on a
#: canvas in the glyph's font) against a cell's width, and the colour bar's range, ticks and
#: the largest colour value.
JS_HEAT_MAP = """() => {
  let fig = null, text = null, bar = null;
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type === 'GlyphRenderer' && m.glyph.type === 'Text' && m.data_source.data.m !== undefined)
      text = m;
    if (m.type === 'ColorBar' && m.ticker.type === 'FixedTicker') bar = m;
  }
  for (const m of Bokeh.documents[0].all_models)
    if (m.type === 'Figure' && m.renderers.includes(text)) fig = m;
  const val = p => (p !== null && typeof p === 'object' && 'value' in p) ? p.value : p;
  const g = text.glyph, ctx = document.createElement('canvas').getContext('2d');
  ctx.font = `${val(g.text_font_style)} ${val(g.text_font_size)} ${val(g.text_font)}`;
  const texts = Array.from(text.data_source.data.text).filter(t => t);
  const z = Array.from(text.data_source.data.z).filter(v => Number.isFinite(v));
  return {font: ctx.font, visible: text.visible, n: texts.length,
          widest: Math.max(0, ...texts.map(t => ctx.measureText(t).width)),
          cell: fig.inner_width / fig.x_range.factors.length,
          low: bar.color_mapper.low, high: bar.color_mapper.high, ticks: Array.from(bar.ticker.ticks),
          zmax: Math.max(...z.map(Math.abs))};
}"""


@pytest.mark.hopkins
def test_card_3_numbers_fit_their_cells(hopkins_root, tmp_path):
    """On cars1 (8 fine models, margins up to 991 nats) card 3's numbers fit their cells (at
    9 pt, "+991" was 27 px in a 25.5 px cell: the numbers ran into each other), and its colour
    bar ends at a labelled tick past every value (it ended at 991 nats, its last label +100)."""
    seq = laav.load_sequence(hopkins_root / "cars1" / "cars1_truth.mat")
    with _served(seq, viser=False) as (port, browser, created):
        page, ex = _first_page(port, browser, created)
        assert ex.wait(120)
        header = page.locator(".card-header", has_text="3 · Fine-to-coarse")
        header.first.wait_for(timeout=60000)
        page.wait_for_function("(" + JS_SOURCES + ")().ztitle.startsWith('Joint merge')", timeout=30000)
        m = page.evaluate(JS_HEAT_MAP)
        header.first.scroll_into_view_if_needed()
        page.screenshot(path=str(Path(os.environ.get("LAAV_EXPLORER_SHOTS", tmp_path)) / "cars1_card3.png"))
        assert m["visible"] and m["n"] > 0, m  # (8 models: the values are written)
        assert m["widest"] <= m["cell"] - 2, m
        assert m["zmax"] <= m["high"] == -m["low"] and m["ticks"][-1] == pytest.approx(m["high"]), m
        assert m["ticks"][0] == pytest.approx(m["low"]), m


def test_card_3_keeps_its_size_while_its_votes_are_fitted(monkeypatch):
    """A result is drawn before card 3's pairwise votes are fitted (the default merge does
    not need them): meanwhile its epipolar caption keeps the room of a full one and its
    plots keep their legends, so the page below does not move up and back on every move (a
    layout of every plot in the browser: ~70 ms of an R1 move on the demo)."""
    from explorer.cards.epipolar import CAPTION_MIN_HEIGHT

    monkeypatch.setenv("LAAV_VOTING_HELPER", "0")  # (a helper fits them during the voting)
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, ex = _first_page(port, browser, created)
        assert ex.wait(60)
        page.wait_for_function("(" + JS_SOURCES + ")().status !== undefined", timeout=30000)
        # the caption and two legends (the later cards arrive after the first result)
        _wait_for(lambda: page.evaluate(JS_WATCH_EPIPOLAR) == 3, 60, "card 3's epipolar panel",
                  page=page)
        pending = []  # card 3's epipolar draws of the new result before its votes were fitted
        real = ex.coarse_view.epipolar.draw
        ex.coarse_view.epipolar.draw = lambda s, r: (pending.append(not V.votes_fitted(r)), real(s, r))[1]
        page.evaluate("() => { window.__epi = []; }")
        assert page.evaluate(JS_SET_SLIDER, ["R1", 23.0]) is not None
        _wait_for(lambda: ex.result is not None and ex.result.params.r1 == 23.0
                  and ex.votes_pending is None, 120, "the result and its votes", page=page)
        page.wait_for_function("(" + JS_SOURCES + ")().status.includes('R1 = 23')", timeout=30000)
        page.wait_for_timeout(1000)
        assert pending[:1] == [True] and pending[-1] is False  # drawn pending, then fitted
        sizes = page.evaluate("() => window.__epi")
        caption = [h for what, h in sizes if what == "caption"]
        legends = [h for what, h in sizes if what == "legend"]
        # about one height throughout (pending and fitted, the same sentences: at most one
        # line apart where a number's digits wrap it), never the one line it was pending
        assert all(h >= CAPTION_MIN_HEIGHT - 1 for h in caption), sizes
        assert not caption or max(caption) - min(caption) <= 20, sizes
        assert all(h > 0 for h in legends), sizes
        text = ex.coarse_view.epipolar.caption.object
        assert "The vote for f1" in text and "Fitting" not in text


def test_3d_points_show_the_2d_colours(tmp_path):
    """The 3-D view's points are drawn in the very colours of the 2-D views: viser's point
    shader writes colours to the screen as given, so they go as sRGB (lines, which three.js
    converts, go linear). Given linear values, as they were, orange #E69F00 showed as a
    red-brown (199, 80, 0)."""
    pytest.importorskip("viser")
    from PIL import Image

    from explorer.viser_view import ViserView

    seq = two_motion_sequence()
    res = laav.Pipeline(seq, 2).result
    colors = V.point_style(seq, res, "gt", None)["color"]
    view = ViserView()
    try:
        view.set_result(seq, res, colors, 0)
        for name in ("/trajectories", "/atoms", "/graph_edges", "/frame_plane"):
            view.server.scene.remove_by_name(name)  # the points alone
        with sync_api.sync_playwright() as p:
            browser = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=ARGS)
            try:
                page = browser.new_page(viewport={"width": 900, "height": 500})
                page.goto(view.url())
                page.locator("canvas").first.wait_for(timeout=60000)
                page.wait_for_timeout(3000)
                page.screenshot(path=str(tmp_path / "points.png"))
            finally:
                browser.close()
    finally:
        view.close()
    px = np.asarray(Image.open(tmp_path / "points.png").convert("RGB")).reshape(-1, 3).astype(int)
    for hex_colour in sorted(set(colors)):
        want = V.hex_to_rgb([hex_colour])[0].astype(int)
        near = (np.abs(px - want).max(axis=1) <= 8).sum()
        assert near >= 50, (hex_colour, near)  # (a point is several pixels across)
