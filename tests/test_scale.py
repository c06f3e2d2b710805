"""Thousands of tracks (issue 14 item 8): no stage holds a P x P array.

The neighbourhoods (KD-tree), the atom graph (sparse overlaps, Prim's pass over the seeds)
and Random Voting's consensus (low-rank co-association) are checked against direct dense
computations, and the memory of the stages is measured at P = 3,000.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

import laav
from laav.atoms import Neighbourhoods, build_atoms, trajectory_distances
from laav.graph import atom_graph
from laav.synthetic import make_sequence


def _random_tracks(rng, F, P):
    """Clustered random walks: many near pairs, some far."""
    start = rng.uniform(0, 200, (P, 2))
    steps = rng.normal(0, rng.uniform(0.5, 4), (F, P, 2))
    steps[:, : P // 2] += rng.normal(0, 2, (F, 1, 2))  # half the points move together
    return start + np.cumsum(steps, axis=0)


def _direct_distances(points):
    """Largest Euclidean distance over the 6 evenly spaced frames, by explicit loops."""
    F, P, _ = points.shape
    frames = sorted({int(round(f)) for f in np.linspace(0, F - 1, min(6, F))})
    D = np.zeros((P, P))
    for i in range(P):
        for f in frames:
            D[i] = np.maximum(D[i], np.hypot(*(points[f] - points[f, i]).T))
    return D


@pytest.mark.parametrize("seed", range(6))
def test_neighbourhoods_equal_the_dense_computation(seed):
    rng = np.random.default_rng(seed)
    F, P = int(rng.integers(2, 40)), int(rng.integers(5, 300))
    pts = _random_tracks(rng, F, P)
    D = _direct_distances(pts)
    dense = trajectory_distances(pts)
    nb = Neighbourhoods(pts)
    # radii in an order that makes the cache grow, shrink and grow again
    for r in (15.0, 5.0, 60.0, 0.5, 30.0, 1e4):
        indptr, idx, dist = nb.within(r)
        assert indptr.shape == (P + 1,) and indptr[-1] == idx.size == dist.size
        for i in range(P):
            row = idx[indptr[i]:indptr[i + 1]]
            assert np.all(np.diff(row) > 0), "neighbours not increasing"
            near = np.flatnonzero(D[i] <= r)
            ambiguous = np.abs(D[i] - r) < 1e-9 * max(r, 1.0)  # rounding may decide either way
            assert set(row) ^ set(near) <= set(np.flatnonzero(ambiguous))
            # bit for bit the matrix the pipeline used before
            assert np.array_equal(row, np.flatnonzero(dense[i] <= r))
            assert np.array_equal(dist[indptr[i]:indptr[i + 1]], dense[i, row])
            assert np.allclose(dist[indptr[i]:indptr[i + 1]], D[i, row], rtol=1e-12, atol=1e-9)
    i, j = rng.integers(0, P, 50), rng.integers(0, P, 50)
    assert np.array_equal(nb.distances(i, j), dense[i, j])


def _dense_graph_edges(seq, atoms, params):
    """The atom graph's edges and overlaps as the dense implementation built them."""
    from scipy.sparse.csgraph import minimum_spanning_tree

    N = atoms.n_atoms
    M = np.zeros((N, atoms.n_points))
    for a, m in enumerate(atoms.members):
        M[a, m] = 1
    shared = (M @ M.T).astype(np.int64)
    np.fill_diagonal(shared, 0)
    D = _direct_distances(seq.points)
    Ds = D[np.ix_(atoms.seeds, atoms.seeds)]
    np.fill_diagonal(Ds, np.inf)
    k = min(params.graph_neighbors, N - 1)
    adj = shared > 0
    order = np.argsort(Ds, axis=1, kind="stable")[:, :k]
    adj[np.repeat(np.arange(N), k), order.ravel()] = True
    Dm = np.where(np.isfinite(Ds), Ds, 0.0) + 1e-9
    np.fill_diagonal(Dm, 0.0)
    adj |= minimum_spanning_tree(Dm).toarray() > 0
    adj |= adj.T
    i, j = np.nonzero(np.triu(adj, 1))
    return np.stack([i, j], axis=1), shared[i, j]


@pytest.mark.parametrize("n_objects, seed, r1, r2", [(1, 0, 20.0, 40.0), (2, 1, 20.0, 40.0),
                                                      (2, 2, 8.0, 25.0), (3, 3, 30.0, 70.0)])
def test_graph_equals_the_dense_computation(n_objects, seed, r1, r2):
    seq = make_sequence(n_objects=n_objects, n_frames=15, n_points=350, noise=0.3, rng=seed)
    p = laav.LaavParams(r1=r1, r2=r2)
    atoms = build_atoms(seq, p, np.random.default_rng(seed))
    assert atoms.n_atoms > 5
    g = atom_graph(seq, atoms, p)
    edges, overlap = _dense_graph_edges(seq, atoms, p)
    assert np.array_equal(g.edges, edges)
    assert np.array_equal(g.overlap, overlap)


def test_atoms_from_neighbourhoods_equal_atoms_from_the_dense_matrix():
    seq = make_sequence(n_objects=2, n_frames=12, n_points=400, noise=0.5, rng=4)
    D = trajectory_distances(seq.points)
    nb = Neighbourhoods(seq.points)
    for r1, r2 in ((20.0, 40.0), (10.0, 25.0), (30.0, 60.0)):
        p = laav.LaavParams(r1=r1, r2=r2)
        a = build_atoms(seq, p, np.random.default_rng(1), D)
        b = build_atoms(seq, p, np.random.default_rng(1), nb)
        assert len(a.members) == len(b.members)
        assert all(np.array_equal(x, y) for x, y in zip(a.members, b.members))
        assert np.array_equal(a.owner, b.owner) and np.array_equal(a.seeds, b.seeds)


@pytest.mark.parametrize("seed", range(8))
def test_consensus_equals_dense_spectral_clustering(seed):
    from sklearn.cluster import SpectralClustering

    from laav._spectral import coassociation_clustering

    rng = np.random.default_rng(seed)
    P, C, T = int(rng.integers(5, 400)), int(rng.integers(2, 5)), int(rng.integers(2, 11))
    truth = rng.integers(0, C, P)
    labs = np.stack([np.where(rng.random(P) < rng.uniform(0.02, 0.4), rng.integers(0, C, P),
                              rng.permutation(C)[truth]) for _ in range(T)])
    A = (labs[:, :, None] == labs[:, None, :]).mean(axis=0)
    ref = SpectralClustering(n_clusters=C, affinity="precomputed", assign_labels="cluster_qr",
                             random_state=seed).fit_predict(A + 1e-6)
    assert np.array_equal(coassociation_clustering(labs, C, seed), ref)


def test_pipeline_reuses_the_neighbourhoods_across_radii():
    seq = make_sequence(n_objects=1, n_frames=10, n_points=250, rng=3)
    pipe = laav.Pipeline(seq, 2, seed=1)
    nb = pipe._distances
    for change in ({"r2": 60.0}, {"r2": 30.0, "r1": 10.0}, {"r1": 25.0, "r2": 45.0}):
        res = pipe.update(**change)
        assert pipe._distances is nb
        fresh = laav.segment(seq, 2, pipe.params, seed=1)
        assert np.array_equal(res.labels, fresh.labels)
        assert all(np.array_equal(x, y) for x, y in zip(res.atoms.members, fresh.atoms.members))


def test_no_stage_allocates_a_p_by_p_array():
    """P = 6,000: a P x P float64 array is 288 MB; every stage allocates under a third of it.
    (At 3,000 the bound, 24 MB, was below what the joint merge allocates whatever P is:
    its pairwise votes and partition search grow with the fine models, 26 MB at 12.)"""
    from laav.coarse import merge_models
    from laav.multicut import solve_multicut
    from laav.pipeline import _stage_rngs
    from laav.rv import consensus
    from laav.voting import random_voting

    P = 6000
    seq = make_sequence(n_objects=2, n_frames=8, n_points=P, noise=0.5, rng=0)
    dense = P * P * 8
    # first-use imports allocate too (tracemalloc counts them): get them done beforehand
    laav.segment(make_sequence(n_objects=2, n_frames=8, n_points=200, rng=1), 3, seed=0)
    consensus([(np.arange(50) % 3,) + (None,) * 5] * 2, 3, np.random.default_rng(0))
    p, rngs, st = laav.LaavParams(), _stage_rngs(0), {}
    stages = {
        "atoms": lambda: build_atoms(seq, p, np.random.default_rng(rngs["atoms"]),
                                     Neighbourhoods(seq.points)),
        "graph": lambda: atom_graph(seq, st["atoms"], p),
        "multicut": lambda: solve_multicut(st["graph"], p.n_fine(3)),
        "coarse": lambda: merge_models(seq, st["atoms"], st["multicut"], 3, p,
                                       np.random.default_rng(rngs["coarse"])),
        "voting": lambda: random_voting(seq, 3, p, np.random.default_rng(rngs["voting"]),
                                        init_labels=st["coarse"].point_labels),
        # Random Voting's consensus, forced (it runs only when no trial converges)
        "consensus": lambda: consensus([(np.random.default_rng(t).integers(0, 3, P),) + (None,) * 5
                                        for t in range(10)], 3, np.random.default_rng(0)),
    }
    peaks = {}
    tracemalloc.start()
    try:
        for name, run in stages.items():
            tracemalloc.reset_peak()
            base = tracemalloc.get_traced_memory()[0]
            st[name] = run()
            peaks[name] = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    assert st["atoms"].n_atoms > 50
    for name, peak in peaks.items():
        assert peak < dense / 3, f"{name} allocated {peak / 2**20:.0f} MB"
