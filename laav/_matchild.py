"""MATLAB v5 reading for :mod:`laav.io`, in this process or as a child process.

``scipy.io.loadmat`` can crash the interpreter outright (a segmentation fault) on some
damaged MAT v5 files: it trusts the sizes and dimensions a file declares. Every read
therefore first walks the file's structure (:func:`validate_mat5`: the header, every data
element's tag, each array's flags, dimensions and name, and that every element's declared
byte count fits in its parent and agrees with the array's dimensions, recursively through
structs, cells, sparse and compressed arrays) and refuses a file where anything is
inconsistent before scipy sees it. As a second line of defence,
:func:`laav.load_sequence` with ``isolated=True`` runs
this file as a script (``python _matchild.py``: it imports only numpy and scipy, never the
``laav`` package) and sends it file paths; a crash or a hang then costs only the child.

Protocol: one hex-encoded path per line on stdin; per path one reply on stdout: a kind
byte (``o``: an ``.npz`` of the numeric variables follows; ``e``: a UTF-8 message), an
8-byte big-endian length and the payload. The child's address space is capped
(:data:`MEMORY_LIMIT`), so a file declaring huge arrays gives a message, not a swapping
machine.
"""

from __future__ import annotations

import io
import os
import struct
import sys

import numpy as np

#: The variables laav reads: Hopkins155's, and KT3DMoSeg's struct ``Data``; every other
#: variable is skipped.
VARIABLES = ("y", "s", "width", "height", "Data")
#: The fields of KT3DMoSeg's ``Data`` laav reads, returned as ``"Data.<field>"``.
DATA_FIELDS = ("ySparse", "visibleSparse", "GtLabel")
#: Address-space cap of the child process (bytes).
MEMORY_LIMIT = 3 << 30


class MatReadError(Exception):
    """The file cannot be read; the message says why (without the path)."""


# MAT v5 data types (mi*) and array classes (mx*), as in MATLAB's "MAT-File Format"
_MI_INT8, _MI_UINT8, _MI_INT32, _MI_UINT32 = 1, 2, 5, 6
_MI_MATRIX, _MI_COMPRESSED = 14, 15
_MI_UTF8 = 16
#: bytes per value of the numeric and text element types
_MI_SIZE = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8, 16: 1, 17: 2, 18: 4}
_MI_DTYPE = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8", 12: "i8",
             13: "u8"}
_MX_CELL, _MX_STRUCT, _MX_OBJECT, _MX_CHAR, _MX_SPARSE = 1, 2, 3, 4, 5
_MX_NUMERIC = frozenset(range(6, 16))  # double, single, int8 .. uint64
_FLAG_COMPLEX = 0x0800
#: Deepest nesting of structs and cells accepted.
MAX_DEPTH = 32
#: Most bytes a compressed variable may inflate to (a zip bomb is refused, not inflated).
MAX_INFLATED = 1 << 30


def validate_mat5(path: str, max_bytes: int | None = None) -> None:
    """Check the structure of the MAT v5 file ``path`` before scipy reads it.

    Raises :class:`MatReadError` saying what is wrong (and at which byte) when the header
    is not MAT v5, an element's tag has an unknown type, declares more bytes than its
    parent holds, an array's flags, dimensions or name element is malformed, an array's
    data element does not hold exactly the values its dimensions declare, a struct's
    field names or a cell's elements do not match its size, a sparse array's indices are
    out of range, a compressed variable does not inflate to exactly one array (or to more
    than ``max_bytes`` / :data:`MAX_INFLATED`), or the file (``max_bytes``) is too large.
    The variables laav reads (:data:`VARIABLES`) are checked whole; of the others, which
    scipy skips, the element's extent and the array header (flags, dimensions, name) that
    scipy parses before skipping them.
    """
    try:
        size = os.path.getsize(path)
        if max_bytes is not None and size > max_bytes:
            raise MatReadError(f"the file's {size:,} bytes are over the limit of {max_bytes:,} "
                               "bytes (max_bytes)")
        with open(path, "rb") as fh:
            buf = fh.read()
    except OSError as exc:
        raise MatReadError(f"cannot be read ({exc.strerror or exc})") from None
    _Mat5Checker(buf, min(max_bytes or MAX_INFLATED, MAX_INFLATED)).file()


class _Mat5Checker:
    def __init__(self, buf: bytes, inflate_limit: int) -> None:
        self.buf, self.limit, self.bo = buf, inflate_limit, "<"

    def fail(self, what: str, pos: int) -> None:
        raise MatReadError(f"corrupt MAT file: {what} (byte {pos})")

    def file(self) -> None:
        buf = self.buf
        if len(buf) < 128:
            self.fail("the 128-byte header is truncated", len(buf))
        endian = buf[126:128]
        if endian not in (b"IM", b"MI"):
            self.fail(f"bad endian indicator {endian!r} in the header", 126)
        self.bo = "<" if endian == b"IM" else ">"
        pos, n_vars = 128, 0
        while pos < len(buf):
            if len(buf) - pos < 8:
                self.fail(f"{len(buf) - pos} stray byte(s) after the last variable", pos)
            mdtype, nbytes = struct.unpack_from(self.bo + "II", buf, pos)
            start, end = pos + 8, pos + 8 + nbytes
            if nbytes == 0 or end > len(buf):
                self.fail(f"variable {n_vars + 1} declares {nbytes:,} bytes, the file holds "
                          f"{len(buf) - start:,} more", pos)
            if mdtype == _MI_MATRIX:
                self.matrix(buf, start, end, 0)
            elif mdtype == _MI_COMPRESSED:
                self.compressed(buf[start:end], pos)
            else:
                self.fail(f"variable {n_vars + 1} has element type {mdtype}, expected a matrix "
                          "(14) or compressed data (15)", pos)
            pos, n_vars = end, n_vars + 1

    def compressed(self, data: bytes, pos: int) -> None:
        import zlib

        d = zlib.decompressobj()
        try:
            inner = d.decompress(data, 1 << 16)  # the header first: scipy reads only that ...
            if len(inner) < 8:
                self.fail("compressed variable holds no array", pos)
            mdtype, nbytes = struct.unpack_from(self.bo + "II", inner, 0)
            if mdtype != _MI_MATRIX:
                self.fail(f"compressed variable holds element type {mdtype}, expected a matrix", pos)
            if nbytes == 0:
                self.fail("compressed variable holds an empty array", pos)
            if len(inner) < 8 + nbytes and not d.eof:  # ... of a variable it is not asked for
                if self.matrix(inner, 8, len(inner), 0, header_only=True) not in VARIABLES:
                    return
                inner += d.decompress(d.unconsumed_tail, self.limit + 1 - len(inner))
        except zlib.error as exc:
            self.fail(f"compressed variable does not inflate ({exc})", pos)
        if len(inner) > self.limit:
            self.fail(f"compressed variable inflates to over {self.limit:,} bytes", pos)
        if 8 + nbytes > len(inner):
            what = "is truncated" if not d.eof else f"inflates to {len(inner) - 8:,} bytes"
            self.fail(f"compressed variable's array declares {nbytes:,} bytes but {what}", pos)
        self.matrix(inner, 8, 8 + nbytes, 0)

    def tag(self, buf: bytes, pos: int, end: int) -> tuple[int, int, int, int]:
        """``(type, byte count, data start, next element)`` of the element at ``pos``."""
        if end - pos < 8:
            self.fail("data element truncated", pos)
        mdtype, nbytes = struct.unpack_from(self.bo + "II", buf, pos)
        small = mdtype >> 16
        if small:  # small data element: type and count in 4 bytes, data in the next 4
            if small > 4:
                self.fail(f"small data element declares {small} bytes (at most 4)", pos)
            return mdtype & 0xFFFF, small, pos + 4, pos + 8
        nxt = pos + 8 + nbytes + (-nbytes % 8)
        if nbytes > end - pos - 8 or nxt > end:
            self.fail(f"data element declares {nbytes:,} bytes, its parent holds "
                      f"{max(end - pos - 8, 0):,}", pos)
        return mdtype, nbytes, pos + 8, nxt

    def values(self, buf, pos, end, count: int, what: str, types) -> tuple[int, int, int]:
        """Check a data element of ``count`` values of one of ``types``; ``(type, start, next)``."""
        mdtype, nbytes, start, nxt = self.tag(buf, pos, end)
        if mdtype not in types:
            self.fail(f"{what} has element type {mdtype}", pos)
        if mdtype == _MI_UTF8:  # variable width: at least one byte per character
            if nbytes < count:
                self.fail(f"{what} holds {nbytes} bytes for {count:,} characters", pos)
        elif nbytes != count * _MI_SIZE[mdtype]:
            self.fail(f"{what} holds {nbytes:,} bytes, its dimensions declare {count:,} values of "
                      f"{_MI_SIZE[mdtype]} bytes", pos)
        return mdtype, start, nxt

    def matrix(self, buf: bytes, start: int, end: int, depth: int,
               header_only: bool = False) -> str | None:
        """An miMATRIX element's content ``buf[start:end]``; the name of a variable (depth 0)."""
        if start == end:  # an empty array inside a struct or cell
            return
        if depth > MAX_DEPTH:
            self.fail(f"structs or cells nested deeper than {MAX_DEPTH}", start)
        bo = self.bo
        mdtype, nbytes, d, pos = self.tag(buf, start, end)
        if mdtype != _MI_UINT32 or nbytes != 8:
            self.fail("array flags element malformed", start)
        flags, nzmax = struct.unpack_from(bo + "II", buf, d)
        cls, cplx = flags & 0xFF, bool(flags & _FLAG_COMPLEX)
        at = pos
        mdtype, nbytes, d, pos = self.tag(buf, pos, end)
        if mdtype != _MI_INT32 or nbytes < 8 or nbytes % 4:
            self.fail("dimensions element malformed", at)
        dims = struct.unpack_from(f"{bo}{nbytes // 4}i", buf, d)
        if min(dims) < 0:
            self.fail(f"negative dimension in {dims}", at)
        count = 1
        for n in dims:
            count *= n
        at = pos
        mdtype, nbytes, d, pos = self.tag(buf, pos, end)
        if mdtype != _MI_INT8:
            self.fail(f"array name element has type {mdtype}", at)
        name = buf[d:d + nbytes].decode("latin1")
        if depth == 0 and (header_only or name not in VARIABLES):
            return name  # scipy parses only the header of a variable it is not asked for
        if cls in _MX_NUMERIC or cls == _MX_CHAR:
            types = _MI_SIZE if cls == _MX_CHAR else _MI_DTYPE
            for part in ("real", "imaginary")[: 1 + (cplx and cls != _MX_CHAR)]:
                _, _, pos = self.values(buf, pos, end, count, f"{part} part", types)
        elif cls == _MX_SPARSE:
            self.sparse(buf, pos, end, dims, nzmax, cplx)
        elif cls in (_MX_STRUCT, _MX_OBJECT):
            if cls == _MX_OBJECT:
                at = pos
                mdtype, nbytes, d, pos = self.tag(buf, pos, end)
                if mdtype != _MI_INT8:
                    self.fail("object class name malformed", at)
            at = pos
            mdtype, nbytes, d, pos = self.tag(buf, pos, end)
            if mdtype != _MI_INT32 or nbytes != 4:
                self.fail("struct field name length malformed", at)
            length = struct.unpack_from(bo + "i", buf, d)[0]
            at = pos
            mdtype, nbytes, d, pos = self.tag(buf, pos, end)
            if mdtype != _MI_INT8 or length <= 0 or nbytes % length:
                self.fail(f"struct field names malformed ({nbytes} bytes, {length} per name)", at)
            self.children(buf, pos, end, count * (nbytes // length), depth)
        elif cls == _MX_CELL:
            self.children(buf, pos, end, count, depth)
        else:  # function handles, opaque objects (classdef, string): scipy has no safe reader
            self.fail(f"unsupported MATLAB array class {cls}", start)
        return name

    def children(self, buf, pos, end, n: int, depth: int) -> None:
        for _ in range(n):
            at = pos
            mdtype, nbytes, d, pos = self.tag(buf, pos, end)
            if mdtype != _MI_MATRIX:
                self.fail(f"struct field or cell element has type {mdtype}, expected a matrix", at)
            self.matrix(buf, d, d + nbytes, depth + 1)

    def sparse(self, buf, pos, end, dims, nzmax: int, cplx: bool) -> None:
        if len(dims) != 2:
            self.fail(f"sparse array with {len(dims)} dimensions", pos)
        M, N = dims
        arrays = []
        for what, count in (("row indices", None), ("column starts", N + 1), ("values", None),
                            ("imaginary values", None))[: 3 + cplx]:
            at = pos
            mdtype, nbytes, d, pos = self.tag(buf, pos, end)
            if mdtype not in _MI_DTYPE or nbytes % _MI_SIZE[mdtype]:
                self.fail(f"sparse {what} element malformed", at)
            n = nbytes // _MI_SIZE[mdtype]
            if count is not None and n != count:
                self.fail(f"sparse array has {n} column starts for {N} columns", at)
            arrays.append((at, np.frombuffer(buf, self.bo + _MI_DTYPE[mdtype], n, d)))
        (_, ir), (at, jc), *vals = arrays
        nnz = jc[-1]
        if jc[0] != 0 or np.any(np.diff(jc.astype(np.float64)) < 0) or nnz > ir.size or any(
                nnz > v.size for _, v in vals):
            self.fail("sparse column starts are inconsistent with the stored values", at)
        if nnz and (ir[:int(nnz)].min() < 0 or ir[:int(nnz)].max() >= M):
            self.fail(f"sparse row index out of range 0..{M - 1}", arrays[0][0])


def read_mat_variables(path: str, max_bytes: int | None = None) -> dict:
    """The :data:`VARIABLES` of the MAT v5 file ``path`` (raises :class:`MatReadError`).

    The file's structure is checked first (:func:`validate_mat5`, with ``max_bytes`` the
    largest file accepted). A struct ``Data`` (KT3DMoSeg) is returned as its
    :data:`DATA_FIELDS`, each under the key ``"Data.<field>"``; ``"Data"`` itself then
    maps to the list of its field names.
    """
    import scipy.io

    validate_mat5(path, max_bytes)
    try:
        mat = scipy.io.loadmat(path, variable_names=VARIABLES)
    except MemoryError:
        raise MatReadError("too large: its arrays do not fit in memory") from None
    except Exception as exc:  # scipy raises many types for damaged files
        raise MatReadError(f"truncated or corrupt MAT file ({type(exc).__name__}: {exc})") from None
    out = {k: mat[k] for k in VARIABLES if k in mat}
    data = out.pop("Data", None)
    if data is not None:
        names = data.dtype.names if isinstance(data, np.ndarray) else None
        if not names:
            raise MatReadError(f"variable 'Data' is not a struct (MATLAB class of dtype {data.dtype})")
        if data.size != 1:
            raise MatReadError(f"variable 'Data' must be one struct, got a {data.shape} struct array")
        record = data.reshape(-1)[0]
        out["Data"] = np.array(names, dtype=str)
        for name in DATA_FIELDS:
            if name in names:
                out["Data." + name] = record[name]
    return out


def _encode(variables: dict) -> bytes:
    """Numeric variables (and ``Data``'s field names) as an ``.npz`` (no pickles); others are
    only named, with their type."""
    arrays, other = {}, []
    for k, v in variables.items():
        a = np.asarray(v)
        if a.dtype.kind in "biufc" or (k == "Data" and a.dtype.kind == "U"):
            arrays[k] = a
        else:
            other.append(f"{k}={a.dtype}")
    buf = io.BytesIO()
    np.savez(buf, **arrays, __nonnumeric__=np.array(other, dtype=str))
    return buf.getvalue()


def decode(payload: bytes) -> dict:
    """The variables sent by the child; non-numeric ones become empty object arrays."""
    with np.load(io.BytesIO(payload), allow_pickle=False) as data:
        out = {k: data[k] for k in data.files if k != "__nonnumeric__"}
        for item in data["__nonnumeric__"].tolist():
            out[item.split("=", 1)[0]] = np.empty(0, dtype=object)
    return out


def main() -> None:  # pragma: no cover - runs in the child process
    try:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))
    except (ImportError, ValueError, OSError):
        pass
    out = sys.stdout.buffer
    for line in sys.stdin.buffer:
        path = os.fsdecode(bytes.fromhex(line.strip().decode("ascii")))
        try:
            kind, payload = b"o", _encode(read_mat_variables(path))
        except MatReadError as exc:
            kind, payload = b"e", str(exc).encode()
        except MemoryError:
            kind, payload = b"e", b"too large: its arrays do not fit in memory"
        except Exception as exc:
            kind, payload = b"e", f"could not be read ({type(exc).__name__}: {exc})".encode()
        out.write(kind + struct.pack(">Q", len(payload)) + payload)
        out.flush()


if __name__ == "__main__":  # pragma: no cover
    main()
