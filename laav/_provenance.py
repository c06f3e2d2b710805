"""Which code produced a result: the package version and the git commit of the checkout.

The commit is the short hash of ``HEAD`` of the git checkout the ``laav`` package is
imported from, with ``-dirty`` when the code there differs from it (tracked changes or
new untracked files under :data:`CODE_PATHS`; results such as ``docs/bench`` do not
count, so a bench writing into the repository does not make itself "dirty"). Without a
checkout (an installed wheel) or without git it is ``"unknown"``.
"""

from __future__ import annotations

import functools
import subprocess
from pathlib import Path

__all__ = ["CODE_PATHS", "commit_of", "git_commit", "provenance"]

#: Paths of the checkout that hold code (relative to its top).
CODE_PATHS = ("laav", "explorer", "benchmarks", "examples", "pyproject.toml")


def _git(root: Path, *args: str) -> str:
    out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                         timeout=30, check=True)
    return out.stdout.strip()


def commit_of(root: str | Path) -> str:
    """``<short hash>[-dirty]`` of the git checkout whose top is ``root``, else ``"unknown"``."""
    root = Path(root).resolve()
    try:
        if Path(_git(root, "rev-parse", "--show-toplevel")).resolve() != root:
            return "unknown"  # e.g. site-packages inside some other repository
        head = _git(root, "rev-parse", "--short", "HEAD")
        dirty = _git(root, "status", "--porcelain", "--", *CODE_PATHS)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


@functools.cache
def git_commit() -> str:
    """:func:`commit_of` the checkout ``laav`` is imported from (computed once per process)."""
    return commit_of(Path(__file__).resolve().parents[1])


def provenance() -> dict:
    """``{"version": laav.__version__, "commit": git_commit()}``."""
    from . import __version__

    return {"version": __version__, "commit": git_commit()}
