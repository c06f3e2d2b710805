"""The official Hopkins155 download (no ``sequences.csv``) works for the tests and the bench."""

from __future__ import annotations

import csv
from collections import Counter
from pathlib import Path

import pytest
from conftest import rows_from_files

from laav.bench import discover

pytestmark = pytest.mark.hopkins


@pytest.fixture(scope="module")
def official(hopkins_root, tmp_path_factory) -> Path:
    """The sequence folders only (symbolic links, nothing copied), as the download has them."""
    root = tmp_path_factory.mktemp("official")
    for folder in hopkins_root.iterdir():
        if folder.is_dir():
            (root / folder.name).symlink_to(folder.resolve(), target_is_directory=True)
    assert not (root / "sequences.csv").exists()
    return root


def test_table_from_the_files_matches_sequences_csv(official, hopkins_root):
    rows = rows_from_files(official)
    bench = [r for r in rows if r["in_hopkins155"] == "yes"]
    assert len(bench) == 155 and "dancing" not in {r["sequence"] for r in bench}
    assert Counter(int(r["num_motions"]) for r in bench) == {2: 120, 3: 35}
    if (hopkins_root / "sequences.csv").is_file():  # the files tell what the table says
        with open(hopkins_root / "sequences.csv", newline="") as fh:
            table = {r["sequence"]: r for r in csv.DictReader(fh)}
        cols = ("num_motions", "num_points", "num_frames", "width", "height", "in_hopkins155")
        for r in rows:
            assert {c: r[c] for c in cols} == {c: table[r["sequence"]][c] for c in cols}


def test_bench_discovers_the_155_without_sequences_csv(official):
    skipped = []
    found = discover(official, log=skipped.append)
    assert len(found) == 155 and "dancing" not in {s.name for s in found}
    assert any("dancing" in m for m in skipped)
    assert Counter(s.motions for s in found) == {2: 120, 3: 35}
