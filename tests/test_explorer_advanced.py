"""The Advanced card and the A/B compare in the app, without a browser: build the explorer,
set widget values, check the requests, the URL it would carry, the other widgets, the
compare card's sources and text (as in tests/test_explorer.py)."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest
from conftest import two_motion_sequence

import laav

pn = pytest.importorskip("panel")

from explorer import Explorer  # noqa: E402
from explorer import views as V  # noqa: E402
from explorer.cards.advanced import MARK  # noqa: E402
from explorer.fields import FIELDS  # noqa: E402


def _shown(pane) -> str:
    return re.sub(r"\\(.)", r"\1", pane.object)


@pytest.fixture(scope="module")
def seq() -> laav.Sequence:
    return two_motion_sequence(0, P=120, F=10, name="advanced_test")


@pytest.fixture
def ex(seq):
    e = Explorer(seq, viser=False)
    assert e.wait(120), "first result did not arrive"
    yield e
    e.close()


def test_advanced_card_has_every_field_folded_with_tooltips(ex):
    adv = ex.advanced
    assert adv.card.collapsed and adv.card in ex.sidebar
    assert list(adv.widgets) == [f.name for f in FIELDS]
    d = laav.LaavParams()
    for f in FIELDS:
        w = adv.widgets[f.name]
        assert w.value == getattr(d, f.name) and w.label == f.name
        # integer fields too are number boxes (panel's integer box read "2.5" typed as 25),
        # stepping by 1; LaavParams refuses a fraction
        kind = {"bool": pn.widgets.Checkbox, "choice": pn.widgets.Select, "int": pn.widgets.FloatInput,
                "int|None": pn.widgets.FloatInput, "float": pn.widgets.FloatInput,
                "float>": pn.widgets.FloatInput}[f.kind]
        assert type(w) is kind, f.name
        if f.kind in ("int", "int|None"):
            assert w.step == 1, f.name
        if f.kind == "choice":
            assert w.options == list(f.choices)
        elif f.kind != "bool":
            # no bounds on the box (the page's box neither clamps nor sends a value past
            # them): LaavParams refuses it with a message; the range is in the tooltip
            assert (w.start, w.end) == (None, None)
            assert w.description == V.md_text(f.tooltip())  # Markdown: every character literal
    assert adv.widgets["coarse_merge"].options == ["auto", "coding", "epipolar", "joint"]
    assert adv.widgets["coarse_merge"].value == "auto"
    assert adv.marked == [] and "All fields at their defaults" in adv.summary.object
    # folded, the card sends none of its fields with the page; the first unfolding does
    assert len(adv.card.objects) == 0
    adv.card.collapsed = False
    assert list(adv.card.objects) == adv.body and adv.w_reset in adv.card.objects
    assert all(w in adv.card.objects or any(w in getattr(o, "objects", []) for o in adv.card.objects)
               for w in adv.widgets.values())
    adv.card.collapsed = True
    adv.card.collapsed = False
    assert list(adv.card.objects) == adv.body


def test_a_field_recomputes_updates_the_url_and_the_sliders(ex):
    adv = ex.advanced
    atoms = ex.result.atoms
    adv.widgets["rv_trials"].value = 20
    assert ex.wait(120)
    assert ex.result.params.rv_trials == 20 and ex.result.atoms is atoms  # only voting reran
    assert ex.query()["rv_trials"] == "20"
    assert adv.marked == ["rv_trials"] and adv.widgets["rv_trials"].label == f"{MARK} rv_trials · default 10"
    assert "1 field off the defaults: rv\\_trials" in adv.summary.object
    adv.widgets["coarse_merge"].value = "coding"
    assert ex.wait(120)
    assert ex.result.params.coarse_merge == "coding" and ex.query()["coarse_merge"] == "coding"
    # a field with a slider: the slider follows, and the slider moves the field
    adv.widgets["lam"].value = 3.5
    assert ex.wait(120)
    assert ex.w_params["lam"].value == 3.5 and ex.result.params.lam == 3.5
    ex.w_params["r1"].value = 25.0
    assert ex.wait(120)
    assert adv.widgets["r1"].value == 25.0 and "r1" in adv.marked
    # fields without a slider keep their values through a slider move
    assert ex.result.params.rv_trials == 20 and ex.result.params.coarse_merge == "coding"
    assert set(adv.marked) == {"r1", "coarse_merge", "lam", "rv_trials"}
    # a switch
    adv.widgets["rv_refine"].value = False
    assert ex.wait(120)
    assert ex.result.params.rv_refine is False and ex.query()["rv_refine"] == "false"


def test_an_invalid_field_shows_a_message_and_keeps_the_result(ex):
    adv = ex.advanced
    res = ex.result
    adv.widgets["affine_threshold"].value = 0.0  # (0, 1e6]: LaavParams refuses 0
    assert ex.wait(60) and ex.result is res
    assert adv.message.visible and "affine_threshold must be in (0" in _shown(adv.message)
    assert ex.alert.visible and "affine_threshold" in _shown(ex.alert)
    for name, bad in (("rv_trials", 0), ("rv_max_iter", 99_999_999)):  # past the field's bounds
        adv.widgets[name].value = bad
        assert ex.wait(60) and ex.result is res
        assert adv.message.visible and name in _shown(adv.message)
    assert "Traceback" not in adv.message.object
    adv.widgets["r2"].value = 10.0  # below R1 = 20
    assert ex.wait(60) and ex.result is res
    assert "r2 must be larger than r1" in _shown(adv.message)
    adv.widgets["rv_trials"].value = None  # an emptied box
    assert ex.wait(60) and ex.result is res and "rv_trials must be an integer" in _shown(adv.message)
    # the next good change clears the message, and every field shows what was computed
    adv.widgets["pooled_trials"].value = 4
    assert ex.wait(120)
    assert ex.result.params.pooled_trials == 4 and not adv.message.visible
    assert adv.widgets["affine_threshold"].value == 2.0 and adv.widgets["r2"].value == 40.0
    assert adv.widgets["rv_trials"].value == 10


def test_fine_models_auto_or_typed_stays_so_through_slider_moves(ex):
    adv = ex.advanced
    adv.widgets["fine_per_motion"].value = 3
    assert ex.wait(120)
    assert ex.result.params.fine_models is None and ex.w_params["fine_models"].value == 6
    ex.w_params["lam"].value = 3.0  # the fine-model slider says 6 = 3C: still "auto"
    assert ex.wait(120)
    assert ex.result.params.fine_models is None and adv.widgets["fine_models"].value is None
    adv.widgets["fine_models"].value = 4
    assert ex.wait(120)
    assert ex.result.params.fine_models == 4 and ex.w_params["fine_models"].value == 4
    ex.w_params["lam"].value = 2.5
    assert ex.wait(120)
    assert ex.result.params.fine_models == 4 and adv.widgets["fine_models"].value == 4
    adv.widgets["fine_models"].value = None  # emptied: auto again
    assert ex.wait(120)
    assert ex.result.params.fine_models is None and ex.w_params["fine_models"].value == 6


def test_reset_url_and_params_json_reach_the_advanced_card(ex):
    adv = ex.advanced
    for name, v in (("rv_trials", 30), ("coarse_merge", "coding")):
        adv.widgets[name].value = v
        assert ex.wait(120)
    adv.w_reset.clicks += 1
    assert ex.wait(120)
    assert ex.result.params == laav.LaavParams() and adv.marked == []
    assert all(adv.widgets[f.name].value == f.default for f in FIELDS)
    # the sidebar's reset too
    adv.widgets["rv_patience"].value = 9
    assert ex.wait(120)
    ex.w_reset.clicks += 1
    assert ex.wait(120) and adv.widgets["rv_patience"].value == 15
    # a shared address
    ex.apply_query({"coarse_merge": ["coding"], "rv_select": ["none"], "lam": ["4"]})
    assert ex.wait(120)
    assert (adv.widgets["coarse_merge"].value, adv.widgets["rv_select"].value) == ("coding", "none")
    assert adv.widgets["lam"].value == 4.0 and ex.w_params["lam"].value == 4.0
    # a params.json
    d = json.loads(ex.files.export_json().getvalue())
    d["params"]["coarse_samples"], d["params"]["rv_reassign"] = 12, False
    assert ex.load_params(json.dumps(d))
    assert ex.wait(120)
    assert adv.widgets["coarse_samples"].value == 12 and adv.widgets["rv_reassign"].value is False
    assert {"coarse_samples", "rv_reassign", "coarse_merge", "rv_select", "lam"} == set(adv.marked)
    # one exported for another sequence: its parameters and seed, not its C, and the page says so
    C = ex.result.n_motions
    d.update(sequence="another", n_motions=C + 1, seed=4)
    d["params"]["coarse_samples"] = 10
    assert ex.load_params(json.dumps(d), "theirs.json")
    assert ex.wait(120)
    assert (ex.result.params.coarse_samples, ex.result.seed, ex.result.n_motions) == (10, 4, C)
    assert "theirs.json was exported for another" in ex.note.object.replace("\\", "")
    assert f"its C = {C + 1} is not (C stays {C})" in ex.note.object.replace("\\", "")
    ex.w_seed.value = 5  # the note goes with that file's result
    assert ex.wait(120) and "theirs.json" not in ex.note.object
    # one that differs only in C: nothing to recompute, the note is shown at once
    res = ex.result
    d.update(seed=5, n_motions=C + 2)
    d["params"] = ex.result.params.to_dict()
    assert ex.load_params(json.dumps(d), "only_c.json")
    assert ex.wait(120) and ex.result is res
    deadline = time.monotonic() + 10
    while "only_c.json" not in ex.note.object and time.monotonic() < deadline:
        time.sleep(0.05)
    assert f"its C = {C + 2} is not (C stays {C})" in ex.note.object.replace("\\", "")
    # a C this sequence could not take does not get the file refused
    d.update(n_motions=10**6, seed=6)
    assert ex.load_params(json.dumps(d), "huge_c.json") and ex.wait(120) and ex.result.seed == 6


def test_presets_in_one_click(ex):
    """The paper's stages and ours with plain RV, each one click in the Advanced card: every
    field as the preset sets it, the sliders and the URL follow, and the Random Voting card
    says which votes LAAV's trial used (the paper's: Sampson alone)."""
    adv = ex.advanced
    adv.w_presets["paper"].clicks += 1
    assert ex.wait(120)
    assert ex.state.target.params == laav.LaavParams.paper() == ex.result.params
    assert adv.widgets["rv_subspace_weight"].value == 0.0 and adv.widgets["rv_select"].value == "none"
    assert ex.query()["rv_subspace_weight"] == "0" and ex.query()["rv_select"] == "none"
    assert ex.result.voting.informed_subspace_weight == 0.0
    assert "Sampson distance alone (the RV paper's)" in ex.rv_view.rv_md.object
    _names_its_preset(ex, "paper")
    adv.w_presets["with_plain_rv"].clicks += 1
    assert ex.wait(120) and ex.result.params == laav.LaavParams.with_plain_rv()
    assert adv.widgets["coarse_merge"].value == "epipolar" and adv.widgets["rv_select"].value == "joint"
    assert ex.query()["rv_select"] == "joint" and ex.result.voting.costs  # plain RV's candidates
    _names_its_preset(ex, "with_plain_rv")
    adv.w_reset.clicks += 1
    assert ex.wait(120) and ex.result.params == laav.LaavParams()


def _names_its_preset(ex, constructor: str) -> None:
    """The preset button just clicked names the preset as the status line (and the What
    changed line) then says it, ``preset = with-plain-rv`` (the button said "Preset: ours +
    plain RV"), and its tooltip names the constructor."""
    button = ex.advanced.w_presets[constructor]
    said = re.search(r"preset = ([\w-]+)", _shown(ex.status))
    assert said, ex.status.object
    name = said.group(1)
    assert laav.params.PRESETS[name] == getattr(laav.LaavParams, constructor)
    assert f"preset = {name}" in button.label, button.label
    assert re.search(rf"preset \S+ → {re.escape(name)}\b", _shown(ex.change_md))
    assert f"LaavParams.{constructor}()" in button.description


def _ring(ex, k):
    return np.c_[ex.compare.src_changed[k].data["x"], ex.compare.src_changed[k].data["y"]]


def test_pin_a_and_compare_with_the_live_b(ex, seq):
    cmp = ex.compare
    assert not cmp.inner.visible and cmp.pinned is None
    assert cmp.pin()
    assert ex.wait(60)
    a = ex.result
    assert cmp.pinned.result is a and cmp.inner.visible and not cmp.w_unpin.disabled
    assert "none (B has A's settings)" in cmp.table.object
    # another λ and RV cap: the table shows both and the difference
    ex.w_params["lam"].value = 5.0
    ex.w_params["rv_max_iter"].value = 10
    assert ex.wait(120, plain_rv=True)
    b = ex.result
    assert cmp.pinned.result is a and b is not a  # the pin survives the change
    text = _shown(cmp.table)
    assert "lam: 2 → 5; rv_max_iter: 150 → 10" in text
    na, nb = V.stage_numbers(seq, a), V.stage_numbers(seq, b, ex.state.plain_rv())
    assert f"| final | {100 * na['error_final']:.2f} % | {100 * nb['error_final']:.2f} % |" in text
    assert f"| coarse | {100 * na['error_coarse']:.2f} % | {100 * nb['error_coarse']:.2f} % |" in text
    assert "| plain RV | " in text and f"{100 * nb['error_plain']:.2f} %" in text
    moved = np.flatnonzero(V.align_labels(b.labels, a.labels) != a.labels)
    assert cmp.comparison.changed.tolist() == moved.tolist()
    assert f"{moved.size} of {seq.n_points}" in text
    # same frame and same colouring as the frame view; the rings on the points that moved
    ex.w_frame.value = 3
    ex.w_color.value = "coarse (atoms merged)"
    for k, res in (("A", a), ("B", b)):
        style = V.point_style(seq, res, "coarse")
        src = V.points_source(seq, 3, style)
        assert np.allclose(cmp.src[k].data["x"], src["x"]) and list(cmp.src[k].data["color"]) == list(
            src["color"])
        assert np.allclose(_ring(ex, k), seq.points[3, moved].reshape(-1, 2))
    assert "frame 3" in cmp.fig_a.title.text and "frame 3" in cmp.fig_b.title.text
    assert ex.query()["lam"] == "5"
    # unpin clears it
    cmp.w_unpin.clicks += 1
    assert cmp.pinned is None and not cmp.inner.visible and cmp.w_unpin.disabled


def test_loading_another_sequence_unpins_with_a_message(ex, tmp_path):
    cmp = ex.compare
    assert cmp.pin()
    assert ex.wait(60) and cmp.inner.visible
    other = two_motion_sequence(2, P=100, F=9, name="<b>other</b>")
    path = laav.save_sequence(other, tmp_path / "other.npz")
    assert ex.load_bytes(path.read_bytes(), "other.npz")
    assert ex.wait(120)
    assert ex.sequence.name == "<b>other</b>"
    assert cmp.pinned is None and not cmp.inner.visible
    assert "A was unpinned" in _shown(cmp.pin_md) and "advanced_test" in _shown(cmp.pin_md)
    assert ex.note.visible and "A was unpinned: it belonged to advanced_test" in _shown(ex.note)
    assert re.search(r"(?<!\\)<", ex.note.object) is None  # the new name as text
    # and pins on the new one
    assert cmp.pin()
    assert ex.wait(60) and cmp.inner.visible and cmp.pinned.sequence is ex.sequence
    # another file of the same name: the message does not name one sequence twice
    same = two_motion_sequence(3, P=100, F=9, name="<b>other</b>")
    path = laav.save_sequence(same, tmp_path / "same.npz")
    assert ex.load_bytes(path.read_bytes(), "same.npz")
    assert ex.wait(120) and cmp.pinned is None
    assert "A was unpinned: it belonged to <b>other</b> (other.npz), and <b>other</b> (same.npz) " \
        "is shown now" in _shown(ex.note)


def test_the_tour_hides_the_compare_card_and_brings_it_back(ex):
    cmp = ex.compare
    assert cmp.pin()
    assert ex.wait(60) and cmp.inner.visible and cmp.card.visible
    ex.tour.start()
    assert not cmp.card.visible  # no tour step shows it
    ex.tour.end()
    assert cmp.card.visible and cmp.inner.visible and cmp.pinned is not None


def test_nothing_to_pin_before_the_first_result(seq):
    e = Explorer(seq, viser=False, start=False)
    try:
        assert not e.compare.pin() and e.compare.pinned is None and not e.compare.inner.visible
        assert "Nothing to pin yet" in e.compare.pin_md.object
    finally:
        e.close()


def test_the_folded_card_makes_its_fields_when_first_opened_with_the_settings_then(ex):
    """The ~30 fields are made at the first opening (a sixth of building the explorer), and
    then hold what the sliders and the URL changed while folded, marked."""
    adv = ex.advanced
    assert adv._widgets is None and adv.card.objects == []
    ex.controls.w_params["r1"].value = 25.0
    assert ex.wait(120) and ex.result.params.r1 == 25.0
    assert adv._widgets is None  # still folded: nothing made
    assert "r1" in adv.summary.object  # the count of fields off their defaults is kept
    adv.card.collapsed = False
    assert adv._widgets is not None and adv.card.objects == adv.body
    assert adv.widgets["r1"].value == 25.0 and adv.marked == ["r1"]
    assert adv.widgets["r1"].label == f"{MARK} r1 · default {laav.LaavParams.r1:g}"
    adv.widgets["lam"].value = 3.5  # and the made fields ask for changes as before
    assert ex.wait(120) and ex.result.params.lam == 3.5
