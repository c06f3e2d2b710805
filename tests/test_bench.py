"""`laav bench`: runs.csv, report and figures, resume, and Dask equivalence, on tiny data."""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np
import pytest

import laav
from laav.bench import COLUMNS, add_pixel_noise, read_runs, run_bench
from laav.synthetic import make_sequence

SMALL = laav.LaavParams(rv_max_iter=25, rv_trials=2, pooled_trials=2)


def _hopkins_folder(root: Path) -> Path:
    """Three tiny synthetic sequences in Hopkins layout, plus things to skip."""
    data = root / "data"
    for i, (objs, name) in enumerate([(1, "syn_a"), (2, "syn_b"), (1, "syn_c")]):
        seq = make_sequence(n_objects=objs, n_frames=8, n_points=60, rng=100 + i, name=name)
        (data / name).mkdir(parents=True)
        laav.save_sequence(seq, data / name / f"{name}_truth.mat")
    dancing = make_sequence(n_objects=1, n_frames=8, n_points=40, rng=7, name="dancing")
    (data / "dancing").mkdir()
    laav.save_sequence(dancing, data / "dancing" / "dancing_truth.mat")
    (data / "notes.txt").write_text("not a sequence")
    return data


@pytest.fixture(scope="module")
def bench_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("bench")
    data = _hopkins_folder(root)
    out = root / "out"
    summary = run_bench(data, out, methods=("laav", "rv"), seeds=2, noise=(0.0, 1.0), jobs=1,
                        params=SMALL, progress=False)
    return data, out, summary


def test_runs_csv_has_one_row_per_run_with_the_schema(bench_run):
    _, out, summary = bench_run
    with open(out / "runs.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames) == COLUMNS
        rows = list(reader)
    assert len(rows) == 3 * 2 * 2 * 2  # sequences x methods x seeds x noise levels
    assert summary.completed == len(rows) and not summary.failed
    assert {r["sequence"] for r in rows} == {"syn_a", "syn_b", "syn_c"}  # dancing skipped
    keys = {(r["sequence"], r["method"], r["seed"], r["noise"]) for r in rows}
    assert len(keys) == len(rows)
    for r in rows:
        assert 0.0 <= float(r["error"]) <= 100.0
        assert float(r["seconds"]) > 0
        assert int(r["motions"]) in (2, 3)


def _recompute_table(rows, sigma=0.0):
    """Independent recomputation: mean over seeds per sequence, then over sequences."""
    per = {}
    for r in rows:
        if r["noise"] != sigma:
            continue
        per.setdefault((r["method"], r["sequence"], r["motions"]), []).append(r["error"])
    out = {}
    for (m, _s, c), errs in per.items():
        out.setdefault(m, {}).setdefault(c, []).append(np.mean(errs))
        out[m].setdefault("all", []).append(np.mean(errs))
    return {m: {k: float(np.mean(v)) for k, v in d.items()} for m, d in out.items()}


def test_report_table_equals_a_recomputation_from_the_csv(bench_run):
    _, out, _ = bench_run
    rows = read_runs(out / "runs.csv")
    text = (out / "report.md").read_text()
    expected = _recompute_table(rows)
    for method, label in (("laav", "LAAV"), ("rv", "RV")):
        line = next(ln for ln in text.splitlines() if ln.startswith(f"| {label} |"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        # | method | 2 mean | 2 median | 3 mean | 3 median | all mean | all median | n |
        assert float(cells[1]) == pytest.approx(expected[method][2], abs=0.006)
        assert float(cells[3]) == pytest.approx(expected[method][3], abs=0.006)
        assert float(cells[5]) == pytest.approx(expected[method]["all"], abs=0.006)


def test_figures_are_valid_pngs(bench_run):
    from PIL import Image

    _, out, _ = bench_run
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) >= 3
    for p in pngs:
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        with Image.open(p) as im:
            assert im.size[0] > 200 and im.size[1] > 100
        assert re.search(re.escape(p.name), (out / "report.md").read_text())


def test_rerun_skips_finished_runs(bench_run):
    data, out, _ = bench_run
    before = (out / "runs.csv").read_text()
    again = run_bench(data, out, methods=("laav", "rv"), seeds=2, noise=(0.0, 1.0), jobs=1,
                      params=SMALL, progress=False)
    assert again.already_done == 24 and again.completed == 0
    assert (out / "runs.csv").read_text() == before
    more = run_bench(data, out, methods=("rv",), seeds=3, noise=(0.0,), jobs=1,
                     params=SMALL, progress=False)
    assert more.completed == 3  # only seed 2 of rv at sigma 0, once per sequence
    assert len(read_runs(out / "runs.csv")) == 27


def test_resume_refuses_other_parameters(bench_run):
    from laav.bench import BenchError

    data, out, _ = bench_run
    with pytest.raises(BenchError, match="other LAAV parameters"):
        run_bench(data, out, methods=("rv",), seeds=1, noise=(0.0,), jobs=1,
                  params=SMALL.replace(rv_alpha=0.8), progress=False)


def test_pixel_noise_is_seeded_and_has_the_requested_spread():
    seq = make_sequence(n_objects=1, n_frames=10, n_points=200, rng=3)
    a = add_pixel_noise(seq, 1.5, seed=4)
    b = add_pixel_noise(seq, 1.5, seed=4)
    c = add_pixel_noise(seq, 1.5, seed=5)
    np.testing.assert_array_equal(a.points, b.points)
    assert not np.array_equal(a.points, c.points)
    assert np.std(a.points - seq.points) == pytest.approx(1.5, rel=0.05)
    np.testing.assert_array_equal(add_pixel_noise(seq, 0.0, seed=4).points, seq.points)


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_rows_as_joblib(tmp_path):
    distributed = pytest.importorskip("distributed")
    data = _hopkins_folder(tmp_path)
    kw = dict(methods=("laav", "rv"), seeds=1, noise=(0.0, 0.5), only=["syn_a", "syn_b"],
              params=SMALL, progress=False, report=False)
    local = run_bench(data, tmp_path / "local", jobs=1, **kw)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address=None)
    try:
        remote = run_bench(data, tmp_path / "dask", scheduler=cluster.scheduler_address, **kw)
    finally:
        cluster.close()
    assert local.completed == remote.completed == 8

    def strip(rows):
        return sorted(tuple((k, v) for k, v in r.items() if k != "seconds") for r in rows)

    assert strip(read_runs(tmp_path / "local" / "runs.csv")) == strip(
        read_runs(tmp_path / "dask" / "runs.csv"))
