"""The explorer computes the next seed while idle (``seeds_ahead``): a step of the seed
slider then shows it at once, with the labels a fresh computation gives."""

from __future__ import annotations

import time

import numpy as np

import laav
from explorer.state import AHEAD_MAX_POINTS, ExplorerState
from laav.synthetic import make_sequence

PARAMS = laav.LaavParams(rv_max_iter=40, rv_trials=3)


def _wait(pred, timeout=120.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if pred():
            return True
        time.sleep(0.02)
    return False


def _ahead_ready(st, seed):
    key = (id(st.sequence), st.settings.__class__(st.settings.params, seed, st.settings.n_motions))
    return lambda: key in st._ahead and st.plain_rv(settings=key[1]) is not None


def test_the_next_seed_is_shown_from_the_computation_ahead_with_fresh_labels():
    seq = make_sequence(n_objects=1, n_points=150, n_frames=15, rng=4)
    st = ExplorerState(seq, 2, PARAMS, seed=3, seeds_ahead=True)
    try:
        assert st.wait(120) and st.result.seed == 3
        assert _wait(_ahead_ready(st, 4))  # pipeline and plain RV for seed 4, while idle
        st.request(seed=4)
        assert st.wait(120) and st.result.seed == 4
        assert st.ahead_used == 1 and st.computed_ahead(st.result)
        fresh = laav.segment(seq, 2, PARAMS, seed=4)
        np.testing.assert_array_equal(st.result.labels, fresh.labels)
        np.testing.assert_array_equal(st.result.coarse.point_labels, fresh.coarse.point_labels)
        # a step back: the pipeline it replaced was kept for those settings
        st.request(seed=3)
        assert st.wait(120) and st.result.seed == 3 and st.ahead_used == 2
        np.testing.assert_array_equal(st.result.labels, laav.segment(seq, 2, PARAMS, seed=3).labels)
        assert _wait(_ahead_ready(st, 4))
        st.request(seed=4)
        assert st.wait(120) and st.ahead_used == 3
        # a later move goes on from the pipeline computed ahead, as from any other
        st.request(params={"lam": 3.0})
        assert st.wait(120) and st.result.params.lam == 3.0 and not st.computed_ahead(st.result)
        np.testing.assert_array_equal(
            st.result.labels, laav.segment(seq, 2, PARAMS.replace(lam=3.0), seed=4).labels)
        # a jump to a seed not computed ahead is computed as before
        st.request(seed=9)
        assert st.wait(120) and st.result.seed == 9 and st.ahead_used == 3
    finally:
        st.close()


def test_a_request_stops_the_computation_ahead_and_it_is_off_by_default(monkeypatch):
    import threading

    import explorer.state as S

    started = threading.Event()

    class Watched(laav.Pipeline):
        def __init__(self, *a, **k):
            if "-plain-rv_" in threading.current_thread().name:  # (ExplorerState.threads)
                started.set()  # the computation ahead (plain RV's worker) has begun
                time.sleep(0.2)
            super().__init__(*a, **k)

    monkeypatch.setattr(S, "Pipeline", Watched)
    seq = make_sequence(n_objects=2, n_points=400, n_frames=30, rng=5)
    st = ExplorerState(seq, 3, laav.LaavParams(), seed=0, seeds_ahead=True)
    try:
        assert st.wait(120)
        before = st.rv_computing.interrupted
        assert started.wait(120)
        old_key = (id(seq), S.Settings(laav.LaavParams(), 1, 3))
        st.request(params={"lam": 2.5})
        assert st.wait(120) and st.result.params.lam == 2.5
        assert _wait(lambda: st.rv_computing.interrupted > before, 60)
        assert old_key not in st._ahead  # stopped, not finished
    finally:
        st.close()
    off = ExplorerState(make_sequence(n_objects=1, n_points=120, n_frames=12, rng=1), 2, PARAMS)
    try:
        assert off.wait(120) and off.wait_plain_rv(60) is not None
        time.sleep(0.3)
        assert off.seeds_ahead is False and len(off._ahead) == 0
    finally:
        off.close()
    big = ExplorerState(make_sequence(n_objects=1, n_points=AHEAD_MAX_POINTS + 10, n_frames=8, rng=2),
                        2, PARAMS, seeds_ahead=True)
    try:
        assert big.wait(300) and big.wait_plain_rv(120) is not None
        time.sleep(0.3)
        assert len(big._ahead) == 0  # above the size limit: nothing computed ahead
    finally:
        big.close()


def test_a_seed_the_sweep_computed_is_shown_from_its_pipeline():
    """The seed sweep's pipelines are kept (``offer_pipeline``): a request of a swept seed
    shows that pipeline's result at once, said as such, with a fresh computation's labels;
    a pipeline for other settings, or another sequence, is not kept."""
    from explorer.sweep import SeedSweep

    seq = make_sequence(n_objects=1, n_points=150, n_frames=15, rng=4)
    st = ExplorerState(seq, 2, PARAMS, seed=0)
    sw = SeedSweep(on_pipeline=st.offer_pipeline)
    try:
        assert st.wait(120)
        sw.start(seq, 2, PARAMS, seeds=(5, 6))
        assert sw.wait(300) and [r.seed for r in sw.rows] == [5, 6]
        st.request(seed=6)
        assert st.wait(120) and st.result.seed == 6 and st.ahead_used == 1
        assert st.computed_ahead(st.result) == "by the seed sweep"
        fresh = laav.segment(seq, 2, PARAMS, seed=6)
        np.testing.assert_array_equal(st.result.labels, fresh.labels)
        np.testing.assert_array_equal(st.result.coarse.point_labels, fresh.coarse.point_labels)
        other = make_sequence(n_objects=1, n_points=150, n_frames=15, rng=5)
        assert not st.offer_pipeline(other, 2, PARAMS, 7, laav.Pipeline(other, 2, PARAMS, 7))
        st.request(params={"lam": 3.0})  # the swept seed 5 was for other settings
        assert st.wait(120)
        st.request(seed=5)
        assert st.wait(120) and st.result.seed == 5 and st.ahead_used == 1
        assert st.computed_ahead(st.result) is None
        # once another sequence is asked for, the old one's pipelines are neither kept nor taken
        st.load(other)
        assert not st.offer_pipeline(seq, 2, PARAMS, 8, laav.Pipeline(seq, 2, PARAMS, 8))
        assert st.wait(120) and st.sequence is other and len(st._ahead) == 0
    finally:
        sw.close()
        st.close()


def _watch_pipelines(monkeypatch) -> list:
    """From now on, the times (monotonic) at which the state starts a pipeline."""
    import explorer.state as S

    started = []

    class Watched(laav.Pipeline):
        def __init__(self, *a, **k):
            started.append(time.monotonic())
            super().__init__(*a, **k)

    monkeypatch.setattr(S, "Pipeline", Watched)
    return started


def test_the_computation_ahead_waits_until_nothing_was_asked_for_a_while(monkeypatch):
    """The next seed is computed only after ``AHEAD_IDLE_S`` without a request or a result:
    not beside the views being drawn and the next move of a slider (each request restarts
    the wait)."""
    import explorer.state as S

    monkeypatch.setattr(S, "AHEAD_IDLE_S", 2.0)
    seq = make_sequence(n_objects=1, n_points=150, n_frames=15, rng=4)
    st = ExplorerState(seq, 2, PARAMS, seed=3, seeds_ahead=True)
    try:
        assert st.wait(120)
        started = _watch_pipelines(monkeypatch)
        for lam in (2.5, 3.0, 3.5):  # a slider moved every 0.5 s: nothing computed ahead
            st.request(params={"lam": lam})
            assert st.wait(120)
            t_result = st._quiet_since
            time.sleep(0.5)
        assert started == []
        assert _wait(_ahead_ready(st, 4))  # then, once quiet for 2 s
        assert started and started[0] >= t_result + 2.0
        assert st.result.params.lam == 3.5
    finally:
        st.close()


def test_frame_moves_hold_the_computation_ahead_back_too(monkeypatch):
    """A person scrubbing the frames (no request to the state) is using the page: the next
    seed waits until ``AHEAD_IDLE_S`` after the last frame move as well."""
    import explorer.state as S
    from explorer import Explorer

    monkeypatch.setattr(S, "AHEAD_IDLE_S", 1.5)
    seq = make_sequence(n_objects=1, n_points=150, n_frames=15, rng=4)
    ex = Explorer(seq, 2, params=PARAMS, seed=3, viser=False, seeds_ahead=True)
    try:
        assert ex.wait(120)
        started = _watch_pipelines(monkeypatch)
        for f in range(1, 9):  # a frame every 0.4 s for 3.2 s: nothing computed ahead
            last = time.monotonic()  # (the move touches the state as it starts)
            ex.w_frame.value = f
            time.sleep(0.4)
        assert started == []
        assert _wait(_ahead_ready(ex.state, 4))  # then, 1.5 s after the last frame move
        assert started and started[0] >= last + 1.5
    finally:
        ex.close()
