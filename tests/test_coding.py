"""The coding-length merge of fine models (laav/coding.py), against direct computations."""

import itertools

import numpy as np
import pytest

import laav
from laav import coding


def _direct_length(W: np.ndarray, eps: float) -> float:
    """Ma et al.'s coding length of the columns of W (D, N), straight from the formula."""
    D, N = W.shape
    mu = W.mean(axis=1, keepdims=True)
    Wc = W - mu
    _, logdet = np.linalg.slogdet(np.eye(D) + D / (eps ** 2 * N) * Wc @ Wc.T)
    return (N + D) / 2 * logdet + N / 2 * np.log1p(float((mu ** 2).sum()) / eps ** 2)


def _two_dependent_motions(rng, n_bg=60, n_obj=30, F=12):
    """A static camera: a static background and an object translating across it.

    Both fit one rank-3 linear subspace (span of x, y and the object's translation), so a
    linear-subspace or rank test cannot separate them; their coding lengths can.
    """
    bg = rng.uniform(0, 400, (n_bg, 2))
    obj = rng.uniform(150, 250, (n_obj, 2))
    shift = np.cumsum(rng.normal(4, 1, (F, 2)), axis=0)
    shift -= shift[0]
    pts = np.concatenate([np.broadcast_to(bg, (F, n_bg, 2)), obj[None] + shift[:, None]], axis=1)
    pts = pts + rng.normal(0, 0.3, pts.shape)
    labels = np.r_[np.zeros(n_bg, int), np.ones(n_obj, int)]
    return pts, labels


def test_coding_lengths_match_the_formula_on_raw_trajectories():
    rng = np.random.default_rng(0)
    pts, labels = _two_dependent_motions(rng)
    F, P, _ = pts.shape
    fine = np.r_[rng.integers(0, 3, 60), 3 + rng.integers(0, 2, 30)]  # 5 fine models
    st = coding.model_stats(pts, fine, 5, rank=2 * F)  # no projection: exact
    # the raw trajectories, from the corner of the points' bounding box (the origin the
    # statistics use: the mean term would otherwise depend on the coordinates' origin)
    W = np.transpose(pts - pts.min(axis=(0, 1)), (0, 2, 1)).reshape(2 * F, P)
    for group in ([0], [1, 2], [0, 3], [0, 1, 2, 3, 4]):
        m = np.isin(np.arange(5), group).astype(float)[None]
        got = coding.coding_lengths(*st.union(m), st.dim, eps=3.0)[0]
        want = _direct_length(W[:, np.isin(fine, group)], eps=3.0)
        assert got == pytest.approx(want, rel=1e-9)


def test_projection_keeps_the_lengths_when_the_data_has_low_rank():
    rng = np.random.default_rng(1)
    pts, _ = _two_dependent_motions(rng)
    pts = np.round(pts)  # keep it exact-ish but not rank deficient beyond K
    fine = np.r_[np.zeros(60, int), np.ones(30, int)]
    exact = coding.model_stats(pts, fine, 2, rank=pts.shape[0] * 2)
    proj = coding.model_stats(pts, fine, 2, rank=20)
    a = coding.coding_lengths(exact.count, exact.total, exact.scatter, exact.dim, 10.0)
    b = coding.coding_lengths(proj.count, proj.total, proj.scatter, proj.dim, 10.0)
    assert np.allclose(a, b, rtol=2e-2)


def test_best_partition_is_the_brute_force_minimum():
    rng = np.random.default_rng(2)
    pts, _ = _two_dependent_motions(rng)
    fine = np.r_[rng.integers(0, 4, 60), 4 + rng.integers(0, 3, 30)]  # 7 models
    st = coding.model_stats(pts, fine, 7)
    assign, total = coding.best_partition(st, 2, eps=10.0)
    best = np.inf
    for a in itertools.product(range(2), repeat=7):
        if len(set(a)) < 2:
            continue
        a = np.array(a)
        best = min(best, coding._total(st, a, 2, 10.0))
    assert total == pytest.approx(best)
    assert coding._total(st, assign, 2, 10.0) == pytest.approx(total)


def test_dependent_motions_are_separated_where_a_subspace_residual_merges_them():
    rng = np.random.default_rng(3)
    pts, labels = _two_dependent_motions(rng)
    # three fine models: two halves of the background, the object
    fine = np.r_[np.arange(60) % 2, np.full(30, 2)]
    st = coding.model_stats(pts, fine, 3)
    assign, _ = coding.best_partition(st, 2, eps=10.0)
    assert assign[0] == assign[1] != assign[2]
    # the linear rank-4 residual cannot tell: every grouping fits (almost) exactly
    for lab in ([0, 0, 1], [0, 1, 1], [0, 1, 0]):
        cost = laav.refine.subspace_residuals(pts, np.array(lab)[fine], 2, rank=4, rounds=1)
        own = cost[np.array(lab)[fine], np.arange(fine.size)]
        assert own.max() < 1.0  # px^2: all three partitions explained to the noise


def test_greedy_path_reaches_the_exact_partition_on_separated_models():
    rng = np.random.default_rng(4)
    pts, labels = _two_dependent_motions(rng, n_bg=80, n_obj=40)
    fine = np.r_[np.arange(80) % 10, 10 + np.arange(40) % 8]  # 18 models: greedy path
    st = coding.model_stats(pts, fine, 18)
    assign, _ = coding.best_partition(st, 2, eps=10.0)
    got = assign[fine]
    assert laav.misclassification_rate(got, labels) == 0.0


def test_merge_cost_is_symmetric_and_negative_within_a_motion():
    rng = np.random.default_rng(5)
    pts, _ = _two_dependent_motions(rng)
    fine = np.r_[np.arange(60) % 2, np.full(30, 2)]
    g = coding.merge_cost(coding.model_stats(pts, fine, 3), eps=10.0)
    assert np.allclose(g, g.T) and np.all(np.diag(g) == 0)
    assert g[0, 1] < 0 < g[0, 2]


@pytest.mark.parametrize("n, C, stirling", [(3, 3, 1), (4, 2, 7), (6, 2, 31), (9, 3, 3025),
                                             (7, 4, 350)])
def test_every_partition_is_enumerated_once(n, C, stirling):
    A = coding._assignments(n, C)
    assert A.shape == (stirling, n)  # Stirling numbers of the second kind S(n, C)
    canon = {tuple(np.unique(a, return_inverse=True)[1]) for a in A}
    assert len(canon) == stirling and all(len(set(a)) == C for a in A.tolist())


def _brute_force_lengths(st, C, eps, min_count):
    """Every partition of the models into C groups with >= min_count points per group,
    as {canonical assignment: total length}, by itertools (independent of _assignments)."""
    n = st.n_models
    out = {}
    for a in itertools.product(range(C), repeat=n):
        if len(set(a)) < C:
            continue
        first = {}
        canon = tuple(first.setdefault(g, len(first)) for g in a)
        counts = np.bincount(np.array(canon), weights=st.count, minlength=C)
        if counts.min() >= min_count and canon not in out:
            out[canon] = coding._total(st, np.array(canon), C, eps)
    return out


@pytest.mark.parametrize("min_count", [1, 20])
def test_shortlist_is_the_brute_force_ranking(min_count):
    rng = np.random.default_rng(6)
    pts, _ = _two_dependent_motions(rng)
    fine = np.r_[rng.integers(0, 4, 60), 4 + rng.integers(0, 3, 30)]  # 7 models
    st = coding.model_stats(pts, fine, 7)
    want = _brute_force_lengths(st, 2, 10.0, min_count)
    assign, total = coding.shortlist(st, 2, 10.0, n_best=12, min_count=min_count)
    ranked = sorted(want.values())[:12]
    assert np.allclose(total, ranked)
    for a, t in zip(assign, total):
        assert want[tuple(a.tolist())] == pytest.approx(t)
    if min_count == 1:  # the first is best_partition's
        best, length = coding.best_partition(st, 2, 10.0)
        assert np.array_equal(assign[0], best) and total[0] == pytest.approx(length)


def test_shortlist_keeps_every_group_above_min_count():
    rng = np.random.default_rng(7)
    pts, _ = _two_dependent_motions(rng)
    fine = np.r_[np.zeros(57, int), np.ones(3, int), np.full(30, 2)]  # model 1: 3 points
    st = coding.model_stats(pts, fine, 3)
    assign, _ = coding.shortlist(st, 2, 10.0, n_best=10, min_count=8)
    sizes = np.stack([np.bincount(a[fine], minlength=2) for a in assign])
    assert sizes.min() >= 8
    assert not any((a == a[1]).sum() == 1 for a in assign)  # model 1 never alone
    none, _ = coding.shortlist(st, 2, 10.0, n_best=10, min_count=50)
    assert none.shape == (0, 3)


def test_shortlist_greedy_path_starts_from_the_greedy_partition(monkeypatch):
    rng = np.random.default_rng(8)
    pts, labels = _two_dependent_motions(rng, n_bg=80, n_obj=40)
    fine = np.r_[np.arange(80) % 10, 10 + np.arange(40) % 8]  # 18 models: greedy path
    st = coding.model_stats(pts, fine, 18)
    assign, total = coding.shortlist(st, 2, 10.0, n_best=5)
    best, length = coding.best_partition(st, 2, 10.0)
    assert np.array_equal(assign[0], best) and total[0] == pytest.approx(length)
    assert np.all(np.diff(total) >= 0) and assign.shape == (5, 18)
    # the others are one model move away from it
    assert all((a != best).sum() == 1 for a in assign[1:])


def test_n_least_is_the_stable_sorts_first_n_with_ties_and_nan():
    """The shortlist sorts only the partitions up to the n-th least length: the same
    indices, in the same order, as a stable sort of all of them (ties in enumeration
    order, NaN last)."""
    from laav.coding import _n_least

    rng = np.random.default_rng(0)
    for _ in range(500):
        v = rng.integers(0, 6, size=int(rng.integers(1, 40))).astype(float)
        if rng.random() < 0.3:
            v[rng.integers(0, v.size)] = np.nan
        n = int(rng.integers(1, 12))
        np.testing.assert_array_equal(_n_least(v, n), np.argsort(v, kind="stable")[:n])


def test_coding_lengths_do_not_depend_on_the_scatters_memory_layout(monkeypatch):
    """The same lengths for a C-ordered, a Fortran-ordered and a transposed-view scatter (a
    non-contiguous product once lost the identity added to it, and factored log det S); and
    when the Cholesky factorisation fails, the eigenvalue route gets the covariance without
    the identity (``_log_det_1p``'s ``remake``), with the scatter left as it was."""
    rng = np.random.default_rng(4)
    X = rng.normal(size=(5, 600)) * 20.0
    st = coding.stats_of(X, rng.integers(0, 3, 600), 3, 40)
    want = coding.coding_lengths(st.count, st.total, st.scatter, st.dim, 2.0)
    for scatter in (np.asfortranarray(st.scatter), st.scatter.transpose(0, 2, 1)):
        np.testing.assert_allclose(coding.coding_lengths(st.count, st.total, scatter, st.dim, 2.0), want,
                                   rtol=1e-12)
    kept = st.scatter.copy()

    def fail(_):
        raise np.linalg.LinAlgError("forced")

    monkeypatch.setattr(coding.np.linalg, "cholesky", fail)
    np.testing.assert_allclose(coding.coding_lengths(st.count, st.total, st.scatter, st.dim, 2.0), want,
                               rtol=1e-10)
    np.testing.assert_array_equal(st.scatter, kept)


def test_stats_are_the_one_hot_sums_over_each_groups_columns():
    """:func:`coding.stats_of`: counts, totals and scatters of each group, against the
    one-hot products over every column it summed before (the same bits for K >= 2 and up to
    8,192 columns: a non-member's term was an exact zero), on groups of many sizes, an empty
    one included."""
    rng = np.random.default_rng(5)
    for K, n, C in ((2, 7, 3), (9, 300, 4), (40, 1000, 12), (1, 50, 2)):
        X = rng.standard_normal((K, n)) * 50.0
        labels = rng.integers(0, C - 1, n)  # group C - 1 empty
        st = coding.stats_of(X, labels, C, 2 * K)
        onehot = np.zeros((C, n))
        onehot[labels, np.arange(n)] = 1.0
        np.testing.assert_array_equal(st.count, onehot.sum(1))
        np.testing.assert_array_equal(st.total, onehot @ X.T)
        old = np.einsum("mp,ip,jp->mij", onehot, X, X)
        if K >= 2:  # (numpy 2.4: the same sums, up to 8,192 columns; see stats_of)
            np.testing.assert_array_equal(st.scatter, old)
        np.testing.assert_allclose(st.scatter, old, rtol=1e-13, atol=1e-9)
        assert not st.scatter[C - 1].any() and st.scatter.flags.c_contiguous
