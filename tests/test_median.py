"""laav._median.median is np.median bit for bit (values, shapes, dtypes, NaN and inf),
on the shapes the robust fits call it with and on random ones."""

from __future__ import annotations

import warnings

import numpy as np

from laav._median import median


def _same(a, b) -> bool:
    return (np.array_equal(np.asarray(a), np.asarray(b), equal_nan=True) and np.shape(a) == np.shape(b)
            and np.asarray(a).dtype == np.asarray(b).dtype and type(a) is type(b))


def test_median_is_numpys_median_bit_for_bit():
    rng = np.random.default_rng(0)
    checked = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (numpy's, for NaN and empty input)
        for _ in range(1500):
            shape = tuple(int(v) for v in rng.integers(1, 30, size=rng.integers(1, 4)))
            x = rng.normal(size=shape) * 10.0 ** rng.integers(-5, 6)
            if rng.random() < 0.3:
                x = np.round(x, 1)  # ties
            if rng.random() < 0.1:
                x.flat[rng.integers(x.size)] = np.nan
            if rng.random() < 0.05:
                x.flat[rng.integers(x.size)] = np.inf
            if rng.random() < 0.3:
                x = x.astype(np.float32)
            for axis in [None, -1, *range(x.ndim)]:
                for keepdims in (False, True):
                    assert _same(np.median(x, axis=axis, keepdims=keepdims),
                                 median(x, axis=axis, keepdims=keepdims)), (shape, axis, keepdims)
                    checked += 1
        # what np.median itself does: integers, an empty row, a scalar-like array
        for x, axis in ((np.arange(7), None), (np.zeros((3, 0)), 1), (np.array([2.5]), 0)):
            assert _same(np.median(x, axis=axis), median(x, axis=axis))
    assert checked > 10000


def test_median_of_the_fits_shapes():
    """(K, n) rows with keepdims (the epipolar fits' weights) and 1-D residuals (the subspace
    fits'), even and odd n: the middle value, or the mean of the two middle ones."""
    x = np.array([[3.0, 1.0, 2.0, 10.0], [5.0, 4.0, 6.0, 1.0]])
    np.testing.assert_array_equal(median(x, axis=1, keepdims=True), [[2.5], [4.5]])
    assert median(np.array([4.0, 1.0, 3.0])) == 3.0 and isinstance(median(np.array([4.0, 1.0])), np.floating)
    assert np.isnan(median(np.array([1.0, np.nan, 2.0])))
