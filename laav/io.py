"""Reading and writing sequences: Hopkins155 ``*_truth.mat`` files and the project's ``.npz``.

The format is chosen once, from the file's first bytes, never from its extension, and
every failure becomes a :class:`~laav.SequenceError` that names the file and the problem.
For untrusted files (``isolated=True``: uploads, the command line, the benchmark) MAT
content is parsed in a child process (:mod:`laav._matchild`), because scipy's MAT reader
can crash the interpreter on damaged files.
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
           "safe_name"]

_MAT_MAGIC = b"MATLAB 5.0 MAT-file"
_HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
_ZIP_MAGIC = b"PK\x03\x04"


#: Most trajectories a file may hold unless ``max_points`` says otherwise. LAAV's memory
#: grows as about 48 bytes x P^2 (pairwise trajectory distances and the voting's arrays):
#: 10,000 points need about 5 GB, 20,000 would exhaust a 16 GB machine.
MAX_POINTS = 10_000
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
    return stem[: -len("_truth")] if stem.endswith("_truth") else stem


def _resolve(path: str | os.PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise SequenceError(f"{p}: no such file or folder")
    if p.is_dir():
        found = sorted(p.glob("*_truth.mat"))
        if not found:
            found = sorted(q for q in p.iterdir() if q.suffix.lower() in (".mat", ".npz"))
        if len(found) != 1:
            what = "no" if not found else f"{len(found)}"
            raise SequenceError(
                f"{p}: folder holds {what} sequence files; expected exactly one *_truth.mat"
            )
        p = found[0]
    return p


def load_sequence(path: str | os.PathLike, *, isolated: bool = False,
                  timeout: float = 60.0, max_points: int | None = None,
                  max_bytes: int | None = None) -> Sequence:
    """Read a sequence from a Hopkins155 ``*_truth.mat``, a ``.npz``, or a folder holding one.

    Parameters
    ----------
    path : str or path-like
        A MATLAB v5 file with the Hopkins155 variables (``y``: (3, P, F) homogeneous pixel
        coordinates, ``s``: (P, 1) 1-based labels, ``width``, ``height``), a ``.npz`` with
        ``points`` (F, P, 2) and optionally ``labels`` (P,), ``width``, ``height``, or a
        folder containing exactly one such file. The format is taken from the content.
    isolated : bool
        Parse MAT content in a child process, so that a file crashing scipy's reader (or
        hanging it longer than ``timeout`` seconds, or needing more memory than
        :data:`laav._matchild.MEMORY_LIMIT`) raises a :class:`SequenceError` instead of
        taking the caller down. Use it for every file you did not write yourself.
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
        return _load_mat(p, _READER.read(p, timeout, lim[1]) if isolated else _read_mat_here(p), lim)
    if head[:512].find(_HDF5_MAGIC) >= 0 or head.startswith(b"MATLAB 7.3"):
        raise SequenceError(f"{p}: MATLAB v7.3 (HDF5) files are not supported; save with -v7")
    raise SequenceError(
        f"{p}: not a MATLAB v5 .mat or NumPy .npz file (unrecognised content)"
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


def _read_mat_here(p: Path) -> dict:
    from ._matchild import MatReadError, read_mat_variables

    try:
        return read_mat_variables(str(p))
    except MatReadError as exc:
        raise SequenceError(f"{p}: {exc}") from None


def _load_mat(p: Path, mat: dict, lim: tuple[int, int]) -> Sequence:
    if "y" not in mat:
        raise SequenceError(f"{p}: missing variable 'y' (homogeneous pixel coordinates, 3 x P x F)")
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
        labels = s - 1
    image_size = None
    if "width" in mat and "height" in mat:
        image_size = (_scalar(mat["width"], "width", p), _scalar(mat["height"], "height", p))
    return Sequence(
        points=points, labels=labels, name=_name_from_path(p), image_size=image_size, source=str(p)
    )


_NPZ_MEMBERS = ("points", "labels", "width", "height", "name")


def _load_npz(p: Path, lim: tuple[int, int]) -> Sequence:
    try:
        _npz_declared(p, _NPZ_MEMBERS, lim)
        with np.load(p, allow_pickle=False) as data:
            files = set(data.files)
            if "points" not in files:
                raise SequenceError(f"{p}: missing array 'points' (frames x points x 2)")
            points = data["points"]
            labels = data["labels"] if "labels" in files else None
            image_size = None
            if "width" in files and "height" in files:
                image_size = (
                    _scalar(data["width"], "width", p),
                    _scalar(data["height"], "height", p),
                )
            name = _stored_name(data["name"]) if "name" in files else None
    except SequenceError:
        raise
    except Exception as exc:  # BadZipFile, zlib.error, ValueError, MemoryError, ...
        raise SequenceError(f"{p}: truncated or corrupt NPZ file ({type(exc).__name__}: {exc})") from None
    return Sequence(points=points, labels=labels, name=name or _name_from_path(p),
                    image_size=image_size, source=str(p))


def _stored_name(value) -> str | None:
    """The ``name`` stored in a file: one string, control characters dropped, at most 200 long."""
    arr = np.asarray(value)
    if arr.size != 1 or arr.dtype.kind not in "US":
        return None
    text = arr.ravel()[0]
    text = text.decode("utf-8", "replace") if isinstance(text, bytes) else str(text)
    return re.sub(r"[\x00-\x1f\x7f-\x9f\u2028\u2029]", "", text)[:200].strip() or None


def save_sequence(seq: Sequence, path: str | os.PathLike) -> Path:
    """Write ``seq`` to ``path`` as ``.npz`` or Hopkins-style MATLAB v5 ``.mat`` (by extension).

    Coordinates are written as float64, so ``load_sequence(save_sequence(seq, p))`` gives
    back identical arrays. The ``.mat`` file carries ``x``, ``y``, ``K``, ``s`` (1-based,
    only with labels), ``points``, ``frames``, ``width`` and ``height`` like Hopkins155.

    Returns
    -------
    Path
        The path written.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".npz":
        arrays = {"points": seq.points, "name": np.array(seq.name)}
        if seq.labels is not None:
            arrays["labels"] = seq.labels
        if seq.image_size is not None:
            arrays["width"] = np.array(seq.image_size[0])
            arrays["height"] = np.array(seq.image_size[1])
        with open(p, "wb") as fh:  # np.savez on an open handle keeps the exact name
            np.savez_compressed(fh, **arrays)
        return p
    if suffix == ".mat":
        import scipy.io

        F, P, _ = seq.points.shape
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
    raise SequenceError(f"{p}: unknown extension {p.suffix!r}; use .npz or .mat")


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
            script = str(Path(__file__).with_name("_matchild.py"))
            self._proc = subprocess.Popen([sys.executable, "-c", code, script], stdin=subprocess.PIPE,
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
