"""MATLAB v5 reading for :mod:`laav.io`, in this process or as a child process.

``scipy.io.loadmat`` can crash the interpreter outright (a segmentation fault) on some
damaged MAT v5 files. :func:`laav.load_sequence` with ``isolated=True`` therefore runs
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


def read_mat_variables(path: str) -> dict:
    """The :data:`VARIABLES` of the MAT v5 file ``path`` (raises :class:`MatReadError`).

    A struct ``Data`` (KT3DMoSeg) is returned as its :data:`DATA_FIELDS`, each under the
    key ``"Data.<field>"``; ``"Data"`` itself then maps to the list of its field names.
    """
    import scipy.io

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
