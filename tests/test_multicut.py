"""Minimum cost multicut: GAEC, Kernighan-Lin, the count adjustment, the exact oracle.

Measured with the generators below (ER p=0.4 and 3-NN graphs, 8-14 nodes, costs N(0, 1)):
on 200 graphs (seeds 0-99 of each kind) GAEC alone is optimal on 82.5 %, GAEC + KL on
89.5 %, with mean relative gap 0.32 % and largest 18.9 %; KL never worsened GAEC and its
result admitted no improving single-node move. On the 60 graphs of
``test_gaec_kl_close_to_exact_optimum`` (seeds 0-29 of each kind) GAEC+KL is exact on 55
(91.7 %), mean relative gap 0.20 %, largest 5.9 % (ER seed 19); the misses are ER 15, 19,
22 and kNN 18, 27. (Same numbers before and after the KL split fix of c0d5750.)
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from laav.graph import AtomGraph
from laav.multicut import (
    exact_multicut,
    gaec,
    kernighan_lin,
    multicut_objective,
    solve_multicut,
)

# --------------------------------------------------------------------------- helpers


def er_graph(rng, n, p=0.4):
    iu = np.triu_indices(n, 1)
    keep = rng.random(iu[0].size) < p
    return np.stack([iu[0][keep], iu[1][keep]], 1).astype(np.int64)


def knn_graph(rng, n, k=3):
    x = rng.random((n, 2))
    D = ((x[:, None] - x[None]) ** 2).sum(-1)
    np.fill_diagonal(D, np.inf)
    nn = np.argsort(D, 1)[:, :k]
    pairs = {(min(i, j), max(i, j)) for i in range(n) for j in nn[i]}
    return np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)


def random_instance(kind, seed, lo=8, hi=15):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(lo, hi))
    e = er_graph(rng, n) if kind == "er" else knn_graph(rng, n)
    c = rng.normal(0, 1, e.shape[0])
    return n, e, c


def n_components(n, edges):
    if edges.shape[0] == 0:
        return n
    A = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(A, directed=False)[0]


def segments_connected(n, edges, labels):
    """True when every segment induces a connected subgraph."""
    for s in np.unique(labels):
        nodes = np.flatnonzero(labels == s)
        if nodes.size == 1:
            continue
        inside = np.isin(edges[:, 0], nodes) & np.isin(edges[:, 1], nodes)
        pos = {v: i for i, v in enumerate(nodes.tolist())}
        sub = np.array([[pos[a], pos[b]] for a, b in edges[inside].tolist()],
                       dtype=np.int64).reshape(-1, 2)
        if n_components(nodes.size, sub) != 1:
            return False
    return True


def same_partition(a, b):
    a = np.asarray(a)
    b = np.asarray(b)
    return np.array_equal(a[:, None] == a[None, :], b[:, None] == b[None, :])


def set_partitions(n):
    """All partitions of range(n) as restricted growth strings."""
    lab = [0] * n

    def rec(i, m):
        if i == n:
            yield np.array(lab)
            return
        for v in range(m + 1):
            lab[i] = v
            yield from rec(i + 1, max(m, v + 1))

    if n == 0:
        yield np.zeros(0, dtype=int)
    else:
        lab[0] = 0
        yield from rec(1, 1)


def brute_force_optimum(n, edges, costs):
    """Least objective over partitions whose segments are connected (= valid multicuts)."""
    best = np.inf
    for lab in set_partitions(n):
        if segments_connected(n, edges, lab):
            best = min(best, multicut_objective(edges, costs, lab))
    return best


def make_graph(n, edges, costs):
    E = edges.shape[0]
    return AtomGraph(edges=edges, errors=np.zeros(E), costs=costs,
                     overlap=np.zeros(E, np.int64), positions=np.zeros((1, n, 2)), n_nodes=n)


@st.composite
def signed_graphs(draw, min_nodes=2, max_nodes=12):
    n = draw(st.integers(min_nodes, max_nodes))
    iu = np.triu_indices(n, 1)
    keep = draw(st.lists(st.booleans(), min_size=iu[0].size, max_size=iu[0].size))
    keep = np.array(keep, dtype=bool)
    edges = np.stack([iu[0][keep], iu[1][keep]], 1).astype(np.int64).reshape(-1, 2)
    costs = draw(st.lists(st.floats(-5, 5, allow_nan=False, allow_infinity=False),
                          min_size=edges.shape[0], max_size=edges.shape[0]))
    return n, edges, np.array(costs, dtype=float)


# --------------------------------------------------------------------------- the oracle


@pytest.mark.parametrize("seed", range(12))
def test_exact_multicut_matches_brute_force(seed):
    """The MILP oracle itself is right: same optimum as enumerating all partitions."""
    rng = np.random.default_rng(100 + seed)
    n = int(rng.integers(3, 8))
    e = er_graph(rng, n, 0.6)
    c = rng.normal(0, 1, e.shape[0])
    lab = exact_multicut(n, e, c)
    assert lab.shape == (n,)
    assert segments_connected(n, e, lab)
    assert multicut_objective(e, c, lab) == pytest.approx(brute_force_optimum(n, e, c), abs=1e-9)


# --------------------------------------------------------------------------- GAEC + KL


def test_gaec_kl_close_to_exact_optimum():
    n_exact, gaps, rows = 0, [], []
    for kind in ("er", "knn"):
        for seed in range(30):
            n, e, c = random_instance(kind, seed)
            g, _, _ = gaec(n, e, c)
            k = kernighan_lin(n, e, c, g)
            og = multicut_objective(e, c, g)
            ok = multicut_objective(e, c, k)
            oe = multicut_objective(e, c, exact_multicut(n, e, c))
            rows.append((kind, seed, og, ok, oe))
            assert ok >= oe - 1e-9, "heuristic beat the exact optimum: oracle is wrong"
            assert ok <= og + 1e-9, "KL worsened GAEC"
            n_exact += ok <= oe + 1e-9
            gaps.append((ok - oe) / max(abs(oe), 1e-12))
    frac = n_exact / len(rows)
    worst = [r for r in rows if r[3] > r[4] + 1e-9]
    assert frac >= 0.9, f"GAEC+KL exact on only {frac:.0%}: {worst}"
    assert np.mean(gaps) <= 0.05, f"mean relative gap {np.mean(gaps):.2%}"


def test_kl_improves_a_suboptimal_gaec_solution():
    """ER seed 15 is one where GAEC is not optimal and KL closes most of the gap."""
    n, e, c = random_instance("er", 15)
    g, _, _ = gaec(n, e, c)
    k = kernighan_lin(n, e, c, g)
    og, ok = multicut_objective(e, c, g), multicut_objective(e, c, k)
    oe = multicut_objective(e, c, exact_multicut(n, e, c))
    assert oe < og - 1e-6  # the instance is a meaningful one
    assert ok < og - 1e-6


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(signed_graphs())
def test_kl_never_worsens_gaec(graph):
    n, e, c = graph
    g, _, _ = gaec(n, e, c)
    k = kernighan_lin(n, e, c, g)
    assert k.shape == (n,)
    assert multicut_objective(e, c, k) <= multicut_objective(e, c, g) + 1e-9
    assert segments_connected(n, e, k)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(signed_graphs(), st.integers(0, 2**32 - 1))
def test_kl_from_any_start_is_no_worse_and_locally_optimal(graph, seed):
    n, e, c = graph
    start = np.random.default_rng(seed).integers(0, 3, n)
    k = kernighan_lin(n, e, c, start)
    ok = multicut_objective(e, c, k)
    assert ok <= multicut_objective(e, c, start) + 1e-9
    assert segments_connected(n, e, k)
    # no single-node move to another (or a new) segment improves the result
    for u in range(n):
        for t in [*np.unique(k).tolist(), int(k.max()) + 1]:
            if t == k[u]:
                continue
            moved = k.copy()
            moved[u] = t
            # (KL ignores gains below 1e-9 by design, hence the tolerance)
            assert multicut_objective(e, c, moved) >= ok - 1e-6, f"move {u} -> {t} improves"


def test_kl_keeps_improving_after_splitting_disconnected_segments():
    """Regression (found by hypothesis): from this disconnected start KL used to stop at
    objective -3 and only then split the segment {1, 2}, although moving node 4 next to
    node 0 gives -4. KL now splits first and goes on improving."""
    e = np.array([[0, 1], [0, 2], [0, 3], [0, 4], [0, 5], [3, 6], [3, 7], [3, 8], [4, 5],
                  [4, 6], [4, 7], [4, 8], [5, 6], [5, 8]])
    c = np.array([0.0, 0, 0, 1, -1, 0, 0, 0, 0, 0, 0, -1, 0, -2])
    start = np.array([2, 1, 1, 0, 0, 0, 0, 0, 0])
    k = kernighan_lin(9, e, c, start)
    assert segments_connected(9, e, k)
    assert multicut_objective(e, c, k) == pytest.approx(-4.0)
    assert multicut_objective(e, c, exact_multicut(9, e, c)) == pytest.approx(-4.0)


@settings(max_examples=60, deadline=None)
@given(signed_graphs())
def test_gaec_stops_with_no_positive_join_and_connected_segments(graph):
    n, e, c = graph
    lab, steps, step_costs = gaec(n, e, c)
    assert lab.shape == (n,)
    assert segments_connected(n, e, lab)
    assert np.all(step_costs > 0)
    segs = np.unique(lab)
    assert np.array_equal(segs, np.arange(segs.size))  # relabelled 0..K-1
    # summed cost between any two segments is <= 0 (else GAEC would have contracted)
    between = {}
    for (u, v), w in zip(e.tolist(), c.tolist()):
        a, b = sorted((lab[u], lab[v]))
        if a != b:
            between[(a, b)] = between.get((a, b), 0.0) + w
    assert all(w <= 1e-9 for w in between.values()), between


@settings(max_examples=60, deadline=None)
@given(signed_graphs())
def test_gaec_contractions_replay_to_its_labels(graph):
    n, e, c = graph
    lab, steps, step_costs = gaec(n, e, c)
    assert steps.shape == (step_costs.size, 2)
    parent = list(range(n))

    def find(x):
        while parent[x] != x:
            x = parent[x]
        return x

    for kept, merged in steps.tolist():
        # both are current representatives, as documented
        assert find(kept) == kept and find(merged) == merged and kept != merged
        parent[merged] = kept
    replay = np.array([find(i) for i in range(n)])
    assert same_partition(replay, lab)
    assert np.unique(lab).size == n - steps.shape[0]


@settings(max_examples=40, deadline=None)
@given(signed_graphs(min_nodes=2), st.integers(1, 12))
def test_gaec_with_n_clusters_on_connected_graphs(graph, k):
    n, e, c = graph
    lab, _, _ = gaec(n, e, c, n_clusters=k)
    comps = n_components(n, e)
    assert np.unique(lab).size == max(min(k, n), comps)
    assert segments_connected(n, e, lab)


# --------------------------------------------------------------------------- solve_multicut


@pytest.mark.parametrize("kind", ["er", "knn"])
@pytest.mark.parametrize("seed", range(8))
def test_solve_multicut_exact_count_and_connected(kind, seed):
    n, e, c = random_instance(kind, 200 + seed, 4, 15)
    g = make_graph(n, e, c)
    connected = n_components(n, e) == 1
    gl, steps, step_costs = gaec(n, e, c)
    for k in range(1, n + 2):
        mc = solve_multicut(g, k)
        m = mc.atom_labels
        assert m.shape == (n,)
        assert mc.n_models == min(k, n)
        assert np.array_equal(np.unique(m), np.arange(mc.n_models))
        sizes = np.bincount(m)
        assert np.all(np.diff(sizes) <= 0), "segments not numbered by decreasing size"
        assert segments_connected(n, e, mc.multicut_labels)
        if connected:
            assert segments_connected(n, e, m)
        assert mc.n_segments == np.unique(mc.multicut_labels).size
        assert mc.objective == pytest.approx(multicut_objective(e, c, mc.multicut_labels))
        assert np.array_equal(mc.cut, m[e[:, 0]] != m[e[:, 1]])
        # the multicut itself is GAEC followed by KL, and the contractions are GAEC's
        assert np.array_equal(mc.contractions, steps)
        assert np.allclose(mc.contraction_costs, step_costs)
        assert mc.objective <= multicut_objective(e, c, gl) + 1e-9


@settings(max_examples=40, deadline=None)
@given(signed_graphs(min_nodes=2, max_nodes=10), st.integers(1, 12))
def test_solve_multicut_count_property(graph, k):
    n, e, c = graph
    mc = solve_multicut(make_graph(n, e, c), k)
    assert mc.n_models == min(k, n)
    assert np.unique(mc.atom_labels).size == mc.n_models
    if n_components(n, e) <= min(k, n):
        assert segments_connected(n, e, mc.atom_labels)


def test_solve_multicut_two_cliques():
    """Two positive cliques joined by negative edges: the multicut is the two cliques."""
    A = [(i, j) for i in range(5) for j in range(i + 1, 5)]
    B = [(i + 5, j + 5) for i, j in A]
    cross = [(0, 5), (2, 7), (4, 9)]
    e = np.array(A + B + cross, dtype=np.int64)
    c = np.array([2.0] * (len(A) + len(B)) + [-3.0] * len(cross))
    mc = solve_multicut(make_graph(10, e, c), 2)
    assert mc.n_segments == 2
    assert same_partition(mc.atom_labels, np.repeat([0, 1], 5))
    assert mc.objective == pytest.approx(-9.0)
    # asking for 4 splits the cliques, asking for 1 merges them
    assert solve_multicut(make_graph(10, e, c), 4).n_models == 4
    assert np.all(solve_multicut(make_graph(10, e, c), 1).atom_labels == 0)


def test_solve_multicut_empty_and_edgeless():
    mc = solve_multicut(make_graph(0, np.zeros((0, 2), np.int64), np.zeros(0)), 4)
    assert mc.n_models == 0 and mc.atom_labels.size == 0
    mc = solve_multicut(make_graph(3, np.zeros((0, 2), np.int64), np.zeros(0)), 2)
    assert mc.n_models == 2 and mc.atom_labels.shape == (3,)
    assert mc.objective == 0.0
