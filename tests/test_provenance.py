"""Provenance: the git commit and version in bench.json, runs.csv rows and the reports."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

import laav
from laav._provenance import commit_of, git_commit
from laav.bench import COLUMNS, LEGACY_COLUMNS, BenchError, read_runs, run_bench
from laav.report import report_from_csv
from laav.synthetic import make_sequence

REPO = Path(__file__).resolve().parent.parent
SMALL = laav.LaavParams(rv_max_iter=20, rv_trials=1)
KW = dict(methods=("rv",), seeds=1, noise=(0.0,), jobs=1, params=SMALL, progress=False,
          log=lambda m: None)


def _git(root, *args):
    subprocess.run(["git", "-C", str(root), *args], check=True, capture_output=True)


def test_commit_of_a_checkout(tmp_path):
    assert commit_of(tmp_path) == "unknown"  # not a checkout
    _git(tmp_path, "init", "-q")
    (tmp_path / "laav").mkdir()
    (tmp_path / "laav" / "a.py").write_text("x = 1\n")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "r.md").write_text("r\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "c")
    head = subprocess.run(["git", "-C", str(tmp_path), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True).stdout.strip()
    assert commit_of(tmp_path) == head
    (tmp_path / "docs" / "r.md").write_text("results change\n")  # not code
    assert commit_of(tmp_path) == head
    (tmp_path / "laav" / "a.py").write_text("x = 2\n")
    assert commit_of(tmp_path) == head + "-dirty"
    _git(tmp_path, "checkout", "-q", "laav/a.py")
    (tmp_path / "laav" / "new.py").write_text("y = 1\n")  # untracked code counts too
    assert commit_of(tmp_path) == head + "-dirty"
    assert commit_of(tmp_path / "laav") == "unknown"  # only the top of a checkout


def test_this_checkout_is_named():
    assert re.fullmatch(r"[0-9a-f]{7,}(-dirty)?", git_commit())


@pytest.fixture
def data(tmp_path):
    root = tmp_path / "data"
    for i, name in enumerate(("syn_a", "syn_b")):
        (root / name).mkdir(parents=True)
        laav.save_sequence(make_sequence(n_objects=1, n_frames=8, n_points=60, rng=i, name=name),
                           root / name / f"{name}_truth.mat")
    return root


def test_bench_records_the_code_and_refuses_to_mix(data, tmp_path, monkeypatch):
    out = tmp_path / "out"
    run_bench(data, out, only=["syn_a"], **KW)
    meta = json.loads((out / "bench.json").read_text())
    assert meta["commit"] == git_commit() and meta["laav_version"] == laav.__version__
    rows = read_runs(out / "runs.csv")
    assert rows and all((r["version"], r["commit"]) == (laav.__version__, git_commit()) for r in rows)
    assert f"laav {laav.__version__} at git `{git_commit()}` (every run)" in (out / "report.md").read_text()

    # the same code resumes; another commit is refused, then allowed with allow_mixed
    run_bench(data, out, only=["syn_a"], **{**KW, "seeds": 2})
    monkeypatch.setattr("laav.bench.provenance", lambda: {"version": "9.9", "commit": "abc1234"})
    with pytest.raises(BenchError, match="other code.*--allow-mixed"):
        run_bench(data, out, **KW)
    summary = run_bench(data, out, allow_mixed=True, **KW)
    assert summary.completed == 1  # syn_b
    meta = json.loads((out / "bench.json").read_text())
    assert meta["commit"] == "abc1234" and len(meta["mixed"]) == 2
    report = (out / "report.md").read_text()
    assert "**mixed**" in report and "laav 9.9 at git `abc1234`: 1 runs" in report


def test_cli_allow_mixed_flag(data, tmp_path, monkeypatch):
    from laav.cli import main

    out = tmp_path / "cli"
    args = ["bench", "--data", str(data), "--methods", "rv", "--only", "syn_a", "--out", str(out),
            "-q", "--no-report", "--param", "rv_max_iter=20", "--param", "rv_trials=1", "-j", "1"]
    assert main(args) == 0
    monkeypatch.setattr("laav.bench.provenance", lambda: {"version": "9.9", "commit": "abc1234"})
    assert main([*args, "--seeds", "2"]) == 2  # refused: a usage error, exit code 2
    assert main([*args, "--seeds", "2", "--allow-mixed"]) == 0


def test_legacy_runs_csv_is_read_and_upgraded(data, tmp_path):
    out = tmp_path / "old"
    run_bench(data, out, only=["syn_a"], **KW)
    with open(out / "runs.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    with open(out / "runs.csv", "w", newline="") as fh:  # as written before provenance
        w = csv.DictWriter(fh, fieldnames=LEGACY_COLUMNS, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    old = read_runs(out / "runs.csv")
    assert old and all(r["commit"] == "" and r["version"] == "" for r in old)
    assert "laav ? at git `unrecorded` (every run)" in report_from_csv(out / "runs.csv")
    with pytest.raises(BenchError, match="unrecorded"):  # unknown code: not silently mixed
        run_bench(data, out, **KW)
    run_bench(data, out, allow_mixed=True, **KW)
    with open(out / "runs.csv", newline="") as fh:
        assert tuple(csv.DictReader(fh).fieldnames) == COLUMNS


def test_json_reports_name_version_and_commit(tmp_path):
    sys.path.insert(0, str(REPO / "benchmarks"))
    try:
        import _machine
    finally:
        sys.path.remove(str(REPO / "benchmarks"))
    path = _machine.write_json_report(tmp_path / "r.md", "T", "what", {"a": 1})
    text = path.read_text()
    assert f"laav {laav.__version__} (git {commit_of(REPO)})" in text
