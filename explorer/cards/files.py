"""The sidebar's files: the sequence shown, opening another one (or a ``params.json``) by
upload, and the exports (labels CSV, parameters JSON, views PNG; see :mod:`explorer.export`).

Uploads (issue 16, items 5 and 8). The upload box (panel's ``FileDropper``) sends a file in
chunks of :data:`UPLOAD_CHUNK` bytes, so no websocket message grows with the file (the old
single-message upload closed the connection, code 1009, past ~15 MB and left a dead tab).
The size limit (``laav-explore --max-upload``, :data:`DEFAULT_MAX_UPLOAD`) is checked three
times, before anything is parsed: in the browser before sending (the box refuses the file,
and the page names it, its size and the limit), on the server from the first chunk's count
and while the chunks arrive (for a client that skips the browser's check). An empty file
gets its own message. Long work (reading a big file, a first computation, any recompute
past a second) shows a progress line with the elapsed time and a Cancel button; cancelling
keeps the last good result and says so.
"""

from __future__ import annotations

import dataclasses
import io
import json
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import panel as pn

import laav

from .. import export
from .. import views as V
from ..sizes import DEFAULT_MAX_UPLOAD, UPLOAD_CHUNK, fmt_size, parse_size  # noqa: F401 (re-exported)
from ..state import Origin, is_params_json
from .base import SIDE_W, Markdown, page_box, shown_style

#: Work shorter than this shows no progress line (a slider move on a small sequence).
PROGRESS_AFTER = 1.0


class UploadBox(pn.widgets.FileDropper):
    """panel's FileDropper, its chunks handed to ``receiver(name, chunk, n_chunks, data)`` as
    they arrive instead of being collected in ``value`` (the files card counts them against
    the limit and assembles them)."""

    def __init__(self, receiver, **params):
        super().__init__(**params)
        self._receiver = receiver

    def _process_event(self, event) -> None:
        if event.event_name != "upload_event":
            return  # a removed file: nothing is kept here
        d = event.data
        self._receiver(str(d.get("name") or "upload"), int(d.get("chunk", 1)),
                       int(d.get("total_chunks", 1)), d.get("data") or b"")


# Runs in the browser when the server writes ``arm:N`` into the hidden ``w_refused`` box
# (see Files.arm; repeated until the browser answers ``armed``): files the upload box refuses
# (over the limit) or that are empty are reported to the server through that box, so the
# page names them in its alert too; an empty file is removed from the box (it would
# otherwise wait for an upload that never ends). The server writes ``clear:[N, name]`` when
# it has refused a file the box sent, or its read was cancelled: that file leaves the box (it
# said "Upload complete" beside the page's alert that the file was not used); another file
# dropped meanwhile stays.
_ARM_JS = """
const out = cb_obj;  // the page's reports go back through the same box
if (String(cb_obj.value).startsWith('clear:')) {  // a file the server refused (Files.clear_box)
  const name = JSON.parse(String(cb_obj.value).slice(6))[1];
  const view = Bokeh.index.find_one(box);
  const pond = view == null ? null : view._file_pond;
  // an item still queued, loading or being sent (FilePond's status 9, 7, 3; the server may
  // refuse a file before the box has finished with it) is removed once it has, or after 10 s
  const take = (left) => {
    let busy = false;
    for (const item of pond.getFiles()) {
      if (item.filename !== name) continue;
      if (left > 0 && [3, 7, 9].includes(item.status)) busy = true;
      else pond.removeFile(item.id);
    }
    if (busy) setTimeout(() => take(left - 1), 200);
  };
  if (pond != null) take(50);
  return;
}
if (!String(cb_obj.value).startsWith('arm:')) return;
const tries = [0];
const hook = () => {
  const view = Bokeh.index.find_one(box);
  const pond = view == null ? null : view._file_pond;
  if (pond == null) { if (tries[0]++ < 100) setTimeout(hook, 100); return; }
  if (view._laav_armed) { out.value = JSON.stringify({kind: 'armed', t: Date.now()}); return; }
  view._laav_armed = true;
  out.value = JSON.stringify({kind: 'armed', t: Date.now()});
  pond.on('addfile', (error, item) => {
    const say = (kind) => {
      out.value = JSON.stringify({kind: kind, name: item.filename, size: item.fileSize, t: Date.now()});
    };
    if (error) { say('too_big'); }
    else if (item.fileSize === 0) { say('empty'); setTimeout(() => pond.removeFile(item.id), 0); }
  });
};
hook();
"""


def _refusal(message: str, name: str, path: Path) -> str:
    """The page's message for an upload that is not a sequence; for binary content that no
    sequence format has (a video, most likely: :func:`explorer.video.is_video`) it says that
    videos are not tracked in the page (tracking a video takes a while, and an uploaded
    video is never handed to FFmpeg in the server), and how to open one."""
    from laav.track import IMAGE_EXTENSIONS

    from ..video import damaged_sequence, is_video

    if Path(name).suffix.lower() in IMAGE_EXTENSIONS:
        return (f"{name} is an image, not a sequence file (.mat, .npz or tracks .csv): a folder of a "
                f"video's frames opens on the command line, laav-explore FOLDER (it tracks, then "
                "segments) — still showing the last valid result")
    damaged = damaged_sequence(path, name)
    if damaged:  # named as a sequence, and no video either: a damaged one
        return (f"{name} is not a readable {damaged} file: its content is binary and of none of "
                "the sequence formats (MAT, NumPy .npz, tracks CSV) — still showing the last "
                "valid result")
    if is_video(path):
        return (f"{name} is not a sequence file (.mat, .npz or tracks .csv): if it is a video, the page "
                f"does not track uploaded videos — open it with laav-explore {name} on the command line "
                "(it tracks, then segments), or upload the tracks.npz that laav track writes — still "
                "showing the last valid result")
    return message + " — still showing the last valid result"


def seq_text(seq: laav.Sequence) -> str:
    gt = f"{V.counted(seq.n_motions, 'motion')} in the ground truth" if seq.labels is not None else \
        "**no ground truth** (set C below)"
    return f"**{V.md_text(seq.name)}**: {seq.n_points} points, {seq.n_frames} frames, {gt}."


class Files:
    """Upload and export. ``host`` is the app (:meth:`load_params`, :meth:`lock_for_upload`,
    ``schedule``, ``on_server``, the shown ``sequence`` / ``result``); ``controls`` gives C for
    a file without ground truth; ``view`` returns what the PNG shows now:
    ``(frame, colour mode, GAEC step, plain RV run)``."""

    def __init__(self, host, state, controls, status, seq: laav.Sequence, view,
                 max_upload: int = DEFAULT_MAX_UPLOAD) -> None:
        self.host, self.state, self.controls, self.status, self._view = host, state, controls, status, view
        self.max_upload = int(max_upload)
        self.seq_info = Markdown(seq_text(seq), width=SIDE_W, margin=(0, 10))
        # any content: the format is taken from the bytes (the box's type filter would also
        # refuse a .mat whose type the browser does not know)
        self.w_upload = UploadBox(self._receive, multiple=False, chunk_size=UPLOAD_CHUNK,
                                  max_file_size=f"{max(self.max_upload // 1000, 1)}KB",
                                  layout="compact", previews=[], width=SIDE_W, margin=(5, 10))
        self.upload_hint = Markdown(
            f"Up to {fmt_size(self.max_upload)} (`laav-explore --max-upload`).", margin=(0, 10),
            styles={"font-size": "0.85em", "color": "#555"})
        # the browser reports files its upload box refused (see _ARM_JS)
        self.w_refused = page_box(_ARM_JS, args={"box": self.w_upload})
        self.w_refused.param.watch(self._on_refused, "value")
        self._parts: dict = {}  # name -> [chunks, bytes so far] of the upload arriving
        self._upload_lock = threading.Lock()
        self._reading: tuple | None = None  # (token, name, size, t0) of the file being read
        self._estimating = None  # the token of the read whose C is being estimated
        self._work_t0: float | None = None  # since when the state has been busy
        # the progress line of long work (reading, a first computation, a recompute)
        self.progress_md = Markdown("", margin=(4, 6), sizing_mode="stretch_width")
        self.progress_bar = pn.indicators.Progress(value=-1, active=True, width=160, height=14,
                                                   margin=(12, 6), bar_color="primary")
        self.w_cancel = pn.widgets.Button(label="Cancel", color="warning", width=90,
                                          margin=(6, 6))
        self.w_cancel.on_click(self._on_cancel)
        # shown and hidden by its inline style, not ``visible`` (see shown_style)
        self.progress = pn.Row(self.progress_bar, self.progress_md, self.w_cancel,
                               sizing_mode="stretch_width", styles=shown_style(False))
        self._ticker: threading.Thread | None = None
        self._armed, self._arms = False, 0  # the page reports refused files (see arm)
        self._clears = 0  # the server empties the box of a file it refused (clear_box)
        #: (sequence, file name) of an upload read and being computed, until it is shown: a
        #: first computation that fails or is cancelled takes the file out of the box too
        self._opened: tuple | None = None
        self._asking = False  # the state is being asked for the upload (not_opened waits)
        self._opened_lock = threading.Lock()  # (never held while calling out)
        self.w_dl_csv = pn.widgets.FileDownload(callback=self.export_csv, filename="labels.csv",
                                                label="Labels (CSV)", color="primary",
                                                embed=False, width=SIDE_W)
        self.w_dl_json = pn.widgets.FileDownload(callback=self.export_json, filename="params.json",
                                                 label="Parameters (JSON)", color="primary",
                                                 embed=False, width=SIDE_W)
        self.w_dl_png = pn.widgets.FileDownload(callback=self.export_png, filename="views.png",
                                                label="Views (PNG)", color="primary",
                                                embed=False, width=SIDE_W)
        self.downloads = [self.w_dl_csv, self.w_dl_json, self.w_dl_png]
        self.exports_ready(False)  # until the first result is shown (exports_ready)

    def show_sequence(self, seq: laav.Sequence) -> None:
        self.seq_info.object = seq_text(seq)

    def result_shown(self, seq: laav.Sequence) -> None:
        """(Document thread.) A result of ``seq`` is shown (not a preview): an upload of it
        stays in the box."""
        with self._opened_lock:
            if self._opened is not None and self._opened[0] is seq:
                self._opened = None

    def not_opened(self) -> None:
        """(After a failure or a cancel, once the last result is back; and once an upload has
        been asked for.) An upload that was read but whose first result will not come (its
        computation failed or was cancelled: neither shown nor still asked for) leaves the
        box, as a file that could not be read does."""
        with self._opened_lock:
            opened = self._opened
            if opened is None or self._asking:
                return  # (the upload thread checks again once the state has been asked)
        seq = opened[0]
        if self.state.target_sequence is seq or self.host.sequence is seq and not self.host.previewing:
            return
        with self._opened_lock:
            if self._opened is not opened:
                return
            self._opened = None
        self.clear_box(opened[1])

    def exports_ready(self, ready: bool) -> None:
        """(Document thread.) The downloads export the result shown, so they wait (``ready``
        False) before the first result and while a preview is shown: a preview's labels are
        LAAV's own trial's, which the result on its way may change, and neither the CSV nor
        the JSON could say so. Only
        ``disabled`` changes (the status line says what is computing): a tooltip set here
        (``description``) adds a model to the document, and the preview and the result then
        reached the page about 200 ms later (measured in Chromium, demo, two pairs)."""
        for w in self.downloads:
            if w.disabled == ready:
                w.disabled = not ready

    def name_downloads(self, seq: laav.Sequence) -> None:
        for w, ext in ((self.w_dl_csv, "labels.csv"), (self.w_dl_json, "params.json"),
                       (self.w_dl_png, "views.png")):
            w.filename = f"{laav.safe_name(seq.name)}_{ext}"

    # ------------------------------------------------------------------ upload
    def arm(self) -> None:
        """(Document thread, once the page is on screen.) Let the browser report the files
        its upload box refuses (asked again every 2 s until the page answers: a request
        sent before the page had its widgets would go unseen), and start the progress
        line's clock."""
        if not self._armed:
            self._arms += 1
            self.w_refused.value = f"arm:{self._arms}"
        if self._ticker is None:
            self._ticker = threading.Thread(target=self._tick, name="laav-explore-progress", daemon=True)
            self._ticker.start()

    def _on_refused(self, event) -> None:
        try:
            d = json.loads(event.new) if str(event.new).startswith("{") else None
            if d.get("kind") == "armed":
                self._armed = True
                return
            name, size = Path(str(d["name"])).name or "upload", int(d["size"])
        except (ValueError, TypeError, KeyError, AttributeError):
            return
        if d.get("kind") == "empty":
            self._refuse_empty(name)
        else:
            self._refuse_big(name, size, sent=False)

    def clear_box(self, name: str) -> None:
        """(Any thread.) Take the file ``name`` out of the page's upload box: it was not used."""
        if self.host.on_server:
            self.host.schedule(self._clear_box_now, name)

    def _clear_box_now(self, name: str) -> None:
        self._clears += 1
        self.w_refused.value = "clear:" + json.dumps([self._clears, name])

    def _refuse_empty(self, name: str) -> None:
        self.state.report(f"{name} is empty (0 bytes): nothing was loaded — still showing the last "
                          "valid result")

    def _refuse_big(self, name: str, size: int | None, sent: bool = True) -> None:
        what = f"{name} ({fmt_size(size)})" if size is not None else name
        if sent:
            self.clear_box(name)
        self.state.report(f"{what} is larger than the upload limit of {fmt_size(self.max_upload)}"
                          f"{'' if sent else ' and was not sent'} (start laav-explore with a larger "
                          "--max-upload to open it) — still showing the last valid result")

    def _receive(self, name: str, chunk: int, total: int, data) -> None:
        """One chunk of an upload (the document's thread). Counted against the limit as it
        arrives: an upload over it is dropped at once, before anything is parsed."""
        with self._upload_lock:
            if chunk == 1:
                self._parts[name] = [[], 0]
                if (total - 1) * UPLOAD_CHUNK > self.max_upload:  # the count alone says so
                    self._parts[name] = None
                    self._refuse_big(name, (total - 1) * UPLOAD_CHUNK)
                    return
            part = self._parts.get(name)
            if part is None:
                return  # refused, or its first chunk never came
            part[0].append(bytes(data))
            part[1] += len(data)
            if part[1] > self.max_upload:
                self._parts[name] = None
                self._refuse_big(name, None)
                return
            if chunk < total:
                return
            del self._parts[name]
        self.receive(b"".join(part[0]), name)

    def receive(self, data: bytes, name: str) -> None:
        """A whole uploaded file: a params.json, or a sequence read in the background."""
        name = name or "upload"
        if isinstance(data, str):
            data = data.encode("utf-8")
        if len(data) == 0:
            self._refuse_empty(Path(name).name)
            return
        if len(data) > self.max_upload:
            self._refuse_big(Path(name).name, len(data))
            return
        if is_params_json(data[:4096]):
            if not self.host.load_params(data, name):
                self.clear_box(Path(name).name)
            return
        if not self.host.on_server:
            self.load_bytes(data, name)
            return
        self.host.lock_for_upload(True)
        # reading (a MAT file is parsed in a child process) must not block the page
        self.status.show_reading(Path(name).name)
        token = object()
        self._reading = (token, Path(name).name, len(data), time.monotonic())
        threading.Thread(target=self._read_upload, args=(token, data, name), name="laav-explore-upload",
                         daemon=True).start()

    def _read_upload(self, token, data: bytes, name: str) -> None:
        self.load_bytes(data, name, token)

    def load_bytes(self, data: bytes, filename: str, token=None) -> bool:
        """Load an uploaded ``.mat`` / ``.npz`` (bytes). Returns False (and shows why) on failure.
        ``token``: the upload's (see :meth:`cancel`); a cancelled read's sequence is dropped."""
        base = Path(filename).name or "upload"
        # the C for a file without labels: the state's (the box may show a value it refused)
        C = self.state.target.n_motions
        self.controls.switching = True
        if not self._load_bytes(data, base, C, token):
            if token is None or self._end_reading(token):
                self.host.schedule(self.host.lock_for_upload, False)
                self.clear_box(base)  # (a cancelled read's file left the box at the cancel)
            return False
        return True

    def _end_reading(self, token) -> bool:
        """The read of ``token`` is over; False when it had been cancelled meanwhile."""
        with self._upload_lock:
            if self._reading is None or self._reading[0] is not token:
                return False
            self._reading = None
        return True

    def _load_bytes(self, data: bytes, base: str, C: int, token=None) -> bool:
        try:
            with tempfile.TemporaryDirectory(prefix="laav-explore-") as d:
                p = Path(d) / laav.safe_name(base, "upload")
                p.write_bytes(data)
                try:
                    # the format comes from the content, whatever the name says; MAT content
                    # is parsed in a child process (scipy's reader can crash the interpreter
                    # on some damaged files, and an upload must never do that)
                    seq = laav.load_sequence(p, isolated=True)  # incomplete tracks too
                    # a tracks CSV's own track ids, for the labels CSV (read while the file is here)
                    ids = laav.io.point_numbers(seq)
                    ids = None if np.array_equal(ids, np.arange(seq.n_points)) else ids
                    # named by the file the user gave, not this temporary copy (later
                    # messages, e.g. of the computation, name the sequence's source)
                    seq = dataclasses.replace(seq, source=base)
                except laav.SequenceError as exc:
                    if token is None or self._reading is not None and self._reading[0] is token:
                        self.state.report(_refusal(str(exc).replace(str(p), base), base, p))
                    return False
        except Exception as exc:  # never let an upload kill the session
            self.state.report(f"{base}: could not be read ({type(exc).__name__}: {exc})")
            return False
        self._estimating = token
        try:  # without ground truth C is estimated, as by the command (a second or a few)
            origin = dataclasses.replace(_estimated_motions(seq), point_ids=ids)
        finally:
            self._estimating = None
        if origin.motions_estimate is not None:
            C = origin.motions_estimate
        if token is not None and not self._end_reading(token):
            return False  # cancelled while reading: the shown result stays
        self.host.add_origin(seq, origin)
        with self._opened_lock:  # (not_opened waits until the state has been asked for it)
            self._opened, self._asking = (seq, base), True
        try:
            asked = self.state.load(seq, None if seq.labels is not None else C) is not None
        finally:
            with self._opened_lock:
                self._asking = False
                if not asked:  # refused at once (load_bytes' caller takes it out of the box)
                    self._opened = None
        if asked:
            self.not_opened()  # its computation may have failed already
        return asked

    # ------------------------------------------------------------------ progress and cancel
    def _tick(self) -> None:
        """Twice a second: the progress line (shown once work has lasted PROGRESS_AFTER)."""
        shown = False
        n = 0
        while not self.state.closed:
            n += 1
            try:
                if not self._armed and self.host.on_server and n % 4 == 0:
                    self.host.schedule(self.arm)
                busy = self.state.busy
                if busy and self._work_t0 is None:
                    self._work_t0 = time.monotonic()
                elif not busy:
                    self._work_t0 = None
                text = self.progress_text()
                if text is not None or shown:
                    shown = text is not None
                    self.host.schedule(self._show_progress, text)
            except Exception:  # the clock must keep going
                import traceback
                traceback.print_exc()
            time.sleep(0.5)

    def progress_text(self) -> str | None:
        """What the progress line says now (None: nothing long is going on)."""
        now = time.monotonic()
        reading = self._reading
        if reading is not None:
            _, name, size, t0 = reading
            if now - t0 < PROGRESS_AFTER:
                return None
            doing = " — no ground truth: estimating C" if self._estimating is reading[0] else ""
            return f"Reading **{V.md_text(name)}** ({fmt_size(size)}){doing}… {now - t0:.0f} s"
        t0 = self._work_t0
        if t0 is None or now - t0 < PROGRESS_AFTER or not self.state.busy:
            return None
        seq = self.state.target_sequence
        if seq is not self.host.sequence or self.host.result is None:
            what = (f"Computing the first result for **{V.md_text(seq.name)}** ({seq.n_points:,} points, "
                    f"{seq.n_frames} frames)")
        else:
            what = "Recomputing"
        return f"{what}… {now - t0:.0f} s"

    def _show_progress(self, text: str | None) -> None:
        if text is not None:
            text = self.progress_text()  # now, on the document's thread: the work may be over
        if text is None:
            self.show_progress(False)
            return
        self.progress_md.object = text
        self.show_progress(True)

    def show_progress(self, shown: bool) -> None:
        """Show or hide the progress line (by its style: :func:`~.base.shown_style`)."""
        self.progress.styles = shown_style(shown)

    def _on_cancel(self, event=None) -> None:
        self.cancel()

    def cancel(self) -> bool:
        """Stop the read or computation going on: the last good result stays, and the page
        says so. Returns False when there was nothing to cancel."""
        seq = self.state.target_sequence
        what = ("the recomputation" if seq is self.host.sequence and self.host.result is not None
                else f"the first computation of {seq.name}")
        with self._upload_lock:
            reading, self._reading = self._reading, None
        stopped = self.state.cancel()
        if reading is None and not stopped:
            return False
        if reading is not None:
            what = f"reading {reading[1]}"
            self.clear_box(reading[1])
        shown = self.host.sequence.name if self.host.result is not None else None
        self.host.schedule(self._after_cancel, what, shown)
        return True

    def _after_cancel(self, what: str, shown: str | None) -> None:
        """(Document thread.) Controls back to the shown result's settings, and a note."""
        self.host.lock_for_upload(False)
        self.controls.switching = False
        self.host.restore_result()  # a preview shown gives way to the last result
        self.not_opened()
        self.controls.show_settings(self.state.settings)
        self.show_progress(False)
        self._work_t0 = None
        self.status.show_last()
        cancelled = (f"**Cancelled** {V.md_text(what)}"
                     + (f" — still showing {V.md_text(shown)} with its last result." if shown else "."))
        self.host.show_notes(cancelled)  # the notes about the data shown stay

    # ------------------------------------------------------------------ exports
    def _need_result(self):
        if self.host.result is None:
            raise RuntimeError("no result yet")
        if self.host.previewing:  # (a click sent just before the buttons were disabled)
            raise RuntimeError("a preview is shown: the exports wait for the result")
        return self.host.sequence, self.host.result

    def export_csv(self):
        seq, res = self._need_result()
        return io.StringIO(export.labels_csv(seq, res, self.host.origin_of(seq).point_ids))

    def export_json(self):
        seq, res = self._need_result()
        return io.StringIO(export.params_json(seq, res))

    def export_png(self):
        seq, res = self._need_result()
        frame, mode, step, plain = self._view()
        return io.BytesIO(export.views_png(seq, res, int(frame), mode, int(step), plain))


def _estimated_motions(seq: laav.Sequence) -> Origin:
    """An opened file's :class:`Origin`: for one without ground truth, C estimated as
    ``laav-explore FILE`` does (:func:`laav.estimate_motions`; when it cannot be, the C box's
    value is used and the page says so)."""
    if seq.labels is not None:
        return Origin()
    try:
        count = laav.estimate_motions(seq)
    except Exception:  # noqa: BLE001 - never let an upload hang on "Reading": the C box's value
        return Origin()
    return Origin(count.n_motions, count.explain())
