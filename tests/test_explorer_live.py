"""The data the page gets to draw frame moves itself (explorer/cards/live.py), without a
browser: tracks, templates, the size limit, the legend's stand-ins. The page's side is
checked in Chromium by tests/test_explorer_frame_browser.py."""

from __future__ import annotations

import numpy as np
import pytest

from explorer import views as V
from explorer.app import Explorer
from explorer.cards.live import LIVE_MAX_ENTRIES, LiveFrames, legend_rows, packed_colors, unpacked_colors
from explorer.demo import demo_sequence


@pytest.fixture(scope="module")
def seq():
    from test_explorer_incomplete import occluded_sequence

    return occluded_sequence()


def test_the_page_gets_the_tracks_once_and_the_templates_per_result(seq):
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        live = ex.live
        assert live.enabled and live.active
        pts = live.tracks["points"].data
        F, P = seq.n_frames, seq.n_points
        assert len(pts["x"]) == F * P and np.asarray(pts["x"]).dtype == np.float32
        np.testing.assert_array_equal(np.asarray(pts["v"]).reshape(F, P), seq.visible)
        y = np.asarray(pts["y"]).reshape(F, P)
        np.testing.assert_allclose(y[seq.visible], seq.points[..., 1][seq.visible], rtol=1e-6)
        meta = live.meta.data
        assert (meta["live"][0], meta["points_f"][0], meta["points_n"][0]) == (1, F, P)
        assert meta["t_frame_title"][0].startswith(f"frame {{f}} of {F - 1}")
        # a template, made at the frame shown, is what the server shows there
        _, tsrc, spec = live.views["frame_trails"]
        # (its colours go packed, 0xRRGGBBAA: the page's bokeh maps them without a CSS parse)
        assert np.asarray(tsrc.data["=color"]).dtype == np.uint32
        tpl = {("_" + k[1:]) if k[0] == "@" else k[1:]: unpacked_colors(np.asarray(v))
               for k, v in tsrc.data.items()}
        ex.w_frame.value = 7
        got = V.instantiate(tpl, spec, seq.points, seq.visible, 7)
        for k, v in got.items():
            np.testing.assert_array_equal(np.asarray(ex.frame_view.src_trails.data[k]), v)
        # a frame move: the page makes these; a result: their templates go, the views do not
        moved = {id(m) for m in live.models(frame_move=True)}
        assert id(ex.frame_view.src_points) in moved and id(ex.graph_view.src_nodes) in moved
        assert id(live.meta) in moved and id(live.meta) not in {id(m) for m in live.models()}
        sent_track = live.tracks["points"]
        before = dict(sent_track.data)
        ex.w_params["lam"].value = 3.5
        assert ex.wait(60)
        assert all(sent_track.data[k] is before[k] for k in before)  # same sequence: not again
    finally:
        ex.close()


def test_the_page_remakes_its_views_only_when_what_it_makes_them_from_changed(seq):
    """A redraw that leaves every track, template, text format and the frame as they were
    (the same result drawn again; a λ move that merged the fine models as before) sends no
    new generation: the page's views, already those, are not remade and repainted. A
    redraw that changes a template (another colouring) or the frame does."""
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        live, meta = ex.live, ex.live.meta
        gen = meta.data["gen"][0]
        st = ex.state
        ex._apply_result(st.result, st.sequence, st.settings, ex.applied_generation)
        assert meta.data["gen"][0] == gen  # the same result again: nothing new for the page
        before = {k: dict(tsrc.data) for k, (_, tsrc, _) in live.views.items()}
        ex.controls.set_color_mode("atoms")
        assert ex.wait(60)
        assert meta.data["gen"][0] > gen  # another colouring: the points' template changed
        assert any(not all(np.array_equal(np.asarray(v), np.asarray(before[k][c]))
                           for c, v in tsrc.data.items()) for k, (_, tsrc, _) in live.views.items())
        gen = meta.data["gen"][0]
        assert not live.commit(ex.frame) and meta.data["gen"][0] == gen
        assert live.commit(ex.frame + 1) and meta.data["gen"][0] == gen + 1  # another frame
        live.text("frame_title", "frame {f} · another format", ex.frame, {})
        assert live.commit(ex.frame + 1) and meta.data["gen"][0] == gen + 2
    finally:
        ex.close()


def test_above_the_limit_the_server_draws_every_frame(seq, monkeypatch):
    monkeypatch.setenv("LAAV_EXPLORE_LIVE_MAX", str(seq.n_frames * seq.n_points - 1))
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        live = ex.live
        assert not live.enabled and live.models() == [] and live.models(frame_move=True) == []
        assert len(live.tracks["points"].data["x"]) == 0 and live.meta.data["live"][0] == 0
        assert all(len(tsrc.data["@a"]) == 0 for _, tsrc, _ in live.views.values())
        ex.w_frame.value = 6  # the server's copies follow (they are sent: nothing is dropped)
        idx = np.asarray(ex.src_points.data["index"])
        assert len(idx) == seq.visible[6].sum() and seq.visible[6, idx].all()
    finally:
        ex.close()


@pytest.mark.parametrize("raw", ["", "many", "1e3"])
def test_a_bad_limit_in_the_environment_is_the_default(raw, monkeypatch):
    monkeypatch.setenv("LAAV_EXPLORE_LIVE_MAX", raw)
    assert LiveFrames().max_entries == LIVE_MAX_ENTRIES


def test_legend_rows_one_per_label_no_position():
    tpl = {"_a": np.array([4, 2, 9], np.int32), "color": np.array(["#a", "#b", "#a"]),
           "label": np.array(["m1", "m2", "m1"])}
    spec = V.frame_specs()["points"]
    rows = legend_rows(tpl, spec, by="label")
    assert list(rows["label"]) == ["m1", "m2"] and list(rows["color"]) == ["#a", "#b"]
    assert np.isnan(rows["x"]).all() and len(rows["y"]) == 2
    trails = legend_rows({"_a": np.arange(3), "_b": np.arange(3), "color": np.array(["#c"] * 3)},
                         V.frame_specs()["trails"])
    assert list(trails["alpha"]) == [V.trail_alpha(1)] and np.isnan(trails["x1"]).all()
    empty = legend_rows({"_a": np.zeros(0, np.int32)}, V.frame_specs()["errors"])
    assert len(empty["x"]) == 0


def test_the_legend_draws_stand_ins_that_follow_the_layers(seq):
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        fv = ex.frame_view
        items = fv.fig.legend[0].items
        moving = {id(r) for r in (fv.r_points, fv.r_r1, fv.r_r2, fv.r_unassigned, fv.r_errors, fv.r_changed)}
        assert not any(id(r) in moving for it in items for r in it.renderers)
        points_stand_in = ex.live.stand_in(fv.r_points)
        assert points_stand_in is not fv.r_points and "index" not in points_stand_in.data_source.data
        labels = set(np.asarray(points_stand_in.data_source.data["label"]))
        assert labels == set(np.asarray(fv.src_points.data["label"]))  # one legend entry per motion
        ex.w_layers.value = [v for v in ex.w_layers.value if not v.startswith("atom")]
        assert not fv.r_r1.visible and not ex.live.stand_in(fv.r_r1).visible
        assert fv.r_points.level == "overlay" and fv.fig.title.level == "overlay"
    finally:
        ex.close()


def test_atom_ids_are_written_up_to_a_limit(seq, monkeypatch):
    """Atom ids beside the graph's nodes up to MAX_ATOM_IDS atoms; above it (thousands of
    tracks) they are hidden, and the caption says so and where to find an id."""
    from explorer.cards import graph

    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        gv = ex.graph_view
        n = ex.result.graph.n_nodes
        assert 0 < n <= graph.MAX_ATOM_IDS
        assert gv.r_ids.visible and "Atom ids are written" not in gv.caption.object
        assert list(gv.src_nodes.data["label"])  # the ids are in the nodes' source
        # placed at the plot's size: those that would overlap are left out, and the caption
        # says how many (views.id_layout)
        left_out = sum(1 for t in gv.src_nodes.data["label"] if not t) - len(gv.src_pair.data["text"])
        assert (f"{left_out} atom id" in gv.caption.object) == (left_out > 0)
        assert gv.id_layout(ex.result) is gv.id_layout(ex.result)  # (kept across steps)
        monkeypatch.setattr(graph, "MAX_ATOM_IDS", n - 1)
        gv.draw(ex.result, ex.frame, ex.fine_colors)
        assert not gv.r_ids.visible
        assert f"up to {n - 1} atoms (here {n}" in gv.caption.object
        monkeypatch.setattr(graph, "MAX_ATOM_IDS", n)
        gv.draw(ex.result, ex.frame, ex.fine_colors)
        assert gv.r_ids.visible and "Atom ids are written" not in gv.caption.object
    finally:
        ex.close()


def test_packed_colours_round_trip_and_leave_other_columns():
    """The page's templates carry hex colours as bokeh's packed RGBA (uint32 0xRRGGBBAA);
    anything that is not a column of hex colours goes as it is."""
    hexes = np.array(["#0072B2", "#D55E00", "#FFFFFF"])
    packed = packed_colors(hexes)
    assert packed.dtype == np.uint32 and int(packed[0]) == 0x0072B2FF and int(packed[2]) == 0xFFFFFFFF
    np.testing.assert_array_equal(unpacked_colors(packed), hexes)
    for other in (np.array([1.0, 2.0]), np.array(["red", "#000000"]), np.array(["#12345G"]),
                  np.array(["#FFFFFF80"]), np.zeros(0, "U7"), np.array([3, 4], dtype=np.int32)):
        assert packed_colors(other) is other or np.array_equal(packed_colors(other), other)
        assert packed_colors(other).dtype == other.dtype


def test_a_zoom_places_the_atom_ids_again(monkeypatch):
    """Card 2's ids are placed at the plot's scale: zooming in (the page's RangesUpdate)
    writes the ids that overlapped before, zooming back out leaves them out again, and a
    pan or a small zoom places nothing again."""
    from bokeh.events import RangesUpdate

    from explorer.cards import graph

    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        gv, f = ex.graph_view, ex.graph_view.fig
        shown = lambda: sum(1 for t in gv.src_nodes.data["label"] if t)  # noqa: E731
        n, before = ex.result.graph.n_nodes, shown()
        assert 0 < before < n, "every id fits at the first size: the test would check nothing"
        assert "left out: zoom in" in gv.caption.object
        home = (f.x_range.start, f.x_range.end, f.y_range.start, f.y_range.end)
        layouts = []
        real = V.id_layout
        monkeypatch.setattr(V, "id_layout", lambda *a: layouts.append(1) or real(*a))

        def view(zoom, shift=0.0):
            x0, x1, y0, y1 = home
            cx, cy, hx, hy = (x0 + x1) / 2 + shift, (y0 + y1) / 2, (x1 - x0) / 2 / zoom, (y1 - y0) / 2 / zoom
            r = dict(x0=cx - hx, x1=cx + hx, y0=cy - hy, y1=cy + hy)
            f.x_range.start, f.x_range.end = r["x0"], r["x1"]
            f.y_range.start, f.y_range.end = r["y0"], r["y1"]
            f._trigger_event(RangesUpdate(f, **r))  # as bokeh's server dispatches the page's event

        view(1.0, shift=40.0)  # a pan: the same scale
        view(1.1)  # under RELAYOUT_ZOOM
        assert not layouts and shown() == before
        view(4.0)
        assert layouts and shown() > before
        assert shown() == n and "left out" not in gv.caption.object
        view(1.0)
        assert shown() == before
        assert graph.RELAYOUT_ZOOM > 1.1
        # a new sequence's extent is the reset tool's view too
        from explorer.cards.base import fit_image_figure

        fit_image_figure(f, (0.0, 100.0, 0.0, 50.0))
        assert (f.x_range.reset_start, f.x_range.reset_end) == (f.x_range.start, f.x_range.end)
        assert (f.y_range.reset_start, f.y_range.reset_end) == (f.y_range.start, f.y_range.end)
    finally:
        ex.close()


def test_a_mark_with_no_rows_keeps_its_legend_swatch():
    """No point changed motion (the first result) and none misclassified: their legend
    entries still draw their ring (one row at no position), as their glyphs' look is all
    constants; a view whose glyph reads a column of its rows (the atoms' colour) gets none."""
    seq = demo_sequence()
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        fv, live = ex.frame_view, ex.live
        assert len(fv.src_changed.data["x"]) == 0  # nothing changed yet
        rows = live.stand_in(fv.r_changed).data_source.data
        assert len(rows["x"]) == 1 and np.isnan(rows["x"]).all()
        tpl = {"_a": np.zeros(0, np.int32), "r1": np.zeros(0), "r2": np.zeros(0),
               "color": np.zeros(0, "U7"), "atom": np.zeros(0, np.int64)}
        live.template("frame_atoms", tpl)
        assert all(len(v) == 0 for v in live.stand_in(fv.r_r1).data_source.data.values())
    finally:
        ex.close()
