"""Card 2's atom ids follow a zoom, checked in Chromium: a box zoom with the plot's own tool
writes the ids that overlapped at the first scale (the page's source, as the server placed
them again), and the reset tool leaves them out again."""

from __future__ import annotations

import pytest
from test_explorer_browser import _served, _wait_for
from test_explorer_latency_browser import _open_with_result

from explorer.demo import demo_sequence

pytestmark = [pytest.mark.browser, pytest.mark.slow]

#: The ids the page's card 2 writes (non-empty labels of the nodes' source ``sid``), and the
#: figure ``fid``'s frame on screen: (count, [left, top, right, bottom] in page px).
JS_IDS = """([sid, fid]) => {
  let n = -1, box = null;
  for (const m of Bokeh.documents[0].all_models) {
    if (m.id === sid) n = Array.from(m.data.label).filter((t) => t).length;
    if (m.id === fid) {
      const v = Bokeh.index.find_one(m);
      if (v) {
        const r = v.el.getBoundingClientRect(), f = v.frame.bbox;
        box = [r.left + f.left, r.top + f.top, r.left + f.right, r.top + f.bottom];
      }
    }
  }
  return [n, box];
}"""


def test_a_box_zoom_places_the_atom_ids_again():
    seq = demo_sequence()
    with _served(seq, viser=False) as (port, browser, created):
        page, errors, _ = _open_with_result(browser, port)
        ex = created[0]
        gv = ex.graph_view
        n = ex.result.graph.n_nodes
        ids = lambda: page.evaluate(JS_IDS, [gv.src_nodes.id, gv.fig.id])  # noqa: E731
        # card 2's toolbar (below its plot: the second with a box zoom), on screen (the page
        # paints the plots on screen only)
        picked = page.locator(".bk-Toolbar").filter(has=page.locator(".bk-tool-icon-box-zoom")).nth(1)
        picked.scroll_into_view_if_needed()
        page.wait_for_timeout(500)
        before, box = ids()
        assert 0 < before < n and box is not None
        left, top, right, bottom = box
        tb = picked.bounding_box()
        assert 0 < bottom < tb["y"] < bottom + 150 and tb["y"] + tb["height"] <= 800, (box, tb)
        # its box zoom, then a drag over the middle third of the plot
        picked.locator(".bk-tool-icon-box-zoom").click()
        w, h = right - left, bottom - top
        page.mouse.move(left + w / 3, top + h / 3)
        page.mouse.down()
        page.mouse.move(left + w / 2, top + h / 2, steps=5)
        page.mouse.move(left + 2 * w / 3, top + 2 * h / 3, steps=5)
        page.mouse.up()
        _wait_for(lambda: ids()[0] > before, 30, "more ids written after the zoom", page=page)
        assert ids()[0] == sum(1 for t in gv.src_nodes.data["label"] if t)
        picked.locator(".bk-tool-icon-reset").click()
        _wait_for(lambda: ids()[0] == before, 30, "the first ids again after the reset", page=page)
        assert not errors, errors
