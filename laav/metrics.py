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

    The matching (Hungarian assignment on the confusion matrix) pairs each predicted
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
