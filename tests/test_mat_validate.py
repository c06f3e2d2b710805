"""The MAT v5 structure check that runs before scipy reads a file (issue 16 items 2 and 6).

scipy's MAT reader trusts the sizes and dimensions a file declares and can crash the
interpreter on damaged files; :func:`laav._matchild.validate_mat5` walks the whole
structure first, so ``laav.load_sequence(path)`` refuses such files in-process too.
"""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.io
import scipy.sparse

import laav
from laav._matchild import MatReadError, validate_mat5
from laav.synthetic import make_sequence

REPO = Path(__file__).resolve().parents[1]
ASSETS = sorted((REPO / "explorer" / "assets").glob("*.mat"))
HOPKINS = Path("/work/shared/data/hopkins155")


def _rich() -> dict:
    return {"y": np.random.default_rng(0).random((3, 10, 4)), "s": np.arange(10.0).reshape(-1, 1) + 1,
            "c": np.array([1 + 2j, 3]), "txt": "hello wörld", "empty": np.zeros((0,)),
            "cell": np.array([np.zeros(3), "x", np.zeros((0, 0))], dtype=object),
            "st": {"a": np.eye(2), "b": "q", "e": np.zeros((0, 3)), "n": {"deep": np.arange(3)}},
            "sp": scipy.sparse.random(5, 4, density=0.3, format="csc", random_state=0),
            "spc": scipy.sparse.csc_matrix(np.array([[0, 1j], [2, 0]])),
            "lg": np.array([True, False]), "i8": np.arange(5, dtype=np.int8),
            "u64": np.arange(3, dtype=np.uint64)}


@pytest.mark.parametrize("path", ASSETS, ids=lambda p: p.name)
def test_bundled_assets_pass(path):
    validate_mat5(str(path))


def test_hopkins155_files_pass():
    files = sorted(HOPKINS.glob("*/*_truth.mat")) if HOPKINS.is_dir() else []
    if not files:
        pytest.skip("Hopkins155 not at /work/shared/data/hopkins155")
    for f in files:
        validate_mat5(str(f))


@pytest.mark.parametrize("compress", [False, True], ids=["plain", "compressed"])
def test_every_array_class_scipy_writes_passes(tmp_path, compress):
    p = tmp_path / "rich.mat"
    scipy.io.savemat(p, _rich(), do_compression=compress)
    validate_mat5(str(p))
    assert {"y", "st", "sp", "cell"} <= set(scipy.io.loadmat(p))


def _elements(b: bytes) -> list[int]:
    out, o = [], 128
    while o + 8 <= len(b):
        out.append(o)
        o += 8 + struct.unpack_from("<I", b, o + 4)[0]
    return out


def _y_file(tmp_path) -> bytes:
    seq = make_sequence(n_objects=1, n_frames=5, n_points=40, rng=0)
    return laav.save_sequence(seq, tmp_path / "ok_truth.mat").read_bytes()


@pytest.mark.parametrize("case, message", [
    ("truncated header", "header is truncated"),
    ("endian", "bad endian indicator"),
    ("variable too long", "declares"),
    ("top type", "expected a matrix"),
    ("data type 15", "real part has element type 15"),
    ("data count", "its dimensions declare"),
    ("dims", "its dimensions declare"),
    ("negative dim", "negative dimension"),
    ("flags", "array flags element malformed"),
    ("class", "unsupported MATLAB array class"),
    ("stray bytes", "stray byte"),
    ("bad zlib", "does not inflate"),
])
def test_damaged_structure_is_refused(tmp_path, case, message):
    b = bytearray(_y_file(tmp_path))
    y = b.index(b"\x01\x00\x01\x00y\x00\x00\x00")  # the name element of 'y'
    data = y + 8  # the tag of y's real part
    first = [e for e in _elements(bytes(b)) if e < y][-1]  # the variable 'y' (laav reads it)
    if case == "truncated header":
        b = b[:100]
    elif case == "endian":
        b[126:128] = b"XX"
    elif case == "variable too long":
        struct.pack_into("<I", b, first + 4, len(b))
    elif case == "top type":
        struct.pack_into("<I", b, first, 9)
    elif case == "data type 15":
        b[data] = 15
    elif case == "data count":
        struct.pack_into("<I", b, data + 4, 16)
    elif case in ("dims", "negative dim"):
        dims = b.index(struct.pack("<II", 5, 12), first)  # 3 dims of y: miINT32, 12 bytes
        struct.pack_into("<i", b, dims + 12, -1 if case == "negative dim" else 7)
    elif case == "flags":
        struct.pack_into("<I", b, first + 8 + 4, 4)
    elif case == "class":
        b[first + 16] = 16  # mxFUNCTION
    elif case == "stray bytes":
        b += b"\0\0\0"
    elif case == "bad zlib":
        b = b[:128] + struct.pack("<II", 15, 16) + b"not zlib at all!"
    p = tmp_path / "bad_truth.mat"
    p.write_bytes(bytes(b))
    with pytest.raises(MatReadError, match=message):
        validate_mat5(str(p))
    with pytest.raises(laav.SequenceError, match=rf"bad_truth\.mat: .*{message}"):
        laav.load_sequence(p)


def test_zip_bomb_in_a_compressed_variable_is_not_inflated(tmp_path):
    import zlib

    n = 1 << 23  # y: 1 x n doubles, 64 MiB of zeros
    header = (struct.pack("<IIII", 6, 8, 6, 0) + struct.pack("<IIii", 5, 8, 1, n)
              + struct.pack("<I", (1 << 16) | 1) + b"y\0\0\0" + struct.pack("<II", 9, 8 * n))
    inner = struct.pack("<II", 14, len(header) + 8 * n) + header + bytes(8 * n)
    comp = zlib.compress(inner, 9)
    p = tmp_path / "bomb_truth.mat"
    p.write_bytes(b"MATLAB 5.0 MAT-file".ljust(124, b" ") + b"\x00\x01IM"
                  + struct.pack("<II", 15, len(comp)) + comp + bytes(-len(comp) % 8))
    with pytest.raises(laav.SequenceError, match="inflates to over 1,000,000 bytes"):
        laav.load_sequence(p, max_bytes=1_000_000)


def test_fuzzed_mutants_never_crash_in_process():
    """A slice of benchmarks/fuzz_loader.py in its in-process mode (the whole run: >= 5,000
    mutants, 0 crashes, see the closing note of issue 16)."""
    run = subprocess.run([sys.executable, str(REPO / "benchmarks" / "fuzz_loader.py"),
                          "--mode", "inprocess", "--per-source", "60", "--hopkins", str(HOPKINS)],
                         capture_output=True, text=True, timeout=900)
    tail = run.stdout[-3000:]
    assert run.returncode == 0, tail
    assert "crash               0" in tail and "raw exception       0" in tail
