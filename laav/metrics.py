"""Scoring a segmentation against ground truth."""

from __future__ import annotations

import numpy as np

__all__ = ["confusion_matrix", "misclassification_rate", "best_label_map"]


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


def _assign(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns of the assignment with the largest total count (Hungarian method).

    scipy.optimize is imported here, not at module level: it costs 0.4 s, and ``import laav``
    is on the explorer's start-up path.
    """
    from scipy.optimize import linear_sum_assignment

    return linear_sum_assignment(-counts)


def _matchable(counts: np.ndarray, tv: np.ndarray, pv: np.ndarray) -> np.ndarray:
    """``counts`` with the rows and columns of negative labels (-1: unlabelled) zeroed, so
    that the assignment never matches them (their points count as errors)."""
    if (tv.size and tv[0] < 0) or (pv.size and pv[0] < 0):  # sorted: a negative label comes first
        counts = counts.copy()
        counts[tv < 0] = 0
        counts[:, pv < 0] = 0
    return counts


def best_label_map(true, pred) -> dict:
    """The one-to-one map from predicted to true labels that agrees on the most points.

    Predicted labels left without a partner (more predicted than true groups) are absent,
    and so are negative labels (-1: a point left unlabelled), which are never matched.
    """
    counts, tv, pv = confusion_matrix(true, pred)
    rows, cols = _assign(_matchable(counts, tv, pv))
    return {pv[c].item(): tv[r].item() for r, c in zip(rows, cols)
            if pv[c] >= 0 and tv[r] >= 0}


def misclassification_rate(true, pred) -> float:
    """Fraction of points misassigned under the best one-to-one matching of labels.

    The matching (Hungarian assignment on the confusion matrix) pairs each predicted
    group with at most one true group; points of unmatched groups count as errors. This
    is the Hopkins155 error measure. A negative label (-1: a point LAAV left unlabelled,
    see ``LaavResult.unlabelled_reason``) is never matched: such points always count as
    errors. It is symmetric (swapping ``true`` and ``pred`` gives the same value),
    invariant to renaming the non-negative labels, 0 for identical partitions without
    negative labels, in ``[0, 1 - 1/P]`` for other partitions without them, and 1 when
    every point is unlabelled.

    Parameters
    ----------
    true, pred : array-like of shape (P,)

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
