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

from explorer.cards.base import Alert, Markdown


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
