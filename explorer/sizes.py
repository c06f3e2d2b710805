"""Upload sizes: the default limit, the chunk an upload travels in, ``"50MB"`` parsed and
``61.2 MB`` printed. No GUI imports (the command parses ``--max-upload`` before panel loads).
"""

from __future__ import annotations

import re

__all__ = ["DEFAULT_MAX_UPLOAD", "UPLOAD_CHUNK", "parse_size", "fmt_size"]

#: Default upload limit (bytes, decimal units like the upload box's "50 MB").
DEFAULT_MAX_UPLOAD = 50_000_000
#: Bytes per websocket message of an upload: far below the server's message limit.
UPLOAD_CHUNK = 1_000_000

_UNITS = {"": 1, "B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "KIB": 2**10, "MIB": 2**20, "GIB": 2**30}


def parse_size(text) -> int:
    """Bytes from ``"50MB"``, ``"750 KB"``, ``"1.5GB"``, ``"20MiB"`` or a plain number of bytes
    (KB/MB/GB are powers of 1000). Raises ValueError with a readable message."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d*)?|\.\d+)\s*([A-Za-z]*)\s*", str(text))
    unit = m.group(2).upper() if m else None
    if m is None or unit not in _UNITS:
        raise ValueError(f"a size like 50MB, 750KB or 2GB, got {str(text)[:40]!r}")
    n = int(float(m.group(1)) * _UNITS[unit])
    if n < 1:
        raise ValueError(f"a size of at least 1 byte, got {str(text)[:40]!r}")
    return n


def fmt_size(n: int) -> str:
    """A size as the page's upload box prints it (powers of 1000): ``812 bytes``, whole
    kilobytes rounded down (``268 KB`` for 268,900 bytes), megabytes to one decimal without a
    trailing ``.0`` (``61.2 MB``, ``50 MB``), gigabytes to two (``2.10 GB``), so that a message
    and the box name the same size."""
    n = int(n)
    if n < 1000:
        return f"{n} byte{'s' if n != 1 else ''}"
    if n < 10**6:
        return f"{n // 1000} KB"
    if n < 10**9:
        text = f"{n / 10**6:.1f}"
        return f"{text[:-2] if text.endswith('.0') else text} MB"
    return f"{n / 10**9:.2f} GB"
