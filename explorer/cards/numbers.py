"""Card 5 · Final labels and numbers: every stage's error (and plain RV's) against the
ground truth, the parameters and timings."""

from __future__ import annotations

from .. import views as V
from .base import Markdown, card


class NumbersView:
    def __init__(self) -> None:
        self.numbers = Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        self.card = card("5 · Final labels and numbers: every stage against the ground truth",
                         self.numbers)

    def draw(self, seq, res, plain) -> dict:
        """Show the numbers of ``res`` (and of ``plain``, plain RV's run, when there); returns
        them (:func:`views.stage_numbers`)."""
        num = V.stage_numbers(seq, res, plain)
        self.numbers.object = V.numbers_markdown(num)
        return num
