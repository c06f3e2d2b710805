"""Shared fixtures: where the Hopkins155 ground truth lives, and a table of its sequences.

The data set sits outside the repository. ``$HOPKINS155`` names its folder; without it the
fixtures look for ``<repo>/../shared/data/hopkins155``. Tests that use these fixtures are
skipped (not failed) when the folder holds no ``<seq>/<seq>_truth.mat``. The official
download has no ``sequences.csv``: the table then comes from the files themselves
(:func:`rows_from_files`), with ``dancing`` (5 motions, not one of the 155) marked out.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

import laav

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_HOPKINS = REPO_ROOT.parent / "shared" / "data" / "hopkins155"


@pytest.fixture(scope="session")
def hopkins_root() -> Path:
    """Folder of the Hopkins155 ground truth (``<seq>/<seq>_truth.mat``, optional ``sequences.csv``)."""
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else DEFAULT_HOPKINS
    if not (root.is_dir() and any(root.glob("*/*_truth.mat"))):
        how = "$HOPKINS155" if env else "default location (set $HOPKINS155)"
        pytest.skip(f"Hopkins155 data not found at {root} ({how})")
    return root


@pytest.fixture(scope="session")
def hopkins_rows(hopkins_root: Path) -> list[dict[str, str]]:
    """One dict of strings per sequence folder: ``sequences.csv``, else :func:`rows_from_files`."""
    if not (hopkins_root / "sequences.csv").is_file():
        return rows_from_files(hopkins_root)
    with open(hopkins_root / "sequences.csv", newline="") as fh:
        return list(csv.DictReader(fh))


#: Sequences of the original distribution that are not among the 155.
NOT_IN_HOPKINS155 = ("dancing",)


def rows_from_files(root: Path) -> list[dict[str, str]]:
    """The columns of ``sequences.csv`` that the files tell (no ``category``)."""
    rows = []
    for f in laav.find_truth_files(root):
        seq = laav.load_sequence(f)
        w, h = seq.image_size or ("", "")
        rows.append({"sequence": f.parent.name, "num_motions": str(seq.n_motions),
                     "num_points": str(seq.n_points), "num_frames": str(seq.n_frames),
                     "width": str(w), "height": str(h),
                     "in_hopkins155": "no" if f.parent.name in NOT_IN_HOPKINS155 else "yes"})
    return rows


def stop_process(proc) -> None:
    """End a server started by a test: terminate, then kill if it has not gone in 30 s."""
    import subprocess

    proc.terminate()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def session_text(url: str, timeout: float = 60.0) -> str:
    """All text a browser tab of the served app is given (every bokeh model's ``text``),
    read through a script session: the sequence name lives in the page's panes, not in its
    static HTML."""
    import time

    import panel.models  # noqa: F401 - registers the models the client receives
    import panel.models.file_dropper  # noqa: F401 - the upload box (not in panel.models)
    from bokeh.client import pull_session

    with pull_session(url=url) as session:
        deadline = time.monotonic() + timeout
        while True:
            texts = [str(getattr(m, "text", "") or "") for m in session.document.models]
            joined = "\n".join(texts)
            if joined.strip() or time.monotonic() > deadline:
                return joined
            time.sleep(0.5)
