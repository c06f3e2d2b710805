"""Degenerate input gets an error or a LaavWarning, never a silent single label (issue 16)."""

import warnings

import numpy as np
import pytest

import laav
from laav import LaavParams, LaavWarning, Sequence, segment
from laav.synthetic import make_sequence

FAST = LaavParams(rv_max_iter=30, rv_trials=2)


def _scene():
    return make_sequence(n_objects=1, n_frames=8, n_points=80, rng=0)


def _segment_quietly(seq, C=2):
    with warnings.catch_warnings():
        warnings.simplefilter("error", LaavWarning)
        return segment(seq, C, FAST)


def test_ordinary_input_gives_no_warning():
    seq = _scene()
    res = _segment_quietly(seq)
    assert laav.misclassification_rate(seq.labels, res.labels) < 0.05


def test_too_few_points_for_the_motions():
    pts = np.random.default_rng(0).uniform(0, 500, (5, 9, 2))
    with pytest.warns(LaavWarning, match="nine.npz: 9 points are too few for 2 motions"):
        segment(Sequence(pts, source="nine.npz"), 2, FAST)
    with pytest.warns(LaavWarning, match="too few"):
        laav.Pipeline(Sequence(pts, source="nine.npz"), 2, FAST)


def test_identical_trajectories():
    one = np.random.default_rng(0).uniform(0, 500, (5, 1, 2))
    with pytest.raises(ValueError, match="only 1 distinct trajectory for 2 motions"):
        segment(np.repeat(one, 40, axis=1), 2, FAST)
    two = np.concatenate([np.repeat(one, 20, axis=1), np.repeat(one + 50, 20, axis=1)], axis=1)
    with pytest.raises(ValueError, match="only 2 distinct trajectories for 3 motions"):
        segment(two, 3, FAST)


def test_static_trajectories_warn():
    still = np.repeat(np.random.default_rng(0).uniform(0, 500, (1, 40, 2)), 6, axis=0)
    with pytest.warns(LaavWarning, match="no point moves"):
        segment(still, 2, FAST)


def test_collinear_trajectories_warn():
    rng = np.random.default_rng(1)
    t = rng.uniform(0, 300, 40)
    s = [t + 5 * f + (t > 150) * 3 * f for f in range(6)]  # two speeds along one line
    frames = [np.stack([x, 0.5 * x + 20], axis=1) for x in s]
    with pytest.warns(LaavWarning, match="collinear in every frame"):
        segment(np.stack(frames), 2, FAST)


@pytest.mark.parametrize("factor", [1e9, 1e-9])
def test_extreme_scales_warn(factor):
    seq = _scene()
    with pytest.warns(LaavWarning, match="px, outside 1-1e"):
        segment(seq.points * factor, 2, FAST)


def test_single_label_result_warns():
    seq = _scene()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # fixed pixel thresholds: the noise-adaptive ones grow with the coordinates' scale
        # (σ̂ too is 1e9 times larger) and can still find two motions there
        res = segment(seq.points * 1e9, 2, FAST.replace(noise_adaptive=False))
    messages = [str(w.message) for w in caught if w.category is LaavWarning]
    assert np.unique(res.labels).size == 1  # what LAAV does at this scale (pixel radii)
    assert any("every point got the same label though 2 motions" in m for m in messages)



def test_a_result_with_empty_motions_warns():
    """More motions asked for than the tracks support: some labels end empty, and the
    caller hears it (it was silent unless all but one were empty)."""
    base = make_sequence(1, n_frames=10, n_points=60, rng=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = segment(base, 7)
    used = np.unique(res.labels).size
    assert 1 < used < 7  # what LAAV does here
    messages = [str(w.message) for w in caught if w.category is LaavWarning]
    assert any(f"only {used} of the 7 motions asked for got points" in m for m in messages), messages

# --- plain Random Voting and `laav segment --method rv` check like LAAV (issue 16 item 8) ---

def _static():
    return np.repeat(np.random.default_rng(0).uniform(0, 500, (1, 40, 2)), 6, axis=0)


def _nine():
    return np.random.default_rng(0).uniform(0, 500, (5, 9, 2))


@pytest.mark.parametrize("run", [segment, laav.random_voting], ids=["laav", "rv"])
@pytest.mark.parametrize("case, match", [
    (_nine, "9 points are too few for 2 motions"),
    (_static, "no point moves"),
    (lambda: _scene().points * 1e9, "px, outside 1-1e"),
], ids=["nine", "static", "huge"])
def test_both_methods_warn_alike(run, case, match):
    with pytest.warns(LaavWarning, match=match):
        run(Sequence(case(), source="odd.npz"), 2, FAST)


@pytest.mark.parametrize("run", [segment, laav.random_voting], ids=["laav", "rv"])
def test_both_methods_refuse_identical_trajectories(run):
    one = np.random.default_rng(0).uniform(0, 500, (5, 1, 2))
    with pytest.raises(ValueError, match="only 1 distinct trajectory for 2 motions"):
        run(np.repeat(one, 40, axis=1), 2, FAST)


def test_random_voting_warns_on_a_single_label(monkeypatch):
    import laav.selection as selection

    real = selection.finish

    def one_label(points, C, params, best, *args, **kw):
        res = real(points, C, params, best, *args, **kw)
        import dataclasses

        return dataclasses.replace(res, labels=np.zeros_like(res.labels))

    monkeypatch.setattr(selection, "finish", one_label)
    monkeypatch.setattr(selection, "select", lambda points, C, params, cands, *a, **k: one_label(
        points, C, params, cands[0][1], (), False, "x"))
    with pytest.warns(LaavWarning, match="every point got the same label though 2 motions"):
        laav.random_voting(_scene(), 2, FAST)


def test_ordinary_input_gives_no_warning_rv():
    seq = _scene()
    with warnings.catch_warnings():
        warnings.simplefilter("error", LaavWarning)
        res = laav.random_voting(seq, 2, FAST)
    assert laav.misclassification_rate(seq.labels, res.labels) < 0.05


@pytest.mark.parametrize("method", ["laav", "rv"])
def test_cli_methods_check_alike(tmp_path, capsys, method):
    from laav.cli import main

    small = ["--param", "rv_max_iter=30", "--param", "rv_trials=2"]
    path = tmp_path / "still.npz"
    np.savez(path, points=_static())
    with pytest.warns(LaavWarning, match="still.npz: no point moves"):
        code = main(["segment", str(path), "--motions", "2", "--method", method,
                     "--out", str(tmp_path / "l.csv"), *small])
    assert code == 0
    one = np.random.default_rng(0).uniform(0, 500, (5, 1, 2))
    np.savez(path, points=np.repeat(one, 40, axis=1))
    code = main(["segment", str(path), "--motions", "2", "--method", method,
                 "--out", str(tmp_path / "l.csv"), *small])
    err = capsys.readouterr().err
    assert code == 2 and "only 1 distinct trajectory for 2 motions" in err
    assert len(err.strip().splitlines()) == 1


def test_segment_warns_once_when_no_atom_forms_and_plain_rv_runs():
    seq = make_sequence(n_objects=1, n_frames=10, n_points=60, rng=0)
    tiny = Sequence(seq.points * 1e-4, seq.labels)  # spread 0.06 px: the scale warning
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = segment(tiny, 2, LaavParams(r1=1e-4, r2=2e-4), seed=0)
    assert not (res.coarse.point_labels >= 0).any()  # no atom: plain Random Voting ran
    spread = [w for w in caught if issubclass(w.category, LaavWarning) and "span" in str(w.message)]
    assert len(spread) == 1, [str(w.message) for w in caught]
    # plain RV called directly still checks its input
    with pytest.warns(LaavWarning, match="span"):
        laav.random_voting(tiny, 2, seed=0)


@pytest.mark.parametrize("call", ["segment", "Pipeline", "random_voting", "segment_incomplete"])
def test_warnings_name_the_callers_line(call):
    """However deep inside laav a warning is raised, it names the user's file and line."""
    seq = make_sequence(n_objects=1, n_frames=10, n_points=60, rng=0)
    tiny = Sequence(seq.points * 1e-4, seq.labels)  # the spread warning
    if call == "segment_incomplete":
        vis = np.ones(tiny.points.shape[:2], bool)
        vis[:2, ::5] = False
        tiny = Sequence(np.where(vis[..., None], tiny.points, np.nan), seq.labels, visible=vis)
    run = {"segment": lambda: segment(tiny, 2, seed=0),
           "segment_incomplete": lambda: segment(tiny, 2, seed=0),
           "Pipeline": lambda: laav.Pipeline(tiny, 2),
           "random_voting": lambda: laav.random_voting(tiny, 2, seed=0)}[call]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        run()
    mine = [w for w in caught if issubclass(w.category, LaavWarning)]
    assert mine and all(w.filename == __file__ for w in mine), [(w.filename, w.lineno) for w in mine]


def test_settings_of_the_wrong_kind_get_a_clear_error():
    seq = _scene()
    for run in (segment, laav.random_voting):
        with pytest.raises(TypeError, match="params must be a LaavParams"):
            run(seq, 2, {"lam": 3.0})
    with pytest.raises(ValueError, match="give init_labels too"):  # was silently ignored
        laav.random_voting(seq, 2, weights=np.ones(seq.n_points))


def test_too_much_missing_is_refused_before_any_stage_runs(monkeypatch):
    """No two frames share the points one fit per motion needs: the error names the file
    and comes before the atoms (it came from the voting, after every other stage)."""
    import laav.pipeline as pipeline_module

    seq = laav.synthetic.occlude(make_sequence(2, n_frames=20, n_points=200, rng=3), 0.85, rng=1)
    seq = Sequence(seq.points, seq.labels, visible=seq.visible, source="clip.mat")

    def no_atoms(*a, **k):
        raise AssertionError("a stage ran")

    monkeypatch.setattr(pipeline_module, "build_atoms", no_atoms)
    with pytest.raises(ValueError, match="clip.mat: no two frames share 24 visible points"):
        segment(seq, 3)
    pipe_seq = laav.synthetic.occlude(make_sequence(2, n_frames=20, n_points=200, rng=3), 0.5, rng=1)
    monkeypatch.undo()
    pipe = laav.Pipeline(pipe_seq, 3)
    with pytest.raises(ValueError, match="no two frames share"):
        pipe.update(rv_sample_size=60)  # 180 points in two frames: refused, state kept
    assert pipe.params.rv_sample_size == LaavParams().rv_sample_size


def test_one_far_track_is_a_scale_problem_not_collinear_points():
    """A single track 1e13 px away (a near-zero homogeneous coordinate, say): the warning
    names the span of the coordinates, not collinearity (the tolerance, relative to the
    far track, made every frame look collinear)."""
    pts = make_sequence(1, n_frames=10, n_points=60, rng=0).points.copy()
    pts[:, 0] *= 1e11
    with pytest.warns(LaavWarning) as caught:
        segment(pts, 2, FAST)
    messages = " ".join(str(w.message) for w in caught)
    assert "outside 1-1e" in messages and "collinear" not in messages


@pytest.mark.parametrize("max_points", [None, 150])
def test_plain_voting_names_the_file_when_too_much_is_missing(max_points):
    """Random Voting alone (and on its seeded subset above rv_max_points, an array) names
    the sequence's file when no frame pair has enough points."""
    seq = laav.synthetic.occlude(make_sequence(2, n_frames=20, n_points=200, rng=3), 0.85, rng=1)
    seq = Sequence(seq.points, seq.labels, visible=seq.visible, source="clip.mat")
    with pytest.raises(ValueError, match=r"^clip\.mat: no two frames share"):
        laav.random_voting(seq, 3, LaavParams(rv_max_points=max_points), seed=0)


def test_segment_warns_when_no_atom_formed():
    """No atom at C > 1: the fine-tuning started from random labels (plain RV, not LAAV);
    laav.segment says so (the explorer's note), an ordinary run does not."""
    from laav.synthetic import make_sequence

    seq = make_sequence(1, n_frames=10, n_points=60, rng=0)
    with pytest.warns(LaavWarning, match=r"no atom formed with R1 = 0.5, R2 = 1 px: the fine-tuning "
                                         r"started from random labels \(plain Random Voting"):
        res = laav.segment(seq, 2, laav.LaavParams(r1=0.5, r2=1.0), seed=0)
    assert res.atoms.n_atoms == 0
    with warnings.catch_warnings():
        warnings.simplefilter("error", LaavWarning)
        assert laav.segment(seq, 2, seed=0).atoms.n_atoms > 0
