"""The sequence formats with missing data: KT3DMoSeg ``.mat``, ``.npz`` with ``visible``,
tracks CSV; exact round trips, content sniffing, and hostile files.

Every bad file must raise :class:`laav.SequenceError` whose one-line message names the file.
"""

from __future__ import annotations

import io
import zipfile
from pathlib import Path

import numpy as np
import pytest
import scipy.io
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from laav import Sequence, SequenceError, load_sequence, save_sequence

PROPERTY = settings(max_examples=40, deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


def _occluded(seed=0, frames=7, points=16, motions=3, missing=0.35, scale=700.0, name="occl",
              image_size=(640, 480)) -> Sequence:
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-0.1, 1.0, size=(frames, points, 2)) * scale
    vis = rng.random((frames, points)) > missing
    vis[0] = True  # every point in frame 0 and one other: at least 2 frames each
    vis[1 + rng.integers(0, frames - 1, points), np.arange(points)] = True
    vis[:, 0] = True  # and every frame holds a point
    labels = None
    if motions:
        labels = np.r_[np.arange(motions), rng.integers(0, motions, points - motions)]
    return Sequence(pts, labels=labels, visible=vis, name=name, image_size=image_size)


def _same(a: Sequence, b: Sequence, name=True) -> None:
    assert a.points.shape == b.points.shape
    assert np.array_equal(a.visible, b.visible)
    assert np.array_equal(a.points, b.points, equal_nan=True)  # bit for bit where visible
    assert (a.labels is None) == (b.labels is None)
    if a.labels is not None:
        assert np.array_equal(a.labels, b.labels) and b.labels.dtype == np.int64
    if name:
        assert a.name == b.name


def _error(path, match=None, **kw) -> str:
    with pytest.raises(SequenceError) as exc:
        load_sequence(path, **kw)
    msg = str(exc.value)
    assert str(path) in msg, f"message does not name {path}: {msg}"
    assert "\n" not in msg
    if match is not None:
        assert match in msg, msg
    return msg


# --------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
@pytest.mark.parametrize("motions", [3, None], ids=["labels", "no-labels"])
@pytest.mark.parametrize("fmt,file", [("npz", "occl.npz"), ("kt3d", "occl_Tracks.mat"),
                                      ("csv", "occl.csv")])
def test_round_trip_with_missing_entries(tmp_path, fmt, file, motions, isolated):
    seq = _occluded(motions=motions)
    assert 0.5 < seq.visible_share < 0.9
    path = save_sequence(seq, tmp_path / file)
    back = load_sequence(path, isolated=isolated)
    _same(seq, back)
    if fmt == "csv":
        assert back.image_size is None  # documented: a CSV does not carry it
    else:
        assert back.image_size == (640, 480)
    again = load_sequence(save_sequence(back, tmp_path / ("again_" + file)))
    _same(back, again, name=False)


def test_hopkins_round_trip_and_refusal_of_missing_entries(tmp_path):
    seq = _occluded(points=30, missing=0.1)
    full, kept = seq.complete()
    back = load_sequence(save_sequence(full, tmp_path / "full_truth.mat"))
    _same(full, back, name=False)
    assert back.is_complete and back.name == "full"
    with pytest.raises(SequenceError, match=r"x\.mat: the Hopkins155 format cannot hold missing"):
        save_sequence(seq, tmp_path / "x.mat", format="hopkins")
    # .mat without a format: Hopkins when complete, KT3DMoSeg when not
    assert "Data" not in scipy.io.whosmat(str(tmp_path / "full_truth.mat"))[0][0]
    save_sequence(seq, tmp_path / "auto.mat")
    assert [v[0] for v in scipy.io.whosmat(str(tmp_path / "auto.mat"))] == ["Data", "width", "height"]
    _same(seq, load_sequence(tmp_path / "auto.mat"), name=False)


def test_chain_through_every_format_is_exact(tmp_path):
    seq = _occluded(seed=5, frames=9, points=25)
    cur = seq
    for i, file in enumerate(["a.csv", "b.npz", "c.mat", "d.csv", "e.npz"]):
        cur = load_sequence(save_sequence(cur, tmp_path / f"{i}{file}"))
        _same(seq, cur, name=False)


@PROPERTY
@given(frames=st.integers(2, 9), points=st.integers(8, 30), seed=st.integers(0, 2**32 - 1),
       missing=st.floats(0.0, 0.8), scale=st.sampled_from([1e-3, 1.0, 640.0, 1e7]),
       fmt=st.sampled_from(["csv", "kt3d", "npz"]), motions=st.sampled_from([None, 1, 2, 4]))
def test_round_trip_property(tmp_path_factory, frames, points, seed, missing, scale, fmt, motions):
    seq = _occluded(seed, frames, points, motions, missing, scale, image_size=None)
    d = tmp_path_factory.mktemp("rt")
    back = load_sequence(save_sequence(seq, d / "s.x", format=fmt))
    _same(seq, back, name=False)


def test_format_comes_from_the_content_not_the_extension(tmp_path):
    seq = _occluded()
    for fmt, file in (("csv", "tracks.npz"), ("kt3d", "tracks.csv"), ("npz", "tracks.mat")):
        _same(seq, load_sequence(save_sequence(seq, tmp_path / file, format=fmt)), name=False)


def test_unknown_format_and_extension(tmp_path):
    seq = _occluded()
    with pytest.raises(SequenceError, match="unknown format 'mp4'"):
        save_sequence(seq, tmp_path / "a.npz", format="mp4")
    with pytest.raises(SequenceError, match=r"a\.txt: unknown extension"):
        save_sequence(seq, tmp_path / "a.txt")


def test_csv_cannot_write_an_empty_frame(tmp_path):
    rng = np.random.default_rng(0)
    vis = np.ones((4, 10), bool)
    vis[2] = False
    seq = Sequence(rng.uniform(0, 9, (4, 10, 2)), visible=vis)
    with pytest.raises(SequenceError, match=r"e\.csv: frame\(s\) 2 have no visible point"):
        save_sequence(seq, tmp_path / "e.csv")
    _same(seq, load_sequence(save_sequence(seq, tmp_path / "e.npz")), name=False)


# --------------------------------------------------------------------------- KT3DMoSeg


def _kt3d_file(path, P=12, F=5, seed=0, junk=np.nan, **fields):
    """A file laid out like the published KT3DMoSeg ``<clip>_Tracks.mat``."""
    rng = np.random.default_rng(seed)
    vis = rng.random((P, F)) > 0.3
    vis[:, :2] = True
    y = np.ones((3, P, F))
    y[:2] = rng.uniform(0, 1200, (2, P, F))
    y[:, ~vis] = junk
    data = {"ySparse": y, "visibleSparse": vis, "GtLabel": (np.arange(P) % 2 + 1.0).reshape(-1, 1),
            "K": np.eye(3), "nFrames": float(F), "nSparsePoints": float(P),
            "Other": np.array(["ignored"], dtype=object)}
    data.update(fields)
    data = {k: v for k, v in data.items() if v is not None}
    scipy.io.savemat(str(path), {"Data": data}, format="5")
    return y, vis


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
@pytest.mark.parametrize("junk", [np.nan, 0.0, 1e308], ids=["nan", "zero", "huge"])
def test_kt3d_published_layout(tmp_path, isolated, junk):
    path = tmp_path / "seq005_Clip01_Tracks.mat"
    y, vis = _kt3d_file(path, junk=junk)
    seq = load_sequence(path, isolated=isolated)
    assert seq.name == "seq005_Clip01"
    assert seq.points.shape == (5, 12, 2)
    assert np.array_equal(seq.visible, vis.T)
    assert np.array_equal(seq.points[vis.T], np.transpose(y[:2], (2, 1, 0))[vis.T])
    assert np.isnan(seq.points[~vis.T]).all()
    assert np.array_equal(seq.labels, np.arange(12) % 2)


def test_kt3d_divides_by_the_homogeneous_row_and_needs_no_mask_or_labels(tmp_path):
    path = tmp_path / "h.mat"
    rng = np.random.default_rng(1)
    y = rng.uniform(1, 100, (3, 10, 4))
    scipy.io.savemat(str(path), {"Data": {"ySparse": y}})
    seq = load_sequence(path)
    assert seq.is_complete and seq.labels is None
    assert np.allclose(seq.points, np.transpose(y[:2] / y[2], (2, 1, 0)), rtol=1e-15)


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
@pytest.mark.parametrize("case,fields,expect", [
    ("no ySparse", {"ySparse": None}, "has no field 'ySparse'"),
    ("ySparse 2-D", {"ySparse": np.ones((3, 12))}, "Data.ySparse must have shape 3 x P x F"),
    ("ySparse 4 rows", {"ySparse": np.ones((4, 12, 5))}, "Data.ySparse must have shape 3 x P x F"),
    ("ySparse text", {"ySparse": np.array(["a", "b"], dtype=object)}, "Data.ySparse is not numeric"),
    ("ySparse complex", {"ySparse": np.ones((3, 12, 5)) * 1j}, "must be real numbers"),
    ("mask transposed", {"visibleSparse": np.ones((5, 12), bool)}, "Data.visibleSparse must have shape"),
    ("mask values", {"visibleSparse": np.full((12, 5), 2.0)}, "only 0 and 1"),
    ("labels 0-based", {"GtLabel": np.arange(12.0)}, "labels 1..K"),
    ("labels too few", {"GtLabel": np.ones(5)}, "5 labels for 12 points"),
    ("labels gap", {"GtLabel": np.r_[np.ones(6), np.full(6, 3.0)]},
     "Data.GtLabel has no point with motion label(s) [2] (1-based labels must be 1..3"),
])
def test_kt3d_bad_fields(tmp_path, isolated, case, fields, expect):
    path = tmp_path / "bad_Tracks.mat"
    _kt3d_file(path, **fields)
    _error(path, expect, isolated=isolated)


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
def test_kt3d_nan_or_zero_where_visible(tmp_path, isolated):
    path = tmp_path / "n_Tracks.mat"
    y, vis = _kt3d_file(path)
    y[0, 3, 1] = np.nan
    scipy.io.savemat(str(path), {"Data": {"ySparse": y, "visibleSparse": vis}})
    _error(path, "1 point(s) have NaN or infinite coordinates in Data.ySparse where", isolated=isolated)
    y[0, 3, 1] = 5.0
    y[2, 4, 0] = 0.0
    scipy.io.savemat(str(path), {"Data": {"ySparse": y, "visibleSparse": vis}})
    _error(path, "zero homogeneous coordinate where visible", isolated=isolated)


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
def test_kt3d_data_that_is_not_one_struct(tmp_path, isolated):
    path = tmp_path / "d.mat"
    scipy.io.savemat(str(path), {"Data": np.ones((3, 4))})
    _error(path, "variable 'Data' is not a struct", isolated=isolated)
    one = {"ySparse": np.ones((3, 10, 3))}
    arr = np.empty((1, 2), dtype=[("ySparse", object)])
    arr[0, 0]["ySparse"] = one["ySparse"]
    arr[0, 1]["ySparse"] = one["ySparse"]
    scipy.io.savemat(str(path), {"Data": arr})
    _error(path, "must be one struct", isolated=isolated)
    scipy.io.savemat(str(path), {"Other": np.ones(3)})
    _error(path, "missing variable 'y'", isolated=isolated)


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
def test_kt3d_over_the_limits(tmp_path, isolated):
    path = tmp_path / "big_Tracks.mat"
    _kt3d_file(path, P=40)
    _error(path, "40 points exceed the limit of 20", isolated=isolated, max_points=20)
    _error(path, "over the limit of 1,000 bytes", isolated=isolated, max_bytes=1000)


# --------------------------------------------------------------------------- tracks CSV


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def _tracker_csv(rows_per_track=3, tracks=9, stride=5, first=100, sep=",", label=True) -> str:
    """A tracker's CSV: ids not from 0, frames with a stride, rows in frame order, 1-based labels."""
    head = sep.join(["frame", "track", "x", "y", "score"] + (["label"] if label else []))
    lines = [head]
    for f in range(rows_per_track):
        for t in range(tracks):
            row = [str(first + stride * f), str(10 * t + 7), f"{t + 0.5 * f}", f"{2.0 * t - f}", "0.9"]
            lines.append(sep.join(row + ([str(1 + t % 3)] if label else [])))
    return "\n".join(lines) + "\n"


def test_csv_as_trackers_write_it(tmp_path):
    seq = load_sequence(_write(tmp_path / "cam.csv", _tracker_csv()))
    assert seq.n_frames == 3 and seq.n_points == 9 and seq.is_complete  # no empty frames from the stride
    assert np.array_equal(seq.points[:, 4], [[4.0, 8.0], [4.5, 7.0], [5.0, 6.0]])  # track 47
    assert np.array_equal(seq.labels, np.arange(9) % 3)  # 1..3 renumbered 0..2
    assert seq.name == "cam"


@pytest.mark.parametrize("variant", ["semicolon", "tab", "bom-quoted-crlf", "no-label"])
def test_csv_dialects(tmp_path, variant):
    text = _tracker_csv(sep={"semicolon": ";", "tab": "\t"}.get(variant, ","),
                        label=variant != "no-label")
    if variant == "bom-quoted-crlf":
        head, rest = text.split("\n", 1)
        text = "\ufeff" + ",".join(f'"{c.upper()}"' for c in head.split(",")) + "\n" + rest
        text = text.replace("\n", "\r\n")
    seq = load_sequence(_write(tmp_path / "d.csv", text))
    assert seq.points.shape == (3, 9, 2)
    assert np.array_equal(seq.points[2, 1], [2.0, 0.0])
    assert (seq.labels is None) == (variant == "no-label")


def test_csv_gaps_become_missing_entries(tmp_path):
    text = "track,frame,x,y\n" + "".join(
        f"{t},{f},{t}.5,{f}.25\n" for t in range(10) for f in range(6) if (t + f) % 4 or f < 2)
    seq = load_sequence(_write(tmp_path / "g.csv", text))
    expect = np.array([[(t + f) % 4 != 0 or f < 2 for t in range(10)] for f in range(6)])
    assert np.array_equal(seq.visible, expect)
    assert seq.points[5, 4].tolist() == [4.5, 5.25]
    assert np.isnan(seq.points[2, 2]).all()


@pytest.mark.parametrize("isolated", [False, True], ids=["here", "isolated"])
@pytest.mark.parametrize("case,text,expect", [
    ("duplicate", "track,frame,x,y\n" + "".join(f"{t},{f},1,2\n" for t in range(9) for f in range(2))
     + "4,1,3,3\n", "track 4 has two rows for frame 1 (data rows 10 and 19)"),
    ("x text", "track,frame,x,y\n0,0,1,2\n0,1,abc,2\n", "could not convert string 'abc' to float64 "
     "in column 'x' of data row 2"),
    ("track text", "track,frame,x,y\ncar,0,1,2\n", "in column 'track' of data row 1"),
    ("empty field", "track,frame,x,y,label\n0,0,1,2,\n", "in column 'label' of data row 1"),
    ("short row", "track,frame,x,y\n0,0,1,2\n0,1,3\n", "data row 2 has only 3 fields: every "
     "row needs a value for each column the header names"),
    ("fractional frame", "track,frame,x,y\n0,0,1,2\n0,1.5,1,2\n", "column 'frame' must hold whole "
     "numbers, got 1.5 on data row 2"),
    ("huge track id", "track,frame,x,y\n1e300,0,1,2\n", "column 'track' must hold whole numbers of "
     "magnitude at most 2**53, got 1e+300 on data row 1"),
    ("nan x", "track,frame,x,y\n0,0,1,2\n0,1,nan,2\n", "NaN or infinite coordinate on data row 2 (a track "
     "not seen in a frame has no row"),
    ("inf y", "track,frame,x,y\n0,0,1,2\n0,1,1,-inf\n", "NaN or infinite coordinate on data row 2"),
    ("label changes", "track,frame,x,y,label\n0,0,1,2,1\n0,1,1,2,1\n0,2,1,2,2\n",
     "track 0 has labels 1 and 2 (data row 3)"),
    ("negative label", "track,frame,x,y,label\n0,0,1,2,-1\n0,1,1,2,-1\n", "must be non-negative"),
    ("single observation", "track,frame,x,y\n" + "".join(f"{t},{f},{t},{f}\n" for t in range(9)
                                                          for f in range(2)) + "42,0,1,1\n",
     "1 track(s) have a single observation (track 42)"),
    ("header only", "track,frame,x,y\n", "has a header but no observations"),
    ("no header", "0,0,1,2\n0,1,1,2\n", "a CSV file without the tracks header"),
    ("header missing y", "track,frame,x,z\n0,0,1,2\n", "must name the columns track,frame,x,y"),
    ("header twice", "track,frame,x,y,x\n0,0,1,2,3\n", "names column(s) ['x'] twice"),
    ("few points", "track,frame,x,y\n" + "".join(f"{t},{f},{t},{f}\n" for t in range(3)
                                                  for f in range(2)), "needs at least 8 points"),
    ("bad utf-8", "track,frame,x,y\n0,0,1,2\n", "bad tracks CSV"),
])
def test_csv_hostile(tmp_path, isolated, case, text, expect):
    path = _write(tmp_path / "t.csv", text)
    if case == "bad utf-8":
        path.write_bytes(text.encode() + b"0,1,\xff\xfe,2\n")
    _error(path, expect, isolated=isolated)


def test_csv_limits_checked_before_allocating(tmp_path):
    # 600 tracks, each seen twice, in frames all different: a dense (1200, 600) grid
    text = "track,frame,x,y\n" + "".join(f"{t},{2 * t + k},1,2\n" for t in range(600) for k in range(2))
    path = _write(tmp_path / "sparse.csv", text)
    msg = _error(path, "over the limit of 1,000,000 bytes", max_bytes=1_000_000)
    assert "12,240,000" in msg  # 17 bytes x 1200 frames x 600 points, declared, not allocated
    _error(path, "600 points exceed the limit of 500", max_points=500)
    _error(path, "bytes is over the limit of 2,500 bytes for a tracks CSV", max_bytes=10_000)
    assert load_sequence(path).visible_share == pytest.approx(2 / 1200)


def test_text_that_is_no_csv_still_says_unrecognised(tmp_path):
    msg = _error(_write(tmp_path / "notes.csv", "hello world\nno separators here\n"), "unrecognised content")
    assert "laav track" not in msg


def test_a_video_or_a_folder_of_frames_points_to_laav_track(tmp_path):
    """Given to the sequence loader (laav segment), a video or a folder of frames is refused
    with the command that reads it."""
    clip = tmp_path / "clip.mp4"
    clip.write_bytes(b"\x00\x00\x00\x20ftypisom\x00\x00\x02\x00isomiso2avc1mp41" + bytes(200))
    _error(clip, "a video is tracked first: laav track VIDEO")
    frames = tmp_path / "frames"
    frames.mkdir()
    for k in range(3):
        (frames / f"{k}.png").write_bytes(b"\x89PNG")
    _error(frames, "a folder of video frames is tracked first: laav track FOLDER")
    # other binary content (an image, a pickle) gets no such hint
    png = tmp_path / "frame.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(100))
    assert "laav track" not in _error(png, "unrecognised content")
    for head in (b"RIFF\x00\x00\x00\x00AVI LIST", b"\x1a\x45\xdf\xa3\x01\x00", b"OggS\x00\x02"):
        other = tmp_path / "clip.bin"
        other.write_bytes(head + bytes(100))
        _error(other, "a video is tracked first")
    empty = tmp_path / "empty"
    empty.mkdir()
    msg = _error(empty, "holds no sequence files; expected exactly one (a *_truth.mat, or one .mat")
    assert "laav track" not in msg


# --------------------------------------------------------------------------- npz with visible


def _npz(path, **arrays):
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def test_npz_visible_checks(tmp_path):
    seq = _occluded()
    pts = np.nan_to_num(seq.points)
    _error(_npz(tmp_path / "a.npz", points=pts, visible=seq.visible.T), "visible must have shape")
    _error(_npz(tmp_path / "b.npz", points=pts, visible=np.full(seq.visible.shape, "x")),
           "visible must be a bool")
    bad = seq.points.copy()
    bad[seq.visible] = np.nan
    _error(_npz(tmp_path / "c.npz", points=bad, visible=seq.visible),
           "NaN or infinite coordinates in frames where they are visible")
    vis = seq.visible.copy()
    vis[1:, 5] = False
    vis[0, 5] = True
    _error(_npz(tmp_path / "d.npz", points=pts, visible=vis), "visible in fewer than 2 frames (points 5)")
    # hidden entries may hold anything
    junk = np.where(seq.visible[..., None], seq.points, 1e300)
    _same(seq, load_sequence(_npz(tmp_path / "e.npz", points=junk, visible=seq.visible,
                                  labels=seq.labels)), name=False)


def test_npz_huge_declared_visible_is_refused_before_reading(tmp_path):
    seq = _occluded()
    path = tmp_path / "bomb.npz"
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "|b1", "fortran_order": False,
                                               "shape": (100_000, 100_000)})
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("points.npy", _npy(seq.points))
        zf.writestr("visible.npy", buf.getvalue())  # 10 GB declared, no data
    declared = 100_000 * 100_000 + seq.points.nbytes
    _error(path, f"its arrays declare {declared:,} bytes, over the limit")


def _npy(a) -> bytes:
    buf = io.BytesIO()
    np.save(buf, a)
    return buf.getvalue()


def test_load_sequence_reads_the_image_size_laav_track_writes(tmp_path):
    from laav.track import Tracks, save_tracks

    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 300, (6, 20, 2))
    vis = np.ones((6, 20), bool)
    p = save_tracks(Tracks(pts, vis, "clip", np.arange(0, 12, 2), (640, 480)), tmp_path / "t.npz")
    seq = load_sequence(p)
    assert seq.image_size == (640, 480) and seq.name == "clip"
    unknown = save_tracks(Tracks(pts, vis, "clip", np.arange(6), (0, 0)), tmp_path / "u.npz")
    assert load_sequence(unknown).image_size is None
    bad = tmp_path / "bad.npz"
    np.savez(bad, points=pts, image_size=np.array([640.5, 480.0]))
    with pytest.raises(SequenceError, match=r"bad\.npz.*image_size"):
        load_sequence(bad)
