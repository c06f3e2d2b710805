"""The page's messages: the header's sequence name (and the browser tab's title), the status
line with its spinner, what the last recompute changed, and the alerts (errors, notes, a
shared address's unusable settings)."""

from __future__ import annotations

import panel as pn

import laav

from .. import views as V
from .base import Alert, Markdown, page_box, shown_style

#: What the status line says while a preview is shown (``ExplorerState.on_preview``);
#: a browser benchmark waits for the result by its absence. The line says what is still
#: computing: plain RV and the selection (:data:`PREVIEW_PLAIN`) or, in LAAV's own chain, the
#: missing-motion starts (:data:`PREVIEW_OWN`).
PREVIEW_STATUS = "still computing…"
PREVIEW_PLAIN = "LAAV's own fine-tuning in {ms} ms; plain RV and the model selection " + PREVIEW_STATUS
#: The "What changed" line's name for a preview's labels (the final ones still to come).
PREVIEW_FINAL = "LAAV's trial (so far)"
PREVIEW_OWN = ("LAAV's informed trial after {ms} ms; the trials for a missed motion (ours) "
               + PREVIEW_STATUS)
#: What replaces :data:`PREVIEW_STATUS` when the computation a preview came from was cancelled
#: or failed before any result (:meth:`StatusBar.preview_abandoned`).
PREVIEW_ABANDONED = ("its computation did not finish: a preview, not a result (change a setting "
                     "to compute one)")


RECOMPUTING = "Recomputing… (the views keep the last result until the new one is ready)"

#: The "What changed" line before there is a change to tell (the first result, a new
#: sequence): an empty line of the same height. Hidden by ``display: none`` instead, its
#: 41 px came and went, and every card below moved by as much when a change first showed.
NO_CHANGE = "&nbsp;"
#: That line's paragraph without its own margins (a line of type each, above and below): the
#: room it keeps is one line high.
TIGHT_LINE = ":host p { margin: 0.2em 0; }"


#: The status line's paragraph keeps two lines of room, at any width: it wraps at a projector's
#: 1024 px once settings are off their defaults ("Not at the defaults: R1 = 22, ..."), and at
#: 1280 px for a preview's longer line ("LAAV's informed trial after N ms; the trials for a
#: missed motion (ours) still computing…"), and every card below moved down by a line (17 px)
#: when it did, and back up when the result's shorter line came. A line of three (a long
#: list of settings at 1024 px) still moves them. Without the paragraph's own margins (a line
#: of type above and below, as :data:`TIGHT_LINE`): with them and the two lines kept, the
#: first page had a blank band of 70 px between its one line of status and card 1.
STATUS_ROOM = ":host p { min-height: 2lh; margin: 0.2em 0; }"


def header_text(seq: laav.Sequence) -> str:
    return f"{V.md_text(seq.name)} · {seq.n_points} points, {seq.n_frames} frames"


#: The loading spinner's turn (panel's ``:host(.loader.spin) div::after`` animation) follows
#: an inline custom property, so that hiding the spinner pauses it without a class change
SPIN_PAUSABLE = ":host div::after { animation-play-state: var(--laav-spin, running) !important; }"


#: The address box's page side: the query into the address bar after the next paint.
JS_ADDRESS = """
const search = cb_obj.value || '';
const write = () => setTimeout(() => {
  if (cb_obj.value === search && window.location.search !== search)
    window.history.replaceState(window.history.state, '',
                                window.location.pathname + search + window.location.hash);
}, 0);
// after the next paint; a hidden tab paints no frame: at once
if (document.hidden) write(); else requestAnimationFrame(write);
"""


def spinner_style(busy: bool) -> dict:
    """The spinner's inline styles: shown and turning while busy, else hidden and paused."""
    return {**shown_style(busy, keep_space=True), "--laav-spin": "running" if busy else "paused"}


class StatusBar:
    def __init__(self, seq: laav.Sequence) -> None:
        self.alert = Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                           margin=(4, 6))
        self.note = Alert("", alert_type="info", visible=False, sizing_mode="stretch_width",
                          margin=(4, 6))
        # no ground truth, and LAAV and plain RV far apart (views.disagreement_warning)
        self.check_alert = Alert("", alert_type="warning", visible=False, sizing_mode="stretch_width",
                                 margin=(4, 6))
        # problems with the settings a shared URL carried (kept until the next URL)
        self.url_alert = Alert("", alert_type="warning", visible=False, sizing_mode="stretch_width",
                               margin=(4, 6))
        # always "spinning" (a change of its value is one of its CSS classes), shown and hidden
        # by its opacity (its own style sheet overrides visibility; see shown_style), its
        # animation paused while hidden by an inline custom property (SPIN_PAUSABLE): a hidden
        # spinner that kept turning kept the browser's compositor drawing 60 frames a second
        self.spinner = pn.indicators.LoadingSpinner(value=True, size=22, margin=(8, 6),
                                                    styles=spinner_style(True),
                                                    stylesheets=[SPIN_PAUSABLE])
        self._status_text = "Computing the first result…"
        self.status = Markdown(self._status_text, margin=(4, 6),
                               sizing_mode="stretch_width", stylesheets=[STATUS_ROOM])
        # an empty line until the first change (NO_CHANGE): its place is kept, so the
        # cards below stay where they are when it is filled
        self.change_md = Markdown(NO_CHANGE, margin=(0, 10), sizing_mode="stretch_width",
                                  stylesheets=[TIGHT_LINE])
        # the sequence shown, in the page header (the template's own title is fixed at load)
        # the browser tab's title follows the sequence shown (bokeh's document title is sent
        # once, with the page): a hidden box whose value the page copies into document.title
        self.tab_title = page_box("document.title = cb_obj.value")
        # the page address carries the state shown (Explorer._sync_url): a hidden box whose
        # value the page puts in the address bar with replaceState once the views are drawn
        # (after the next paint: off the redraw's path; panel's Location did a pushState
        # inside it, about 25 ms of the page's main thread a move in Chromium, and sent the
        # new address back to the server). A change of settings is not a new history entry
        # (Back leaves the page, as it would have: nothing restored the state on Back).
        # (its first value is none a query can be: the first result's address, "" too, is
        # then a change the page acts on, cleaning an address of keys that were not used)
        self.address = page_box(JS_ADDRESS, value="(not set)")
        self.header_name = Markdown(header_text(seq), margin=(0, 10),
                                    styles={"color": "white", "font-size": "1.25em"})
        self.line = pn.Column(pn.Row(self.spinner, self.status, sizing_mode="stretch_width"), self.change_md,
                              sizing_mode="stretch_width")

    def show_sequence(self, seq: laav.Sequence) -> None:
        self.header_name.object = header_text(seq)
        self.tab_title.value = f"LAAV explorer: {laav.safe_name(seq.name)}"  # the browser tab

    def show_reading(self, name: str) -> None:
        self.status.object = f"Reading {V.md_text(name)}…"

    def end_reading(self) -> None:
        """A read that failed: back to what is shown."""
        if self.status.object.startswith("Reading "):
            self.status.object = self._status_text

    def show_last(self) -> None:
        """Back to the shown result's status line (after a cancelled read or computation)."""
        self.status.object = self._status_text

    def preview_abandoned(self) -> None:
        """The preview shown stays, with no result behind it (the first computation of a
        sequence cancelled or failed after its preview): the line says so instead of
        "still computing"."""
        self.status.object = self._status_text = self._status_text.replace(PREVIEW_STATUS,
                                                                           PREVIEW_ABANDONED)

    def show_error(self, message: str) -> None:
        # settings and files alike ("empty.mat is empty (0 bytes)" is no setting)
        self.alert.object = f"**Not used:** {V.md_text(message)}"
        self.alert.visible = True

    def show_busy(self, busy: bool, has_result: bool) -> None:
        style = spinner_style(busy)
        if self.spinner.styles != style:  # (an idle bar stays as it is: nothing sent)
            self.spinner.styles = style
        if busy and has_result:
            self.status.object = RECOMPUTING
        elif not busy and self.status.object == RECOMPUTING:
            # the work ended without a new result (an error, a cancel): the shown one's line
            self.status.object = self._status_text

    def show_note(self, note: str) -> None:
        self.note.object = note
        self.note.visible = bool(note)

    def show_check(self, num: dict) -> None:
        """The warning of :func:`views.disagreement_warning` for the numbers ``num`` shown
        (hidden when there is none)."""
        text = V.disagreement_warning(num) or ""
        if self.check_alert.object != text:
            self.check_alert.object = text
        if self.check_alert.visible != bool(text):
            self.check_alert.visible = bool(text)

    def show_url_problems(self, problems: list[str]) -> None:
        self.url_alert.object = ("" if not problems else "**Some settings in the page address were not "
                                 "used:** " + "; ".join(V.md_text(m) for m in problems))
        self.url_alert.visible = bool(problems)

    def show_result(self, seq, error_final, compute_seconds: float, changed: list[str], change,
                    ahead: str | None = None, preview: bool = False, own: bool = False) -> None:
        """The status line for a shown result (``changed``: the settings off their defaults)
        and what moved since the last (``change``: :class:`state.Change` or None); ``ahead``:
        how it was computed before it was asked for (``"ahead, while idle"``, ``"by the seed
        sweep"``: :meth:`ExplorerState.computed_ahead`), or None; ``preview``: a preview's
        line, with ``own`` of LAAV's own chain (:data:`PREVIEW_OWN`)."""
        err = "" if error_final is None else f" — final error **{100 * error_final:.1f} %**"
        if preview:  # LAAV's own trial first (ExplorerState.on_preview)
            err = "" if error_final is None else f" — error **{100 * error_final:.1f} %**"
            how = (PREVIEW_OWN if own else PREVIEW_PLAIN).format(ms=f"{1000 * compute_seconds:.0f}")
        else:
            how = f"computed in {1000 * compute_seconds:.0f} ms{', ' + ahead if ahead else ''}"
        self.status.object = self._status_text = (
            f"Showing {V.md_text(seq.name)}{err} ({how}). "
            + (f"Not at the defaults: {V.md_text(', '.join(changed))}." if changed
               else "All settings at their defaults."))
        # (a preview's labels are LAAV's trial's so far, not the final labels)
        named = PREVIEW_FINAL if preview else "final"
        self.change_md.object = (NO_CHANGE if change is None else
                                 f"**What changed:** {V.md_text(change.text(named))}")
