"""Pin a result as A and compare it with the live result B (no GUI imports).

:func:`pin` keeps what A was: the sequence, the settings (parameters, seed, C), the result
with each stage's labels, and each stage's error (:func:`explorer.views.stage_numbers`; plain
Random Voting's when it was computed). :func:`compare` sets A beside B: the settings that
differ (``name: A → B``), the error of every stage in both with the difference, and the
points whose final motion differs (B's labels matched to A's first, so a mere renaming of
motions changes nothing). Without ground truth there are no errors, only those points.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

import laav

from . import views as V
from .fields import fmt_value

__all__ = ["Pinned", "Comparison", "pin", "with_plain", "params_diff", "error_diff", "changed_points",
           "compare", "comparison_markdown", "ERROR_STAGES"]

#: The stages whose errors are compared: key of :func:`views.stage_numbers` -> row name.
ERROR_STAGES = {"fine": "fine models", "coarse": "coarse", "final": "final", "plain": "plain RV"}


@dataclass(frozen=True)
class Pinned:
    """A result kept as A (or the live one as B).

    ``settings`` is an :class:`explorer.state.Settings`; ``labels`` the labels after each
    stage (``fine``, ``coarse``, ``final``; copies); ``errors`` each stage's error (a
    fraction; None without ground truth, and ``plain`` None until plain RV was computed).
    """

    sequence: laav.Sequence
    settings: object
    result: laav.LaavResult
    plain: laav.Voting | None
    labels: dict
    errors: dict

    @property
    def has_truth(self) -> bool:
        return self.sequence.labels is not None


def _errors(seq, result, plain) -> dict:
    num = V.stage_numbers(seq, result, plain)
    return {st: num[f"error_{st}"] for st in ERROR_STAGES}


def pin(seq: laav.Sequence, result: laav.LaavResult, settings, plain: laav.Voting | None = None) -> Pinned:
    """Keep ``result`` (of ``seq`` with ``settings``; ``plain``: plain RV with the same
    settings, if computed) as it is now."""
    labels = {k: np.array(v, dtype=np.int64, copy=True) for k, v in result.stage_labels().items()}
    return Pinned(seq, settings, result, plain, labels, _errors(seq, result, plain))


def with_plain(p: Pinned, plain: laav.Voting | None) -> Pinned:
    """``p`` with plain RV's run (computed after pinning); ``p`` itself when there is none."""
    if plain is None or p.plain is plain:
        return p
    return dataclasses.replace(p, plain=plain, errors=_errors(p.sequence, p.result, plain))


def _setting_values(settings) -> dict:
    d = settings.params.to_dict()
    d["seed"], d["motions"] = settings.seed, settings.n_motions
    return d


def params_diff(a, b) -> list[tuple[str, object, object]]:
    """``(name, value in A, value in B)`` for every setting that differs: the
    ``LaavParams`` fields (their names, as in the URL), then ``seed`` and ``motions`` (C)."""
    va, vb = _setting_values(a), _setting_values(b)
    return [(k, va[k], vb[k]) for k in va if va[k] != vb[k]]


def error_diff(a: dict, b: dict) -> list[tuple[str, float | None, float | None, float | None]]:
    """``(stage, A, B, B - A)`` for each of :data:`ERROR_STAGES` (fractions; the difference
    is None when either is unknown)."""
    return [(st, a.get(st), b.get(st), None if a.get(st) is None or b.get(st) is None
             else b[st] - a[st]) for st in ERROR_STAGES]


def changed_points(a_labels, b_labels) -> np.ndarray:
    """Indices of the points whose motion differs between A and B, after renaming B's
    motions to match A's as far as possible (:func:`views.align_labels`)."""
    a = np.asarray(a_labels, dtype=np.int64)
    b = np.asarray(b_labels, dtype=np.int64)
    if a.shape != b.shape:
        raise ValueError(f"A and B label different numbers of points ({a.size} and {b.size})")
    return np.flatnonzero(V.align_labels(b, a) != a)


@dataclass(frozen=True)
class Comparison:
    """A beside B: :func:`params_diff`, :func:`error_diff`, the points whose final motion
    differs (:func:`changed_points`), and whether the sequence has ground truth."""

    params: list
    errors: list
    changed: np.ndarray
    n_points: int
    has_truth: bool


def compare(a: Pinned, b: Pinned) -> Comparison:
    """Compare A with B (two results on the same sequence)."""
    if a.sequence is not b.sequence:
        raise ValueError("A and B are results on different sequences")
    return Comparison(params_diff(a.settings, b.settings), error_diff(a.errors, b.errors),
                      changed_points(a.labels["final"], b.labels["final"]), a.sequence.n_points, a.has_truth)


def _pct(v) -> str:
    """Two decimals: one point in a few hundred moves the second one (and the difference
    then reads as the difference of the two columns)."""
    return "–" if v is None else f"{100 * v:.2f} %"


def _delta(v) -> str:
    if v is None:
        return "–"
    if abs(v) < 5e-5:
        return "same"
    return f"{100 * v:+.2f} pp"


def comparison_markdown(c: Comparison) -> str:
    """The compare card's table and lists (every value as literal text)."""
    n = int(c.changed.size)
    lines = []
    if c.has_truth:
        lines += ["| error vs ground truth | A (pinned) | B (live) | B − A (percentage points) |",
                  "|---|---|---|---|"]
        for st, ea, eb, d in c.errors:
            lines.append(f"| {ERROR_STAGES[st]} | {_pct(ea)} | {_pct(eb)} | {_delta(d)} |")
        lines.append("")
    else:
        lines.append("No ground truth: no errors to compare, only the labels.  ")
    share = f" ({100 * n / max(c.n_points, 1):.1f} %)" if n else ""
    lines.append(f"**Points whose final motion differs between A and B: {n} of {c.n_points}**{share}"
                 " (B's motions matched to A's first; ringed in both views).")
    lines.append("")
    if c.params:
        lines.append("**Settings that differ (A → B):** " + "; ".join(
            V.md_text(f"{name}: {fmt_value(va)} → {fmt_value(vb)}") for name, va, vb in c.params))
    else:
        lines.append("**Settings that differ:** none (B has A's settings).")
    return "\n".join(lines)
