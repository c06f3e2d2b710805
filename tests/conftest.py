"""Shared fixtures: where the Hopkins155 ground truth lives, and its ``sequences.csv`` table.

The data set sits outside the repository. ``$HOPKINS155`` names its folder; without it the
fixtures look for ``<repo>/../shared/data/hopkins155``. Tests that use these fixtures are
skipped (not failed) when the folder or its ``sequences.csv`` is absent.
"""

from __future__ import annotations

import csv
import os
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_HOPKINS = REPO_ROOT.parent / "shared" / "data" / "hopkins155"


@pytest.fixture(scope="session")
def hopkins_root() -> Path:
    """Folder of the Hopkins155 ground truth (``<seq>/<seq>_truth.mat`` + ``sequences.csv``)."""
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else DEFAULT_HOPKINS
    if not (root / "sequences.csv").is_file():
        how = "$HOPKINS155" if env else "default location (set $HOPKINS155)"
        pytest.skip(f"Hopkins155 data not found at {root} ({how})")
    return root


@pytest.fixture(scope="session")
def hopkins_rows(hopkins_root: Path) -> list[dict[str, str]]:
    """The rows of ``sequences.csv``, one dict per sequence folder, as strings."""
    with open(hopkins_root / "sequences.csv", newline="") as fh:
        return list(csv.DictReader(fh))
