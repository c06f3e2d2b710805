"""Every :class:`laav.LaavParams` field as the Advanced panel shows it (no GUI imports).

One :class:`Field` per field, in the order of the stages that read them
(:data:`laav.params.STAGE_PARAMS`), with its kind and bounds (the validation table
``laav.params._BOUNDS``, so the panel's inputs allow what ``LaavParams`` allows), its
default and its description from the ``LaavParams`` docstring as plain text (for the
tooltip). Nothing here validates a combination: the state does that by constructing
``LaavParams`` (:meth:`explorer.state.ExplorerState.request`).
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

from laav import LaavParams
from laav.params import _BOUNDS, STAGE_PARAMS, STAGES

__all__ = ["Field", "FIELDS", "STAGE_TITLES", "field_docs", "fmt_value", "changed_fields", "widget_value"]

#: The Advanced panel's heading of each stage's fields.
STAGE_TITLES = {"atoms": "1 · Atoms", "graph": "2 · Atom graph", "multicut": "3 · Multicut (fine models)",
                "coarse": "4 · Fine-to-coarse", "voting": "5 · Random Voting", "other": "Other"}


@dataclass(frozen=True)
class Field:
    """One ``LaavParams`` field.

    ``kind`` is the validation table's: ``"int"``, ``"float"`` ([low, high]),
    ``"float>"`` ((low, high]), ``"int|None"`` (None allowed: ``fine_models``, "auto"),
    ``"bool"`` or ``"choice"`` (one of ``choices``).
    """

    name: str
    kind: str
    low: float | None
    high: float | None
    choices: tuple
    default: object
    stage: str
    doc: str

    def range_text(self) -> str:
        """What the field allows, e.g. ``(0, 1e+06]``, ``one of: coding, epipolar``."""
        if self.kind == "bool":
            return "on or off"
        if self.kind == "choice":
            return "one of: " + ", ".join(self.choices)
        text = f"{'(' if self.kind == 'float>' else '['}{self.low:g}, {self.high:g}]"
        if self.kind.endswith("|None"):
            text += f", or empty for auto ({AUTO.get(self.name, 'auto')})"
        return text

    def tooltip(self) -> str:
        """The widget's tooltip (plain text): the docstring's description, range, default."""
        return f"{self.name}: {self.doc} Allowed: {self.range_text()}. Default: {fmt_value(self.default)}."


#: What "auto" (None) means for the fields that allow it.
AUTO = {"fine_models": "fine_per_motion × C",
        "fine_per_motion": "4 with the joint merge, 3 coding, 2 epipolar",
        "rv_max_points": "every point votes"}

_RST = [
    (re.compile(r":(?:mod|func|meth|class|data|attr):`~?([^`]+)`"), r"\1"),  # :mod:`laav.coding`
    (re.compile(r"``([^`]+)``"), r"\1"),  # ``r1``
    (re.compile(r"\s+"), " "),
]


def _plain(text: str) -> str:
    for pat, rep in _RST:
        text = pat.sub(rep, text)
    return text.strip()


def field_docs(doc: str | None = None) -> dict[str, str]:
    """``{field: description}`` from the ``Parameters`` section of ``LaavParams``'s
    docstring (numpydoc: ``name : type`` then indented lines), as plain text."""
    doc = LaavParams.__doc__ if doc is None else doc
    lines = doc.splitlines()
    try:
        start = next(i for i, ln in enumerate(lines) if ln.strip() == "Parameters") + 2
    except StopIteration:
        return {}
    out: dict[str, list[str]] = {}
    name = None
    head = re.compile(r"^(\s*)([A-Za-z_][A-Za-z0-9_]*) : ")
    indent = None
    for ln in lines[start:]:
        m = head.match(ln)
        if m and (indent is None or len(m.group(1)) == indent):
            indent = len(m.group(1))
            name = m.group(2)
            out[name] = []
            continue
        if ln.strip() and indent is not None and len(ln) - len(ln.lstrip()) <= indent:
            break  # the next section ("Validation")
        if name is not None:
            out[name].append(ln)
    return {k: _plain(" ".join(v)) for k, v in out.items()}


def _fields() -> tuple[Field, ...]:
    docs = field_docs()
    bounds = {name: (kind, low, high) for name, kind, low, high in _BOUNDS}
    defaults = LaavParams()
    stage_of = {n: st for st in STAGES for n in STAGE_PARAMS[st]}
    order = [f.name for f in dataclasses.fields(LaavParams)]
    stage_rank = {st: i for i, st in enumerate((*STAGES, "other"))}
    out = []
    for name in order:
        kind, low, high = bounds[name]
        choices = tuple(low) if kind == "choice" else ()
        if kind in ("choice", "bool"):
            low = high = None
        out.append(Field(name, kind, low, high, choices, getattr(defaults, name), stage_of.get(name, "other"),
                         docs.get(name, "")))
    # by stage, in the dataclass's order within a stage
    return tuple(sorted(out, key=lambda f: stage_rank[f.stage]))


#: Every LaavParams field, grouped by stage.
FIELDS: tuple[Field, ...] = _fields()


def fmt_value(v) -> str:
    """A field's value as the page writes it: ``20``, ``0.25``, ``on``, ``auto`` (None)."""
    if v is None:
        return "auto"
    if isinstance(v, bool):
        return "on" if v else "off"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def changed_fields(params: LaavParams) -> list[str]:
    """The fields of ``params`` that differ from their defaults, in :data:`FIELDS` order."""
    return [f.name for f in FIELDS if getattr(params, f.name) != f.default]


def widget_value(field: Field, value):
    """A widget's value as the field's Python type: a number box gives ``int`` or ``float``
    (or None when empty), a checkbox ``bool``, a select ``str``. An empty box is None (for
    ``fine_models``: auto; for the others ``LaavParams`` says it is not a number)."""
    if value is None:
        return None
    if field.kind in ("int", "int|None"):
        return int(value) if float(value).is_integer() else float(value)
    if field.kind in ("float", "float>"):
        return float(value)
    if field.kind == "bool":
        return bool(value)
    return str(value)
