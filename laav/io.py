"""Reading and writing sequences: Hopkins155 ``*_truth.mat``, KT3DMoSeg ``.mat``, ``.npz``, tracks CSV.

The format is chosen once, from the file's first bytes, never from its extension, and
every failure becomes a :class:`~laav.SequenceError` that names the file and the problem.
MAT content is
parsed by scipy only after its structure was checked (:func:`laav._matchild.validate_mat5`:
every tag, dimension and declared size against its parent and the file), because scipy's
MAT reader trusts them and can crash the interpreter on damaged files. For untrusted files
(``isolated=True``: uploads, the command line, the benchmark) the parse also runs in a
child process (:mod:`laav._matchild`), so that a crash the check did not foresee, a hang
or a memory bomb costs only the child.
"""

from __future__ import annotations

import atexit
import os
import re
import select
import signal
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from ._sequence import Sequence, SequenceError

__all__ = ["load_sequence", "load_sequence_isolated", "save_sequence", "find_truth_files",
           "safe_name", "FORMATS", "point_numbers", "csv_track_ids", "layout_warning",
           "looks_like_video"]

#: The formats :func:`save_sequence` writes (``format=``); :func:`load_sequence` reads them all.
FORMATS = ("hopkins", "kt3d", "npz", "csv")

_MAT_MAGIC = b"MATLAB 5.0 MAT-file"
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_ZIP_MAGIC = b"PK\x03\x04"


#: Most trajectories a file may hold unless ``max_points`` says otherwise. No stage holds
#: a P x P array (issue 14 item 8): memory grows linearly in P, and 20,000 tracks x 100
#: frames segment in about 1 GB; what grows is time (``docs/bench/scale.md``).
MAX_POINTS = 20_000
#: Most bytes the arrays read from one file may declare together (before they are read).
MAX_BYTES = 1 << 28  # 256 MiB: e.g. 10,000 points over 1,600 frames as float64

_UNSAFE = re.compile(r"[^\w.+-]+")


def safe_name(text, default: str = "sequence", max_len: int = 100) -> str:
    """``text`` (e.g. a sequence name read from a file) reduced to a safe file base name.

    Only letters, digits, ``_ . + -`` are kept (every other run of characters, path
    separators included, becomes ``_``); leading dots and underscores are dropped, so
    the result is never ``..``, hidden or absolute, and it is at most ``max_len`` long.
    ``default`` when nothing is left.
    """
    name = _UNSAFE.sub("_", str(text)).lstrip("._")[:max_len].rstrip(".")
    return name or default


def _name_from_path(path: Path) -> str:
    stem = path.stem
    for suffix in ("_truth", "_Tracks"):  # Hopkins155's and KT3DMoSeg's file names
        if stem.endswith(suffix) and len(stem) > len(suffix):
            return stem[: -len(suffix)]
    return stem


def _resolve(path: str | os.PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise SequenceError(f"{p}: no such file or folder")
    if p.is_dir():
        found = sorted(p.glob("*_truth.mat"))
        if not found:
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in (".mat", ".npz", ".csv"))
        if len(found) != 1:
            what = "no" if not found else f"{len(found)}"
            raise SequenceError(
                f"{p}: folder holds {what} sequence files; expected exactly one (a *_truth.mat, "
                "or one .mat, .npz or tracks .csv file)"
                + ("; a folder of video frames is tracked first: laav track FOLDER" if not found
                   and any(q.suffix.lower() in (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
                           for q in p.iterdir()) else ""))
        p = found[0]
    return p


def load_sequence(path: str | os.PathLike, *, isolated: bool = False,
                  timeout: float = 60.0, max_points: int | None = None,
                  max_bytes: int | None = None) -> Sequence:
    """Read a sequence from a Hopkins155 or KT3DMoSeg ``.mat``, a ``.npz``, a tracks CSV, or a
    folder holding one.

    Parameters
    ----------
    path : str or path-like
        The format is taken from the content, never from the extension:

        - **Hopkins155** ``*_truth.mat`` (MATLAB v5; complete): ``y`` (3, P, F) homogeneous
          pixel coordinates, ``s`` (P, 1) 1-based labels, ``width``, ``height``.
        - **KT3DMoSeg** ``*_Tracks.mat`` (MATLAB v5): a struct ``Data`` with ``ySparse``
          (3, P, F) homogeneous coordinates (third row 1 where visible), ``visibleSparse``
          (P, F), 1 = visible (absent: all visible), ``GtLabel`` (P,) labels 1..K
          (optional); its other fields are ignored, ``width`` / ``height`` beside it are read.
        - **.npz**: ``points`` (F, P, 2) and optionally ``labels`` (P,), ``visible`` (F, P)
          bool, ``width``, ``height``, ``name``.
        - **tracks CSV**: a header naming the columns ``track,frame,x,y`` and optionally
          ``label`` (any order, other columns ignored; ``,`` ``;`` or tab separated), then
          one row per observation. Tracks are points in increasing track id, frames the
          distinct frame numbers in increasing order (a tracker's stride leaves no empty
          frame); labels must be constant per track, non-negative integers, and are
          renumbered 0..K-1 in increasing order.

        or a folder containing exactly one such file (a ``*_truth.mat`` first).
    isolated : bool
        Parse MAT content in a child process, so that a file crashing scipy's reader (or
        hanging it longer than ``timeout`` seconds, or needing more memory than
        :data:`laav._matchild.MEMORY_LIMIT`) raises a :class:`SequenceError` instead of
        taking the caller down. Either way the file's MAT v5 structure is checked before
        scipy reads it (the damaged files known to crash scipy, 7 of 5,908 fuzzed
        mutants, are all refused by that check in-process too); ``isolated`` is the
        second line of defence, for every file you did not write yourself.
    timeout : float
        Seconds an isolated read may take.
    max_points : int, optional
        Most trajectories accepted (default :data:`MAX_POINTS`, read at call time).
    max_bytes : int, optional
        Most bytes the file's arrays may declare together (default :data:`MAX_BYTES`).
        Sizes are checked before the arrays are allocated: from the ``.npy`` headers of an
        ``.npz``, and for MAT files from the size of the parsed variables the child process
        sends (isolated) before this process reads them, and from ``y``'s dimensions.

    Returns
    -------
    Sequence

    Raises
    ------
    SequenceError
        When the file is missing, of another format, corrupt, lacks a variable, or its
        arrays have the wrong shape or values, or exceed a limit (the message then gives
        the size and the limit). The message names the file.
    """
    lim = _limits(max_points, max_bytes)
    p = _resolve(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(128)
    except OSError as exc:
        raise SequenceError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    if not head:
        raise SequenceError(f"{p}: file is empty")
    if head.startswith(_ZIP_MAGIC):
        return _load_npz(p, lim)
    if head.startswith(_MAT_MAGIC):
        mat = _READER.read(p, timeout, lim[1]) if isolated else _read_mat_here(p, lim[1])
        return _load_mat(p, mat, lim)
    if head[:512].find(_HDF5_MAGIC) >= 0 or head.startswith(b"MATLAB 7.3"):
        raise SequenceError(f"{p}: MATLAB v7.3 (HDF5) files are not supported; save with -v7")
    csv_head = _csv_header(p)
    if csv_head is not None:
        return _load_csv(p, csv_head, lim)
    video = looks_like_video(head)
    raise SequenceError(
        f"{p}: not a MATLAB v5 .mat, NumPy .npz or tracks CSV file (unrecognised content)"
        + ("; a video is tracked first: laav track VIDEO (laav-explore opens one directly)"
           if video else "")
    )


def _limits(max_points, max_bytes) -> tuple[int, int]:
    out = []
    for name, value, default in (("max_points", max_points, MAX_POINTS),
                                 ("max_bytes", max_bytes, MAX_BYTES)):
        value = default if value is None else value
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise ValueError(f"{name} must be a positive integer, got {value!r}")
        out.append(int(value))
    return out[0], out[1]


def _check_size(p: Path, n_points: int | None, n_bytes: int, lim: tuple[int, int]) -> None:
    """Refuse a file declaring more points or bytes than the limits, before reading it."""
    if n_points is not None and n_points > lim[0]:
        raise SequenceError(f"{p}: {n_points:,} points exceed the limit of {lim[0]:,} "
                            "(raise it with max_points / --max-points)")
    if n_bytes > lim[1]:
        raise SequenceError(f"{p}: its arrays declare {n_bytes:,} bytes, over the limit of "
                            f"{lim[1]:,} bytes (max_bytes)")


def _npz_declared(p: Path, members, lim: tuple[int, int]) -> None:
    """Check the ``.npy`` headers of ``members`` of the zip ``p`` (nothing else is read)."""
    import zipfile

    from numpy.lib import format as npy

    total, n_points = 0, None
    with zipfile.ZipFile(p) as zf:
        infos = {i.filename: i for i in zf.infolist()}
        for name in members:
            info = infos.get(name) or infos.get(name + ".npy")  # np.load's order
            if info is None:
                continue
            with zf.open(info) as fh:
                if fh.read(len(npy.MAGIC_PREFIX)) != npy.MAGIC_PREFIX:
                    raise SequenceError(f"{p}: member '{info.filename}' is not a NumPy array")
                fh.seek(0)
                version = npy.read_magic(fh)
                read = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                shape, _, dtype = read(fh)
            size = 1
            for n in shape:
                size *= int(n)
            total += size * dtype.itemsize
            if name == "points" and len(shape) == 3:
                n_points = int(shape[1])
    _check_size(p, n_points, total, lim)


def _scalar(value, what: str, p: Path) -> int:
    arr = np.asarray(value)
    if arr.size != 1:
        raise SequenceError(f"{p}: variable '{what}' should be a single number, got {arr.shape}")
    try:
        return int(arr.ravel()[0])
    except (TypeError, ValueError, OverflowError):  # OverflowError: inf
        raise SequenceError(f"{p}: variable '{what}' is not a number") from None


def _read_mat_here(p: Path, max_bytes: int) -> dict:
    from ._matchild import MatReadError, read_mat_variables

    try:
        return read_mat_variables(str(p), max_bytes)
    except MatReadError as exc:
        raise SequenceError(f"{p}: {exc}") from None


def _one_based_gaps(p: Path, labels: np.ndarray, what: str) -> None:
    """A motion label of 1..max(``labels``) (a MAT file's 1-based labels) that no point
    has, named in the file's own numbers (:class:`laav.Sequence` would name it 0-based)."""
    s = labels
    if not (s.size and np.isfinite(s).all() and np.all(s == np.round(s)) and s.max() <= s.size):
        return  # (other problems, a label above the number of points too: the Sequence says them)
    top = int(s.max())
    missing = np.setdiff1d(np.arange(1, top + 1), s.astype(np.int64))
    if missing.size:
        shown = ", ".join(map(str, missing[:10].tolist())) + (", ..." if missing.size > 10 else "")
        raise SequenceError(f"{p}: {what} has no point with motion label(s) [{shown}] (1-based "
                            f"labels must be 1..{top}, every one used)")


def _load_mat(p: Path, mat: dict, lim: tuple[int, int]) -> Sequence:
    if "y" not in mat and "Data" in mat:
        return _load_kt3d(p, mat, lim)
    if "y" not in mat:
        raise SequenceError(f"{p}: missing variable 'y' (Hopkins155: homogeneous pixel coordinates, "
                            "3 x P x F) or struct 'Data' (KT3DMoSeg: ySparse, visibleSparse, GtLabel)")
    y = np.asarray(mat["y"])
    _check_size(p, y.shape[1] if y.ndim == 3 else None, 8 * y.size, lim)
    if not np.issubdtype(y.dtype, np.number):
        raise SequenceError(f"{p}: variable 'y' is not numeric (dtype {y.dtype})")
    if np.iscomplexobj(y):
        raise SequenceError(f"{p}: variable 'y' must be real numbers, got complex values")
    if y.ndim == 2 and y.shape[0] in (2, 3):  # a single frame saved without the last axis
        raise SequenceError(f"{p}: variable 'y' has one frame only (shape {y.shape}); needs 3 x P x F")
    if y.ndim != 3 or y.shape[0] not in (2, 3):
        raise SequenceError(f"{p}: variable 'y' must have shape 3 x P x F, got {y.shape}")
    y = y.astype(np.float64)
    if not np.isfinite(y).all():  # check before dividing: x / inf would look finite
        bad = int((~np.isfinite(y)).any(axis=(0, 2)).sum())
        raise SequenceError(f"{p}: {bad} point(s) have NaN or infinite coordinates")
    if y.shape[0] == 3:
        w = y[2]
        if np.isfinite(w).all() and np.any(np.abs(w) < 1e-12):
            raise SequenceError(f"{p}: variable 'y' has a zero homogeneous coordinate")
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = y[:2] / w
    else:
        xy = y
    points = np.transpose(xy, (2, 1, 0))  # (F, P, 2)
    labels = None
    if "s" in mat:
        s = np.asarray(mat["s"])
        if not np.issubdtype(s.dtype, np.number):
            raise SequenceError(f"{p}: variable 's' (labels) is not numeric")
        s = s.astype(np.float64).ravel()
        if s.size and np.isfinite(s).all() and s.min() < 1:
            raise SequenceError(f"{p}: variable 's' must hold 1-based labels, found {s.min():g}")
        _one_based_gaps(p, s, "variable 's'")
        labels = s - 1
    image_size = None
    if "width" in mat and "height" in mat:
        image_size = (_scalar(mat["width"], "width", p), _scalar(mat["height"], "height", p))
    return Sequence(
        points=points, labels=labels, name=_name_from_path(p), image_size=image_size, source=str(p)
    )


def _numeric(p: Path, value, what: str) -> np.ndarray:
    a = np.asarray(value)
    if a.dtype == object or not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise SequenceError(f"{p}: {what} is not numeric (dtype {a.dtype})")
    if np.iscomplexobj(a):
        raise SequenceError(f"{p}: {what} must be real numbers, got complex values")
    return a


def _load_kt3d(p: Path, mat: dict, lim: tuple[int, int]) -> Sequence:
    """KT3DMoSeg: struct ``Data`` with ``ySparse`` (3, P, F), ``visibleSparse`` (P, F), ``GtLabel``."""
    if "Data.ySparse" not in mat:
        raise SequenceError(f"{p}: struct 'Data' has no field 'ySparse' (KT3DMoSeg: homogeneous "
                            "pixel coordinates, 3 x P x F)")
    y = _numeric(p, mat["Data.ySparse"], "Data.ySparse")
    _check_size(p, y.shape[1] if y.ndim == 3 else None, 8 * y.size, lim)
    if y.ndim != 3 or y.shape[0] != 3:
        raise SequenceError(f"{p}: Data.ySparse must have shape 3 x P x F, got {y.shape}")
    _, P, F = y.shape
    if "Data.visibleSparse" in mat:
        v = _numeric(p, mat["Data.visibleSparse"], "Data.visibleSparse")
        if v.shape != (P, F):
            raise SequenceError(f"{p}: Data.visibleSparse must have shape P x F = {P} x {F} like "
                                f"Data.ySparse, got {v.shape}")
        if v.dtype != bool:
            if not np.isin(v, (0, 1)).all():
                raise SequenceError(f"{p}: Data.visibleSparse must hold only 0 and 1")
            v = v != 0
        vis = v.T  # (F, P)
    else:
        vis = np.ones((F, P), dtype=bool)
    y = y.astype(np.float64)
    w = y[2].T  # (F, P)
    finite = np.isfinite(y).all(axis=0).T  # check before dividing: x / inf would look finite
    bad = vis & ~finite
    if bad.any():
        raise SequenceError(f"{p}: {int(bad.any(axis=0).sum())} point(s) have NaN or infinite "
                            "coordinates in Data.ySparse where Data.visibleSparse says visible")
    if np.any(vis & (np.abs(np.where(finite, w, 1.0)) < 1e-12)):
        raise SequenceError(f"{p}: Data.ySparse has a zero homogeneous coordinate where visible")
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        points = np.transpose(y[:2], (2, 1, 0)) / w[..., None]  # (F, P, 2)
    labels = None
    if "Data.GtLabel" in mat:
        g = _numeric(p, mat["Data.GtLabel"], "Data.GtLabel").astype(np.float64).ravel()
        if g.size and np.isfinite(g).all() and g.min() < 1:
            raise SequenceError(f"{p}: Data.GtLabel must hold labels 1..K, found {g.min():g}")
        _one_based_gaps(p, g, "Data.GtLabel")
        labels = g - 1
    image_size = None
    if "width" in mat and "height" in mat:
        image_size = (_scalar(mat["width"], "width", p), _scalar(mat["height"], "height", p))
    return Sequence(points=points, labels=labels, name=_name_from_path(p), image_size=image_size,
                    source=str(p), visible=vis)


#: Columns of a tracks CSV: required, then optional.
CSV_COLUMNS = ("track", "frame", "x", "y")
CSV_OPTIONAL = ("label",)


def _csv_header(p: Path) -> tuple[str, dict] | None:
    """``(delimiter, {column: index})`` when ``p`` starts with a tracks-CSV header, else None.

    Raises :class:`SequenceError` for a text file that looks like a CSV without that header.
    """
    try:
        with open(p, "rb") as fh:
            head = fh.read(1 << 16)
    except OSError as exc:
        raise SequenceError(f"{p}: cannot be read ({exc.strerror or exc})") from None
    first = head.split(b"\n", 1)[0]
    if b"\0" in first:
        return None
    try:
        line = first.decode("utf-8").lstrip("\ufeff").rstrip("\r")
    except UnicodeDecodeError:
        return None
    for delim in (",", ";", "\t"):
        names = [c.strip().strip('"').strip().lower() for c in line.split(delim)]
        if set(CSV_COLUMNS) <= set(names):
            dup = sorted({n for n in names if names.count(n) > 1 and n in CSV_COLUMNS + CSV_OPTIONAL})
            if dup:
                raise SequenceError(f"{p}: tracks CSV header names column(s) {dup} twice")
            return delim, {n: names.index(n) for n in CSV_COLUMNS + CSV_OPTIONAL if n in names}
    if any(d in line for d in (",", ";", "\t")):
        shown = line[:60] + ("..." if len(line) > 60 else "")
        raise SequenceError(f"{p}: a CSV file without the tracks header: its first line must name "
                            f"the columns track,frame,x,y (and optionally label), got {shown!r}")
    return None


def looks_like_video(head: bytes) -> bool:
    """Whether a file's first bytes ``head`` (12 or more) are a common video container's
    (MP4 / MOV, AVI, Matroska / WebM, Ogg, FLV, MPEG program stream): :func:`load_sequence`'s
    error then says to track it, and ``laav-explore`` tells a video named ``.csv`` from a
    damaged sequence file by it."""
    return (head[4:8] in (b"ftyp", b"moov", b"mdat", b"wide", b"free")
            or (head[:4] == b"RIFF" and head[8:12] == b"AVI ")
            or head[:4] in (b"\x1a\x45\xdf\xa3", b"OggS", b"\x00\x00\x01\xba")
            or head[:3] == b"FLV")


def layout_warning(seq: Sequence) -> str | None:
    """A warning for an ``.npz`` sequence with more frames than points, which is how a
    ``points`` array written as (P, F, 2) instead of (F, P, 2) reads (nothing else tells:
    its stages then find no atom); None otherwise. The loader cannot warn itself: it runs
    in a child process for the command line and the explorer."""
    src = str(getattr(seq, "source", "") or "")
    if seq.n_frames <= seq.n_points or not src or src.startswith("<"):
        return None
    try:
        with open(src, "rb") as fh:
            if not fh.read(4).startswith(_ZIP_MAGIC[:4]):
                return None
    except OSError:
        return None
    return (f"{src}: {seq.n_frames} frames of {seq.n_points} points: if its 'points' array is "
            "(points, frames, 2), transpose it to (frames, points, 2)")


def csv_track_ids(path: str | os.PathLike) -> np.ndarray | None:
    """The track ids of a tracks CSV, in the order :func:`load_sequence` makes its points
    (increasing id): int64 (P,); None when ``path`` is not a tracks CSV. For a file that
    :func:`load_sequence` has read (the ids of its other formats are ``0 .. P-1``), so
    that outputs can name the points as the file does. Raises :class:`SequenceError` for an
    unreadable file."""
    p = Path(path)
    try:
        header = _csv_header(p)
    except SequenceError:
        if not p.is_file():
            raise
        header = None  # a CSV without the tracks header
    if header is None:
        return None
    delim, cols = header
    try:
        ids = np.loadtxt(p, delimiter=delim, skiprows=1, usecols=[cols["track"]], dtype=np.float64,
                         ndmin=1, encoding="utf-8", quotechar='"')
    except Exception as exc:  # changed since it was read
        raise SequenceError(f"{p}: bad tracks CSV ({type(exc).__name__}: {exc})") from None
    return np.unique(ids).astype(np.int64)


def point_numbers(seq: Sequence, kept: np.ndarray | None = None) -> np.ndarray:
    """The number its file gives each point of ``seq`` (int64 (P,)): a tracks CSV's track
    ids (:func:`csv_track_ids`), else the point's index in the file. ``kept``: ``seq`` is
    these points of the file's (``Sequence.complete()``'s indices); their numbers then.
    A sequence not read from a file (``source`` ``"<array>"``), or a file that can no longer
    be read, numbers its points by index."""
    index = np.arange(seq.n_points) if kept is None else np.asarray(kept, dtype=np.int64)
    src = str(getattr(seq, "source", "") or "")
    try:
        ids = csv_track_ids(src) if src and not src.startswith("<") else None
    except (SequenceError, OSError):  # changed or gone since it was read: the indices
        ids = None
    if ids is not None and index.size and ids.size > index.max():
        index = ids[index]
    return index


def _load_csv(p: Path, header: tuple[str, dict], lim: tuple[int, int]) -> Sequence:
    """A tracks CSV: one row per observation of a track in a frame."""
    import warnings

    delim, cols = header
    size = p.stat().st_size
    if size > lim[1] // 4:  # parsed, a row of >= 8 bytes becomes <= 5 float64 values
        raise SequenceError(f"{p}: {size:,} bytes is over the limit of {lim[1] // 4:,} bytes for a "
                            "tracks CSV (max_bytes / 4)")
    names = [n for n in CSV_COLUMNS + CSV_OPTIONAL if n in cols]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "input contained no data": said below
            table = np.loadtxt(p, delimiter=delim, skiprows=1, usecols=[cols[n] for n in names],
                               dtype=np.float64, ndmin=2, encoding="utf-8", quotechar='"')
    except ValueError as exc:
        msg = str(exc).rstrip(".")
        m = re.search(r"at row (\d+), column (\d+)$", msg)  # numpy: 0-based data row
        if m:
            by_index = {i + 1: n for n, i in cols.items()}
            col = by_index.get(int(m.group(2)), f"column {m.group(2)}")
            msg = f"{msg[: m.start()].strip()} in column '{col}' of data row {int(m.group(1)) + 1}"
        elif short := re.match(r"invalid column index (\d+) at row (\d+) with (\d+) columns", msg):
            # numpy: the row among the lines it read (blank and # lines not counted)
            msg = (f"data row {int(short.group(2))} has only "
                   f"{short.group(3)} fields: every row needs a value for each column the header "
                   "names (a track not seen in a frame has no row for that frame)")
        else:  # numpy: 0-based line of the file
            msg = re.sub(r"at row (\d+)", lambda g: f"on line {int(g.group(1)) + 1}", msg)
        raise SequenceError(f"{p}: bad tracks CSV: {msg}") from None
    except Exception as exc:  # UnicodeDecodeError, MemoryError, ...
        raise SequenceError(f"{p}: bad tracks CSV ({type(exc).__name__}: {exc})") from None
    if table.shape[0] == 0:
        raise SequenceError(f"{p}: tracks CSV has a header but no observations")
    col = dict(zip(names, table.T))

    def _row(mask) -> int:
        return int(np.flatnonzero(mask)[0]) + 1

    for name in ("track", "frame") + (("label",) if "label" in col else ()):
        v = col[name]
        bad = ~np.isfinite(v) | (v != np.round(v)) | (np.abs(v) > 2.0**53)
        if bad.any():
            first = float(v[bad][0])
            what = ("whole numbers of magnitude at most 2**53"
                    if np.isfinite(first) and first == round(first) else "whole numbers")
            raise SequenceError(f"{p}: column '{name}' must hold {what}, got "
                                f"{first:g} on data row {_row(bad)}")
    bad = ~np.isfinite(col["x"]) | ~np.isfinite(col["y"])
    if bad.any():
        raise SequenceError(f"{p}: NaN or infinite coordinate on data row {_row(bad)} (a track not "
                            "seen in a frame has no row for that frame: leave such rows out)")
    tracks, ti = np.unique(col["track"], return_inverse=True)
    frames, fi = np.unique(col["frame"], return_inverse=True)
    P, F = tracks.size, frames.size
    _check_size(p, P, 17 * F * P, lim)  # points (F, P, 2) float64 and visible (F, P)
    key = ti * F + fi
    order = np.argsort(key, kind="stable")
    dup = np.flatnonzero(key[order][1:] == key[order][:-1])
    if dup.size:
        a, b = sorted(order[dup[0]: dup[0] + 2])
        raise SequenceError(f"{p}: track {int(tracks[ti[a]])} has two rows for frame "
                            f"{int(frames[fi[a]])} (data rows {a + 1} and {b + 1}); one row per "
                            "track and frame")
    counts = np.bincount(ti, minlength=P)
    if (counts < 2).any():
        short = tracks[counts < 2].astype(np.int64)
        shown = ", ".join(str(t) for t in short[:5]) + (", ..." if short.size > 5 else "")
        raise SequenceError(f"{p}: {short.size} track(s) have a single observation (track {shown}); "
                            "every track needs at least 2 frames")
    labels = None
    if "label" in col:
        lab = col["label"]
        first = lab[np.unique(ti, return_index=True)[1]]  # each track's label on its first row
        bad = lab != first[ti]
        if bad.any():
            r = int(np.flatnonzero(bad)[0])
            raise SequenceError(f"{p}: track {int(tracks[ti[r]])} has labels {first[ti[r]]:g} and "
                                f"{lab[r]:g} (data row {r + 1}); a track keeps one label")
        if first.min() < 0:
            raise SequenceError(f"{p}: column 'label' must be non-negative, found {first.min():g}")
        labels = np.unique(first, return_inverse=True)[1].reshape(-1)
    points = np.full((F, P, 2), np.nan)
    points[fi, ti, 0] = col["x"]
    points[fi, ti, 1] = col["y"]
    visible = np.zeros((F, P), dtype=bool)
    visible[fi, ti] = True
    return Sequence(points=points, labels=labels, name=_name_from_path(p), source=str(p),
                    visible=visible)


_NPZ_MEMBERS = ("points", "labels", "visible", "width", "height", "image_size", "name")


def _load_npz(p: Path, lim: tuple[int, int]) -> Sequence:
    try:
        _npz_declared(p, _NPZ_MEMBERS, lim)
        with np.load(p, allow_pickle=False) as data:
            files = set(data.files)
            if "points" not in files:
                raise SequenceError(f"{p}: missing array 'points' (frames x points x 2)")
            points = data["points"]
            labels = data["labels"] if "labels" in files else None
            visible = data["visible"] if "visible" in files else None
            image_size = None
            if "width" in files and "height" in files:
                image_size = (
                    _scalar(data["width"], "width", p),
                    _scalar(data["height"], "height", p),
                )
            elif "image_size" in files:  # as `laav track` writes it: (width, height)
                image_size = _image_size(data["image_size"], p)
            name = _stored_name(data["name"]) if "name" in files else None
    except SequenceError:
        raise
    except Exception as exc:  # BadZipFile, zlib.error, ValueError, MemoryError, ...
        raise SequenceError(f"{p}: truncated or corrupt NPZ file ({type(exc).__name__}: {exc})") from None
    return Sequence(points=points, labels=labels, name=name or _name_from_path(p),
                    image_size=image_size, source=str(p), visible=visible)


def _image_size(value, p: Path) -> tuple[int, int] | None:
    """``(width, height)`` from an ``image_size`` array of two whole numbers; None when it is
    (0, 0), what ``laav track`` writes when the size is unknown."""
    arr = np.asarray(value)
    if arr.shape != (2,) or arr.dtype.kind not in "iu":
        raise SequenceError(f"{p}: variable 'image_size' should be two whole numbers "
                            f"(width, height), got shape {arr.shape} of {arr.dtype}")
    w, h = (int(v) for v in arr)
    if w == 0 and h == 0:
        return None
    if w < 0 or h < 0:
        raise SequenceError(f"{p}: variable 'image_size' must not be negative, got ({w}, {h})")
    return w, h


def _stored_name(value) -> str | None:
    """The ``name`` stored in a file: one string, control characters dropped, at most 200 long."""
    arr = np.asarray(value)
    if arr.size != 1 or arr.dtype.kind not in "US":
        return None
    text = arr.ravel()[0]
    text = text.decode("utf-8", "replace") if isinstance(text, bytes) else str(text)
    return re.sub(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]", "", text)[:200].strip() or None


def save_sequence(seq: Sequence, path: str | os.PathLike, format: str | None = None) -> Path:
    """Write ``seq`` to ``path`` in one of :data:`FORMATS`; :func:`load_sequence` reads it back exactly.

    Parameters
    ----------
    seq : Sequence
    path : str or path-like
    format : {"hopkins", "kt3d", "npz", "csv"}, optional
        Default from the extension: ``.npz``, ``.csv``, and ``.mat`` as ``"hopkins"`` for a
        complete sequence, ``"kt3d"`` for one with missing entries.

        - ``"npz"``: ``points`` (F, P, 2) float64 (NaN where hidden), ``visible`` (only when
          incomplete), ``labels``, ``width``, ``height``, ``name``.
        - ``"hopkins"``: MATLAB v5 with ``x``, ``y``, ``K``, ``s`` (1-based, only with
          labels), ``points``, ``frames``, ``width`` and ``height`` like Hopkins155.
          Complete sequences only.
        - ``"kt3d"``: MATLAB v5 with struct ``Data``: ``ySparse`` (3, P, F; 0 where hidden),
          ``visibleSparse`` (P, F) logical, ``GtLabel`` (P, 1) 1-based (with labels),
          ``nFrames``, ``nSparsePoints``; ``width`` and ``height`` beside it when known.
        - ``"csv"``: ``track,frame,x,y[,label]``, one row per visible entry, tracks
          ``0..P-1``, frames ``0..F-1``, labels 0-based, coordinates written exactly. The
          image size is not kept, and a frame where no point is visible cannot be written.

    The name read back is the stored one (``.npz``) or the file name (without
    ``_truth`` / ``_Tracks``). Coordinates are float64 and written exactly, so
    ``load_sequence(save_sequence(seq, p))`` gives back identical points, visibility and
    labels.

    Returns
    -------
    Path
        The path written.

    Raises
    ------
    SequenceError
        For a path that is a folder, an unknown extension or format, an incomplete sequence
        as ``"hopkins"``, or an empty frame as ``"csv"``.
    """
    p = Path(path)
    fmt = _save_format(seq, p, format)
    if fmt == "npz":
        arrays = {"points": seq.points, "name": np.array(seq.name)}
        if not seq.is_complete:
            arrays["visible"] = seq.visible
        if seq.labels is not None:
            arrays["labels"] = seq.labels
        if seq.image_size is not None:
            arrays["width"] = np.array(seq.image_size[0])
            arrays["height"] = np.array(seq.image_size[1])
        with open(p, "wb") as fh:  # np.savez on an open handle keeps the exact name
            np.savez_compressed(fh, **arrays)
        return p
    if fmt == "csv":
        _save_csv(seq, p)
        return p
    import scipy.io

    F, P, _ = seq.points.shape
    if fmt == "kt3d":
        vis = seq.visible.T  # (P, F)
        y = np.zeros((3, P, F))
        y[:2] = np.where(vis, np.transpose(seq.points, (2, 1, 0)), 0.0)
        y[2] = vis
        data = {"ySparse": y, "visibleSparse": vis.copy(),
                "nFrames": np.array([[F]], dtype=np.float64),
                "nSparsePoints": np.array([[P]], dtype=np.float64)}
        if seq.labels is not None:
            data["GtLabel"] = (seq.labels + 1).astype(np.float64).reshape(-1, 1)
        out = {"Data": data}
        if seq.image_size is not None:
            out["width"] = np.array([[seq.image_size[0]]], dtype=_mat_uint(seq.image_size[0]))
            out["height"] = np.array([[seq.image_size[1]]], dtype=_mat_uint(seq.image_size[1]))
        scipy.io.savemat(str(p), out, do_compression=False, format="5")
        return p
    y = np.ones((3, P, F))
    y[:2] = np.transpose(seq.points, (2, 1, 0))
    if seq.image_size is not None:
        width, height = seq.image_size
    else:
        xmin, xmax, ymin, ymax = seq.extent()
        width, height = int(np.ceil(max(xmax, 1.0))), int(np.ceil(max(ymax, 1.0)))
    K = np.array([[width / 2.0, 0.0, width / 2.0], [0.0, height / 2.0, height / 2.0], [0, 0, 1]])
    x = np.linalg.solve(K, y.reshape(3, -1)).reshape(3, P, F)
    out = {
        "x": x,
        "y": y,
        "K": K,
        "points": np.array([[P]], dtype=_mat_uint(P)),
        "frames": np.array([[F]], dtype=_mat_uint(F)),
        "width": np.array([[width]], dtype=_mat_uint(width)),
        "height": np.array([[height]], dtype=_mat_uint(height)),
    }
    if seq.labels is not None:
        top = int(seq.labels.max()) + 1
        out["s"] = (seq.labels + 1).astype(_mat_uint(top, np.uint8)).reshape(-1, 1)
    scipy.io.savemat(str(p), out, do_compression=False, format="5")
    return p


def _save_format(seq: Sequence, p: Path, format: str | None) -> str:
    if p.is_dir():
        raise SequenceError(f"{p}: is a folder; give a file name (.npz, .mat or .csv)")
    if format is not None:
        if format not in FORMATS:
            raise SequenceError(f"{p}: unknown format {format!r}; use one of {', '.join(FORMATS)}")
        fmt = format
    else:
        fmt = {".npz": "npz", ".csv": "csv", ".mat": "hopkins" if seq.is_complete else "kt3d"}.get(
            p.suffix.lower())
        if fmt is None:
            raise SequenceError(f"{p}: unknown extension {p.suffix!r}; use .npz, .mat or .csv "
                                "(or give the format)")
    if fmt == "hopkins" and not seq.is_complete:
        raise SequenceError(
            f"{p}: the Hopkins155 format cannot hold missing entries ({100 * (1 - seq.visible_share):.1f} "
            "% of this sequence's are missing): save as kt3d, npz or csv, or seq.complete() first")
    return fmt


def _save_csv(seq: Sequence, p: Path) -> None:
    empty = np.flatnonzero(~seq.visible.any(axis=1))
    if empty.size:
        raise SequenceError(f"{p}: frame(s) {', '.join(map(str, empty[:5]))} have no visible point, "
                            "which a tracks CSV (one row per observation) cannot hold: save as npz or kt3d")
    fi, ti = np.nonzero(seq.visible)
    order = np.lexsort((fi, ti))  # by track, then frame
    fi, ti = fi[order], ti[order]
    xy = seq.points[fi, ti]
    header = "track,frame,x,y" + (",label" if seq.labels is not None else "")
    with open(p, "w", newline="", encoding="utf-8") as fh:
        fh.write(header + "\n")
        if seq.labels is None:
            fh.writelines(f"{t},{f},{x!r},{y!r}\n"
                          for t, f, x, y in zip(ti.tolist(), fi.tolist(), *xy.T.tolist()))
        else:
            lab = seq.labels[ti].tolist()
            fh.writelines(f"{t},{f},{x!r},{y!r},{c}\n"
                          for t, f, x, y, c in zip(ti.tolist(), fi.tolist(), *xy.T.tolist(), lab))


def _mat_uint(largest: int, narrowest=np.uint16) -> type:
    """The unsigned type Hopkins155 uses (``narrowest``), wider only when ``largest`` needs it."""
    for dtype in (np.uint8, np.uint16, np.uint32):
        if np.dtype(dtype).itemsize >= np.dtype(narrowest).itemsize and largest <= np.iinfo(dtype).max:
            return dtype
    return np.uint64


def find_truth_files(root: str | os.PathLike) -> list[Path]:
    """All ``<seq>/<seq>_truth.mat`` files under a Hopkins155-style folder, sorted by name."""
    root = Path(root)
    if not root.is_dir():
        raise SequenceError(f"{root}: not a folder")
    return sorted(root.glob("*/*_truth.mat"), key=lambda q: q.parent.name)


def load_sequence_isolated(path: str | os.PathLike, timeout: float = 60.0, *,
                           max_points: int | None = None, max_bytes: int | None = None) -> Sequence:
    """:func:`load_sequence` with ``isolated=True``: for untrusted files (uploads, the CLI)."""
    return load_sequence(path, isolated=True, timeout=timeout, max_points=max_points,
                         max_bytes=max_bytes)


class _MatReader:
    """The child process that parses MAT files for this process (started on first use, reused).

    A crash, a hang or a memory error of the child becomes a :class:`SequenceError` naming
    the file; the next read starts a fresh child. Reads are serialised (one child).
    """

    #: The script the child runs (tests point it elsewhere to simulate a crash).
    script = Path(__file__).with_name("_matchild.py")

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._proc: subprocess.Popen | None = None
        self._pid = 0  # the process that started the child (a forked copy starts its own)

    def _child(self) -> subprocess.Popen:
        if self._proc is None or self._proc.poll() is not None or self._pid != os.getpid():
            env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
            # -c with the current folder dropped from sys.path: the child imports nothing
            # but numpy and scipy, never a module that happens to sit next to the data
            code = ("import sys, runpy; del sys.path[0]; "
                    "runpy.run_path(sys.argv[1], run_name='__main__')")
            self._proc = subprocess.Popen([sys.executable, "-c", code, str(self.script)],
                                          stdin=subprocess.PIPE,
                                          stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                          bufsize=0, env=env)
            self._pid = os.getpid()
        return self._proc

    def read(self, p: Path, timeout: float, max_bytes: int = MAX_BYTES) -> dict:
        from ._matchild import decode

        with self._lock:
            proc = self._child()
            deadline = time.monotonic() + timeout
            try:
                proc.stdin.write(os.fsencode(str(p.resolve())).hex().encode() + b"\n")
                head = _read_exact(proc.stdout, 9, deadline)
                size = struct.unpack(">Q", head[1:])[0]
                if head[:1] == b"o" and size > max_bytes:  # the variables, before reading them
                    self.close(kill=True)
                    _check_size(p, None, size, (0, max_bytes))
                payload = _read_exact(proc.stdout, size, deadline)
            except TimeoutError:
                self.close(kill=True)
                raise SequenceError(f"{p}: reading the file did not finish within {timeout:g} s") from None
            except (OSError, EOFError):  # the child died (BrokenPipeError is an OSError)
                code = self.close()
                how = f"signal {signal.Signals(-code).name}" if code and code < 0 else f"exit code {code}"
                raise SequenceError(f"{p}: corrupt MAT file (the reader crashed: {how})") from None
        if head[:1] == b"e":
            raise SequenceError(f"{p}: {payload.decode(errors='replace')}")
        return decode(payload)

    def close(self, kill: bool = False) -> int | None:
        """Stop the child; its exit code (negative: the signal that ended it)."""
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        if kill:
            proc.kill()
        for stream in (proc.stdin, proc.stdout):
            try:
                stream.close()
            except OSError:
                pass
        try:
            return proc.wait(2)
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.wait()


def _read_exact(stream, n: int, deadline: float) -> bytes:
    fd, chunks = stream.fileno(), []
    while n:
        left = deadline - time.monotonic()
        if left <= 0 or not select.select([fd], [], [], left)[0]:
            raise TimeoutError
        chunk = os.read(fd, min(n, 1 << 20))
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        n -= len(chunk)
    return b"".join(chunks)


_READER = _MatReader()
atexit.register(_READER.close)
