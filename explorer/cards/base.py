"""What every card shares: the card and figure builders, sizes, and the app a card talks to.

A card's callbacks never compute: they ask the app (:class:`Host`) to run a redraw on the
document's thread, and draw what the app shows (``host.result``; the algorithm runs in
:class:`~explorer.state.ExplorerState`'s worker).
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
import panel as pn
from bokeh.models import Legend, Range1d
from bokeh.plotting import figure

from .. import views as V

TOOLS = "pan,wheel_zoom,box_zoom,reset,save"
#: Width of the sidebar's widgets (the sidebar is SIDE_W + 35 px wide). With it, every card
#: fits the main area at 1024 px (checked at 1024x768 and 1280x800 in the browser tests).
SIDE_W = 265


class Host(Protocol):
    """The part of :class:`explorer.app.Explorer` the cards use."""

    result: object  # the laav.LaavResult shown (None before the first)
    sequence: object  # the laav.Sequence shown
    settings: object  # the explorer.state.Settings of the result shown
    style: dict  # the points' colours and marks (views.point_style)
    fine_colors: object  # the fine models' colours (views.fine_colors)

    @property
    def frame(self) -> int: ...  # the frame shown

    @property
    def quieted(self) -> bool: ...  # the app is putting values on widgets: callbacks do nothing

    def schedule(self, fn, *args, now_if_on_doc_thread: bool = False) -> None: ...

    def hold(self, freeze: bool = False, live: str | None = None):
        ...  # context manager: the model changes inside go out as one batch (live: see Explorer.hold)

    def restore_result(self) -> None: ...  # a preview shown gives way to the last result

    def touch(self) -> None: ...  # a person moved a view control (no computation ahead now)

    def complete_page(self) -> None: ...  # the later cards onto the page now (the tour, a pin)

    def show_notes(self, *lines) -> None: ...  # the page's note: these lines and the data's

    def origin_of(self, seq): ...  # how seq came from its file (explorer.state.Origin)

    def add_origin(self, seq, origin) -> None: ...


def _same(a, b) -> bool:
    try:
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and (a.dtype == b.dtype or a.dtype.kind in "UO" and b.dtype.kind in "UO"
                                       or a.dtype.kind in "fiub" and b.dtype.kind in "fiub") \
            and bool(np.array_equal(a, b, equal_nan=a.dtype.kind == "f" and b.dtype.kind == "f"))
    except (TypeError, ValueError):
        return False


def set_data(src, data: dict) -> list[str]:
    """Put ``data`` on the ColumnDataSource ``src``, sending the browser only what changed.

    Columns equal to the ones shown are not sent at all; when the row count is the same
    only the changed columns go out (``data.update``: bokeh sends just those); a new row
    count replaces the whole data. Returns the names of the columns sent (empty: nothing
    changed, nothing was sent)."""
    old = src.data
    if set(old) != set(data):
        src.data = dict(data)
        return list(data)
    n_old = {len(v) for v in old.values()}
    n_new = {len(v) for v in data.values()}
    if n_old != n_new or len(n_new) > 1:
        src.data = dict(data)
        return list(data)
    changed = {k: v for k, v in data.items() if not _same(old[k], v)}
    if changed:
        src.data.update(changed)
    return list(changed)


class _TextUpdate:
    """A text pane whose re-render sends its text, not its style sheets.

    Panel re-renders an HTML / Markdown pane by sending every property of its model
    (``HTMLBasePane._update``), the style sheets included, and computes them there
    differently from its template's design, which sets them when the page is built and
    again whenever a layout above the pane changes: the pane's first text change after
    either swapped its style sheets, and the browser then re-styled the whole page. The
    explorer's first slider move took 2.2-3.8 s in Chromium against 0.5-1.2 s for the
    next, 1.4 s of it computed-style reads. The explorer never changes a text pane's style
    sheets itself, so its panes keep the design's.

    A change of the text alone (``object``, what the cards change) sends the new text
    without computing the other properties: panel's way (every property, the design's
    style sheets made anew as models, then dropped here) was half of a result's apply on
    the server (demo, R1 move: 27 of 47 ms for its seven text changes, in-process profile)."""

    def _update_pane(self, *events) -> None:
        self._text_only = all(e.name == "object" for e in events)
        try:
            super()._update_pane(*events)
        finally:
            self._text_only = False

    def _update(self, ref, model) -> None:
        if getattr(self, "enable_streaming", False):  # (not used here) panel's own path
            return super()._update(ref, model)
        if getattr(self, "_text_only", False) and self._rename.get("object", "text") == "text":
            model.update(text=self._transform_object(self.object)["object"])
            return
        props = self._get_properties(model.document)
        props.pop("stylesheets", None)
        model.update(**props)


class Markdown(_TextUpdate, pn.pane.Markdown):
    """``pn.pane.Markdown`` whose text changes leave its style sheets alone (:class:`_TextUpdate`)."""


class HTML(_TextUpdate, pn.pane.HTML):
    """``pn.pane.HTML`` whose text changes leave its style sheets alone (:class:`_TextUpdate`)."""


class Alert(_TextUpdate, pn.pane.Alert):
    """``pn.pane.Alert`` whose text changes leave its style sheets alone (:class:`_TextUpdate`)."""


def page_box(js: str, value: str = "", args: dict | None = None) -> pn.widgets.TextInput:
    """A hidden text box through which the server hands the page a value: ``js`` runs in the
    page (``cb_obj`` the box) whenever the server changes it (the tab's title, the address,
    the upload box's reports)."""
    box = pn.widgets.TextInput(value=value, visible=False, margin=0, width=0)
    box.jscallback(args=args or {}, value=js)
    return box


def shown_style(shown: bool, keep_space: bool = False) -> dict:
    """Inline ``styles`` that show or hide a part of the page without a layout change.

    Bokeh lays out a whole page area again, every card's figures, when a part's ``visible``
    or CSS classes change (0.2-0.5 s in Chromium for the main area, up to four times a move);
    an inline style it just applies, and the browser reflows. ``keep_space``: hidden by
    opacity, keeping its place (a spinner in a line of text); else by ``display: none``
    (shown again by removing the inline display: the layout's own applies)."""
    if keep_space:
        return {"opacity": "1" if shown else "0"}
    return {"display": None if shown else "none"}


#: A foldable card's arrow is stroked with ``--background-text-color``, which panel's
#: Bootstrap design leaves undefined: the arrow was invisible (a folded card looked like a
#: plain title bar). Set on the card's own root, so its widgets keep their own colours.
FOLD_ARROW = ":host { --background-text-color: var(--bs-body-color, #212529); }"


#: The card titles' own stylesheet: bold, as the first page draws them. panel's Card writes
#: its title as an ``<h3>`` in a pane of its own, which inherits the card header's bold; when
#: the title changes in a live page (the Numbers and Seed sweep cards retitle themselves for a
#: sequence without ground truth, the tour renames a card) the pane is drawn again with the
#: template's Bootstrap sheet inside it, whose ``h3`` is 500, and the title turned light.
TITLE_CSS = "h3 { font-weight: 700; }"


class TitledCard(pn.Card):
    """A :class:`panel.Card` whose title stays bold when it changes (:data:`TITLE_CSS`): the
    title is drawn by a header pane of its own, with that sheet, rewritten at every change of
    ``title`` (read and set as for any card)."""

    def __init__(self, *objs, title: str = "", **kw):
        self._title_pane = pn.pane.HTML(_title_html(title), css_classes=["card-title"], margin=(5, 0),
                                        stylesheets=[TITLE_CSS])
        super().__init__(*objs, title=title, header=self._title_pane, **kw)
        self.param.watch(self._retitle, "title")

    def _retitle(self, event) -> None:
        self._title_pane.object = _title_html(event.new)


def _title_html(title: str) -> str:
    import html

    return f"<h3>{html.escape(title, quote=False)}</h3>" if title else "&#8203;"


def card(title: str, *objs, **kw) -> pn.Card:
    kw.setdefault("sizing_mode", "stretch_width")
    return TitledCard(*objs, title=title, collapsible=False, margin=(6, 6), **kw)


def flex(*objs, **kw) -> pn.FlexBox:
    """Parts side by side while they fit, wrapped below each other when not."""
    kw.setdefault("sizing_mode", "stretch_width")
    return pn.FlexBox(*objs, flex_wrap="wrap", align_items="flex-start", **kw)


def image_figure(title: str, frame_width: int, extent, **kw):
    """A bokeh figure in pixel coordinates with the y axis pointing down, showing
    ``extent`` (x0, x1, y0, y1) with a margin (:func:`explorer.views.view_extent`)."""
    x0, x1, y0, y1 = V.view_extent(extent)
    fh = int(round(frame_width * (y1 - y0) / max(x1 - x0, 1e-9)))
    kw.setdefault("toolbar_location", "right")
    kw.setdefault("tools", TOOLS)
    fig = figure(title=title, frame_width=frame_width, frame_height=max(fh, 80),
                 x_range=Range1d(x0, x1), y_range=Range1d(y1, y0), match_aspect=True, **kw)
    fig.toolbar.logo = None  # (bokeh's coloured logo: beside the motion colours, noise)
    fig.xaxis.axis_label = "x (px)"
    fig.yaxis.axis_label = "y (px, pointing down)"
    fig.title.text_font_size = "11pt"
    return fig


def fit_image_figure(fig, extent) -> None:
    """Point an :func:`image_figure` at another sequence's pixel extent (same frame width)."""
    x0, x1, y0, y1 = V.view_extent(extent)
    fig.x_range.start, fig.x_range.end = x0, x1
    fig.y_range.start, fig.y_range.end = y1, y0
    # the reset tool's view too (bokeh keeps the first ranges a plot was drawn with otherwise)
    fig.x_range.reset_start, fig.x_range.reset_end = x0, x1
    fig.y_range.reset_start, fig.y_range.reset_end = y1, y0
    fw = fig.frame_width
    fig.frame_height = max(int(round(fw * (y1 - y0) / max(x1 - x0, 1e-9))), 80)


def move_legend(fig) -> None:
    """The figure's legend to its right, small, click to hide an entry."""
    leg = fig.legend[0]
    fig.renderers  # noqa: B018 (legend already built)
    fig.center = [c for c in fig.center if not isinstance(c, Legend)]
    leg.location = "top_left"
    leg.label_text_font_size = "9pt"
    leg.spacing = 0
    leg.padding = 4
    leg.click_policy = "hide"
    fig.add_layout(leg, "right")
