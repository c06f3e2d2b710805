"""Scoring a segmentation against ground truth."""

from __future__ import annotations

import functools
import itertools
import math

import numpy as np

__all__ = ["confusion_matrix", "misclassification_rate", "best_label_map", "matched_counts",
           "labelling_distance", "DISAGREEMENT_WARN"]

#: Two runs without ground truth (LAAV and plain Random Voting) whose labellings are more
#: than this share of the points apart (:func:`labelling_distance`) are a warning sign: at
#: least one of them is wrong on half that share or more (``laav segment --check``, the
#: explorer's amber warning).
DISAGREEMENT_WARN = 0.10


def _as_labels(a, name: str) -> tuple[np.ndarray, np.ndarray]:
    arr = np.asarray(a)
    if arr.ndim != 1:
        raise ValueError(f"{name} must be a 1-D label vector, got shape {arr.shape}")
    values, inverse = np.unique(arr, return_inverse=True)
    return values, inverse.ravel()


def confusion_matrix(true, pred) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Counts of points per (true label, predicted label).

    Parameters
    ----------
    true, pred : array-like of shape (P,)
        Label vectors of any hashable integer values; the sets may differ in size.

    Returns
    -------
    counts : ndarray of shape (n_true, n_pred), int64
        ``counts[i, j]`` = points whose true label is ``true_values[i]`` and predicted
        label ``pred_values[j]``.
    true_values, pred_values : ndarray
        The sorted distinct labels behind the rows and columns.
    """
    tv, ti = _as_labels(true, "true")
    pv, pi = _as_labels(pred, "pred")
    if ti.shape != pi.shape:
        raise ValueError(f"true has {ti.size} labels but pred has {pi.size}")
    counts = np.zeros((tv.size, pv.size), dtype=np.int64)
    np.add.at(counts, (ti, pi), 1)
    return counts, tv, pv


#: Most candidate matchings :func:`_assign` enumerates itself (6! = 720: e.g. 6 motions
#: against 6; ``perm(columns, rows)`` counts them); above, scipy's Hungarian method.
_ENUMERATE_MAX = 720


@functools.lru_cache(maxsize=32)
def _matchings(n: int, k: int) -> np.ndarray:
    """Every ordered choice of ``k`` distinct columns of ``range(n)``, (n! / (n - k)!, k), in
    lexicographic order; cached read-only."""
    out = np.array(list(itertools.permutations(range(n), k)), dtype=np.intp)
    out.flags.writeable = False
    return out


def _assign(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the one-to-one assignment with the largest total count, rows
    increasing (as :func:`scipy.optimize.linear_sum_assignment` returns them).

    Motions are few: while there are at most :data:`_ENUMERATE_MAX` matchings (e.g. 6
    motions against 6) every one is scored at once (the first of equal totals kept); beyond,
    the Hungarian method. The total is the same either way; scipy.optimize is imported only
    then: it costs 0.35-0.4 s, which fell on the explorer's first result.
    """
    r, c = counts.shape
    if min(r, c) == 0:
        return np.zeros(0, np.intp), np.zeros(0, np.intp)
    if r > c:
        cols, rows = _assign(counts.T)
        order = np.argsort(rows, kind="stable")
        return rows[order], cols[order]
    if math.perm(c, r) <= _ENUMERATE_MAX:
        choices = _matchings(c, r)  # (M, r): the column of each row
        best = int(np.argmax(counts[np.arange(r), choices].sum(axis=1)))
        return np.arange(r), choices[best].copy()
    from scipy.optimize import linear_sum_assignment

    return linear_sum_assignment(counts, maximize=True)


def matched_counts(counts: np.ndarray) -> np.ndarray:
    """The largest total of a one-to-one matching of rows to columns, for every matrix of a
    stack: ``counts`` (..., r, c) non-negative integers -> (...) int64, e.g. the points a
    labelling gets right under the best matching of its labels, for every row of a label
    trace at once."""
    counts = np.asarray(counts, dtype=np.int64)
    r, c = counts.shape[-2:]
    if min(r, c) == 0:
        return np.zeros(counts.shape[:-2], dtype=np.int64)
    if r > c:
        counts, (r, c) = np.swapaxes(counts, -1, -2), (c, r)
    if math.perm(c, r) <= _ENUMERATE_MAX:
        return counts[..., np.arange(r), _matchings(c, r)].sum(axis=-1).max(axis=-1)
    flat = counts.reshape(-1, r, c)
    out = np.array([m[_assign(m)].sum() for m in flat], dtype=np.int64)
    return out.reshape(counts.shape[:-2])


#: The label of a point left unlabelled (``LaavResult.unlabelled_reason``): never matched.
UNLABELLED = -1


def _matchable(counts: np.ndarray, tv: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """``counts`` with the row and column of label -1 (unlabelled) zeroed, so that the
    assignment never matches them (their points count as errors)."""
    rows, cols = tv == UNLABELLED, pv == UNLABELLED
    if rows.any() or cols.any():
        counts = counts.copy()
        counts[rows] = 0
        counts[:, cols] = 0
    return counts


def best_label_map(true, pred) -> dict:
    """The one-to-one map from predicted to true labels that agrees on the most points.

    Predicted labels left without a partner (more predicted than true groups) are absent,
    and so is -1 (a point left unlabelled), which is never matched.
    """
    counts, tv, pv = confusion_matrix(true, pred)
    rows, cols = _assign(_matchable(counts, tv, pv))
    return {pv[c].item(): tv[r].item() for r, c in zip(rows, cols)
            if pv[c] != UNLABELLED and tv[r] != UNLABELLED}


def misclassification_rate(true, pred) -> float:
    """Fraction of points misassigned under the best one-to-one matching of labels.

    The matching (the best one-to-one assignment on the confusion matrix: every matching
    scored for a few labels, the Hungarian method beyond) pairs each predicted
    group with at most one true group; points of unmatched groups count as errors. This
    is the Hopkins155 error measure. The label -1 is reserved: it marks a point LAAV left
    unlabelled (``LaavResult.unlabelled_reason``) and is never matched, so such points
    always count as errors. It is symmetric (swapping ``true`` and ``pred`` gives the
    same value), invariant to renaming labels (other than -1), 0 for identical
    partitions without -1, in ``[0, 1 - 1/P]`` for other partitions without it, and 1
    when every point is unlabelled.

    Parameters
    ----------
    true, pred : array-like of shape (P,)
        Integer labels; -1 means unlabelled.

    Returns
    -------
    float
    """
    counts, tv, pv = confusion_matrix(true, pred)
    total = counts.sum()
    if total == 0:
        raise ValueError("cannot score an empty labelling")
    counts = _matchable(counts, tv, pv)
    rows, cols = _assign(counts)
    return float(1.0 - counts[rows, cols].sum() / total)


def labelling_distance(a, b) -> float:
    """The share of the points two labellings of the same points label differently, their
    motions matched one to one (the best matching): :func:`misclassification_rate` of one
    against the other over the points at least one of them labels, counted over all P. A
    point both leave unlabelled (-1) is no difference; one only one of them leaves is. A
    metric (symmetric, 0 for the same partition, the triangle inequality holds), so against
    a ground truth T, ``max(d(a, T), d(b, T)) >= d(a, b) / 2``: two runs far apart mean at
    least one of them is wrong, which is the check when there is no ground truth (LAAV
    against plain Random Voting: ``laav segment --check``, the explorer's card 5).

    Parameters
    ----------
    a, b : array-like of shape (P,)
        Integer labels; -1 means unlabelled.

    Returns
    -------
    float in [0, 1]
    """
    a, b = np.asarray(a), np.asarray(b)
    if a.shape != b.shape or a.ndim != 1:
        raise ValueError(f"labellings of different shapes: {a.shape} and {b.shape}")
    some = (a >= 0) | (b >= 0)
    if not some.any():
        return 0.0
    return misclassification_rate(a[some], b[some]) * float(some.sum()) / a.size
