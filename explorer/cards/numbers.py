"""Card 5 · Final labels and numbers: every stage's error (and plain RV's) against the
ground truth, the parameters and timings."""

from __future__ import annotations

from .. import views as V
from .base import Markdown, card

#: Card 5's title with and without ground truth (a sequence without one has no error).
CARD_TITLES = {True: "5 · Final labels and numbers: every stage against the ground truth",
               False: "5 · Final labels and numbers: every stage (no ground truth: no error)"}


class NumbersView:
    def __init__(self) -> None:
        self.numbers = Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        self.card = card(CARD_TITLES[True], self.numbers)

    def draw(self, seq, res, plain, pending: str | None = None) -> dict:
        """Show the numbers of ``res`` (and of ``plain``, plain RV's run, when there); returns
        them (:func:`views.stage_numbers`). ``pending``: ``res`` is a preview, this note
        (e.g. :data:`views.PREVIEW_NOTE_OWN`) said first: its "final" row is LAAV's trial so
        far."""
        num = V.stage_numbers(seq, res, plain)
        title = CARD_TITLES[seq.labels is not None]
        if self.card.title != title:
            self.card.title = title
        self.numbers.object = (pending + "\n\n" if pending else "") + V.numbers_markdown(num)
        return num
