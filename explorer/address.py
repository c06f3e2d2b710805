"""The page address and params.json: the state a link or an exported file carries, taken in
and given out (issue 13, item 8; moved from :class:`explorer.app.Explorer`). ``host`` is the
app: its computation state, controls, tour, status bar and the sequence and result shown.

A page URL's query names settings by :class:`laav.LaavParams` field plus ``seed``, ``motions``,
``frame``, ``color`` (and ``tour``, ``sequence``: :data:`explorer.state.URL_KEYS`); the
address follows every change (:meth:`PageAddress.sync`); a link's unusable values are named
in a warning that stays until the page moves on from that link.
"""

from __future__ import annotations

import urllib.parse
from pathlib import Path

import panel as pn

from . import views as V
from .state import params_file_note, parse_settings, query_of, settings_from_json

#: Markers of :attr:`PageAddress.problems_at` for a link to a tour step: its tour not yet
#: seen running, and running.
_TOUR_LINK, _TOUR_RUNNING = object(), object()


class PageAddress:
    """The page's address and params.json for the app ``host``; ``first_sequence``: the one a
    new page starts with (the address names another when it is shown)."""

    def __init__(self, host, first_sequence) -> None:
        self.host = host
        self.first_sequence = first_sequence
        #: after a link with unusable values, whose warning stays until the page moves on:
        #: the query of the state the link asked for (:meth:`_forget_problems`; for a link
        #: to a tour step, _TOUR_LINK / _TOUR_RUNNING until its tour ends); None: no warning
        self.problems_at: dict | object | None = None
        self.params_note = None  # (generation, text): about a params.json, with its result

    def note_for(self, gen: int) -> str | None:
        """The params.json note to show with the result of request ``gen`` (None: none)."""
        return V.md_text(self.params_note[1]) if self.params_note and self.params_note[0] == gen else None

    def apply_query(self, pairs: dict) -> list[str]:
        """Take the settings and view a page URL's query carries (see :data:`state.URL_KEYS`).

        Every value is validated (:func:`state.parse_settings`); what cannot be used is
        listed in a warning on the page, as text, and the rest is applied. Before
        :meth:`explorer.app.Explorer.start` the first computation uses them; afterwards they are requested."""
        h = self.host
        pairs = {k: v for k, v in pairs.items() if not str(k).startswith("bokeh")}
        if not pairs:
            return []
        new, view, problems = parse_settings(pairs, h.sequence, h.state.target)
        if not h.state._started:
            h.state.retarget(new)
        else:
            h.state.request(params=new.params.to_dict(), seed=new.seed, n_motions=new.n_motions)
        h.controls.show_settings(new)
        if "color" in view:
            h.controls.set_color_mode(view["color"])
        if "frame" in view:
            h.controls.w_frame.value = view["frame"]
        if "tour" in view:  # on a served page once it is on screen (the tour's keys and
            step = view["tour"] - 1  # sidebar fold run in the page's own script)
            if h.session.on_server:
                pn.state.onload(lambda: h.tour.start(step))
            else:
                h.tour.start(step)
        h.status_bar.show_url_problems(problems)
        # the link's state, as the page asks for it (see _forget_problems); a link to a
        # tour step: the state once its tour has ended (the steps set their own colourings)
        self.problems_at = None
        if problems:
            self.problems_at = _TOUR_LINK if "tour" in view else self.query(asked=True)
        return problems

    def query(self, asked: bool = False) -> dict[str, str]:
        """The URL query of what the page shows now (only what differs from the defaults);
        ``asked``: with the settings asked for last (the state's target) instead of those
        of the result shown."""
        h = self.host
        seq = h.sequence
        return query_of(h.state.target if asked else h.state.settings,
                        h.state.default_motions(), h.frame,
                        h.controls.color_mode, h._default_color(),
                        h.tour.step if h.tour.active else None,
                        None if seq is self.first_sequence else seq.name)

    def sync(self) -> None:
        """(Document thread.) The page address carries the shown state (no reload; the page
        writes it once the views are redrawn: :attr:`StatusBar.address`)."""
        h = self.host
        if h.result is None:
            return
        self._forget_problems()
        if h.session.on_server:
            q = self.query()
            h.status_bar.address.value = "?" + urllib.parse.urlencode(q) if q else ""

    def _forget_problems(self) -> None:
        """The warning about a link's unusable values stays until the page moves on from
        that link: hidden once the state asked for (settings, frame, colouring, sequence)
        differs from the link's (it stayed for good, beside a page long changed)."""
        h = self.host
        at = self.problems_at
        if at is _TOUR_LINK or at is _TOUR_RUNNING:  # a link to a tour step
            if h.tour.active:
                self.problems_at = _TOUR_RUNNING
            elif at is _TOUR_RUNNING:  # its tour ended: the page as the tour left it
                self.problems_at = self.query(asked=True)
            return
        if at is not None and self.query(asked=True) != at:
            self.problems_at = None
            h.status_bar.show_url_problems([])

    def load_params(self, data: bytes | str, filename: str = "params.json") -> bool:
        """Apply a params.json (as exported here). False, and a message, when it is not valid."""
        h = self.host
        name = Path(filename).name
        try:
            new = settings_from_json(data, h.sequence, h.state.target)
        except ValueError as exc:
            h.state.report(f"{name}: {exc} — nothing was changed")
            return False
        note = params_file_note(data, h.sequence, new, name)  # exported for another sequence
        h.schedule(h.controls.show_settings, new)
        gen = h.state.request(params=new.params.to_dict(), seed=new.seed, n_motions=new.n_motions)
        if gen is not None and note:
            self.params_note = (gen, note)  # shown with that request's result
            if gen == h.applied_generation:  # nothing to recompute: shown now
                h.schedule(self.show_params_note)
        return gen is not None

    def show_params_note(self) -> None:
        """(Document thread.) The params.json note, with the page's other notes, when its
        settings needed no new result."""
        h = self.host
        if self.params_note and self.params_note[0] == h.applied_generation:
            h.show_notes(V.md_text(self.params_note[1]))
