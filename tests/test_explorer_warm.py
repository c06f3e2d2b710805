"""The first result computed in a child process (explorer.warm) and taken by the explorer's
state: the same labels as a pipeline computed in-process, later updates too; a failed or
missing child falls back to computing in-process; a request made while it is being waited
for supersedes the wait and still starts from it."""

from __future__ import annotations

import threading
from concurrent.futures import Future

import numpy as np
import pytest
from conftest import two_motion_sequence

import laav
from explorer import state as state_mod
from explorer import warm
from explorer.state import ExplorerState, Settings


@pytest.fixture(scope="module")
def seq() -> laav.Sequence:
    return two_motion_sequence(0, P=120, F=10, name="warm_test")


def _same(a: laav.LaavResult, b: laav.LaavResult) -> bool:
    return (np.array_equal(a.labels, b.labels)
            and np.array_equal(a.coarse.point_labels, b.coarse.point_labels)
            and np.array_equal(a.atoms.seeds, b.atoms.seeds))


def test_a_pipeline_travels_and_updates_like_the_original(seq):
    pipe = laav.Pipeline(seq, 2, seed=3)
    back = warm.pipeline_from_state(warm.pipeline_state(pipe), seq)
    assert back.seq is seq and _same(back.result, pipe.result)
    for change in ({"lam": 4.0}, {"r1": 15.0}, {"seed": 5}):
        assert _same(back.update(**change), pipe.update(**change))


def test_the_child_computes_the_pipeline_and_plain_rv_of_this_process(seq):
    p = laav.LaavParams(lam=3.0)
    w = warm.first_results(seq, 2, p, 1)
    pipe = w.pipeline.result(timeout=120)
    assert isinstance(pipe, laav.Pipeline) and pipe.seq is seq
    assert _same(pipe.result, laav.Pipeline(seq, 2, p, 1).result)
    voting = w.plain_rv.result(timeout=120)
    assert np.array_equal(voting.labels, state_mod.plain_rv_of(seq, Settings(p, 1, 2)).labels)


def test_a_held_state_is_rebuilt_only_when_released(seq, monkeypatch):
    """With ``hold``, the pipeline's state is rebuilt only once the event is set (the child
    is done with this small sequence well before), or after HOLD_MAX_S."""
    import time

    calls = []
    real = warm.pipeline_from_state
    monkeypatch.setattr(warm, "pipeline_from_state",
                        lambda *a: calls.append(time.monotonic()) or real(*a))
    class Hold(threading.Event):
        waited = threading.Event()  # the state arrived and its rebuild is waiting on the hold

        def wait(self, timeout=None):
            Hold.waited.set()
            return super().wait(timeout)

    hold = Hold()
    w = warm.first_results(seq, 2, None, 1, hold=hold)
    assert Hold.waited.wait(120), "the state never reached the hold"
    time.sleep(0.5)
    assert not calls and not w.pipeline.done() and not w.plain_rv.done()
    released = time.monotonic()
    hold.set()
    pipe = w.pipeline.result(timeout=120)
    assert calls and calls[0] >= released
    assert isinstance(pipe, laav.Pipeline) and _same(pipe.result, laav.Pipeline(seq, 2, seed=1).result)
    assert w.plain_rv.result(timeout=120) is not None
    monkeypatch.setattr(warm, "HOLD_MAX_S", 0.2)  # never released: read after HOLD_MAX_S
    w2 = warm.first_results(seq, 2, None, 1, hold=threading.Event())
    assert isinstance(w2.pipeline.result(timeout=120), laav.Pipeline)


def test_a_failing_child_gives_none(seq):
    bad = warm.first_results(seq, 10 ** 6, None, 0)  # C > P: the child fails
    assert bad.pipeline.result(timeout=120) is None and bad.plain_rv.result(timeout=120) is None
    assert bad.preview.result(timeout=120) is None


def test_the_child_sends_its_preview_first_and_the_state_shows_it_before_the_result(seq):
    """The child's pipeline hands its preview (LAAV's own fine-tuning, before plain RV, with
    ``with_plain_rv()``) back
    first; the state shows it (``on_preview``) while it waits for the pipeline, then the
    result; a preview for other settings than the ones asked for is not shown."""
    plain = laav.LaavParams.with_plain_rv()  # the preview exists where plain RV runs
    w = warm.first_results(seq, 2, plain, 1)
    pre = w.preview.result(timeout=120)
    pipe = w.pipeline.result(timeout=120)
    assert isinstance(pre, laav.LaavResult) and pre.voting.selected == "informed"
    np.testing.assert_array_equal(pre.voting.informed_changed, pipe.result.voting.informed_changed)
    assert pre.voting.costs == {} and pipe.result.voting.costs
    # the state, the child slow: the preview arrives first, then the pipeline
    fut, pfut = Future(), Future()
    st = ExplorerState(seq, 2, plain, seed=1, pipeline=fut, preview=pfut, autostart=False)
    events = []
    st.on_preview = lambda r, s, t, gen: events.append(("preview", r, gen))
    st.on_result = lambda r, s, t, gen: events.append(("result", r, gen))
    try:
        st.start()
        threading.Timer(0.3, pfut.set_result, (pre,)).start()
        threading.Timer(1.0, fut.set_result, (pipe,)).start()
        assert st.wait(120)
        assert [e[0] for e in events] == ["preview", "result"] and events[0][2] == events[1][2]
        assert events[0][1] is pre and events[1][1] is pipe.result and st.result is pipe.result
        # (plain RV's run in the background ends here: a later test's fork must not copy a
        # thread holding the pipeline's thread-limit lock)
        assert st.wait_plain_rv(120) is not None
    finally:
        st.close()
    # asked for other settings (a shared URL): that preview is not shown
    fut2, pfut2 = Future(), Future()
    st = ExplorerState(seq, 2, plain, seed=1, pipeline=fut2, preview=pfut2, autostart=False)
    st.retarget(Settings(plain.replace(lam=4.0), 1, 2))
    shown = []
    st.on_preview = lambda r, s, t, gen: shown.append(r)
    try:
        st.start()
        pfut2.set_result(pre)
        fut2.set_result(pipe)
        assert st.wait(120) and pre not in shown and st.result.params.lam == 4.0
        assert st.wait_plain_rv(120) is not None
    finally:
        st.close()


def test_state_takes_plain_rv_from_the_child(seq, monkeypatch):
    w = warm.first_results(seq, 2)  # (forked before the patch below)
    ran = []
    monkeypatch.setattr(state_mod, "plain_rv_of", lambda *a: ran.append(a))
    st = ExplorerState(seq, 2, pipeline=w.pipeline, plain_rv=w.plain_rv, autostart=False)
    try:
        st.start()
        assert st.wait(120) and st.wait_plain_rv(120) is not None
        assert not ran, "plain RV was computed although the child gave it"
        assert np.array_equal(st.plain_rv().labels, laav.random_voting(seq, 2, laav.LaavParams(), 0).labels)
    finally:
        st.close()


def _state(seq, fut, settings: Settings | None = None) -> ExplorerState:
    st = ExplorerState(seq, 2, pipeline=fut, autostart=False)
    if settings is not None:
        st.retarget(settings)
    return st


def test_state_takes_the_warm_pipeline_and_updates_it_to_the_settings_asked(seq, monkeypatch):
    built = []
    monkeypatch.setattr(state_mod, "Pipeline", lambda *a, **k: built.append(a) or laav.Pipeline(*a, **k))
    fut: Future = Future()
    fut.set_result(laav.Pipeline(seq, 2))
    asked = Settings(laav.LaavParams(lam=4.0), 0, 2)
    st = _state(seq, fut, asked)  # e.g. a shared URL's settings
    try:
        st.start()
        assert st.wait(120) and st.error is None
        assert not built, "a pipeline was built although a warm one was given"
        assert _same(st.result, laav.Pipeline(seq, 2, asked.params, 0).result)
    finally:
        st.close()


def test_the_time_shown_is_the_computation_not_the_wait(seq):
    fut: Future = Future()
    pipe = laav.Pipeline(seq, 2)
    st = _state(seq, fut)
    try:
        st.start()
        threading.Timer(1.0, fut.set_result, (pipe,)).start()  # the child takes a while
        assert st.wait(120) and st.result is pipe.result
        own = sum(pipe.result.timings.values())
        assert own <= st.compute_seconds < own + 0.9  # not the >= 1 s wait for the child
    finally:
        st.close()


def test_state_computes_itself_when_the_child_gave_nothing(seq):
    fut: Future = Future()
    fut.set_result(None)
    st = _state(seq, fut)
    try:
        st.start()
        assert st.wait(120) and st.error is None
        assert _same(st.result, laav.Pipeline(seq, 2).result)
    finally:
        st.close()


def test_a_request_supersedes_the_wait_and_starts_from_the_warm_pipeline(seq, monkeypatch):
    built = []
    monkeypatch.setattr(state_mod, "Pipeline", lambda *a, **k: built.append(a) or laav.Pipeline(*a, **k))
    fut: Future = Future()
    st = _state(seq, fut)
    try:
        st.start()
        started = threading.Event()
        st.on_busy = lambda busy: started.set()
        gen = st.request(params={"lam": 5.0})  # while the first result is still awaited
        assert gen is not None and started.wait(10)
        fut.set_result(laav.Pipeline(seq, 2))  # the child delivers
        assert st.wait(120) and st.error is None
        assert st.computing.interrupted >= 1 or st.published_generation == gen
        assert not built
        assert st.settings.params.lam == 5.0
        assert _same(st.result, laav.Pipeline(seq, 2, laav.LaavParams(lam=5.0)).result)
    finally:
        st.close()


def test_the_collector_is_held_off_during_start_up_and_resumes_once(monkeypatch):
    """``laav-explore`` holds Python's cyclic collector off while it starts; what the imports
    made is frozen; ``end`` (a page complete, or the timer) lets it run again, once."""
    import gc

    from explorer import cli

    was = gc.isenabled()
    frozen = gc.get_freeze_count()
    held = None
    try:
        gc.enable()
        held = cli._StartupGC()
        assert not gc.isenabled()
        held.imported()
        assert gc.get_freeze_count() > frozen and not gc.isenabled()
        held.end()
        assert gc.isenabled()
        gc.disable()  # a second end() must not turn it back on
        held.end()
        assert not gc.isenabled()
    finally:
        if held is not None:
            held.end()  # (the timer cancelled even when an assertion failed)
        gc.unfreeze()
        (gc.enable if was else gc.disable)()


def test_an_in_process_start_leaves_the_test_sessions_heap_unfrozen(monkeypatch):
    """``main`` run in-process (``fake_serving``) freezes the heap as ``laav-explore`` does;
    the suite's autouse fixture (conftest ``_collector_as_it_was``) undoes it, so a later
    test's garbage is still collected. Checked here on the fixture's own terms: frozen
    during the test, and the fixture's rule releases exactly that."""
    import gc

    from conftest import fake_serving

    from explorer import cli

    fake_serving(monkeypatch)
    assert gc.get_freeze_count() == 0  # the fixture undid every earlier test's freeze
    assert cli.main(["--no-browser", "--port", "5998"]) == 0
    assert gc.get_freeze_count() > 0 and gc.isenabled()  # frozen; the collector back on


def test_a_served_page_once_built_releases_the_held_state(seq):
    """``app_factory(on_built=...)`` (what ``laav-explore`` passes, the hold's ``set``) is
    called once a tab's page has been built, before it is sent."""
    import socket
    import time
    import urllib.request

    import panel as pn

    from explorer.cli import _free_port, app_factory, serve_options

    built, created = threading.Event(), []
    port = _free_port("127.0.0.1")
    server = pn.serve({"/": app_factory(seq, 2, created=created, viser=False, on_built=built.set)},
                      port=port, address="127.0.0.1", websocket_origin=[f"127.0.0.1:{port}"],
                      show=False, threaded=True, verbose=False, **serve_options())
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "the server did not listen"
                time.sleep(0.05)
        assert not built.is_set()
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=60) as r:
            assert r.status == 200 and b"bokeh" in r.read().lower()
        assert built.is_set() and len(created) == 1
    finally:
        server.stop()
        for ex in created:
            ex.close()
