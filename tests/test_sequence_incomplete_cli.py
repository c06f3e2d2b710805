"""Incomplete sequences on the command line and in the explorer: ``laav segment`` segments
them (the stages handle missing data, issue 14 item 3), ``--complete-only`` keeps the tracks
seen in every frame, ``laav convert`` converts formats; the explorer takes them too
(``laav-explore FILE`` and an upload of an incomplete file segment and draw them), and
``--motions auto`` estimates C on the tracks seen in every frame.
"""

from __future__ import annotations

import csv
import re

import numpy as np
import pytest

import laav
from laav.cli import main
from laav.synthetic import make_sequence

SMALL = ["--param", "rv_max_iter=30", "--param", "rv_trials=2"]


def _occluded_scene(path=None, name="occluded"):
    """A 2-motion scene where 20 of 80 tracks end early (frames 7-9 hidden)."""
    seq = make_sequence(1, n_frames=10, n_points=80, rng=4, name=name)
    vis = np.ones((10, 80), bool)
    hidden = np.arange(0, 80, 4)
    vis[7:, hidden] = False
    occl = laav.Sequence(seq.points, seq.labels, name=name, image_size=seq.image_size, visible=vis)
    if path is not None:
        laav.save_sequence(occl, path)
    return occl, np.setdiff1d(np.arange(80), hidden)


@pytest.mark.parametrize("method", ["laav", "rv"])
def test_segment_segments_an_incomplete_file(tmp_path, capsys, method):
    path = tmp_path / "occluded.npz"
    seq, _ = _occluded_scene(path)
    out = tmp_path / "l.csv"
    assert main(["segment", str(path), "--method", method, "-o", str(out), *SMALL]) == 0
    cap = capsys.readouterr()
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    got = np.array(rows[1:], dtype=int)
    assert np.array_equal(got[:, 0], np.arange(80))  # every point of the file
    err = 100 * laav.misclassification_rate(seq.labels, got[:, 1])
    assert f"misclassification: {err:.2f} %" in cap.out
    assert err < 5


def test_segment_reports_unlabelled_points(tmp_path, capsys):
    seq = make_sequence(1, n_frames=12, n_points=80, rng=4, name="brief")
    vis = np.ones((12, 80), bool)
    vis[:, :3] = False
    vis[5:7, :3] = True  # 3 tracks seen in 2 neighbouring frames only: never voted on
    laav.save_sequence(laav.Sequence(seq.points, seq.labels, visible=vis), tmp_path / "b.npz")
    assert main(["segment", str(tmp_path / "b.npz"), "-o", str(tmp_path / "l.csv"), *SMALL]) == 0
    out = capsys.readouterr().out
    assert "unlabelled: 3 of 80 points (label -1" in out
    with open(tmp_path / "l.csv", newline="") as fh:
        got = np.array(list(csv.reader(fh))[1:], dtype=int)
    assert (got[:3, 1] == -1).all() and (got[3:, 1] >= 0).all()


def test_segment_auto_on_an_incomplete_file_estimates_c_on_its_complete_tracks(tmp_path, capsys):
    path = tmp_path / "occluded.npz"
    _occluded_scene(path)
    assert main(["segment", str(path), "--motions", "auto", "-o", str(tmp_path / "l.csv"), *SMALL]) == 0
    out = capsys.readouterr().out
    assert "motions: 2 (estimated:" in out and "estimated on the 60 of 80 tracks seen in every frame" in out


def test_segment_auto_with_too_few_complete_tracks_is_one_clear_line(tmp_path, capsys):
    seq = make_sequence(1, n_frames=10, n_points=80, rng=4)
    vis = np.ones((10, 80), bool)
    vis[8:, 10:] = False  # only 10 tracks seen in every frame
    path = laav.save_sequence(laav.Sequence(seq.points, seq.labels, name="few", visible=vis),
                              tmp_path / "few.npz")
    assert main(["segment", str(path), "--motions", "auto", "-o", str(tmp_path / "l.csv")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err
    assert "only 10 of the 80 tracks are seen in every frame" in err and "--motions N" in err


@pytest.mark.parametrize("method", ["laav", "rv"])
def test_complete_only_segments_the_full_tracks_and_keeps_the_file_numbers(tmp_path, capsys, method):
    path = tmp_path / "occluded.csv"
    seq, kept = _occluded_scene(path)
    out = tmp_path / "labels.csv"
    assert main(["segment", str(path), "--complete-only", "--method", method, "-o", str(out),
                 *SMALL]) == 0
    cap = capsys.readouterr()
    assert "--complete-only: kept 60 of 80 points" in cap.err
    with open(out, newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["point", "label"]
    got = np.array(rows[1:], dtype=int)
    assert np.array_equal(got[:, 0], kept)  # the file's point numbers, not 0..59
    err = 100 * laav.misclassification_rate(seq.labels[kept], got[:, 1])
    assert f"misclassification: {err:.2f} %" in cap.out
    assert err < 5


@pytest.mark.parametrize("complete_only", [False, True])
def test_segment_names_a_tracks_csvs_points_by_their_track_ids(tmp_path, capsys, monkeypatch, complete_only):
    """A tracks CSV numbers its tracks itself (here 1000, 1007, ..., rows shuffled): the
    labels file names each point by that id (the points are the tracks in increasing id),
    the tracks kept by --complete-only too."""
    seq, kept = _occluded_scene()
    ids = 1000 + 7 * np.arange(seq.n_points)
    rows = [(ids[p], f, *seq.points[f, p], seq.labels[p])
            for f in range(seq.n_frames) for p in range(seq.n_points) if seq.visible[f, p]]
    order = np.random.default_rng(0).permutation(len(rows))
    path = tmp_path / "tracks.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(("track", "frame", "x", "y", "label"))
        w.writerows(rows[i] for i in order)
    out = tmp_path / "labels.csv"
    assert main(["segment", str(path), "-o", str(out), *SMALL,
                 *(["--complete-only"] if complete_only else [])]) == 0
    capsys.readouterr()
    with open(out, newline="") as fh:
        got = np.array(list(csv.reader(fh))[1:], dtype=int)
    want = ids[kept] if complete_only else ids
    assert np.array_equal(got[:, 0], want)
    truth = seq.labels[kept] if complete_only else seq.labels
    assert laav.misclassification_rate(truth, got[:, 1]) < 0.05
    assert np.array_equal(laav.io.csv_track_ids(path), ids)
    assert laav.io.csv_track_ids(tmp_path / "labels.csv") is None  # another CSV: no tracks header
    # laav-explore numbers them the same way in its labels CSV (state.Origin.point_ids)
    from conftest import fake_serving

    from explorer import export
    from explorer.cli import main as explore

    seen = fake_serving(monkeypatch)
    assert explore([str(path), "--no-browser", *(["--complete-only"] if complete_only else [])]) == 0
    assert np.array_equal(seen["origin"].point_ids, want)
    res = laav.segment(seen["seq"], 2, seed=0)
    table = export.labels_csv(seen["seq"], res, seen["origin"].point_ids).splitlines()
    assert [int(r.split(",")[0]) for r in table[1:]] == want.tolist()


def test_convert_between_formats(tmp_path, capsys):
    seq, kept = _occluded_scene(tmp_path / "in.csv")
    assert main(["convert", str(tmp_path / "in.csv"), str(tmp_path / "out.mat")]) == 0
    assert "80 points, 92.5 % visible" in capsys.readouterr().out
    back = laav.load_sequence(tmp_path / "out.mat")  # KT3DMoSeg layout: it is incomplete
    assert np.array_equal(back.visible, seq.visible)
    assert np.array_equal(back.points, seq.points, equal_nan=True)
    assert np.array_equal(back.labels, seq.labels)

    assert main(["convert", str(tmp_path / "out.mat"), str(tmp_path / "h.mat"),
                 "--format", "hopkins"]) == 2
    assert "cannot hold missing entries" in capsys.readouterr().err
    assert main(["convert", str(tmp_path / "out.mat"), str(tmp_path / "h_truth.mat"),
                 "--complete-only"]) == 0
    full = laav.load_sequence(tmp_path / "h_truth.mat")
    assert full.is_complete and np.array_equal(full.points, seq.points[:, kept])

    (tmp_path / "bad.csv").write_text("track,frame,x,y\n0,0,1,2\n0,0,1,2\n")
    assert main(["convert", str(tmp_path / "bad.csv"), str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "bad.csv: track 0 has two rows for frame 0" in err and "Traceback" not in err


# --------------------------------------------------------------------------- explorer

pn = pytest.importorskip("panel")


def test_explorer_cli_accepts_an_incomplete_file(tmp_path, capsys, monkeypatch):
    """Once refused (exit 2); now served with every track, C from the file's truth."""
    from conftest import fake_serving

    from explorer.cli import main as explore

    seen = fake_serving(monkeypatch)
    path = tmp_path / "occluded.npz"
    _occluded_scene(path)
    assert explore([str(path), "--no-browser"]) == 0
    out = capsys.readouterr().out
    assert "80 tracks, 92.5 % of the entries visible" in out and "(80 points, 10 frames, C = 2)" in out
    assert seen["n_motions"] == 2
    # --complete-only keeps working: the 60 full tracks
    assert explore([str(path), "--no-browser", "--complete-only"]) == 0
    cap = capsys.readouterr()
    assert "--complete-only: kept the 60 of 80 tracks" in cap.err
    assert "(60 points, 10 frames, C = 2)" in cap.out


def test_explorer_cli_estimates_c_of_an_incomplete_file_without_truth(tmp_path, capsys, monkeypatch):
    from conftest import fake_serving

    from explorer.cli import main as explore

    seen = fake_serving(monkeypatch)
    occl, _ = _occluded_scene()
    path = laav.save_sequence(laav.Sequence(occl.points, name="no_truth", visible=occl.visible),
                              tmp_path / "no_truth.npz")
    assert explore([str(path), "--no-browser"]) == 0
    out = capsys.readouterr().out
    assert "C = 2 estimated" in out and "seen in every frame" in out and seen["n_motions"] == 2
    # too few complete tracks to estimate C: one clear line, exit 2
    vis = np.ones((10, 80), bool)
    vis[8:, 10:] = False  # only 10 tracks seen in every frame
    base = make_sequence(1, n_frames=10, n_points=80, rng=4)
    few = laav.save_sequence(laav.Sequence(base.points, name="few", visible=vis), tmp_path / "few.npz")
    assert explore([str(few), "--no-browser"]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1
    assert "only 10 of the 80 tracks are seen in every frame" in err and "--motions N" in err


def test_explorer_state_accepts_an_incomplete_sequence(tmp_path):
    from explorer import ExplorerState

    occl, _ = _occluded_scene()
    full = make_sequence(1, n_frames=8, n_points=60, rng=2, name="full")
    state = ExplorerState(full, params=laav.LaavParams(rv_max_iter=30, rv_trials=2))
    try:
        assert state.wait(120) and state.result is not None
        assert state.load(occl) is not None  # once refused
        assert state.wait(120) and state.error is None
        assert state.sequence is occl and state.result.labels.shape == (80,)
    finally:
        state.close()
    direct = ExplorerState(occl, params=laav.LaavParams(rv_max_iter=30, rv_trials=2))  # once raised
    try:
        assert direct.wait(120) and direct.result is not None and direct.sequence is occl
    finally:
        direct.close()


def test_explorer_upload_of_an_incomplete_file_replaces_the_sequence(tmp_path):
    from explorer import Explorer

    full = make_sequence(1, n_frames=8, n_points=60, rng=2, name="full")
    ex = Explorer(full, params=laav.LaavParams(rv_max_iter=30, rv_trials=2), viser=False)
    try:
        assert ex.wait(120)
        path = tmp_path / "tracks.csv"
        occl, _ = _occluded_scene(path)
        assert ex.load_bytes(path.read_bytes(), "my tracks.csv")  # once refused
        assert ex.wait(120) and not ex.alert.visible
        assert ex.sequence.name == "my_tracks" and not ex.sequence.is_complete
        assert ex.sequence.n_points == 80
        # the frame view: every point at frame 0, only the 60 complete tracks at frame 9
        ex.w_frame.value = 0
        assert len(ex.src_points.data["x"]) == 80
        ex.w_frame.value = 9
        idx = np.asarray(ex.src_points.data["index"])
        assert len(idx) == 60 and ex.sequence.visible[9, idx].all()
        shown = re.sub(r"\\(.)", r"\1", ex.note.object)
        assert "80 tracks over 10 frames, 92.5 % of the entries visible" in shown
        # a complete tracks CSV uploads like any other sequence
        laav.save_sequence(make_sequence(1, n_frames=9, n_points=50, rng=5), tmp_path / "ok.csv")
        assert ex.load_bytes((tmp_path / "ok.csv").read_bytes(), "ok.csv")
        assert ex.wait(120)
        assert ex.sequence.n_points == 50 and ex.sequence.name == "ok"
        assert ex.origin_of(ex.sequence).point_ids is None  # tracks 0..49: numbered by index
        # a tracker's CSV with its own track ids: the labels CSV names the points by them
        ids = 500 + 3 * np.arange(occl.n_points)
        xy = occl.points.tolist()
        rows = ["track,frame,x,y"] + [f"{ids[q]},{f},{xy[f][q][0]!r},{xy[f][q][1]!r}"
                                      for f in range(occl.n_frames) for q in range(occl.n_points)
                                      if occl.visible[f, q]]
        assert ex.load_bytes(("\n".join(rows) + "\n").encode(), "ids.csv") and ex.wait(120)
        assert np.array_equal(ex.origin_of(ex.sequence).point_ids, ids)
        from explorer import export

        table = export.labels_csv(ex.sequence, ex.result, ex.origin_of(ex.sequence).point_ids)
        assert [int(r.split(",")[0]) for r in table.splitlines()[1:]] == ids.tolist()
    finally:
        ex.close()
