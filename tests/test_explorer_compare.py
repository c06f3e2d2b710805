"""The GUI-free parts of the Advanced panel and of the A/B compare: the field table
(:mod:`explorer.fields`) and the compare logic (:mod:`explorer.compare`): which settings
differ, the errors side by side, the points whose final motion differs."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest
from conftest import two_motion_sequence

import laav
from explorer import compare as C
from explorer import views as V
from explorer.fields import FIELDS, STAGE_TITLES, changed_fields, field_docs, fmt_value, widget_value
from explorer.state import Settings
from laav.params import _BOUNDS, STAGE_PARAMS


@pytest.fixture(scope="module")
def seq() -> laav.Sequence:
    return two_motion_sequence(0, P=120, F=10, name="ab_test")


@pytest.fixture(scope="module")
def results(seq):
    """Two results on ``seq``: the defaults (A) and another λ and Random Voting cap (B)."""
    pa, pb = laav.LaavParams(), laav.LaavParams(lam=5.0, rv_max_iter=3, rv_trials=1)
    ra = laav.Pipeline(seq, 2, pa, 0).result
    rb = laav.Pipeline(seq, 2, pb, 1).result
    return (ra, Settings(pa, 0, 2)), (rb, Settings(pb, 1, 2))


# ---------------------------------------------------------------------------- fields
def test_every_field_once_with_the_validation_tables_bounds():
    names = [f.name for f in FIELDS]
    assert sorted(names) == sorted(f.name for f in dataclasses.fields(laav.LaavParams))
    assert len(set(names)) == len(names)
    table = {n: (k, lo, hi) for n, k, lo, hi in _BOUNDS}
    d = laav.LaavParams()
    for f in FIELDS:
        kind, lo, hi = table[f.name]
        assert f.kind == kind and f.default == getattr(d, f.name)
        if kind == "choice":
            assert f.choices == tuple(lo) and f.default in f.choices
        elif kind != "bool":
            assert (f.low, f.high) == (lo, hi)
        # grouped by the stage that reads it, in the stages' order
        assert f.name in STAGE_PARAMS[f.stage] and f.stage in STAGE_TITLES
    stages = [f.stage for f in FIELDS]
    assert stages == sorted(stages, key=["atoms", "graph", "multicut", "coarse", "voting"].index)
    by_name = {f.name: f for f in FIELDS}
    assert by_name["coarse_merge"].choices == ("auto", "coding", "epipolar", "joint")
    assert by_name["coarse_merge"].default == "auto"
    assert by_name["rv_refine"].kind == "bool" and by_name["fine_models"].kind == "int|None"


def test_every_field_has_its_docstring_as_plain_text_tooltip():
    docs = field_docs()
    for f in FIELDS:
        assert f.doc and f.doc == docs[f.name], f.name
        tip = f.tooltip()
        assert tip.startswith(f"{f.name}: ") and "Default: " in tip and "Allowed: " in tip
        assert "``" not in tip and not re.search(r":(mod|func|meth|class):`", tip), tip
        assert "\n" not in tip
    lam = next(f for f in FIELDS if f.name == "lam")
    assert "Epipolar voting strength lambda" in lam.doc and "(0, 1e+12]" in lam.tooltip()
    merge = next(f for f in FIELDS if f.name == "coarse_merge")
    assert "laav.coding" in merge.doc and "one of: auto, coding, epipolar, joint" in merge.tooltip()
    # the parser stops at the next section and reads any numpydoc Parameters block
    doc = """Title.

    Parameters
    ----------
    a : int
        First ``a`` line,
        second line.
    b_c : {"x", "y"}
        See :func:`laav.segment`.

    Validation
    ----------
    not : a field
    """
    assert field_docs(doc) == {"a": "First a line, second line.", "b_c": "See laav.segment."}


def test_widget_values_and_changed_fields():
    f = {x.name: x for x in FIELDS}
    assert widget_value(f["rv_trials"], 20) == 20 and type(widget_value(f["rv_trials"], 20.0)) is int
    assert widget_value(f["rv_trials"], 2.5) == 2.5  # LaavParams then says "an integer"
    assert widget_value(f["fine_models"], None) is None
    assert widget_value(f["lam"], 3) == 3.0 and type(widget_value(f["lam"], 3)) is float
    assert widget_value(f["rv_refine"], False) is False
    assert widget_value(f["coarse_merge"], "coding") == "coding"
    with pytest.raises(ValueError, match="rv_trials must be an integer"):
        laav.LaavParams(rv_trials=widget_value(f["rv_trials"], 2.5))
    assert changed_fields(laav.LaavParams()) == []
    p = laav.LaavParams(rv_trials=20, coarse_merge="coding", r1=10.0)
    assert changed_fields(p) == ["r1", "coarse_merge", "rv_trials"]
    assert (fmt_value(None), fmt_value(True), fmt_value(2.0), fmt_value(0.25), fmt_value("x")) == (
        "auto", "on", "2", "0.25", "x")


# ---------------------------------------------------------------------------- compare
def test_params_diff_names_every_setting_that_differs():
    a = Settings(laav.LaavParams(), 0, 2)
    assert C.params_diff(a, a) == []
    b = Settings(laav.LaavParams(lam=3.5, coarse_merge="coding", fine_models=5), 4, 3)
    assert C.params_diff(a, b) == [("fine_models", None, 5), ("coarse_merge", "auto", "coding"),
                                   ("lam", 2.0, 3.5), ("seed", 0, 4), ("motions", 2, 3)]
    assert C.params_diff(b, a)[0] == ("fine_models", 5, None)


def test_error_diff_and_changed_points():
    a = {"fine": 0.0, "coarse": 0.05, "final": 0.02, "plain": None}
    b = {"fine": 0.1, "coarse": 0.05, "final": 0.0, "plain": 0.3}
    rows = C.error_diff(a, b)
    assert [r[0] for r in rows] == ["fine", "coarse", "final", "plain"]
    assert rows[0] == ("fine", 0.0, 0.1, pytest.approx(0.1))
    assert rows[1][3] == 0.0 and rows[2][3] == pytest.approx(-0.02)
    assert rows[3] == ("plain", None, 0.3, None)
    # a mere renaming of the motions moves no point; a real move does
    la = np.array([0, 0, 0, 1, 1, 1, 2, 2])
    assert C.changed_points(la, (la + 1) % 3).size == 0
    lb = (la + 1) % 3
    lb[[1, 6]] = lb[[3, 0]]
    assert C.changed_points(la, lb).tolist() == [1, 6]
    with pytest.raises(ValueError, match="different numbers of points"):
        C.changed_points(la, la[:-1])


def test_compare_two_results(seq, results):
    (ra, sa), (rb, sb) = results
    a, b = C.pin(seq, ra, sa), C.pin(seq, rb, sb)
    # A keeps its own copies of the labels and each stage's error (from views.stage_numbers)
    num = V.stage_numbers(seq, ra)
    assert a.errors == {"fine": num["error_fine"], "coarse": num["error_coarse"],
                        "final": num["error_final"], "plain": None}
    assert np.array_equal(a.labels["final"], ra.labels) and a.labels["final"] is not ra.labels
    comp = C.compare(a, b)
    assert comp.has_truth and comp.n_points == seq.n_points
    assert [p[0] for p in comp.params] == ["lam", "rv_max_iter", "rv_trials", "seed"]
    nb = V.stage_numbers(seq, rb)
    assert comp.errors[2] == ("final", num["error_final"], nb["error_final"],
                              pytest.approx(nb["error_final"] - num["error_final"]))
    expect = np.flatnonzero(V.align_labels(rb.labels, ra.labels) != ra.labels)
    assert comp.changed.tolist() == expect.tolist()
    md = C.comparison_markdown(comp)
    assert "| final | " in md and f"{comp.changed.size} of {seq.n_points}" in md
    assert "lam: 2 → 5" in re.sub(r"\\(.)", r"\1", md)
    # A against itself: nothing differs
    same = C.compare(a, a)
    assert same.params == [] and same.changed.size == 0 and all(r[3] in (0, None) for r in same.errors)
    assert "none (B has A's settings)" in C.comparison_markdown(same)
    # plain RV's run, computed later, adds its error
    plain = laav.random_voting(seq, 2, sa.params, 0)
    a2 = C.with_plain(a, plain)
    assert a2.errors["plain"] == pytest.approx(laav.misclassification_rate(seq.labels, plain.labels))
    assert C.with_plain(a2, None) is a2 and a.errors["plain"] is None
    # results on different sequences are not compared
    other = two_motion_sequence(1, P=120, F=10, name="other")
    with pytest.raises(ValueError, match="different sequences"):
        C.compare(a, C.pin(other, ra, sa))


def test_compare_without_ground_truth_counts_the_points_that_moved(seq, results):
    (ra, sa), (rb, sb) = results
    bare = laav.Sequence(seq.points, None, name="<b>no truth</b>")
    comp = C.compare(C.pin(bare, ra, sa), C.pin(bare, rb, sb))
    assert not comp.has_truth and all(r[1] is None and r[2] is None for r in comp.errors)
    md = C.comparison_markdown(comp)
    assert "No ground truth" in md and "error vs ground truth" not in md
    assert f"{comp.changed.size} of {seq.n_points}" in md


def test_values_in_the_compare_text_are_escaped():
    comp = C.Comparison([("coarse_merge", "<img src=x onerror=alert(1)>", "coding")], [], np.zeros(0, int),
                        5, False)
    md = C.comparison_markdown(comp)
    assert re.search(r"(?<!\\)[<>]", md) is None  # every < and > escaped: text, no HTML
    assert "coarse_merge: <img src=x onerror=alert(1)> → coding" in re.sub(r"\\(.)", r"\1", md)


def test_without_truth_b_is_coloured_like_a(seq, results):
    """B's motions take A's colours when there is no ground truth to match both to."""
    (ra, _), _ = results
    bare = laav.Sequence(seq.points, None, name="bare")
    # the same segmentation with every label renamed (coarse and final): the views would
    # colour it the other way round unless matched to A
    co = ra.coarse
    rn = dataclasses.replace(ra, labels=1 - ra.labels, coarse=dataclasses.replace(
        co, point_labels=np.where(co.point_labels >= 0, 1 - co.point_labels, -1),
        fine_to_coarse=1 - np.asarray(co.fine_to_coarse)))
    sa = V.point_style(bare, ra, "final")
    free = V.point_style(bare, rn, "final")
    assert not np.array_equal(free["color"], sa["color"])  # the test can fail
    ref = V.shown_labels(bare, ra)["final"]
    for mode in ("final", "coarse", "fine"):
        s_a = V.point_style(bare, ra, mode)
        s_b = V.point_style(bare, rn, mode, ref=ref)
        assert np.array_equal(s_a["color"], s_b["color"]), mode
        assert np.array_equal(s_a["marker"], s_b["marker"]), mode
    # with ground truth the reference is not used
    s = V.point_style(seq, rn, "final", ref=1 - ref)
    assert np.array_equal(s["color"], V.point_style(seq, rn, "final")["color"])


def test_one_legend_lists_the_motions_of_both_sides(seq, results):
    """The compare views' legend (beside B, for both): every label of A's and of B's points
    once, in the frame view's order, with the colour and marker its points are drawn with,
    at no position (drawn only in the legend), a label only one side has included."""
    (ra, _), (rb, _) = results
    for mode in ("final", "fine", "errors", "atoms"):
        sa, sb = V.point_style(seq, ra, mode), V.point_style(seq, rb, mode)
        rows = V.legend_points(sa, sb)
        labels = set(sa["label"]) | set(sb["label"])
        # numbers read as numbers ("fine model 2" before "fine model 10"), written out here
        by_number = lambda t: [int(u) if u.isdigit() else u for u in re.split(r"(\d+)", t)]  # noqa: E731
        assert list(rows["label"]) == sorted(labels, key=by_number), mode
        assert np.isnan(rows["x"]).all() and np.isnan(rows["y"]).all()
        drawn = V.points_source(seq, 0, sa)  # (a label's sample: as the frame view's legend draws it)
        for lab, color, marker in zip(rows["label"], rows["color"], rows["marker"]):
            side = sa if lab in set(sa["label"]) else sb
            i = np.flatnonzero(side["label"] == lab)
            assert color in set(side["color"][i]) and marker in set(side["marker"][i]), (mode, lab)
        if mode == "final":
            assert list(rows["color"]) == [drawn["color"][list(drawn["label"]).index(lab)]
                                           for lab in rows["label"]]
    # a motion only B has (A all motion 1): listed too, with B's colour and marker
    only_a = dict(V.point_style(seq, ra, "final"))
    only_a.update(label=np.full(seq.n_points, "motion 1"), color=np.full(seq.n_points, V.motion_color(0)),
                  marker=np.full(seq.n_points, V.motion_marker(0), dtype=object))
    rows = V.legend_points(only_a, V.point_style(seq, rb, "final"))
    assert list(rows["label"]) == ["motion 1", "motion 2"]
    assert list(rows["color"]) == [V.motion_color(0), V.motion_color(1)]
    assert list(rows["marker"]) == [V.motion_marker(0), V.motion_marker(1)]
    assert V.legend_points()["label"].size == 0


def test_a_shared_legend_groups_both_sides_or_neither(seq):
    """Beside B, one legend for both views: when either side has more fine models than its
    rows, both sides list theirs per motion ("motion 1: its fine models"), never a mix of
    one side's rows per model and the other's per motion."""
    few = laav.Pipeline(seq, 2, laav.LaavParams(fine_models=2), 0).result
    many = laav.Pipeline(seq, 2, laav.LaavParams(fine_models=8), 0).result
    nf, nm = V.n_fine_models(few), V.n_fine_models(many)
    assert nf <= 3 < nm
    assert V.shared_fine_rows(nm, few, many) == nm  # both fit
    rows = V.shared_fine_rows(nf, few, many)
    assert rows == -1
    labels = set(V.legend_points(*(V.point_style(seq, r, "fine", fine_rows=rows, fine_counts=False)
                                   for r in (few, many)))["label"])
    assert labels <= {"motion 1: its fine models", "motion 2: its fine models", "no fine model"}
    # deciding per side, as before, mixed them
    mixed = set(V.legend_points(V.point_style(seq, few, "fine", fine_rows=nf, fine_counts=False),
                                V.point_style(seq, many, "fine", fine_rows=nf, fine_counts=False))["label"])
    assert any(t.startswith("fine model ") for t in mixed)
    assert any(t.endswith("its fine models") for t in mixed)
