"""``laav-explore VIDEO``: a video or a folder of frames is tracked, every track the tracker
keeps is segmented (incomplete ones included; ``--complete-only``: the full ones), and the
frame view draws the video's frames behind the points.

The project's synthetic clip (``assets/two_objects/``: 24 frames of 320 x 240 px and the mask
of every frame) says which object lies under every pixel, so the frames' placement under the
points is checked against the truth (and in Chromium by ``test_explorer_browser``).
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2")
pn = pytest.importorskip("panel")

from conftest import FakeServer  # noqa: E402

import laav  # noqa: E402
from explorer import Explorer  # noqa: E402
from explorer.cli import main  # noqa: E402
from explorer.video import MAX_WIDTH, FrameCache, VideoError, is_video, open_video  # noqa: E402
from laav.synthetic_video import load_clip, render_clip  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
CLIP = REPO / "assets" / "two_objects"


@pytest.fixture(scope="module")
def clip():
    return load_clip(CLIP)


@pytest.fixture(scope="module")
def video():
    return open_video(CLIP, progress=False)


def _write_video(path: Path, frames, fps: int = 10) -> Path:
    h, w = frames[0].shape[:2]
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h), False)
    if not out.isOpened():
        pytest.skip("this OpenCV build cannot write MJPG")
    for f in frames:
        out.write(f)
    out.release()
    return path


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _blank_folder(tmp_path: Path, n: int = 4) -> Path:
    d = tmp_path / "blank"
    d.mkdir()
    for i in range(n):
        cv2.imwrite(str(d / f"{i}.png"), np.full((60, 80), 128, np.uint8))
    return d


# ---------------------------------------------------------------------------- telling videos apart
def test_is_video_tells_videos_and_frames_from_sequence_files(tmp_path):
    assert is_video(CLIP)  # a folder of PNGs (its truth.npz is not a sequence)
    avi = _write_video(tmp_path / "clip.avi", render_clip(0).frames[:3])
    assert is_video(avi) and is_video(avi.rename(tmp_path / "clip.csv"))  # content, not name
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(np.random.default_rng(0).bytes(4000) + b"\0")
    assert is_video(junk)  # binary, no sequence format: the tracker's message will say it
    assert is_video(tmp_path / "img_%04d.png")  # an image-sequence pattern OpenCV reads
    seq = laav.Sequence(np.random.default_rng(0).uniform(0, 100, (3, 10, 2)), name="s")
    for ext in ("npz", "csv", "mat"):
        p = laav.save_sequence(seq, tmp_path / f"s.{ext}")
        assert not is_video(p), ext
        assert not is_video(p.rename(tmp_path / f"s_{ext}.mp4")), ext  # the name does not matter
    hop = tmp_path / "hop"
    hop.mkdir()
    laav.save_sequence(seq, hop / "x_truth.mat")
    cv2.imwrite(str(hop / "frame.png"), np.zeros((8, 8), np.uint8))
    assert not is_video(hop)  # a Hopkins155 folder with its images stays a sequence
    (tmp_path / "empty").mkdir()
    assert not is_video(tmp_path / "empty") and not is_video(tmp_path / "missing.mp4")
    (tmp_path / "notes.txt").write_text("track,frame,x,y\n")
    assert not is_video(tmp_path / "notes.txt")


# ---------------------------------------------------------------------------- the frame cache
def test_frame_cache_downscales_and_keeps_the_placement():
    fc = FrameCache(max_width=640)
    big = np.zeros((720, 1280), np.uint8)
    big[:, 640:] = 200
    for t in range(3):
        fc.add(t, big)
    assert fc.image_size == (1280, 720) and fc.shape == (360, 640) and fc.n_kept == 3
    img = fc.get(1)
    assert img.shape == (360, 640) and img.dtype == np.uint8 and not img.flags.writeable
    assert img[:, :320].max() == 0 and img[:, 320:].min() == 200  # the half split stays at x = 640
    assert fc.nbytes == 3 * 640 * 360
    assert fc.placement == {"x": -0.5, "y": -0.5, "dw": 1280.0, "dh": 720.0}
    # the full frame's pixel centres: (0, 0) -> (0, 0), (1279, 719) -> (639, 359), x = 639.6 -> col 320
    r, c = fc.pixel([0, 1279, 639.6], [0, 719, 0])
    assert r.tolist() == [0, 359, 0] and c.tolist() == [0, 639, 320]
    small = FrameCache()
    small.add(0, np.zeros((240, 320, 3), np.uint8))  # colour, narrower than MAX_WIDTH: kept as is, grey
    assert small.shape == (240, 320) and small.get(0).ndim == 2
    with pytest.raises(ValueError, match="the first was 320x240"):
        small.add(1, np.zeros((100, 100), np.uint8))
    hd = FrameCache()  # by default as wide as the frame view: one image pixel per screen pixel
    hd.add(0, big)
    assert MAX_WIDTH == 410 and hd.shape == (231, 410)


def test_frame_cache_memory_stays_bounded_for_a_long_video():
    one = 640 * 360
    fc = FrameCache(max_width=640, max_bytes=10 * one)  # room for 10 frames
    frame = np.zeros((720, 1280), np.uint8)
    for t in range(100):
        fc.add(t, frame)
        assert fc.nbytes <= 10 * one
    assert fc.n_seen == 100 and fc.step == 16 and fc.n_kept == 7  # 0, 16, ..., 96
    assert fc.get(0) is not None and fc.get(96) is not None and fc.get(1) is None and fc.get(8) is None
    assert "one frame in 16 (memory bound)" in fc.describe()


def test_the_kept_frames_lie_under_their_tracked_points(clip, video):
    """Frames coded by layer (0 background, 1 rectangle, 2 disc), downscaled 2x: the pixel
    :meth:`FrameCache.pixel` finds under a complete track is its true layer's."""
    fc = FrameCache(max_width=160)
    for t, m in enumerate(clip.masks):
        fc.add(t, m.astype(np.uint8) * 100)
    seq = video.sequence.complete()[0]  # the tracks seen in every frame
    tracks_vis = np.ones((seq.n_frames, seq.n_points), bool)
    labels, _ = clip.track_truth(seq.points, tracks_vis)
    assert np.bincount(labels, minlength=3).min() >= 10  # every object has complete tracks
    hits, flipped = [], []
    for t in range(0, seq.n_frames, 4):
        img = fc.get(t)
        x, y = seq.points[t, :, 0], seq.points[t, :, 1]
        r, c = fc.pixel(x, y)
        hits.append(img[r, c] == labels * 100)
        flipped.append(img[fc.shape[0] - 1 - r, c] == labels * 100)  # a y-flipped image
    hits, flipped, lab = np.concatenate(hits), np.concatenate(flipped), np.tile(labels, len(range(0, 24, 4)))
    per_object = [hits[lab == k].mean() for k in range(3)]
    # misses: points on an object's edge, where the downscaled pixel mixes two layers
    assert min(per_object) >= 0.9 and hits.mean() >= 0.97, per_object
    assert min(flipped[lab == k].mean() for k in range(3)) < 0.5  # the check sees a flipped image


# ---------------------------------------------------------------------------- tracking for the explorer
def test_open_video_keeps_every_track_and_estimates_c(video):
    """Every track laav track keeps (once only the complete ones); C estimated on the tracks
    seen in every frame; ``complete_only`` still keeps only those."""
    from laav.track import track

    seq = video.sequence
    tracks = track(CLIP, progress=False)  # laav track itself, its own filters
    assert not seq.is_complete and seq.labels is None and seq.image_size == (320, 240)
    assert seq.n_frames == 24 and seq.n_points == video.n_tracks == tracks.n_tracks
    assert np.array_equal(video.kept, np.arange(tracks.n_tracks))
    assert np.array_equal(seq.visible, tracks.visible)
    n_full = int(tracks.visible.all(axis=0).sum())
    assert 0 < n_full < seq.n_points
    assert video.n_motions == 3 and video.motion_count is not None  # background, rectangle, disc
    reason = video.motion_count.reason
    assert f"estimated on the {n_full} of {seq.n_points} tracks seen in every frame" in reason
    assert video.frames.n_kept == 24 and video.frames.shape == (240, 320)
    assert np.array_equal(video.frames.get(5), cv2.imread(str(CLIP / "frame_005.png"), cv2.IMREAD_GRAYSCALE))
    text = video.summary()
    assert (f"{video.n_tracks} tracks over 24 frames; all {seq.n_points} kept, "
            f"{100 * seq.visible_share:.1f} % of the track x frame entries visible ({n_full} tracks seen "
            "in every frame") in text
    assert "C = 3 estimated" in text
    # how far an estimate goes, as the page says for a tracks file (not for a C given)
    from explorer.state import ESTIMATE_NOTE

    assert text.endswith(ESTIMATE_NOTE)
    # another C from the C box: said, the caveat about the estimate no longer
    other = video.summary(4)
    assert other.endswith("C = 4 is taken from the C box.") and ESTIMATE_NOTE not in other
    full = open_video(CLIP, 3, progress=False, complete_only=True)
    assert full.sequence.is_complete and full.sequence.n_points == n_full == full.kept.size
    summary = full.summary()
    assert f"kept {n_full} of the {full.n_tracks}, those seen in every frame (--complete-only" in summary
    given = open_video(CLIP, 2, progress=False, track_options={"stride": 2})
    assert given.n_motions == 2 and given.motion_count is None and given.sequence.n_frames == 12
    assert "C = 2 as given" in given.summary() and ESTIMATE_NOTE not in given.summary()


@pytest.mark.parametrize("case, needle", [
    ("junk", "cannot open this video"),
    ("blank", "no features found"),
    ("short", "shorter than the minimum length of 30 frames"),
    ("too_many_motions", "fewer than the 1600 LAAV needs for C = 200"),
])
def test_open_video_refuses_with_one_line(tmp_path, case, needle):
    kw = {"progress": False}
    path = CLIP
    if case == "junk":
        path = tmp_path / "junk.mp4"
        path.write_bytes(np.random.default_rng(0).bytes(4000))
    elif case == "blank":
        path = _blank_folder(tmp_path)
    elif case == "short":
        kw["track_options"] = {"min_length": 30}
    else:
        kw["n_motions"] = 200
    with pytest.raises(VideoError) as err:
        open_video(path, **kw)
    assert needle in str(err.value) and "\n" not in str(err.value)


def test_explorer_from_file_tracks_a_video_and_draws_its_frames(tmp_path):
    ex = Explorer.from_file(CLIP, viser=False, progress=False)
    try:
        assert ex.wait(120)
        fv = ex.frame_view
        frames = ex.video.frames
        assert ex.state.settings.n_motions == 3 and ex.sequence is ex.video.sequence
        assert fv.w_background.visible and fv.w_background.value and fv.r_background.visible
        assert fv.fig.frame_width == MAX_WIDTH  # the frames are kept as wide as the view shows them
        assert fv.src_background.data["image"][0] is frames.get(0)
        assert {k: fv.src_background.data[k] for k in ("x", "y", "dw", "dh")} == \
            {"x": [-0.5], "y": [-0.5], "dw": [320.0], "dh": [240.0]}
        note = re.sub(r"\\(.)", r"\1", ex.note.object)
        assert f"all {ex.sequence.n_points} kept" in note and "% of the track x frame entries visible" in note
        assert "Behind the points" in fv.caption.object
        # scrubbing: the background follows the frame, and only its image column is sent
        sent = []
        fv.src_background.on_change("data", lambda attr, old, new: sent.append(set(new)))
        t0 = time.perf_counter()
        ex.w_frame.value = 7
        ms = 1000 * (time.perf_counter() - t0)
        assert fv.src_background.data["image"][0] is frames.get(7)
        assert ms < 500  # server side, measured ~2-4 ms; generous for a loaded machine
        # the toggle hides it (nothing sent) and shows it again at the current frame
        fv.w_background.value = False
        assert not fv.r_background.visible and "hidden" in fv.caption.object
        ex.w_frame.value = 9
        assert fv.src_background.data["image"][0] is frames.get(7)
        fv.w_background.value = True
        assert fv.r_background.visible and fv.src_background.data["image"][0] is frames.get(9)
        # another C than the estimate: off its default in the status line, said in the note
        assert "All settings at their defaults" in ex.status.object
        ex.w_motions.value = 4
        assert ex.wait(120) and ex.result.n_motions == 4
        assert "C = 4" in re.sub(r"\\(.)", r"\1", ex.status.object), ex.status.object
        assert "C = 4 is taken from the C box" in re.sub(r"\\(.)", r"\1", ex.note.object)
        ex.w_motions.value = 3
        assert ex.wait(120) and "All settings at their defaults" in ex.status.object
        # another sequence (an upload) has no video behind it
        other = laav.save_sequence(laav.Sequence(ex.sequence.complete()[0].points[:, :40], name="plain"),
                                   tmp_path / "plain.npz")
        assert ex.load_bytes(other.read_bytes(), "plain.npz") and ex.wait(120)
        assert ex.sequence.name == "plain" and not fv.r_background.visible
        assert not fv.w_background.visible
    finally:
        ex.close()


def test_a_video_uploaded_to_the_page_is_refused_with_a_clear_message(tmp_path):
    from conftest import two_motion_sequence

    ex = Explorer(two_motion_sequence(0, P=60, F=8, name="shown"), viser=False)
    try:
        assert ex.wait(120)
        data = _write_video(tmp_path / "clip.avi", render_clip(0).frames[:4]).read_bytes()
        assert not ex.load_bytes(data, "clip.avi")
        msg = ex.state.error
        assert "does not track uploaded videos" in msg and "laav-explore clip.avi" in msg
        assert ex.sequence.name == "shown"
        # a single image is no video: the message says what to open instead
        import cv2

        ok, png = cv2.imencode(".png", render_clip(0).frames[0])
        assert ok and not ex.load_bytes(png.tobytes(), "frame.png")
        msg = ex.state.error
        assert "frame.png is an image, not a sequence file" in msg and "laav-explore FOLDER" in msg
        assert "if it is a video" not in msg and ex.sequence.name == "shown"
    finally:
        ex.close()


# ---------------------------------------------------------------------------- the command
def test_cli_tracks_a_folder_of_frames_then_serves_it(monkeypatch, capsys):
    import explorer.cli as cli

    seen = {}
    real_factory = cli.app_factory

    def factory(seq, n_motions, seed=0, host="127.0.0.1", **kw):
        seen.update(seq=seq, n_motions=n_motions, video=kw.get("video"))
        kw["prebuild"] = False
        return real_factory(seq, n_motions, seed, host, **kw)

    monkeypatch.setattr(cli, "app_factory", factory)
    monkeypatch.setattr(pn, "serve", lambda panels, **kw: seen.update(title=kw["title"]) or FakeServer())
    assert main([str(CLIP), "--no-browser", "--port", "0", "--stride", "2", "--track-points", "400"]) == 0
    out = capsys.readouterr().out
    v = seen["video"]
    assert v is not None and seen["seq"] is v.sequence and seen["n_motions"] == v.n_motions
    assert v.sequence.n_frames == 12 and v.frames.n_kept == 12 and v.options["max_points"] == 400
    assert re.search(r"tracked \d+ tracks over 12 frames in [\d.]+ s; keeping all of them, [\d.]+ % of the "
                     r"entries visible \(\d+ tracks seen in every frame\)", out)
    assert v.sequence.n_points == v.n_tracks
    assert f"C = {v.n_motions} (" in out and "12 frames of 320x240 kept at 320x240 grey" in out
    assert f"two_objects ({v.sequence.n_points} points, 12 frames, C = {v.n_motions}) at http://" in out
    assert main([str(CLIP), "--no-browser", "--port", "0", "--motions", "2", "--max-frames", "10"]) == 0
    assert seen["n_motions"] == 2 and seen["video"].motion_count is None
    assert seen["seq"].n_frames == 10
    # the whole clip, every track (laav-explore assets/two_objects): incomplete tracks kept
    from laav.track import track

    tracks = track(CLIP, progress=False)
    assert main([str(CLIP), "--no-browser", "--port", "0"]) == 0
    out = capsys.readouterr().out
    seq = seen["seq"]
    assert seq is seen["video"].sequence and seq.n_points == tracks.n_tracks and not seq.is_complete
    assert np.array_equal(seq.visible, tracks.visible) and seen["n_motions"] == 3
    share = 100 * seq.visible_share
    assert f"keeping all of them, {share:.1f} % of the entries visible" in out
    # --complete-only: only the tracks seen in every frame
    assert main([str(CLIP), "--no-browser", "--port", "0", "--complete-only", "--motions", "3"]) == 0
    assert seen["seq"].is_complete and seen["seq"].n_points == int(tracks.visible.all(axis=0).sum())
    assert "those seen in every frame (--complete-only)" in capsys.readouterr().out


@pytest.mark.parametrize("case, needle", [
    ("junk", "cannot open this video (not a format OpenCV reads)"),
    ("blank", "no features found"),
    ("short", "shorter than the minimum length of 30 frames"),
    ("too_many_motions", "fewer than the 1600 LAAV needs for C = 200"),
])
def test_cli_bad_video_exits_2_with_one_line(tmp_path, capsys, monkeypatch, case, needle):
    monkeypatch.setattr(pn, "serve", lambda *a, **k: pytest.fail("no server for a bad video"))
    args = [str(CLIP)]
    if case == "junk":
        bad = tmp_path / "junk.mp4"
        bad.write_bytes(np.random.default_rng(0).bytes(4000))
        args = [str(bad)]
    elif case == "blank":
        args = [str(_blank_folder(tmp_path))]
    elif case == "short":
        args += ["--min-length", "30"]
    else:
        args += ["--motions", "200"]
    assert main([*args, "--no-browser", "--port", "0"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("laav-explore: error: ") and needle in err, err


def test_cli_serves_a_video_file(tmp_path):
    """The real command on a video file: it tracks, prints its address, serves the page."""
    video = _write_video(tmp_path / "clip.avi", render_clip(0).frames)
    port = _free_port()
    proc = subprocess.Popen([sys.executable, "-m", "explorer.cli", str(video), "--no-browser",
                             "--port", str(port)], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        lines = []
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            if " at http://" in line:
                break
        out = "".join(lines)
        assert "tracked " in out and "kept at 320x240 grey" in out, out
        assert f"at http://127.0.0.1:{port}/" in out, out
        page = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=120).read().decode()
        assert "LAAV explorer" in page
    finally:
        proc.terminate()
        proc.wait(30)


def test_cli_undecodable_video_in_a_process_is_one_line(tmp_path):
    # FFmpeg's and OpenCV's own log lines are silenced: stderr is exactly our one line
    bad = tmp_path / "junk.mp4"
    bad.write_bytes(np.random.default_rng(1).bytes(4000))
    proc = subprocess.run([sys.executable, "-m", "explorer.cli", str(bad), "--no-browser"], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [f"laav-explore: error: {bad}: cannot open this video "
                                        "(not a format OpenCV reads)"]


def test_cli_damaged_sequence_file_and_params_file_are_named_as_such(tmp_path):
    """Binary content of no sequence format named .npz is a damaged .npz (not only "cannot
    open this video"); a params.json given as FILE says to pass it with --params."""
    from explorer.cards.files import _refusal
    from explorer.video import damaged_sequence

    bad = tmp_path / "tracks.npz"
    bad.write_bytes(b"xx\0" + np.random.default_rng(1).bytes(4000))
    proc = subprocess.run([sys.executable, "-m", "explorer.cli", str(bad), "--no-browser"], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [f"laav-explore: error: {bad}: not a readable .npz file "
                                        "(binary content of no sequence format, and no video's "
                                        "either)"]
    params = tmp_path / "p.json"
    params.write_bytes(b'\xef\xbb\xbf  {"r1": 25}')  # (a byte-order mark, as some editors save)
    proc = subprocess.run([sys.executable, "-m", "explorer.cli", str(params), "--no-browser"], cwd=REPO,
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == [f"laav-explore: error: {params}: a params file (JSON), not a "
                                        f"sequence: give the sequence as FILE and this with --params "
                                        f"{params}"]
    # the page's message for the same upload
    msg = _refusal("unused", "tracks.npz", bad)
    assert msg.startswith("tracks.npz is not a readable .npz file") and "video" not in msg
    junk = tmp_path / "clip.mp4"
    junk.write_bytes(bad.read_bytes())
    assert "if it is a video" in _refusal("unused", "clip.mp4", junk)
    # a real video under a sequence's name is a video still: tracked on the command line,
    # and the page says how to open it (content decides, not the name)
    avi = _write_video(tmp_path / "clip.avi", render_clip(0).frames[:3]).rename(tmp_path / "clip.csv")
    assert damaged_sequence(avi) is None and damaged_sequence(bad) == ".npz"
    assert "laav-explore clip.csv on the command line" in _refusal("unused", "clip.csv", avi)
