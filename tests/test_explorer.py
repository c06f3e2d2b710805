"""The explorer without a browser: build the app, set widget values, check the views' data.

The app object is built outside a server, so results are applied directly by the worker
thread; ``Explorer.wait()`` blocks until the newest request's result is on the views.
"""

from __future__ import annotations

import dataclasses
import io
import json
import re
import threading
import time
from pathlib import Path

import numpy as np
import pytest

import laav

pn = pytest.importorskip("panel")

from conftest import fake_serving  # noqa: E402

from explorer import Explorer, ExplorerState  # noqa: E402
from explorer import views as V  # noqa: E402
from explorer.cards.status import NO_CHANGE  # noqa: E402
from explorer.cli import build_parser, main  # noqa: E402
from explorer.demo import demo_path, demo_sequence  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def _shown(pane) -> str:
    """A Markdown pane's text as the page shows it (backslash escapes resolved)."""
    return re.sub(r"\\(.)", r"\1", pane.object)


def _two_motion_sequence(n_frames: int = 12, n_points: int = 120, seed: int = 0) -> laav.Sequence:
    """Two planar patches under different smooth affine motions (no laav.synthetic needed)."""
    rng = np.random.default_rng(seed)
    half = n_points // 2
    a = rng.uniform([40, 60], [260, 400], (half, 2))
    b = rng.uniform([360, 60], [600, 400], (n_points - half, 2))
    t = np.linspace(0, 1, n_frames)[:, None, None]
    pa = a[None] + t * np.array([60.0, 20.0]) + 0.05 * t * (a[None] - 150)
    cb = b.mean(0)
    ang = 0.35 * t[..., 0]
    c, s = np.cos(ang), np.sin(ang)
    rel = b[None] - cb
    pb = np.stack([c * rel[..., 0] - s * rel[..., 1], s * rel[..., 0] + c * rel[..., 1]], -1) + cb
    pb = pb + t * np.array([-30.0, 40.0])
    pts = np.concatenate([pa, pb], axis=1) + rng.normal(0, 0.3, (n_frames, n_points, 2))
    labels = np.r_[np.zeros(half, int), np.ones(n_points - half, int)]
    return laav.Sequence(pts, labels, name="two_patches", image_size=(640, 480))


@pytest.fixture(scope="module")
def seq() -> laav.Sequence:
    return _two_motion_sequence()


@pytest.fixture
def ex(seq):
    e = Explorer(seq, viser=False)
    assert e.wait(120), "first result did not arrive"
    yield e
    e.close()


def _data(src, key):
    return np.asarray(src.data[key], dtype=float).copy()


# ---------------------------------------------------------------------------- pure views
def test_views_are_pure_functions_of_the_result(seq):
    res = laav.Pipeline(seq, 2).result
    for mode in V.COLOR_MODES.values():
        st = V.point_style(seq, res, mode)
        assert st["color"].shape == (seq.n_points,)
        assert all(c.startswith("#") and len(c) == 7 for c in st["color"].tolist())
    fs = V.frame_sources(seq, res, 5, V.point_style(seq, res, "gt"), trail=5)
    assert len(fs["points"]["x"]) == seq.n_points
    assert len(fs["trails"]["x0"]) == 5 * seq.n_points
    assert len(fs["atoms"]["x"]) == res.atoms.n_atoms
    np.testing.assert_allclose(fs["points"]["x"], seq.points[5, fs["points"]["index"], 0])
    assert sorted(fs["points"]["index"].tolist()) == list(range(seq.n_points))
    # GAEC replay: step 0 = every atom alone; past the end = the final fine models
    N = res.graph.n_nodes
    assert len(np.unique(V.replay_labels(res, 0))) == N
    K = len(res.multicut.contractions)
    assert len(np.unique(V.replay_labels(res, K))) == N - K
    np.testing.assert_array_equal(V.replay_labels(res, K + 1), res.multicut.atom_labels)
    g = V.graph_sources(res, 3, K + 1)
    assert len(g["joined"]["x0"]) + len(g["cut"]["x0"]) == res.graph.n_edges
    assert len(g["cut"]["x0"]) == int(np.asarray(res.multicut.cut).sum())
    z, factors = V.z_sources(res, seq)
    n = res.multicut.n_models
    assert len(factors) == n and len(z["z"]) == n * n
    # no self-pair; a pair is drawn with a fundamental matrix the merge itself used
    assert not V.epipolar_sources(seq, res, 0, 0)["ok"]
    e = V.epipolar_sources(seq, res, 0, 1)
    assert e["ok"] and list(e["frames"]) in res.coarse.frame_pairs.tolist()
    assert e["sample_vote"] == pytest.approx(np.exp(-res.run_params.lam * e["sample_distance"]))
    assert e["pairwise"] == pytest.approx(res.coarse.pairwise_vote[0, 1])
    assert len(e["sample_left"]["x"]) == np.unique(res.coarse.vote_samples.points[0, 1]).size
    # each model drawn with the marker card 1 draws it with (its motion's, numbered as there)
    fine = np.asarray(res.coarse.fine_point_labels)
    card1 = V.point_style(seq, res, "fine")["marker"]
    want = {f"fine model f{m + 1}": card1[np.flatnonzero(fine == m)[0]] for m in (0, 1)}
    assert len(e["left"]["marker"]) == int(np.isin(fine, [0, 1]).sum())
    assert [want[m] for m in e["left"]["model"]] == list(e["left"]["marker"])
    num = V.stage_numbers(seq, res)
    assert 0 <= num["error_final"] <= 1 and num["n_atoms"] == res.atoms.n_atoms
    assert "Random Voting" in V.numbers_markdown(num)


def test_fine_legend_groups_by_motion_when_it_would_overflow(seq):
    """With more fine models than the legend has rows for beside the plot, the "fine"
    colouring's legend has a row per motion (it ran past the plot over the caption at 16-18
    fine models); each point's hover text keeps its own model."""
    res = laav.Pipeline(seq, 2, laav.LaavParams(fine_models=10)).result
    lab = np.asarray(res.coarse.fine_point_labels)
    n = np.unique(lab[lab >= 0]).size
    assert n >= 6
    each = V.point_style(seq, res, "fine", fine_rows=n)  # they fit: a row per fine model
    mot = V.fine_motions(seq, res)  # (the motion each model joined, as the views number it)
    assert {t for t in each["label"] if t != "no fine model"} == {
        f"fine model {f + 1} → motion {mot[f] + 1}" for f in np.unique(lab[lab >= 0])}
    assert set(each["detail"]) == {""}  # (the hover shows the label)
    grouped = V.point_style(seq, res, "fine", fine_rows=n - 1)
    rows = sorted({t for t in grouped["label"] if t != "no fine model"})
    assert len(rows) == 2 and all(re.fullmatch(r"motion \d: \d+ fine models?", t) for t in rows)
    assert sum(int(t.split(": ")[1].split()[0]) for t in rows) == n
    assert list(grouped["detail"]) == list(each["label"])  # the hover's text
    np.testing.assert_array_equal(grouped["color"], each["color"])
    t = V.points_template(grouped)  # (in legend order: "index" is each row's point)
    assert list(t["detail"]) == list(each["label"][t["index"]])
    shared = V.point_style(seq, res, "fine", fine_rows=n - 1, fine_counts=False)  # A/B legend
    assert {t for t in shared["label"] if t != "no fine model"} == {"motion 1: its fine models",
                                                                     "motion 2: its fine models"}
    # rows beside a 640 x 480 sequence's frame view (310 px): 18, six of them not fine models'
    assert V.fine_legend_rows(310) == 12 and V.fine_legend_rows(310, views=2) == 6


def test_epipolar_panel_markers_are_card_1s():
    """Card 3's panels draw each fine model with the marker card 1 gives it: its motion's as
    the views number motions (matched to the ground truth), not the coarse stage's own
    numbering (on this scene they differ: f1 was a square in card 1 and a circle in card 3)."""
    from laav.synthetic import make_sequence

    seq = make_sequence(1, rng=0)
    res = laav.Pipeline(seq, 2).result
    assert not np.array_equal(V.fine_motions(seq, res), np.asarray(res.coarse.fine_to_coarse))
    fine = np.asarray(res.coarse.fine_point_labels)
    card1 = V.point_style(seq, res, "fine")["marker"]
    n = V.n_fine_models(res)
    for j, k in ((0, 1), (0, n - 1)):
        e = V.epipolar_sources(seq, res, j, k)
        want = {f"fine model f{m + 1}": card1[np.flatnonzero(fine == m)[0]] for m in (j, k)}
        assert [want[m] for m in e["left"]["model"]] == list(e["left"]["marker"])


def test_epipolar_check_never_offers_a_model_against_itself(ex):
    """Card 3's pair: k is offered every fine model but j; picking j = k's model moves k."""
    panel = ex.coarse_view.epipolar
    n = int(np.asarray(ex.result.coarse.fine_to_coarse).size)
    assert n >= 3 and list(panel.w_pair_j.options) == [f"f{m + 1}" for m in range(n)]
    assert (panel.w_pair_j.value, panel.w_pair_k.value) == ("f1", "f2")
    assert "f1" not in panel.w_pair_k.options and len(panel.w_pair_k.options) == n - 1
    panel.w_pair_j.value = "f2"  # k's model: k moves to another
    j, k = panel.pair()
    assert j == 1 and k != j and "f2" not in panel.w_pair_k.options and "f1" in panel.w_pair_k.options
    panel.w_pair_k.value = "f3"
    assert panel.pair() == (1, 2)
    assert "Pick two different" not in panel.caption.object


def test_disagreement_with_plain_rv_warns_only_without_ground_truth(seq):
    res = laav.Pipeline(seq, int(seq.labels.max()) + 1).result
    lab = np.asarray(res.labels)
    C = int(lab.max()) + 1
    wrong = lab.copy()
    wrong[: seq.n_points // 4] = (lab[: seq.n_points // 4] + 1) % C  # a quarter moved
    plain = laav.random_voting(seq, C, seed=0)
    far = dataclasses.replace(plain, labels=wrong)
    unlabelled = dataclasses.replace(seq, labels=None)
    d = laav.misclassification_rate(lab, wrong)
    assert d > V.DISAGREEMENT_WARN
    from explorer.cards.status import StatusBar

    bar = StatusBar(seq)
    for s_, warned in ((seq, False), (unlabelled, True)):
        num = V.stage_numbers(s_, res, far)
        assert num["plain_disagreement"] == pytest.approx(d)
        line = V.disagreement_line(num)
        assert line.startswith(f"They label {round(d * seq.n_points)} of the {seq.n_points} points")
        assert f"both with C = {C}" in line
        assert ("warning sign" in line) is warned
        assert ("LAAV against plain RV" in V.numbers_markdown(num))
        # ... and the status line's warning, above the cards
        bar.show_check(num)
        assert bar.check_alert.visible is warned
        assert (f"disagree on {100 * d:.1f} % of the points" in bar.check_alert.object) is warned
    # the colouring of the differences marks exactly the points the share counts
    for s_ in (seq, unlabelled):
        st = V.point_style(s_, res, "vs_plain", far)
        black = st["color"] == V.DIFFERS_MARK
        assert black.sum() == round(d * seq.n_points) and st["mode"] == "vs_plain" and not st["note"]
        assert set(st["label"][black]) == {"differs from plain RV"}
        assert not (st["color"] == V.ERROR_MARK).any()  # black is the misclassified rings' colour
    assert V.point_style(unlabelled, res, "vs_plain")["mode"] == "final"  # plain RV not there yet
    # a point both leave unlabelled (-1: seen too briefly) is no difference; one that only
    # one of them leaves is
    a = np.array([0, 0, 1, 1, -1, -1, 0, 1])
    assert V.labelling_distance(a, a) == 0 and not V.plain_differs(a, a).any()
    b = a.copy()
    b[0] = -1
    assert V.labelling_distance(a, b) == pytest.approx(1 / 8) and V.plain_differs(a, b).tolist() == [
        True] + [False] * 7
    assert V.labelling_distance(a, 1 - a * (a >= 0) - 2 * (a < 0)) == 0  # renamed motions
    # the same labels: no difference, no warning; before plain RV: no line
    same = V.stage_numbers(unlabelled, res, dataclasses.replace(plain, labels=lab.copy()))
    assert same["plain_disagreement"] == 0 and "warning" not in V.disagreement_line(same)
    bar.show_check(same)
    assert not bar.check_alert.visible and bar.check_alert.object == ""
    assert V.disagreement_line(V.stage_numbers(unlabelled, res)) is None
    assert "error (needs a ground truth)" in V.numbers_markdown(same)
    assert "error vs ground truth" in V.numbers_markdown(V.stage_numbers(seq, res))


def test_align_labels_renames_to_the_reference():
    ref = np.array([0, 0, 1, 1, 2, 2])
    pred = np.array([2, 2, 0, 0, 1, -1])
    np.testing.assert_array_equal(V.align_labels(pred, ref), [0, 0, 1, 1, 2, -1])
    # a reference with fewer labels (a coarse stage that put every covered point in one
    # motion, C = 2): the unmatched motion takes the smallest free number, 1, not 2 ("motion 3")
    np.testing.assert_array_equal(V.align_labels([1, 1, 0, 0], [0, 0, 0, -1]), [0, 0, 1, 1])
    # ... and a number the reference left unused in between: 1, not 3
    np.testing.assert_array_equal(V.align_labels([0, 1, 2, 2], [0, 2, 2, 2]), [0, 1, 2, 2])


# ---------------------------------------------------------------------------- live updates
def test_lambda_change_alters_z_and_not_the_atoms():
    # a demo sequence: on very easy data the fine models' co-association Z is 0/1 whatever λ is
    p = REPO / "explorer" / "assets" / "demo_two_objects.mat"
    if not p.is_file():
        pytest.skip("explorer/assets/demo_two_objects.mat is missing")
    # λ enters Z with the epipolar merge (the paper's, and the default on incomplete tracks;
    # the coding merge does not use it, the joint merge only in its epipolar cost: see
    # test_lambda_does_not_move_the_coding_merge, test_lambda_weighs_the_joint_merges_epipolar_cost)
    ex = Explorer.from_file(p, viser=False, params=laav.LaavParams(coarse_merge="epipolar"))
    try:
        assert ex.wait(120)
        z0 = _data(ex.src_z, "z")
        atoms0 = _data(ex.src_atoms, "x")
        atoms_obj, coarse_obj = ex.result.atoms, ex.result.coarse
        ex.w_params["lam"].value = 0.3
        assert ex.wait(120)
        assert ex.result.params.lam == 0.3
        assert ex.result.atoms is atoms_obj  # atoms reused, not recomputed
        assert ex.result.coarse is not coarse_obj
        np.testing.assert_array_equal(_data(ex.src_atoms, "x"), atoms0)
        np.testing.assert_allclose(_data(ex.src_z, "z"), np.ravel(ex.result.coarse.affinity))
        assert not np.allclose(_data(ex.src_z, "z"), z0), "Z heat map did not change with lambda"
        assert "λ = 0.3" in ex.fig_z.title.text
    finally:
        ex.close()


def test_lambda_weighs_the_joint_merges_epipolar_cost():
    """With the joint merge (``LaavParams.own_chain()``) on complete tracks λ sets the unit
    of the epipolar cost of the shortlisted partitions (``2 / λ``); their coding lengths
    stay, and card 3's map (the merge's decision margins) follows the new costs."""
    ex = Explorer.demo(viser=False, params=laav.LaavParams.own_chain())
    assert ex.wait(120)
    co0 = ex.result.coarse
    m0 = _data(ex.src_z, "m")
    ex.w_params["lam"].value = 0.3
    assert ex.wait(120)
    co = ex.result.coarse
    assert co0.method == co.method == "joint" and co is not co0
    np.testing.assert_array_equal(co.shortlist.coding_length, co0.shortlist.coding_length)
    assert not np.allclose(co.shortlist.epipolar_cost, co0.shortlist.epipolar_cost)
    m = _data(ex.src_z, "m")
    np.testing.assert_allclose(m, V.joint_margins(ex.result)[0].ravel())
    assert not np.allclose(m, m0, equal_nan=True), "the margins did not follow λ"
    assert "Joint merge" in ex.fig_z.title.text and "λ = 0.3" in ex.fig_z.title.text
    ex.close()


@pytest.mark.hopkins
def test_the_joint_merges_close_calls_are_outlined(hopkins_root):
    """Card 3 outlines the pairs the joint merge decided by less than CLOSE_CALL_NATS (on the
    margins' log scale they read as nearly white, like undecided pairs): exactly those cells.
    cars2B at seed 5 fails (38.5 %) on such a call; none with the paper's epipolar merge (its
    map is Z, no margins)."""
    f = hopkins_root / "cars2B" / "cars2B_truth.mat"
    if not f.is_file():
        pytest.skip("cars2B is not in the Hopkins155 folder")
    seq = laav.load_sequence(f)
    for params, outlined in ((laav.LaavParams(), True), (laav.LaavParams.paper(), False)):
        ex = Explorer(seq, params=params, seed=5, viser=False)
        try:
            assert ex.wait(120)
            close = ex.coarse_view.src_close.data
            if not outlined:
                assert len(close["x"]) == 0
                continue
            m = V.joint_margins(ex.result)[0]
            n = m.shape[0]
            want = {(j, k) for j in range(n) for k in range(n)
                    if j != k and np.isfinite(m[j, k]) and abs(m[j, k]) < V.CLOSE_CALL_NATS}
            fac = list(ex.fig_z.x_range.factors)
            got = {(fac.index(y), fac.index(x)) for x, y in zip(close["x"], close["y"])}
            assert want and got == want
            assert "outlined in black: decided by less than 10 nats" in ex.coarse_view.merge_md.object
        finally:
            ex.close()


def test_lambda_does_not_move_the_coding_merge():
    """With the coding-length merge λ is not used: stage 4 reruns, its decision and the Z
    drawn (the coding affinity) stay."""
    ex = Explorer.demo(viser=False, params=laav.LaavParams(coarse_merge="coding", fine_per_motion=3))
    assert ex.wait(120)
    co0 = ex.result.coarse
    z0 = _data(ex.src_z, "z")
    ex.w_params["lam"].value = 0.3
    assert ex.wait(120)
    co = ex.result.coarse
    assert co is not co0 and co.method == "coding"
    np.testing.assert_array_equal(co.fine_to_coarse, co0.fine_to_coarse)
    np.testing.assert_allclose(_data(ex.src_z, "z"), z0)
    assert "ε = 10 px" in ex.fig_z.title.text
    ex.close()


def test_radius_change_alters_the_atoms(ex):
    seeds0 = np.asarray(ex.result.atoms.seeds).copy()
    r1_0 = _data(ex.src_atoms, "r1")
    ex.w_params["r1"].value = 12.0
    assert ex.wait(60)
    assert ex.result.atoms.r1 == 12.0
    r1 = _data(ex.src_atoms, "r1")
    assert np.all(r1 == 12.0) and not np.array_equal(r1, r1_0)
    assert len(r1) == ex.result.atoms.n_atoms
    assert (len(seeds0) != ex.result.atoms.n_atoms
            or not np.array_equal(seeds0, ex.result.atoms.seeds)
            or ex.result.atoms.r1 != 20.0)


def test_frame_change_moves_points_without_recomputing(ex, seq):
    res = ex.result
    gen = ex.state.generation
    x0 = _data(ex.src_points, "x")
    nodes0 = _data(ex.src_nodes, "x")
    ex.w_frame.value = seq.n_frames - 1
    x1 = _data(ex.src_points, "x")
    assert not np.allclose(x0, x1)
    np.testing.assert_allclose(x1, seq.points[-1, np.asarray(ex.src_points.data["index"]), 0])
    assert not np.allclose(nodes0, _data(ex.src_nodes, "x"))  # graph nodes follow the frame
    assert ex.result is res and ex.state.generation == gen  # no recomputation


def test_the_compare_views_share_one_legend(ex):
    """The A/B compare views have a legend, as every frame view: one, beside B, for both
    (titled so), listing the motions of either side with their points' colours and markers
    and the rings of the points whose final motion differs, counted in the frame shown; a
    click on an entry hides it in both views."""
    from explorer.cards.compare import LEGEND_TITLE, ring_label

    cv = ex.compare
    assert not cv.fig_a.legend and len(cv.fig_b.legend) == 1
    legend = cv.fig_b.legend[0]
    assert legend.title == LEGEND_TITLE and legend.click_policy == "hide"
    assert cv.pin()
    ex.w_seed.value = 3
    assert ex.wait(120) and ex.result is not cv.pinned.result
    assert cv.inner.visible
    motions, ring = legend.items
    assert motions.label.field == "label"
    rows = cv.src_legend.data
    labels = set(cv._styles[0]["label"]) | set(cv._styles[1]["label"])
    assert list(rows["label"]) == sorted(labels)
    for k in ("A", "B"):  # each motion's sample as its points are drawn, on either side
        pts = cv.src[k].data
        for lab, color, marker in zip(pts["label"], pts["color"], pts["marker"]):
            i = list(rows["label"]).index(lab)
            assert (rows["color"][i], rows["marker"][i]) == (color, marker), (k, lab)
    n = len(cv.src_changed["B"].data["x"])
    assert n == cv.comparison.changed.size  # (complete tracks: every ring in every frame)
    assert ring.label.value == ring_label(n)
    # a click hides both views' points (or rings): the legend's callback pairs each entry's
    # renderer with both views' own
    (cb,) = legend.js_event_callbacks["legend_item_click"]
    pairs = cb.args["pairs"]
    assert [p for p, _ in pairs] == [motions.renderers[0], ring.renderers[0]]
    assert [{r.data_source for r in rs} for _, rs in pairs] == [{cv.src["A"], cv.src["B"]},
                                                               {cv.src_changed["A"], cv.src_changed["B"]}]


def test_colour_by_and_gaec_step(ex):
    ex.w_color.value = "atoms"
    c_atoms = list(ex.src_points.data["color"])
    ex.w_color.value = "errors: final"
    assert set(ex.src_points.data["label"]) <= {"correct (final)", "misclassified (final)"}
    assert list(ex.src_points.data["color"]) != c_atoms
    from explorer.cards.graph import STEP_ENTRIES

    items = ex.graph_view._step_items
    assert sorted(it.label.value for it in items) == sorted(STEP_ENTRIES)
    assert not any(it.visible for it in items)  # the final step: nothing to mark
    ex.w_step.value = 0
    assert len(ex.src_cut.data["x0"]) == ex.result.graph.n_edges  # nothing contracted yet
    assert "step 0" in ex.graph_caption.object
    assert not any(it.visible for it in items)  # before any contraction: nothing to mark
    ex.w_step.value = 1
    assert len(ex.src_pair.data["x"]) == 2
    assert all(it.visible for it in items)  # a replay step: its entries shown
    ex.w_step.value = ex.w_step.end
    assert "Final fine models" in ex.graph_caption.object
    assert not any(it.visible for it in items)


def test_invalid_slider_combination_shows_a_message_and_keeps_the_result(ex):
    res = ex.result
    z = _data(ex.src_z, "z")
    # 2C < C (R1 >= R2 cannot be set with the sliders: R2 moves along, see below)
    ex.w_params["fine_models"].value = 1
    assert ex.wait(30)
    assert ex.alert.visible and "fine_models" in _shown(ex.alert)
    assert ex.result is res
    np.testing.assert_array_equal(_data(ex.src_z, "z"), z)
    ex.w_params["fine_models"].value = 4
    assert ex.wait(60)
    assert not ex.alert.visible


def _upload(ex, name: str, data: bytes) -> None:
    """What the page's upload box sends: the file in chunks (see test_explorer_upload)."""
    from test_explorer_upload import send_chunks

    send_chunks(ex, name, data)


def test_empty_upload_says_so_and_a_bad_c_is_refused(ex, seq):
    res = ex.result
    _upload(ex, "nothing.npz", b"")
    assert ex.wait(60) and ex.result is res
    assert ex.alert.visible and "nothing.npz is empty (0 bytes)" in _shown(ex.alert)
    # C: at least 1, at most the number of points; the box has no bounds (the page's box
    # would neither clamp nor send a value past them): the state refuses it, with a message
    assert (ex.w_motions.start, ex.w_motions.end) == (None, None)
    fm = ex.w_params["fine_models"]
    fine, fine_end, C = fm.value, fm.end, ex.w_motions.value
    for bad, msg in ((0, "must be a positive integer"), (-2, "must be a positive integer"),
                     (2.5, "must be a positive integer, got 2.5"),
                     (seq.n_points + 1, f"more than the {seq.n_points} points"), (10**8, "more than")):
        ex.w_motions.value = bad
        assert ex.wait(60) and ex.result is res
        assert ex.alert.visible and msg in _shown(ex.alert)
        assert (fm.value, fm.end) == (fine, fine_end)  # a refused C does not move the fine models
        assert ex.w_motions.value == C  # the box shows the C in use again, the message stays
    # another control after a refused C is not refused with it (the box held the 0, and every
    # later request carried it)
    ex.w_motions.value = 0
    assert ex.wait(60) and ex.result is res and "got 0" in _shown(ex.alert)
    ex.w_params["lam"].value = 3.0
    assert ex.wait(60) and ex.result.params.lam == 3.0 and ex.result.n_motions == C
    res = ex.result
    # a valid C after a refused one: the fine models follow it from the C shown (the
    # refused value was taken as the old C, and the fine models became a fixed number)
    k = fine // int(C)
    ex.w_motions.value = 0
    assert ex.wait(60) and ex.result is res
    ex.w_motions.value = C + 1
    assert ex.wait(60) and ex.result.n_motions == C + 1
    assert fm.value == k * (C + 1) and ex.result.params.fine_models is None
    ex.w_motions.value = C  # back: the fine models still follow C (auto), as before
    assert ex.wait(60) and ex.result.params.fine_models is None
    assert fm.value == fine


def test_c_typed_while_another_sequence_is_read_lets_the_fine_models_follow(tmp_path):
    """A C that arrives while another sequence is being read (its settings already the
    state's target, the slider still the shown one's): the new sequence keeps its own C (a
    C typed meanwhile is not asked for) and the fine models stay automatic, following that
    C (a review found them fixed at the number the slider showed)."""
    first = _two_motion_sequence(n_points=100, seed=4)
    e = Explorer(first, n_motions=3, viser=False)
    try:
        assert e.wait(120)
        fm = e.w_params["fine_models"]
        assert e.result.params.fine_models is None and fm.value == 4 * 3
        assert fm.end >= 6 * 3  # the default inside the slider's range, not at its end
        other = _two_motion_sequence(n_points=100, seed=5)
        path = laav.save_sequence(other, tmp_path / "o.npz")
        assert e.load_bytes(path.read_bytes(), "o.npz")
        e.w_motions.value = 4
        assert e.wait(120)
        assert e.sequence is not first and e.result.n_motions == other.n_motions == 2
        assert e.result.params.fine_models is None and fm.value == 4 * 2
        # the address names a sequence opened in the page (a new page would start with
        # the first one, and says so)
        assert e.query()["sequence"] == e.sequence.name
    finally:
        e.close()


def test_bad_upload_shows_a_message_and_keeps_the_result(ex):
    res = ex.result
    _upload(ex, "broken_truth.mat", b"this is not a MATLAB file")
    assert ex.wait(30)
    assert ex.alert.visible and "broken_truth.mat" in _shown(ex.alert)
    assert ex.result is res
    assert not ex.load_bytes(b"x", "notes.txt")
    assert ".npz" in _shown(ex.alert)
    # a well-formed file with a bad array
    buf = io.BytesIO()
    np.savez(buf, points=np.zeros((3, 4, 2)))
    assert not ex.load_bytes(buf.getvalue(), "tiny.npz")
    assert "tiny.npz" in _shown(ex.alert) and ex.result is res


def test_good_upload_replaces_the_sequence(ex, seq):
    other = _two_motion_sequence(n_frames=9, n_points=100, seed=3)
    buf = io.BytesIO()
    np.savez(buf, points=other.points)  # no labels: C is estimated, as by laav-explore FILE
    C = laav.estimate_motions(laav.Sequence(other.points, None)).n_motions
    ex.w_motions.value = C + 1  # not the box's C
    assert ex.wait(60) and ex.result.n_motions == C + 1
    assert ex.load_bytes(buf.getvalue(), "unlabelled.npz")
    assert ex.wait(60)
    assert ex.sequence.name == "unlabelled" and ex.sequence.n_points == 100
    assert len(ex.src_points.data["x"]) == 100
    assert ex.w_frame.end == 8
    assert ex.result.n_motions == C and ex.w_motions.value == C
    assert ex.note.visible and "no ground truth" in ex.note.object
    assert V.md_text(f"C = {C} was estimated: ") in ex.note.object
    assert "All settings at their defaults" in ex.status.object
    # another C than the estimate is a setting off its default (the status line said "All
    # settings at their defaults" beside "What changed: C 3 → 2")
    ex.w_motions.value = C + 1
    assert ex.wait(60) and ex.result.n_motions == C + 1
    assert f"C = {C + 1}" in _shown(ex.status), ex.status.object
    ex.w_motions.value = C
    assert ex.wait(60) and "All settings at their defaults" in ex.status.object
    # the frame view's caption does not count errors it cannot score
    assert "no ground truth, so no point is marked misclassified" in ex.frame_view.caption.object
    # ... nor is its misclassified layer offered (it would mark nothing)
    from explorer.cards.frame import LAYERS, TRUTH_LAYER

    assert TRUTH_LAYER not in ex.w_layers.options and TRUTH_LAYER not in ex.w_layers.value
    assert len(ex.w_layers.options) == len(LAYERS) - 1 and not ex.frame_view.r_errors.visible
    assert ex.w_color.value == "final (after Random Voting)"
    # no colouring that needs the ground truth it does not have is offered
    assert "ground truth" not in ex.w_color.options and "atoms" in ex.w_color.options
    from explorer.cards.sweep import TITLES

    assert ex.sweep_view.card.title == TITLES[False]  # the seed sweep lists no error either
    assert not [o for o in ex.w_color.options if o.startswith("errors")]
    ex.controls.set_color_mode("errors")
    assert ex.w_color.value == "final (after Random Voting)"
    # ... nor asked for by a URL: said, and the final labels shown
    problems = ex.apply_query({"color": ["gt"]})
    assert len(problems) == 1 and "color=gt needs a ground truth" in problems[0]
    problems = ex.apply_query({"color": ["bogus"]})  # the modes it lists are those it can show
    assert len(problems) == 1 and "color must be one of atoms, fine," in problems[0]
    assert "gt" not in problems[0].split("got")[0] and "errors" not in problems[0]
    assert ex.w_color.value == "final (after Random Voting)"
    from explorer import export  # the PNG's frame panel too

    fig = export.views_figure(ex.sequence, ex.result, 0, "gt", plain=None)
    assert fig.axes[0].get_title().startswith("Frame 0, coloured by final")
    # plain RV far from the final labels: the amber warning above the cards
    assert ex.wait(60, plain_rv=True) and not ex.check_alert.visible  # (they agree here)
    plain = ex.state.plain_rv()
    lab = np.asarray(ex.result.labels)
    moved = lab.copy()
    moved[: lab.size // 4] = (lab[: lab.size // 4] + 1) % ex.result.n_motions
    ex._apply_plain_rv(dataclasses.replace(plain, labels=moved), ex.state.plain_rv_key())
    assert ex.check_alert.visible and "LAAV and plain RV disagree on" in ex.check_alert.object
    assert "warning sign" in ex.numbers.object
    # the RV card: converging is not being right, and where to look without a truth
    rv_text = ex.rv_view.rv_md.object
    assert "**The two end apart" in rv_text and "not that they are right" in rv_text
    assert "differences: final vs plain RV" in rv_text and "against the ground truth" not in rv_text
    # back to a sequence with ground truth: every colouring offered again, the truth shown
    buf = io.BytesIO()
    np.savez(buf, points=seq.points, labels=seq.labels)
    assert ex.load_bytes(buf.getvalue(), "labelled.npz") and ex.wait(60)
    assert ex.sequence.labels is not None
    assert list(ex.w_color.options) == list(V.COLOR_MODES) and ex.w_color.value == "ground truth"
    assert list(ex.w_layers.options) == LAYERS and TRUTH_LAYER in ex.w_layers.value  # ticked, as before
    assert ex.frame_view.r_errors.visible
    assert ex.sweep_view.card.title == TITLES[True]
    assert not ex.check_alert.visible  # errors can be scored: no warning


def test_reset_restores_defaults(ex):
    ex.w_params["lam"].value = 3.0
    ex.w_seed.value = 5
    assert ex.wait(60)
    ex.w_reset.clicks += 1
    assert ex.wait(60)
    d = laav.LaavParams()
    assert ex.result.params.lam == d.lam and ex.result.seed == 0


def test_exports(ex, seq):
    import csv as csvmod

    from explorer import export

    csv = ex.files.export_csv().getvalue().splitlines()
    assert csv[0].startswith("point,label,") and len(csv) == seq.n_points + 1
    rows = list(csvmod.DictReader(csv))
    # 0-based like `laav segment`: the point index and the final label as in result.labels
    assert [int(r["point"]) for r in rows] == list(range(seq.n_points))
    assert [int(r["label"]) for r in rows] == np.asarray(ex.result.labels).tolist()
    assert [int(r["ground_truth"]) for r in rows] == np.asarray(seq.labels).tolist()
    st = ex.result.stage_labels()
    assert [int(r["coarse_motion"]) for r in rows] == np.asarray(st["coarse"]).tolist()  # -1: in no atom
    assert [int(r["owner_atom"]) for r in rows] == np.asarray(ex.result.atoms.owner).tolist()
    # atoms: how many atoms hold each point, 0 exactly where the coarse stage left it out
    sets = [set(np.asarray(m).tolist()) for m in ex.result.atoms.members]
    held = [sum(i in m for m in sets) for i in range(seq.n_points)]
    assert [int(r["atoms"]) for r in rows] == held
    assert [int(r["atoms"]) == 0 for r in rows] == [int(r["coarse_motion"]) == -1 for r in rows]
    assert any(int(r["owner_atom"]) == -1 and int(r["atoms"]) > 0 for r in rows)  # ring points
    # page_motion: the page's "motion N" of the final label, matched to the ground truth
    shown = V.shown_labels(seq, ex.result)["final"]
    assert [int(r["page_motion"]) for r in rows] == (shown + 1).tolist()
    agree = np.mean([int(r["page_motion"]) == int(r["ground_truth"]) + 1 for r in rows])
    assert agree == pytest.approx(1 - laav.misclassification_rate(ex.result.labels, seq.labels))
    # the PNG carries the parameters, errors and legends
    fig = export.views_figure(seq, ex.result, 3, "final", plain=None)
    head = fig._suptitle.get_text()
    num = V.stage_numbers(seq, ex.result)
    for part in (seq.name, "C = 2", "seed 0", f"R1 = {ex.result.params.r1:g}", "λ = ",
                 f"final {100 * num['error_final']:.1f} %", f"coarse {100 * num['error_coarse']:.1f} %",
                 "not at the defaults: none"):
        assert part in head, (part, head)
    axes = [a for a in fig.axes if a.get_label() != "<colorbar>"]
    assert axes[0].get_legend() is not None and axes[1].get_legend() is not None  # frame, graph
    assert any(a.get_label() == "<colorbar>" for a in fig.axes)  # Z's colour bar
    assert "motion 1" in [t.get_text() for t in axes[0].get_legend().get_texts()]
    d = json.loads(ex.files.export_json().getvalue())
    assert laav.LaavParams(**d["params"]) == ex.result.params and d["n_motions"] == 2
    png = ex.files.export_png().getvalue()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_plain_rv_comparison_is_cached_and_drawn(ex):
    assert ex.wait(120, plain_rv=True)
    assert len(ex.src_rv_plain.data["iteration"]) > 0
    assert len(ex.src_rv_laav.data["iteration"]) == len(ex.result.voting.changed)
    v = ex.state.plain_rv()
    ex.w_params["lam"].value = 2.5  # RV settings unchanged: the cached run is reused
    assert ex.wait(60, plain_rv=True)
    assert ex.state.plain_rv() is v
    assert "Plain RV" in ex.rv_md.object


def test_the_rv_card_is_not_redrawn_for_the_same_runs(ex, monkeypatch):
    """A change that leaves the fine-tuning and plain RV's run as they were (λ on a merge
    that stays, another colouring) does not rebuild the RV card; another run does."""
    import explorer.cards.rv as R

    assert ex.wait(120, plain_rv=True)
    calls = []
    real = R.V.rv_sources
    monkeypatch.setattr(R.V, "rv_sources", lambda v: calls.append(v) or real(v))
    seq, v, plain = ex.sequence, ex.result.voting, ex.state.plain_rv()
    ex.rv_view.draw(seq, v, plain)
    assert calls == []
    ex.rv_view.draw(seq, v, plain, pending=True)  # the same runs, now a preview: drawn
    assert len(calls) == 2
    ex.rv_view.draw(seq, v, None)
    assert len(calls) == 4
    ex.rv_view.draw(seq, v, plain)
    assert len(calls) == 6


def test_rv_card_draws_each_trials_error_per_iteration(ex):
    """The RV card's first chart (the paper's Fig. 3 in one run): each drawn trial's error
    per iteration from its label trace, row 0 its start; the misclassification rate of
    every row against the ground truth, or without one the share off the trial's end."""
    from explorer.cards.rv import ERROR_TITLES
    from explorer.views import rv_error_sources, trace_errors

    assert ex.wait(120, plain_rv=True)
    seq, v, plain = ex.sequence, ex.result.voting, ex.state.plain_rv()
    rv = ex.rv_view
    laav_err = np.asarray(rv.src_err_laav.data["error"])
    assert laav_err.size == v.informed_changed.size + 1  # the start, then each iteration
    for trace, drawn in ((v.informed_label_trace, laav_err),
                         (plain.label_trace, np.asarray(rv.src_err_plain.data["error"]))):
        want = [100 * laav.misclassification_rate(seq.labels, row) for row in trace]
        np.testing.assert_allclose(drawn, want, atol=1e-9)
    assert rv.fig_error.title.text == ERROR_TITLES[True]
    # a random start is far off; LAAV's start (the coarse labels) is closer
    plain_err = np.asarray(rv.src_err_plain.data["error"])
    assert plain_err[0] > 20 and laav_err[0] < plain_err[0]
    # without ground truth: the share of points not yet at the trial's last labels
    blind = trace_errors(v.informed_label_trace, None)
    assert blind[-1] == 0 and np.all((blind >= 0) & (blind <= 1))
    np.testing.assert_allclose(blind[0], np.mean(v.informed_label_trace[0] != v.informed_label_trace[-1]))
    assert rv_error_sources(seq, None)["error"].size == 0
    assert "Error per iteration" in ex.rv_md.object


def test_the_error_per_iteration_covers_the_points_that_voted():
    """Above rv_max_points a seeded subset votes, on incomplete tracks the points a voting
    frame pair sees: the chart is the error over those (Voting.voted), not left empty."""
    from explorer.views import rv_error_sources
    from laav.bench import hide_entries

    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=15, n_points=200, rng=0)
    for case, params in ((seq, laav.LaavParams(rv_max_points=120)),
                         (hide_entries(seq, 0.7, 0), laav.LaavParams())):
        v = laav.segment(case, 2, params, seed=0).voting
        assert v.voted is not None and v.voted.size < case.n_points
        got = rv_error_sources(case, v)["error"]
        want = [100 * laav.misclassification_rate(case.labels[v.voted], row)
                for row in v.informed_label_trace]
        assert got.size == len(want) > 1
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_newest_request_supersedes_stale_ones(seq):
    st = ExplorerState(seq, autostart=False)
    seen = []
    st.on_result = lambda res, s, settings, gen: seen.append((gen, res.params.lam))
    st.start()
    assert st.wait(60)
    gens = [st.request(params={"lam": lam}) for lam in (1.0, 1.5, 2.5, 3.5, 4.5, 5.5)]
    assert st.wait(60)
    assert seen[-1] == (gens[-1], 5.5)
    assert st.result.params.lam == 5.5
    assert len(seen) < 1 + len(gens)  # some stale requests were skipped or dropped
    assert [g for g, _ in seen] == sorted(g for g, _ in seen)
    st.close()


def test_pipeline_errors_never_kill_the_session(seq, monkeypatch):
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(60)
        res = ex.result

        def boom(self, **kw):
            raise RuntimeError("simulated bug")

        monkeypatch.setattr(laav.Pipeline, "update", boom)
        ex.w_params["lam"].value = 9.0
        assert ex.wait(30)
        assert ex.alert.visible and "simulated bug" in _shown(ex.alert) and ex.result is res
        monkeypatch.undo()
        ex.w_params["lam"].value = 8.0
        assert ex.wait(60)
        assert ex.result.params.lam == 8.0 and not ex.alert.visible
    finally:
        ex.close()


def test_two_explorers_are_independent(seq):
    a, b = Explorer(seq, viser=False), Explorer(seq, viser=False)
    try:
        assert a.wait(60) and b.wait(60)
        zb = _data(b.src_z, "z")
        a.w_params["lam"].value = 6.0
        assert a.wait(60)
        assert b.result.params.lam == laav.LaavParams().lam
        np.testing.assert_array_equal(_data(b.src_z, "z"), zb)
    finally:
        a.close()
        b.close()


def test_viser_view_follows_the_frame(seq):
    pytest.importorskip("viser")
    ex = Explorer(seq)
    try:
        assert ex.wait(60)
        # the 3-D card starts folded: no server (it starts at the first unfold), no iframe
        assert ex.viser is None and ex.view3d.thread is None
        assert ex.v_viser.collapsed and "<iframe" not in ex.viser_pane.object
        ex.v_viser.collapsed = False  # unfolded: the server starts, then the iframe
        assert ex.wait(60) and ex.viser is not None and ex.viser.port > 0
        ex.v_viser.collapsed = True  # folded again: the scene is not updated meanwhile
        ex.w_frame.value = 5
        assert ex.viser._frame != 5
        ex.v_viser.collapsed = False  # unfolded: the iframe, and the scene catches up
        assert f":{ex.viser.port}/" in ex.viser_pane.object and "127.0.0.1" in ex.viser_pane.object
        assert ex.viser._frame == 5 and ex.viser._result is ex.result
        ex.w_frame.value = 7
        assert ex.viser._frame == 7
        assert abs(ex.viser._plane.position[2] - 7 * ex.viser._map.dz) < 1e-5
        # moving viser's own frame box moves the panel slider
        ex.viser._frame_box.value = 3
        deadline = time.monotonic() + 30  # it must happen; how fast is a benchmark's question
        while ex.w_frame.value != 3 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert ex.w_frame.value == 3
    finally:
        ex.close()


def test_3d_trails_are_the_tracked_samples_within_a_budget(monkeypatch):
    """The 3-D view's trails are the tracked samples as a point cloud (software WebGL redraws
    10,000 screen-space line segments at ~0.3 s of CPU, as many points at no cost measured);
    beyond TRAIL_SAMPLES, each track's every k-th sample, its first and its last: no track,
    however short, loses its trail, and no hidden sample is drawn."""
    pytest.importorskip("viser")
    import explorer.viser_view as VV

    vis = np.ones((25, 421), bool)
    np.testing.assert_array_equal(VV.trail_samples(vis), vis)  # 1R2RCT_A: every sample
    big = VV.trail_samples(np.ones((100, 1000), bool))
    assert big.sum() <= VV.TRAIL_SAMPLES and big[0].all() and big[-1].all()
    assert np.array_equal(np.flatnonzero(big[:, 0])[:-1], np.arange(0, 99, 9))  # k = 9
    # short tracks (as a tracked video gives): 2,000 tracks each seen in 30 of 300 frames
    short = np.zeros((300, 2000), bool)
    for p in range(2000):
        a = (p * 7) % 270
        short[a:a + 30, p] = True
    got = VV.trail_samples(short)
    assert got.sum() <= VV.TRAIL_SAMPLES and not (got & ~short).any()
    for p in range(0, 2000, 97):  # each track keeps its first and last sample
        seen = np.flatnonzero(short[:, p])
        assert got[seen[0], p] and got[seen[-1], p]
    # what the view sends: an incomplete sequence over a (small) budget
    from laav.synthetic import occlude

    seq = occlude(_two_motion_sequence(n_frames=20, n_points=200), 0.3, rng=2)
    res = laav.Pipeline(seq, 2).result
    monkeypatch.setattr(VV, "TRAIL_SAMPLES", 900)
    view = VV.ViserView()
    try:
        sent = {}
        real = view.server.scene.add_point_cloud

        def record(name, points, colors, **k):
            sent[name] = (np.asarray(points), np.asarray(colors))
            return real(name, points, colors, **k)

        view.server.scene.add_point_cloud = record
        view.set_result(seq, res, V.point_style(seq, res, "gt", None)["color"], 0)
        pts, cols = sent["/trajectories"]
        want = VV.trail_samples(seq.visible, 900)
        assert seq.visible.sum() > 900 and pts.shape == (want.sum(), 3) == cols.shape
        assert np.isfinite(pts).all()
        f, _ = np.nonzero(want)
        np.testing.assert_allclose(np.sort(pts[:, 2]), np.sort(f * view._map.dz), atol=1e-5)
    finally:
        view.close()


def test_viser_prints_nothing_to_the_users_output(capsys, monkeypatch):
    """viser prints its banner (with the server's address) and "Server stopped" through
    rich's global console, which in Jupyter displays them in the cell's output, ignoring any
    redirect of sys.stdout and any ``file``: the 3-D view keeps both off it, in a notebook
    as in a terminal, and puts the console back after (also when two views overlap)."""
    pytest.importorskip("viser")
    import builtins

    import rich
    import rich.jupyter
    from rich.console import Console

    from explorer.viser_view import ViserView

    class ZMQInteractiveShell:  # what rich takes for a Jupyter kernel
        pass

    shown = []
    monkeypatch.setattr(builtins, "get_ipython", lambda: ZMQInteractiveShell(), raising=False)
    monkeypatch.setattr(rich.jupyter, "display", lambda segments, text: shown.append(text))
    old = rich._console
    rich._console = mine = Console()  # a notebook's console (it detects the kernel)
    try:
        assert mine.is_jupyter
        first = ViserView()
        second = ViserView()  # (overlapping: the first's stop comes after the second's start)
        first.close()
        second.close()
        assert rich._console is mine
        assert shown == []  # nothing of viser's reached the cell
        rich.print("after")  # the user's own rich output still does
    finally:
        rich._console = old
    assert len(shown) == 1 and "after" in shown[0]
    assert "viser" not in capsys.readouterr().out


def test_viser_view_has_axes_and_atoms_that_leave_points_visible(seq):
    """The 3-D view names its axes (x and y in pixels with their ranges, the frames along
    the depth), draws the atoms' centres smaller than the frame's points (at 0.09 they hid
    the points round them), and its card says how to read it."""
    pytest.importorskip("viser")
    from explorer import viser_view as VV

    view = VV.ViserView()
    try:
        labels = {}
        real = view.server.scene.add_label

        def record(name, text, **k):
            labels[name] = text
            return real(name, text, **k)

        view.server.scene.add_label = record
        res = laav.Pipeline(seq, 2).result
        view.set_result(seq, res, V.point_style(seq, res, "gt", None)["color"], 0)
        x0, x1, y0, y1 = seq.extent()
        assert labels == {"/axes/x": f"x (px) {x0:.0f} → {x1:.0f}", "/axes/y": f"y (px) {y1:.0f} → {y0:.0f}",
                          "/axes/frame": f"frame 0 → {seq.n_frames - 1}"}
        assert VV.ATOM_SIZE < VV.POINT_SIZE
    finally:
        view.close()
    from explorer.cards.view3d import CAPTION

    assert "atoms' centres" in CAPTION and "the frames along the depth" in CAPTION


def test_viser_view_sends_only_what_changed(seq):
    """Each scene message makes the 3-D page draw anew (software WebGL: the other core), so a
    change that leaves a node's data as it was sends nothing for it: a λ change keeping the
    labels sends nothing at all; a frame move sends the frame's points, atoms and edges; a
    result without atoms takes the atoms away."""
    pytest.importorskip("viser")
    from explorer.viser_view import ViserView

    view = ViserView()
    try:
        sent: list[str] = []
        kinds: dict[str, str] = {}
        scene = view.server.scene
        for method in ("add_point_cloud", "add_line_segments", "remove_by_name"):
            real = getattr(scene, method)

            def record(name, *a, _real=real, _method=method, **k):
                sent.append(name)
                kinds[name] = _method
                return _real(name, *a, **k)

            setattr(scene, method, record)
        res = laav.Pipeline(seq, 2).result
        colors = V.point_style(seq, res, "gt", None)["color"]
        view.set_result(seq, res, colors, 0)
        # (a new sequence: its axes too, once)
        assert sorted(sent) == ["/atoms", "/axes", "/graph_edges", "/points", "/trajectories"]
        assert kinds["/trajectories"] == "add_point_cloud"  # the tracked samples, as points
        sent.clear()
        same = laav.Pipeline(seq, 2, laav.LaavParams(lam=res.params.lam * 1.01)).result
        assert np.array_equal(same.labels, res.labels)
        view.set_result(seq, same, colors, 0)  # (what a λ move gives the view)
        view.set_colors(colors)
        view.set_frame(0)
        assert sent == []
        view.set_frame(3)
        assert sorted(sent) == ["/atoms", "/graph_edges", "/points"]
        assert abs(view._plane.position[2] - 3 * view._map.dz) < 1e-5
        sent.clear()
        view.set_frame(3)
        assert sent == []
        recoloured = np.array(colors, dtype=object)
        recoloured[0] = "#000000"
        view.set_colors(recoloured)
        assert sorted(sent) == ["/points", "/trajectories"]
        sent.clear()
        lonely = dataclasses.replace(res, graph=dataclasses.replace(  # atoms, no edge
            res.graph, edges=np.zeros((0, 2), int), costs=np.zeros(0)))
        view.set_result(seq, lonely, recoloured, 3)
        assert sent == ["/graph_edges"]  # the last result's edges removed, the atoms as they were
        sent.clear()
        view.set_result(seq, res, recoloured, 3)
        assert sent == ["/graph_edges"]  # back
        sent.clear()
        none = dataclasses.replace(res, graph=dataclasses.replace(
            res.graph, positions=np.zeros((0, seq.n_frames, 2)), edges=np.zeros((0, 2), int),
            costs=np.zeros(0)))
        view.set_result(seq, none, recoloured, 3)
        assert sorted(sent) == ["/atoms", "/graph_edges"]  # removed
    finally:
        view.close()


def test_a_3d_view_that_cannot_start_says_so(seq, monkeypatch):
    """The first unfold starts the 3-D view's server; one that fails to start shows why (the
    card never stays on "is starting")."""
    pytest.importorskip("viser")
    import explorer.viser_view as VV

    def broken(*a, **k):
        raise OSError("no port for you")

    monkeypatch.setattr(VV, "ViserView", broken)
    ex = Explorer(seq)
    try:
        assert ex.wait(60) and ex.view3d.thread is None
        ex.v_viser.collapsed = False
        assert ex.wait(60)
        deadline = time.monotonic() + 30
        while "could not start" not in ex.viser_pane.object and time.monotonic() < deadline:
            time.sleep(0.05)
        assert "could not start" in ex.viser_pane.object and "no port for you" in ex.viser_pane.object
        assert ex.viser is None
    finally:
        ex.close()


def test_card_3_colour_bar_follows_the_map():
    """Card 3's colour bar keeps one ticker model (BokehJS reads a bar's ticker once) and
    switches its ticks and labels with the map: margins in nats under the joint merge, Z in
    [0, 1] under the epipolar one."""
    from explorer.cards.coarse import Z_TICKS
    from explorer.demo import demo_sequence

    seq = demo_sequence()
    joint = laav.segment(seq, 3, seed=1)
    paper = laav.segment(seq, 3, laav.LaavParams(coarse_merge="epipolar"), seed=1)
    assert joint.coarse.shortlist is not None
    ex = Explorer(seq, viser=False, start=False)
    try:
        cv = ex.coarse_view
        ticker = cv.z_bar.ticker
        for res in (joint, paper, joint):
            cv.draw(seq, res)
            assert cv.z_bar.ticker is ticker
            if res is joint:
                top = cv.z_mapper.high
                assert cv.z_mapper.low == -top and top >= V.signed_log(10)
                labels = cv.z_bar.major_label_overrides
                assert set(labels) == set(ticker.ticks) and "0" in labels.values()
                for where, text in labels.items():  # each tick labelled with its margin in nats
                    assert V.signed_log(float(text)) == pytest.approx(where)
                assert "Joint merge" in ex.fig_z.title.text
            else:
                assert (cv.z_mapper.low, cv.z_mapper.high) == (0, 1)
                assert list(ticker.ticks) == list(Z_TICKS) and cv.z_bar.major_label_overrides == {}
                assert "Affinity Z" in ex.fig_z.title.text
    finally:
        ex.close()


def test_explorer_from_file_and_demo(tmp_path, seq):
    p = laav.save_sequence(seq, tmp_path / "seq.npz")
    ex = Explorer.from_file(p, viser=False)
    try:
        assert ex.wait(60) and ex.sequence.n_points == seq.n_points
        assert ex.panel() is not None and ex.template() is not None
    finally:
        ex.close()
    demo = demo_sequence()
    assert demo.n_points >= 8
    # the bundled file, found through importlib.resources in the explorer package
    assert demo_path() is not None and demo_path().name == "demo_three_motions.mat"
    assert Path(str(demo_path())) == REPO / "explorer" / "assets" / "demo_three_motions.mat"
    assert demo.name == "demo_three_motions"


# ---------------------------------------------------------------------------- CLI
def test_cli_argument_errors_exit_2_with_a_message(tmp_path, capsys):
    assert main([str(tmp_path / "missing_truth.mat")]) == 2
    err = capsys.readouterr().err
    assert "laav-explore: error:" in err and "missing_truth.mat" in err and "Traceback" not in err

    unlabelled = tmp_path / "nolabels.npz"
    np.savez(unlabelled, points=_two_motion_sequence().points)

    assert main(["--motions", "0"]) == 2
    assert "--motions" in capsys.readouterr().err
    assert main(["--port", "70000"]) == 2
    assert main(["--bogus"]) == 2
    assert main([str(unlabelled), "--motions", "1000"]) == 2
    assert "--motions: C = 1000 motions is more than the 120 points" in capsys.readouterr().err
    assert main([str(unlabelled), "--motions", "16"]) == 2  # fewer than 8 points a motion
    assert "--motions: C = 16 motions need at least 8 points each" in capsys.readouterr().err
    # a seed laav refuses is a bad argument (the page waited forever on it)
    assert main(["--seed", "-1", "--no-browser"]) == 2
    assert "--seed must be a whole number between 0 and" in capsys.readouterr().err
    # a params file nested thousands deep: exit 2, not a RecursionError traceback
    deep = tmp_path / "nested.json"
    deep.write_text('{"a":' + "[" * 5000 + "]" * 5000 + "}")
    assert main(["--params", str(deep), "--no-browser"]) == 2
    err = capsys.readouterr().err
    assert "nested too deeply" in err and "Traceback" not in err


def test_cli_binds_localhost_by_default(monkeypatch, tmp_path):
    assert build_parser().parse_args([]).host == "127.0.0.1"
    seen = {}

    class FakeLoop:
        def add_callback(self, fn):
            seen["browser_callback"] = fn

        def start(self):
            seen["started"] = True

    class FakeServer:
        io_loop = FakeLoop()

        def start(self):
            pass

        def stop(self):
            seen["stopped"] = True

    def fake_serve(panels, **kw):
        seen.update(kw)
        return FakeServer()

    monkeypatch.setattr(pn, "serve", fake_serve)
    p = laav.save_sequence(_two_motion_sequence(), tmp_path / "s.npz")
    assert main([str(p), "--no-browser", "--port", "0"]) == 0
    assert seen["address"] == "127.0.0.1"
    assert all(o.split(":")[0] in ("127.0.0.1", "localhost") for o in seen["websocket_origin"])
    assert "browser_callback" not in seen and seen["started"] and seen["stopped"]


# ---------------------------------------------------------------------------- notebook
def test_notebook_runs_top_to_bottom():
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    pytest.importorskip("ipykernel")
    nb = nbformat.read(REPO / "examples" / "explorer_notebook.ipynb", as_version=4)
    # (run where Jupyter runs it: in its own folder; from the repository's root, a path
    # relative to the root passed here and failed for a user)
    client = nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                     resources={"metadata": {"path": str(REPO / "examples")}})
    client.execute()
    outs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outs if o.output_type == "error"]
    text = "".join(o.get("text", "") for o in outs if o.output_type == "stream" and o.name == "stdout")
    assert "atoms reused: True" in text and "alert after fixing it: False" in text
    assert "refused: True" in text  # the impossible combination the text promises
    # nothing a user would take for a fault: the upload box's extension is loaded, the
    # tracker's bar is text, the last cell shows no stray value
    err = "".join(o.get("text", "") for o in outs if o.output_type == "stream" and o.name == "stderr")
    assert "was not imported" not in err and "Warning" not in err, err[:500]
    assert "execute_result" not in [o.output_type for o in nb.cells[-1].get("outputs", [])]
    assert "card 3's map (joint merge) changed: True" in text  # λ is the epipolar cost's unit
    # the video cell: tracked, its tracks kept, its frames kept for the frame view
    assert "of the track x frame entries visible" in text
    assert "24 frames of 320x240 kept at 320x240 grey" in text
    html = [o for o in outs if o.output_type in ("display_data", "execute_result")
            and "application/vnd.holoviews_exec.v0+json" in o.get("data", {})]
    assert len(html) >= 2, "the explorers did not display"


def test_no_thread_leaks_after_close(seq):
    before = threading.active_count()
    ex = Explorer(seq, viser=False)
    assert ex.wait(60)
    ex.close()
    time.sleep(0.5)
    assert threading.active_count() <= before + 2


def test_close_joins_the_workers_even_mid_computation(seq, monkeypatch):
    """close() returns once its worker threads have ended: the one computing stops at its
    next check (here a new seed's result and plain RV were being computed)."""
    ex = Explorer(seq, viser=False)
    assert ex.wait(60)
    from laav._interrupt import check

    started = threading.Event()

    def long_plain_rv(*args, **kwargs):  # plain RV that only a stop request ends
        started.set()
        while True:
            check()
            time.sleep(0.01)

    monkeypatch.setattr(laav, "random_voting", long_plain_rv)
    ex.state.request(seed=7)
    ex.state.request_plain_rv()
    assert started.wait(30)
    threads = ex.state.threads()
    # the pipeline's worker and plain RV's (and the drawn votes', once the first result's
    # votes were fitted: ExplorerState.fit_votes)
    tag = ex.state._thread_tag + "-"
    kinds = sorted(t.name[len(tag):].rsplit("_", 1)[0] for t in threads)
    assert kinds in (["pipeline", "plain-rv"], ["pipeline", "plain-rv", "votes"]), kinds
    assert ex.close(timeout=5) is True
    assert not [t.name for t in threads if t.is_alive()]


def test_rv_summary_names_the_points_each_polishing_step_moved():
    from explorer.views import rv_summary
    from laav.synthetic import make_sequence

    seq = make_sequence(n_objects=2, n_frames=20, n_points=300, rng=3)
    rng = np.random.default_rng(2)
    bad = seq.labels.copy()
    flip = rng.choice(seq.n_points, 90, replace=False)
    bad[flip] = (bad[flip] + 1) % seq.n_motions
    p = laav.LaavParams(rv_max_iter=1, rv_select="none")
    v = laav.random_voting(seq, seq.n_motions, p, seed=0, init_labels=bad)
    assert v.reassigned > 0
    text = rv_summary(v, None)
    assert f"joint reassignment {v.reassigned}" in text
    if v.refined:
        assert f"refinement {v.refined}" in text
    off = laav.random_voting(seq, seq.n_motions, p.replace(rv_reassign=False, rv_refine=False),
                             seed=0, init_labels=bad)
    assert "points moved" not in rv_summary(off, None)
    # LAAV's own chain (the default) descends on the joint score: named as ours, with its count
    own = laav.random_voting(seq, seq.n_motions, laav.LaavParams(rv_max_iter=1, rv_refine=False,
                                                                 rv_reassign=False), seed=0, init_labels=bad)
    assert own.descended > 0
    assert f"the descent on the joint score (ours, `rv_descent`) {own.descended}" in rv_summary(own, None)


def test_rv_card_legend_names_the_subspace_votes_of_ours():
    """Card 4's curves differ in their votes too when LAAV's trial used our subspace term
    (the default): its legend says so; with the paper's votes (the paper preset) it does not."""
    from explorer import export
    from explorer.cards.rv import RVView
    from explorer.views import RV_OWN_NAMES as OWN_LEGEND

    seq = _two_motion_sequence()
    view = RVView()
    for params, ours in ((laav.LaavParams(), True), (laav.LaavParams.paper(), False)):
        res = laav.segment(seq, 2, params, seed=0)
        assert ((res.voting.informed_subspace_weight or 0) > 0) is ours
        view.draw(seq, res.voting, None)
        for fig in (view.fig_error, view.fig_changed, view.fig_margin):
            assert fig.legend.items[0].label.value == OWN_LEGEND[ours]
        # the PNG export names the runs as the card does
        png = export.views_figure(seq, res, 0, "final", plain=res.voting)
        ax = next(a for a in png.axes if a.get_title() == "Random Voting convergence")
        names = [t.get_text() for t in ax.get_legend().get_texts()]
        assert names == [OWN_LEGEND[ours], "plain RV (random start)"], names
    assert "subspace votes (ours)" in OWN_LEGEND[True]


def test_rv_card_says_the_candidates_were_scored_after_their_cleaning():
    """When LAAV's candidates differ, the selection scores each after a short descent
    (``rv_select_descent``, ours): the RV card says so, and not when it is off."""
    from test_own_chain import small_motion_uncovered

    from explorer.views import rv_summary

    seq, init, _ = small_motion_uncovered(0)
    every = laav.LaavParams(rv_missing_gate=0.0)  # every start's trials run: candidates to score
    on = laav.random_voting(seq, 2, every, seed=0, init_labels=init)
    off = laav.random_voting(seq, 2, every.replace(rv_select_descent=0.0), seed=0, init_labels=init)
    assert on.score == "joint-cleaned" and len(on.costs) == 1 + laav.LaavParams().rv_missing_trials
    assert "best moves of a few points (`rv_select_descent`)" in rv_summary(on, None)
    assert f"(score {on.costs[on.selected]:.2f} nats, after its cleaning" in rv_summary(on, None)
    assert "rv_select_descent" not in rv_summary(off, None) and "cleaning" not in rv_summary(off, None)


def test_md_text_renders_names_as_literal_text():
    """Names from files reach the page as text: no HTML, link, image, math or block markup."""
    from markdown_it import MarkdownIt

    md = MarkdownIt("commonmark")
    for raw in ["<img src=x onerror=alert(1)>", "<script>alert(1)</script>", "[x](http://evil.example)",
                "![i](http://evil.example/i.png)", "a_b *c* $x$ `d` &amp; \\", "line\n# heading\n    code"]:
        out = md.render(V.md_text(raw))
        assert out.count("<") == 2 and out.startswith("<p>") and out.endswith("</p>\n"), out
        assert "href" not in out and "<img" not in out and "<script" not in out
    assert md.render(V.md_text("<b>&amp;</b>")) == "<p>&lt;b&gt;&amp;amp;&lt;/b&gt;</p>\n"


def test_hostile_stored_name_is_escaped_in_the_views(tmp_path):
    seq = _two_motion_sequence()
    bad = laav.Sequence(seq.points, seq.labels, name="<img src=x onerror=alert(1)>[a](b)")
    ex = Explorer(bad, viser=False)
    try:
        assert ex.wait(60)
        for text in (ex.seq_info.object, ex.status.object):
            assert not re.search(r"(?<!\\)[<\[]", text)
            assert "\\<img src\\=x onerror\\=alert\\(1\\)\\>\\[a\\]\\(b\\)" in text
        assert ex.w_dl_csv.filename == "img_src_x_onerror_alert_1_a_b__labels.csv"
        ex.state.report(f"{bad.name}: broken")
        assert not re.search(r"(?<!\\)<", ex.alert.object) and "<img src=x" in _shown(ex.alert)
    finally:
        ex.close()


def test_slider_moved_during_an_upload_keeps_the_new_sequences_C():
    """A slider moved while another sequence loads never computes it with the old C."""
    ex = Explorer(demo_sequence(), viser=False)  # three motions
    try:
        assert ex.wait(60) and ex.result.n_motions == 3
        other = _two_motion_sequence(seed=5)
        buf = io.BytesIO()
        np.savez(buf, points=other.points, labels=other.labels)
        assert ex.load_bytes(buf.getvalue(), "two.npz")
        ex.w_params["lam"].value = 2.5  # before the new sequence's first result is shown
        assert ex.wait(60)
        assert ex.sequence.n_points == other.n_points
        assert ex.result.n_motions == 2 and ex.state.target.n_motions == 2
        assert ex.result.params.lam == 2.5
        assert ex.w_motions.value == 2 and not ex.w_motions.disabled
        # a failed upload unlocks the C box too
        assert not ex.load_bytes(b"garbage", "bad.npz")
        assert not ex.w_motions.disabled
    finally:
        ex.close()


def test_rv_summary_says_when_the_labels_are_not_laavs_own_trial():
    """The fine-tuning line must not call a plain RV trial LAAV's (issue 12, item 7)."""
    import dataclasses

    from explorer.views import rv_summary

    seq = laav.load_sequence(Path(__file__).resolve().parents[1] / "explorer" / "assets"
                             / "demo_two_objects.mat")
    v = laav.random_voting(seq, seq.n_motions, seed=0, init_labels=seq.labels)
    own = dataclasses.replace(v, selected="informed")
    assert "not LAAV's informed trial" not in rv_summary(own, None)
    other = dataclasses.replace(v, selected="plain trial", trial_iterations=(40, 25),
                                n_iterations=65, n_trials=2)
    text = rv_summary(other, None)
    assert "returned plain trial, not LAAV's informed trial" in text
    assert "65 voting iterations in all, LAAV's informed trial 40" in text
    plain = laav.random_voting(seq, seq.n_motions, seed=0)  # not initialised: no such note
    assert "not LAAV's" not in rv_summary(None, plain)
    # the coarse labels themselves (incomplete tracks, rv_coarse_candidate): named as such
    coarse = dataclasses.replace(v, selected="coarse", trial_iterations=(150, 150),
                                 n_iterations=300, n_trials=2)
    text = rv_summary(coarse, None)
    assert "returned LAAV's coarse labels, not its informed trial" in text
    assert "no voting" in text and "300 voting iterations in all, LAAV's informed trial 150" in text


def test_what_changed_is_shown_and_ringed():
    """After a recompute: one line says what moved, the points that changed motion are ringed
    (a layer toggle), the status names every setting off its default."""
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        # nothing to compare yet: an empty line, in its place (the cards below do not move
        # when it is filled)
        assert ex.change_md.object == NO_CHANGE and ex.change is None
        assert ex.change_md.styles.get("display") is None
        assert "All settings at their defaults" in ex.status.object
        before = ex.result
        ex.w_params["r1"].value = 21.0
        assert ex.wait(120)
        ch = ex.change
        assert ch is not None and ex.state.change_of(ex.result) is ch
        assert ex.change_md.styles.get("display") is None
        assert _shown(ex.change_md).startswith("**What changed:** R1 20 → 21: coarse ")
        assert f"{ch.moved.size} point" in _shown(ex.change_md)
        # the rings sit on exactly the points whose final motion changed
        prev = np.asarray(before.labels)
        expect = np.flatnonzero(V.align_labels(ex.result.labels, prev) != prev)
        assert ch.moved.tolist() == expect.tolist()
        f = int(ex.w_frame.value)
        ring = np.c_[ex.src_changed.data["x"], ex.src_changed.data["y"]]
        assert np.allclose(ring, ex.sequence.points[f, expect])
        assert "R1 = 21" in _shown(ex.status)
        # the layer toggle hides and shows the rings
        layer = [n for n in ex.w_layers.options if n.startswith("changed motion")][0]
        ex.w_layers.value = [n for n in ex.w_layers.value if n != layer]
        assert not ex.r_changed.visible
        ex.w_layers.value = [*ex.w_layers.value, layer]
        assert ex.r_changed.visible
        # seed and α too; back at the defaults the status says so
        ex.w_seed.value = 2
        assert ex.wait(120)
        assert _shown(ex.change_md).startswith("**What changed:** seed 0 → 2: ")
        assert "R1 = 21, seed = 2" in _shown(ex.status)
        ex.w_reset.clicks += 1
        assert ex.wait(120)
        assert "All settings at their defaults" in ex.status.object
        assert _shown(ex.change_md).startswith("**What changed:** R1 21 → 20, seed 2 → 0: ")
        print(f"demo R1 20 -> 21: {ch.text()}")
    finally:
        ex.close()


def test_query_and_params_json_set_the_state(seq, tmp_path):
    from explorer import export

    ex = Explorer(seq, viser=False, start=False)
    try:
        problems = ex.apply_query({"r1": ["25"], "seed": ["3"], "frame": ["4"], "color": ["final"],
                                   "lam": ["<img src=x onerror=alert(1)>"], "bokeh-session-id": ["x"]})
        assert len(problems) == 1 and "lam must be a number" in problems[0]
        ex.start()
        assert ex.wait(120)
        assert (ex.result.params.r1, ex.result.seed) == (25.0, 3)
        assert (ex.w_params["r1"].value, ex.w_seed.value, ex.w_frame.value) == (25.0, 3, 4)
        assert ex.w_color.value == "final (after Random Voting)"
        # the problem is shown as text (escaped), and stays after the result arrived
        assert ex.url_alert.visible and re.search(r"(?<!\\)<", ex.url_alert.object) is None
        assert "<img src=x onerror=alert(1)>" in _shown(ex.url_alert)
        assert ex.query() == {"r1": "25", "seed": "3", "frame": "4", "color": "final"}
        # a control moves the state the URL would carry; the page has moved on from the
        # link, whose warning goes
        ex.w_params["lam"].value = 3.0
        assert ex.wait(120)
        assert ex.query()["lam"] == "3"
        assert not ex.url_alert.visible
        # a link that asks for no new result: its warning goes with the first change after it
        assert ex.apply_query({"nonsense": ["1"]}) and ex.url_alert.visible
        ex.w_frame.value = 2
        assert ex.wait(120) and not ex.url_alert.visible
        # a link whose result is superseded by a newer change before it is shown: the page
        # moved on, the warning goes with the newer result
        assert ex.apply_query({"nonsense": ["1"], "lam": ["2.5"]}) and ex.url_alert.visible
        ex.w_params["r1"].value = 22.0
        assert ex.wait(120) and ex.result.params.r1 == 22.0 and not ex.url_alert.visible
        ex.w_params["r1"].value = 25.0
        ex.w_params["lam"].value = 3.0
        ex.w_frame.value = 4
        assert ex.wait(120)
        # a link to a tour step: its warning stays through the tour (whose steps set their
        # own colourings) and goes with the first change after it
        assert ex.apply_query({"nonsense": ["1"], "tour": ["2"]}) and ex.tour.active
        assert ex.wait(120)
        ex.tour.go(2)
        assert ex.url_alert.visible
        ex.tour.end()
        assert ex.url_alert.visible
        ex.w_frame.value = 5
        assert ex.wait(120) and not ex.url_alert.visible
        ex.w_frame.value = 4
        assert ex.wait(120)
        # the exported params.json loads back (as an upload): state restored, also fields
        # without a control here
        text = export.params_json(ex.sequence, ex.result)
        ex.w_params["r1"].value = 30.0
        assert ex.wait(120)
        d = json.loads(text)
        d["params"]["coarse_frames"] = 5
        _upload(ex, "params.json", json.dumps(d).encode())
        assert ex.wait(120)
        p = ex.result.params
        assert (p.r1, p.lam, p.coarse_frames, ex.result.seed) == (25.0, 3.0, 5, 3)
        assert ex.w_params["r1"].value == 25.0
        # a broken one changes nothing and says why
        res = ex.result
        _upload(ex, "bad.json", b'{"params": {"r1": -1}}')
        assert ex.wait(120) and ex.result is res
        assert ex.alert.visible and "bad.json" in _shown(ex.alert) and "r1 must be in (0" in _shown(ex.alert)
        _upload(ex, "deep.json", ('{"a":' + "[" * 5000 + "]" * 5000 + "}").encode())
        assert ex.wait(120) and ex.result is res and "nested too deeply" in _shown(ex.alert)
        # one saved with a UTF-8 byte-order mark is a params.json too (it was read as a
        # sequence file, and refused as a CSV without the tracks header)
        _upload(ex, "bom.json", b"\xef\xbb\xbf" + json.dumps({"r1": 27}).encode())
        assert ex.wait(120) and ex.result.params.r1 == 27.0
        res = ex.result
        # a value far beyond a slider's range widens it while shown; its own range comes back
        lam = ex.w_params["lam"]
        own = (lam.start, lam.end)
        assert ex.apply_query({"lam": ["1e9"]}) == [] and lam.end == 1e9 and lam.value == 1e9
        assert ex.apply_query({"lam": ["3"]}) == [] and (lam.start, lam.end) == own
        assert ex.wait(120) and ex.result.params.lam == 3.0
        # the URL carries seeds up to laav's bound, as the command line does; the slider's
        # end stays below 2**53 (the page's numbers are doubles)
        for big in (2**40, 2**63 - 1):
            assert ex.apply_query({"seed": [str(big)]}) == []
            assert ex.wait(120) and ex.result.seed == big and ex.query()["seed"] == str(big)
        assert ex.w_seed.end <= 2**53 - 1
        ex.apply_query({"seed": ["3"]})
        assert ex.wait(120)
        # reset brings back every default, also the ones without a control
        ex.w_reset.clicks += 1
        assert ex.wait(120)
        assert ex.result.params == laav.LaavParams() and ex.query() == {"frame": "4", "color": "final"}
    finally:
        ex.close()


def test_cli_loads_params_json_and_param(monkeypatch, tmp_path, capsys):
    seen = fake_serving(monkeypatch)
    s = _two_motion_sequence()
    f = laav.save_sequence(s, tmp_path / "s.npz")
    pj = tmp_path / "p.json"
    pj.write_text(json.dumps({"sequence": "x", "n_motions": 2, "seed": 5,
                              "params": {**laav.LaavParams(r1=22.0, lam=1.5).to_dict()}}))
    assert main([str(f), "--no-browser", "--port", "0", "--params", str(pj), "--param", "lam=3",
                 "--param", "rv_refine=false"]) == 0
    assert seen["params"] == laav.LaavParams(r1=22.0, lam=3.0, rv_refine=False)
    assert seen["seed"] == 5 and seen["n_motions"] == 2
    assert main([str(f), "--no-browser", "--port", "0", "--params", str(pj), "--seed", "1"]) == 0
    assert seen["seed"] == 1
    # a preset first, then --param on top of it
    assert main([str(f), "--no-browser", "--port", "0", "--preset", "paper", "--param", "lam=3"]) == 0
    assert seen["params"] == laav.LaavParams.paper(lam=3.0)
    assert main([str(f), "--no-browser", "--port", "0", "--preset", "own-chain"]) == 0
    assert seen["params"] == laav.LaavParams.own_chain()
    # a partial params.json changes the preset's fields it names, not the others
    bare = tmp_path / "bare.json"
    bare.write_text(json.dumps({"lam": 4.0}))
    assert main([str(f), "--no-browser", "--port", "0", "--preset", "paper", "--params", str(bare)]) == 0
    assert seen["params"] == laav.LaavParams.paper(lam=4.0)
    capsys.readouterr()
    for args, msg in ((["--param", "lam=abc"], "lam must be a number"),
                      (["--param", "lam"], "NAME=VALUE"),
                      (["--param", "r2=5"], "r2 must be larger than r1"),
                      (["--param", "zz=1"], "unknown setting 'zz'"),
                      (["--params", str(tmp_path / "missing.json")], "No such file"),
                      (["--params", str(f)], "not a JSON file"),
                      (["--preset", "ours"], "invalid choice"),
                      (["--param", "sequence=x"], "'sequence' is the page address's"),
                      # a C the points cannot hold is --motions' fault, not --param's
                      (["--motions", str(s.n_points // 8 + 1), "--param", "lam=3"],
                       f"--motions: C = {s.n_points // 8 + 1} motions need at least 8 points")):
        assert main([str(f), "--no-browser", "--port", "0", *args]) == 2
        err = capsys.readouterr().err
        assert msg in err and "Traceback" not in err, (args, err)


def test_stage_errors_plain_rv_numbers_and_replay_reset():
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120, plain_rv=True)
        seq, res = ex.sequence, ex.result
        plain = ex.state.plain_rv()
        # plain RV's error beside LAAV's in the numbers card
        num = V.stage_numbers(seq, res, plain)
        assert f"{100 * num['error_plain']:.1f} %" in ex.numbers.object and "plain RV" in ex.numbers.object
        # ... and how far the two labellings are apart (the check left without ground truth)
        d = laav.misclassification_rate(res.labels, plain.labels)
        assert num["plain_disagreement"] == pytest.approx(d)
        assert f"They label {round(d * seq.n_points)} of the {seq.n_points} points differently" \
            in ex.numbers.object
        # colouring by the coarse stage rings the coarse stage's mistakes (the demo's coarse
        # stage is wrong on some points; the old view said "misclassified: 0" here)
        ex.w_color.value = "coarse (atoms merged)"
        wrong = V.stage_errors(seq, res, "coarse")[0]
        assert wrong.sum() > 0 and len(ex.src_errors.data["x"]) == wrong.sum()
        assert "misclassified by the coarse stage" in ex.frame_caption.object
        for label, stage in (("errors: fine models", "fine"), ("errors: plain RV", "plain")):
            ex.w_color.value = label
            w = V.stage_errors(seq, res, stage, plain)[0]
            assert len(ex.src_errors.data["x"]) == w.sum()
            assert (np.asarray(ex.src_points.data["color"]) == V.ERROR_MARK).sum() == w.sum()
        ex.w_color.value = "plain RV (random start)"
        assert ex.query()["color"] == "plain"
        # GAEC replay: the pair of a step is ringed; a new result starts at its final step
        ex.w_step.value = 3
        assert len(ex.src_pair.data["x"]) == 2
        ex.w_params["lam"].value = 2.5
        assert ex.wait(120)
        assert ex.w_step.value == ex.w_step.end == len(ex.result.multicut.contractions) + 1
        assert len(ex.src_pair.data["x"]) == 0
    finally:
        ex.close()


def test_a_change_sends_only_what_it_changed(seq):
    """A λ change reruns stages 4-5 only: the frame view's atoms and the multicut graph are
    not sent again, the figures are the same objects (never rebuilt), and a frame move
    sends only the points' coordinates, not their colours, shapes or labels."""
    from explorer.cards import base

    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        figs = [ex.fig_frame, ex.fig_graph, ex.fig_z]
        renderers = [list(f.renderers) for f in figs]
        sent: dict = {}
        real = base.set_data

        def spy(src, data):
            cols = real(src, data)
            sent.setdefault(id(src), []).extend(cols)
            return cols

        for mod in ("frame", "graph", "coarse", "epipolar", "rv"):
            pytest.MonkeyPatch().setattr(f"explorer.cards.{mod}.set_data", spy)
        before = ex.result
        ex.w_params["lam"].value = 3.5
        assert ex.wait(60) and ex.result is not before
        assert ex.result.atoms is before.atoms  # the pipeline reused stages 1-3
        assert sent.get(id(ex.src_atoms), []) == []
        assert sent.get(id(ex.src_nodes), []) == []
        assert [f for f in (ex.fig_frame, ex.fig_graph, ex.fig_z)] == figs
        assert [list(f.renderers) for f in figs] == renderers
        ex.w_frame.value = 5  # five frames of trails from here on
        sent.clear()
        ex.w_frame.value = 6
        assert set(sent[id(ex.src_points)]) == {"x", "y"}
        assert set(sent[id(ex.frame_view.src_trails)]) == {"x0", "y0", "x1", "y1"}
        assert np.allclose(np.sort(ex.src_points.data["x"]), np.sort(seq.points[6, :, 0]))
    finally:
        pytest.MonkeyPatch().undo()
        ex.close()


def test_raw_points_are_drawn_before_any_compute(seq):
    ex = Explorer(seq, viser=False, start=False)
    try:
        assert ex.result is None
        assert len(ex.src_points.data["x"]) == seq.n_points
        assert set(ex.src_points.data["color"]) == {V.motion_color(0), V.motion_color(1)}
    finally:
        ex.close()


def test_a_newer_request_interrupts_the_running_computation(seq, monkeypatch):
    """A request arriving while the worker computes stops that computation at its next
    check (the pipeline checks between stages and once per voting iteration: ``Superseded``;
    the pipeline rolls back) and computes the newest settings; their labels are those of a
    fresh run. The state's threads are left as they were (no clean-up is cut short)."""
    import laav.pipeline as LP
    from laav._interrupt import check

    real = LP.build_atoms
    started, finished = threading.Event(), threading.Event()

    def slow_atoms(seq_, p, *a, **k):
        if p.r1 == 22.0:  # the request to be superseded: a stage of 60 s, checking as voting does
            started.set()
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                check()
                time.sleep(0.005)
            finished.set()
        return real(seq_, p, *a, **k)

    monkeypatch.setattr(LP, "build_atoms", slow_atoms)
    st = ExplorerState(seq, autostart=True)
    try:
        assert st.wait(60)
        st.request(params={"r1": 22.0})
        assert started.wait(30)
        gen = st.request(params={"r1": 18.0, "lam": 3.0})
        assert st.wait(30)
        assert st.computing.interrupted >= 1 and not finished.is_set()
        assert st.published_generation == gen
        fresh = laav.segment(seq, seq.n_motions, st.settings.params, seed=0)
        assert st.result.params.r1 == 18.0
        assert np.array_equal(st.result.labels, fresh.labels)
        from laav import _threads
        assert _threads._blas_users == 0  # every thread limit was given back
    finally:
        st.close()


def test_cli_estimates_c_for_a_file_without_ground_truth(monkeypatch, tmp_path, capsys):
    """No labels and no --motions: C is estimated (laav.estimate_motions), said on the
    terminal, and the page opens with it (issue 14 item 7)."""
    seen = fake_serving(monkeypatch)
    s = _two_motion_sequence()
    f = tmp_path / "nolabels.npz"
    np.savez(f, points=s.points)
    assert main([str(f), "--no-browser", "--port", "0"]) == 0
    out = capsys.readouterr().out
    expected = laav.estimate_motions(laav.load_sequence(f)).n_motions
    assert seen["n_motions"] == expected and f"C = {expected} estimated (" in out
    # the page says so too (explorer.state.Origin), and once C is changed, that it was
    prov = seen["origin"]
    assert prov.motions_estimate == expected and prov.point_ids is None
    assert prov.motions_note(expected).startswith(f"C = {expected} was estimated: ")
    from explorer.state import ESTIMATE_NOTE

    assert ESTIMATE_NOTE in prov.motions_note(expected)  # how far an estimate can be trusted
    assert ESTIMATE_NOTE not in prov.motions_note(expected + 1)
    assert "taken from the C box (estimated: " in prov.motions_note(expected + 1)
    # a close call is said, on the terminal and on the page (laav.MotionCount.close_call)
    close = laav.MotionCount(2, (1, 2, 3), (0,) * 3, (0,) * 3, (0,) * 3, (5.0, -0.4), 0.01, "why")
    monkeypatch.setattr(laav, "estimate_motions", lambda *a, **k: close)
    assert main([str(f), "--no-browser", "--port", "0"]) == 0
    said = capsys.readouterr().out
    assert "C = 2 estimated (why; a close call: the test gave motion 3 a 40 % chance" in said
    assert "why; a close call: " in seen["origin"].motions_note(2)
    assert "compare C = 3" in seen["origin"].motions_note(2)
    assert main([str(f), "--no-browser", "--port", "0", "--motions", "3"]) == 0
    assert seen["n_motions"] == 3 and seen["origin"].motions_estimate is None
    # C from --motions: not said to come from the C box
    assert seen["origin"].motions_note(3).startswith("C = 3 as given (--motions or the C box)")


def test_complete_only_exports_the_files_point_numbers(monkeypatch, tmp_path, capsys):
    """``laav-explore FILE --complete-only``: the labels CSV numbers the kept tracks as the
    file does (as ``laav segment --complete-only`` writes them), and the page says how many
    tracks were dropped."""
    import csv as csvmod

    from laav.synthetic import occlude

    seen = fake_serving(monkeypatch)
    s = occlude(_two_motion_sequence(n_frames=9, n_points=120, seed=2), 0.05, rng=0)
    f = tmp_path / "gaps.npz"
    laav.save_sequence(s, f)
    assert main([str(f), "--no-browser", "--port", "0", "--complete-only"]) == 0
    prov = seen["origin"]
    kept = np.flatnonzero(s.visible.all(axis=0))
    assert 0 < kept.size < s.n_points and np.array_equal(prov.point_ids, kept)
    assert f"kept the {kept.size} of {s.n_points} tracks" in prov.note
    ex = Explorer(seen["seq"], seen["n_motions"], viser=False, origin=prov)
    try:
        assert ex.wait(120) and ex.result is not None
        rows = list(csvmod.DictReader(ex.files.export_csv().getvalue().splitlines()))
        assert [int(r["point"]) for r in rows] == kept.tolist()
        assert ex.note.visible and V.md_text(f"kept the {kept.size} of {s.n_points} tracks") in ex.note.object
    finally:
        ex.close()


def test_frame_move_sends_only_the_changed_columns(ex):
    """A frame move changes the points' positions, not their colours, markers or labels:
    only the position columns go to the browser (checked on the document's events)."""
    from bokeh.document import Document
    from bokeh.document.events import ColumnDataChangedEvent, ModelChangedEvent

    doc = Document()
    doc.add_root(ex.frame_view.fig)
    sent: list = []
    doc.on_change(lambda event: sent.append(event))
    ex.w_frame.value = 1
    src = ex.frame_view.src_points
    changed = [e for e in sent if getattr(e, "model", None) is src]
    assert changed, "the frame move sent nothing for the points"
    cols = set()
    for e in changed:
        hint = getattr(e, "hint", None)
        if isinstance(e, ColumnDataChangedEvent) or isinstance(hint, ColumnDataChangedEvent):
            cols |= set((hint or e).cols)
        else:
            assert not isinstance(e, ModelChangedEvent), "the whole data was replaced"
    assert cols == {"x", "y"}


def test_the_frame_player_and_parameters_are_handled_without_panels_wait(ex):
    """A frame or parameter change from the browser is handled at once (panel's 50 ms
    gathering wait is off: a newer parameter value supersedes the computation running)."""
    assert ex.controls.w_frame._debounce == 0
    assert all(w._debounce == 0 for w in ex.controls.w_params.values())
    assert ex.controls.w_seed._debounce == 0


def test_the_page_is_built_with_one_walk_of_its_models(seq, monkeypatch):
    """Bokeh walks every model of a document after each root added and each JavaScript
    link attached unless its index is frozen; the explorer's template builds the page frozen
    (0.6 of 1.4 s on the demo), so the page's ~870 models are walked once."""
    from bokeh.document import Document
    from bokeh.document.models import DocumentModelManager
    from panel.io.state import set_curdoc

    walks = []
    real = DocumentModelManager.recompute
    monkeypatch.setattr(DocumentModelManager, "recompute",
                        lambda self: walks.append(1) or real(self))
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        doc = Document()
        template = ex.template("LAAV explorer", lazy=True)
        with set_curdoc(doc):
            template.server_doc(doc)
        assert len(doc.models) > 300
        assert len(walks) == 1
    finally:
        ex.close()


def test_hidden_cards_come_later_and_at_once_when_asked_for(ex, monkeypatch):
    """The served page's first document leaves out the compare card (hidden until asked
    for) with the later cards; starting the tour (or pinning) before those came puts every
    card on the page at once, in stage order. The tour's panel, hidden at the top of the
    sidebar, is in the first document: the sidebar is never laid out again for it."""
    monkeypatch.setattr(pn.state, "onload", lambda *a, **k: None)  # the page never loads here
    ex.template("LAAV explorer", lazy=True)
    first = ex.main_column.objects
    assert all(c is not ex.compare.card for c in first)
    assert ex.sidebar_column.objects[0] is ex.tour.panel and not ex.tour.panel.visible
    sidebar = list(ex.sidebar_column.objects)
    assert any(c is ex.frame_view.card for c in first) and len(first) < len(ex.main)
    ex.tour.start()
    assert ex.tour.panel.visible
    assert [id(c) for c in ex.main_column.objects] == [id(c) for c in ex.main]
    assert ex.sidebar_column.objects == sidebar  # the same sidebar, untouched
    ex.tour.end()
    ex.template("LAAV explorer", lazy=True)
    assert ex.compare.pin()
    assert [id(c) for c in ex.main_column.objects] == [id(c) for c in ex.main]
    assert ex.compare.inner.visible
    # the colouring's short name in the plots' titles (its long one was cut off at 1280 px)
    ex.w_color.value = "final (after Random Voting)"
    assert ex.compare.fig_a.title.text == f"A (pinned) · frame {ex.frame} · final"
    # ground truth is the same picture on both sides: the compare views colour each side's
    # final motions instead (and say so)
    final_colors = list(ex.compare.src["A"].data["color"])
    ex.w_color.value = "ground truth"
    assert ex.compare.fig_a.title.text == f"A (pinned) · frame {ex.frame} · final"
    assert ex.compare.fig_b.title.text == f"B (live) · frame {ex.frame} · final"
    assert list(ex.compare.src["A"].data["color"]) == final_colors
    assert [st["mode"] for st in ex.compare._styles] == ["final", "final"]  # (here final = truth)
    ex.w_color.value = "errors: coarse"  # any other colouring is the sidebar's
    assert ex.compare.fig_a.title.text == f"A (pinned) · frame {ex.frame} · errors: coarse"


def test_r2_moves_along_when_r1_passes_it_and_values_stay_round(ex):
    """R1 dragged past R2 takes R2 along (a refusal held every later change back, with the
    status line no longer matching the controls), and takes it back to its own value when R1
    goes back (it stayed pushed up, with other atoms, before); slider values carry no floating-point
    residue into the run and the URL (0.1 + 67 x 0.1 = 6.800000000000001)."""
    assert ex.wait(120)
    r2 = ex.w_params["r2"].value
    ex.w_params["r1"].value = r2 + 5.0
    assert ex.wait(120) and not ex.alert.visible
    assert ex.w_params["r2"].value == r2 + 6.0
    assert (ex.result.params.r1, ex.result.params.r2) == (r2 + 5.0, r2 + 6.0)
    ex.w_params["r2"].value = 10.0  # below R1: R1 goes down along
    assert ex.wait(120) and ex.w_params["r1"].value == 9.0 and ex.result.params.r1 == 9.0
    # a pushed radius goes back to its own value when the one that pushed it goes back
    # (R2 set by hand to 10 above: R1 pushes it, and leaves it at 10 again)
    ex.w_params["r1"].value = 30.0
    assert ex.wait(120) and ex.w_params["r2"].value == 31.0
    ex.w_params["r1"].value = 20.0  # still above 10: R2 follows it down, just above it
    assert ex.wait(120) and ex.w_params["r2"].value == 21.0
    ex.w_params["r1"].value = 5.0
    assert ex.wait(120) and ex.w_params["r2"].value == 10.0
    assert (ex.result.params.r1, ex.result.params.r2) == (5.0, 10.0)
    ex.w_params["r1"].value = 12.0  # pushed again, then set by hand: its own value now
    ex.w_params["r2"].value = 14.0
    ex.w_params["r1"].value = 6.0
    assert ex.wait(120) and ex.w_params["r2"].value == 14.0
    # R2 pushes R1 down, and lets it back up to its own value
    ex.w_params["r2"].value = 4.0
    assert ex.wait(120) and ex.w_params["r1"].value == 3.0
    ex.w_params["r2"].value = 30.0
    assert ex.wait(120) and ex.w_params["r1"].value == 6.0
    # a reset in between makes the defaults the radii's own values: nothing stale comes back
    ex.w_params["r1"].value = 35.0
    assert ex.wait(120) and ex.w_params["r2"].value == 36.0
    ex.controls._on_reset()
    assert ex.wait(120) and (ex.w_params["r1"].value, ex.w_params["r2"].value) == (20.0, 40.0)
    ex.w_params["r1"].value = 25.0
    assert ex.wait(120) and ex.w_params["r2"].value == 40.0
    ex.w_params["lam"].value = 0.1 + 67 * 0.1
    assert ex.wait(120) and ex.result.params.lam == 6.8 and ex.query()["lam"] == "6.8"
    ex.w_reset.clicks += 1
    assert ex.wait(120)


def test_a_file_that_fails_to_compute_leaves_the_status_line_and_no_temp_path(ex):
    """An upload that reads but cannot be segmented (every trajectory the same): the
    alert names the file the user gave (not the server's temporary copy) and the status
    line is back on the shown result (it stayed on "Recomputing…")."""
    import io

    assert ex.wait(120)
    res, line = ex.result, ex.status.object
    seq = ex.sequence
    buf = io.BytesIO()
    np.savez(buf, points=np.zeros_like(seq.points), labels=np.asarray(seq.labels))
    _upload(ex, "zeros.npz", buf.getvalue())
    assert ex.wait(120) and ex.result is res
    shown = _shown(ex.alert)
    assert "zeros.npz" in shown and "laav-explore-" not in shown and "/tmp" not in shown
    for _ in range(200):  # the busy flag's end is applied on the document's next tick
        if ex.status.object == line:
            break
        time.sleep(0.1)
    assert ex.status.object == line


def test_a_closed_explorer_is_freed(seq):
    """A tab's explorer, once closed, leaves nothing holding it: panel's class-wide registry
    of page scripts kept every closed tab's explorer (and its results) for the server's life."""
    import gc
    import weakref

    ex = Explorer(seq, viser=False, start=False)
    ex.template("LAAV explorer", lazy=False)
    ex.close()
    ref = weakref.ref(ex)
    del ex
    gc.collect()
    assert ref() is None


def test_the_first_page_complete_is_reported_once(seq, monkeypatch):
    """An explorer's ``on_page_complete`` runs when its later cards are added, and only once."""
    monkeypatch.setattr(pn.state, "onload", lambda *a, **k: None)  # no page loads here
    ex = Explorer(seq, viser=False)
    try:
        assert ex.wait(120)
        calls = []
        ex.template("LAAV explorer", lazy=True)
        ex.on_page_complete = lambda: calls.append(1)
        ex.complete_page()
        ex.complete_page()
        assert calls == [1] and ex.on_page_complete is None
    finally:
        ex.close()


def test_rv_card_names_the_missing_motion_start_and_trial_returned():
    """The RV card says which of LAAV's own starts returned the labels: the missing-motion
    start by its pair, and which of its ``rv_missing_trials`` trials (when it ran several)."""
    import dataclasses

    from test_own_chain import small_motion_uncovered

    from explorer.views import md_text, rv_summary

    seq, init, _ = small_motion_uncovered(0)
    every = laav.LaavParams(rv_missing_gate=0.0)  # (the default's gate skips the start here)
    res = laav.random_voting(seq, 2, every, seed=0, init_labels=init)
    assert res.selected == "missing motion (0+1)"
    start = md_text("missing motion (0+1)")  # as Markdown shows it
    assert f"returned the trial 1 (of `rv_missing_trials`) from the {start} start" in rv_summary(res, None)
    one = dataclasses.replace(res, costs={"informed": 1.0, "missing motion (0+1)": 0.5})
    assert f"returned the trial from the {start} start" in rv_summary(one, None)  # one trial a start
    second = dataclasses.replace(res, selected="missing motion (0+1), trial 2")
    text = rv_summary(second, None)
    assert f"returned the trial 2 (of `rv_missing_trials`) from the {start} start" in text


def test_rv_card_says_what_the_outlier_veto_passed_over():
    """``Voting.vetoed`` (``rv_outlier_veto``, ours): on a scene with outlier tracks the RV
    card names the missing-motion candidates passed over, each with its cost and LAAV's
    informed trial's over the points both explain, and a descent not kept in its own
    words; nothing without the veto."""
    import dataclasses

    from test_own_chain import outlier_scene

    from explorer.views import md_text, rv_summary

    seq, _ = outlier_scene()
    res = laav.segment(seq, 3, seed=0).voting
    starts = [v for v in res.vetoed if v[0].startswith("missing motion")]
    text = rv_summary(res, None)
    assert f"**passed over {len(starts)} missing-motion candidates**" in text
    for name, n, own_cost, its_cost in starts:
        assert f"{md_text(name)}: {its_cost:,.0f} against {own_cost:,.0f} over {n} points" in text
    assert "`rv_outlier_veto`" in text
    one = dataclasses.replace(res, vetoed=(("missing motion (0+1)", 251, 7030.2, 7456.0),
                                           ("the descent", 280, 10.0, 12.0)))
    text = rv_summary(one, None)
    assert "**passed over 1 missing-motion candidate**" in text
    assert f"({md_text('missing motion (0+1)')}: 7,456 against 7,030 over 251 points;" in text
    assert "**kept the labels before the descent, not its result** (12 against 10 over 280 points)" in text
    assert text.count("`rv_outlier_veto`") == 1  # the reason once
    own = md_text("the trial's own labels, descended")
    mine = dataclasses.replace(res, vetoed=(("the trial's own labels, descended", 270, 9.0, 11.0),))
    assert f"kept the polished labels, not {own}" in rv_summary(mine, None)
    off = laav.segment(seq, 3, laav.LaavParams(rv_outlier_veto=False), seed=0).voting
    assert off.vetoed == () and "rv_outlier_veto" not in rv_summary(off, None)


def test_rv_card_says_when_the_refinement_and_reassignment_were_dropped():
    """``Voting.unpolished`` (``rv_descent_from_trial``, ours): the card says the trial's own
    labels descended and the polish was dropped, in the order the steps ran (above
    ``rv_max_points`` the reassignment over every point comes after), and says nothing of
    it otherwise."""
    import dataclasses

    from test_own_chain import small_motion_uncovered

    from explorer.views import rv_summary

    seq, init, _ = small_motion_uncovered(0)
    every = laav.LaavParams(rv_missing_gate=0.0)  # candidates compared: the selection's line
    res = laav.random_voting(seq, 2, every, seed=0, init_labels=init)
    assert not res.unpolished and "dropped" not in rv_summary(res, None)
    un = dataclasses.replace(res, unpolished=True, refined=0, reassigned=0, descended=3)
    text = rv_summary(un, None)
    assert "points moved by the descent on the joint score from the trial's own labels 3;" in text
    assert "**the refinement and reassignment were dropped**" in text and "`rv_descent_from_trial`" in text
    assert "its trial's own labels after the full descent, unpolished" in text
    big = dataclasses.replace(un, reassigned=7)
    assert ("the trial's own labels 3 and then the reassignment over every point 7"
            in rv_summary(big, None))


def test_state_uses_the_voting_helper_after_preload(monkeypatch):
    """Once the page is complete (preload), the session's pipeline runs half of LAAV's own
    trials in the server's voting helper; the labels stay those of laav.segment."""
    from explorer.state import plain_rv_of, shared_helper
    from laav import synthetic

    monkeypatch.setenv("LAAV_VOTING_HELPER", "1")  # (by default only on >= 4 cores)

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
    st = ExplorerState(seq, autostart=True)
    off = ExplorerState(seq, autostart=False, voting_helper=False)
    try:
        assert st.wait(60)
        st.wait_plain_rv(60)  # (plain RV's worker sends its job to the helper once attached)
        st.preload()
        off.preload()
        assert st.helper is not None and st.helper is shared_helper() and off.helper is None
        assert st.helper.wait_ready()
        jobs, delivered = st.helper.jobs, st.helper.delivered
        st.request(params={"r1": 12.0})
        assert st.wait(60)
        st.wait_plain_rv(60)  # (the same seed: plain RV is cached, no job)
        # the coarse stage's pairwise votes (what card 3 draws), then a part of the candidates
        assert (st.helper.jobs, st.helper.delivered) == (jobs + 2, delivered + 2)
        fresh = laav.segment(seq, 3, st.settings.params, seed=0)
        assert np.array_equal(st.result.labels, fresh.labels)
        assert st.result.voting.trial_iterations == fresh.voting.trial_iterations
        # a new seed: the votes, the pipeline's part, then plain RV for the RV card, all there
        jobs, delivered = st.helper.jobs, st.helper.delivered
        st.request(seed=4)
        assert st.wait(60)
        plain = st.wait_plain_rv(60)
        assert (st.helper.jobs, st.helper.delivered) == (jobs + 3, delivered + 3)
        alone = plain_rv_of(seq, st.settings)
        assert np.array_equal(plain.labels, alone.labels)
        assert plain.trial_iterations == alone.trial_iterations
    finally:
        st.close()
        off.close()


def test_the_voting_helper_by_default_only_with_a_core_for_each(monkeypatch):
    """The server, the helper and the browser each need a core: by default no helper below
    4 cores (on 2 the browser shares the helper's core); LAAV_VOTING_HELPER overrides."""
    import os

    import explorer.state as S

    monkeypatch.setattr(S, "_helper", [])  # no helper started yet in this process
    monkeypatch.delenv("LAAV_VOTING_HELPER", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    assert S.shared_helper() is None
    monkeypatch.setattr(S, "_helper", [])
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    helper = S.shared_helper()
    try:
        assert helper is not None and S.shared_helper() is helper
    finally:
        helper.close()
    monkeypatch.setattr(S, "_helper", [])
    monkeypatch.setenv("LAAV_VOTING_HELPER", "0")
    assert S.shared_helper() is None
    monkeypatch.setattr(S, "_helper", [])
    monkeypatch.setenv("LAAV_VOTING_HELPER", "1")
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    helper = S.shared_helper()
    try:
        assert helper is not None
    finally:
        helper.close()


def test_card_3_votes_are_fitted_after_the_result_is_shown(monkeypatch):
    """The pairwise votes card 3 draws (which the default merge does not fit) are fitted
    once the result is on the views, not inside its computation: card 3 first draws the
    result with them pending ("fitting…", no distances), then, when the votes worker has
    fitted them, draws them; ``wait`` returns once they are drawn. (Without the voting
    helper, which fits them during the voting: on by default from 4 cores.)"""
    monkeypatch.setenv("LAAV_VOTING_HELPER", "0")
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        seen = []  # (result, its votes fitted) at each draw of card 3's epipolar panel
        real = ex.coarse_view.epipolar.draw

        def draw(seq, res):
            seen.append((res, V.votes_fitted(res)))
            real(seq, res)

        ex.coarse_view.epipolar.draw = draw
        ex.w_params["r1"].value = 23.0  # new atoms: new fine models, new votes
        assert ex.wait(120) and ex.result.params.r1 == 23.0
        res = ex.result
        mine = [fitted for r, fitted in seen if r is res]
        assert mine[0] is False, "the votes were fitted before the result was shown"
        assert mine[-1] is True and V.votes_fitted(res)
        assert ex.votes_pending is None
        caption = ex.coarse_view.epipolar.caption.object
        assert "(being fitted)" not in caption and "vote for f1" in caption
        d = ex.coarse_view.src_z.data["d"]
        assert np.isfinite(np.asarray(d, float)).sum() > 0
    finally:
        ex.close()


def test_a_dropped_votes_fit_is_asked_again(monkeypatch):
    """A votes fit dropped for a newer request (which may never show a result: cancelled,
    failed) is asked again while its result is still the one shown, so card 3 does not stay
    on "fitting…" and ``wait`` does not time out."""
    monkeypatch.setenv("LAAV_VOTING_HELPER", "0")
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        asked = []
        real = ex.state.fit_votes
        ex.state.fit_votes = lambda r: (asked.append(r), real(r))[1]
        block = threading.Event()
        ex.state._votes_worker.submit(block.wait, 60)  # the result's fit queues behind this
        ex.w_params["r1"].value = 23.0
        deadline = time.monotonic() + 120
        while not (ex.result is not None and ex.result.params.r1 == 23.0
                   and ex.votes_pending is ex.result):
            assert time.monotonic() < deadline
            time.sleep(0.02)
        res = ex.result
        with ex.state._lock:
            ex.state._gen += 1  # a newer request that shows nothing: the queued fit is dropped
        block.set()
        assert ex.wait(60), "card 3 stayed waiting for a dropped fit"
        assert [r for r in asked if r is res] == [res, res]  # asked again once
        assert V.votes_fitted(res) and ex.votes_pending is None
        assert "(being fitted)" not in ex.coarse_view.epipolar.caption.object
    finally:
        ex.close()


def test_a_seed_beyond_the_slider_widens_it(seq):
    # a seed from the address or the command line (e.g. 150) is shown by the slider's handle,
    # not pinned at the slider's usual end (99)
    ex = Explorer(seq, seed=150, viser=False, start=False)
    try:
        assert ex.w_seed.value == 150 and ex.w_seed.end >= 150
    finally:
        ex.close()


def test_the_page_passes_bokehs_integrity_checks(ex, monkeypatch):
    """``laav-explore`` serves its pages without bokeh's per-session document validation
    (:func:`explorer.cli.no_session_validation`: 0.10-0.13 s of every tab's first page), so
    the checks run here, on the whole page (every card, the Advanced card's fields unfolded,
    not only the first page's), with a result drawn: no error and no warning."""
    from bokeh.core.validation.check import check_integrity
    from bokeh.document import Document
    from bokeh.settings import settings

    from explorer import cli

    ex.advanced.card.collapsed = False  # its fields are made and sent when first unfolded
    doc = Document()
    ex.template(lazy=False).server_doc(doc)
    found = []
    for root in doc.roots:
        issues = check_integrity(root.references())
        found += [("error", str(e)) for e in issues.error] + [("warning", str(w)) for w in issues.warning]
    assert len(doc.models) > 1000  # the whole page, the Advanced card's fields too
    assert found == []
    # what the command's server does: off, unless the person asked for it
    setting = settings.perform_document_validation
    before = setting._user_value
    monkeypatch.delenv("BOKEH_VALIDATE_DOC", raising=False)
    try:
        cli.no_session_validation()
        assert setting() is False
        setting.unset_value()
        monkeypatch.setenv("BOKEH_VALIDATE_DOC", "true")
        cli.no_session_validation()
        assert setting() is True
    finally:
        setting._user_value = before  # as this process had it


def test_card_titles_stay_bold_when_they_change():
    """A card's title drawn again in a live page (the Numbers and Seed sweep cards retitle
    themselves for a sequence without ground truth) got the template's Bootstrap ``h3``
    weight (500) and turned light: the cards draw their title in a header pane of their own,
    with a bold sheet, rewritten (escaped) at every change of ``title``."""
    from explorer.cards.base import TITLE_CSS, card

    c = card("5 · Final labels")
    assert c.header.object == "<h3>5 · Final labels</h3>" and TITLE_CSS in c.header.stylesheets
    c.title = "Seed sweep: <does it change?>"
    assert c.title == "Seed sweep: <does it change?>"
    assert c.header.object == "<h3>Seed sweep: &lt;does it change?&gt;</h3>"
    assert TITLE_CSS in c.header.stylesheets


def test_card_3_gets_the_joint_merges_whole_comparison():
    """A library run scores the joint merge's shortlist only until no partition can win
    (laav.Pipeline's default); the explorer's pipelines score all of it, since card 3 draws
    every pair's margin from it. On this scene the library stops after 2 of 10."""
    from explorer.state import ExplorerState
    from laav import synthetic

    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=1)
    lib = laav.Pipeline(seq, 3).result.coarse.shortlist
    full0 = full = laav.Pipeline(seq, 3, full_shortlist=True).result.coarse.shortlist
    assert lib.score.size < full.score.size and not lib.complete and full.complete
    st = ExplorerState(seq, autostart=True)
    try:
        assert st.wait(60)
        for _ in range(2):  # the first result, then a recomputed one
            got = st.result.coarse.shortlist
            assert np.array_equal(got.score, full.score) and got.chosen == full.chosen
            st.request(params={"lam": 1.5})
            assert st.wait(60)
            full = laav.Pipeline(seq, 3, laav.LaavParams(lam=1.5),
                                 full_shortlist=True).result.coarse.shortlist
    finally:
        st.close()
    # a caller's pipeline (ExplorerState(pipeline=...)) scoring part of it is made to score all
    lib_pipe = laav.Pipeline(seq, 3)
    lib_labels = lib_pipe.result.labels
    assert not lib_pipe.result.coarse.shortlist.complete
    st = ExplorerState(seq, 3, pipeline=lib_pipe, autostart=True)
    try:
        assert st.wait(60)
        got = st.result.coarse.shortlist
        assert got.complete and np.array_equal(got.score, full0.score)
        assert np.array_equal(st.result.labels, lib_labels)
    finally:
        st.close()
