"""A change shows LAAV's own fine-tuning first when more is still to compute: the result
with the informed trial alone, then the result. ``laav.Pipeline.update(preview=...)`` makes it;
the state hands it on as ``on_preview``; the app draws it with a status line that says what is
still computing. With plain RV beside LAAV's trial (``LaavParams.with_plain_rv()``, the default
until 2026-12-02): plain RV and the selection. In the default, LAAV's own chain: the
missing-motion starts its gate (``rv_missing_gate``) lets through; when it lets none through
there is nothing to wait for and no preview."""

from __future__ import annotations

import numpy as np
import pytest

import laav
from explorer import Explorer
from explorer.cards.status import PREVIEW_ABANDONED, PREVIEW_OWN, PREVIEW_PLAIN, PREVIEW_STATUS
from explorer.state import ExplorerState
from explorer.views import PREVIEW_NOTE, PREVIEW_NOTE_OWN
from laav.synthetic import make_sequence

SEQ = make_sequence(n_objects=2, n_frames=20, n_points=300, rng=0)
PLAIN = laav.LaavParams.with_plain_rv()


def test_the_state_hands_on_the_preview_before_the_result():
    st = ExplorerState(SEQ, 3, PLAIN, seed=0)
    events = []
    try:
        assert st.wait(120)
        st.on_preview = lambda r, seq, s, gen: events.append(("preview", r, s.seed, gen, st.result))
        st.on_result = lambda r, seq, s, gen: events.append(("result", r, s.seed, gen, st.result))
        before = st.result
        st.request(seed=2)
        assert st.wait(120)
        assert [e[0] for e in events] == ["preview", "result"]
        (_, pre, s1, g1, shown), (_, res, s2, g2, _) = events
        assert s1 == s2 == 2 and g1 == g2
        assert shown is before  # the preview is not the state's result
        assert pre.voting.selected == "informed" and pre.voting.costs == {}
        np.testing.assert_array_equal(pre.voting.informed_changed, res.voting.informed_changed)
        assert st.result is res and st.change_of(pre) is not None
        np.testing.assert_array_equal(res.labels, laav.segment(SEQ, 3, PLAIN, seed=2).labels)
        events.clear()
        st.request(params={"lam": 3.5})  # plain RV's runs are kept: nothing to wait for
        assert st.wait(120) and [e[0] for e in events] == ["result"]
    finally:
        st.close()


@pytest.fixture
def ex():
    e = Explorer(SEQ, 3, PLAIN, viser=False)
    assert e.wait(120)
    yield e
    e.close()


def test_the_app_draws_the_preview_then_the_result(ex):
    seen, exports = [], []
    draw = ex._apply_result

    def spy(result, seq, settings, gen, preview=False):
        draw(result, seq, settings, gen, preview)
        seen.append((preview, ex.status_bar._status_text, ex.rv_md.object, ex.applied_generation,
                     gen, ex.result is result))
        exports.append([w.disabled for w in ex.files.downloads])

    ex._apply_result = spy
    ex.controls.w_seed.value = 2
    assert ex.wait(120)
    assert [p for p, *_ in seen] == [True, False]
    assert exports == [[True] * 3, [False] * 3]  # no export of a preview
    (_, text1, rv1, applied1, gen1, shown1), (_, text2, rv2, applied2, gen2, shown2) = seen
    assert PREVIEW_STATUS in text1 and "seed \\= 2" in text1 and PREVIEW_NOTE in rv1
    assert PREVIEW_PLAIN.split("{ms}")[1] in text1  # plain RV and the selection to come
    assert applied1 < gen1 and shown1  # drawn, but not yet the applied result (wait())
    assert PREVIEW_STATUS not in text2 and "seed \\= 2" in text2 and PREVIEW_NOTE not in rv2
    assert applied2 == gen2 == gen1 and shown2
    assert ex.result.seed == 2 and ex.state.result is ex.result


def test_a_preview_gives_way_to_the_last_result_when_its_result_will_not_come(ex):
    """Cancelled or failed after its preview was drawn: the views go back to the result."""
    shown = ex.result
    got = []
    laav.Pipeline(SEQ, 3, PLAIN).update(seed=4, preview=got.append)
    ex._apply_result(got[0], SEQ, ex.settings.__class__(ex.settings.params, 4, 3),
                     ex.applied_generation + 1, True)
    assert ex.previewing and ex.result is got[0]
    assert PREVIEW_STATUS in ex.status_bar._status_text
    # the exports wait: a preview's labels are not the result's (nor would the files say so)
    assert all(w.disabled for w in ex.files.downloads)
    ex.restore_result()
    assert not ex.previewing and ex.result is shown and ex.state.result is shown
    assert PREVIEW_STATUS not in ex.status_bar._status_text
    assert not any(w.disabled for w in ex.files.downloads)


def test_the_busy_line_does_not_replace_a_previews_line(ex):
    """The spinner's timer often fires just after the preview is drawn: its "Recomputing…
    (the views keep the last result …)" replaced the preview's line, which says what is
    still computing, while the views showed the preview, not the last result."""
    from explorer.cards.status import RECOMPUTING, spinner_style

    got = []
    laav.Pipeline(SEQ, 3, PLAIN).update(seed=4, preview=got.append)
    ex._apply_result(got[0], SEQ, ex.settings.__class__(ex.settings.params, 4, 3),
                     ex.applied_generation + 1, True)
    ex._busy_period = object()  # (a computation running for longer than the spinner waits)
    ex._show_busy(True)
    text = ex.status_bar.status.object
    assert PREVIEW_STATUS in text and RECOMPUTING not in text
    assert ex.status_bar.spinner.styles == spinner_style(True)  # the spinner still turns
    ex.restore_result()  # (no result of that request will come)
    ex._show_busy(True)  # a result shown: the line says it is being recomputed
    assert ex.status_bar.status.object == RECOMPUTING


def test_a_first_computations_preview_stays_a_preview_when_its_result_will_not_come(ex):
    """Cancelled or failed after its preview with no result before it (a sequence's first
    computation): the preview stays, the status line says it is one and that its computation
    did not finish, and the exports and the pin refuse it (its labels are not a result's)."""
    got = []
    laav.Pipeline(SEQ, 3, PLAIN).update(seed=4, preview=got.append)
    ex.state.result = None  # (as before a sequence's first result)
    ex._apply_result(got[0], SEQ, ex.settings.__class__(ex.settings.params, 4, 3),
                     ex.applied_generation + 1, True)
    assert ex.previewing and all(w.disabled for w in ex.files.downloads)
    ex.restore_result()
    assert ex.previewing and ex.result is got[0]
    text = ex.status_bar.status.object
    assert PREVIEW_ABANDONED in text and PREVIEW_STATUS not in text
    assert all(w.disabled for w in ex.files.downloads)
    with pytest.raises(RuntimeError, match="preview"):
        ex.files.export_csv()  # (a click sent before the buttons were disabled)
    assert not ex.compare.pin() and "preview" in ex.compare.pin_md.object
    assert ex.compare.pinned is None


def test_the_default_has_no_preview_when_its_gate_runs_no_start():
    """The default (LAAV's own chain) runs no plain RV: a seed change whose informed trial
    explains the points (the gate lets no missing-motion start through; the demo at seed 3)
    draws the result once."""
    from explorer.demo import demo_sequence

    st = ExplorerState(demo_sequence(), 3, seed=0)
    events = []
    try:
        assert st.wait(120)
        st.on_preview = lambda r, seq, s, gen: events.append("preview")
        st.on_result = lambda r, seq, s, gen: events.append("result")
        st.request(seed=3)
        assert st.wait(120) and events == ["result"]
        assert len(st.result.voting.skipped_starts) == 3
    finally:
        st.close()


def test_the_default_previews_its_informed_trial_while_the_gate_runs_starts(monkeypatch):
    """When the gate lets missing-motion starts through (here: every point judged
    unexplained), a seed change draws LAAV's informed trial first, its status line and RV
    card saying that the trials for a missed motion are still computing, then the result."""
    import laav.own_chain as V

    monkeypatch.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                        np.ones(labels.size, bool))
    e = Explorer(SEQ, 3, viser=False)
    try:
        assert e.wait(120)
        seen, seen_changes, seen_numbers = [], [], []
        draw = e._apply_result

        def spy(result, seq, settings, gen, preview=False):
            draw(result, seq, settings, gen, preview)
            seen.append((preview, e.status_bar._status_text, e.rv_md.object, result))
            seen_changes.append(e.status_bar.change_md.object)
            seen_numbers.append(e.numbers_view.numbers.object)

        e._apply_result = spy
        e.controls.w_seed.value = 2
        assert e.wait(120)
        assert [p for p, *_ in seen] == [True, False]
        (_, text1, rv1, pre), (_, text2, rv2, res) = seen
        assert PREVIEW_OWN.split("{ms}")[1] in text1 and "seed \\= 2" in text1
        assert PREVIEW_NOTE_OWN in rv1 and PREVIEW_NOTE not in rv1
        # the numbers card's "final" row is the trial's so far: said above the table
        numbers1, numbers2 = seen_numbers
        assert numbers1.startswith(PREVIEW_NOTE_OWN) and PREVIEW_NOTE_OWN not in numbers2
        # what changed, so far: the preview's labels are not called final
        change1, change2 = seen_changes
        assert "trial \\(so far\\)" in change1 and "final" not in change1, change1
        assert "final" in change2 and "so far" not in change2, change2
        assert PREVIEW_STATUS not in text2 and PREVIEW_NOTE_OWN not in rv2
        assert pre.voting.selected == "informed" and len(res.voting.trial_iterations) > 1
        np.testing.assert_array_equal(res.labels, laav.segment(SEQ, 3, seed=2).labels)
    finally:
        e.close()


def test_a_preview_of_a_replaced_request_is_not_drawn(ex):
    """A cancel (or a newer request) after a preview was made but before it is drawn: the
    preview is dropped (the cancel's restore found nothing to restore, and its result will
    not come: drawn, it stayed on screen for good)."""
    shown = ex.result
    got = []
    laav.Pipeline(SEQ, 3, PLAIN).update(seed=4, preview=got.append)
    gen = ex.state.generation + 1  # the request the preview answers
    with ex.state._lock:
        ex.state._gen = gen + 1  # ... then cancelled (ExplorerState.cancel)
    ex._apply_result(got[0], SEQ, ex.settings.__class__(ex.settings.params, 4, 3), gen, True)
    assert not ex.previewing and ex.result is shown
    assert PREVIEW_STATUS not in ex.status_bar._status_text
    with ex.state._lock:
        ex.state._gen = gen  # not replaced: drawn
    ex._apply_result(got[0], SEQ, ex.settings.__class__(ex.settings.params, 4, 3), gen, True)
    assert ex.previewing and ex.result is got[0]
    ex.restore_result()
    assert ex.result is shown


def test_the_tour_says_the_missed_motion_trials_are_still_computing(monkeypatch):
    """Tour step 4 on a preview of LAAV's own chain where the gate let one start through and
    skipped the others: it says the trials for a missed motion are still computing, not
    that no search was needed (what it says of the same labels once they are the result)."""
    import laav.own_chain as V
    from explorer.demo import demo_sequence
    from explorer.tour import fine_tuning_facts

    starts = []
    real = V.missing_motion_start
    monkeypatch.setattr(V, "missing_motion_start",
                        lambda *a, **k: starts.append(real(*a, **k)) or starts[-1])
    # only the first start's new motion unexplained (its share near 1 leaves the others out)
    monkeypatch.setattr(V, "unexplained", lambda points, labels, C, params, fits=None:
                        starts[-3] == C - 1)
    seq = demo_sequence()
    params = laav.LaavParams(rv_missing_gate=0.95)
    got = []
    res = laav.Pipeline(seq, 3, params, seed=1, preview=got.append).result
    assert len(got) == 1 and got[0].voting.skipped_starts and len(res.voting.trial_iterations) == 3
    pre = got[0].voting
    said = fine_tuning_facts(seq, pre, None, searching=True)
    assert "still computing" in said and "no search" not in said.lower(), said
    assert "no search for a missed motion needed" in fine_tuning_facts(seq, pre, None)
    e = Explorer(seq, 3, params, viser=False)
    try:
        assert e.wait(120)
        e.tour.start(3)  # step 4: the fine-tuning
        seen = []
        draw = e._apply_result

        def spy(result, seq_, settings, gen, preview=False):
            draw(result, seq_, settings, gen, preview)
            seen.append((preview, e.tour.texts[1]))

        e._apply_result = spy
        e.controls.w_seed.value = 1
        assert e.wait(120)
        assert [p for p, _ in seen] == [True, False], seen
        assert "are still computing" in seen[0][1] and "are still computing" not in seen[1][1]
    finally:
        e.close()


def test_the_exports_wait_for_the_first_result():
    """Before any result the downloads are greyed (a click used to raise "no result yet"
    on the server); the first result shown enables them."""
    e = Explorer(SEQ, 3, PLAIN, viser=False, start=False)
    try:
        assert all(w.disabled for w in e.files.downloads)
        e.start()
        assert e.wait(120) and not e.previewing
        assert not any(w.disabled for w in e.files.downloads)
    finally:
        e.close()
