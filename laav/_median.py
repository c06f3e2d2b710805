"""``np.median`` of float arrays, bit for bit, with less call overhead (the robust fits call
it a few hundred times a run, on arrays of tens to hundreds of values)."""

from __future__ import annotations

import numpy as np

__all__ = ["median"]


def median(x: np.ndarray, axis: int | None = None, keepdims: bool = False):
    """``np.median(x, axis=axis, keepdims=keepdims)``: the same numbers for a float array
    (the same partition; the mean of the two middle values as ``(a + b) / 2``, which is
    what ``np.mean`` of two values computes; NaN where the reduced values hold one). Other
    dtypes and empty reductions go to ``np.median`` itself."""
    x = np.asarray(x)
    if axis is None:
        flat = x.reshape(-1)
        if x.dtype.kind != "f" or flat.size == 0:
            return np.median(x, keepdims=keepdims)
        out = median(flat, 0)
        return np.reshape(out, (1,) * x.ndim) if keepdims else out
    axis = axis % max(x.ndim, 1)
    n = x.shape[axis]
    if x.dtype.kind != "f" or n == 0:
        return np.median(x, axis=axis, keepdims=keepdims)
    h = n // 2
    kth = sorted({h - 1, h, n - 1} if n % 2 == 0 else {h, n - 1})
    part = np.partition(x, kth, axis=axis)
    out = np.take(part, h, axis=axis)
    if n % 2 == 0:
        out = (np.take(part, h - 1, axis=axis) + out) / 2.0
    last = np.take(part, n - 1, axis=axis)  # the largest value, NaN when there is one
    nan = np.isnan(last)
    if np.any(nan):
        out = np.where(nan, last, out)
    if keepdims:
        out = np.expand_dims(out, axis)
    return out[()] if isinstance(out, np.ndarray) and out.ndim == 0 else out
