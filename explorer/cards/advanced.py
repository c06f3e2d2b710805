"""The sidebar's Advanced card: every :class:`laav.LaavParams` field, grouped by stage,
and two presets in one click (:data:`PRESETS`: ``paper`` and ``with-plain-rv``, named as the
status line names them).

Folded at first. One widget per field (:data:`explorer.fields.FIELDS`): a number box (its
bounds in its tooltip; the state checks them), a select for a choice (``coarse_merge``, ``atom_frames``,
``rv_select``), a checkbox for a switch; its tooltip is the field's description from the
``LaavParams`` docstring, its range and its default. A field off its default is marked
(``● name · default X``). A change only requests (:meth:`ExplorerState.request`, which
validates through ``LaavParams``): an invalid value is named in the card and in the page's
alert, and the last good result stays. The card always shows the settings asked for last
(:attr:`ExplorerState.target`, through the state's ``on_target`` hook), so the sliders, a
URL, a ``params.json`` and the reset buttons move it too; its own changes move the sliders
(:meth:`Controls.show_settings`).
"""

from __future__ import annotations

import math
from functools import partial

import panel as pn

from laav import LaavParams

from .. import views as V
from ..fields import AUTO, FIELDS, STAGE_TITLES, changed_fields, fmt_value, widget_value
from .base import FOLD_ARROW, SIDE_W, Alert, Host, Markdown

#: The presets the card sets in one click: LaavParams constructor -> (the preset's name, as
#: the status line and the What changed line say it, ``preset = with-plain-rv``, and as
#: ``laav-explore --preset`` takes it: :data:`laav.params.PRESETS`; what it is, the button's
#: tooltip, one short line: a tooltip does not wrap, and the card's text says more). The
#: button says the name: it said "Preset: ours + plain RV", the status line "with-plain-rv",
#: not to be told for the same thing.
PRESETS = {
    "paper": ("paper", "LaavParams.paper(): the paper's stages, nothing of ours"),
    "with_plain_rv": ("with-plain-rv", "LaavParams.with_plain_rv(): ours + plain RV"),
}
#: Width of a field's widget inside the card (the card's padding and border fit the sidebar).
FIELD_W = SIDE_W - 30
#: Marks a field off its default, in its label.
MARK = "●"


def preset_label(name: str) -> str:
    """A preset button's label: the preset as the status line names it."""
    return f"Set preset = {name}"


def _step(default) -> float:
    """A number box's arrow step: a tenth of the default's order of magnitude (0.1 for 0):
    1 for R1 = 20, 0.1 for λ = 2, 0.01 for 0.25."""
    d = abs(float(default or 0))
    return 0.1 if d == 0 else 10.0 ** (math.floor(math.log10(d)) - 1)


def label_of(field, value) -> str:
    """The widget's label: the field name, marked with its default when ``value`` differs."""
    if value == field.default:
        return field.name
    return f"{MARK} {field.name} · default {fmt_value(field.default)}"


class AdvancedPanel:
    """Every LaavParams field for ``state``; ``controls`` are the sidebar's sliders (kept in step)."""

    def __init__(self, host: Host, state, controls) -> None:
        self.host, self.state, self.controls = host, state, controls
        p = state.target.params
        self._params = p  # the parameters shown (what the fields hold when they are built)
        self._widgets: dict | None = None  # built when first opened or read (:attr:`widgets`)
        # (stretched up to FIELD_W, not FIELD_W wide: with a fixed width the text took the whole
        # width inside the box's padding and ran past its right edge)
        self.message = Alert("", alert_type="danger", visible=False, sizing_mode="stretch_width",
                             max_width=FIELD_W, margin=(4, 5))
        self.summary = Markdown("", width=FIELD_W, margin=(0, 5), styles={"font-size": "0.9em"})
        self.w_reset = pn.widgets.Button(label="Reset every field to its default", color="warning",
                                         width=FIELD_W, margin=(8, 5))
        self.w_reset.on_click(self._on_reset)
        # the presets (laav.LaavParams): compare ours with the paper's stages by pinning one
        self.w_presets = {}
        for name, (preset, tip) in PRESETS.items():
            b = pn.widgets.Button(label=preset_label(preset), description=tip, color="light",
                                  width=FIELD_W, margin=(2, 5))
            b.on_click(partial(self._on_preset, name))
            self.w_presets[name] = b
        self.intro = Markdown(
            "Every `LaavParams` field (hover the **?** for its meaning, range and default); a field "
            f"off its default is marked {MARK}. Seed and C stay in the sliders above. The presets "
            "set every field, and the status line then says `preset = NAME`: `paper` "
            "(`LaavParams.paper()`, each stage as the paper writes it) and `with-plain-rv` "
            "(`LaavParams.with_plain_rv()`, ours with plain RV beside LAAV's trial and a selection: "
            "an earlier default, behind the current one on clean tracks, ahead of it under pixel "
            "noise, README); pin a result first (Compare) to see what changes.",
            width=FIELD_W, margin=(0, 5), styles={"font-size": "0.9em"})
        # folded, the card holds nothing: its ~130 models (a third of the sidebar's) go to the
        # page when it is first opened, not with the page (served and built that much sooner);
        # its ~30 fields are not even made until then (about a sixth of building the explorer)
        self.card = pn.Card(title="Advanced: every parameter", collapsed=True, collapsible=True,
                            sizing_mode="stretch_width", margin=(6, 10), stylesheets=[FOLD_ARROW])
        self.card.param.watch(self._on_unfold, "collapsed")
        self._mark(p)

    @property
    def widgets(self) -> dict:
        """``{field name: widget}`` of every LaavParams field, made when first asked for (the
        card's first opening): holding the parameters shown last."""
        if self._widgets is None:
            widgets, rows, stage, p = {}, [], None, self._params  # (one snapshot of the settings)
            for f in FIELDS:
                if f.stage != stage:
                    stage = f.stage
                    rows.append(Markdown(f"**{STAGE_TITLES[stage]}**", margin=(8, 5, 0, 5)))
                w, row = self._widget(f, getattr(p, f.name))
                w.param.watch(partial(self._on_field, f), "value")
                widgets[f.name] = w
                rows.append(row)
            self._rows = rows
            self._widgets = widgets
        return self._widgets

    @property
    def body(self) -> list:
        """What the card holds once opened."""
        self.widgets  # noqa: B018 - made now
        return [self.intro, self.summary, self.message, *self.w_presets.values(), *self._rows,
                self.w_reset]

    def _on_unfold(self, event) -> None:
        """The card's fields go to the page the first time it is opened."""
        if not event.new and not self.card.objects:
            self.card.objects = self.body

    @staticmethod
    def _widget(f, value):
        """The widget of field ``f`` and what goes in the card (the widget, or a checkbox
        with its tooltip icon beside it)."""
        tip = V.md_text(f.tooltip())  # rendered as Markdown: every character literal
        if f.kind == "bool":
            w = pn.widgets.Checkbox(label=label_of(f, value), value=bool(value), width=FIELD_W - 30,
                                    margin=(6, 5))
            return w, pn.Row(w, pn.widgets.TooltipIcon(value=f.tooltip(), margin=(4, 0)), margin=0)
        if f.kind == "choice":
            w = pn.widgets.Select(label=label_of(f, value), options=list(f.choices), value=value,
                                  description=tip, width=FIELD_W, margin=(4, 5))
            return w, w
        # no bounds on the box: the page's box neither clamps nor sends a value past them (it
        # showed the value and nothing happened); LaavParams refuses it, named in the card
        kw = dict(label=label_of(f, value), value=value, description=tip, width=FIELD_W, margin=(4, 5))
        auto = f"auto ({AUTO.get(f.name, 'auto')})" if f.kind.endswith("|None") else ""
        if f.kind in ("int", "int|None"):
            # a number box, not panel's integer box: that one drops what is not a digit as it
            # is typed ("2.5" became 25); a fraction reaches LaavParams, which refuses it
            w = pn.widgets.FloatInput(step=1, placeholder=auto, **kw)
        else:
            w = pn.widgets.FloatInput(step=_step(f.default), placeholder=auto, **kw)
        return w, w

    # ------------------------------------------------------------------ widgets -> request
    def _on_field(self, field, event) -> None:
        if self.host.quieted:
            return
        self.request({field.name: widget_value(field, event.new)})

    def request(self, changes: dict) -> bool:
        """Ask for ``changes`` (LaavParams fields). False, and the message in the card, when
        ``LaavParams`` refuses them (nothing else changes; the last good result stays)."""
        if self.state.request(params=changes) is None:
            self.message.object = f"**Not applied:** {V.md_text(self.state.error or 'invalid value')}"
            self.message.visible = True
            return False
        self.message.visible = False
        self.controls.show_settings(self.state.target)  # the sliders follow
        return True

    def _on_reset(self, event=None) -> None:
        self.request({f.name: f.default for f in FIELDS})

    def _on_preset(self, name: str, event=None) -> None:
        """Every field as the preset ``name`` (a :class:`laav.LaavParams` constructor) sets it."""
        self.request(getattr(LaavParams, name)().to_dict())

    # ------------------------------------------------------------------ settings -> widgets
    def show(self, settings) -> None:
        """(Document thread.) Put ``settings``' parameters on the widgets without requesting."""
        p = self._params = settings.params
        if self._widgets is not None:  # (else they are made holding p)
            with self.host.quiet():
                for f in FIELDS:
                    w, v = self._widgets[f.name], getattr(p, f.name)
                    if w.value != v:
                        w.value = v
        self.message.visible = False  # what is shown was accepted
        self._mark(p)

    def _mark(self, params) -> None:
        """Mark the fields off their defaults (their labels) and count them."""
        for f in ([] if self._widgets is None else FIELDS):  # (made with their labels)
            name = label_of(f, getattr(params, f.name))
            w = self._widgets[f.name]
            if w.label != name:
                w.label = name
        off = changed_fields(params)
        self.summary.object = ("All fields at their defaults." if not off else
                               f"{len(off)} field{'s' if len(off) != 1 else ''} off the defaults: "
                               + ", ".join(V.md_text(n) for n in off) + ".")

    @property
    def marked(self) -> list[str]:
        """The fields whose labels carry the mark."""
        return [n for n, w in self.widgets.items() if w.label.startswith(MARK)]
