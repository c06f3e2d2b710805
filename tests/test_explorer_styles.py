"""The explorer's text panes keep their style sheets when their text changes.

Panel re-renders a Markdown pane by sending every property of its model, and the style
sheets it computes there differ from those its template's design gives the pane when the
page is built (and again whenever a layout above it changes). The first text change then
swapped every pane's style sheets, and the browser re-styled the whole page: the first
slider move took 2.2-3.8 s in Chromium against 0.5-1.2 s for the next
(explorer/cards/base.py, ``_TextUpdate``).
"""

from __future__ import annotations

import panel as pn
import pytest
from bokeh.document import Document
from panel.io.state import set_curdoc

from explorer.cards.base import HTML, Alert, Markdown


def _model(pane):
    return next(iter(pane._models.values()))[0]


def _page(*panes):
    doc = Document()
    column = pn.Column(*panes)
    with set_curdoc(doc):
        pn.template.BootstrapTemplate(main=[column]).server_doc(doc)
    return doc, column


@pytest.mark.parametrize("kind", [Markdown, Alert])
def test_a_text_change_leaves_the_style_sheets_alone(kind):
    pane = kind("first")
    doc, column = _page(pane)
    model = _model(pane)
    before = list(model.stylesheets)
    with set_curdoc(doc):
        pane.object = "second"
    assert model.text != "" and "second" in model.text
    assert list(model.stylesheets) == before
    with set_curdoc(doc):
        column.append(Markdown("added later"))  # the design is applied to the column again
        after_layout = list(model.stylesheets)
        pane.object = "third"
    assert list(model.stylesheets) == after_layout


@pytest.mark.parametrize("kind", [Markdown, Alert, HTML])
def test_a_text_change_sends_the_text_panel_would(kind):
    """A change of the text alone sends only the text (``_TextUpdate``'s short path), the
    same text panel's full re-render computes; other re-rendering changes (CSS classes) take
    panel's path and reach the model."""
    pane = kind("first **bold** `code` <b>x</b> & [a](https://example.org)")
    doc, column = _page(pane)
    model = _model(pane)
    events = []
    model.on_change("text", lambda attr, old, new: events.append(attr))
    model.on_change("stylesheets", lambda attr, old, new: events.append(attr))
    full = []  # panel's full path (every property computed): not taken for a text change
    real = pane._get_properties
    pane._get_properties = lambda *a, **k: (full.append(1), real(*a, **k))[1]
    with set_curdoc(doc):
        pane.object = "| a | b |\n|---|---|\n| *1* | 2 < 3 |\n\nnext & <i>line</i>"
    assert events == ["text"] and full == []
    del pane._get_properties
    assert model.text == pane._get_properties(doc)["text"] != ""
    with set_curdoc(doc):
        pane.css_classes = ["laav-test"]
    assert "laav-test" in model.css_classes


def test_a_move_toggles_no_layout_property_in_the_main_area(monkeypatch):
    """A slider move (after the first, which shows the "What changed" line) changes no
    ``visible`` or CSS classes in the main area: in the page each such change makes bokeh lay
    out the whole area again, every card's figures (the spinner's value toggled its classes
    twice a move, the progress line its ``visible``: 0.55 s of a 1.07 s move at 5,000 tracks).
    The busy state is shown by inline styles instead (here at once: no BUSY_SHOW_AFTER_S)."""
    import explorer.app
    from explorer import Explorer
    from explorer.demo import demo_sequence

    monkeypatch.setattr(explorer.app, "BUSY_SHOW_AFTER_S", 0.0)
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        ex.w_params["lam"].value = 3.0  # the first change shows the "What changed" line
        assert ex.wait(120)
        changes = []
        watched = [v for obj in ex.main for v in obj.select(pn.viewable.Viewable)]
        # a loading spinner's value is its CSS classes in the page
        watchers = [(v, v.param.watch(lambda e: changes.append((type(e.obj).__name__, e.name)),
                                      ["visible", "css_classes"]
                                      + (["value"] if isinstance(v, pn.indicators.LoadingSpinner) else [])))
                    for v in watched]
        busy = []
        real = ex.status_bar.show_busy
        spins = []  # the spinner turns while shown (busy), is paused while hidden
        ex.status_bar.show_busy = lambda b, h: (busy.append(b), real(b, h),
                                                spins.append(ex.status_bar.spinner.styles["--laav-spin"]))[1]
        ex.files.show_progress(True)  # a long move's progress line, shown and hidden
        ex.files.show_progress(False)
        for lam in (2.5, 3.0):
            ex.w_params["lam"].value = lam
            assert ex.wait(120) and ex.result.params.lam == lam
        for v, w in watchers:
            v.param.unwatch(w)
        assert True in busy and False in busy  # the spinner was shown and hidden
        assert spins == ["running" if b else "paused" for b in busy]
        assert changes == []
    finally:
        ex.close()


def test_a_result_on_the_same_sequence_walks_the_document_graph_no_time():
    """Applying a result on the same sequence changes no model reference, so bokeh never
    walks the page's model graph (a walk is ~0.08 s on the demo page: most of a result's
    apply when it was forced once per result by freezing the graph). A new sequence's
    result is applied frozen: one walk, whatever its cards change."""
    from bokeh.document import Document

    from explorer import Explorer
    from explorer.demo import demo_sequence
    from laav.synthetic import make_sequence

    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        doc = Document()
        ex.panel().server_doc(doc)
        assert ex._doc() is doc
        walks = []
        real = doc.models.recompute
        doc.models.recompute = lambda: (walks.append(1), real())[1]
        for lam in (3.0, 2.5):
            ex.w_params["lam"].value = lam
            assert ex.wait(120) and ex.result.params.lam == lam
        ex.w_seed.value = 5
        assert ex.wait(120) and ex.result.seed == 5
        assert walks == []
        ex.state.load(make_sequence(n_objects=1, n_points=120, n_frames=12, rng=3))
        assert ex.wait(120) and ex.sequence.n_points == 120
        assert len(walks) == 1
    finally:
        ex.close()


def test_a_message_queued_behind_a_finished_dispatch_is_sent():
    """panel's queue race (explorer.app._keep_panel_queue_moving): a message left queued
    with the queue's flag cleared (a dispatch that ended while it was queued) is sent by
    the next dispatch instead of staying queued."""
    import asyncio

    import panel.io.document as pdoc
    from bokeh.document import Document

    import explorer.app  # noqa: F401  (mends the queue on import)

    sent = []

    class Conn:  # a connection whose socket is no tornado handler: panel's other writer
        _socket = object()

    doc = Document()
    pdoc._WRITE_MSGS[doc] = {Conn(): ["a message"]}
    pdoc._WRITE_BLOCK.pop(doc, None)  # the flag a finished dispatch cleared
    real = pdoc.dispatch_django
    pdoc.dispatch_django = lambda conn, msg=None, events=None: (sent.append(msg), [])[1]
    try:
        asyncio.run(pdoc._dispatch_msgs(doc))
    finally:
        pdoc.dispatch_django = real
    assert sent == ["a message"]
    assert doc not in pdoc._WRITE_MSGS and doc not in pdoc._WRITE_BLOCK


def test_foldable_cards_draw_their_arrow():
    """The 3-D and Advanced cards fold; their arrow is stroked with a colour panel's
    Bootstrap design leaves undefined, so each card defines it (the arrow was invisible:
    a folded card looked like a plain title bar; seen in Chromium at 1280x800)."""
    import laav
    from explorer.app import Explorer
    from explorer.cards.base import FOLD_ARROW

    seq = laav.synthetic.make_sequence(1, n_frames=10, n_points=80, rng=0)
    ex = Explorer(seq, viser=False, start=False)
    try:
        for c in (ex.view3d.card, ex.advanced.card):
            assert c.collapsible and FOLD_ARROW in c.stylesheets
        assert "--background-text-color" in FOLD_ARROW
    finally:
        ex.close()


def test_the_spinner_shows_only_for_a_computation_that_lasts(monkeypatch):
    """The status line's spinner and "Recomputing…" show once the state has been busy for
    BUSY_SHOW_AFTER_S, and a busy period that ends sooner changes nothing in the page (each
    change is a message the server writes and the page lays out: three a move, shown at once).
    A second request inside one busy period does not restart its clock."""
    import time

    import explorer.app
    from explorer import Explorer
    from explorer.cards.status import RECOMPUTING
    from explorer.demo import demo_sequence

    # (1 s: the 0.15 s waited below stays well short of it on a loaded machine)
    monkeypatch.setattr(explorer.app, "BUSY_SHOW_AFTER_S", 1.0)
    ex = Explorer(demo_sequence(), viser=False)
    try:
        assert ex.wait(120)
        bar = ex.status_bar
        line, idle_style = bar.status.object, dict(bar.spinner.styles)
        assert idle_style["--laav-spin"] == "paused"
        changes = []
        watchers = [(w, w.param.watch(lambda e: changes.append(e.name), [name]))
                    for w, name in ((bar.spinner, "styles"), (bar.status, "object"))]

        ex._on_busy(True)  # a short computation: over before its time
        ex._on_busy(False)
        time.sleep(2.0)
        assert changes == [] and bar.status.object == line

        ex._on_busy(True)  # a long one: shown once its time has passed, not before
        time.sleep(0.15)
        ex._on_busy(True)  # (a second request: the period's clock runs on)
        assert changes == []
        deadline = time.monotonic() + 10  # (0.15 s after the first: shown once the 1 s passed)
        while bar.status.object != RECOMPUTING and time.monotonic() < deadline:
            time.sleep(0.02)
        assert bar.spinner.styles["--laav-spin"] == "running" and bar.status.object == RECOMPUTING
        ex._on_busy(False)  # ended without a result (a cancel): back to the shown line
        for _ in range(50):
            if bar.status.object == line:
                break
            time.sleep(0.02)
        assert bar.status.object == line and bar.spinner.styles == idle_style
        for w, watcher in watchers:
            w.param.unwatch(watcher)
    finally:
        ex.close()
