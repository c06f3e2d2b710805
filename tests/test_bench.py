"""`laav bench`: runs.csv, report and figures, resume, skipping, and Dask equivalence, on tiny data."""

from __future__ import annotations

import csv
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

import laav
import laav.bench as bench
from laav.bench import COLUMNS, BenchError, add_pixel_noise, read_runs, run_bench
from laav.cli import main
from laav.report import report_from_csv
from laav.synthetic import make_sequence

_FIELDS = {f.name for f in dataclasses.fields(laav.LaavParams)}
# Small settings for speed; only fields the current LaavParams has (its fields may change).
_SMALL_KW = {k: v for k, v in dict(rv_max_iter=25, rv_trials=2, pooled_trials=2).items()
             if k in _FIELDS}
SMALL = laav.LaavParams(**_SMALL_KW)
SMALL_ARGS = [a for k, v in _SMALL_KW.items() for a in ("--param", f"{k}={v}")]
SEQS = {"syn_a": (1, "checkerboard"), "syn_b": (2, "traffic"), "syn_c": (1, "articulated")}
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def _hopkins_folder(root: Path) -> Path:
    """Three tiny synthetic sequences in Hopkins layout, a sequences.csv, and things to skip."""
    data = root / "data"
    for i, (name, (objs, _)) in enumerate(SEQS.items()):
        seq = make_sequence(n_objects=objs, n_frames=8, n_points=60, rng=100 + i, name=name)
        (data / name).mkdir(parents=True)
        laav.save_sequence(seq, data / name / f"{name}_truth.mat")
    for name in ("dancing", "extra"):  # dancing always skipped; extra by sequences.csv
        (data / name).mkdir()
        seq = make_sequence(n_objects=1, n_frames=8, n_points=40, rng=7, name=name)
        laav.save_sequence(seq, data / name / f"{name}_truth.mat")
    (data / "empty").mkdir()
    (data / "notes.txt").write_text("not a sequence")
    with open(data / "sequences.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["sequence", "category", "num_motions", "in_hopkins155"])
        for name, (objs, cat) in SEQS.items():
            w.writerow([name, cat, objs + 1, "yes"])
        w.writerow(["extra", "traffic", 2, "no"])
    return data


def _csv_rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return _hopkins_folder(tmp_path_factory.mktemp("hopkins"))


@pytest.fixture(scope="module")
def bench_run(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "out"
    messages = []
    summary = run_bench(data_dir, out, methods=("laav", "rv"), seeds=2, noise=(0.0, 1.0), jobs=1,
                        params=SMALL, progress=False, log=messages.append)
    return out, summary, messages


def test_runs_csv_has_one_row_per_run_with_the_schema(bench_run):
    out, summary, _ = bench_run
    with open(out / "runs.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames) == COLUMNS
        rows = list(reader)
    assert len(rows) == 3 * 2 * 2 * 2  # sequences x methods x seeds x noise levels
    assert summary.completed == summary.planned == len(rows) and not summary.failed
    assert {r["sequence"] for r in rows} == set(SEQS)  # dancing, extra, empty skipped
    keys = {(r["sequence"], r["method"], r["seed"], r["noise"]) for r in rows}
    assert keys == {(s, m, str(seed), n) for s in SEQS for m in ("laav", "rv")
                    for seed in (0, 1) for n in ("0", "1")}
    for r in rows:
        objs, cat = SEQS[r["sequence"]]
        assert r["category"] == cat
        assert int(r["motions"]) == objs + 1
        assert (int(r["points"]), int(r["frames"])) == (60, 8)
        assert 0.0 <= float(r["error"]) <= 100.0
        assert float(r["seconds"]) > 0
        assert int(r["iterations"]) >= 1 and int(r["trials"]) >= 1
        assert r["converged"] in ("True", "False")


def test_skipped_entries_are_reported(bench_run):
    _, _, messages = bench_run
    text = "\n".join(messages)
    for name in ("dancing", "extra", "empty", "notes.txt"):
        assert re.search(rf"skipping {re.escape(name)}:", text), text


def test_rows_agree_with_a_direct_api_call(bench_run, data_dir):
    out, _, _ = bench_run
    row = next(r for r in read_runs(out / "runs.csv")
               if (r["sequence"], r["method"], r["seed"], r["noise"]) == ("syn_b", "laav", 1, 1.0))
    seq = laav.load_sequence(data_dir / "syn_b" / "syn_b_truth.mat")
    noisy = add_pixel_noise(seq, 1.0, seed=1)
    res = laav.segment(noisy, 3, SMALL, 1)
    assert row["error"] == pytest.approx(100 * laav.misclassification_rate(seq.labels, res.labels))
    assert row["iterations"] == res.voting.n_iterations
    assert row["converged"] == res.voting.converged


def _recompute(rows, sigma):
    """Independent recomputation: mean over seeds per sequence, then mean/median over sequences."""
    per = {}
    for r in rows:
        if float(r["noise"]) == sigma:
            per.setdefault((r["method"], r["sequence"], int(r["motions"])), []).append(float(r["error"]))
    out = {}
    for (m, _s, c), errs in per.items():
        out.setdefault(m, {}).setdefault(c, []).append(np.mean(errs))
        out[m].setdefault("all", []).append(np.mean(errs))
    return {m: {k: (float(np.mean(v)), float(np.median(v)), len(v)) for k, v in d.items()}
            for m, d in out.items()}


def _table_line(text, label, after):
    section = text.split(after, 1)[1]
    line = next(ln for ln in section.splitlines() if ln.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_report_table_equals_a_recomputation_from_the_csv(bench_run):
    out, _, _ = bench_run
    rows = _csv_rows(out / "runs.csv")  # raw strings, not laav's reader
    text = (out / "report.md").read_text()
    assert text == report_from_csv(out / "runs.csv")
    exp = _recompute(rows, 0.0)
    for method, label in (("laav", "LAAV"), ("rv", "RV")):
        cells = _table_line(text, label, "## Table 1")
        # | method | 2 mean | 2 median | 3 mean | 3 median | all mean | all median | n |
        want = [exp[method][2][0], exp[method][2][1], exp[method][3][0], exp[method][3][1],
                exp[method]["all"][0], exp[method]["all"][1]]
        assert cells[1:7] == [f"{v:.2f}" for v in want]
        assert int(cells[7]) == 3
    # Fig. 2 table: mean (median) per noise level
    for sigma in (0.0, 1.0):
        exp = _recompute(rows, sigma)
        col = 1 + [0.0, 1.0].index(sigma)
        for method, label in (("laav", "LAAV"), ("rv", "RV")):
            cell = _table_line(text, label, "## Error vs. noise")[col]
            assert cell == f"{exp[method]['all'][0]:.2f} ({exp[method]['all'][1]:.2f})"
    # Fig. 3 table: non-converged share
    for method, label in (("laav", "LAAV"), ("rv", "RV")):
        rs = [r for r in rows if r["method"] == method and r["noise"] == "0"]
        nc = 100 * np.mean([r["converged"] == "False" for r in rs])
        line = next(ln for ln in text.split("## Convergence", 1)[1].splitlines()
                    if ln.startswith(f"| {label} | 0 |"))
        assert line.rstrip(" |").endswith(f"{nc:.1f}")


def test_report_labels_the_published_rows(bench_run):
    out, _, _ = bench_run
    text = (out / "report.md").read_text()
    assert "| LAAV (published) | 0.37 | – | 1.12 | – | 0.55 |" in text
    assert "| RV (published) | 0.44 | – | 1.88 | – | 0.77 |" in text


def test_figures_are_valid_pngs(bench_run):
    from PIL import Image

    out, _, _ = bench_run
    pngs = sorted(out.glob("*.png"))
    assert len(pngs) == 3
    text = (out / "report.md").read_text()
    for p in pngs:
        assert p.read_bytes()[:8] == PNG_MAGIC
        with Image.open(p) as im:
            im.verify()
        with Image.open(p) as im:
            assert im.size[0] > 400 and im.size[1] > 300
        assert f"({p.name})" in text


def test_rerun_skips_finished_runs_and_redoes_lost_ones(bench_run, data_dir, monkeypatch):
    out, _, _ = bench_run
    calls = []
    real = bench.run_one

    def counting(*a, **k):
        calls.append((a[0].name, a[1], int(a[2]), float(a[3])))
        return real(*a, **k)

    monkeypatch.setattr(bench, "run_one", counting)
    before = (out / "runs.csv").read_text()
    kw = dict(methods=("laav", "rv"), seeds=2, noise=(0.0, 1.0), jobs=1, params=SMALL,
              progress=False, log=lambda m: None)
    again = run_bench(data_dir, out, **kw)
    assert (again.already_done, again.completed, calls) == (24, 0, [])
    assert (out / "runs.csv").read_text() == before

    # lose three rows and leave a line cut short, as a kill during a write would
    lines = before.splitlines(keepends=True)
    lost = lines[5:8]
    (out / "runs.csv").write_text("".join(lines[:5] + lines[8:]) + "syn_a,checkerb")
    third = run_bench(data_dir, out, **kw)
    assert third.completed == 3 and len(calls) == 3
    lost_keys = {(r["sequence"], r["method"], int(r["seed"]), float(r["noise"]))
                 for r in csv.DictReader([lines[0], *lost])}
    assert set(calls) == lost_keys

    def strip(text):
        return [{k: v for k, v in r.items() if k != "seconds"}
                for r in csv.DictReader(text.splitlines())]

    assert strip((out / "runs.csv").read_text()) == strip(before)

    # more seeds later: only the new ones run
    calls.clear()
    more = run_bench(data_dir, out, **{**kw, "methods": ("rv",), "seeds": 3, "noise": (0.0,)})
    assert more.completed == 3 and sorted(calls) == [(n, "rv", 2, 0.0) for n in sorted(SEQS)]
    assert len(read_runs(out / "runs.csv")) == 27


def test_resume_refuses_other_parameters(bench_run, data_dir):
    out, _, _ = bench_run
    with pytest.raises(BenchError, match="other LAAV parameters"):
        run_bench(data_dir, out, methods=("rv",), seeds=1, noise=(0.0,), jobs=1,
                  params=SMALL.replace(rv_alpha=0.8), progress=False, log=lambda m: None)


def test_pixel_noise_is_seeded_and_has_the_requested_spread():
    seq = make_sequence(n_objects=1, n_frames=10, n_points=200, rng=3, name="n")
    a = add_pixel_noise(seq, 1.5, seed=4)
    np.testing.assert_array_equal(a.points, add_pixel_noise(seq, 1.5, seed=4).points)
    assert not np.array_equal(a.points, add_pixel_noise(seq, 1.5, seed=5).points)
    assert not np.array_equal(a.points, add_pixel_noise(seq, 1.5 + 1e-3, seed=4).points)
    other = laav.Sequence(seq.points, seq.labels, name="other")
    assert not np.array_equal(a.points, add_pixel_noise(other, 1.5, seed=4).points)
    d = a.points - seq.points
    assert np.std(d) == pytest.approx(1.5, rel=0.05) and abs(np.mean(d)) < 0.05
    np.testing.assert_array_equal(add_pixel_noise(seq, 0.0, seed=4).points, seq.points)


def test_param_parsing():
    assert bench.parse_param("rv_max_iter=7") == ("rv_max_iter", 7)
    assert bench.parse_param("r1 = 15") == ("r1", 15.0)
    assert bench.parse_param("rv_refine=false") == ("rv_refine", False)
    assert bench.parse_param("fine_models=none") == ("fine_models", None)
    # a choice called "none" stays that string (the paper's rv_select), and builds params
    assert bench.parse_param("rv_select=none") == ("rv_select", "none")
    assert bench.params_from_assignments(["rv_select=None"]).rv_select == "none"
    with pytest.raises(BenchError, match="unknown LAAV parameter"):
        bench.parse_param("nope=1")
    with pytest.raises(BenchError, match="key=value"):
        bench.parse_param("rv_max_iter")
    with pytest.raises(BenchError, match="rv_alpha"):
        bench.params_from_assignments(["rv_alpha=2"])
    assert bench.parse_noise("2,0, 0.5,0") == (0.0, 0.5, 2.0)
    with pytest.raises(BenchError):
        bench.parse_noise("0,-1")


def test_cli_bench_parallel_only_and_errors(data_dir, tmp_path, capsys):
    out = tmp_path / "cli"
    rc = main(["bench", "--data", str(data_dir), "--methods", "rv", "--seeds", "1",
               "--noise", "0,0.5", "--only", "syn_[ab]", "--jobs", "2", "--out", str(out), "-q",
               *SMALL_ARGS])
    assert rc == 0
    printed = capsys.readouterr()
    assert f"report: {out / 'report.md'}" in printed.out and "| RV |" in printed.out
    rows = read_runs(out / "runs.csv")
    assert sorted((r["sequence"], r["noise"]) for r in rows) == [
        ("syn_a", 0.0), ("syn_a", 0.5), ("syn_b", 0.0), ("syn_b", 0.5)]
    assert "dancing" not in printed.err  # filtered out by --only before any message
    # same runs as the in-process run of the fixture would give
    direct = bench.run_one(bench.discover(data_dir, ["syn_b"], log=lambda m: None)[0],
                           "rv", 0, 0.5, SMALL)
    got = next(r for r in rows if (r["sequence"], r["noise"]) == ("syn_b", 0.5))
    assert {k: v for k, v in got.items() if k != "seconds"} == {
        k: v for k, v in direct.items() if k != "seconds"}

    assert main(["bench", "--data", str(tmp_path / "missing"), "--out", str(out), "-q"]) == 2
    assert "not a folder" in capsys.readouterr().err
    assert main(["bench", "--data", str(data_dir), "--only", "zzz*", "--out",
                 str(tmp_path / "o2"), "-q"]) == 2
    assert "no benchmark sequences" in capsys.readouterr().err
    assert main(["bench", "--data", str(data_dir), "--methods", "laav,xx", "--out",
                 str(tmp_path / "o3"), "-q"]) == 2
    assert main(["bench", "--data", str(data_dir), "--noise", "a", "--out",
                 str(tmp_path / "o4"), "-q"]) == 2
    assert main(["report", str(out)]) == 0
    assert main(["report", str(tmp_path / "nothing")]) == 2


@pytest.mark.slow
def test_dask_local_cluster_gives_the_same_rows_as_joblib(data_dir, tmp_path):
    distributed = pytest.importorskip("distributed")
    kw = dict(methods=("laav", "rv"), seeds=1, noise=(0.0, 0.5), only=["syn_a", "syn_b"],
              params=SMALL, progress=False, report=False, log=lambda m: None)
    local = run_bench(data_dir, tmp_path / "local", jobs=1, **kw)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address=None)
    try:
        remote = run_bench(data_dir, tmp_path / "dask", scheduler=cluster.scheduler_address, **kw)
    finally:
        cluster.close()
    assert local.completed == remote.completed == 8 and not remote.failed

    def strip(path):
        return [{k: v for k, v in r.items() if k != "seconds"} for r in _csv_rows(path)]

    # runs.csv is sorted by key at the end of a bench, so the files match row for row
    assert strip(tmp_path / "local" / "runs.csv") == strip(tmp_path / "dask" / "runs.csv")


@pytest.mark.slow
def test_speed_script_writes_its_report(data_dir, tmp_path):
    import subprocess
    import sys

    script = Path(__file__).resolve().parents[1] / "benchmarks" / "speed.py"
    out = tmp_path / "speed.md"
    proc = subprocess.run([sys.executable, str(script), "--data", str(data_dir), "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    assert "3 sequences" in text and "one core" in text and "Machine:" in text
    for label in ("LAAV atoms", "LAAV voting", "LAAV total", "Pipeline.update", "plain Random Voting"):
        assert label in text
    assert "dancing" not in proc.stderr and "extra" not in proc.stderr


def test_interrupt_keeps_finished_runs_and_resume_completes(data_dir, tmp_path, monkeypatch):
    real = bench.run_one
    calls = []

    def interrupted_on_7th(*a, **k):
        calls.append(a[0].name)
        if len(calls) == 7:
            raise KeyboardInterrupt
        return real(*a, **k)

    monkeypatch.setattr(bench, "run_one", interrupted_on_7th)
    kw = dict(methods=("rv",), seeds=4, noise=(0.0,), jobs=1, params=SMALL, progress=False,
              log=lambda m: None, max_batch=2)
    first = run_bench(data_dir, tmp_path, **kw)
    assert first.interrupted and first.report is None
    kept = read_runs(tmp_path / "runs.csv")
    assert len(kept) == first.completed == 6  # three batches of two finished
    monkeypatch.setattr(bench, "run_one", real)
    second = run_bench(data_dir, tmp_path, **kw)
    assert (second.already_done, second.completed, second.interrupted) == (6, 6, False)
    assert len(read_runs(tmp_path / "runs.csv")) == 12


def test_two_benches_never_share_an_output_folder(data_dir, tmp_path):
    with bench._OutLock(tmp_path):
        with pytest.raises(BenchError, match="another laav bench"):
            run_bench(data_dir, tmp_path, methods=("rv",), seeds=1, noise=(0.0,), jobs=1,
                      params=SMALL, progress=False, log=lambda m: None)
    assert not (tmp_path / "runs.csv").exists()


def test_bench_max_points(data_dir, tmp_path, capsys):
    from laav import io

    rc = main(["bench", "--data", str(data_dir), "--max-points", "50", "--out",
               str(tmp_path / "o"), "-q"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "60 points exceed the limit of 50" in err and "no benchmark sequences" in err
    assert io.MAX_POINTS == 20_000  # restored for the rest of the process


def test_two_benches_with_different_max_points_do_not_interfere(data_dir, tmp_path, monkeypatch):
    """--max-points is a parameter of run_bench / discover, not module state: two benches in
    one process, interleaved at their first load, each keep their own limit."""
    import threading

    from laav import io

    real = bench.load_sequence
    arrived = threading.Barrier(2, timeout=60)
    seen = {}

    def load(path, **kw):  # both benches load their first file only when both got there
        name = threading.current_thread().name
        if name not in seen:
            seen[name] = kw.get("max_points")
            arrived.wait()
        return real(path, **kw)

    monkeypatch.setattr(bench, "load_sequence", load)
    results, messages = {}, {"strict": [], "default": []}

    def run(name, max_points):
        try:
            results[name] = run_bench(data_dir, tmp_path / name, methods=("rv",), seeds=1,
                                      noise=(0.0,), jobs=1, params=SMALL, progress=False,
                                      report=False, log=messages[name].append,
                                      max_points=max_points)
        except BenchError as exc:
            results[name] = exc

    threads = [threading.Thread(target=run, args=("strict", 50), name="strict"),
               threading.Thread(target=run, args=("default", None), name="default")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    assert seen == {"strict": 50, "default": None}
    assert isinstance(results["strict"], BenchError)
    assert "no benchmark sequences" in str(results["strict"])
    assert sum("60 points exceed the limit of 50" in m for m in messages["strict"]) == len(SEQS)
    assert not any("exceed the limit" in m for m in messages["default"])
    assert results["default"].completed == len(SEQS)
    assert io.MAX_POINTS == 20_000


def test_discover_max_points(data_dir):
    msgs = []
    assert [s.name for s in bench.discover(data_dir, log=msgs.append, max_points=60)] == sorted(SEQS)
    assert bench.discover(data_dir, log=lambda m: None, max_points=None)
    with pytest.raises(BenchError):
        bench.discover(data_dir, log=msgs.append, max_points=59)
    assert any("60 points exceed the limit of 59" in m for m in msgs)


# --------------------------------------------------------------------------- missing data


def _load_bench_script(name: str):
    """``benchmarks/<name>.py`` as a module (its folder on sys.path, as when run as a script)."""
    import importlib.util
    import sys

    folder = Path(__file__).resolve().parent.parent / "benchmarks"
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))
    spec = importlib.util.spec_from_file_location(f"_bench_{name}_script", folder / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def missing_run(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("bench-missing") / "out"
    summary = run_bench(data_dir, out, methods=("laav", "rv"), seeds=1, noise=(0.0,),
                        missing=(0.0, 0.3), only=["syn_a", "syn_b"], jobs=1, params=SMALL,
                        progress=False, log=lambda m: None)
    return out, summary


def test_missing_share_is_a_column_and_part_of_the_key(missing_run, data_dir, monkeypatch):
    out, summary = missing_run
    assert bench.KEY == ("sequence", "method", "seed", "noise", "missing")
    rows = _csv_rows(out / "runs.csv")
    assert tuple(rows[0]) == COLUMNS and not summary.failed
    keys = {(r["sequence"], r["method"], r["seed"], r["noise"], r["missing"]) for r in rows}
    assert keys == {(s, m, "0", "0", share) for s in ("syn_a", "syn_b") for m in ("laav", "rv")
                    for share in ("0", "0.3")}
    for r in rows:
        assert 0.0 <= float(r["unlabelled"]) <= float(r["error"]) + 1e-9
    # a row is the direct API call on the noisy, then occluded sequence
    typed = read_runs(out / "runs.csv")
    row = next(r for r in typed if (r["sequence"], r["method"], r["missing"]) == ("syn_b", "laav", 0.3))
    seq = laav.load_sequence(data_dir / "syn_b" / "syn_b_truth.mat")
    occl = bench.hide_entries(seq, 0.3, seed=0)
    assert not occl.is_complete and 1 - occl.visible_share == pytest.approx(0.3, abs=1e-3)
    res = laav.segment(occl, 3, SMALL, 0)
    assert row["error"] == pytest.approx(100 * laav.misclassification_rate(seq.labels, res.labels))
    assert row["unlabelled"] == pytest.approx(100 * np.mean(res.labels < 0))
    # another share later: only its runs run
    calls = []
    real = bench.run_one
    monkeypatch.setattr(bench, "run_one", lambda *a, **k: calls.append(a[5]) or real(*a, **k))
    more = run_bench(data_dir, out, methods=("laav", "rv"), seeds=1, noise=(0.0,),
                     missing=(0.0, 0.3, 0.5), only=["syn_a", "syn_b"], jobs=1, params=SMALL,
                     progress=False, report=False, log=lambda m: None)
    assert (more.already_done, more.completed, calls) == (8, 4, [0.5] * 4)


def test_runs_csv_without_the_missing_columns_still_loads_and_resumes(bench_run, data_dir, tmp_path):
    out, _, _ = bench_run
    new = _csv_rows(out / "runs.csv")
    old_dir = tmp_path / "old"
    old_dir.mkdir()
    (old_dir / "bench.json").write_text((out / "bench.json").read_text())
    for cols, name in ((bench.NO_MISSING_COLUMNS, "runs.csv"), (bench.LEGACY_COLUMNS, "legacy.csv")):
        with open(old_dir / name, "w", newline="") as fh:
            w = csv.DictWriter(fh, cols, extrasaction="ignore")
            w.writeheader()
            w.writerows(new)
        rows = read_runs(old_dir / name)
        assert len(rows) == len(new) and all(r["missing"] == 0.0 for r in rows)
        assert all(np.isnan(r["unlabelled"]) for r in rows)
        assert {bench.run_key(r) for r in rows} == {bench.run_key(r) for r in read_runs(out / "runs.csv")}
        assert "Error vs. missing share" not in report_from_csv(old_dir / name)
    # a resume of the old folder runs nothing and rewrites the file with the new columns
    again = run_bench(data_dir, old_dir, methods=("laav", "rv"), seeds=2, noise=(0.0, 1.0), jobs=1,
                      params=SMALL, progress=False, log=lambda m: None)
    assert (again.already_done, again.completed) == (24, 0)
    rewritten = _csv_rows(old_dir / "runs.csv")
    assert tuple(rewritten[0]) == COLUMNS
    assert {r["missing"] for r in rewritten} == {"0"} and {r["unlabelled"] for r in rewritten} == {""}
    assert read_runs(old_dir / "runs.csv") and not list(old_dir.glob("fig5*"))


def test_occlusion_is_seeded_and_the_same_as_benchmarks_missing_py(data_dir):
    import zlib

    from laav.synthetic import BENCH_SPREAD, occlude, occlusion_rng

    script = _load_bench_script("missing")
    assert script.occlusion_rng is occlusion_rng and script.SPREAD == BENCH_SPREAD == 0.5
    seq = make_sequence(n_objects=1, n_frames=12, n_points=80, rng=5, name="occl")
    a = bench.hide_entries(seq, 0.4, seed=3)
    np.testing.assert_array_equal(a.visible, bench.hide_entries(seq, 0.4, seed=3).visible)
    assert not np.array_equal(a.visible, bench.hide_entries(seq, 0.4, seed=4).visible)
    other = laav.Sequence(seq.points, seq.labels, name="other")
    assert not np.array_equal(a.visible, bench.hide_entries(other, 0.4, seed=3).visible)
    # the seeding of docs/bench/missing.md's runs: (seed, crc32(name), round(level * 1e6))
    gen = np.random.default_rng(np.random.SeedSequence([3, zlib.crc32(b"occl"), 400000]))
    np.testing.assert_array_equal(a.visible, occlude(seq, 0.4, gen, spread=0.5).visible)
    # noise first, then the same entries hidden whatever the noise
    noisy = bench.hide_entries(add_pixel_noise(seq, 1.0, seed=3), 0.4, seed=3)
    np.testing.assert_array_equal(noisy.visible, a.visible)
    assert bench.hide_entries(seq, 0.0, seed=3) is seq
    # the whole run: the script's row and the bench's row agree (default parameters)
    item = bench.discover(data_dir, ["syn_a"], log=lambda m: None)[0]
    row = bench.run_one(item, "laav", 0, 0.0, None, 0.3)
    theirs = script.run_sequence(item.path, [0.3], 0)[0]
    assert row["error"] == pytest.approx(float(theirs["error"]), abs=1e-3)
    assert row["unlabelled"] == pytest.approx(float(theirs["unlabelled"]), abs=1e-3)


def test_report_has_the_missing_table_and_figure(missing_run):
    from PIL import Image

    from laav.report import MISSING_FIGURE, missing_table

    out, _ = missing_run
    text = (out / "report.md").read_text()
    assert "## Error vs. missing share (Fig. 5)" in text and f"({MISSING_FIGURE})" in text
    rows = read_runs(out / "runs.csv")
    _, mt = missing_table(rows)
    for m, label in (("laav", "LAAV"), ("rv", "RV")):
        for share, pct in ((0.0, "0 %"), (0.3, "30 %")):
            line = next(ln for ln in text.split("Error vs. missing share", 1)[1].splitlines()
                        if ln.startswith(f"| {label} | {pct} |"))
            cells = [c.strip() for c in line.strip("|").split("|")]
            errs = [r["error"] for r in rows if r["method"] == m and r["missing"] == share]
            assert cells[6] == f"{np.mean(errs):.2f}" == f"{mt[m][share]['all'][0]:.2f}"
            assert cells[8] == "2"
    # the complete-data sections use the share-0 runs only
    t1 = _table_line(text, "LAAV", "## Table 1")
    zero = [r["error"] for r in rows if r["method"] == "laav" and r["missing"] == 0.0]
    assert t1[4] == f"{np.mean(zero):.2f}"
    png = out / MISSING_FIGURE
    assert png.read_bytes()[:8] == PNG_MAGIC
    with Image.open(png) as im:
        assert im.size[0] > 400 and im.size[1] > 300


def test_cli_rejects_bad_missing_shares(data_dir, tmp_path, capsys):
    assert bench.parse_missing("0.4,0, 0.2,0") == (0.0, 0.2, 0.4)
    assert bench.parse_missing("0.94") == (0.94,)
    for bad, what in (("1.2", "in [0, 0.95)"), ("x", "is not a number"), ("0.95", "in [0, 0.95)"),
                      ("-0.1", "in [0, 0.95)"), ("nan", "in [0, 0.95)"), ("", "no missing share")):
        out = tmp_path / f"o{len(what)}"
        assert main(["bench", "--data", str(data_dir), "--missing", bad, "--out", str(out),
                     "-q"]) == 2, bad
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("laav bench: error: ") and what in err[0], err
        assert not out.exists()


def test_label_identity_all_covers_every_sequence_clean_and_occluded(hopkins_root):
    """``benchmarks/label_identity.py --all``: every Hopkins155 sequence the benchmarks use
    (``speed.truth_files``), each at seeds 0-1 with the default preset and at 20 % and 40 %
    missing (seeded occlusion), in that order; nothing run here, only the list checked."""
    import itertools

    mod = _load_bench_script("label_identity")
    from speed import truth_files  # (the benchmarks' folder is on sys.path now)

    first = truth_files(hopkins_root, [])[0].parent.name
    head = list(itertools.islice(mod.every_sequence(hopkins_root), 4))
    assert [r[0] for r in head] == [f"all/{first}/seed0", f"all/{first}/seed1",
                                    f"all/{first}/missing20", f"all/{first}/missing40"]
    assert [r[4] for r in head] == [0, 1, 0, 0]
    clean, _, m20, m40 = (r[1] for r in head)
    assert clean.is_complete and not m20.is_complete and not m40.is_complete
    assert abs((1 - m20.visible.mean()) - 0.2) < 0.05 and abs((1 - m40.visible.mean()) - 0.4) < 0.05
    assert all(r[2] == clean.n_motions and r[3] == mod.laav.LaavParams() for r in head)


def _chain_row(config, seq, seed, error, iterations, seconds, motions=2):
    return {"config": config, "sequence": seq, "motions": str(motions), "seed": str(seed),
            "error": f"{error:.4f}", "coarse": "0.0000", "coverage": "1.0", "converged": "1",
            "iterations": str(iterations), "trials": "1", "selected": "informed",
            "seconds": f"{seconds:.5f}", "informed_converged": "1",
            "informed_iterations": str(iterations)}


def test_chain_summary_without_plain_rv_rows():
    """``chain.py --no-plain-rv`` on an --out without plain RV's rows: the ratio columns say
    there are none (it raised KeyError), and with the rows the ratios are over the pairs."""
    chain = _load_bench_script("chain")
    own = [_chain_row("default", "a", 0, 1.0, 20, 0.05), _chain_row("default", "b", 0, 3.0, 40, 0.07, 3)]
    row = chain.summarise(own)[2]
    assert row.startswith("| default | 1.00 / 3.00 / 2.00 |")
    assert "- (no plain-RV rows) | - (no plain-RV rows) ; - (no plain-RV rows) |" in row
    plain = [_chain_row("plain-rv", "a", 0, 2.0, 200, 0.025),
             _chain_row("plain-rv", "b", 0, 2.0, 400, 0.7, 3)]
    rows = chain.summarise(plain + own)
    assert "| 30 / 300 = 0.10 | 2.00 (50 / 25 ms) ; 0.10 (70 / 700 ms) |" in rows[3]
    # a plain-RV row for one run only: the ratios over that run, and the table says so
    rows = chain.summarise(plain[:1] + own)
    assert "| 20 / 200 = 0.10 (of 1 runs) | 2.00 (50 / 25 ms) ; - (no plain-RV rows) |" in rows[3]
    # two two-motion runs, one with plain RV's row: the time ratio says of how many
    rows = chain.summarise(plain[:1] + own + [_chain_row("default", "c", 0, 0.0, 10, 0.03)])
    assert "2.00 (50 / 25 ms, of 1 runs) ; - (no plain-RV rows) |" in rows[3]
