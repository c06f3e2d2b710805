"""Merging fine models into motions by coding length (this project's stage 4, not the paper's).

Under an affine camera the trajectories of one rigid motion, each stacked as a 2F vector,
lie on an affine subspace of dimension at most 3. Two motions that share the camera's
rotation (a static background and a translating object, the usual *dependent* motions of
Hopkins155) together still fit one low-dimensional linear subspace and often one
fundamental matrix, which is why subspace residuals and epipolar votes merge them. What
tells them apart is how many bits it takes to describe them: one group needs a coordinate
along the extra direction for every point, two groups do not. This is the lossy coding
length of Ma, Derksen, Hong and Wright (PAMI 2007, "Segmentation of multivariate mixed
data via lossy data compression"), used here over whole fine models:

    L(W) = (N + D) / 2 * logdet(I + D / (eps^2 N) * Wc Wc^T) + N / 2 * log(1 + |mu|^2 / eps^2)

for N trajectories W (D = 2F rows) with mean mu and centred Wc, distortion ``eps`` (px).
The trajectories are taken from the corner of the points' bounding box
(:func:`laav.refine.trajectory_matrix`), so that ``mu`` does not depend on where the
coordinates' origin is.
The merge chooses the partition of the fine models into C groups of least total length.

Everything needed is a few sufficient statistics per fine model (count, sum, scatter), in
the K principal directions of all trajectories (K = 20 holds every motion's subspace for
C <= 5 with room for noise), so each candidate group costs one small eigenvalue problem:
all 2^n - 1 groups are evaluated at once and the partitions enumerated exactly when there
are few (n = 3C fine models: 3,025 partitions for C = 3), else a greedy merge followed by
moves of single models.
"""

from __future__ import annotations

import functools

import numpy as np

from .refine import trajectory_matrix

__all__ = ["ModelStats", "model_stats", "coding_lengths", "best_partition", "shortlist",
           "merge_cost"]

#: Principal directions of all trajectories the statistics are kept in.
PROJECTION_RANK = 20
#: Most assignments (C^(n-1)) enumerated exactly; beyond, greedy merge + single moves.
_EXHAUSTIVE_MAX = 200_000
#: Most fine models whose 2^n - 1 subsets are all evaluated.
_SUBSETS_MAX_MODELS = 16


class ModelStats:
    """Sufficient statistics of each fine model's trajectories, in K principal directions.

    Attributes
    ----------
    count : ndarray of shape (n,)
    total : ndarray of shape (n, K)
        Sum of the projected trajectories.
    scatter : ndarray of shape (n, K, K)
        Sum of their outer products.
    dim : int
        D = 2F, the trajectories' dimension.
    """

    def __init__(self, count, total, scatter, dim):
        self.count, self.total, self.scatter, self.dim = count, total, scatter, int(dim)

    @property
    def n_models(self) -> int:
        return int(self.count.size)

    def union(self, members: np.ndarray) -> tuple:
        """(count, total, scatter) of the groups ``members`` (G, n) of 0/1 weights."""
        m = np.asarray(members, dtype=np.float64)
        K = self.scatter.shape[-1]
        # a matrix product over the flattened scatters: 4x faster than the same einsum
        return (m @ self.count, m @ self.total,
                (m @ self.scatter.reshape(self.n_models, K * K)).reshape(-1, K, K))


def model_stats(points: np.ndarray, fine_labels: np.ndarray, n_models: int,
                rank: int = PROJECTION_RANK) -> ModelStats:
    """Statistics of every fine model.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    fine_labels : ndarray of shape (P,)
        Fine model of every point, -1 for points in none (ignored).
    n_models : int
    rank : int
        K.
    """
    cov = fine_labels >= 0
    return stats_of(principal_trajectories(points, cov, rank), fine_labels[cov], n_models,
                    2 * points.shape[0])


def principal_trajectories(points: np.ndarray, columns=None,
                           rank: int = PROJECTION_RANK) -> np.ndarray:
    """The trajectories (:func:`laav.refine.trajectory_matrix`, origin at the points'
    corner: translation-free) in their ``rank`` principal directions: (K, n), over the
    points ``columns`` (a mask or indices; None: all P of ``points`` (F, P, 2))."""
    W = trajectory_matrix(points)
    if columns is not None:
        W = W[:, columns]
    k = min(rank, *W.shape)
    U = np.linalg.svd(W, full_matrices=False)[0][:, :k]
    return U.T @ W


def stats_of(X: np.ndarray, labels: np.ndarray, n_models: int, dim: int) -> ModelStats:
    """:class:`ModelStats` of the groups ``labels`` (n,) in ``0 .. n_models-1`` of the
    projected trajectories ``X`` (K, n) (:func:`principal_trajectories`); ``dim`` = 2F.

    Each group's scatter is summed over its own columns only, not as one product with a
    one-hot matrix over every column (``einsum("mp,ip,jp->mij", onehot, X, X)``, the way
    before 2026-12-05: 5x the arithmetic, a third of a descent's sweep). The terms a
    non-member added there were exact zeros, and with numpy 2.4 the members' terms are
    summed in the same order for K >= 2 and up to 8,192 columns (every Hopkins155 call
    checked: the same bits); beyond 8,192 columns the one-hot product summed in buffered
    chunks, and the two differ by about 1e-15 relative."""
    onehot = np.zeros((n_models, labels.size))
    onehot[labels, np.arange(labels.size)] = 1.0
    count = onehot.sum(1)
    total = onehot @ X.T
    K = X.shape[0]
    scatter = np.zeros((n_models, K, K))
    for m in range(n_models):
        Xm = X[:, labels == m]
        np.einsum("ip,jp->ij", Xm, Xm, out=scatter[m])
    return ModelStats(count, total, scatter, dim)


def _log_det_1p(S: np.ndarray, remake=None) -> np.ndarray:
    """``log det(I + S)`` = the sum of ``log1p`` of the eigenvalues of the symmetric
    positive semi-definite ``S`` (G, K, K), by a Cholesky factorisation (about 4x faster
    than the eigenvalues, which cost 60 ms a run for the 4,095 groups of 12 fine models).
    Rounding may leave ``S`` slightly indefinite; its tiny negative eigenvalues then count
    as they are (the eigenvalue route clipped them at 0: a difference far below the
    lengths' own rounding). Should ``I + S`` not be positive definite (an eigenvalue of
    ``S`` at or below -1, never for a covariance), the whole batch goes by the
    eigenvalues clipped at 0.

    ``remake``: a caller that hands over ``S`` (it is overwritten with ``I + S``) passes
    a function that makes ``S`` again, for that fallback; None: ``S`` is left as it was."""
    K = S.shape[-1]
    IS = S.copy() if remake is None else S
    IS.reshape(S.shape[:-2] + (K * K,))[..., ::K + 1] += 1.0  # I + S
    try:
        L = np.linalg.cholesky(IS)
    except np.linalg.LinAlgError:
        S = S if remake is None else remake()
        return np.log1p(np.clip(np.linalg.eigvalsh(S), 0.0, None)).sum(-1)
    return 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(-1)


def coding_lengths(count, total, scatter, dim: int, eps: float) -> np.ndarray:
    """Lossy coding length (nats) of groups given their statistics.

    Parameters
    ----------
    count : ndarray of shape (G,)
    total : ndarray of shape (G, K)
    scatter : ndarray of shape (G, K, K)
    dim : int
        D.
    eps : float
        Distortion (px).

    Returns
    -------
    ndarray of shape (G,)
        0 for empty groups.
    """
    n = np.maximum(np.asarray(count, dtype=np.float64), 1.0)
    mu = total / n[:, None]
    e2 = float(eps) ** 2
    a = dim / e2

    def scaled_covariance():
        # a cov = a (scatter / n - mu mu^T), in place (the groups' K x K arrays are large)
        # (C order whatever the scatter's: _log_det_1p adds the identity through a flat view)
        S = np.multiply(scatter, (a / n)[:, None, None], order="C")
        outer = np.multiply(mu[:, :, None], mu[:, None, :])
        outer *= a
        S -= outer
        return S

    L = ((n + dim) / 2.0 * _log_det_1p(scaled_covariance(), remake=scaled_covariance)
         + n / 2.0 * np.log1p((mu ** 2).sum(1) / e2))
    return np.where(np.asarray(count) > 0, L, 0.0)


def coding_lengths_one_moved(count: float, total: np.ndarray, scatter: np.ndarray, X: np.ndarray,
                             dim: int, eps: float, sign: int) -> np.ndarray:
    """:func:`coding_lengths` of one group with each point alone added (``sign`` +1) or
    taken out (``sign`` -1), for every point at once: (P,).

    ``count``, ``total`` (K,), ``scatter`` (K, K): the group's statistics; ``X`` (P, K):
    the points (a point taken out must be in the group). The same numbers as
    :func:`coding_lengths` of the P changed groups, to rounding, from one K x K
    factorisation instead of P: with ``M`` the group's scatter about its mean ``mu`` and
    ``n' = count + sign``, moving ``x`` changes ``M`` by ``sign n / n' (x - mu)(x - mu)^T``
    (a rank-one change), so ``det(I + a M' / n') = det(B) (1 + c d^T B^-1 d)`` with
    ``B = I + a M / n'``, ``d = x - mu``, ``c = sign a n / n'^2``, ``a = dim / eps^2``.
    A group left empty has length 0. Should rounding make ``1 + c d^T B^-1 d`` non-positive
    for a point taken out (never for a covariance), that point's length is NaN (a caller
    then skips that move) rather than a huge negative number.
    """
    n = float(count)
    n1 = n + sign
    e2 = float(eps) ** 2
    if n1 <= 0:
        return np.zeros(X.shape[0])
    if n <= 0:  # one point into an empty group: no scatter, its mean term alone
        return 0.5 * np.log1p(np.add.reduce(X * X, axis=1) / e2)
    a = dim / e2
    K = total.size
    B = (a / n1) * (scatter - np.outer(total, total) / n)
    B.flat[::K + 1] += 1.0
    B = (B + B.T) / 2.0
    try:
        Lb = np.linalg.cholesky(B)
        logdet_b = 2.0 * np.log(np.diagonal(Lb)).sum()
        # d^T B^-1 d for every point, by the triangular factor: |Lb^-1 d|^2
        Y = np.linalg.solve(Lb, (X - total / n).T)  # (K, P)
    except np.linalg.LinAlgError:
        w, V = np.linalg.eigh(B)
        w = np.clip(w, 1.0, None)  # (B >= I for a covariance)
        logdet_b = float(np.log(w).sum())
        Y = (V / np.sqrt(w)).T @ (X - total / n).T
    q = np.add.reduce(Y * Y, axis=0)
    inner = 1.0 + (sign * a * n / n1 ** 2) * q
    inner[inner <= 0.0] = np.nan
    t1 = total + sign * X  # (P, K)
    return ((n1 + dim) / 2.0 * (logdet_b + np.log(inner))
            + n1 / 2.0 * np.log1p(np.add.reduce(t1 * t1, axis=1) / (n1 * n1 * e2)))


def labelling_coding_length(points: np.ndarray, labels: np.ndarray, n_groups: int,
                            eps: float, projected: np.ndarray | None = None,
                            stats: ModelStats | None = None) -> float:
    """Lossy coding length (nats) of the trajectories grouped by ``labels``: the sum of
    :func:`coding_lengths` over the groups (distortion ``eps`` px), without a membership
    term, in the principal directions of all trajectories (:func:`model_stats`).

    ``points`` (F, P, 2), ``labels`` (P,) in ``0 .. n_groups-1``. LAAV's own chain scores
    whole labellings with it (:func:`laav.voting.joint_score`), the motion count its
    candidates (per point, :mod:`laav.motions`). ``projected``: the points'
    :func:`principal_trajectories` (K, P), when the caller scores many labellings of them;
    ``stats``: their :func:`stats_of` for ``labels``, when already computed."""
    labels = np.asarray(labels)
    if stats is not None:
        st = stats
    else:
        st = (model_stats(points, labels, n_groups) if projected is None
              else stats_of(projected, labels, n_groups, 2 * points.shape[0]))
    # summed in sorted order: the same partition numbered otherwise gets the same length,
    # bit for bit (LAAV's own chain keeps the first of equal scores)
    return float(np.sort(coding_lengths(st.count, st.total, st.scatter, st.dim, eps)).sum())


def merge_cost(stats: ModelStats, eps: float) -> np.ndarray:
    """Coding length gained by merging each pair of models, per point (nats), (n, n).

    ``L(j + k) - L(j) - L(k)`` divided by ``n_j + n_k``; negative when one group is the
    cheaper description; 0 on the diagonal.
    """
    n = stats.n_models
    single = coding_lengths(stats.count, stats.total, stats.scatter, stats.dim, eps)
    jj, kk = np.triu_indices(n, 1)
    pair = np.zeros((jj.size, n))
    pair[np.arange(jj.size), jj] = 1.0
    pair[np.arange(jj.size), kk] = 1.0
    both = coding_lengths(*stats.union(pair), stats.dim, eps)
    out = np.zeros((n, n))
    out[jj, kk] = out[kk, jj] = (both - single[jj] - single[kk]) / (stats.count[jj] + stats.count[kk])
    return out


@functools.lru_cache(maxsize=32)
def _assignments(n: int, C: int) -> np.ndarray:
    """Every partition of n models into C non-empty groups, once: groups numbered in order
    of their first model (model 0 in group 0), (A, n), read-only."""
    # every assignment of models 1..n-1, in itertools.product order (the last model's group
    # changing fastest), built as int8 digits: no Python tuples (about 30 MB at 12 models)
    idx = np.arange(C ** (n - 1), dtype=np.int64)
    A = np.zeros((idx.size, n), dtype=np.int8)
    for j in range(1, n):
        A[:, j] = (idx // C ** (n - 1 - j)) % C
    del idx
    first = np.stack([np.where((A == c).any(1), (A == c).argmax(1), n) for c in range(C)], axis=1)
    A = A[np.all(np.diff(first, axis=1) > 0, axis=1) & (first[:, -1] < n)]  # all used, in order
    A = A.astype(np.int64)
    A.flags.writeable = False
    return A


def _total(stats, assign, C, eps) -> float:
    m = (assign[None, :] == np.arange(C)[:, None]).astype(np.float64)
    return float(coding_lengths(*stats.union(m), stats.dim, eps).sum())


def _exact(n: int, C: int) -> bool:
    """Whether every partition of ``n`` models into ``C`` groups is enumerated."""
    return n <= _SUBSETS_MAX_MODELS and C ** (n - 1) <= _EXHAUSTIVE_MAX


def _every_partition(stats: ModelStats, C: int, eps: float, min_count: int = 1) -> tuple:
    """Every partition of the models into ``C`` groups (:func:`_assignments`, (A, n)), its
    total coding length (A,) and whether each of its groups holds at least ``min_count``
    points (A,) bool: the 2^n - 1 groups' lengths are evaluated once, and a partition sums
    its groups' (left to right, as ``lengths[groups].sum(1)`` does for the C < 8 groups
    this branch enumerates: the same bits)."""
    n = stats.n_models
    bits = (np.arange(1, 2 ** n)[:, None] >> np.arange(n)) & 1  # every non-empty subset
    # in chunks: the subsets' K x K scatters are 13 MB at 12 models, several times over
    cost = np.concatenate([coding_lengths(*stats.union(bits[i:i + 512]), stats.dim, eps)
                           for i in range(0, bits.shape[0], 512)])
    small = (bits @ stats.count) < min_count
    groups = _group_subsets(n, C)  # (C, A): one contiguous row per group, gathered at once
    # (a gather by row and a sum of C rows: 5x faster than the (A, C) gather, and its
    # reduction over a short axis, for the 86,526 partitions of 12 models into 3)
    tot = cost.take(groups[0])
    ok = ~small.take(groups[0])
    for g in groups[1:]:
        tot = tot + cost.take(g)
        ok &= ~small.take(g)
    return _assignments(n, C), tot, ok


@functools.lru_cache(maxsize=32)
def _group_subsets(n: int, C: int) -> np.ndarray:
    """For every partition of :func:`_assignments`, each group's models as the index of
    their subset in :func:`_every_partition` (its bit mask - 1), (C, A), read-only."""
    A = _assignments(n, C)
    codes = np.stack([(A == c).astype(np.int64) @ (1 << np.arange(n)) for c in range(C)]) - 1
    codes.flags.writeable = False
    return codes


def best_partition(stats: ModelStats, n_groups: int, eps: float) -> tuple[np.ndarray, float]:
    """The assignment of the models to ``n_groups`` groups of least total coding length.

    Exact (every partition) when there are at most ``_EXHAUSTIVE_MAX`` assignments,
    otherwise greedy pairwise merging from single models, then single-model moves while
    the total decreases.

    Returns
    -------
    assign : ndarray of shape (n,), int64
        Group of each model (renumbered in order of first appearance).
    total : float
        Its total coding length (nats).
    """
    n, C = stats.n_models, int(n_groups)
    if n <= C:
        return np.arange(n, dtype=np.int64), _total(stats, np.arange(n), max(n, 1), eps)
    if _exact(n, C):
        A, tot, _ = _every_partition(stats, C, eps)
        k = int(np.argmin(tot))
        return A[k].copy(), float(tot[k])
    # greedy: merge the pair of groups whose union adds the least length
    assign = np.arange(n, dtype=np.int64)
    while assign.max() + 1 > C:
        G = assign.max() + 1
        m = (assign[None, :] == np.arange(G)[:, None]).astype(np.float64)
        single = coding_lengths(*stats.union(m), stats.dim, eps)
        jj, kk = np.triu_indices(G, 1)
        both = coding_lengths(*stats.union(m[jj] + m[kk]), stats.dim, eps)
        b = int(np.argmin(both - single[jj] - single[kk]))
        assign[assign == kk[b]] = jj[b]
        assign = np.unique(assign, return_inverse=True)[1].astype(np.int64)
    best = _total(stats, assign, C, eps)
    improved = True
    while improved:
        improved = False
        for i in range(n):
            for c in range(C):
                if c == assign[i] or (assign == assign[i]).sum() == 1:
                    continue
                trial = assign.copy()
                trial[i] = c
                t = _total(stats, trial, C, eps)
                if t < best - 1e-9:
                    assign, best, improved = trial, t, True
    _, first = np.unique(assign, return_index=True)
    rank = np.argsort(np.argsort(first))
    return rank[assign].astype(np.int64), best


def _n_least(values: np.ndarray, n: int) -> np.ndarray:
    """Indices of the ``n`` least ``values`` in increasing order, ties in index order:
    ``np.argsort(values, kind="stable")[:n]``, sorting only those up to the n-th least
    (86,526 partitions of 12 models into 3, of which 10 are kept)."""
    idx = np.arange(values.size)
    if values.size > n:
        keep = ~(values > np.partition(values, n - 1)[n - 1])  # (a NaN kept: sorted last)
        idx, values = idx[keep], values[keep]
    return idx[np.argsort(values, kind="stable")][:n]


def shortlist(stats: ModelStats, n_groups: int, eps: float, n_best: int,
              min_count: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The ``n_best`` partitions of least total coding length whose groups all hold at
    least ``min_count`` points (the joint merge of :func:`laav.coarse.merge_models`
    re-ranks them by their epipolar fit).

    Exact when :func:`best_partition` is; otherwise the greedy partition and every
    partition one model move away from it.

    Returns
    -------
    assign : ndarray of shape (K, n), int64
        Group of each model per partition (K <= ``n_best``; groups numbered in order of
        their first model), by increasing total length; K = 0 when no partition has
        ``min_count`` points in every group.
    total : ndarray of shape (K,)
        Their total coding lengths (nats).
    """
    n, C = stats.n_models, int(n_groups)
    if n <= C:
        A = np.arange(n, dtype=np.int64)[None]
        tot = np.array([_total(stats, A[0], max(n, 1), eps)])
        ok = np.array([bool(np.all(stats.count >= min_count))])
    elif _exact(n, C):
        A, tot, ok = _every_partition(stats, C, eps, min_count)
    else:  # the greedy partition and its one-move neighbours
        best, _ = best_partition(stats, C, eps)
        rows = [best]
        for i in range(n):
            for c in range(C):
                if c != best[i] and (best == best[i]).sum() > 1:
                    trial = best.copy()
                    trial[i] = c
                    _, first = np.unique(trial, return_index=True)
                    rank = np.argsort(np.argsort(first))
                    rows.append(rank[trial])
        A = np.unique(np.array(rows, dtype=np.int64), axis=0)
        tot = np.array([_total(stats, a, C, eps) for a in A])
        size = np.stack([(A == c) @ stats.count for c in range(C)], axis=1)
        ok = size.min(axis=1) >= min_count
    ok = np.flatnonzero(ok)
    order = ok[_n_least(tot[ok], n_best)]
    return np.array(A[order], dtype=np.int64).reshape(-1, n), tot[order]
