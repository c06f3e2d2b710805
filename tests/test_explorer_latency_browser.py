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
#: its first line or scatter (what bokeh draws) and of that renderer's source].
JS_PLOTS = """() => {
  const out = [];
  for (const m of Bokeh.documents[0].all_models) {
    if (m.type !== 'Figure') continue;
    const v = Bokeh.index.find_one(m);
    if (!v || !v.el) continue;
    const r = v.el.getBoundingClientRect();
    let glyph = null, source = null;
    for (const rv of v.renderer_views.values()) {
      if (!rv.glyph || !rv.model.data_source || rv.model.data_source.data.x === undefined) continue;
      glyph = Array.from(rv.glyph.x || []); source = Array.from(rv.model.data_source.data.x); break;
    }
    out.push([String(m.title.text), r.top, r.height, !!v._laav_deferred, glyph, source]);
  }
  return out;
}"""


def test_plots_off_screen_are_painted_when_seen():
    """A result's plots below the fold keep their paint for when they are scrolled into view
    (explorer/cards/onscreen.py): after R1 moves no plot on screen has a paint waiting and
    some plot far below has one, its data applied already (its glyph view holds its
    source's new data); scrolled into view, it is painted and nothing on screen waits.
    Scrolled away, the frame view is deferred in its turn on the next move."""
    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, frames = _open_with_result(browser, port)

        def move(value):
            assert page.evaluate(JS_SET, ["R1", value])
            page.wait_for_function(f"() => ({JS_PAGE})().status.includes('R1 = {value:g}')", timeout=60000)
            page.wait_for_timeout(500)
            return {p[0]: p for p in page.evaluate(JS_PLOTS)}

        def is_frame_view(title):
            return title.startswith("frame ") and " of " in title

        move(16.0)  # the first move observes every plot; the next defers those off screen
        plots = move(18.0)
        on_screen = [p for p in plots.values() if p[2] > 0 and p[1] < 800]
        assert any(is_frame_view(p[0]) for p in on_screen)
        assert not [p[0] for p in on_screen if p[3]], "a plot on screen kept its paint"
        waiting = [p for p in plots.values() if p[3]]
        assert waiting and all(p[1] > 800 for p in waiting), "no plot off screen kept its paint"
        assert any(p[4] is not None for p in waiting)
        for p in waiting:  # (categorical coordinates: the glyph holds their positions)
            same = p[4] == p[5] if all(isinstance(x, (int, float)) for x in p[5] or []) else \
                p[4] is not None and len(p[4]) == len(p[5])
            assert same, f"the data of {p[0]!r}, off screen, were not applied"
        title = waiting[-1][0]
        page.evaluate("""(t) => { for (const m of Bokeh.documents[0].all_models)
            if (m.type === 'Figure' && m.title.text === t)
              Bokeh.index.find_one(m).el.scrollIntoView({block: 'start'}); }""", title)
        page.wait_for_timeout(500)
        plots = {p[0]: p for p in page.evaluate(JS_PLOTS)}
        assert 0 <= plots[title][1] < 800, "not scrolled into view"
        assert not [p[0] for p in plots.values() if p[2] > 0 and 0 <= p[1] < 800 and p[3]], \
            "scrolled into view, a plot was not painted"
        plots = move(17.0)
        frame = next(p for t, p in plots.items() if is_frame_view(t))
        assert frame[1] < -300 and frame[3], "the frame view, scrolled away, was painted"
        assert not errors, errors
