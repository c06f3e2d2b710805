"""Feature tracks from a video: ``laav track VIDEO -o tracks.npz``.

:func:`track` follows corners (OpenCV's ``goodFeaturesToTrack``, Shi-Tomasi) from frame
to frame with pyramidal Lucas-Kanade optical flow (``calcOpticalFlowPyrLK``):

* every step is checked forward and backward: a point is kept only when tracking its new
  position back to the previous frame lands within ``fb_max`` pixels (default 1) of where
  it started, its window still looks alike (its residual is at most ``residual_factor``
  times the step's median), and it stays inside the image; otherwise its track ends (it
  is never resumed: a point found again later is a new track);
* every ``redetect_every`` frames new corners are detected where no track is (farther
  than ``min_distance`` from every live point), up to ``max_points`` live tracks;
* tracks seen in fewer than ``min_length`` frames are dropped; ``max_tracks`` keeps the
  longest ones;
* ``stride`` tracks every stride-th frame of the source only.

The result (:class:`Tracks`) holds ``points`` (F, P, 2), NaN where a track is not visible,
and ``visible`` (F, P); :func:`save_tracks` writes them as ``.npz`` with the keys
``points``, ``visible`` and ``name`` (plus ``frame_index`` and ``image_size``).

OpenCV is used because Lucas-Kanade tracking with image pyramids, sub-pixel accuracy and
a fast corner detector is what it does well and what this project should not reimplement;
it comes with the ``track`` extra (``pip install 'laav[track]'``) and is imported only here,
on first use, so the algorithm itself never needs it.

Input: anything ``cv2.VideoCapture`` opens (a video file, an image-sequence pattern such
as ``img_%04d.png``), a folder of images (sorted by name, numbers compared as numbers),
or frames as an array (F, H, W) / (F, H, W, 3) or a list of such images.
"""

from __future__ import annotations

import os
import re
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["Tracks", "TrackError", "track", "save_tracks", "load_tracks", "IMAGE_EXTENSIONS"]

#: Extensions of the files a folder of frames is read from (case-insensitive).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")


#: Grey levels under which a step's Lucas-Kanade residual is never too large (see ``residual_factor``).
MIN_RESIDUAL = 2.0


class TrackError(ValueError):
    """The input cannot be tracked: unreadable video, no features, every track too short."""


@dataclass(frozen=True, eq=False)
class Tracks:
    """Feature tracks over F frames.

    Attributes
    ----------
    points : ndarray (F, P, 2) float64
        ``(x, y)`` pixel coordinates (x = column, y = row, pixel centres at integers);
        NaN where the track is not visible.
    visible : ndarray (F, P) bool
        Whether track p is seen in frame f.
    name : str
        The source's name (file or folder stem).
    frame_index : ndarray (F,) int64
        Index in the source of each frame tracked (``stride`` apart).
    image_size : (width, height)
    """

    points: np.ndarray
    visible: np.ndarray
    name: str
    frame_index: np.ndarray
    image_size: tuple[int, int]

    @property
    def n_frames(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_tracks(self) -> int:
        return int(self.points.shape[1])

    def arrays(self) -> dict[str, np.ndarray]:
        """The arrays of the ``.npz`` layout: ``points``, ``visible``, ``name`` (and extras)."""
        return {"points": self.points, "visible": self.visible, "name": np.asarray(self.name),
                "frame_index": self.frame_index,
                "image_size": np.asarray(self.image_size, dtype=np.int64)}

    def complete(self) -> np.ndarray:
        """Indices of the tracks visible in every frame."""
        return np.flatnonzero(self.visible.all(axis=0))


def save_tracks(tracks: Tracks, path: str | os.PathLike) -> Path:
    """Write ``tracks`` as a compressed ``.npz`` (keys points, visible, name, frame_index, image_size)."""
    p = Path(path)
    with open(p, "wb") as fh:  # np.savez would append .npz to a name without it
        np.savez_compressed(fh, **tracks.arrays())
    return p


def load_tracks(path: str | os.PathLike) -> Tracks:
    """Read a file written by :func:`save_tracks`."""
    with np.load(path, allow_pickle=False) as z:
        pts = np.asarray(z["points"], dtype=np.float64)
        vis = np.asarray(z["visible"], dtype=bool)
        fi = z["frame_index"] if "frame_index" in z else np.arange(pts.shape[0])
        size = tuple(int(v) for v in z["image_size"]) if "image_size" in z else (0, 0)
        return Tracks(pts, vis, str(z["name"]), np.asarray(fi, dtype=np.int64), size)


# --------------------------------------------------------------------------- reading frames


def _cv2():
    try:
        import cv2
    except ImportError:
        raise TrackError("tracking needs OpenCV: pip install opencv-python-headless "
                         "(or pip install 'laav[track]')") from None
    return cv2


def _natural_key(name: str):
    return [int(t) if t.isdigit() else t.lower() for t in re.split(r"(\d+)", name)]


def _gray(cv2, img: np.ndarray, src: str) -> np.ndarray:
    img = np.asarray(img)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.ndim != 2:
        raise TrackError(f"{src}: a frame must be a grey or colour image, got shape {img.shape}")
    if img.dtype != np.uint8:
        if np.issubdtype(img.dtype, np.floating) and img.size and np.nanmax(img) <= 1.0:
            img = img * 255.0
        img = np.clip(np.nan_to_num(img), 0, 255).astype(np.uint8)
    return img


def _frames(source, stride: int) -> tuple[Iterator[tuple[int, np.ndarray]], int | None, str]:
    """(iterator of (source index, grey frame), expected count or None, name)."""
    cv2 = _cv2()
    if isinstance(source, (str, os.PathLike)):
        p = Path(source)
        if p.is_dir():
            files = sorted((f for f in p.iterdir() if f.suffix.lower() in IMAGE_EXTENSIONS
                            and f.is_file()), key=lambda f: _natural_key(f.name))
            if not files:
                raise TrackError(f"{p}: no image files in this folder "
                                 f"({', '.join(IMAGE_EXTENSIONS)})")
            files = files[::stride]

            def read_folder():
                for i, f in enumerate(files):
                    img = cv2.imread(str(f), cv2.IMREAD_GRAYSCALE)
                    if img is None:
                        raise TrackError(f"{f}: cannot read this image")
                    yield i * stride, img

            return read_folder(), len(files), p.name or p.resolve().name
        if not p.exists() and "%" not in p.name:
            raise TrackError(f"{p}: no such file or folder")
        cap = cv2.VideoCapture(str(p))
        if not cap.isOpened():
            cap.release()
            raise TrackError(f"{p}: cannot open this video (not a format OpenCV reads)")
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        count = (n + stride - 1) // stride if n > 0 else None

        def read_video():
            try:
                i = 0
                while True:
                    ok, img = cap.read()
                    if not ok:
                        break
                    if i % stride == 0:
                        yield i, _gray(cv2, img, str(p))
                    i += 1
            finally:
                cap.release()

        name = p.stem if p.suffix else p.name
        return read_video(), count, re.sub(r"[_%.-]*%\d*d", "", name) or "video"
    frames = list(source)[::stride] if not isinstance(source, np.ndarray) else source[::stride]
    gen = ((i * stride, _gray(cv2, f, "<frames>")) for i, f in enumerate(frames))
    return gen, len(frames), "frames"


# --------------------------------------------------------------------------- tracking


def track(
    frames_or_path,
    *,
    max_points: int = 1000,
    max_tracks: int | None = None,
    min_length: int = 5,
    stride: int = 1,
    redetect_every: int = 5,
    min_distance: float = 7.0,
    quality: float = 0.01,
    block_size: int = 7,
    win_size: int = 15,
    levels: int = 3,
    fb_max: float = 1.0,
    residual_factor: float | None = 4.0,
    border: float = 2.0,
    max_frames: int | None = None,
    name: str | None = None,
    progress: bool | None = False,
    on_frame=None,
) -> Tracks:
    """Track corners through a video with pyramidal Lucas-Kanade and a forward-backward check.

    Parameters
    ----------
    frames_or_path : path, folder, array (F, H, W[, 3]) or iterable of images
        A video file (anything ``cv2.VideoCapture`` opens), a folder of images (sorted by
        name, numbers compared as numbers), or the frames themselves (uint8, or floats in
        0-1 or 0-255; colour is BGR as OpenCV reads it).
    max_points : int
        Most tracks alive at once; detection fills up to it.
    max_tracks : int or None
        Keep only the longest ``max_tracks`` tracks of the result (ties: earliest first).
    min_length : int
        Fewest frames (of the tracked ones, after ``stride``) a track must be seen in.
    stride : int
        Track every ``stride``-th frame of the source.
    redetect_every : int
        Detect new corners every this many tracked frames, away from live tracks.
    min_distance, quality, block_size : float, float, int
        ``goodFeaturesToTrack``'s ``minDistance`` (px), ``qualityLevel``, ``blockSize``.
    win_size, levels : int
        Lucas-Kanade window (px, square) and pyramid levels above the image.
    fb_max : float
        Largest forward-backward error (px) a step may have.
    residual_factor : float or None
        A step whose Lucas-Kanade residual (mean absolute grey-level difference over the
        window) exceeds this many times the step's median (and :data:`MIN_RESIDUAL`) ends
        its track: the window's content changed, as when an object slides over the
        background behind the point. None: no such check.
    border : float
        A point closer than this to the image edge is dropped.
    max_frames : int or None
        Stop after this many tracked frames.
    name : str or None
        Name stored with the tracks (default: the file or folder stem).
    progress : bool or None
        Show a progress bar on stderr (None: only when stderr is a terminal).
    on_frame : callable or None
        Called as ``on_frame(t, image)`` with every tracked frame as it is read: ``t`` its
        number among the tracked frames (0 .. F-1, the ``points`` axis) and ``image`` the
        grey uint8 (H, W) array tracked (read-only: the tracker keeps using it). Lets a
        caller keep what it needs of the frames (e.g. small copies to draw the points on)
        without decoding the video twice or holding it at full size.

    Raises
    ------
    TrackError
        The video cannot be opened or holds fewer than two frames, no corner is found, or
        every track is shorter than ``min_length``.
    """
    for key, v, lo in (("max_points", max_points, 1), ("min_length", min_length, 2),
                       ("stride", stride, 1), ("redetect_every", redetect_every, 1),
                       ("block_size", block_size, 3), ("win_size", win_size, 5),
                       ("levels", levels, 0)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
            raise ValueError(f"{key} must be an integer >= {lo}, got {v!r}")
    if max_tracks is not None and (not isinstance(max_tracks, (int, np.integer)) or max_tracks < 1):
        raise ValueError(f"max_tracks must be a positive integer or None, got {max_tracks!r}")
    if max_frames is not None and (not isinstance(max_frames, (int, np.integer)) or max_frames < 2):
        raise ValueError(f"max_frames must be an integer >= 2 or None, got {max_frames!r}")
    if not (fb_max > 0 and min_distance > 0 and 0 < quality < 1 and border >= 0):
        raise ValueError("fb_max and min_distance must be > 0, quality in (0, 1), border >= 0")
    if residual_factor is not None and not residual_factor > 0:
        raise ValueError(f"residual_factor must be > 0 or None, got {residual_factor!r}")
    cv2 = _cv2()
    src = str(frames_or_path) if isinstance(frames_or_path, (str, os.PathLike)) else "<frames>"
    frames, count, default_name = _frames(frames_or_path, int(stride))
    if max_frames is not None:
        count = min(count, max_frames) if count is not None else max_frames
    if progress is None:
        progress = sys.stderr.isatty()
    bar = None
    if progress:
        # (a text bar everywhere: tqdm.auto's notebook bar warns "IProgress not found" in a
        # kernel without ipywidgets, and the text bar shows in a notebook's cell too)
        from tqdm import tqdm

        bar = tqdm(total=count, unit="frame", desc="tracking", file=sys.stderr, leave=False)

    lk = dict(winSize=(win_size, win_size), maxLevel=levels,
              criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
    # per track: first frame and its coordinates frame by frame (lists, grown as we go)
    starts: list[int] = []
    paths: list[list[np.ndarray]] = []
    live = np.zeros(0, dtype=np.int64)  # track ids alive in the previous frame
    pos = np.zeros((0, 1, 2), dtype=np.float32)
    index: list[int] = []
    prev = None
    size = None
    try:
        for t, (src_i, img) in enumerate(frames):
            if max_frames is not None and t >= max_frames:
                break
            if size is None:
                size = img.shape
            elif img.shape != size:
                raise TrackError(f"{src}: frame {src_i} is {img.shape[1]}x{img.shape[0]}, the first "
                                 f"was {size[1]}x{size[0]} (all frames must have one size)")
            index.append(src_i)
            H, W = size
            if on_frame is not None:
                img.flags.writeable = False
                on_frame(t, img)
            if prev is not None and len(live):
                nxt, st, res = cv2.calcOpticalFlowPyrLK(prev, img, pos, None, **lk)
                back, st2, _ = cv2.calcOpticalFlowPyrLK(img, prev, nxt, None, **lk)
                fb = np.linalg.norm((back - pos).reshape(-1, 2), axis=1)
                q = nxt.reshape(-1, 2)
                ok = (st.ravel() == 1) & (st2.ravel() == 1) & (fb <= fb_max)
                ok &= np.isfinite(q).all(axis=1)
                if residual_factor is not None and ok.any():
                    r = res.ravel()
                    ok &= r <= max(MIN_RESIDUAL, residual_factor * float(np.median(r[ok])))
                ok &= (q[:, 0] >= border) & (q[:, 0] <= W - 1 - border)
                ok &= (q[:, 1] >= border) & (q[:, 1] <= H - 1 - border)
                live, pos = live[ok], nxt[ok]
                for tid, xy in zip(live, pos.reshape(-1, 2)):
                    paths[tid].append(xy.astype(np.float64))
            elif prev is not None:
                live, pos = live[:0], pos[:0]
            if t % redetect_every == 0 and len(live) < max_points:
                mask = np.full((H, W), 255, dtype=np.uint8)
                for x, y in pos.reshape(-1, 2):
                    cv2.circle(mask, (int(round(x)), int(round(y))), int(np.ceil(min_distance)), 0, -1)
                found = cv2.goodFeaturesToTrack(img, maxCorners=int(max_points - len(live)),
                                                qualityLevel=quality, minDistance=min_distance,
                                                mask=mask, blockSize=block_size)
                if found is not None:
                    f = found.reshape(-1, 2)
                    inside = ((f[:, 0] >= border) & (f[:, 0] <= W - 1 - border)
                              & (f[:, 1] >= border) & (f[:, 1] <= H - 1 - border))
                    f = f[inside]
                    new = np.arange(len(starts), len(starts) + len(f))
                    for xy in f:
                        starts.append(t)
                        paths.append([xy.astype(np.float64)])
                    live = np.concatenate([live, new])
                    pos = np.concatenate([pos, f.reshape(-1, 1, 2).astype(np.float32)])
            prev = img
            if bar is not None:
                bar.update(1)
    finally:
        if bar is not None:
            bar.close()
    F = len(index)
    if F < 2:
        raise TrackError(f"{src}: {'no frames' if F == 0 else 'only one frame'} could be read "
                         "(tracking needs at least two)")
    if not starts:
        raise TrackError(f"{src}: no features found to track (is the video blank or flat?)")
    lengths = np.array([len(p) for p in paths])
    keep = np.flatnonzero(lengths >= min_length)
    if not len(keep):
        raise TrackError(f"{src}: all {len(starts)} tracks are shorter than the minimum length "
                         f"of {min_length} frames (the longest has {lengths.max()}); lower "
                         "--min-length or check the video")
    if max_tracks is not None and len(keep) > max_tracks:
        order = np.lexsort((keep, -lengths[keep]))  # longest first, then earliest id
        keep = np.sort(keep[order[:max_tracks]])
    points = np.full((F, len(keep), 2), np.nan)
    visible = np.zeros((F, len(keep)), dtype=bool)
    for j, tid in enumerate(keep):
        a = starts[tid]
        points[a:a + lengths[tid], j] = paths[tid]
        visible[a:a + lengths[tid], j] = True
    return Tracks(points=points, visible=visible,
                  name=default_name if name is None else str(name),
                  frame_index=np.asarray(index, dtype=np.int64),
                  image_size=(int(size[1]), int(size[0])))

