"""The ``laav`` command line: ``segment``, ``--version``, errors and exit codes."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import laav
from laav.cli import main

SMALL = ["--param", "rv_max_iter=30", "--param", "rv_trials=2"]


def _rigid_scene(n_motions: int = 2, n_per: int = 30, n_frames: int = 10, seed: int = 0):
    """Fallback scene: rigid point clouds moving independently before a pinhole camera."""
    rng = np.random.default_rng(seed)
    tracks = []
    for k in range(n_motions):
        X = rng.uniform(-1, 1, (n_per, 3)) + np.array([2.2 * k - 1.1 * (n_motions - 1), 0, 7.0])
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        vel = rng.normal(scale=0.06, size=3)
        frames = []
        for f in range(n_frames):
            a = 0.05 * f
            K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            R = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
            c = X.mean(0)
            Y = (X - c) @ R.T + c + vel * f
            frames.append(np.array([320.0, 240.0]) + 500 * Y[:, :2] / Y[:, 2:])
        tracks.append(np.stack(frames))
    labels = np.repeat(np.arange(n_motions), n_per)
    return laav.Sequence(np.concatenate(tracks, axis=1), labels, name="scene")


def make_scene(n_motions: int = 2, seed: int = 0, name: str = "scene") -> laav.Sequence:
    """A small labelled sequence: laav.synthetic.make_sequence when available."""
    try:
        from laav.synthetic import make_sequence
    except ImportError:
        seq = _rigid_scene(n_motions, seed=seed)
        return laav.Sequence(seq.points, seq.labels, name=name)
    return make_sequence(n_motions - 1, n_frames=10, n_points=30 * n_motions, rng=seed, name=name)


def _labels_csv(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["point", "label"]
    return np.array([[int(a), int(b)] for a, b in rows[1:]])


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"laav {laav.__version__}"


@pytest.mark.parametrize("ext,method", [(".mat", "laav"), (".npz", "rv")])
def test_segment_writes_labels_and_error(tmp_path, capsys, ext, method):
    seq = make_scene(2, seed=1)
    path = laav.save_sequence(seq, tmp_path / f"scene{ext}")
    out = tmp_path / "sub" / "labels.csv"
    rc = main(["segment", str(path), "--method", method, "--seed", "3", "--out", str(out), *SMALL])
    assert rc == 0
    stdout = capsys.readouterr().out
    assert f"labels: {out}" in stdout
    lab = _labels_csv(out)
    assert lab.shape == (seq.n_points, 2)
    np.testing.assert_array_equal(lab[:, 0], np.arange(seq.n_points))
    assert set(lab[:, 1]) <= {0, 1}
    err = 100 * laav.misclassification_rate(seq.labels, lab[:, 1])
    assert f"misclassification: {err:.2f} %" in stdout


def test_segment_is_reproducible_and_matches_api(tmp_path, capsys):
    seq = make_scene(2, seed=2)
    path = laav.save_sequence(seq, tmp_path / "scene.npz")
    params = laav.LaavParams(rv_max_iter=30, rv_trials=2)
    expected = laav.segment(laav.load_sequence(path), 2, params, 5).labels
    for i in range(2):
        assert main(["segment", str(path), "--seed", "5", "-o", str(tmp_path / f"l{i}.csv"), *SMALL]) == 0
        np.testing.assert_array_equal(_labels_csv(tmp_path / f"l{i}.csv")[:, 1], expected)


def test_segment_default_output_name(tmp_path, capsys, monkeypatch):
    seq = make_scene(2, seed=0, name="mine")
    path = laav.save_sequence(seq, tmp_path / "mine.npz")
    monkeypatch.chdir(tmp_path)
    assert main(["segment", str(path), *SMALL]) == 0
    assert (tmp_path / "mine_labels.csv").is_file()
    assert "labels: mine_labels.csv" in capsys.readouterr().out
    # two track files of one video (the same stored name) get two labels files, named
    # after the files (they overwrote each other's when named after the stored name)
    a = laav.save_sequence(seq, tmp_path / "a_stride1.npz")
    b = laav.save_sequence(laav.Sequence(seq.points[::2], seq.labels, name="mine"),
                           tmp_path / "b_stride2.npz")
    assert main(["segment", str(a), *SMALL]) == 0 and main(["segment", str(b), *SMALL]) == 0
    assert (tmp_path / "a_stride1_labels.csv").is_file() and (tmp_path / "b_stride2_labels.csv").is_file()
    # a Hopkins155 file: its sequence's name, without _truth
    h = laav.save_sequence(seq, tmp_path / "cars9_truth.mat")
    assert main(["segment", str(h), *SMALL]) == 0 and (tmp_path / "cars9_labels.csv").is_file()


def test_segment_bad_file_exit_2_names_file(tmp_path, capsys):
    bad = tmp_path / "broken_truth.mat"
    bad.write_bytes(b"this is not a MAT file at all")
    rc = main(["segment", str(bad)])
    assert rc == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "error" in err
    assert "Traceback" not in err


def test_segment_missing_file_exit_2(tmp_path, capsys):
    rc = main(["segment", str(tmp_path / "nope.mat")])
    assert rc == 2
    assert "nope.mat" in capsys.readouterr().err


def test_segment_without_labels_needs_motions(tmp_path, capsys):
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(laav.Sequence(seq.points, name="unlabelled"), tmp_path / "u.npz")
    rc = main(["segment", str(path)])
    assert rc == 2
    err = capsys.readouterr().err
    assert "--motions" in err and "no ground-truth labels" in err and str(path) in err
    out = tmp_path / "u.csv"
    assert main(["segment", str(path), "--motions", "2", "-o", str(out), *SMALL]) == 0
    stdout = capsys.readouterr().out
    assert "misclassification" not in stdout
    assert _labels_csv(out).shape == (seq.n_points, 2)


def test_segment_bad_options(tmp_path, capsys):
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(seq, tmp_path / "s.npz")
    assert main(["segment", str(path), "--param", "no_such=1"]) == 2
    assert "unknown LAAV parameter" in capsys.readouterr().err
    assert main(["segment", str(path), "--param", "rv_alpha=3"]) == 2
    assert "rv_alpha" in capsys.readouterr().err
    assert main(["segment", str(path), "--param", "rv_alpha"]) == 2
    assert main(["segment", str(path), "--motions", str(seq.n_points + 1)]) == 2
    assert "Traceback" not in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["segment", str(path), "--motions", "0"])
    assert exc.value.code == 2


def test_console_process_exit_code_and_no_gui_imports(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 truncated")
    proc = subprocess.run([sys.executable, "-m", "laav.cli", "segment", str(bad)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert str(bad) in proc.stderr and "Traceback" not in proc.stderr

    seq = make_scene(2, seed=0)
    good = laav.save_sequence(seq, tmp_path / "good.npz")
    code = (
        "import sys; from laav.cli import main; import laav.bench, laav.report\n"
        f"rc = main(['segment', {str(good)!r}, '-o', {str(tmp_path / 'l.csv')!r}, "
        "'--param', 'rv_max_iter=20'])\n"
        "bad = [m for m in sys.modules if m.split('.')[0] in "
        "('matplotlib', 'panel', 'viser', 'bokeh')]\n"
        "print('BAD', bad); sys.exit(rc)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "BAD []" in proc.stdout


@pytest.mark.parametrize("stored", ["../../evil/x", "/abs/evil/x", "..", "a/../../b\\c"])
def test_segment_name_from_the_file_stays_a_base_name(tmp_path, monkeypatch, capsys, stored):
    """Without --out the labels go to <input file's name>_labels.csv in the current folder
    only; the name stored in the file (crafted here) plays no part."""
    seq = make_scene(2, seed=1)
    src = tmp_path / "in"
    src.mkdir()
    path = laav.save_sequence(laav.Sequence(seq.points, seq.labels, name=stored), src / "crafted.npz")
    cwd = tmp_path / "w" / "a" / "b"
    cwd.mkdir(parents=True)
    monkeypatch.chdir(cwd)
    before = sorted(p for p in tmp_path.rglob("*"))
    assert main(["segment", str(path), *SMALL]) == 0
    new = sorted(set(tmp_path.rglob("*")) - set(before))
    want = cwd / "crafted_labels.csv"
    assert new == [want]
    assert not Path("/abs").exists()
    assert f"labels: {want.name}" in capsys.readouterr().out
    # a folder given with --out gets the same safe base name inside it
    outdir = tmp_path / "outdir"
    outdir.mkdir()
    assert main(["segment", str(path), "--out", str(outdir), *SMALL]) == 0
    assert [p.name for p in outdir.iterdir()] == [want.name]


def test_preset_paper_starts_from_the_papers_parameters(tmp_path):
    from laav.bench import BenchError, params_from_assignments

    P = laav.LaavParams
    assert params_from_assignments(["rv_max_iter=5"], "paper") == P.paper(rv_max_iter=5)
    assert params_from_assignments([], "default") == P()
    with pytest.raises(BenchError, match="unknown preset"):
        params_from_assignments([], "fast")
    out = tmp_path / "labels.csv"
    demo = Path(__file__).resolve().parents[1] / "explorer" / "assets" / "demo_two_objects.mat"
    assert main(["segment", str(demo), "--preset", "paper", "--out", str(out)]) == 0
    assert out.read_text().startswith("point,label")


def test_segment_max_points(tmp_path, capsys):
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(seq, tmp_path / "s.npz")
    assert main(["segment", str(path), "--max-points", "20", "-o", str(tmp_path / "a.csv")]) == 2
    err = capsys.readouterr().err
    assert f"{seq.n_points} points exceed the limit of 20" in err and str(path) in err
    assert err.count("\n") == 1
    assert main(["segment", str(path), "--max-points", str(seq.n_points), "-o",
                 str(tmp_path / "b.csv"), *SMALL]) == 0
    with pytest.raises(SystemExit) as exc:
        main(["segment", str(path), "--max-points", "0"])
    assert exc.value.code == 2


@pytest.mark.parametrize("case", ["missing", "folder", "out_under_file", "out_missing_dir",
                                  "bench_missing", "bench_data_file", "bench_out_file",
                                  "bench_out_under_file"])
def test_path_errors_are_one_line_exit_2(tmp_path, capsys, case):
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(seq, tmp_path / "s.npz")
    afile = tmp_path / "afile"
    afile.write_text("x")
    (tmp_path / "empty").mkdir()
    data = tmp_path / "data" / "s"
    data.mkdir(parents=True)
    laav.save_sequence(seq, data / "s_truth.mat")
    argv = {
        "missing": ["segment", str(tmp_path / "nope.npz")],
        "folder": ["segment", str(tmp_path / "empty")],
        "out_under_file": ["segment", str(path), "-o", str(afile / "x.csv"), *SMALL],
        "out_missing_dir": ["segment", str(path), "-o", str(tmp_path / "no" / "x.csv" / "y.csv"),
                            *SMALL],
        "bench_missing": ["bench", "--data", str(tmp_path / "nope"), "-q",
                          "--out", str(tmp_path / "o")],
        "bench_data_file": ["bench", "--data", str(afile), "-q", "--out", str(tmp_path / "o")],
        "bench_out_file": ["bench", "--data", str(tmp_path / "data"), "-q", "--out", str(afile)],
        "bench_out_under_file": ["bench", "--data", str(tmp_path / "data"), "-q",
                                 "--out", str(afile / "sub")],
    }[case]
    if case == "out_missing_dir":  # a folder that can't be made: its parent is a file
        (tmp_path / "no").write_text("x")
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "error" in err and "Traceback" not in err
    assert str(tmp_path) in err


def test_segment_too_few_tracks_for_c_exit_2_one_line(tmp_path, capsys):
    # issue 14 item 9: fewer tracks than C needs (8 per motion) is refused, as laav-explore does
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(laav.Sequence(seq.points[:, :20], name="few"), tmp_path / "few.npz")
    out = tmp_path / "few.csv"
    assert main(["segment", str(path), "--motions", "3", "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err
    assert err.startswith(f"laav segment: error: {path}: 20 tracks, fewer than the 24")
    assert not out.exists()
    assert main(["segment", str(path), "--motions", "2", "-o", str(out), *SMALL]) == 0  # enough
    # too few to estimate C: estimate_motions' own message, the file named once
    path12 = laav.save_sequence(laav.Sequence(seq.points[:, :12], name="few"), tmp_path / "f12.npz")
    assert main(["segment", str(path12), "--motions", "auto"]) == 2
    err = capsys.readouterr().err
    assert err.count(f"{path12}:") == 1 and "too few to estimate" in err


def test_segment_warning_is_one_line(tmp_path):
    # a LaavWarning from the console command: one line on stderr, no Python source line
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(laav.Sequence(seq.points * 1e-3, name="tiny"), tmp_path / "tiny.npz")
    run = subprocess.run([sys.executable, "-m", "laav.cli", "segment", str(path), "--motions", "2",
                          "-o", str(tmp_path / "t.csv"), *SMALL], capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr
    err = [ln for ln in run.stderr.splitlines() if ln.strip()]
    # one line per warning: the scale, and (at that scale the radii hold no neighbours) the
    # atoms that did not form
    assert len(err) == 2, err
    assert err[0].startswith(f"laav segment: warning: {path}: the coordinates span")
    assert err[1].startswith(f"laav segment: warning: {path}: no atom formed with R1 = ")


def test_segment_out_with_a_trailing_separator_is_a_folder(tmp_path, capsys):
    # `--out DIR/` names a folder (created), not a file called DIR
    seq = make_scene(2, seed=0, name="mine")
    path = laav.save_sequence(seq, tmp_path / "mine.npz")
    assert main(["segment", str(path), "-o", str(tmp_path / "new") + "/", *SMALL]) == 0
    assert (tmp_path / "new").is_dir() and (tmp_path / "new" / "mine_labels.csv").is_file()
    assert main(["segment", str(path), "-o", str(tmp_path / "a" / "b") + "/", *SMALL]) == 0
    assert (tmp_path / "a" / "b" / "mine_labels.csv").is_file()
    assert main(["segment", str(path), "-o", str(tmp_path / "dot") + "/.", *SMALL]) == 0
    assert (tmp_path / "dot" / "mine_labels.csv").is_file()  # a folder, not a file "dot"
    capsys.readouterr()
    assert main(["segment", str(path), "-o", "", *SMALL]) == 2
    assert "--out is empty" in capsys.readouterr().err
    (tmp_path / "afile").write_text("x")
    assert main(["segment", str(path), "-o", str(tmp_path / "afile" / "x.csv"), *SMALL]) == 2
    out = capsys.readouterr()
    assert "afile is a file, not a folder" in out.err
    assert "misclassification" not in out.out  # said before the segmentation, not after


def test_seed_and_jobs_are_checked_by_the_parser(tmp_path, capsys):
    seq = make_scene(2, seed=0)
    path = laav.save_sequence(seq, tmp_path / "s.npz")
    for argv, said in ((["segment", str(path), "--seed", "-1"], "--seed: expected an integer in [0, 2**63)"),
                       (["bench", "--data", str(tmp_path), "--jobs", "0"], "--jobs/-j: expected a positive")):
        with pytest.raises(SystemExit) as exc:
            main(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert said in err and str(path) not in err  # the option is wrong, not the file


def test_convert_to_a_folder_says_so(tmp_path, capsys):
    path = laav.save_sequence(make_scene(2, seed=0), tmp_path / "s.npz")
    (tmp_path / "dir").mkdir()
    assert main(["convert", str(path), str(tmp_path / "dir")]) == 2
    assert "is a folder; give a file name" in capsys.readouterr().err
    assert main(["convert", str(path), str(tmp_path / "new") + "/"]) == 2
    assert "names a folder; give a file name" in capsys.readouterr().err
    assert main(["convert", str(path), str(tmp_path / "sub" / "s.csv")]) == 0  # its folder made
    assert (tmp_path / "sub" / "s.csv").is_file()


def test_segment_check_compares_with_plain_rv(tmp_path, capsys, monkeypatch):
    """--check runs plain RV with the same parameters and seed and says how far the two
    labellings are apart (laav.labelling_distance), plain RV's error with a ground truth;
    above 10 % a warning on stderr."""
    seq = make_scene(2, seed=0, name="mine")
    path = laav.save_sequence(seq, tmp_path / "mine.npz")
    out = tmp_path / "l.csv"
    assert main(["segment", str(path), "-o", str(out), "--check", *SMALL]) == 0
    cap = capsys.readouterr()
    lab = _labels_csv(out)[:, 1]
    params = laav.LaavParams(rv_max_iter=30, rv_trials=2)
    plain = laav.random_voting(seq, 2, params, seed=0).labels
    d = laav.labelling_distance(lab, plain)
    assert (f"check: LAAV and plain Random Voting label {round(d * seq.n_points)} of {seq.n_points} "
            f"points differently ({100 * d:.1f} %); plain RV misclassification "
            f"{100 * laav.misclassification_rate(seq.labels, plain):.2f} %") in cap.out
    assert "warning" not in cap.err and d <= 0.10
    # plain RV far off: the warning
    real = laav.random_voting

    def far(seq_, C, params_, seed_, **kw):
        assert kw == {"check_input": False}  # segment's input warnings are not said twice
        v = real(seq_, C, params_, seed_, **kw)
        moved = v.labels.copy()
        moved[: moved.size // 3] = 1 - moved[: moved.size // 3]
        import dataclasses

        return dataclasses.replace(v, labels=moved)

    monkeypatch.setattr(laav, "random_voting", far)
    assert main(["segment", str(path), "-o", str(out), "--check", *SMALL]) == 0
    cap = capsys.readouterr()
    assert "laav segment: warning: LAAV and plain RV disagree on" in cap.err
    assert "at least one of them is wrong" in cap.err
    # without --check plain RV is not run
    calls = []
    monkeypatch.setattr(laav, "random_voting", lambda *a, **k: calls.append(a) or real(*a, **k))
    assert main(["segment", str(path), "-o", str(out), *SMALL]) == 0 and not calls


def test_segment_reads_a_params_file_as_the_explorer_exports_it(tmp_path, capsys):
    """--params takes the explorer's Parameters (JSON) export (its seed too, unless --seed
    is given, as laav-explore --params does; not its C), on the preset, --param after it; a
    bad file is one line naming it."""
    import json

    seq = make_scene(2, seed=0, name="mine")
    path = laav.save_sequence(seq, tmp_path / "mine.npz")
    exported = {"sequence": "other", "n_motions": 3, "seed": 7,
                "params": {**laav.LaavParams().to_dict(), "r1": 25.0, "rv_max_iter": 30, "rv_trials": 2}}
    pj = tmp_path / "p.json"
    pj.write_text(json.dumps(exported))
    out = tmp_path / "l.csv"
    assert main(["segment", str(path), "--params", str(pj), "-o", str(out)]) == 0
    fast = laav.LaavParams(r1=25.0, rv_max_iter=30, rv_trials=2)
    assert "seed 7)" in capsys.readouterr().out  # the file's seed
    assert np.array_equal(_labels_csv(out)[:, 1], laav.segment(seq, 2, fast, seed=7).labels)
    assert main(["segment", str(path), "--params", str(pj), "--seed", "0", "-o", str(out)]) == 0
    assert "seed 0)" in capsys.readouterr().out  # --seed wins
    assert np.array_equal(_labels_csv(out)[:, 1], laav.segment(seq, 2, fast, seed=0).labels)
    assert laav.LaavParams.from_json(pj.read_text()).r1 == 25.0
    assert laav.LaavParams.from_json('{"r1": 9}', laav.LaavParams.paper()) == laav.LaavParams.paper(r1=9)
    # --param after the file
    assert main(["segment", str(path), "--params", str(pj), "--param", "r1=20", "-o", str(out)]) == 0
    capsys.readouterr()
    bad = tmp_path / "bad.json"
    bad.write_text('{"params": {"r1": 25, "nonsense": 1}}')
    assert main(["segment", str(path), "--params", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: unknown LAAV parameter(s): nonsense" in err and "Traceback" not in err
    assert main(["segment", str(path), "--params", str(tmp_path / "none.json"), "-o", str(out)]) == 2
    assert "none.json: cannot be read" in capsys.readouterr().err
    badseed = tmp_path / "badseed.json"
    badseed.write_text('{"params": {"r1": 25}, "seed": -3}')
    assert main(["segment", str(path), "--params", str(badseed), "-o", str(out)]) == 2
    assert f"{badseed}: seed must be a whole number in [0, 2**63), got -3" in capsys.readouterr().err
    for text, msg in (("[1, 2]", "one JSON object"), ("{", "not a JSON file"),
                      ('{"params": {"r1": -5}}', "r1")):
        with pytest.raises(ValueError, match=msg):
            laav.LaavParams.from_json(text)


def test_an_npz_with_more_frames_than_points_warns_of_a_transposed_array(tmp_path, capsys):
    """points written as (P, F, 2) read as P frames of F points and segment into nothing
    useful without a word; laav segment and laav-explore say what it looks like."""
    seq = make_scene(2, seed=0)
    swapped = tmp_path / "swapped.npz"
    np.savez(swapped, points=seq.points.transpose(1, 0, 2)[:, :9])  # 9 of the points, transposed
    assert laav.io.layout_warning(laav.load_sequence(swapped)).startswith(
        f"{swapped}: {seq.n_points} frames of 9 points: if its 'points' array is (points, frames, 2)")
    main(["segment", str(swapped), "--motions", "1", "-o", str(tmp_path / "l.csv")])
    assert "laav segment: warning: " in capsys.readouterr().err
    # the right layout, and other formats, say nothing
    assert laav.io.layout_warning(laav.load_sequence(laav.save_sequence(seq, tmp_path / "ok.npz"))) is None
    wide = laav.save_sequence(laav.Sequence(seq.points.transpose(1, 0, 2)[:, :9]), tmp_path / "w.csv")
    assert laav.io.layout_warning(laav.load_sequence(wide)) is None  # a CSV names its columns
