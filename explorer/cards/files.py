"""The sidebar's files: the sequence shown, opening another one (or a ``params.json``) by
upload, and the exports (labels CSV, parameters JSON, views PNG; see :mod:`explorer.export`).
"""

from __future__ import annotations

import io
import tempfile
import threading
from pathlib import Path

import panel as pn

import laav

from .. import export
from .. import views as V
from .base import SIDE_W


def seq_text(seq: laav.Sequence) -> str:
    gt = f"{seq.n_motions} motions in the ground truth" if seq.labels is not None else \
        "**no ground truth** (set C below)"
    return f"**{V.md_text(seq.name)}**: {seq.n_points} points, {seq.n_frames} frames, {gt}."


class Files:
    """Upload and export. ``host`` is the app (:meth:`load_params`, :meth:`lock_for_upload`,
    ``schedule``, ``on_server``, the shown ``sequence`` / ``result``); ``controls`` gives C for
    a file without ground truth; ``view`` returns what the PNG shows now:
    ``(frame, colour mode, GAEC step, plain RV run)``."""

    def __init__(self, host, state, controls, status, seq: laav.Sequence, view) -> None:
        self.host, self.state, self.controls, self.status, self._view = host, state, controls, status, view
        self.seq_info = pn.pane.Markdown(seq_text(seq), width=SIDE_W, margin=(0, 10))
        self.w_upload = pn.widgets.FileInput(accept=".mat,.npz,.csv,.json", multiple=False, width=SIDE_W)
        self.w_upload.param.watch(self._on_upload, "value")
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

    def show_sequence(self, seq: laav.Sequence) -> None:
        self.seq_info.object = seq_text(seq)

    def name_downloads(self, seq: laav.Sequence) -> None:
        for w, ext in ((self.w_dl_csv, "labels.csv"), (self.w_dl_json, "params.json"),
                       (self.w_dl_png, "views.png")):
            w.filename = f"{laav.safe_name(seq.name)}_{ext}"

    # ------------------------------------------------------------------ upload
    def _on_upload(self, event=None) -> None:
        data, name = self.w_upload.value, self.w_upload.filename or "upload"
        if data is None:
            return
        if len(data) == 0:
            self.state.report(f"{Path(name).name} is empty (0 bytes): nothing was loaded")
            return
        if data.lstrip()[:1] == b"{":  # a params.json (a sequence file never starts so)
            self.host.load_params(data, name)
            return
        if not self.host.on_server:
            self.load_bytes(data, name)
            return
        self.host.lock_for_upload(True)
        # reading (a MAT file is parsed in a child process) must not block the page
        self.status.show_reading(Path(name).name)
        threading.Thread(target=self.load_bytes, args=(data, name), name="laav-explore-upload",
                         daemon=True).start()

    def load_bytes(self, data: bytes, filename: str) -> bool:
        """Load an uploaded ``.mat`` / ``.npz`` (bytes). Returns False (and shows why) on failure."""
        base = Path(filename).name or "upload"
        C = int(self.controls.w_motions.value or 1)  # read before locking: the C for a file without labels
        self.controls.switching = True
        if not self._load_bytes(data, base, C):
            self.host.schedule(self.host.lock_for_upload, False)
            return False
        return True

    def _load_bytes(self, data: bytes, base: str, C: int) -> bool:
        try:
            with tempfile.TemporaryDirectory(prefix="laav-explore-") as d:
                p = Path(d) / laav.safe_name(base, "upload")
                p.write_bytes(data)
                try:
                    # the format comes from the content, whatever the name says; MAT content
                    # is parsed in a child process (scipy's reader can crash the interpreter
                    # on some damaged files, and an upload must never do that)
                    seq = laav.load_sequence(p, isolated=True)
                    laav.require_complete(seq)  # the last good result stays (issue 14)
                except laav.SequenceError as exc:
                    self.state.report(str(exc).replace(str(p), base)
                                      + " — still showing the last valid result")
                    return False
        except Exception as exc:  # never let an upload kill the session
            self.state.report(f"{base}: could not be read ({type(exc).__name__}: {exc})")
            return False
        return self.state.load(seq, None if seq.labels is not None else C) is not None

    # ------------------------------------------------------------------ exports
    def _need_result(self):
        if self.host.result is None:
            raise RuntimeError("no result yet")
        return self.host.sequence, self.host.result

    def export_csv(self):
        seq, res = self._need_result()
        return io.StringIO(export.labels_csv(seq, res))

    def export_json(self):
        seq, res = self._need_result()
        return io.StringIO(export.params_json(seq, res))

    def export_png(self):
        seq, res = self._need_result()
        frame, mode, step, plain = self._view()
        return io.BytesIO(export.views_png(seq, res, int(frame), mode, int(step), plain))
