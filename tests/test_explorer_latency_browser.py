"""What makes the explorer quick in Chromium (docs/bench/explorer_browser_latency.md), checked
on the page's websocket and models, never on timings:

- start-up: the trajectories are drawn before the first result, the later stages' cards
  come after it (a warm pipeline held back by the test), and the page loads no MathJax;
- a parameter change's result reaches the page as ONE message, its data last, and is
  drawn without a script error (bokeh's legend read a glyph's old colours when a legend
  label came after the data in one patch);
- a frame move sends none of the frame views' data: the page draws it itself
  (tests/test_explorer_frame_browser.py), the server only follows.
"""

from __future__ import annotations

import json
from concurrent.futures import Future

import pytest
from test_explorer_browser import ARGS, CHROMIUM, _sequence, _served, _wait_for  # noqa: F401

import laav
from explorer.cards.status import PREVIEW_STATUS
from explorer.warm import Warm

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: The page's state; ``status`` is a result's status line (a preview's, which a result
#: follows, is ``preview``: ExplorerState.on_preview).
JS_PAGE = """() => {
  const out = {status: '', preview: '', points: 0, graph: false, frame_title: ''};
  if (!(window.Bokeh && Bokeh.documents.length > 0)) return out;
  for (const m of Bokeh.documents[0].all_models) {
    if (typeof m.text === 'string' && m.text.includes('Showing')) {
      if (m.text.includes(""" + json.dumps(PREVIEW_STATUS) + """)) out.preview = m.text;
      else out.status = m.text;
    }
    if (m.type === 'ColumnDataSource' && m.data.index !== undefined) out.points = m.data.index.length;
    if (m.type === 'Title' && typeof m.text === 'string' && m.text.includes('atoms,') &&
        m.text.includes('edges')) out.graph = true;
    if (m.type === 'Title' && /^frame \\d+ of/.test(m.text)) out.frame_title = m.text;
  }
  return out;
}"""

JS_SET = """([prefix, value]) => {
  for (const m of Bokeh.documents[0].all_models) {
    if ((m.type === 'Slider' || m.type.endsWith('Player')) && typeof m.title === 'string'
        && m.title.startsWith(prefix)) { m.value = value; m.value_throttled = value; return true; }
  }
  return false;
}"""


def _open(browser, port):
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    errors: list[str] = []
    frames: list = []  # text frames the page received
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("websocket", lambda ws: ws.on("framereceived", lambda f: frames.append(f) if isinstance(f, str)
                                          else None))
    page.goto(f"http://127.0.0.1:{port}/")
    return page, errors, frames


def _open_with_result(browser, port):
    """:func:`_open`, then wait for the first result's status and graph (and half a second
    for anything the server sends after them)."""
    page, errors, frames = _open(browser, port)
    page.wait_for_function(f"() => ({JS_PAGE})().status.length > 0", timeout=60000)
    page.wait_for_function(f"() => ({JS_PAGE})().graph", timeout=60000)
    page.wait_for_timeout(500)
    return page, errors, frames


def _patches(frames) -> list[list[dict]]:
    """The events of every PATCH-DOC content the page received (header frames skipped)."""
    out = []
    for f in frames:
        if f.startswith('{"events"'):
            out.append(json.loads(f)["events"])
    return out


def test_start_up_shows_points_then_the_result_then_the_later_cards(monkeypatch):
    import test_explorer_browser as tb

    seq = _sequence()
    held: Future = Future()  # the first result (as laav-explore's child computes it), held back
    no_rv: Future = Future()
    no_rv.set_result(None)  # plain RV: computed by the server itself
    factory = tb.app_factory
    monkeypatch.setattr(tb, "app_factory", lambda *a, **k: factory(*a, warm=Warm(held, no_rv), **k))
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, _ = _open(browser, port)
        page.wait_for_function(f"() => ({JS_PAGE})().points > 0", timeout=60000)
        state = page.evaluate(JS_PAGE)
        assert state["status"] == "" and not state["graph"], state  # the points first, alone
        assert "bokeh-mathjax" not in page.content()
        page.wait_for_timeout(500)
        assert not page.evaluate(JS_PAGE)["graph"]  # the later cards wait for the result
        held.set_result(laav.Pipeline(seq, seq.n_motions))
        page.wait_for_function(f"() => ({JS_PAGE})().status.length > 0", timeout=60000)
        page.wait_for_function(f"() => ({JS_PAGE})().graph", timeout=60000)
        assert not errors, errors
        assert created[0].state.result is not None


def test_a_result_is_one_message_and_a_frame_move_sends_no_view_data():
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, frames = _open_with_result(browser, port)
        ex = created[0]
        # λ: here only the coarse stage's numbers change (the fine models merge as before: the
        # page's frame views are not remade); R1: new atoms, every view's data changes
        for title, field, value in (("λ", "lam", 3.5), ("λ", "lam", 2.5), ("R1", "r1", 16.0)):
            n0 = len(frames)
            gen0 = ex.live.meta.data["gen"][0]
            assert page.evaluate(JS_SET, [title, value])
            page.wait_for_function(f"() => ({JS_PAGE})().status.includes('{title} = {value:g}')",
                                   timeout=60000)
            _wait_for(lambda f=field, v=value: getattr(ex.settings.params, f) == v
                      and ex.result is ex.state.result, 30, "the result", page=page)
            page.wait_for_timeout(300)
            patches = _patches(frames[n0:])
            with_status = [ev for ev in patches
                           if any(e.get("attr") == "text" and "Showing" in str(e.get("new")) for e in ev)]
            assert len(with_status) == 1, "the status line came in more than one message"
            events = with_status[0]
            data = [i for i, e in enumerate(events) if e["kind"] == "ColumnDataChanged"
                    or (e["kind"] == "ModelChanged" and e.get("attr") == "data")]
            # (card 3's votes come in a message after the result's, once fitted:
            # ExplorerState.fit_votes; nothing else, and nothing before it)
            at = next(i for i, ev in enumerate(patches) if ev is events)
            ep = ex.coarse_view.epipolar
            votes = {m.id for m in (ex.coarse_view.src_z, ep.src_epi_l, ep.src_epi_r, ep.src_sample_l,
                                    ep.src_sample_r, ep.src_epi_lines)}

            def is_data(e):
                return e["kind"] == "ColumnDataChanged" or e.get("attr") == "data"

            assert not any(is_data(e) for ev in patches[:at] for e in ev) and not any(
                is_data(e) and e.get("model", {}).get("id") not in votes
                for ev in patches[at + 1:] for e in ev), "the result's data sources came in another message"
            assert data == list(range(len(events) - len(data), len(events))), "data changes are not last"
            ids = [e.get("model", {}).get("id") for e in events]
            if ex.live.meta.data["gen"][0] != gen0:  # the page remakes its frame views: told last
                assert ids[-1] == ex.live.meta.id, "the page's frame views' meta is not last"
            else:
                assert ex.live.meta.id not in ids
            if field == "r1":
                assert data and ex.live.meta.data["gen"][0] != gen0, "new atoms: new templates"
        n0 = len(frames)
        assert page.evaluate(JS_SET, ["frame", 1])
        page.wait_for_function(f"() => ({JS_PAGE})().frame_title.startsWith('frame 1 of')", timeout=30000)
        page.wait_for_timeout(300)
        _wait_for(lambda: ex.frame == 1, 30, "the server at frame 1", page=page)
        page.wait_for_timeout(300)
        views = {m.id for m in ex.live.models(frame_move=True)}
        assert ex.frame_view.src_points.id in views
        moved = [ev for ev in _patches(frames[n0:]) if any(e.get("model", {}).get("id") in views for e in ev)]
        assert not moved, "a frame move sent frame views' data (the page makes them)"
        assert not errors, errors


#: Every figure of the page: [title, element's top in the viewport (px), height, a paint
#: waiting for the plot to be seen (explorer/cards/onscreen.py), the x of the glyph view of
#: its first renderer with an x (or x0) column (what bokeh draws) and that column of its
#: source, new data waiting for the plot to be seen, and whether every visible renderer's
#: last paint drew its glyph's data (its screen x is the plot's x scale of the glyph's x)].
JS_PLOTS = """() => {
  const out = [];
  const column = (rv) => {
    const spec = rv.model.glyph.x !== undefined ? rv.model.glyph.x : rv.model.glyph.x0;
    return spec && typeof spec === 'object' && spec.field !== undefined ? spec.field : null;
  };
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure') continue;
    const v = Bokeh.index.find_one(m);
    if (!v || !v.el) continue;
    const r = v.el.getBoundingClientRect();
    let glyph = null, source = null, painted = true;
    for (const rv of v.renderer_views.values()) {
      const f = rv.glyph && rv.model.data_source ? column(rv) : null;
      if (f === null || rv.model.data_source.data[f] === undefined) continue;
      const gx = rv.glyph.x !== undefined ? rv.glyph.x : rv.glyph.x0;
      const sx = rv.glyph.sx !== undefined ? rv.glyph.sx : rv.glyph.sx0;
      if (glyph === null) { glyph = Array.from(gx || []); source = Array.from(rv.model.data_source.data[f]); }
      if (!rv.model.visible || !gx || !sx) continue;
      const want = rv.coordinates.x_scale.v_compute(gx);
      if (want.length !== sx.length) painted = false;
      for (let i = 0; painted && i < want.length; i++)
        if (!(Math.abs(want[i] - sx[i]) <= 1e-6 || (want[i] !== want[i] && sx[i] !== sx[i]))) painted = false;
    }
    out.push([String(m.title.text), r.top, r.height, !!v._laav_deferred, glyph, source,
              !!(v._laav_stale && v._laav_stale.size), painted]);
  }
  return out;
}"""


#: The rows of the first renderer with an x column of the figure titled ``title`` reversed in
#: the page only (its picture and its plot's ranges unchanged, its screen coordinates
#: reordered); whether there was one with 3 or more rows.
JS_REVERSE_ROWS = """(title) => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure' || String(m.title.text) !== title) continue;
    for (const r of m.renderers) {
      const spec = r.glyph && (r.glyph.x !== undefined ? r.glyph.x : r.glyph.x0);
      if (!r.data_source || !spec || typeof spec !== 'object' || spec.field === undefined) continue;
      const d = r.data_source.data, n = r.data_source.get_length();
      if (!(n >= 3)) continue;
      const out = {};
      for (const k of Object.keys(d)) out[k] = Array.from(d[k]).reverse();
      r.data_source.setv({data: out}, {sync: false});
      return true;
    }
  }
  return false;
}"""

#: A figure below the fold (its top more than ``margin`` px under the viewport) whose legend
#: lists a column's values: its legend's renderer given twice its rows in the page only, the
#: copies under a new value of that column (one more legend entry, and rows past the colours
#: its glyph computed before); the figure's title, or null.
JS_GROW_LEGEND = """(margin) => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure') continue;
    const v = Bokeh.index.find_one(m);
    if (!v || !v.el || !(v.el.getBoundingClientRect().top > window.innerHeight + margin)) continue;
    for (const leg of [...m.center, ...m.below, ...m.above, ...m.left, ...m.right]) {
      if (leg.type !== 'Legend') continue;
      for (const it of leg.items) {
        const field = it.label && it.label.field, r = it.renderers[0];
        if (field === undefined || !r || !r.data_source || !(r.data_source.get_length() >= 1)) continue;
        const d = r.data_source.data, out = {};
        for (const k of Object.keys(d)) {
          const a = Array.from(d[k]);
          out[k] = a.concat(k === field ? a.map(() => 'zz') : a);
        }
        r.data_source.setv({data: out}, {sync: false});
        return String(m.title.text);
      }
    }
  }
  return null;
}"""

#: No figure on screen has a paint, data or a reveal waiting (explorer/cards/onscreen.py).
JS_SETTLED = """() => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure') continue;
    const v = Bokeh.index.find_one(m);
    if (!v || !v.el) continue;
    const r = v.el.getBoundingClientRect();
    if (r.height > 0 && r.bottom > 0 && r.top < window.innerHeight
        && (v._laav_deferred || (v._laav_stale && v._laav_stale.size) || v._laav_revealing)) return false;
  }
  return true;
}"""


def test_plots_off_screen_are_painted_when_seen():
    """A result's plots below the fold keep their paint, and their glyphs' new data, for when
    they are scrolled into view (explorer/cards/onscreen.py): after R1 moves no plot on
    screen has a paint or data waiting and some plot far below has both; scrolled into view,
    it is painted from its new data. Scrolled away again, a change its ranges do not see
    waits, then is painted when seen (the renderer repainted, not only the plot); a plot
    whose data wait is not painted by bokeh's direct paint after a layout (its legend would
    read new rows past its glyph's old colours and throw), and is drawn right when seen.
    Scrolled away, the frame view is deferred in its turn on the next move."""
    from explorer.cards.onscreen import MARGIN_BELOW_PX

    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, frames = _open_with_result(browser, port)

        def plots():
            return {p[0]: p for p in page.evaluate(JS_PLOTS)}

        def move(value):
            assert page.evaluate(JS_SET, ["R1", value])
            page.wait_for_function(f"() => ({JS_PAGE})().status.includes('R1 = {value:g}')", timeout=60000)
            page.wait_for_timeout(300)  # (the server's later messages: plain RV, votes)
            page.wait_for_function(JS_SETTLED, timeout=10000)
            return plots()

        def scroll_to(t, away=None):
            """A figure by title, or the frame view (None), to the top; until the page's
            observer has reported it (and ``away``, a title, off screen) and no plot on screen
            waits."""
            page.evaluate("""(t) => { for (const m of Bokeh.documents[0].all_models)
                if (m.type === 'Figure'
                    && (t === null ? /^frame \\d+ of/.test(m.title.text) : m.title.text === t))
                  Bokeh.index.find_one(m).el.scrollIntoView({block: 'start'}); }""", t)
            page.wait_for_function("""([t, away]) => { for (const m of Bokeh.documents[0].all_models) {
                if (m.type !== 'Figure') continue;
                const v = Bokeh.index.find_one(m), title = String(m.title.text);
                const target = t === null ? /^frame \\d+ of/.test(title) : title === t;
                if (target && v._laav_shown !== true) return false;
                if (away !== null && title === away && v._laav_shown !== false) return false;
              } return true; }""", arg=[t, away], timeout=10000)
            page.wait_for_function(JS_SETTLED, timeout=10000)
            return plots()

        def renders(t):  # how many times bokeh has painted the figure titled t
            return page.evaluate("""(t) => { for (const m of Bokeh.documents[0].all_models)
                if (m.type === 'Figure' && m.title.text === t) return Bokeh.index.find_one(m)._render_count;
              return null; }""", t)

        def is_frame_view(title):
            return title.startswith("frame ") and " of " in title

        def holds_its_data(p):  # (categorical coordinates: the glyph holds their positions)
            if all(isinstance(x, (int, float)) for x in p[5] or []):
                return p[4] == p[5]
            return p[4] is not None and len(p[4]) == len(p[5])

        below = 800 + MARGIN_BELOW_PX  # off screen for the page's observer
        move(16.0)  # the first move observes every plot; the next defers those off screen
        got = move(18.0)
        on_screen = [p for p in got.values() if p[2] > 0 and p[1] < 800]
        assert any(is_frame_view(p[0]) for p in on_screen)
        assert not [p[0] for p in on_screen if p[3] or p[6]], "a plot on screen kept its paint or data"
        assert all(p[7] for p in on_screen) and all(holds_its_data(p) for p in on_screen if p[4] is not None)
        waiting = [p for p in got.values() if p[3]]
        assert waiting and all(p[1] > 800 for p in waiting), "no plot off screen kept its paint"
        stale = [p for p in waiting if p[6] and p[4] is not None]
        assert stale, "no plot off screen kept its glyphs' new data (the server's)"
        title = stale[-1][0]
        got = scroll_to(title)
        assert 0 <= got[title][1] < 800, "not scrolled into view"
        seen = [p for p in got.values() if p[2] > 0 and 0 <= p[1] < 800]
        assert not [p[0] for p in seen if p[3] or p[6]], "scrolled into view, a plot was not painted"
        assert holds_its_data(got[title]), f"scrolled into view, {title!r} holds old data"
        # what was painted is the new data (a renderer given it but not repainted shows the old)
        assert not [p[0] for p in seen if not p[7]], "a plot on screen shows other data than it holds"

        # seen, then off screen again: a change its ranges do not see (its rows reversed: the
        # same picture) leaves only that renderer to repaint when seen again
        assert scroll_to(None, away=title)[title][1] > below
        assert page.evaluate(JS_REVERSE_ROWS, title)
        got = plots()
        assert got[title][6] and not holds_its_data(got[title]), "the new rows were applied off screen"
        got = scroll_to(title)
        assert not got[title][3] and not got[title][6] and holds_its_data(got[title])
        assert got[title][7], "seen again, its renderer was not repainted with its new rows"

        # a plot whose data wait, laid out again off screen (shown anew, as a tour step or a
        # pin does): bokeh paints it directly, which must wait too
        scroll_to(None)
        grown = page.evaluate(JS_GROW_LEGEND, MARGIN_BELOW_PX)
        assert grown is not None, "no figure with a legend of a column below the fold"
        scroll_to(None, away=grown)
        assert plots()[grown][6]
        before = renders(grown)
        page.evaluate("""(t) => { for (const m of Bokeh.documents[0].all_models)
            if (m.type === 'Figure' && m.title.text === t) {
              m.setv({visible: false}, {sync: false}); m.setv({visible: true}, {sync: false}); } }""", grown)
        page.wait_for_timeout(300)
        assert not errors, errors
        assert renders(grown) == before, "laid out off screen with its data waiting, the plot was painted"
        assert plots()[grown][6], "laid out off screen, the plot was given its data"
        got = scroll_to(grown)
        assert not got[grown][3] and not got[grown][6] and got[grown][7] and holds_its_data(got[grown])
        assert not errors, errors
        got = move(17.0)
        frame = next(p for t, p in got.items() if is_frame_view(t))
        assert frame[1] < -300 and frame[3], "the frame view, scrolled away, was painted"
        assert not errors, errors
