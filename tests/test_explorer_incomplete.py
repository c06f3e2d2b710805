"""The explorer on incomplete tracks (issue 14): a sequence with a visibility mask loads and
computes, every view draws only what is seen (the frame view at frame f only the points
visible at f, trails broken at gaps; the 3-D view, the graph and the epipolar panel likewise),
and points labelled -1 (seen too briefly) get their own style and legend entry and count as
errors in the numbers, as the metrics count them.

Hidden coordinates are NaN here, so a view that read one would show NaN.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import laav

pn = pytest.importorskip("panel")

from conftest import two_motion_sequence  # noqa: E402

from explorer import Explorer  # noqa: E402
from explorer import views as V  # noqa: E402
from laav.synthetic import occlude  # noqa: E402

FAST = laav.LaavParams(rv_max_iter=30, rv_trials=2)
BRIEF = np.arange(0, 140, 35)  # 4 points seen in frames 0-1 only: too briefly to decide


def occluded_sequence() -> laav.Sequence:
    """140 points, 12 frames, 30 % of the entries hidden (NaN there), 4 points seen briefly."""
    seq = two_motion_sequence(0)
    occ = occlude(seq, 0.3, np.random.default_rng(0))
    vis = occ.visible.copy()
    vis[:, BRIEF] = False
    vis[:2, BRIEF] = True
    pts = seq.points.copy()
    pts[~vis] = np.nan
    return laav.Sequence(pts, seq.labels, name="occluded", image_size=seq.image_size, visible=vis)


@pytest.fixture(scope="module")
def occ() -> laav.Sequence:
    return occluded_sequence()


@pytest.fixture(scope="module")
def res(occ):
    return laav.Pipeline(occ, 2, FAST).result


def _finite(d: dict, skip=("error", "cost")) -> None:
    for k, v in d.items():
        a = np.asarray(v)
        if a.dtype.kind == "f" and k not in skip:
            assert np.isfinite(a).all(), k


def test_the_fixture_has_gaps_and_unlabelled_points(occ, res):
    assert not occ.is_complete and 0.6 < occ.visible_share < 0.8
    assert np.all(res.labels[BRIEF] == -1) and np.all(res.unlabelled_code[BRIEF] == 1)


def test_frame_view_data_holds_only_visible_points(occ, res):
    style = V.point_style(occ, res, "final")
    counts = []
    for f in range(occ.n_frames):
        d = V.frame_sources(occ, res, f, style, moved=np.arange(occ.n_points))
        idx = np.asarray(d["points"]["index"])
        assert np.array_equal(np.sort(idx), np.flatnonzero(occ.visible[f]))
        counts.append(idx.size)
        for key in ("points", "trails", "atoms", "unassigned", "errors", "changed"):
            _finite(d[key])
        assert len(d["changed"]["x"]) == occ.visible[f].sum()  # every point "moved": the visible ones
        # trails: one segment per consecutive pair of frames both seen (a gap breaks the trail)
        f0 = max(0, f - 5)
        want = int((occ.visible[f0:f] & occ.visible[f0 + 1:f + 1]).sum())
        assert len(d["trails"]["x0"]) == want
        seeds = np.asarray(res.atoms.seeds)
        assert np.array_equal(np.asarray(d["atoms"]["atom"]), np.flatnonzero(occ.visible[f, seeds]))
    assert len(set(counts)) > 1  # frames see different numbers of points


def test_graph_and_epipolar_views_draw_only_what_is_seen(occ, res):
    pos = np.asarray(res.graph.positions)
    for f in range(occ.n_frames):
        for step in (0, 3, 10**6):
            g = V.graph_sources(res, f, step)
            for key in ("nodes", "joined", "cut", "step_edge", "pair"):
                _finite(g[key])
            assert np.array_equal(np.asarray(g["nodes"]["atom"]), np.flatnonzero(np.isfinite(pos[f, :, 0])))
    n = len(res.coarse.fine_to_coarse)
    checked = 0
    for j in range(n):
        for k in range(n):
            e = V.epipolar_sources(occ, res, j, k)
            if not e["ok"]:
                continue
            fl, fr = e["frames"]
            both = occ.visible[fl] & occ.visible[fr]
            fine = np.asarray(res.coarse.fine_point_labels)
            assert len(e["left"]["x"]) == int((((fine == j) | (fine == k)) & both).sum())
            for key in ("left", "right", "sample_left", "sample_right", "lines"):
                _finite(e[key])
            checked += 1
    assert checked


def test_unlabelled_points_have_their_own_style_and_count_as_errors(occ, res):
    for mode in ("final", "plain"):
        st = V.point_style(occ, res, mode, plain=res.voting if mode == "plain" else None)
        assert set(st["label"][BRIEF]) == {V.UNSEEN_LABEL}
        assert set(st["marker"][BRIEF]) == {V.UNSEEN_MARKER} and set(st["color"][BRIEF]) == {V.UNSEEN}
        others = np.setdiff1d(np.arange(occ.n_points), BRIEF)[res.labels[np.setdiff1d(
            np.arange(occ.n_points), BRIEF)] >= 0]
        assert V.UNSEEN_LABEL not in set(st["label"][others])
    err = V.point_style(occ, res, "errors")
    assert err["misclassified"][BRIEF].all()  # an error, as the metrics count it
    assert set(err["marker"][BRIEF]) == {V.UNSEEN_MARKER}
    num = V.stage_numbers(occ, res)
    assert num["n_unlabelled"] == BRIEF.size
    assert num["error_final"] == pytest.approx(laav.misclassification_rate(occ.labels, res.labels))
    assert num["error_final"] >= BRIEF.size / occ.n_points
    md = V.numbers_markdown(num)
    assert f"{occ.n_points - BRIEF.size} of {occ.n_points} points labelled" in md
    assert f"{BRIEF.size} {V.UNSEEN_LABEL}" in md and "counted as errors" in md
    assert "unlabelled ones count as errors" in md
    # without a ground truth nothing is counted as an error (no error is scored)
    bare = V.numbers_markdown({**num, "error_final": None, "error_fine": None, "error_coarse": None})
    assert f"{BRIEF.size} {V.UNSEEN_LABEL}" in bare and "as errors" not in bare
    assert f"{100 * occ.visible_share:.1f} % of the entries visible" in md
    # colour-by modes stay consistent: every mode styles every point, the same points
    for mode in V.COLOR_MODES.values():
        st = V.point_style(occ, res, mode, plain=res.voting)
        assert st["color"].shape == st["marker"].shape == st["label"].shape == (occ.n_points,)
    table = V.labels_table(occ, res).splitlines()
    hidden0 = np.flatnonzero(~occ.visible[0])
    assert hidden0.size and ",," in table[1 + hidden0[0]] and "nan" not in "".join(table)


def test_the_app_loads_draws_and_counts_an_incomplete_sequence(occ):
    ex = Explorer(occ, params=FAST, viser=False)
    try:
        assert ex.wait(120) and ex.result is not None and not ex.alert.visible
        counts = {}
        for f in (0, 1, 6):
            ex.w_frame.value = f
            idx = np.asarray(ex.src_points.data["index"])
            assert ex.sequence.visible[f, idx].all() and idx.size == occ.visible[f].sum()
            assert np.isfinite(np.asarray(ex.src_points.data["x"], float)).all()
            assert np.isfinite(np.asarray(ex.src_nodes.data["x"], float)).all()
            counts[f] = idx.size
        assert counts[1] != counts[6]
        ex.w_frame.value = 0
        ex.w_color.value = "final (after Random Voting)"
        labels = set(ex.src_points.data["label"])
        assert V.UNSEEN_LABEL in labels  # the legend entry (legend_field="label")
        md = ex.numbers_view.numbers.object
        assert f"{BRIEF.size} {V.UNSEEN_LABEL}" in md
        note = re.sub(r"\\(.)", r"\1", ex.note.object)
        assert "140 tracks over 12 frames" in note and "% of the entries visible" in note
        assert f"{BRIEF.size} points are" in note
        # after a cancel the note says so and keeps what it says about the data
        ex.files._after_cancel("the recomputation", occ.name)
        after = re.sub(r"\\(.)", r"\1", ex.note.object)
        assert after.startswith("**Cancelled** the recomputation") and "% of the entries visible" in after
        for label in V.COLOR_MODES:
            ex.w_color.value = label
            assert len(ex.src_points.data["x"]) == occ.visible[0].sum()
    finally:
        ex.close()


def test_the_3d_view_draws_only_visible_samples(occ, monkeypatch):
    pytest.importorskip("viser")
    ex = Explorer(occ, params=FAST)
    try:
        assert ex.wait(120)
        ex.view3d.start()  # (what the card's first unfold does; the scene is sent at the unfold below)
        ex.view3d.wait(120)
        scene = ex.viser.server.scene
        drawn = {}
        real_pc, real_ls = scene.add_point_cloud, scene.add_line_segments

        def pc(name, points, colors, **kw):
            drawn[name] = np.asarray(points)
            return real_pc(name, points, colors, **kw)

        def ls(name, points, colors, **kw):
            drawn[name] = np.asarray(points)
            return real_ls(name, points, colors, **kw)

        monkeypatch.setattr(scene, "add_point_cloud", pc)
        monkeypatch.setattr(scene, "add_line_segments", ls)
        ex.v_viser.collapsed = False
        ex.w_color.value = "ground truth"  # new colours: the trajectories are redrawn
        ex.w_frame.value = 6
        assert ex.viser._frame == 6
        assert len(drawn["/points"]) == occ.visible[6].sum() and np.isfinite(drawn["/points"]).all()
        from explorer.viser_view import TRAIL_SAMPLES

        want = int(occ.visible.sum())  # the trails: every seen sample (within the budget)
        assert want <= TRAIL_SAMPLES
        assert len(drawn["/trajectories"]) == want and np.isfinite(drawn["/trajectories"]).all()
        assert np.isfinite(drawn["/atoms"]).all()
    finally:
        ex.close()


def test_titles_fit_when_not_every_point_voted_and_without_ground_truth():
    # card 4's title with the voted count was cut off beside the toolbar; card 5's title
    # spoke of a ground truth the sequence does not have
    from explorer.cards.numbers import CARD_TITLES
    from explorer.cards.rv import ERROR_TITLES, VOTED_AXIS

    assert len(VOTED_AXIS.format(k=12345, p=12345)) <= 32  # the axis's 235 px
    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=12, n_points=160, rng=0)
    bare = laav.Sequence(seq.points, name="bare")
    ex = Explorer(bare, 2, params=laav.LaavParams(rv_max_points=100), viser=False)
    try:
        assert ex.wait(120)
        assert ex.result.voting.voted.size == 100
        fig = ex.rv_view.fig_error
        assert fig.title.text == ERROR_TITLES[False]  # as short as with every point voting
        assert fig.yaxis.axis_label == "% of the 100 voted (of 160)"
        assert ex.numbers_view.card.title == CARD_TITLES[False]
        assert "ground truth" not in CARD_TITLES[False].split(":")[1].replace("no ground truth", "")
    finally:
        ex.close()
