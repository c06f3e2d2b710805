"""A frame move is drawn by the page itself (explorer/cards/live.py), checked in Chromium on
the page's bokeh models and the renderers' glyph data, never on timings:

- with the server's event loop blocked, moving the frame player redraws the frame view
  (points, trails, atoms, marks, title) and the graph at that frame's coordinates;
- afterwards the server knows the frame and sent none of those views' data;
- the page's views equal the server's copies after frame moves from either side, a λ
  change, a colouring and a GAEC step, on an incomplete sequence (gaps in the trails).
"""

from __future__ import annotations

import threading

import numpy as np
import pytest
from test_explorer_browser import _sequence, _served, _wait_for
from test_explorer_latency_browser import JS_PAGE, JS_SET, _open_with_result, _patches

from explorer import views as V
from explorer.cards.live import unpacked_colors

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: The page's copy of some models, by id: a source's columns, a title's or a legend item's text.
JS_MODELS = """(ids) => {
  const byid = {}, out = {};
  for (const m of Bokeh.documents[0].all_models) byid[m.id] = m;
  for (const id of ids) {
    const m = byid[id];
    if (m === undefined) { out[id] = null; continue; }
    if (m.type === 'ColumnDataSource') {
      const d = {};
      for (const k of Object.keys(m.data)) d[k] = Array.from(m.data[k]);
      out[id] = d;
    } else if (m.type === 'Title') out[id] = m.text;
    else out[id] = m.label && m.label.value !== undefined ? m.label.value : m.label;
  }
  return out;
}"""

#: What bokeh draws for a renderer: its glyph view's x (null before its view exists).
JS_GLYPH_X = """(id) => {
  for (const m of Bokeh.documents[0].all_models) {
    if (m.id === id) { const v = Bokeh.index.find_one(m); return v ? Array.from(v.glyph.x) : null; }
  }
  return null;
}"""


def _columns_differ(page_cols: dict, want: dict) -> list:
    """Where a page source's columns differ from ``want`` (coordinates to float32's precision)."""
    bad = []
    if set(page_cols) != set(want):
        bad.append(("columns", sorted(set(page_cols) ^ set(want))))
    for k, v in want.items():
        a, b = np.asarray(page_cols.get(k, [])), np.asarray(v)
        if a.shape != b.shape:
            bad.append((k, a.shape, b.shape))
        elif b.dtype.kind == "f":
            if not np.allclose(a.astype(float), b, atol=1e-3, rtol=1e-6, equal_nan=True):
                bad.append((k, "values"))
        elif b.dtype.kind in "UO" and a.dtype.kind in "iuf" and a.size:
            # colours, which the page holds packed (explorer.cards.live.packed_colors)
            page_hex = np.char.upper(unpacked_colors(a.astype(np.uint32)).astype(str))
            if not (page_hex == np.char.upper(b.astype(str))).all():
                bad.append((k, "values"))
        elif not (a.astype(str) == b.astype(str)).all():
            bad.append((k, "values"))
    return bad


def _page_differs_from_server(page, ex) -> list:
    """Where the page's frame-following views (sources, titles, legend labels) differ from
    the server's copies; [] when they agree."""
    models = ex.live.models()
    assert models, "the page does not make the frame views (LiveFrames inactive)"
    got = page.evaluate(JS_MODELS, [m.id for m in models])
    bad = []
    for m in models:
        g = got[m.id]
        if g is None:
            bad.append((m, "not in the page"))
        elif hasattr(m, "data"):
            bad += [(m.id, *b) for b in _columns_differ(g, dict(m.data))]
        elif hasattr(m, "text"):
            if g != m.text:
                bad.append((m.id, g, m.text))
        else:
            want = m.label.get("value") if isinstance(m.label, dict) else getattr(m.label, "value", m.label)
            if g != want:
                bad.append((m.id, g, want))
    return bad


def _settle(page, ex, frame: int) -> None:
    _wait_for(lambda: ex.frame == frame, 30, f"the server at frame {frame}", page=page)
    page.wait_for_timeout(400)  # anything the server sends after it has arrived


def test_a_frame_move_is_drawn_by_the_page_while_the_server_is_blocked():
    seq = _sequence()
    f = 7
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, frames = _open_with_result(browser, port)
        ex = created[0]
        assert ex.frame == 0 and not _page_differs_from_server(page, ex)
        fv, gv = ex.frame_view, ex.graph_view
        want = V.frame_sources(seq, ex.result, f, ex.style, moved=ex.moved)
        want_graph = V.graph_sources(ex.result, f, int(gv.w_step.value), ex.fine_colors,
                                     layout=gv.id_layout(ex.result))
        assert len(want["trails"]["x0"]) > 0 and len(want["atoms"]["x"]) > 0

        # the session's event loop stops here: the server handles nothing until released
        gate, blocked = threading.Event(), threading.Event()
        ex.schedule(lambda: (blocked.set(), gate.wait(60)))
        assert blocked.wait(30)
        try:
            n0 = len(frames)
            assert page.evaluate(JS_SET, ["frame", f])
            title = page.wait_for_function(
                f"() => {{ const t = ({JS_PAGE})().frame_title; return t.startsWith('frame {f} of') && t; }}",
                timeout=10000).json_value()
            assert ex.frame == 0, "the server saw the move: it was not blocked"
            x = seq.points[f, np.asarray(want["points"]["index"]), 0]
            glyph = page.wait_for_function(
                f"() => {{ const x = ({JS_GLYPH_X})('{fv.r_points.id}'); "
                f"return x && x.length === {x.size} && x; }}", timeout=10000).json_value()
            np.testing.assert_allclose(glyph, x, atol=1e-3)  # what bokeh draws: frame f's points
            got = page.evaluate(JS_MODELS, [s.id for s in (fv.src_points, fv.src_trails, fv.src_atoms,
                                                           fv.src_unassigned, fv.src_errors, fv.src_changed,
                                                           gv.src_nodes, gv.src_joined, gv.src_cut)])
            for src, key in ((fv.src_points, "points"), (fv.src_trails, "trails"), (fv.src_atoms, "atoms"),
                             (fv.src_unassigned, "unassigned"), (fv.src_errors, "errors"),
                             (fv.src_changed, "changed")):
                assert not _columns_differ(got[src.id], want[key]), key
            for src, key in ((gv.src_nodes, "nodes"), (gv.src_joined, "joined"), (gv.src_cut, "cut")):
                assert not _columns_differ(got[src.id], want_graph[key]), key
            assert ex.frame == 0
        finally:
            gate.set()
        _settle(page, ex, f)
        assert title.startswith(f"frame {f} of") and fv.fig.title.text == title
        sent = {m.id for m in ex.live.models(frame_move=True)}
        touched = [e for ev in _patches(frames[n0:]) for e in ev if e.get("model", {}).get("id") in sent]
        assert not touched, f"the server sent frame views after the move: {touched[:3]}"
        assert not _page_differs_from_server(page, ex)  # the server's copies followed the page
        # the legend draws stand-ins (live.py); a click on an entry still hides its renderers
        shown = ("(id) => { for (const m of Bokeh.documents[0].all_models) "
                 "if (m.id === id) return m.visible; }")
        assert page.evaluate(shown, fv.r_r1.id)
        page.get_by_text("atom R1", exact=True).first.click()
        page.wait_for_function(f"() => ({shown})('{fv.r_r1.id}') === false && ({shown})('{fv.r_r2.id}')",
                               timeout=10000)
        _wait_for(lambda: not fv.r_r1.visible, 30, "the server to hide the atom circles", page=page)
        assert not errors, errors


def test_the_page_and_the_server_agree_on_an_incomplete_sequence():
    """Frame moves from the page and from the server, a λ change, a colouring and a GAEC
    step at frames past 0 on an occluded sequence (points, trails with gaps, atoms hidden):
    the page's views equal the server's copies after each."""
    from test_explorer_incomplete import occluded_sequence

    seq = occluded_sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, _ = _open_with_result(browser, port)
        ex = created[0]
        for f in (3, 8):
            assert page.evaluate(JS_SET, ["frame", f])
            _settle(page, ex, f)
            assert not _page_differs_from_server(page, ex), f
            idx = np.asarray(ex.src_points.data["index"])
            assert seq.visible[f, idx].all() and len(idx) == seq.visible[f].sum()
        assert page.evaluate(JS_SET, ["λ", 3.5])
        page.wait_for_function(f"() => ({JS_PAGE})().status.includes('λ = 3.5')", timeout=60000)
        _wait_for(lambda: ex.result is ex.state.result and ex.settings.params.lam == 3.5, 30, "the result",
                  page=page)
        page.wait_for_timeout(400)
        assert not _page_differs_from_server(page, ex), "after λ"
        # each change is scheduled on the server: wait until it has happened there (else the
        # page and the server agree, trivially, on the state before it), then for the page
        for what, fn, done in (
                ("colour", lambda: setattr(ex.w_color, "value", "errors: final"),
                 lambda: "errors: final" in ex.fig_frame.title.text),
                ("step", lambda: setattr(ex.graph_view.w_step, "value", 2),
                 lambda: int(ex.graph_view.w_step.value) == 2),
                ("server frame", lambda: setattr(ex.w_frame, "value", 10),
                 lambda: ex.frame == 10 and "frame 10 of" in ex.fig_frame.title.text)):
            ex.schedule(fn)
            _wait_for(done, 30, f"the server after the {what}", page=page)
            _wait_for(lambda: not _page_differs_from_server(page, ex), 30, f"the page after the {what}",
                      page=page)
        assert ex.frame == 10 and "frame 10 of" in ex.fig_frame.title.text
        assert not errors, errors


#: The frame view's plot in page pixels (``left``, ``top``: its element), its frame box
#: (``x``, ``y``, ``w``, ``h``, in the plot's own pixels) and its x range's width (``span``);
#: with ``zoom`` its ranges are first narrowed to their middle ``zoom`` share (as the wheel
#: zoom narrows them).
JS_FRAME_BOX = """(zoom) => {
  for (const m of Bokeh.documents[0].all_models)
    if (m.type === 'Figure' && m.title && /^frame \\d+ of/.test(m.title.text)) {
      const v = Bokeh.index.find_one(m);
      if (zoom) for (const r of [m.x_range, m.y_range]) {
        const s = r === m.x_range ? v.frame.x_range : v.frame.y_range;
        const c = (s.start + s.end) / 2, h = (s.end - s.start) * zoom / 2;
        r.setv({start: c - h, end: c + h});
      }
      const e = v.el.getBoundingClientRect(), b = v.frame.bbox;
      return {left: e.left, top: e.top, x: b.x, y: b.y, w: b.width, h: b.height,
              span: Math.abs(v.frame.x_range.end - v.frame.x_range.start)};
    }
  return null;
}"""

#: The control: the page's clipping undone (the glyph renderers' view getter of
#: JS_CLIP_OVERLAYS deleted) and the frame view repainted; whether the getter was there.
JS_UNCLIP = """() => {
  let proto = null, plot = null;
  for (const m of Bokeh.documents[0].all_models) {
    if (proto === null && m.type === 'GlyphRenderer' && m.level === 'overlay')
      proto = m.default_view.prototype;
    if (m.type === 'Figure' && m.title && /^frame \\d+ of/.test(m.title.text)) plot = m;
  }
  const had = Object.prototype.hasOwnProperty.call(proto, 'needs_clip');
  delete proto.needs_clip;
  Bokeh.index.find_one(plot).request_paint();
  return had;
}"""


def test_zoomed_points_are_clipped_to_the_frame_in_chromium(tmp_path):
    """The frame view draws its points, trails and atoms on its overlay canvas (repainted
    alone on a frame move: :meth:`explorer.cards.live.LiveFrames.repaint_alone`), which bokeh
    clips to the plot's frame only when asked (:data:`explorer.cards.live.JS_CLIP_OVERLAYS`).
    Zoomed in to the middle third, most points lie outside the frame: the screenshot's strips
    beside the frame (the axes: black and grey text and lines only) hold no motion colour, and
    the frame itself still does (the points inside are drawn). The control: with the page's
    clipping undone, the same strips do hold motion colours (the test sees an unclipped
    drawing)."""
    from PIL import Image

    seq = _sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, _ = _open_with_result(browser, port)
        before = page.evaluate(JS_FRAME_BOX, 0)
        box = page.evaluate(JS_FRAME_BOX, 1 / 3)
        page.wait_for_timeout(500)  # repainted at the new ranges
        assert page.evaluate(JS_FRAME_BOX, 0)["span"] == pytest.approx(before["span"] / 3, rel=0.01)
        shots = [tmp_path / "zoomed.png", tmp_path / "unclipped.png"]
        page.screenshot(path=str(shots[0]))
        assert page.evaluate(JS_UNCLIP), "the page did not clip (no getter on the view class)"
        page.wait_for_timeout(500)
        page.screenshot(path=str(shots[1]))
        assert not errors, errors
    clipped, unclipped = (np.asarray(Image.open(p).convert("RGB")).astype(int) for p in shots)
    x0, y0 = round(box["left"] + box["x"]), round(box["top"] + box["y"])
    x1, y1 = x0 + round(box["w"]), y0 + round(box["h"])
    assert round(box["left"]) + 2 < x0 - 3 and y0 - 30 >= 0 and y1 + 30 <= clipped.shape[0]

    def outside(img):  # saturated pixels in the y axis's strip, under the frame, above it
        strips = (img[y0:y1, round(box["left"]) + 2:x0 - 3], img[y1 + 3:y1 + 30, x0:x1],
                  img[y0 - 30:y0 - 3, x0:x1])
        return tuple(int(((a.max(-1) - a.min(-1)) > 80).sum()) for a in strips)

    inside = clipped[y0:y1, x0:x1]
    assert int(((inside.max(-1) - inside.min(-1)) > 80).sum()) > 200, "no points drawn inside"
    assert outside(clipped) == (0, 0, 0), "points drawn outside the plot's frame"
    assert sum(outside(unclipped)) > 50, "the control: unclipped points not seen outside the frame"
