"""Uploads (issue 16, items 5 and 8): the size limit (``--max-upload``) checked before any
parsing, empty and too-big files named with their size and the limit, the last good result
kept; long work shows progress and can be cancelled. The browser side (the upload box's own
check, a file past the old websocket limit) is in ``test_explorer_browser.py``."""

from __future__ import annotations

import io
import json
import time
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import hold_computation

import laav

pytest.importorskip("panel")

from explorer import Explorer, cli  # noqa: E402
from explorer.cards import files  # noqa: E402


def send_chunks(ex, name: str, data: bytes, chunk: int = files.UPLOAD_CHUNK, total: int | None = None):
    """Hand ``data`` to the upload box as the browser does: numbered chunks (one more than
    the bytes need, as panel's FileDropper counts). ``total``: claim another count."""
    n = -(-(len(data) + 1) // chunk) if total is None else total
    for i in range(max(n, 1)):
        part = data[i * chunk:(i + 1) * chunk]
        ex.w_upload._process_event(SimpleNamespace(event_name="upload_event", data={
            "name": name, "chunk": i + 1, "total_chunks": n, "data": part}))
        if i * chunk >= len(data) and total is not None:
            break


def _seq(P: int = 60, F: int = 8, seed: int = 0, name: str = "s") -> laav.Sequence:
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, F)[:, None, None]
    a = rng.uniform(0, 300, (1, P // 2, 2)) + t * np.array([40.0, 5.0])
    b = rng.uniform(300, 600, (1, P - P // 2, 2)) + t * np.array([-20.0, 30.0])
    pts = np.concatenate([np.broadcast_to(a, (F, P // 2, 2)), np.broadcast_to(b, (F, P - P // 2, 2))], 1)
    pts = pts + rng.normal(0, 0.3, pts.shape)
    return laav.Sequence(pts, np.r_[np.zeros(P // 2, int), np.ones(P - P // 2, int)], name=name)


def _npz(seq: laav.Sequence, pad: int = 0) -> bytes:
    buf = io.BytesIO()
    extra = {"padding": np.zeros(pad, np.uint8)} if pad else {}
    np.savez(buf, points=seq.points, labels=seq.labels, name=seq.name, **extra)
    return buf.getvalue()


@pytest.fixture
def ex():
    e = Explorer(_seq(), viser=False, max_upload=2_000_000)
    assert e.wait(120)
    yield e
    e.close()


def _alert(ex) -> str:
    return ex.alert.object.replace("\\", "") if ex.alert.visible else ""


@pytest.mark.parametrize("text, n", [("50MB", 50_000_000), ("20 MB", 20_000_000), ("750KB", 750_000),
                                     ("1.5GB", 1_500_000_000), ("20MiB", 20 << 20), ("1000", 1000),
                                     ("2gb", 2_000_000_000)])
def test_sizes_parse(text, n):
    assert files.parse_size(text) == n


@pytest.mark.parametrize("text", ["", "MB", "-5MB", "12XB", "0", "1e9", "five"])
def test_bad_sizes_are_refused(text):
    with pytest.raises(ValueError, match="a size"):
        files.parse_size(text)


def test_sizes_print_like_the_upload_box():
    # (FilePond's own rule: whole kilobytes rounded down, one decimal of a megabyte, two of a
    # gigabyte; the upload box printed 268 KB where a message said 269 KB)
    sizes = (0, 1, 999, 1000, 3_400, 268_900, 999_999, 50_000_000, 61_234_567, 2_100_000_000)
    assert [files.fmt_size(n) for n in sizes] == [
        "0 bytes", "1 byte", "999 bytes", "1 KB", "3 KB", "268 KB", "999 KB", "50 MB", "61.2 MB",
        "2.10 GB"]


def test_cli_max_upload(capsys):
    assert cli.build_parser().parse_args([]).max_upload == files.DEFAULT_MAX_UPLOAD == 50_000_000
    assert cli.build_parser().parse_args(["--max-upload", "20MB"]).max_upload == 20_000_000
    assert cli.main(["--max-upload", "lots", "--no-browser"]) == 2
    assert "--max-upload: a size like 50MB" in capsys.readouterr().err
    # uploads travel in chunks far below the page's websocket message limit
    assert cli.serve_options()["websocket_max_message_size"] >= 4 * files.UPLOAD_CHUNK


def test_too_big_upload_is_refused_before_parsing(ex, monkeypatch):
    res = ex.result
    parsed = []
    monkeypatch.setattr(laav, "load_sequence", lambda *a, **k: parsed.append(a) or 1 / 0)
    # the chunk count of the first chunk already says so: refused at once, later chunks ignored
    big = bytes(3_000_000)
    send_chunks(ex, "big <b>.npz", big)
    assert "big <b>.npz (3 MB) is larger than the upload limit of 2 MB" in _alert(ex)
    assert "--max-upload" in _alert(ex) and "still showing the last valid result" in _alert(ex)
    assert ex.files._parts == {"big <b>.npz": None}
    # a client claiming fewer chunks than it sends is stopped once the bytes pass the limit
    send_chunks(ex, "liar.npz", big, total=3)
    assert "liar.npz is larger than the upload limit of 2 MB" in _alert(ex)
    assert not parsed and ex.wait(10) and ex.result is res
    # the browser's own refusal (reported by the page) is named the same way
    ex.files.w_refused.value = json.dumps({"kind": "too_big", "name": "huge.mat", "size": 61_234_567,
                                           "t": 1})
    assert ("huge.mat (61.2 MB) is larger than the upload limit of 2 MB and was not sent"
            in _alert(ex))
    ex.files.w_refused.value = json.dumps({"kind": "empty", "name": "void.npz", "size": 0, "t": 2})
    assert "void.npz is empty (0 bytes): nothing was loaded" in _alert(ex)
    assert ex.result is res


def test_empty_and_just_fitting_uploads(ex):
    res = ex.result
    send_chunks(ex, "nothing.npz", b"")
    assert "nothing.npz is empty (0 bytes)" in _alert(ex) and ex.result is res
    other = _seq(P=50, seed=4, name="fits")
    base = len(_npz(other, pad=1000)) - 1000  # the zip's own bytes with a padding member
    data = _npz(other, pad=2_000_000 - base)  # exactly the limit, in 3 chunks
    assert len(data) == 2_000_000
    send_chunks(ex, "fits.npz", data)
    assert ex.wait(120) and ex.sequence.name == "fits" and not ex.alert.visible


def test_a_long_first_computation_can_be_cancelled(ex, monkeypatch):
    """A big upload's first computation shows progress; Cancel keeps the last result, says
    so, and the page goes on working."""
    hold_computation(monkeypatch, "big_one")  # long until cancelled, on any machine
    res, shown = ex.result, ex.sequence
    rng = np.random.default_rng(0)  # 3,000 points each moving its own way
    t = np.linspace(0, 1, 30)[:, None, None]
    pts = rng.uniform(0, 500, (1, 3000, 2)) + t * rng.normal(0, 30, (1, 3000, 2))
    big = laav.Sequence(pts, np.r_[np.zeros(1500, int), np.ones(1500, int)], name="big_one")
    cleared = []
    ex.files.clear_box = cleared.append  # (what the page's upload box is told)
    assert ex.files.load_bytes(_npz(big), "big_one.npz")  # read; its computation queued
    text = None
    deadline = time.monotonic() + 30
    while text is None and time.monotonic() < deadline:
        text = ex.files.progress_text()
        time.sleep(0.1)
    assert text is not None
    assert "Computing the first result for **big\\_one** (3,000 points, 30 frames)" in text
    assert ex.controls.switching  # slider moves keep the C of the sequence being loaded
    t0 = time.monotonic()
    assert ex.files.cancel()
    assert ex.wait(20), "the cancelled computation did not stop"
    stopped = time.monotonic() - t0
    assert stopped < 10, stopped
    assert ex.result is res and ex.sequence is shown
    assert cleared == ["big_one.npz"]  # the file whose result will not come leaves the box
    assert ex.note.visible and "Cancelled" in ex.note.object and "big\\_one" in ex.note.object
    assert "still showing s with its last result" in ex.note.object
    assert not ex.controls.switching and not ex.w_motions.disabled and ex.files.progress_text() is None
    assert not ex.files.cancel()  # nothing left to cancel
    ex.w_params["lam"].value = 3.0  # the page still computes, on the shown sequence
    assert ex.wait(120) and ex.result.params.lam == 3.0 and ex.sequence is shown


def test_an_upload_whose_first_computation_fails_leaves_the_box(ex, monkeypatch):
    """A file read fine whose first computation fails is taken out of the upload box (the
    page's list), as an unreadable one is; a file shown stays, whatever fails later."""
    import explorer.state as S

    cleared = []
    monkeypatch.setattr(ex.files, "clear_box", cleared.append)
    res, shown = ex.result, ex.sequence

    class Broken(S.Pipeline):
        def __init__(self, *a, **k):
            raise ValueError("no motion could be found")

    monkeypatch.setattr(S, "Pipeline", Broken)
    assert ex.files.load_bytes(_npz(_seq(P=50, seed=4, name="doomed")), "doomed.npz")
    assert ex.wait(60) and ex.result is res and ex.sequence is shown
    assert "no motion could be found" in _alert(ex)
    assert cleared == ["doomed.npz"]
    monkeypatch.undo()
    monkeypatch.setattr(ex.files, "clear_box", cleared.append)
    assert ex.files.load_bytes(_npz(_seq(P=50, seed=5, name="fine")), "fine.npz")
    assert ex.wait(120) and ex.sequence.name == "fine"
    ex.state.report("a later problem")  # the shown file stays listed
    assert cleared == ["doomed.npz"]


def test_an_upload_cancelled_after_its_preview_leaves_the_box(monkeypatch):
    """With plain RV in LAAV (``with_plain_rv()``), a new sequence's first computation shows
    a preview (LAAV's own trial) while plain RV runs; cancelled then, the preview gives way
    to the last result and the file leaves the upload box."""
    import laav.selection as LS
    from laav._interrupt import check

    e = Explorer(_seq(), params=laav.LaavParams.with_plain_rv(), viser=False, max_upload=2_000_000)
    try:
        assert e.wait(120)
        shown = e.sequence
        cleared = []
        monkeypatch.setattr(e.files, "clear_box", cleared.append)
        real = LS.plain_run

        def slow(*a, **k):  # plain RV inside LAAV: long enough to cancel during the preview
            for _ in range(1200):
                check()
                time.sleep(0.05)
            return real(*a, **k)

        monkeypatch.setattr(LS, "plain_run", slow)
        from laav.synthetic import make_sequence

        up = make_sequence(n_objects=1, n_points=200, n_frames=12, rng=6, name="previewed")
        assert e.files.load_bytes(_npz(up), "previewed.npz")
        deadline = time.monotonic() + 60
        while not (e.previewing and e.sequence.name == "previewed") and time.monotonic() < deadline:
            time.sleep(0.05)
        assert e.previewing and e.sequence.name == "previewed"
        assert cleared == []  # a preview is not a result: still being computed
        assert e.files.cancel() and e.wait(30)
        assert e.sequence is shown and not e.previewing
        assert cleared == ["previewed.npz"]
    finally:
        e.close()


def test_estimating_c_of_an_upload_shows_in_the_progress_line(ex, monkeypatch):
    """An upload without ground truth has its C estimated while it is read (seconds on
    thousands of tracks): the progress line says so; the estimate is then used."""
    import threading

    gate, asked = threading.Event(), threading.Event()
    real = laav.estimate_motions

    def slow(seq, *a, **kw):
        asked.set()
        assert gate.wait(30)
        return real(seq, *a, **kw)

    monkeypatch.setattr(laav, "estimate_motions", slow)
    other = _seq(seed=3, name="bare")
    buf = io.BytesIO()
    np.savez(buf, points=other.points)  # no labels
    token = object()
    ex.files._reading = (token, "bare.npz", 1234, time.monotonic() - 10)  # (as an upload sets it)
    t = threading.Thread(target=ex.files.load_bytes, args=(buf.getvalue(), "bare.npz", token))
    t.start()
    try:
        assert asked.wait(30)
        assert "no ground truth: estimating C" in ex.files.progress_text()
    finally:
        gate.set()
        t.join(60)
    assert ex.wait(120) and ex.sequence.name == "bare"
    assert ex.result.n_motions == real(laav.Sequence(other.points, None)).n_motions
    assert ex.files.progress_text() is None
