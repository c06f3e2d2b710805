"""Which thread may touch a session's page, and how the explorer's changes reach it: one
batch per change (moved from :class:`explorer.app.Explorer`, whose cards reach it through the
app's :meth:`~explorer.app.Explorer.hold`, :meth:`~explorer.app.Explorer.schedule` and
:attr:`~explorer.app.Explorer.quieted`).

Without a server (a notebook cell before it is shown, the tests) every call runs at once,
under the lock; inside a server session (:meth:`DocumentSession.capture`) work from other
threads goes through the document's event loop.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextlib import contextmanager
from functools import partial

import panel as pn
from panel.io.document import unlocked
from panel.io.state import set_curdoc


def _is_data_event(event) -> bool:
    from bokeh.document.events import ColumnDataChangedEvent, ModelChangedEvent
    from bokeh.models import ColumnDataSource

    return isinstance(event, ColumnDataChangedEvent) or (
        isinstance(event, ModelChangedEvent) and isinstance(event.model, ColumnDataSource)
        and event.attr == "data")


class DocumentSession:
    """A page's document, its thread and the batching of its changes.

    ``fallback_doc``: the document the app's figures belong to when no session was captured
    (a notebook's); ``live``: the app's :class:`~explorer.cards.live.LiveFrames` (the views
    the page makes itself: :meth:`hold`'s ``live``), both as functions (made after this)."""

    def __init__(self, fallback_doc: Callable, live: Callable) -> None:
        self._fallback_doc = fallback_doc
        self._live = live
        self.doc_obj = None  # the server session's document (None: not served)
        self.doc_thread = threading.get_ident()  # the session's event-loop thread
        self._suppress = 0
        self.apply_lock = threading.RLock()
        self.capture()

    @property
    def on_server(self) -> bool:
        """Built in (or adopted by) a server session."""
        return self.doc_obj is not None

    @property
    def quieted(self) -> bool:
        """The app is putting values on widgets (see :meth:`quiet`): callbacks do nothing."""
        return self._suppress > 0

    @contextmanager
    def quiet(self):
        """Widget changes made inside request and redraw nothing."""
        self._suppress += 1
        try:
            yield
        finally:
            self._suppress -= 1

    def doc(self):
        return self.doc_obj or self._fallback_doc()

    def schedule(self, fn, *args, now_if_on_doc_thread: bool = False) -> None:
        """Run ``fn(*args)`` on the document's thread (or now, under a lock, without a server)."""
        doc = self.served_doc()
        on_doc_thread = self.doc_obj is not None and threading.get_ident() == self.doc_thread
        if doc is not None and not (now_if_on_doc_thread and on_doc_thread):
            try:
                doc.add_next_tick_callback(partial(self.locked, fn, *args))
                return
            except Exception:  # the session is gone
                return
        self.locked(fn, *args)

    def locked(self, fn, *args) -> None:
        # panel applies pane changes at once only for the document it is processing
        # (pn.state.curdoc); otherwise it defers them, and a deferred change could land
        # outside our batch
        with self.apply_lock, set_curdoc(self.doc_obj):
            try:
                fn(*args)
            except Exception:
                import traceback
                traceback.print_exc()

    @contextmanager
    def hold(self, freeze: bool = False, live: str | None = None):
        """Send all model changes made inside as one batch (the callers run on the document's
        thread, under its lock).

        Once the page has loaded, the batch goes out as ONE websocket message (panel's
        ``unlocked``): bokeh's own hold sends one message per changed property, and the
        browser applies and redraws each in turn (a frame move was about 12 messages, a
        result about 50; docs/bench/explorer_browser_latency.md). Every batch takes that one
        path: panel writes its message at once, or queues it behind a message bokeh is still
        writing, while bokeh's hold serialises its messages when the change is made and
        writes them later, each after the one before. Mixing the two let a later message
        overtake an earlier one that defined a model it names, and the page failed with
        bokeh's "reference ... isn't known" (an intermittent failure of the browser tests
        under load: pinning A sent through bokeh's hold while the Advanced card's fields went
        through panel's queue; ``test_advanced_and_compare_fit_a_projector`` in
        ``tests/test_explorer_ab_browser.py`` checks the one path). The
        data sources' changes go last in the message, the page's frame views' ``meta`` the
        very last (the page makes those views when it arrives: every template must be in):
        a legend repainted while a glyph's new data was still being mapped read past its old
        colours (bokeh's ``draw_legend_for_index`` threw ``Offset is outside the bounds of the
        DataView`` when a result's legend labels came after its data).

        With ``freeze`` the document's model graph is walked once at the end instead of after
        every change of a model reference (bokeh walks every model of the page after each:
        ~0.07 s). The walk at the end happens whether or not anything changed (0.08 s of a
        0.10 s apply on the demo page), so results on the same sequence, which change no
        reference (text panes keep their style sheets: ``cards.base._TextUpdate``; checked by
        ``tests/test_explorer_styles.py``), are applied without it; a new sequence's are frozen.

        ``live``: the batch draws views the page makes itself (:class:`~.cards.live.LiveFrames`):
        ``"draw"`` (a result, colouring or step: their templates go, the made views' changes
        are dropped) or ``"frame"`` (a frame move: the page has drawn it already; nothing of
        those views is sent, the server's copies just follow)."""
        doc = self.doc()
        if doc is None or doc.session_context is None:
            with self._frozen(doc if freeze else None):
                yield
            return
        if doc.callbacks.hold_value is not None:  # inside another batch (panel's, ours)
            with self._frozen(doc if freeze else None):
                yield
            self._tidy(doc.callbacks._held_events, live)
            return
        if (pn.state.curdoc is doc and pn.state.loaded
                and threading.get_ident() == self.doc_thread and doc.session_context.session is not None):
            with unlocked("combine"):
                try:
                    with self._frozen(doc if freeze else None):
                        yield
                finally:
                    self._tidy(doc.callbacks._held_events, live)
            return
        doc.hold("combine")
        try:
            with self._frozen(doc if freeze else None):
                yield
        finally:
            self._tidy(doc.callbacks._held_events, live)
            doc.unhold()

    def _tidy(self, held, live: str | None) -> None:
        """The held events without those of the views the page makes (``live``, see
        :meth:`hold`), data changes last, the page's ``meta`` the very last."""
        if not held:
            return
        drop = {id(m) for m in self._live().models(frame_move=live == "frame")} if live else set()
        meta = self._live().meta
        kept = [e for e in held if id(getattr(e, "model", None)) not in drop]
        held[:] = sorted(kept, key=lambda e: (_is_data_event(e), getattr(e, "model", None) is meta))

    @staticmethod
    @contextmanager
    def _frozen(doc):
        if doc is None:
            yield
            return
        with doc.models.freeze():
            yield

    def served_doc(self):
        """The page's document when a server serves it (timers run there), else None."""
        doc = self.doc()
        return doc if doc is not None and doc.session_context is not None else None

    def after(self, old, fn, seconds: float):
        """(Document thread.) ``fn()`` (under the lock) in ``seconds``, replacing the timer
        ``old`` (a handle this returned, or None); returns the new handle. Without a server
        ``fn()`` runs now (and None is returned)."""
        doc = self.served_doc()
        if doc is None:
            fn()
            return None
        if old is not None:
            try:
                doc.remove_timeout_callback(old)
            except ValueError:  # it has run already
                pass
        return doc.add_timeout_callback(lambda: self.locked(fn), int(1000 * seconds))

    def capture(self) -> None:
        # Built (or claimed) inside a server session: from now on results go through this
        # document's event loop (the figures join the document while the page is being built,
        # and a worker thread must never touch them during that).
        cur = pn.state.curdoc
        self.doc_obj = cur if cur is not None and cur.session_context is not None else None
        self.doc_thread = threading.get_ident()  # the session's event-loop thread
