"""Fuzz the sequence loader the way untrusted files reach it (uploads, ``laav segment``, bench).

Builds >= 5,000 mutants from the bundled ``explorer/assets/*.mat`` and a few Hopkins155
files (bit flips, truncation, wrong MAT tags and dimensions, extension/content mismatch,
pickles, NaN/Inf, wrong shapes, random bytes; the same sequences with tracks hidden, as
KT3DMoSeg ``.mat`` and tracks CSV, bit-flipped, truncated, duplicated rows and text in
numeric fields) and loads each with ``laav.load_sequence(path, isolated=True)`` (``--mode
isolated``, the default) or ``laav.load_sequence(path)`` (``--mode inprocess``: MAT content
parsed in the worker itself, after :mod:`laav._matvalidate` checked its structure) in a
worker process. Prints the count of each outcome:

* ok: a Sequence came back;
* clean error: a ``SequenceError`` whose message names the file;
* crash: the worker (the caller) died;
* hang: a load took over 10 s;
* raw exception: any other exception, or a message not naming the file.

::

    python benchmarks/fuzz_loader.py [--mode isolated|inprocess] [--hopkins DIR] [--per-source N] [--limit N]

Mutants are rebuilt from their index (fixed seeds), so a reported index reproduces with
``--only INDEX``. Nothing is written outside a temporary folder. The worker's address
space is capped (4 GiB) so that a mutant declaring huge arrays cannot exhaust the machine.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import pickle
import struct
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
HOPKINS = ("1R2RC", "cars1", "arm", "people1")
HANG_S = 10.0
MARKER = Path(tempfile.gettempdir()) / "laav_fuzz_pickle_ran"


class _Evil:
    """Unpickling this would create MARKER (it must never happen)."""

    def __reduce__(self):
        return (open, (str(MARKER), "w"))


def _sources(hopkins: Path | None) -> list[tuple[str, bytes]]:
    out = [(p.stem, p.read_bytes()) for p in sorted((REPO / "explorer" / "assets").glob("*.mat"))]
    if hopkins is not None and hopkins.is_dir():
        for name in HOPKINS:
            f = hopkins / name / f"{name}_truth.mat"
            if f.is_file():
                out.append((name, f.read_bytes()))
    return out


def _npz_bytes(**arrays) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def _mat_bytes(**arrays) -> bytes:
    import scipy.io

    buf = io.BytesIO()
    scipy.io.savemat(buf, arrays, do_compression=False, format="5")
    return buf.getvalue()


def _elements(b: bytes) -> list[int]:
    """Offsets of the top-level data elements of a little-endian MAT v5 file."""
    out, o = [], 128
    while o + 8 <= len(b) and len(out) < 64:
        size = struct.unpack_from("<I", b, o + 4)[0]
        out.append(o)
        o += 8 + size + (-size % 8)
    return out


def _as_npz(seq_bytes: bytes) -> bytes:
    """A MAT source's sequence as the project's .npz (points, labels, name, width, height)."""
    import laav

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s_truth.mat"
        p.write_bytes(seq_bytes)
        seq = laav.load_sequence(p)
        return Path(laav.save_sequence(seq, Path(d) / "s.npz")).read_bytes()


def _as_incomplete(seq_bytes: bytes, fmt: str) -> bytes:
    """A MAT source's sequence with a quarter of its tracks ending early, saved as ``fmt``."""
    import laav

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "s_truth.mat"
        p.write_bytes(seq_bytes)
        seq = laav.load_sequence(p)
        vis = np.ones((seq.n_frames, seq.n_points), bool)
        vis[max(2, seq.n_frames // 2):, ::4] = False
        seq = laav.Sequence(seq.points, seq.labels, name=seq.name, visible=vis)
        return Path(laav.save_sequence(seq, Path(d) / "s.x", format=fmt)).read_bytes()


def _incomplete_mutant(kind: str, b: bytearray, name: str, rng) -> tuple[str, bytes]:
    """Mutants of the KT3DMoSeg (``kt3d_*``) and tracks CSV (``csv_*``) forms of a source."""
    fname = f"{name}_Tracks.mat" if kind.startswith("kt3d") else f"{name}.csv"
    if kind.endswith("_bitflip"):
        for pos in rng.integers(0, len(b), rng.integers(1, 9)):
            b[pos] ^= 1 << int(rng.integers(8))
        return fname, bytes(b)
    if kind.endswith("_truncate"):
        return fname, bytes(b[: int(rng.integers(0, len(b)))])
    lines = bytes(b).split(b"\n")
    if kind == "csv_duplicate":  # a (track, frame) twice
        return fname, b"\n".join(lines + [lines[1 + int(rng.integers(len(lines) - 2))]])
    if kind == "csv_text":  # a word in a numeric field
        i = 1 + int(rng.integers(len(lines) - 2))
        cells = lines[i].split(b",")
        cells[int(rng.integers(len(cells)))] = b"<b>x</b>"
        lines[i] = b",".join(cells)
        return fname, b"\n".join(lines)
    if kind == "csv_huge_grid":  # 10,000 rows declaring a (10,000 frames x 5,000 tracks) grid
        rows = b"".join(b"%d,%d,1,2\n" % (t, 2 * t + k) for t in range(5000) for k in range(2))
        return fname, b"track,frame,x,y\n" + rows
    raise ValueError(kind)


def build_specs(n_sources: int, per_source: int) -> list[tuple]:
    """``(kind, source index, seed)`` for every mutant (bytes are made on demand)."""
    kinds = {"bitflip": 0.45, "header_flip": 0.15, "truncate": 0.08, "tag": 0.12, "dims": 0.08,
             "npz_bitflip": 0.06, "npz_truncate": 0.03, "zip_entry": 0.03,
             "kt3d_bitflip": 0.06, "kt3d_truncate": 0.02, "csv_bitflip": 0.04, "csv_truncate": 0.02}
    specs = []
    for s in range(n_sources):
        for kind, share in kinds.items():
            specs += [(kind, s, i) for i in range(max(1, round(share * per_source)))]
    fixed = ["mat_as_npz", "npz_as_mat", "mat_as_txt", "pickle_npz", "pickle_raw", "pickle_raw_mat",
             "nan_mat", "inf_mat", "nan_npz", "inf_npz", "shape_3d_points", "shape_2d_points",
             "shape_labels", "shape_y_4rows", "labels_zero", "empty", "random", "magic_only",
             "hdf5", "zero_w", "csv_duplicate", "csv_text", "csv_huge_grid"]
    for s in range(n_sources):
        specs += [(kind, s, 0) for kind in fixed]
    return specs


def make_mutant(spec: tuple, sources: list[tuple[str, bytes]], npz_cache: dict) -> tuple[str, bytes]:
    """``(file name, bytes)`` of one mutant."""
    kind, s, seed = spec
    name, mat = sources[s]
    rng = np.random.default_rng([s, seed, sum(map(ord, kind))])
    b = bytearray(mat)
    if kind.startswith(("kt3d_", "csv_")):
        fmt = "kt3d" if kind.startswith("kt3d") else "csv"
        if (s, fmt) not in npz_cache:
            npz_cache[(s, fmt)] = _as_incomplete(mat, fmt)
        return _incomplete_mutant(kind, bytearray(npz_cache[(s, fmt)]), name, rng)
    if kind.startswith("npz_") or kind == "zip_entry":
        if s not in npz_cache:
            npz_cache[s] = _as_npz(mat)
        b = bytearray(npz_cache[s])
    if kind in ("bitflip", "npz_bitflip"):
        for pos in rng.integers(0, len(b), rng.integers(1, 9)):
            b[pos] ^= 1 << int(rng.integers(8))
        return f"{name}_truth{'.npz' if kind.startswith('npz') else '.mat'}", bytes(b)
    if kind == "header_flip":  # flips in the first 64 bytes of data elements (tags, flags, dims)
        els = _elements(mat)
        for _ in range(rng.integers(1, 4)):
            o = els[int(rng.integers(len(els)))] + int(rng.integers(64))
            if o < len(b):
                b[o] ^= 1 << int(rng.integers(8))
        return f"{name}_truth.mat", bytes(b)
    if kind in ("truncate", "npz_truncate"):
        cut = int(rng.integers(0, len(b)))
        return f"{name}_truth{'.npz' if kind.startswith('npz') else '.mat'}", bytes(b[:cut])
    if kind == "tag":  # a random 32-bit word of an element header set to an extreme value
        els = _elements(mat)
        o = els[int(rng.integers(len(els)))] + 4 * int(rng.integers(16))
        val = int(rng.choice([0, 1, 5, 14, 15, 0x7FFFFFFF, 0xFFFFFFFF, 0x80000000, 0xFFFF0000,
                              int(rng.integers(0, 2**32))]))
        if o + 4 <= len(b):
            struct.pack_into("<I", b, o, val)
        return f"{name}_truth.mat", bytes(b)
    if kind == "dims":  # one dimension of a matrix (offset 32 in a miMATRIX element) changed
        els = _elements(mat)
        o = els[int(rng.integers(len(els)))] + 32 + 4 * int(rng.integers(3))
        val = int(rng.choice([0, 1, 2, 3, -1, 2**31 - 1, 2**20, 2**16, -(2**31)]))
        if o + 4 <= len(b):
            struct.pack_into("<i", b, o, val)
        return f"{name}_truth.mat", bytes(b)
    if kind == "zip_entry":  # an entry of the .npz replaced by another (valid) array
        arrays = dict(np.load(io.BytesIO(bytes(b))))
        key = ["points", "labels", "name", "width", "height"][seed % 5]
        arrays[key] = [np.zeros(()), np.zeros((3, 4)), np.array(["a", "b"]), np.full((2, 9, 2), 1e308),
                       np.array(-7), np.zeros((0, 0, 2)), np.arange(10 ** 3)][seed % 7]
        return f"{name}.npz", _npz_bytes(**arrays)
    if s not in npz_cache:
        npz_cache[s] = _as_npz(mat)
    npz = npz_cache[s]
    good = dict(np.load(io.BytesIO(npz)))
    pts, lab = good["points"], good.get("labels")
    y = np.concatenate([np.transpose(pts, (2, 1, 0)), np.ones((1,) + pts.shape[1::-1])])
    s1 = None if lab is None else (lab + 1).reshape(-1, 1).astype(float)
    if kind == "mat_as_npz":
        return f"{name}.npz", mat
    if kind == "npz_as_mat":
        return f"{name}_truth.mat", npz
    if kind == "mat_as_txt":
        return f"{name}.txt", mat
    if kind == "pickle_npz":
        return f"{name}.npz", _npz_bytes(points=np.array([_Evil(), 1], dtype=object))
    if kind == "pickle_raw":
        return f"{name}.npz", pickle.dumps(_Evil())
    if kind == "pickle_raw_mat":
        return f"{name}_truth.mat", pickle.dumps({"y": _Evil()})
    if kind in ("nan_mat", "inf_mat"):
        y2 = y.copy()
        y2[0, int(rng.integers(y.shape[1])), 0] = np.nan if kind == "nan_mat" else np.inf
        return f"{name}_truth.mat", _mat_bytes(y=y2, s=s1)
    if kind in ("nan_npz", "inf_npz"):
        p2 = pts.copy()
        p2[0, 0, 1] = np.nan if kind == "nan_npz" else -np.inf
        return f"{name}.npz", _npz_bytes(points=p2, labels=lab)
    if kind == "shape_3d_points":
        return f"{name}.npz", _npz_bytes(points=np.concatenate([pts, pts[..., :1]], axis=2))
    if kind == "shape_2d_points":
        return f"{name}.npz", _npz_bytes(points=pts[0])
    if kind == "shape_labels":
        return f"{name}.npz", _npz_bytes(points=pts, labels=lab[:-3])
    if kind == "shape_y_4rows":
        return f"{name}_truth.mat", _mat_bytes(y=np.concatenate([y, y[:1]]), s=s1)
    if kind == "labels_zero":
        return f"{name}_truth.mat", _mat_bytes(y=y, s=s1 - 1)
    if kind == "zero_w":
        y2 = y.copy()
        y2[2, 0, 0] = 0
        return f"{name}_truth.mat", _mat_bytes(y=y2, s=s1)
    if kind == "empty":
        return f"{name}.mat", b""
    if kind == "random":
        return f"{name}.mat", rng.bytes(4096)
    if kind == "magic_only":
        return f"{name}_truth.mat", mat[:128]
    if kind == "hdf5":
        return f"{name}_truth.mat", b"\x89HDF\r\n\x1a\n" + bytes(500)
    raise ValueError(kind)


def worker(hopkins: Path | None, per_source: int,
           isolated: bool = True) -> None:  # pragma: no cover - child process
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30))
    except (ImportError, ValueError, OSError):
        pass
    import laav

    sources = _sources(hopkins)
    specs = build_specs(len(sources), per_source)
    cache: dict = {}
    with tempfile.TemporaryDirectory(prefix="laav-fuzz-") as d:
        for line in sys.stdin:
            i = int(line)
            fname, data = make_mutant(specs[i], sources, cache)
            path = Path(d) / f"{i}_{fname}"
            path.write_bytes(data)
            t0 = time.monotonic()
            try:
                laav.load_sequence(path, isolated=isolated)
                outcome, msg = "ok", ""
            except laav.SequenceError as exc:
                msg = str(exc)
                outcome = "clean error" if path.name in msg else "raw exception"
            except BaseException as exc:  # noqa: BLE001 - that is what we count
                outcome, msg = "raw exception", f"{type(exc).__name__}: {exc}"
            dt = time.monotonic() - t0
            path.unlink()
            print(json.dumps({"i": i, "outcome": "hang" if dt > HANG_S else outcome, "s": dt,
                              "msg": msg[:300]}), flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hopkins", type=Path, default=Path("/work/shared/data/hopkins155"))
    ap.add_argument("--per-source", type=int, default=720, help="generated mutants per source file")
    ap.add_argument("--limit", type=int, default=0, help="only the first N mutants (0: all)")
    ap.add_argument("--only", type=int, action="append", default=[], help="only mutant INDEX")
    ap.add_argument("--mode", choices=("isolated", "inprocess"), default="isolated",
                    help="isolated: load_sequence(path, isolated=True); inprocess: load_sequence(path)")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        worker(args.hopkins, args.per_source, isolated=args.mode == "isolated")
        return 0
    MARKER.unlink(missing_ok=True)
    sources = _sources(args.hopkins)
    specs = build_specs(len(sources), args.per_source)
    todo = args.only or list(range(len(specs)))[: args.limit or None]
    print(f"{len(todo)} mutants of {len(sources)} files ({args.mode}): "
          f"{', '.join(n for n, _ in sources)}", flush=True)
    cmd = [sys.executable, __file__, "--worker", "--hopkins", str(args.hopkins),
           "--per-source", str(args.per_source), "--mode", args.mode]
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    counts: Counter = Counter()
    by_kind: dict = {}
    notes: list[str] = []
    contained: list[str] = []  # the MAT reader child crashed, the caller got a SequenceError
    proc = None
    t_start = time.monotonic()
    for n, i in enumerate(todo):
        if proc is None or proc.poll() is not None:
            proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                    env=env, bufsize=1)
        proc.stdin.write(f"{i}\n")
        proc.stdin.flush()
        import selectors

        sel = selectors.DefaultSelector()
        sel.register(proc.stdout, selectors.EVENT_READ)
        ready = sel.select(HANG_S + 60)  # the loader itself gives up after 60 s
        sel.close()
        line = proc.stdout.readline() if ready else ""
        if line:
            rec = json.loads(line)
            outcome = rec["outcome"]
        else:
            outcome = "hang" if not ready else "crash"
            code = proc.poll()
            proc.kill()
            proc.wait()
            proc = None
            rec = {"msg": f"worker exit code {code}"}
        counts[outcome] += 1
        if outcome == "clean error" and "the reader crashed" in rec["msg"]:
            contained.append(f"  #{i} {specs[i]}: {rec['msg']}")
        by_kind.setdefault(specs[i][0], Counter())[outcome] += 1
        if outcome in ("crash", "hang", "raw exception"):
            notes.append(f"  #{i} {specs[i]}: {outcome}: {rec['msg']}")
        if (n + 1) % 500 == 0:
            print(f"  {n + 1} done ({time.monotonic() - t_start:.0f} s): {dict(counts)}", flush=True)
    if proc is not None:
        proc.stdin.close()
        proc.wait()
    print(f"\n{len(todo)} mutants in {time.monotonic() - t_start:.0f} s")
    for outcome in ("ok", "clean error", "crash", "hang", "raw exception"):
        print(f"  {outcome:14s} {counts[outcome]:6d}")
    print(f"  (of the clean errors, {len(contained)} were crashes of the isolated MAT reader)")
    print("\n".join(contained[:20]))
    print("by kind:")
    for kind, c in by_kind.items():
        print(f"  {kind:16s} " + ", ".join(f"{k} {v}" for k, v in sorted(c.items())))
    print(f"pickle payload executed: {'YES' if MARKER.exists() else 'no'}")
    if notes:
        print("problems:\n" + "\n".join(notes[:50]))
    bad = counts["crash"] + counts["hang"] + counts["raw exception"] + MARKER.exists()
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
