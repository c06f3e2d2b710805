"""The explorer's GUI-free parts: colours, what changed between results, the page URL state.

No browser and no panel server: pure functions of results (``explorer.views``) and the
session state (``explorer.state``).
"""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

import laav
from explorer import views as V
from explorer.demo import demo_sequence
from laav.synthetic import make_sequence

# Machado, Oliveira & Fernandes (2009), deuteranopia at severity 1.0, on linear RGB
DEUTERANOPIA = np.array([[0.367322, 0.860646, -0.227968],
                         [0.280085, 0.672501, 0.047413],
                         [-0.011820, 0.042940, 0.968881]])
#: CIE76 ΔE every pair must exceed (about 10 just-noticeable differences; "clearly different")
MIN_DELTA_E = 20.0


def _linear(hex_colors) -> np.ndarray:
    c = V.hex_to_rgb(hex_colors).astype(float) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _lab(linear_rgb: np.ndarray) -> np.ndarray:
    """Linear sRGB -> CIE L*a*b* (D65)."""
    m = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]])
    xyz = linear_rgb @ m.T / np.array([0.95047, 1.0, 1.08883])
    d = 6 / 29
    f = np.where(xyz > d ** 3, np.cbrt(xyz), xyz / (3 * d ** 2) + 4 / 29)
    return np.stack([116 * f[:, 1] - 16, 500 * (f[:, 0] - f[:, 1]), 200 * (f[:, 1] - f[:, 2])], axis=1)


def _lab_deuteranope(hex_colors) -> np.ndarray:
    return _lab(np.clip(_linear(hex_colors) @ DEUTERANOPIA.T, 0, 1))


def test_simulation_is_the_standard_one():
    # white and black stay; pure red and pure green become nearly the same colour
    lab = _lab_deuteranope(["#FFFFFF", "#000000", "#FF0000", "#00FF00"])
    assert lab[0, 0] == pytest.approx(100, abs=0.5) and lab[1, 0] == pytest.approx(0, abs=0.5)
    normal = _lab(_linear(["#FF0000", "#00FF00"]))
    assert np.linalg.norm(normal[0] - normal[1]) > 150
    # the old red error ring on the old green motion: 170 apart normally, far less for a deuteranope
    old = _lab_deuteranope(["#d62728", "#2ca02c"])
    assert np.linalg.norm(old[0] - old[1]) < 40


def test_motion_colours_and_error_marks_stay_apart_under_deuteranopia():
    lab = _lab_deuteranope(V.MOTION_COLORS)
    pairs = {(a, b): float(np.linalg.norm(lab[i] - lab[j]))
             for (i, a), (j, b) in itertools.combinations(enumerate(V.MOTION_COLORS), 2)}
    assert min(pairs.values()) > MIN_DELTA_E, pairs
    err = _lab_deuteranope([V.ERROR_MARK])[0]
    to_err = {c: float(np.linalg.norm(err - lab[i])) for i, c in enumerate(V.MOTION_COLORS)}
    assert min(to_err.values()) > MIN_DELTA_E, to_err
    # the differences colouring's orange stays apart from the others' grey and the black rings
    diff = _lab_deuteranope([V.DIFFERS_MARK, V.CORRECT, V.ERROR_MARK])
    assert min(np.linalg.norm(diff[0] - diff[1]), np.linalg.norm(diff[0] - diff[2])) > MIN_DELTA_E
    # and with normal vision
    norm = _lab(_linear(list(V.MOTION_COLORS) + [V.ERROR_MARK]))
    for i, j in itertools.combinations(range(len(norm)), 2):
        assert np.linalg.norm(norm[i] - norm[j]) > MIN_DELTA_E
    # motion colours are Okabe-Ito colours; atoms never borrow one
    okabe_ito = {"#E69F00", "#56B4E9", "#009E73", "#F0E442", "#0072B2", "#D55E00", "#CC79A7", "#000000"}
    assert set(V.MOTION_COLORS) <= okabe_ito
    assert not set(V.ATOM_COLORS) & set(V.MOTION_COLORS)
    # ... nor a grey, the colour of the points in no atom in the same view
    rgb = V.hex_to_rgb(list(V.ATOM_COLORS)).astype(float)
    assert (rgb.max(axis=1) - rgb.min(axis=1)).min() > 40, V.ATOM_COLORS
    # one marker shape per motion, and (colour, shape) unique for many more motions than C ever is
    assert len(set(V.MOTION_MARKERS)) == len(V.MOTION_MARKERS)
    combos = {(V.motion_color(m), V.motion_marker(m)) for m in range(30)}
    assert len(combos) == 30


@pytest.fixture(scope="module")
def demo():
    seq = demo_sequence()
    return seq, laav.Pipeline(seq, 3).result


def test_every_view_gives_a_motion_one_colour_and_shape(demo):
    seq, res = demo
    gt = V.point_style(seq, res, "gt")
    for m in range(3):
        sel = seq.labels == m
        assert set(gt["color"][sel].tolist()) == {V.motion_color(m)}
        assert set(gt["marker"][sel].tolist()) == {V.motion_marker(m)}
    final = V.point_style(seq, res, "final")
    fl = V.align_labels(res.labels, seq.labels)
    for m in np.unique(fl).tolist():
        assert set(final["color"][fl == m].tolist()) == {V.motion_color(m)}
        assert set(final["marker"][fl == m].tolist()) == {V.motion_marker(m)}
    fs = V.frame_sources(seq, res, 3, final)
    assert len(fs["points"]["marker"]) == seq.n_points


def test_the_atoms_colouring_has_one_legend_entry_for_its_points(demo):
    # the points in no atom have the × mark's own entry ("in no atom: N"); a second entry
    # for their grey fill said the same thing twice (tour step 1's legend)
    seq, res = demo
    st = V.point_style(seq, res, "atoms")
    assert len(set(st["label"].tolist())) == 1
    unassigned = np.asarray(res.atoms.unassigned)
    assert unassigned.size and set(st["color"][unassigned].tolist()) == {V.UNLABELLED}


def test_fine_models_are_shades_of_the_motion_they_joined(demo):
    seq, res = demo
    mot = V.fine_motions(seq, res)
    fc = V.fine_colors(seq, res)
    assert mot.size == fc.size == res.multicut.n_models
    for m in np.unique(mot).tolist():
        shades = fc[mot == m].tolist()
        assert len(set(shades)) == len(shades), "two fine models of one motion look the same"
        assert shades[0] == V.motion_color(m)  # the first is the motion's own colour
        allowed = {V.shade(V.motion_color(m), t) for t in V.FINE_SHADES}
        assert set(shades) <= allowed
    # the merge table / Z axis name the same motion the colours say
    _, factors = V.z_sources(res, seq)
    assert [int(f.split("→M")[1]) - 1 for f in factors] == mot.tolist()
    # points coloured by fine model: colour of their model, marker of its motion
    st = V.point_style(seq, res, "fine")
    lab = np.asarray(res.coarse.fine_point_labels)
    ok = lab >= 0
    assert np.array_equal(st["color"][ok], fc[lab[ok]])
    assert [V.motion_marker(m) for m in mot[lab[ok]]] == st["marker"][ok].tolist()
    assert set(st["color"][~ok].tolist()) <= {V.UNLABELLED}
    # the graph's atoms at the final step: the colour of their fine model
    g = V.graph_sources(res, 0, len(res.multicut.contractions) + 1, fc)
    assert np.array_equal(g["nodes"]["color"], fc[np.asarray(res.multicut.atom_labels)])
    # the epipolar panel: its two models in their colours
    e = V.epipolar_sources(seq, res, 0, 1)
    assert set(e["left"]["color"].tolist()) <= {fc[0], fc[1]}


# ---------------------------------------------------------------------------- what changed
def test_describe_change_counts_points_that_changed_motion(demo):
    import dataclasses

    from explorer.state import Settings, describe_change

    seq, res = demo
    s0 = Settings(laav.LaavParams(), 0, 3)
    s1 = Settings(laav.LaavParams(r1=21.0), 0, 3)
    # a renaming of the motions moves nothing
    renamed = dataclasses.replace(res, labels=(np.asarray(res.labels) + 1) % 3)
    ch = describe_change(seq, res, s0, renamed, s1)
    assert ch.moved.size == 0
    assert ch.settings == (("R1", 20.0, 21.0),)
    # three points put in another motion: exactly those are reported
    moved = np.array([5, 77, 300])
    lab = np.asarray(res.labels).copy()
    lab[moved] = (lab[moved] + 1) % 3
    after = dataclasses.replace(res, labels=lab)
    ch = describe_change(seq, res, s0, after, s1)
    assert ch.moved.tolist() == moved.tolist()
    final_before = laav.misclassification_rate(seq.labels, res.labels)
    final_after = laav.misclassification_rate(seq.labels, lab)
    stages = dict((st, (a, b)) for st, a, b in ch.errors)
    assert stages["final"] == pytest.approx((final_before, final_after))
    assert stages["coarse"][0] == stages["coarse"][1]  # the coarse stage is the same result
    coarse = 100 * stages["coarse"][0]
    assert ch.text() == (f"R1 20 → 21: coarse {coarse:.1f} → {coarse:.1f} %, final "
                         f"{100 * final_before:.1f} → {100 * final_after:.1f} %, 3 points changed motion")
    # seed, C and fine models are settings too; no ground truth: no errors
    bare = laav.Sequence(seq.points, None, name="bare")
    ch = describe_change(bare, res, s0, after, Settings(laav.LaavParams(), 4, 3))
    assert ch.errors == () and ch.text() == "seed 0 → 4: 3 points changed motion"
    # a preset chosen: said by its name, with what else moved, not its 14 settings
    ch = describe_change(bare, res, s0, after, Settings(laav.LaavParams.paper(r1=25.0), 0, 3))
    assert ch.settings == (("preset", "default", "paper"), ("R1", 20.0, 25.0))
    assert ch.text() == "preset default → paper, R1 20 → 25: 3 points changed motion"
    back = describe_change(bare, res, Settings(laav.LaavParams.paper(), 0, 3), after, s0)
    assert back.settings == (("preset", "paper", "default"),)
    # within a preset, its fields as usual
    ch = describe_change(bare, res, Settings(laav.LaavParams.paper(), 0, 3), after,
                         Settings(laav.LaavParams.paper(lam=3.0), 0, 3))
    assert ch.settings == (("λ", laav.LaavParams.paper().lam, 3.0),)


def test_non_defaults_names_every_changed_setting():
    from explorer.state import Settings, non_defaults

    P = laav.LaavParams
    assert non_defaults(Settings(P(), 0, 3), 3) == []
    assert non_defaults(Settings(P(r1=25.0), 3, 3), 3) == ["R1 = 25", "seed = 3"]
    got = non_defaults(Settings(P(rv_alpha=0.8, rv_max_iter=90, coarse_frames=5, rv_refine=False,
                                  rv_select="none", fine_models=6), 0, 2), 3)
    assert got == ["fine models = 6", "coarse_frames = 5", "α = 0.8", "iteration cap = 90", "rv_refine = off",
                   "rv_select = none", "C = 2"]
    # the fine models follow C: C = 2 with fine_models unset is 2C = 4, not a change of its own
    assert non_defaults(Settings(P(), 0, 2), 3) == ["C = 2"]
    assert non_defaults(Settings(P(), 0, 2), None) == []  # no ground truth: C is the user's
    # a preset by its name, then what differs from it (not its 13 fields and the fine models)
    assert non_defaults(Settings(P.paper(), 0, 3), 3) == ["preset = paper"]
    assert non_defaults(Settings(P.paper(r1=25.0), 2, 3), 3) == ["preset = paper", "R1 = 25", "seed = 2"]
    assert non_defaults(Settings(P.with_plain_rv(), 0, 3), 3) == ["preset = with-plain-rv"]
    # one field of the paper's is a change of the defaults, not the paper preset
    assert non_defaults(Settings(P(atom_frames="pair"), 0, 3), 3) == ["atom_frames = pair"]


def test_frame_view_rings_the_points_given_as_moved(demo):
    seq, res = demo
    st = V.point_style(seq, res, "final")
    d = V.frame_sources(seq, res, 4, st, moved=np.array([5, 77]))
    assert np.allclose(np.c_[d["changed"]["x"], d["changed"]["y"]], seq.points[4, [5, 77]])
    assert len(V.frame_sources(seq, res, 4, st)["changed"]["x"]) == 0


# ---------------------------------------------------------------------------- URL and params.json
def test_url_query_round_trip_and_validation(demo):
    from explorer.state import URL_KEYS, Settings, parse_settings, query_of

    seq, _ = demo
    base = Settings(laav.LaavParams(), 0, 3)
    assert set(URL_KEYS) == {f.name for f in __import__("dataclasses").fields(laav.LaavParams)} | {
        "seed", "motions", "frame", "color", "tour", "sequence"}
    s, view, problems = parse_settings({"r1": "25", "seed": ["3"], "frame": "4", "color": "final",
                                        "rv_refine": "off", "fine_models": "8", "lam": b"3.5"}, seq, base)
    assert problems == []
    assert (s.params.r1, s.params.lam, s.params.rv_refine, s.params.fine_models, s.seed, s.n_motions) == (
        25.0, 3.5, False, 8, 3, 3)
    assert view == {"frame": 4, "color": "final"}
    q = query_of(s, 3, view["frame"], view["color"], "gt")
    assert q == {"r1": "25", "fine_models": "8", "lam": "3.5", "rv_refine": "false", "seed": "3",
                 "frame": "4", "color": "final"}
    assert parse_settings(q, seq, base) == (s, view, [])
    assert query_of(base, 3, 0, "gt", "gt") == {}  # the defaults: a bare address
    assert query_of(base, None) == {"motions": "3"}  # no ground truth: C is part of the state
    odd = Settings(laav.LaavParams(lam=1 / 3), 0, 3)
    assert parse_settings(query_of(odd, 3), seq, base)[0] == odd  # every digit kept
    # every preset's address restores it: fields whose default is None but that take an
    # integer (fine_per_motion), and an integer field set to none (rv_max_points), included
    for preset in (laav.LaavParams.paper(), laav.LaavParams.own_chain(),
                   laav.LaavParams(fine_per_motion=4, rv_max_points=None)):
        s = Settings(preset, 2, 3)
        got, _, problems = parse_settings(query_of(s, 3), seq, base)
        assert problems == [] and got == s, problems
    # "auto" means auto for the fine-model counts only: it never lifts the voting's point cap
    got, _, problems = parse_settings({"fine_per_motion": "auto", "rv_max_points": "auto"}, seq, base)
    assert got.params.fine_per_motion is None and got.params.rv_max_points == 1000
    assert problems == ["rv_max_points must be a whole number or none, got 'auto'"], problems
    # bad values: a readable message each, everything else applied, never an exception
    s, view, problems = parse_settings(
        {"r1": "abc", "r2": "10", "seed": "-1", "motions": "9999", "frame": "30", "color": "<b>x</b>",
         "nonsense": "1", "lam": "4", "rv_max_iter": "1.5"}, seq, base)
    assert s.params.lam == 4.0 and s.params.r1 == 20.0 and s.params.r2 == 40.0 and s.seed == 0
    assert s.n_motions == 3 and view == {}
    text = " | ".join(problems)
    for part in ("r1 must be a number, got 'abc'", "r2 must be larger than r1", "seed must be between 0",
                 "motions (C) must be between 1 and 350", "frame must be between 0 and 29",
                 "color must be one of", "'<b>x</b>'", "unknown setting 'nonsense'",
                 "rv_max_iter must be a whole number, got '1.5'"):
        assert part in text, (part, problems)
    # a C the points cannot hold, 8 points a motion (the 8-point algorithm): refused at once
    # (C = 99 on the demo's 350 points took 35 s, to a labelling laav calls meaningless)
    s, _, problems = parse_settings({"motions": "99"}, seq, base)
    assert s.n_motions == 3 and len(problems) == 1 and "allow at most 43" in problems[0], problems
    s, _, problems = parse_settings({"motions": "43"}, seq, base)
    assert s.n_motions == 43 and problems == []
    # an address made on another sequence (opened in that page): its other settings apply
    # here, its C does not (as a params.json's), and the page says which sequence it was
    assert query_of(base, 3, sequence="up") == {"sequence": "up"}
    s, _, problems = parse_settings({"sequence": "up", "motions": "2", "r1": "25"}, seq, base)
    assert (s.params.r1, s.n_motions) == (25.0, 3) and len(problems) == 2, problems
    text = " | ".join(problems)
    assert "made on the sequence 'up'" in text and "the upload box" in text and "C stays 3" in text
    s, _, problems = parse_settings({"sequence": seq.name, "motions": "2"}, seq, base)
    assert s.n_motions == 2 and problems == []


def test_params_json_loads_back(demo):
    from explorer import export
    from explorer.state import Settings, settings_from_json

    seq, res = demo
    p = res.params.replace(r1=23.0, rv_alpha=0.8, coarse_frames=5)
    shown = __import__("dataclasses").replace(res, params=p, seed=4, n_motions=2)
    text = export.params_json(seq, shown)
    got = settings_from_json(text, seq, Settings(laav.LaavParams(), 0, 3))
    assert got == Settings(p, 4, 2)
    assert settings_from_json(b'{"lam": 3}', seq, got).params == laav.LaavParams(lam=3.0)  # bare object
    for bad, msg in ((b"\x00\x01", "not a JSON file"), (b"[1]", "one JSON object"),
                     (b'{"params": {"r9": 1}}', "unknown LAAV parameter(s): r9"),
                     (b'{"params": {"r1": "x"}}', "r1 must be a number"),
                     (b'{"params": {}, "n_motions": 999}', "more than the 350 points"),
                     (b'{"params": {}, "seed": -2}', "seed must be")):
        with pytest.raises(ValueError, match=__import__("re").escape(msg)):
            settings_from_json(bad, seq, got)


# ---------------------------------------------------------------------------- errors at every stage
def test_errors_at_every_stage(demo):
    seq, res = demo
    plain = laav.random_voting(seq, 3, res.params, 0)
    num = V.stage_numbers(seq, res, plain)
    for stage in ("fine", "coarse", "final", "plain"):
        wrong, scored = V.stage_errors(seq, res, stage, plain)
        assert not (wrong & ~scored).any()
        assert wrong.sum() / scored.sum() == pytest.approx(num[f"error_{stage}"]), stage
    assert num["error_plain"] == pytest.approx(laav.misclassification_rate(seq.labels, plain.labels))
    # the demo's coarse stage is wrong on some points: colouring by it rings exactly those
    st = V.point_style(seq, res, "coarse", plain)
    assert st["stage"] == "coarse" and st["misclassified"].sum() > 0
    assert np.array_equal(st["misclassified"], V.stage_errors(seq, res, "coarse")[0])
    assert num["error_coarse"] > 0
    # each "errors" mode paints its own stage's mistakes black
    for mode, stage in (("errors_fine", "fine"), ("errors_coarse", "coarse"), ("errors", "final"),
                        ("errors_plain", "plain")):
        st = V.point_style(seq, res, mode, plain)
        wrong = V.stage_errors(seq, res, stage, plain)[0]
        assert np.array_equal(st["color"] == V.ERROR_MARK, wrong), mode
    # plain RV labels in motion colours; before plain RV exists: the final labels and a note
    st = V.point_style(seq, res, "plain", plain)
    pl = V.align_labels(plain.labels, seq.labels)
    assert st["color"].tolist() == [V.motion_color(m) for m in pl.tolist()]
    assert "still computing" in V.point_style(seq, res, "plain", None)["note"]
    # the numbers card has plain RV's error beside LAAV's
    md = V.numbers_markdown(num)
    assert "*plain RV*" in md and f"{100 * num['error_plain']:.1f} %" in md
    assert "computing…" in V.numbers_markdown(V.stage_numbers(seq, res))


# ---------------------------------------------------------------------------- GAEC replay
def test_gaec_replay_keeps_colours_and_rings_the_joined_pair(demo):
    seq, res = demo
    fc = V.fine_colors(seq, res)
    K = len(res.multicut.contractions)
    assert K > 3
    prev = V.graph_sources(res, 0, 0, fc)
    assert len(prev["pair"]["x"]) == 0
    for step in range(1, K + 1):
        g = V.graph_sources(res, 0, step, fc)
        kept, merged = np.asarray(res.multicut.contractions[step - 1]).tolist()
        roots = V.replay_roots(res, step - 1)
        moved = roots == roots[merged]  # the cluster that was joined into kept's
        changed = g["nodes"]["color"] != prev["nodes"]["color"]
        assert not (changed & ~moved).any(), f"step {step} recoloured atoms outside the merged cluster"
        assert (g["nodes"]["color"][moved] == g["nodes"]["color"][kept]).all()
        assert g["pair"]["atom"].tolist() == [kept, merged]
        assert np.allclose(g["pair"]["x"], g["nodes"]["x"][[kept, merged]])
        assert (g["pair"]["size"] > g["nodes"]["size"][[kept, merged]]).all()  # ring around the node
        # the pair's ids are written with it (beside its rings), not under them
        assert g["pair"]["text"].tolist() == [str(kept), str(merged)]
        assert g["nodes"]["label"][kept] == g["nodes"]["label"][merged] == ""
        prev = g
    # without a plot scale every other id is written, right of its node
    assert [t for i, t in enumerate(g["nodes"]["label"]) if i not in (kept, merged)] == [
        str(i) for i in range(res.graph.n_nodes) if i not in (kept, merged)]
    assert (g["nodes"]["dx"] > 0).all() and set(g["nodes"]["align"]) == {"left"}
    final = V.graph_sources(res, 0, K + 1, fc)
    assert len(final["pair"]["x"]) == 0
    assert np.array_equal(final["nodes"]["color"], fc[np.asarray(res.multicut.atom_labels)])


def _id_boxes_drawn(g: dict, scale) -> tuple[list, list]:
    """The boxes (px; left, top, right, bottom) of the ids a graph view writes at a frame
    (its nodes' and its pair's), as the page draws them: a text's start at its x offset
    (``align`` left) or its end (right), vertically centred; and the nodes' middles."""
    sx, sy = scale
    boxes = []
    for src, font in ((g["nodes"], V.ID_FONT_PX), (g["pair"], V.PAIR_ID_FONT_PX)):
        text = src["label"] if "label" in src else src["text"]
        for t, x, y, dx, al in zip(text, src["x"], src["y"], src["dx"], src["align"]):
            if not t:
                continue
            w = len(t) * 0.556 * font
            x0 = x * sx + dx - (w if al == "right" else 0)
            boxes.append((x0, y * sy - font / 2, x0 + w, y * sy + font / 2))
    n = g["nodes"]
    r = V.ID_CLEAR * np.asarray(n["size"]) / 2
    middles = [(x * sx - q, y * sy - q, x * sx + q, y * sy + q) for x, y, q in zip(n["x"], n["y"], r)]
    return boxes, middles


def _overlap(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def test_atom_ids_are_written_only_where_they_overlap_nothing(demo):
    """Card 2's atom ids at a plot's size (px per data unit): in every frame no two written
    ids overlap and none covers a node's middle (cars2B's dense clusters overprinted them
    into blots), each on its node's right or else its left; the ids of the pair joined at a
    replay step are always written, beside its rings, on the sides facing away from each
    other; the larger atoms' ids come first; a layout kept across steps gives the same."""
    seq, res = demo
    n, K = res.graph.n_nodes, len(res.multicut.contractions)
    x0, x1, _, _ = V.view_extent(seq.extent())
    for px in (390, 200):  # the card's plot, and one half as wide (denser)
        scale = (px / (x1 - x0),) * 2
        layout = V.id_layout(res, scale)
        for step in (K + 1, 1, K // 2):
            tpl = V.graph_templates(res, step, None, scale)
            assert V.graph_templates(res, step, None, layout=layout)["nodes"]["label"].tolist() == \
                tpl["nodes"]["label"].tolist()
            written = [t for t in tpl["nodes"]["label"] if t]
            assert 0 < len(written) < n - (2 if step <= K else 0), (px, step)  # (the test can fail)
            if step <= K:
                kept, merged = np.asarray(res.multicut.contractions[step - 1]).tolist()
                assert tpl["pair"]["text"].tolist() == [str(kept), str(merged)]
                sides = np.sign(tpl["pair"]["dx"])
                assert sides[0] != sides[1]
            for f in (0, seq.n_frames // 2, seq.n_frames - 1):
                g = V.graph_sources(res, f, step, None, scale)
                ids, middles = _id_boxes_drawn(g, scale)
                for i, j in itertools.combinations(range(len(ids)), 2):
                    assert not _overlap(ids[i], ids[j]), (px, step, f, i, j)
                for b in ids[:len(ids) - len(g["pair"]["text"])]:  # (the pair's: whatever they cover)
                    assert not any(_overlap(b, m) for m in middles), (px, step, f, b)
        # the larger atoms first: the largest atom's id is written at the final step
        tpl = V.graph_templates(res, K + 1, None, scale)
        sizes = [len(m) for m in res.atoms.members]
        assert tpl["nodes"]["label"][int(np.argmax(sizes))] != ""
    # a place on the left is taken where the right one is not free
    wide = V.graph_templates(res, K + 1, None, (390 / (x1 - x0),) * 2)
    assert "right" in set(wide["nodes"]["align"][wide["nodes"]["label"] != ""])
    # two labels clash only where both atoms are drawn and their boxes meet
    # (boxes 8 px wide, 2 px of gap: 1 is 9 px right of 0 in frame 0, and not drawn in frame 1,
    # where 2 comes 5 px right of 0; 11 px apart, 1 and 0 would not clash)
    xy = np.array([[[0.0, 0.0], [9.0, 0.0], [100.0, 0.0]], [[0.0, 0.0], [np.nan, np.nan], [5.0, 0.0]]])
    box = [[0, -5, 8, 5]] * 3
    clash = V.label_clashes(xy, None, (1.0, 1.0), [0, 1, 2], box, [0, 1, 2], box)
    assert clash[0, 1] and clash[0, 2] and not clash[1, 2]
    assert not V.label_clashes(xy + [[[0, 0], [2, 0], [0, 0]]], None, (1.0, 1.0), [0], box[:1], [1],
                               box[:1]).any()
    seen = np.array([[True, True, True], [True, True, False]])
    assert not V.label_clashes(xy, seen, (1.0, 1.0), [0], box[:1], [2], box[:1]).any()


def test_rv_summary_reads_only_public_fields_and_any_selected_name(demo):
    import dataclasses

    seq, res = demo
    v = res.voting
    for selected, costs in (("informed", {"informed": 1.0, "plain": 2.0}),
                            ("something new", {"a": 1.0, "b": 0.5}),  # not among the scored
                            ("<b>x</b>", {"<b>x</b>": 0.1, "y": 0.2, "z": 0.3, "w": 0.4}),
                            ("", {}), ("only", {"only": 3.0})):
        w = dataclasses.replace(v, selected=selected, costs=costs)
        text = V.rv_summary(w, None)
        assert "LAAV fine-tuning" in text
        if len(costs) >= 2:
            assert V.md_text(selected or "(unnamed)") in text
        assert "<b>" not in text
    assert "lowest" not in V.rv_summary(dataclasses.replace(v, selected="a", costs={"a": 2.0, "b": 1.0,
                                                                                       "c": 3.0, "d": 4.0}),
                                        None)
    # the RV card names what the selection scored by, as the result says
    four = {"a": 2.0, "b": 1.0, "c": 3.0}
    assert "coding length + epipolar cost" in V.rv_summary(
        dataclasses.replace(v, selected="b", costs=four, score="joint"), None)
    # ... with its unit: whole labellings in nats (the default's own candidates), else per point
    pair = {"a": 2.0, "b": 1.0}
    assert "(score 1.00 per point); other candidates: a 2.00 per point" in V.rv_summary(
        dataclasses.replace(v, selected="b", costs=pair, score="joint"), None)
    assert "(score 1.00 nats); other candidates: a 2.00 nats;" in V.rv_summary(
        dataclasses.replace(v, selected="b", costs=pair, score="joint-sum"), None)
    old = V.rv_summary(dataclasses.replace(v, selected="b", costs=four, score="subspace"), None)
    assert "trajectory-subspace cost" in old and "coding length" not in old
    assert "scored by" not in V.rv_summary(dataclasses.replace(v, selected="b", costs=four, score=""),
                                           None)


def test_3d_view_gets_linear_colours_so_it_shows_the_2d_ones():
    pytest.importorskip("viser")
    from explorer.viser_view import _for_webgl

    rgb = V.hex_to_rgb(["#FFFFFF", "#000000", "#808080", V.MOTION_COLORS[0]])
    lin = _for_webgl(rgb)
    assert lin[0].tolist() == [255, 255, 255] and lin[1].tolist() == [0, 0, 0]
    assert lin[2].tolist() == [55, 55, 55]  # sRGB 128 is 21.6 % linear light
    # three.js encodes linear -> sRGB for the screen: that gives the 2-D colour back
    back = np.where(lin / 255 <= 0.0031308, 12.92 * lin / 255, 1.055 * (lin / 255) ** (1 / 2.4) - 0.055)
    assert np.abs(back * 255 - rgb).max() <= 6


def test_merge_table_has_a_true_motion_column(demo):
    seq, res = demo
    md = V.merge_table(seq, res)
    lines = md.splitlines()
    assert lines[0].endswith("| true motion |") and len(lines) == 2 + res.multicut.n_models
    fine = np.asarray(res.coarse.fine_point_labels)
    mot = V.fine_motions(seq, res)
    for j, line in enumerate(lines[2:]):
        sel = fine == j
        m = int(np.bincount(seq.labels[sel]).argmax())
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[3] == f"motion {mot[j] + 1}"
        assert cells[4].startswith(f"motion {m + 1} (") and cells[4].endswith("✗") == (m != mot[j])
    bare = laav.Sequence(seq.points, None, name="bare")
    assert "true motion" not in V.merge_table(bare, res)


def test_shortlist_table_lists_the_joint_merge_partitions(demo):
    seq, _ = demo
    res = laav.segment(seq, seq.n_motions, laav.LaavParams(coarse_merge="joint", fine_per_motion=4),
                       seed=0)
    sl = res.coarse.shortlist
    md = V.shortlist_table(seq, res, rows=3)
    lines = md.splitlines()
    assert "coding length" in lines[0] and "error on atom points" in lines[0]
    assert len(lines) == 2 + min(3, sl.assign.shape[0])
    assert lines[2].count("← chosen") == 1  # the best score comes first
    chosen = np.asarray(sl.assign[sl.chosen])
    fine = np.asarray(res.coarse.fine_point_labels)
    cov = fine >= 0
    err = laav.misclassification_rate(seq.labels[cov], chosen[fine[cov]])
    assert lines[2].rstrip().endswith(f"{100 * err:.1f} % |")
    epipolar = laav.segment(seq, seq.n_motions, laav.LaavParams(coarse_merge="epipolar"), seed=0)
    assert V.shortlist_table(seq, epipolar) == ""  # the epipolar merge has no shortlist


def test_url_carries_the_tour_step(demo):
    from explorer.state import Settings, parse_settings, query_of
    from explorer.tour import TOUR

    seq, _ = demo
    base = Settings(laav.LaavParams(), 0, 3)
    assert query_of(base, 3, tour=2) == {"tour": "3"}  # 1-based in the address
    assert parse_settings({"tour": "3"}, seq, base)[1] == {"tour": 3}
    for bad in ("0", str(len(TOUR) + 1), "x"):
        s, view, problems = parse_settings({"tour": bad}, seq, base)
        assert view == {} and len(problems) == 1 and problems[0].startswith("tour must be")


def test_z_cells_carry_their_value_only_while_it_fits(demo):
    seq, _ = demo
    res = laav.segment(seq, seq.n_motions, laav.LaavParams(coarse_merge="epipolar"), seed=0)
    assert res.multicut.n_models == 6  # 2C: every value written
    data, _ = V.z_sources(res, seq)
    assert all(t == f"{z:.2f}" for t, z in zip(data["text"], data["z"]))
    many = laav.segment(seq, seq.n_motions, laav.LaavParams(coarse_merge="joint", fine_per_motion=4),
                        seed=0)
    assert many.multicut.n_models > V.Z_TEXT_MAX
    data, _ = V.z_sources(many, seq)
    assert not any(data["text"]) and len(data["z"]) == many.multicut.n_models ** 2  # hover only


def test_margin_bar_ends_at_a_labelled_tick_past_every_value():
    """The margin map's colour range ends at 10, 100, 1000, ... nats, the first that no value
    passes, with a label there (it ended at the largest value: ±991 nats on cars1, its last
    label ±100)."""
    for big in (0.0, 3.0, 10.0, 11.0, 991.0, 1000.0, 1001.0, 5e4):
        z = V.signed_log(np.array([big, -2.0, np.nan]))
        top = V.margin_top(z)
        where, labels = V.margin_ticks(top)
        assert np.nanmax(np.abs(z)) <= top + 1e-12
        assert where[-1] == pytest.approx(top) and where[0] == pytest.approx(-top)
        assert labels[-1] == f"+{max(10, 10 ** int(np.ceil(np.log10(max(big, 1.0)))))}", (big, labels)
        assert labels[len(labels) // 2] == "0" and len(labels) % 2 == 1
    # an infinite margin (a partition no other explains) leaves the bar at the finite ones'
    assert V.margin_top(V.signed_log(np.array([np.inf, 991.0, -np.inf]))) == pytest.approx(
        V.margin_top(V.signed_log(np.array([991.0]))))


def test_margin_numbers_are_short_and_sized_to_their_cells():
    """A margin in a cell takes at most four characters, and the font is as large as the widest
    fits a cell (at most 12 px), or 0 (no numbers) below 8 px."""
    texts = [V.margin_text(m) for m in (991.0, -991.0, 0.4, -0.6, 1234.0, -9960.0, 12345.0, np.nan)]
    assert texts == ["991", "-991", "0", "-1", "1.2k", "-10k", "12k", ""]
    assert V.cell_font_px(["-991", "874", ""], 28) == 11  # cars1's 8 models in 224 px
    assert V.cell_font_px(["3"], 112) == 12  # at most 12 px
    assert V.cell_font_px(["-991"], 16) == 0  # too small to read: the hover tells it
    assert V.cell_font_px(["", ""], 10) == 12  # nothing written


def test_joint_margins_are_what_decided_each_pair(demo):
    """Card 3's map under the joint merge: for each pair of fine models, the least score of a
    compared partition splitting them minus the least joining them (checked by a plain loop
    over the shortlist); its sign is the chosen partition's decision; its parts add up; NaN
    on the diagonal and where every partition agrees. Other merges have none."""
    seq, _ = demo
    res = laav.segment(seq, seq.n_motions, laav.LaavParams(), seed=1)
    sl, w = res.coarse.shortlist, res.params.coarse_epipolar_weight
    assert res.coarse.method == "joint" and sl is not None
    m, ml, me = V.joint_margins(res)
    n = sl.assign.shape[1]
    for j in range(n):
        for k in range(n):
            join = [i for i in range(len(sl.score)) if sl.assign[i, j] == sl.assign[i, k]]
            split = [i for i in range(len(sl.score)) if sl.assign[i, j] != sl.assign[i, k]]
            if j == k or not join or not split:
                assert np.isnan(m[j, k]) and np.isnan(ml[j, k]) and np.isnan(me[j, k])
                continue
            a = min(split, key=lambda i: sl.score[i])
            b = min(join, key=lambda i: sl.score[i])
            assert m[j, k] == pytest.approx(sl.score[a] - sl.score[b])
            assert ml[j, k] == pytest.approx(sl.coding_length[a] - sl.coding_length[b])
            assert me[j, k] == pytest.approx(w * (sl.epipolar_cost[a] - sl.epipolar_cost[b]))
            chosen_joins = sl.assign[sl.chosen, j] == sl.assign[sl.chosen, k]
            assert (m[j, k] > 0) == chosen_joins
    assert np.isfinite(m).any(), "nothing contested on the demo: the test would check nothing"
    data, _ = V.z_sources(res, seq)
    np.testing.assert_allclose(data["z"], V.signed_log(m.ravel()), equal_nan=True)
    np.testing.assert_allclose(data["m"], m.ravel(), equal_nan=True)
    paper = laav.segment(seq, seq.n_motions, laav.LaavParams(coarse_merge="epipolar"), seed=0)
    assert V.joint_margins(paper) is None
    data, _ = V.z_sources(paper, seq)
    np.testing.assert_allclose(data["z"], np.ravel(paper.coarse.affinity))
    assert np.isnan(data["m"]).all()


# ---------------------------------------------------------------------------- pixel noise
def test_numbers_card_names_the_measured_noise_and_what_it_widened():
    """The noise-adaptive scales are a departure from the paper: the card says what ran."""
    clean = make_sequence(n_objects=2, n_frames=12, n_points=200, noise=0.0, rng=3)
    noisy = make_sequence(n_objects=2, n_frames=12, n_points=200, noise=1.5, rng=3)
    got = {}
    for name, seq in (("clean", clean), ("noisy", noisy)):
        res = laav.segment(seq, 2, random_state=0)
        got[name] = V.stage_numbers(seq, res)
    assert got["clean"]["noise_sigma"] < 0.1 and got["clean"]["noise_changes"] == {}
    assert "thresholds as set" in V.numbers_markdown(got["clean"])
    ch = got["noisy"]["noise_changes"]
    assert set(ch) == {"affine_threshold", "edge_scale", "lam", "rv_lambda"}
    thr_set, thr_ran = ch["affine_threshold"]
    assert thr_set == 2.0 and thr_ran == pytest.approx(3.35 * got["noisy"]["noise_sigma"], rel=0.01)
    md = V.numbers_markdown(got["noisy"])
    assert "scales widened for the noise" in md and "affine_threshold 2 →" in md
    # the paper preset measures nothing and says nothing
    res = laav.segment(noisy, 2, params=laav.LaavParams.paper(), random_state=0)
    num = V.stage_numbers(noisy, res)
    assert num["noise_sigma"] is None and "pixel noise" not in V.numbers_markdown(num)


def test_replay_caption_names_the_fine_count_and_whether_it_is_the_papers(demo):
    """The multicut caption says how many fine models the count was brought to (as a
    multiple of C) and whether that is the paper's 2C (it said 2C whatever ran)."""
    P = laav.LaavParams
    assert V.fine_count_note(P(), 2) == "4C: ours for the joint merge; the paper: 2C"
    assert V.fine_count_note(P.with_plain_rv(), 2) == "2C, the paper's"
    assert V.fine_count_note(P(), 2, complete=False) == "2C, the paper's"
    assert V.fine_count_note(P(coarse_merge="joint"), 3) == "4C: ours for the joint merge; the paper: 2C"
    assert V.fine_count_note(P(coarse_merge="joint"), 3, complete=False) == "2C, the paper's"
    assert V.fine_count_note(P(fine_per_motion=3), 2) == "3C, as set; the paper: 2C"
    assert V.fine_count_note(P(fine_models=5), 2) == "5, as set; the paper: 2C"
    seq, _ = demo
    res = laav.segment(seq, 3, P(coarse_merge="joint"), seed=0)
    final = V.replay_caption(res, len(res.multicut.contractions) + 1)
    assert f"**Final fine models:** {res.multicut.n_models} " in final and "4C: ours" in final


def test_result_notes_say_what_laav_only_warns_of():
    """The page shows no LaavWarning; a result whose motions ended empty, or in which no
    atom formed (plain RV ran), gets a note; an ordinary one none."""
    import warnings

    from explorer.views import result_notes

    seq = make_sequence(1, n_frames=10, n_points=60, rng=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", laav.LaavWarning)
        many = laav.segment(seq, 7, seed=0)
        tiny = laav.segment(seq, 2, laav.LaavParams(r1=0.5, r2=1.0), seed=0)
    used = np.unique(many.labels).size
    assert any(f"Only {used} of the 7 motions" in n for n in result_notes(many))
    assert tiny.atoms.n_atoms == 0 and any("No atom formed" in n for n in result_notes(tiny))
    assert result_notes(laav.segment(seq, 2, seed=0)) == []


def test_counts_read_as_english():
    assert (V.counted(1, "motion"), V.counted(2, "motion")) == ("1 motion", "2 motions")


def test_rv_summary_at_one_motion_says_no_trial_ran():
    """C = 1: no voting trial runs; the card said "0 iterations, converged (no label
    changed for the patience window)" for LAAV's and plain RV's run alike."""
    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=10, n_points=120, rng=0)
    res = laav.segment(seq, 1, seed=0)
    plain = laav.random_voting(seq, 1, seed=0)
    text = V.rv_summary(res.voting, plain)
    assert text.count("C = 1, every point in the one motion: nothing to vote on") == 2
    assert "converged" not in text
    two = V.rv_summary(laav.segment(seq, 2, seed=0).voting, None)
    assert "nothing to vote on" not in two and "iterations" in two


def test_rv_summary_says_whether_the_two_runs_end_at_the_same_segmentation():
    """Card 4 compares LAAV's final labels with plain RV's: the same segmentation (motions
    renamed) is said so; apart, it says that converging is not being right, with both
    errors against the ground truth (computed, not copied) or, without one, where to look.
    No verdict while LAAV's trial is a preview or plain RV is not there."""
    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=10, n_points=120, rng=0)  # two motions
    res = laav.segment(seq, 2, seed=0)
    lab = np.asarray(res.labels)
    renamed = dataclasses.replace(res.voting, labels=1 - lab)  # the same segmentation
    text = V.rv_summary(res.voting, renamed, truth=seq.labels)
    assert f"**Both end at the same segmentation**: their final labels differ on 0 of the {lab.size}" in text
    moved = lab.copy()
    moved[:30] = 1 - moved[:30]
    apart = dataclasses.replace(res.voting, labels=moved)
    e_own = laav.misclassification_rate(seq.labels, lab)
    e_plain = laav.misclassification_rate(seq.labels, moved)
    assert e_plain > 0.2 > e_own
    errors = f"against the ground truth, LAAV is {100 * e_own:.1f} % wrong, plain RV {100 * e_plain:.1f} %"
    # the run that settled is the worse one: the lesson, with both errors (plain RV settled
    # on its wrong labels, LAAV's kept trial did not)
    plain_settled = dataclasses.replace(apart, converged=True)
    text = V.rv_summary(dataclasses.replace(res.voting, converged=False), plain_settled, truth=seq.labels)
    assert f"differ on 30 of the {lab.size} points (25.0 %)" in text and "not that they are right" in text
    assert errors in text
    # ... and LAAV's kept trial settled on the wrong labels (its final labels are scored)
    wrong = dataclasses.replace(res.voting, labels=moved, converged=True)
    text = V.rv_summary(wrong, dataclasses.replace(res.voting, converged=False), truth=seq.labels)
    assert "not that they are right" in text
    assert f"LAAV is {100 * e_plain:.1f} % wrong, plain RV {100 * e_own:.1f} %" in text
    # the better run settled (or both did): the errors alone, no lesson it would contradict
    for conv in (False, True):
        text = V.rv_summary(dataclasses.replace(res.voting, converged=True),
                            dataclasses.replace(apart, converged=conv), truth=seq.labels)
        assert errors in text and "not that they are right" not in text
    bare = V.rv_summary(res.voting, apart)
    assert "against the ground truth" not in bare and "*differences: final vs plain RV*" in bare
    assert "end apart" not in V.rv_summary(res.voting, apart, pending=True)
    assert "end apart" not in V.rv_summary(res.voting, None) and "same segmentation" not in V.rv_summary(
        res.voting, None)


def test_rv_card_and_tour_name_the_trials_beside_laavs_by_kind():
    """Beside LAAV's informed trial the default runs missing-motion starts; with_plain_rv()
    (and the default on incomplete tracks) runs plain RV's trials: card 4 and the tour name
    them so (they called plain RV's trials missing-motion ones)."""
    from explorer.tour import fine_tuning_facts

    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=10, n_points=120, rng=0)
    own = laav.segment(seq, 2, laav.LaavParams(rv_missing_gate=0.0), seed=0).voting
    missing, plain = V.other_trial_counts(own)
    assert missing == own.n_trials - 1 > 0 and plain == 0
    assert f"then {missing} from starts that look for a missed motion (ours)" in V.rv_summary(own, None)
    assert f"{missing} trials for a missed motion" in fine_tuning_facts(seq, own, None)
    mixed = laav.segment(seq, 2, laav.LaavParams.with_plain_rv(), seed=0).voting
    missing, plain = V.other_trial_counts(mixed)
    assert missing == 0 and plain == mixed.n_trials - 1 > 0
    # the default's gate (rv_missing_gate): here LAAV's trial explains the start's points
    gated = laav.segment(seq, 2, seed=0).voting
    assert gated.skipped_starts == ("missing motion (0+1)",) and gated.n_trials == 1
    assert V.other_trial_counts(gated) == (0, 0)
    assert ("1 missing-motion start skipped: the informed trial's labels already explain the "
            "points it would make a motion (ours, `rv_missing_gate`)") in V.rv_summary(gated, None)
    assert "subspace votes; no search for a missed motion needed." in fine_tuning_facts(seq, gated, None)
    assert "skipped" not in V.rv_summary(own, None) and "needed" not in fine_tuning_facts(seq, own, None)
    text = V.rv_summary(mixed, None)
    assert f"then {plain} of plain RV from random starts, compared with it (ours)" in text
    assert "missed motion" not in text and "missed motion" not in fine_tuning_facts(seq, mixed, None)
    assert f"{plain} plain RV trials it was compared with" in fine_tuning_facts(seq, mixed, None)


def test_numbers_card_gives_the_rv_papers_own_result_beside_plain_rv_polished():
    """Plain RV's row is its labels after our polish; when a trial settled, the row adds that
    trial's own labels' error (the RV paper's result), computed from its label trace."""
    seq = laav.synthetic.make_sequence(n_objects=1, n_frames=10, n_points=120, rng=0)
    res = laav.segment(seq, 2, seed=0)
    plain = laav.random_voting(seq, 2, seed=0)
    assert plain.converged  # (a trial settles on this easy scene)
    num = V.stage_numbers(seq, res, plain)
    raw = laav.misclassification_rate(seq.labels, np.asarray(plain.label_trace)[-1])
    assert num["error_plain_trial"] == pytest.approx(raw)
    note = f"its settled trial's own labels, the RV paper's result: {100 * raw:.1f} %"
    assert note in V.numbers_markdown(num)
    unsettled = V.stage_numbers(seq, res, dataclasses.replace(plain, converged=False))
    assert unsettled["error_plain_trial"] is None
    assert "RV paper's result" not in V.numbers_markdown(unsettled)
    bare = laav.Sequence(seq.points, None)
    assert V.stage_numbers(bare, res, plain)["error_plain_trial"] is None


def test_the_epipolar_panel_draws_the_pair_while_its_votes_are_fitted():
    """Before card 3's votes are fitted (the default merge does not fit them), the panel
    already draws the pair's points, in the first and last frames, with their colours and
    legend names, and its caption says what decided the pair: the plots, their legends and
    the caption keep their size, so the page does not move up and back (a layout of every
    plot in the browser) while the votes are fitted. No lines nor sample until then."""
    from explorer.cards.epipolar import epipolar_caption

    seq = demo_sequence()
    res = laav.Pipeline(seq, 3).result
    assert not V.votes_fitted(res)
    j, k = 0, 1
    d = V.epipolar_sources(seq, res, j, k, fit_votes=False)
    assert d["pending"] and not d["ok"] and d["frames"] == (0, seq.n_frames - 1)
    fine = np.asarray(res.coarse.fine_point_labels)
    idx = np.flatnonzero((fine == j) | (fine == k))
    assert idx.size > 0
    for side, f in (("left", 0), ("right", seq.n_frames - 1)):
        np.testing.assert_array_equal(d[side]["x"], seq.points[f, idx, 0])
        np.testing.assert_array_equal(d[side]["y"], seq.points[f, idx, 1])
    fc = V.fine_colors(seq, res)
    assert d["left"]["color"].tolist() == np.where(fine[idx] == j, fc[j], fc[k]).tolist()
    assert set(d["left"]["model"].tolist()) == {"fine model f1", "fine model f2"}
    assert len(d["lines"]["x0"]) == 0 and len(d["sample_left"]["x"]) == 0
    caption = epipolar_caption(d, res, j, k)
    assert caption.startswith("The vote for f1–f2 (being fitted) drew ")
    assert "The joint merge" in caption  # what decided: the next test
    # the pending draw fitted nothing; once fitted, the same points in the sample's frames
    assert not V.votes_fitted(res)
    full = V.epipolar_sources(seq, res, j, k)
    assert full["ok"] and not full["pending"] and len(full["lines"]["x0"]) > 0
    # the same sentences as once fitted, "…" for the numbers not known yet: about as long
    full_caption = epipolar_caption(full, res, j, k)
    assert "…" in caption and "…" not in full_caption
    assert abs(len(caption) - len(full_caption)) <= 40, (caption, full_caption)
    fl, fr = full["frames"]
    np.testing.assert_array_equal(full["left"]["x"], seq.points[fl, idx, 0])
    np.testing.assert_array_equal(full["right"]["x"], seq.points[fr, idx, 0])
    # a model against itself: nothing drawn, pending or not
    same = V.epipolar_sources(seq, laav.Pipeline(seq, 3).result, 1, 1, fit_votes=False)
    assert same["pending"] and len(same["left"]["x"]) == 0


def test_the_epipolar_caption_says_what_the_joint_merge_decided():
    """Under the joint merge the caption gives the pair's margin (card 3's map): its sign is
    the decision the caption states, for every pair of fine models."""
    from explorer.cards.epipolar import epipolar_caption

    seq = demo_sequence()
    res = laav.Pipeline(seq, 3).result
    margin, coding, epi = V.joint_margins(res)
    f2c = np.asarray(res.coarse.fine_to_coarse)
    n = f2c.size
    decided = 0
    for j, k in itertools.permutations(range(n), 2):
        d = V.epipolar_sources(seq, res, j, k, fit_votes=False)
        text = epipolar_caption(d, res, j, k)
        same = f2c[j] == f2c[k]
        assert text.endswith("the same motion." if same else "different motions.")
        if np.isfinite(margin[j, k]):
            decided += 1
            assert (margin[j, k] > 0) == same  # splitting scores worse exactly when joined
            assert f"scores {margin[j, k]:+.1f} nats" in text
            assert f"length {coding[j, k]:+.1f}, epipolar {epi[j, k]:+.1f}" in text
            assert margin[j, k] == pytest.approx(coding[j, k] + epi[j, k])
        else:
            assert "every partition it compared put" in text
    assert decided > 0
    # a joint merge that compared no partitions: the caption says the coding length decided
    import dataclasses

    bare = dataclasses.replace(res, coarse=dataclasses.replace(res.coarse, shortlist=None))
    text = epipolar_caption(V.epipolar_sources(seq, bare, 0, 1, fit_votes=False), bare, 0, 1)
    assert "compared no partitions" in text and "least coding length decided" in text


def test_the_cross_of_a_point_in_no_atom_shows_on_its_fill():
    """A point in no atom carries a cross inside it: white on the dark motion colours, dark
    on the light fills (the grey of the atoms / fine / coarse colourings, the pale error
    colourings, the yellow and sky-blue motions), where a white one is not seen (contrast
    below 2:1)."""
    dark, light = V.MOTION_COLORS[:3], (V.UNLABELLED, "#EEEEEE", V.MOTION_COLORS[3], V.MOTION_COLORS[4])
    assert list(V.cross_colors(dark)) == [V.NO_ATOM] * 3
    assert list(V.cross_colors(light)) == [V.NO_ATOM_DARK] * 4
    assert V.cross_colors([]).size == 0
    seq = laav.synthetic.make_sequence(n_objects=2, n_frames=10, n_points=150, rng=0)
    res = laav.segment(seq, 3, seed=0)
    un = np.asarray(res.atoms.unassigned)
    assert un.size  # (points in no atom to mark)
    for mode, want in (("gt", V.NO_ATOM), ("atoms", V.NO_ATOM_DARK)):
        style = V.point_style(seq, res, mode)
        t = V.frame_templates(seq, res, style)["unassigned"]
        assert list(t["cross"]) == list(V.cross_colors(style["color"][un]))
        assert want in set(t["cross"]), mode


def test_legends_read_numbers_as_numbers():
    """The frame view's legend (and the compare views' shared one) lists "fine model 2"
    before "fine model 10" and "motion 9" before "motion 10" (a plain string sort put 10
    first); equal labels keep their points' order."""
    labels = np.array(["fine model 10 → motion 2", "fine model 2 → motion 1", "no fine model",
                       "fine model 1 → motion 1", "fine model 10 → motion 2", "fine model 2 → motion 10",
                       "fine model 2 → motion 9"], dtype=object)
    order = V.label_order(labels)
    assert order.tolist() == [3, 1, 6, 5, 0, 4, 2]
    style = {"color": np.full(labels.size, "#000000", dtype="U7"), "label": labels,
             "marker": np.full(labels.size, "circle", dtype=object)}
    tpl = V.points_template(style)
    assert tpl["index"].tolist() == order.tolist()
    rows = V.legend_points(style)
    assert list(rows["label"]) == ["fine model 1 → motion 1", "fine model 2 → motion 1",
                                   "fine model 2 → motion 9", "fine model 2 → motion 10",
                                   "fine model 10 → motion 2", "no fine model"]
    motions = np.array([f"motion {k}" for k in (10, 2, 1, 9)])
    assert motions[V.label_order(motions)].tolist() == ["motion 1", "motion 2", "motion 9", "motion 10"]


def test_card_3_names_the_lambda_the_merge_used():
    """On noisy tracks ``noise_adaptive`` scales λ (``LaavResult.run_params``); card 3's
    title named the λ set, which the merge did not use (a QA pass: 2 shown, 0.755 used)."""
    from types import SimpleNamespace

    def result(set_, ran):
        return SimpleNamespace(params=SimpleNamespace(lam=set_), run_params=SimpleNamespace(lam=ran))

    assert V.lam_label(result(2.0, 2.0)) == "λ = 2"
    assert V.lam_label(result(2.345, 2.345)) == "λ = 2.345"  # a λ set is shown as set
    assert V.lam_label(result(2.0, 0.7551)) == "λ = 0.755 (noise-scaled)"
