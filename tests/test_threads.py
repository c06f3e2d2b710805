"""The pipeline runs with one BLAS/OpenMP thread and restores the caller's thread counts."""

from __future__ import annotations

import threading

import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import laav
import laav.own_chain as own_chain_module
import laav.pipeline as pipeline_module
import laav.voting as voting_module
from laav import LaavParams, random_voting, segment
from laav._threads import limited_threads
from laav.synthetic import make_sequence

FAST = LaavParams(rv_max_iter=30, rv_trials=2)


def _threads() -> dict:
    return {i["filepath"]: i["num_threads"] for i in threadpool_info()}


@pytest.fixture
def two_threads():
    """Every thread pool (BLAS, scikit-learn's OpenMP) at 2 threads during the test."""
    laav.preload()  # load every library whose pool the pipeline limits
    with threadpool_limits(limits=2):
        before = _threads()
        assert before and all(n == 2 for n in before.values()), before
        yield before


def _spy(monkeypatch, module, name, seen):
    orig = getattr(module, name)

    def spy(*args, **kwargs):
        seen.append(_threads())
        return orig(*args, **kwargs)

    monkeypatch.setattr(module, name, spy)


def test_segment_and_random_voting_run_single_threaded(two_threads, monkeypatch):
    seq = make_sequence(n_objects=1, n_frames=10, n_points=100, rng=0)
    seen: list = []
    _spy(monkeypatch, pipeline_module, "merge_models", seen)  # inside Pipeline._run
    _spy(monkeypatch, voting_module, "run_trials", seen)  # inside random_voting (plain RV)
    _spy(monkeypatch, own_chain_module, "informed_side_by_side", seen)  # LAAV's own trials
    segment(seq, 2, FAST)
    pipe = laav.Pipeline(seq, 2, FAST)
    assert _threads() == two_threads
    pipe.update(lam=3.0)
    random_voting(seq, 2, FAST)
    # merge_models 3x (segment, Pipeline, the λ update); LAAV's own trials 2x (the λ update
    # keeps the fine-tuning when the coarse labels stay); plain RV's trials once
    assert len(seen) >= 6
    assert all(set(s.values()) == {1} for s in seen), seen
    assert _threads() == two_threads  # restored after every call


def test_concurrent_runs_share_one_limit(two_threads):
    # A enters, B enters, A leaves (B still limited), B leaves: restored, not stuck at 1.
    # BLAS pools are process-wide; OpenMP's count is per thread (B limits its own).
    a_in, b_in, a_out, b_out = (threading.Event() for _ in range(4))
    seen = {}

    def run_a():
        with limited_threads():
            a_in.set()
            b_in.wait(10)
        a_out.set()

    def run_b():
        a_in.wait(10)
        with limited_threads():
            b_in.set()
            a_out.wait(10)
            seen["b after a left"] = _threads()
        b_out.set()

    threads = [threading.Thread(target=run_a), threading.Thread(target=run_b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert b_out.is_set() and a_out.is_set()
    assert set(seen["b after a left"].values()) == {1}, seen
    assert _threads() == two_threads


def test_an_error_inside_a_run_restores_the_threads(two_threads, monkeypatch):
    def fail(*args, **kwargs):
        assert set(_threads().values()) == {1}
        raise RuntimeError("stage failed")

    monkeypatch.setattr(pipeline_module, "merge_models", fail)
    with pytest.raises(RuntimeError, match="stage failed"):
        segment(make_sequence(n_objects=1, n_frames=10, n_points=100, rng=0), 2, FAST)
    assert _threads() == two_threads


def test_a_library_loaded_after_the_first_run_is_capped_too():
    """The controller of the thread pools is made again when modules were imported since:
    scikit-learn's OpenMP, loaded after a first run, ran at its own thread count inside
    later runs (test_threads failed when it ran after test_coarse)."""
    import subprocess
    import sys

    code = """
import laav
from laav._threads import limited_threads
from threadpoolctl import threadpool_info, threadpool_limits
with limited_threads():
    pass
import sklearn.cluster  # its OpenMP library, loaded after the first run
with threadpool_limits(limits=2):
    with limited_threads():
        inside = {i["filepath"]: i["num_threads"] for i in threadpool_info()}
print(inside)
assert any("gomp" in p or "omp" in p for p in inside), inside
assert set(inside.values()) == {1}, inside
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
