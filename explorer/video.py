"""A video (or a folder of frames) in the explorer: track it, keep its tracks, pick C,
and keep small copies of the frames to draw behind the points.

``laav-explore VIDEO`` and ``Explorer.from_file(VIDEO)`` call :func:`open_video`, which runs
:func:`laav.track.track` (the same tracker and options as ``laav track``), keeps every track
that passes the tracker's own filters, incomplete ones included (LAAV's stages handle missing
data, issue 14; ``complete_only`` keeps only the tracks seen in every tracked frame, what
``--complete-only`` does for a file), takes C from the caller or estimates it
(:func:`laav.estimate_motions`), and gathers the frames as the tracker reads them, so the
video is decoded once. Tracking runs before the page exists (a progress bar on a terminal,
or in the notebook cell), so the page never waits on a half-tracked video.

:class:`FrameCache` holds the frames for the frame view: grey (as tracked), downscaled to at
most :data:`MAX_WIDTH` px wide (the frame view's width), one byte per pixel, at most
:data:`MAX_BYTES` in all (every other frame is dropped when a long video would exceed it).
Shared by every browser tab of one ``laav-explore`` process: filled once, only read afterwards.

No GUI code here (numpy, and OpenCV to resize, which tracking needs anyway).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import laav

__all__ = ["FrameCache", "Video", "VideoError", "is_video", "open_video", "MAX_WIDTH", "MAX_BYTES",
           "POINTS_PER_MOTION"]

#: Widest frame kept (px): the frame view's width (``explorer/cards/frame.py``), so that at the
#: default zoom one image pixel is one screen pixel; wider videos are downscaled to it. Sending
#: more pixels costs a frame move more in the browser and shows nothing more (bokeh draws
#: images without smoothing): measured in docs/bench/explorer_video.md.
MAX_WIDTH = 410
#: Most bytes the kept frames take together: 48 MB, 369 frames of 16:9 video at 410 x 231
#: (37 MB for 300 frames), 284 frames of 4:3 at 410 x 308.
MAX_BYTES = 48_000_000
#: Tracks LAAV needs per motion (the 8-point algorithm fits each motion's fundamental
#: matrices; ``laav.estimate_motions`` asks for two motions' worth of complete tracks).
POINTS_PER_MOTION = laav.MIN_POINTS

_ZIP, _MAT, _HDF5 = b"PK\x03\x04", b"MATLAB", b"\x89HDF\r\n\x1a\n"
#: The sequence files' names (:func:`damaged_sequence`).
SEQUENCE_SUFFIXES = (".mat", ".npz", ".csv")


def damaged_sequence(path, name=None) -> str | None:
    """The suffix (``".npz"``, ...) when ``path`` is named as a sequence file (``name``, else
    its own name) but its content is binary of no sequence format (:func:`is_video`) and no
    common video container's either (:func:`laav.io.looks_like_video`): a damaged file, which
    the messages call so instead of "cannot open this video". A real video under such a name
    is still a video (content decides). None otherwise."""
    from laav.io import looks_like_video

    suffix = Path(name if name is not None else path).suffix.lower()
    if suffix not in SEQUENCE_SUFFIXES or not is_video(path):
        return None
    try:
        with open(path, "rb") as fh:
            head = fh.read(16)
    except OSError:
        return None
    return None if looks_like_video(head) else suffix


class VideoError(ValueError):
    """A video that cannot be used: unreadable, no features, too few tracks for C.
    The message is one line and names the video."""


def is_video(path) -> bool:
    """Whether ``laav-explore`` reads ``path`` as a video (or a folder of frames) rather than a
    sequence file, by content, not by name.

    A folder is frames when it holds image files (:data:`laav.track.IMAGE_EXTENSIONS`) and no
    Hopkins155 ``*_truth.mat``. A file is a video when its first KB is binary (a NUL byte)
    and not a MAT, NPZ (zip) or HDF5 file: every sequence format is one of those or text
    (tracks CSV). A missing path is a video only as an image-sequence pattern
    (``img_%04d.png``, which OpenCV reads). Everything else goes to
    :func:`laav.load_sequence`, whose messages say what is wrong with it.
    """
    from laav.track import IMAGE_EXTENSIONS

    p = Path(path)
    try:
        if p.is_dir():
            if any(p.glob("*_truth.mat")):
                return False
            return any(f.suffix.lower() in IMAGE_EXTENSIONS and f.is_file() for f in p.iterdir())
        if not p.is_file():
            return "%" in p.name
        with open(p, "rb") as fh:
            head = fh.read(1024)
    except OSError:
        return False
    if not head or head.startswith((_ZIP, _MAT)) or _HDF5 in head[:520]:
        return False
    return b"\x00" in head


class FrameCache:
    """Small grey copies of the tracked frames, to draw behind the points.

    ``add(t, image)`` (the tracker's ``on_frame`` hook) keeps frame ``t`` downscaled
    (``cv2.INTER_AREA``) to at most ``max_width`` px wide, uint8. When the frames kept would
    take more than ``max_bytes``, every other one is dropped and from then on only every
    2nd (4th, ...) frame is kept (:attr:`step`): memory stays bounded whatever the video's
    length, and :meth:`get` returns None for a frame not kept.

    Coordinates are the points': x = column, y = row of the full-size frame, pixel centres
    at integers. Whatever its size, a kept image spans x in [-0.5, W - 0.5] and y in
    [-0.5, H - 0.5] of the full frame (:attr:`placement`); :meth:`pixel` finds the pixel of
    the small image under a point. Row 0 is the top of the image (y = -0.5).
    """

    def __init__(self, max_width: int = MAX_WIDTH, max_bytes: int = MAX_BYTES) -> None:
        if max_width < 1 or max_bytes < 1:
            raise ValueError("max_width and max_bytes must be positive")
        self.max_width = int(max_width)
        self.max_bytes = int(max_bytes)
        self.image_size: tuple[int, int] | None = None  # (W, H) of the full frames
        self.shape: tuple[int, int] | None = None  # (h, w) of the kept images
        self.step = 1
        self.n_seen = 0
        self._frames: dict[int, np.ndarray] = {}

    def add(self, t: int, image: np.ndarray) -> None:
        """Keep tracked frame ``t`` (grey uint8 (H, W), or colour BGR (H, W, 3))."""
        import cv2

        img = np.asarray(image)
        if img.ndim == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        if img.ndim != 2:
            raise ValueError(f"a frame must be a (H, W) image, got shape {img.shape}")
        if img.dtype != np.uint8:
            img = np.clip(img, 0, 255).astype(np.uint8)
        H, W = img.shape
        if self.image_size is None:
            w = min(W, self.max_width)
            h = max(1, int(round(H * w / W)))
            self.image_size, self.shape = (W, H), (h, w)
        elif (W, H) != self.image_size:
            raise ValueError(f"frame {t} is {W}x{H}, the first was {self.image_size[0]}x{self.image_size[1]}")
        self.n_seen = max(self.n_seen, int(t) + 1)
        if t % self.step:
            return
        h, w = self.shape
        small = img.copy() if (h, w) == (H, W) else cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)
        small.flags.writeable = False
        self._frames[int(t)] = small
        while self.nbytes > self.max_bytes and len(self._frames) > 1:
            self.step *= 2
            self._frames = {k: v for k, v in self._frames.items() if k % self.step == 0}

    def get(self, t: int) -> np.ndarray | None:
        """The kept image of tracked frame ``t`` ((h, w) uint8, read-only), or None."""
        return self._frames.get(int(t))

    @property
    def n_kept(self) -> int:
        return len(self._frames)

    @property
    def nbytes(self) -> int:
        return sum(v.nbytes for v in self._frames.values())

    @property
    def placement(self) -> dict:
        """Where a kept image goes, in the points' coordinates: ``x, y`` (its corner at row 0,
        column 0: the top left) and its width and height ``dw, dh``."""
        W, H = self.image_size
        return {"x": -0.5, "y": -0.5, "dw": float(W), "dh": float(H)}

    def pixel(self, x, y) -> tuple[np.ndarray, np.ndarray]:
        """(row, column) of the kept image's pixel under the points ``(x, y)`` (arrays)."""
        (W, H), (h, w) = self.image_size, self.shape
        col = np.floor((np.asarray(x, dtype=float) + 0.5) * w / W).astype(np.int64)
        row = np.floor((np.asarray(y, dtype=float) + 0.5) * h / H).astype(np.int64)
        return np.clip(row, 0, h - 1), np.clip(col, 0, w - 1)

    def describe(self) -> str:
        """One line: what is kept and its memory."""
        if self.image_size is None:
            return "no frames"
        (W, H), (h, w) = self.image_size, self.shape
        every = "every frame" if self.step == 1 else f"one frame in {self.step} (memory bound)"
        return (f"{self.n_kept} frames of {W}x{H} kept at {w}x{h} grey, {every}, "
                f"{self.nbytes / 1e6:.1f} MB")


@dataclass(frozen=True, eq=False)
class Video:
    """A tracked video, ready for the explorer.

    Attributes
    ----------
    sequence : laav.Sequence
        The tracks kept (no ground truth), image size set; incomplete unless
        ``complete_only`` (``visible`` says where each is seen).
    n_motions : int
        C: the caller's, or estimated (``motion_count``).
    frames : FrameCache
    source : str
        The video's path as given.
    n_tracks : int
        Tracks the tracker kept (seen in at least its minimum length of frames).
    kept : ndarray
        Indices of the kept tracks among them (all of them unless ``complete_only``).
    motion_count : laav.MotionCount or None
        The estimate of C (None: C was given).
    track_seconds : float
    """

    sequence: laav.Sequence
    n_motions: int
    frames: FrameCache
    source: str
    n_tracks: int
    kept: np.ndarray
    motion_count: object = None
    track_seconds: float = 0.0
    options: dict = field(default_factory=dict)
    complete_only: bool = False

    def summary(self, n_motions: int | None = None) -> str:
        """What was done, in plain text (the page shows it as text); ``n_motions``: the C in
        use, when the C box changed it from the one estimated or given here."""
        seq = self.sequence
        if self.motion_count is not None:
            why = f"C = {self.n_motions} estimated by laav.estimate_motions ({self.motion_count.explain()})"
        else:
            why = f"C = {self.n_motions} as given"
        src = Path(self.source)
        what = f"the frames in the folder {src.name}" if src.is_dir() else f"the video {src.name}"
        head = (f"{seq.name} was tracked from {what} (laav track): {self.n_tracks} tracks over "
                f"{seq.n_frames} frames; ")
        if self.complete_only:
            kept = (f"kept {seq.n_points} of the {self.n_tracks}, those seen in every frame "
                    f"(--complete-only; "
                    f"the other {self.n_tracks - seq.n_points} start late, end early or have gaps)")
        else:
            n_full = int(np.count_nonzero(seq.visible.all(axis=0)))
            kept = (f"all {seq.n_points} kept, {100 * seq.visible_share:.1f} % of the track x frame entries "
                    f"visible ({n_full} tracks seen in every frame; a point is drawn only where it is seen)")
        if n_motions is not None and n_motions != self.n_motions:
            return f"{head}{kept}; {why}; C = {n_motions} is taken from the C box."
        if self.motion_count is None:
            return f"{head}{kept}; {why}."
        from .state import ESTIMATE_NOTE  # (how far an estimate goes, as for a tracks file)

        return f"{head}{kept}; {why}. {ESTIMATE_NOTE}"


def open_video(path, n_motions: int | None = None, *, track_options: dict | None = None,
               progress: bool | None = None, max_points: int | None = None,
               max_width: int = MAX_WIDTH, max_bytes: int = MAX_BYTES,
               log: Callable[[str], None] | None = None, complete_only: bool = False) -> Video:
    """Track a video (or a folder of frames) for the explorer.

    Parameters
    ----------
    path : str or path-like
        Anything :func:`laav.track.track` reads.
    n_motions : int, optional
        C; None (or ``"auto"``) estimates it with :func:`laav.estimate_motions`.
    track_options : dict, optional
        Keyword arguments of :func:`laav.track.track` (``laav.cli.track_options`` of the
        command line).
    progress : bool or None
        The tracker's progress bar (None: only when stderr is a terminal).
    max_points : int, optional
        Refuse more tracks than this (``laav-explore --max-points``).
    complete_only : bool
        Keep only the tracks seen in every tracked frame (``--complete-only``); by default
        every track the tracker kept (its own filters: minimum length and the rest).
    log : callable, optional
        Called with a line of text at every step (the command prints them).

    Raises
    ------
    VideoError
        One line naming the video: it cannot be opened, holds no features, every track is
        too short, or too few tracks are kept for C (or, to estimate C, too few are seen in
        every frame).
    """
    from laav.track import TrackError, track

    say = log or (lambda text: None)
    src = str(path)
    auto = n_motions is None or n_motions == "auto"
    if not auto and (isinstance(n_motions, bool) or int(n_motions) < 1):
        raise VideoError(f"the number of motions must be a positive integer or 'auto', got {n_motions!r}")
    frames = FrameCache(max_width, max_bytes)
    opts = dict(track_options or {})
    say(f"tracking {src} ...")
    t0 = time.perf_counter()
    try:
        tracks = track(path, **opts, progress=progress, on_frame=frames.add)
    except TrackError as exc:
        raise VideoError(str(exc)) from None
    seconds = time.perf_counter() - t0
    F, n = tracks.n_frames, tracks.n_tracks
    kept = tracks.complete() if complete_only else np.arange(n, dtype=np.int64)
    share = 100.0 * float(np.count_nonzero(tracks.visible)) / max(tracks.visible.size, 1)
    if complete_only:
        say(f"tracked {n} tracks over {F} frames in {seconds:.1f} s; keeping {kept.size} of them, those seen "
            "in every frame (--complete-only)")
    else:
        say(f"tracked {n} tracks over {F} frames in {seconds:.1f} s; keeping all of them, {share:.1f} % of "
            f"the entries visible ({tracks.complete().size} tracks seen in every frame)")
    need = POINTS_PER_MOTION * (2 if auto else int(n_motions))
    if kept.size < need:
        what = "to estimate the number of motions (two motions' worth)" if auto else \
            f"for C = {int(n_motions)}"
        which = f"are seen in all {F} tracked frames" if complete_only else "were kept"
        raise VideoError(
            f"{src}: only {kept.size} of the {n} tracks {which}, fewer than the {need} LAAV needs {what} "
            f"({POINTS_PER_MOTION} per motion): track fewer frames (--max-frames, --stride) or more points "
            "(--max-points)")
    if max_points is not None and kept.size > max_points:
        raise VideoError(f"{src}: {kept.size} tracks, more than --max-points {max_points}")
    vis = tracks.visible[:, kept]
    try:
        seq = laav.Sequence(points=tracks.points[:, kept], name=tracks.name, image_size=tracks.image_size,
                            source=src, visible=None if vis.all() else vis)
    except laav.SequenceError as exc:
        raise VideoError(str(exc)) from None
    count = None
    if auto:
        say("estimating the number of motions ...")
        try:
            count = laav.estimate_motions(seq)
        except ValueError as exc:
            raise VideoError(str(exc)) from None
        C = int(count.n_motions)
        say(f"C = {C} ({count.explain()}; {count.seconds:.1f} s)")
    else:
        C = int(n_motions)
    return Video(sequence=seq, n_motions=C, frames=frames, source=src, n_tracks=n, kept=kept,
                 motion_count=count, track_seconds=seconds, options=opts, complete_only=bool(complete_only))
