"""The voting helper (laav.helper): a second process for LAAV's own trials changes no label."""

import functools
import os
import signal
import time

import numpy as np
import pytest

import laav
from laav import synthetic
from laav._interrupt import Interrupted, interruptible
from laav.helper import VotingHelper


@pytest.fixture(scope="module")
def helper():
    h = VotingHelper()
    assert h.wait_ready()
    yield h
    h.close()


#: Every missing-motion start's trials run (the gate, ``rv_missing_gate``, off): the parts the
#: helper takes. The gate itself with the helper: :func:`test_the_gate_with_the_helper`.
ALL = laav.LaavParams(rv_missing_gate=0.0)


def _scene(seed):
    return synthetic.make_sequence(n_objects=2, n_frames=20, n_points=300, rng=seed)


@functools.cache
def _slow_scene():
    return synthetic.make_sequence(n_objects=2, n_frames=20, n_points=_SLOW_POINTS, rng=0)


def _same(a, b):
    va, vb = a.voting, b.voting
    assert np.array_equal(a.labels, b.labels)
    assert va.trial_iterations == vb.trial_iterations
    assert va.costs == vb.costs
    assert va.selected == vb.selected
    assert np.array_equal(va.votes, vb.votes)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_same_result_with_the_helper(helper, seed):
    seq = _scene(seed)
    alone = laav.Pipeline(seq, 3, ALL, seed=seed).result
    jobs, delivered = helper.jobs, helper.delivered
    helped = laav.Pipeline(seq, 3, ALL, seed=seed, helper=helper).result
    # several trials (informed and missing-motion starts), some of them in the helper
    assert len(helped.voting.trial_iterations) >= 3
    assert (helper.jobs, helper.delivered) == (jobs + 1, delivered + 1)
    _same(alone, helped)


def test_the_gate_with_the_helper(helper, monkeypatch):
    """With ``rv_missing_gate`` (the default) the informed trial runs here alone, then the
    starts it leaves unexplained, split with the helper: the labels of computing it all
    here, and with every start left unexplained those of the gate off."""
    import laav.own_chain as V

    seq = _scene(1)
    jobs = helper.jobs
    gated = laav.Pipeline(seq, 3, seed=1, helper=helper).result
    assert gated.voting.skipped_starts and helper.jobs == jobs  # the informed trial alone: here
    _same(laav.Pipeline(seq, 3, seed=1).result, gated)
    monkeypatch.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                        np.ones(labels.size, bool))
    jobs = helper.jobs
    helped = laav.Pipeline(seq, 3, seed=1, helper=helper).result
    assert helper.jobs == jobs + 1 and helped.voting.skipped_starts == ()
    _same(laav.Pipeline(seq, 3, ALL, seed=1).result, helped)


def test_updates_with_the_helper_match(helper):
    seq = _scene(3)
    alone, helped = laav.Pipeline(seq, 3, ALL), laav.Pipeline(seq, 3, ALL, helper=helper)
    for r1 in (8.0, 12.0):
        _same(alone.update(r1=r1), helped.update(r1=r1))
    _same(alone.update(seed=5), helped.update(seed=5))


def test_random_voting_takes_a_helper(helper):
    seq = _scene(4)
    init = laav.Pipeline(seq, 3, ALL, seed=1).result.stage_labels()["coarse"]
    a = laav.random_voting(seq, 3, ALL, seed=7, init_labels=init)
    b = laav.random_voting(seq, 3, ALL, seed=7, init_labels=init, helper=helper)
    assert np.array_equal(a.labels, b.labels)
    assert a.trial_iterations == b.trial_iterations


def test_a_closed_helper_leaves_the_work_here():
    seq = _scene(0)
    h = VotingHelper(start=False)
    h.close()
    assert h.submit(()) is None
    res = laav.Pipeline(seq, 3, ALL, helper=h).result
    assert h.jobs == 0
    _same(laav.Pipeline(seq, 3, ALL).result, res)


def test_a_helper_not_ready_leaves_the_work_here():
    """A computation never waits for the process to start: until it is ready the caller
    computes everything itself."""
    seq = _scene(2)
    with VotingHelper(start=False) as h:
        res = laav.Pipeline(seq, 3, ALL, helper=h).result  # starts the process, does not wait
        assert h.jobs == 0 and not h.ready
        _same(laav.Pipeline(seq, 3, ALL).result, res)
        assert h.wait_ready() and h.ready
        laav.Pipeline(seq, 3, ALL, helper=h)
        assert h.jobs == h.delivered == 1


def test_a_dead_helper_process_leaves_the_work_here():
    seq = _scene(1)
    h = VotingHelper()
    try:
        assert h.wait_ready()
        laav.Pipeline(seq, 3, ALL, helper=h)  # the process is up and has served a job
        for pid in list(h._pool._processes):
            os.kill(pid, signal.SIGKILL)
        time.sleep(0.5)
        res = laav.Pipeline(seq, 3, ALL, seed=2, helper=h).result
        _same(laav.Pipeline(seq, 3, ALL, seed=2).result, res)
        # and a new process serves the next call, once up
        assert h.wait_ready()
        jobs = h.jobs
        res = laav.Pipeline(seq, 3, ALL, seed=3, helper=h).result
        assert h.jobs == jobs + 1
        _same(laav.Pipeline(seq, 3, ALL, seed=3).result, res)
    finally:
        h.close()


def test_a_stopped_computation_stops_the_helpers_half(helper):
    """Stopped while the trials run, the call raises and the helper's job ends at its next
    iteration: the next call is served at once and gives the labels of a run alone."""
    seq = _scene(2)
    pipe = laav.Pipeline(seq, 3, ALL, helper=helper)
    calls = []

    def stop():  # once the voting has begun (a few iterations in)
        calls.append(1)
        return len(calls) > 20

    with pytest.raises(Interrupted), interruptible(stop):
        pipe.update(seed=9)
    t = time.perf_counter()
    res = laav.Pipeline(seq, 3, ALL, seed=9, helper=helper).result
    assert time.perf_counter() - t < 30
    _same(laav.Pipeline(seq, 3, ALL, seed=9).result, res)


def test_stop_ends_a_running_job(helper):
    handle = helper.submit(_long_job(seed=0))
    time.sleep(0.5)
    assert not handle[1].done()
    t = time.perf_counter()
    helper.stop(handle)
    with pytest.raises(Interrupted):
        handle[1].result(timeout=20)
    assert time.perf_counter() - t < 5


def test_the_helper_ends_with_its_parent(tmp_path):
    """A parent killed without clean-up (as a server stopped by SIGTERM) leaves no helper."""
    import subprocess
    import sys

    code = ("import laav, time, os\n"
            "h = laav.VotingHelper()\n"
            "h._pool.submit(os.getpid).result(timeout=60)\n"
            "print([p.pid for p in h._pool._processes.values()][0], flush=True)\n"
            "time.sleep(60)\n")
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        child = int(proc.stdout.readline())
        os.kill(child, 0)  # alive
        proc.kill()
        proc.wait(10)
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            try:
                os.kill(child, 0)
            except ProcessLookupError:
                break
            try:  # reap it if it became ours (it does not: it is re-parented to init)
                os.waitpid(child, os.WNOHANG)
            except ChildProcessError:
                pass
            time.sleep(0.1)
        else:
            pytest.fail("the helper outlived its parent")
    finally:
        proc.kill()


#: A scene whose voting iterations are slow (~5 ms each on 20,000 points): a job of 10,000 of
#: them lasts about a minute, far beyond the 0.2-1 s the tests wait before they stop or kill
#: it (on 300 points it took 2.5-3 s, and a 3-4x faster machine would have finished it).
_SLOW_POINTS = 20_000


def _long_job(seed=1):
    """Arguments of a helper job of 10,000 voting iterations on ``_SLOW_POINTS`` points
    (about a minute: it is stopped or killed long before)."""
    seq = _slow_scene()
    P = seq.points.shape[1]
    rng = np.random.default_rng(seed)
    params = laav.LaavParams(rv_max_iter=10_000, rv_patience=10_000)
    start = (rng.integers(0, 3, P), np.zeros((P, 3)), np.random.default_rng(seed + 1))
    return (seq.points, 3, params, [start], None, [False])


def test_stopping_a_queued_job_leaves_the_running_one(helper):
    """The pool hands its process a job or two beyond the one running, marked running: a
    stop of such a queued job must not stop the running job of another caller."""
    seq = _slow_scene()
    P = seq.points.shape[1]
    params = laav.LaavParams(rv_max_iter=300, rv_patience=300)  # about 1.5 s on 20,000 points
    rng = np.random.default_rng(3)
    start = (rng.integers(0, 3, P), np.zeros((P, 3)), np.random.default_rng(4))
    first = helper.submit((seq.points, 3, params, [start], None, [False]))
    second = helper.submit(_long_job())
    time.sleep(0.2)
    assert not first[1].done()  # (the first still runs: the second is queued behind it)
    helper.stop(second)
    value = helper.result(first, lambda: None)
    assert value is not None and value[0][0][4] == 300  # ran all its iterations
    assert helper.result(second, lambda: None) is None  # stopped (or never started)


def test_a_helper_that_dies_mid_job_leaves_the_job_to_the_caller():
    seq = _scene(0)
    with VotingHelper() as h:
        assert h.wait_ready()
        handle = h.submit(_long_job())
        time.sleep(1.0)
        for pid in list(h._pool._processes):
            os.kill(pid, signal.SIGKILL)
        assert h.result(handle, lambda: None) is None
        # a new process serves the next job, once up
        assert h.wait_ready()
        res = laav.Pipeline(seq, 3, ALL, seed=2, helper=h).result
        assert h.delivered == 1
        _same(laav.Pipeline(seq, 3, ALL, seed=2).result, res)


def test_a_helper_whose_process_keeps_dying_closes_itself():
    seq = _scene(0)
    with VotingHelper() as h:
        with pytest.warns(RuntimeWarning, match="died 3 times"):
            for _ in range(3):
                assert h.wait_ready()
                handle = h.submit(_long_job())
                assert handle is not None
                time.sleep(0.5)
                for pid in list(h._pool._processes):
                    os.kill(pid, signal.SIGKILL)
                assert h.result(handle, lambda: None) is None
        assert h.submit(_long_job()) is None
        _same(laav.Pipeline(seq, 3, ALL).result, laav.Pipeline(seq, 3, ALL, helper=h).result)


def test_a_process_that_dies_at_start_leaves_the_work_here(monkeypatch):
    """A pool whose process dies before it takes its first job (as when a script makes a
    helper at import, which spawn runs again in the child): every call computes here, no
    AttributeError from a pool kept without its readiness, and the helper closes itself
    after a few tries."""
    import laav.helper as H

    made = []

    class DeadPool:
        def __init__(self, *a, **k):
            made.append(self)

        def submit(self, *a, **k):
            raise H.BrokenProcessPool("died at start")

        def shutdown(self, *a, **k):
            pass

    monkeypatch.setattr(H, "ProcessPoolExecutor", DeadPool)
    seq = _scene(0)
    with pytest.warns(RuntimeWarning, match="died 3 times"):
        h = VotingHelper()
        assert not h.ready
        for _ in range(4):
            assert h.submit(_long_job()) is None
    assert len(made) == 3  # then closed: no new process per call
    assert not h.wait_ready(timeout=1)
    _same(laav.Pipeline(seq, 3, ALL).result, laav.Pipeline(seq, 3, ALL, helper=h).result)
    h.close()


def test_prefetched_votes_are_those_fitted_here(helper):
    """With prefetch_votes, the coarse stage's pairwise votes (which the default merge does
    not fit; what the explorer draws) are fitted in the helper while the voting runs: the
    same numbers as fitted here when read."""
    seq = _scene(5)
    alone = laav.Pipeline(seq, 3, ALL)
    helped = laav.Pipeline(seq, 3, ALL, helper=helper)
    helped.prefetch_votes = True
    for r1 in (8.0, 12.0):
        a = alone.update(r1=r1)
        delivered = helper.delivered
        b = helped.update(r1=r1)
        assert a.coarse.pairwise.unfitted() is not None  # not read yet: not fitted
        assert b.coarse.pairwise.unfitted() is None  # fitted, by the helper
        assert helper.delivered == delivered + 2  # the votes and a part of the candidates
        _same(a, b)
        np.testing.assert_array_equal(a.coarse.epipolar_distance, b.coarse.epipolar_distance)
        np.testing.assert_array_equal(a.coarse.pairwise_vote, b.coarse.pairwise_vote)
        va, vb = a.coarse.vote_samples, b.coarse.vote_samples
        for name in ("frames", "fundamental", "points", "distance"):
            np.testing.assert_array_equal(getattr(va, name), getattr(vb, name))


def test_a_job_that_fails_there_is_computed_here(helper):
    """A job the helper cannot run (here: a function that does not pickle) gives None, and
    the caller computes it: no error of the helper's own reaches the caller."""
    handle = helper.submit_call(lambda: 1)
    assert handle is not None
    assert helper.result(handle, lambda: None) is None


def test_close_stops_a_running_job():
    """Closing the helper (also at interpreter exit) does not wait for a running job's end:
    the job stops at its next check."""
    h = VotingHelper()
    assert h.wait_ready()
    handle = h.submit(_long_job())
    time.sleep(0.5)
    assert not handle[1].done()  # running: 10,000 slow iterations, about a minute
    t = time.perf_counter()
    h.close()
    assert time.perf_counter() - t < 5
    with pytest.raises(Interrupted):
        handle[1].result(timeout=0)


_EXIT_CHILD = """
import sys, time
import numpy as np
import laav
from laav.helper import VotingHelper
from laav import synthetic

if __name__ == "__main__":
    h = VotingHelper()
    assert h.wait_ready()
    seq = synthetic.make_sequence(n_objects=2, n_frames=20, n_points=20_000, rng=0)
    P = seq.points.shape[1]
    rng = np.random.default_rng(1)
    params = laav.LaavParams(rv_max_iter=10_000, rv_patience=10_000)  # about a minute
    start = (rng.integers(0, 3, P), np.zeros((P, 3)), np.random.default_rng(2))
    handle = h.submit((seq.points, 3, params, [start], None, [False]))
    time.sleep(0.5)
    assert not handle[1].done()
    print(time.time(), flush=True)  # the script's end: the interpreter exits from here
"""


def test_interpreter_exit_does_not_wait_for_a_running_job(tmp_path):
    """A script that ends while the helper runs a long job exits at once: the helper closes
    itself before ``concurrent.futures`` would wait for the job (an ``atexit`` handler ran
    only after that wait: 6 s for a 10,000-iteration job)."""
    import subprocess
    import sys

    script = tmp_path / "child.py"
    script.write_text(_EXIT_CHILD)
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    ended = time.time()
    assert out.returncode == 0, out.stderr
    assert ended - float(out.stdout.strip().splitlines()[-1]) < 5
