"""The Hopkins155 misclassification rate and the confusion matrix behind it."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from laav import confusion_matrix, misclassification_rate
from laav.metrics import best_label_map

PROPS = settings(max_examples=200, deadline=None)


def _labelings(max_points: int = 40, max_labels: int = 5):
    """Pairs of equally long label vectors with small label alphabets."""
    return st.integers(1, max_points).flatmap(
        lambda n: st.tuples(
            st.lists(st.integers(0, max_labels - 1), min_size=n, max_size=n),
            st.lists(st.integers(0, max_labels - 1), min_size=n, max_size=n),
        )
    )


def _rename(labels, seed: int) -> list[int]:
    """Apply a random bijection to the label names (arbitrary, non-contiguous integers;
    never -1, which marks an unlabelled point)."""
    rng = np.random.default_rng(seed)
    values = sorted(set(labels))
    pool = np.setdiff1d(np.arange(-1000, 1000), [-1])
    names = rng.choice(pool, size=len(values), replace=False)
    mapping = dict(zip(values, names.tolist()))
    return [mapping[v] for v in labels]


def _brute_force_rate(true, pred) -> float:
    """Best one-to-one matching by trying every injective assignment."""
    tv, pv = sorted(set(true)), sorted(set(pred))
    best = 0
    if len(pv) <= len(tv):
        for image in itertools.permutations(tv, len(pv)):
            m = dict(zip(pv, image))
            best = max(best, sum(m[p] == t for t, p in zip(true, pred)))
    else:
        for image in itertools.permutations(pv, len(tv)):
            m = dict(zip(tv, image))
            best = max(best, sum(m[t] == p for t, p in zip(true, pred)))
    return 1.0 - best / len(true)


def _same_partition(a, b) -> bool:
    pairs = set(zip(a, b))
    return len(pairs) == len(set(a)) == len(set(b))


# --------------------------------------------------------------------------- exact cases


def test_identical_is_zero():
    a = [0, 0, 1, 1, 2, 2, 2]
    assert misclassification_rate(a, a) == 0.0
    assert misclassification_rate(np.array(a), np.array(a)) == 0.0


def test_relabelled_is_zero():
    assert misclassification_rate([0, 0, 1, 1, 2], [2, 2, 0, 0, 1]) == 0.0
    assert misclassification_rate([0, 0, 1, 1], [7, 7, -3, -3]) == 0.0


@pytest.mark.parametrize(
    ("true", "pred", "rate"),
    [
        ([0, 0, 1, 1], [0, 1, 1, 1], 0.25),
        ([0, 0, 1, 1], [1, 0, 0, 0], 0.25),
        ([0, 0, 1, 1], [0, 1, 0, 1], 0.5),
        ([0, 0, 1, 1], [5, 5, 5, 5], 0.5),  # one predicted group for two true
        ([0, 0, 0, 0], [0, 1, 2, 3], 0.75),  # every point its own group: 1 - 1/P
        ([0, 0, 0, 1, 1, 1], [0, 0, 1, 2, 2, 2], 1 / 6),  # 3 predicted vs 2 true
        ([0, 0, 1, 2, 2, 2], [0, 0, 0, 1, 1, 1], 1 / 6),  # 2 predicted vs 3 true
        ([0, 0, 1, 1, 2, 2], [0, 0, 0, 0, 0, 0], 4 / 6),
        # greedy (take the 5 first) would score 8 errors; the optimal matching has 5
        ([0] * 9 + [1] * 4, [0] * 5 + [1] * 4 + [0] * 4, 5 / 13),
    ],
)
def test_hand_made_cases(true, pred, rate):
    assert misclassification_rate(true, pred) == pytest.approx(rate, abs=1e-15)
    assert misclassification_rate(pred, true) == pytest.approx(rate, abs=1e-15)


def test_single_point():
    assert misclassification_rate([3], [9]) == 0.0


def test_input_errors():
    with pytest.raises(ValueError):
        misclassification_rate([0, 1, 1], [0, 1])
    with pytest.raises(ValueError):
        misclassification_rate([[0, 1], [1, 0]], [[0, 1], [1, 0]])
    with pytest.raises(ValueError):
        misclassification_rate([], [])


def test_confusion_matrix_hand_made():
    counts, tv, pv = confusion_matrix([0, 0, 0, 1, 1, 1], [4, 4, 9, 2, 2, 2])
    assert counts.dtype == np.int64
    assert tv.tolist() == [0, 1]
    assert pv.tolist() == [2, 4, 9]
    assert counts.tolist() == [[0, 2, 1], [3, 0, 0]]


def test_best_label_map():
    assert best_label_map([0, 0, 1, 1], [7, 7, 3, 3]) == {7: 0, 3: 1}
    # the unmatched third predicted group is left out
    mapping = best_label_map([0, 0, 0, 1, 1, 1], [0, 0, 1, 2, 2, 2])
    assert mapping == {0: 0, 2: 1}


# --------------------------------------------------------------------------- properties


@PROPS
@given(pair=_labelings(), seed=st.integers(0, 2**32 - 1))
def test_zero_for_identical_and_relabelled(pair, seed):
    a, _ = pair
    assert misclassification_rate(a, a) == 0.0
    assert misclassification_rate(a, _rename(a, seed)) == 0.0


@PROPS
@given(pair=_labelings(), seeds=st.tuples(st.integers(0, 2**32 - 1), st.integers(0, 2**32 - 1)))
def test_invariant_to_label_names(pair, seeds):
    a, b = pair
    r = misclassification_rate(a, b)
    assert misclassification_rate(_rename(a, seeds[0]), _rename(b, seeds[1])) == r


@PROPS
@given(pair=_labelings())
def test_symmetric(pair):
    a, b = pair
    assert misclassification_rate(a, b) == misclassification_rate(b, a)


@PROPS
@given(pair=_labelings())
def test_bounds_and_granularity(pair):
    a, b = pair
    P = len(a)
    r = misclassification_rate(a, b)
    assert 0.0 <= r <= 1.0 - 1.0 / P + 1e-12
    assert abs(r * P - round(r * P)) < 1e-9  # a whole number of misassigned points
    assert (r == 0.0) == _same_partition(a, b)


@settings(max_examples=150, deadline=None)
@given(pair=_labelings(max_points=12, max_labels=4))
def test_matches_brute_force(pair):
    a, b = pair
    assert misclassification_rate(a, b) == pytest.approx(_brute_force_rate(a, b), abs=1e-12)


@PROPS
@given(pair=_labelings())
def test_confusion_matrix_counts(pair):
    a, b = pair
    counts, tv, pv = confusion_matrix(a, b)
    assert counts.sum() == len(a)
    assert counts.shape == (len(set(a)), len(set(b)))
    assert tv.tolist() == sorted(set(a)) and pv.tolist() == sorted(set(b))
    assert counts.sum(axis=1).tolist() == [a.count(v) for v in tv.tolist()]
    assert counts.sum(axis=0).tolist() == [b.count(v) for v in pv.tolist()]
    assert (counts >= 0).all()
    transposed, _, _ = confusion_matrix(b, a)
    assert np.array_equal(transposed, counts.T)


# --------------------------------------------------------------------------- -1: unlabelled


@pytest.mark.parametrize("true, pred, rate", [
    ([0, 0, 1, 1], [0, 0, -1, -1], 0.5),   # -1 would otherwise be matched to motion 1
    ([0, 0, 1, 1], [1, 1, -1, 0], 0.25),
    ([0, 0, 1, 1], [-1, -1, -1, -1], 1.0),
    ([0, 1, 2, 2], [5, 6, 7, -1], 0.25),
    ([0, 0, 0, 1], [-1, 0, 0, 1], 0.25),
])
def test_unlabelled_points_always_count_as_errors(true, pred, rate):
    assert misclassification_rate(true, pred) == pytest.approx(rate, abs=1e-15)
    assert misclassification_rate(pred, true) == pytest.approx(rate, abs=1e-15)  # symmetric


@PROPS
@given(pair=_labelings(), data=st.data())
def test_unlabelling_a_point_never_lowers_the_error(pair, data):
    """Setting labels to -1 adds exactly those points' errors, at most: it never helps."""
    a, b = pair
    k = data.draw(st.integers(0, len(b)))
    hidden = list(b)
    for q in range(k):
        hidden[q] = -1
    r = misclassification_rate(a, b)
    rh = misclassification_rate(a, hidden)
    assert rh >= r - 1e-12
    assert rh >= k / len(a) - 1e-12  # every unlabelled point is an error
    assert -1 not in best_label_map(a, hidden)


# --------------------------------------------------------------------------- the matching itself


@pytest.mark.parametrize("r, c", [(1, 1), (2, 3), (3, 2), (3, 3), (4, 6), (6, 6), (7, 7), (9, 4)])
def test_the_matching_is_the_hungarian_methods(r, c):
    """Enumerated (up to 6 motions on the smaller side) or by scipy above: the same largest
    total as scipy's Hungarian method, one-to-one, rows increasing; on stacks too."""
    from scipy.optimize import linear_sum_assignment

    from laav.metrics import _assign, matched_counts

    rng = np.random.default_rng(r * 10 + c)
    stack = rng.integers(0, 4 if r * c % 2 else 40, size=(30, r, c))  # ties among small counts
    want = np.array([m[linear_sum_assignment(-m)].sum() for m in stack])
    np.testing.assert_array_equal(matched_counts(stack), want)
    for m, total in zip(stack, want):
        rows, cols = _assign(m)
        assert m[rows, cols].sum() == total
        assert len(rows) == min(r, c) and list(rows) == sorted(set(rows)) and len(set(cols)) == len(cols)


def test_matching_empty_and_scipy_not_imported_for_few_motions(tmp_path):
    """No rows or columns: nothing matched. Scoring a few motions does not import
    scipy.optimize (0.35-0.4 s on the explorer's first result)."""
    import subprocess
    import sys

    from laav.metrics import matched_counts

    assert matched_counts(np.zeros((2, 0, 3), np.int64)).tolist() == [0, 0]
    code = ("import sys, laav; laav.misclassification_rate([0, 1, 2, 2], [2, 0, 1, 1]); "
            "laav.best_label_map([0, 0, 1], [1, 1, 0]); print('scipy.optimize' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_matched_counts_of_small_or_unsigned_integers_do_not_wrap():
    """Counts of any integer or bool dtype: summed in int64, on both paths (enumerated and
    scipy's), never wrapped (uint8 totals above 255) nor negated (unsigned)."""
    from scipy.optimize import linear_sum_assignment

    from laav.metrics import matched_counts

    rng = np.random.default_rng(5)
    for n in (3, 7):  # enumerated, scipy
        m = rng.integers(100, 255, size=(n, n)).astype(np.uint8)
        want = m.astype(np.int64)[linear_sum_assignment(m.astype(np.int64), maximize=True)].sum()
        assert matched_counts(m) == want and want > 255
        b = m > 180
        assert matched_counts(b) == b[linear_sum_assignment(b.astype(int), maximize=True)].sum()


# ---------------------------------------------------------------------- labelling_distance
def _distance_by_brute_force(a, b) -> float:
    """Every one-to-one renaming of ``b``'s motions tried: the fewest points that then
    differ, -1 in both not counted, over all P."""
    a, b = np.asarray(a), np.asarray(b)
    la = sorted(set(a[a >= 0].tolist()) | set(b[b >= 0].tolist()))
    lb = sorted(set(b[b >= 0].tolist()))
    names = la + [100 + k for k in range(len(lb))]  # fresh names: a motion matched to none
    best = a.size
    for perm in itertools.permutations(names, len(lb)):
        ren = {-1: -1, **dict(zip(lb, perm))}
        r = np.array([ren[v] for v in b.tolist()])
        best = min(best, int(((a != r) & ((a >= 0) | (r >= 0))).sum()))
    return best / a.size


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(st.integers(-1, 2), st.integers(-1, 2)), min_size=1, max_size=12))
def test_labelling_distance_is_the_fewest_points_apart_under_any_renaming(pairs):
    from laav import labelling_distance

    a = np.array([p[0] for p in pairs])
    b = np.array([p[1] for p in pairs])
    d = labelling_distance(a, b)
    assert d == pytest.approx(_distance_by_brute_force(a, b))
    assert d == pytest.approx(labelling_distance(b, a))  # symmetric
    assert labelling_distance(a, a) == 0 and 0 <= d <= 1


def test_labelling_distance_of_renamed_or_unlabelled_points():
    from laav import labelling_distance

    assert labelling_distance([0, 0, 1, 1], [1, 1, 0, 0]) == 0
    assert labelling_distance([0, 0, 1, -1], [1, 1, 0, -1]) == 0  # -1 in both: no difference
    assert labelling_distance([0, 0, 1, 1], [1, 1, 0, -1]) == pytest.approx(0.25)
    assert labelling_distance([-1, -1], [-1, -1]) == 0
    with pytest.raises(ValueError, match="different shapes"):
        labelling_distance([0, 1], [0, 1, 1])
