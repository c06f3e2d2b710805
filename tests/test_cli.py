"""The `laav` command line: segment, and its errors."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import laav
from laav.cli import main
from laav.synthetic import make_sequence


@pytest.fixture(scope="module")
def seq():
    return make_sequence(n_objects=1, n_frames=12, n_points=120, rng=11, name="cli_seq")


@pytest.mark.parametrize("method", ["laav", "rv"])
@pytest.mark.parametrize("suffix", [".mat", ".npz"])
def test_segment_writes_labels_and_prints_the_error(tmp_path, capsys, seq, method, suffix):
    path = laav.save_sequence(seq, tmp_path / f"cli_seq{suffix}")
    out = tmp_path / "labels.csv"
    code = main(["segment", str(path), "--method", method, "--seed", "1", "--out", str(out)])
    assert code == 0
    printed = capsys.readouterr().out
    assert str(out) in printed
    m = [ln for ln in printed.splitlines() if "misclassification" in ln]
    assert m, printed
    with open(out, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [r["point"] for r in rows] == [str(i) for i in range(seq.n_points)]
    labels = np.array([int(r["label"]) for r in rows])
    shown = float(m[0].split(":")[1].split("%")[0])
    assert shown == pytest.approx(100 * laav.misclassification_rate(seq.labels, labels), abs=0.01)


def test_segment_bad_file_exits_2_naming_the_file(tmp_path, capsys):
    bad = tmp_path / "broken_truth.mat"
    bad.write_bytes(b"this is not a MAT file")
    assert main(["segment", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "Traceback" not in err


def test_segment_without_labels_needs_motions(tmp_path, capsys, seq):
    path = laav.save_sequence(laav.Sequence(seq.points, name="nolabels"), tmp_path / "n.npz")
    assert main(["segment", str(path)]) == 2
    assert "--motions" in capsys.readouterr().err
    out = tmp_path / "l.csv"
    assert main(["segment", str(path), "--motions", "2", "--out", str(out)]) == 0
    assert out.is_file()
    assert "misclassification" not in capsys.readouterr().out
