"""Stage 3: minimum cost multicut of the atom graph, brought to exactly ``2C`` fine models.

The multicut problem: choose which edges to cut so that the cut edges form a valid
decomposition (no cut edge inside a component) and the summed cost of the *cut* edges is
minimal, costs being positive for "join" and negative for "cut"
(``min sum_e w_e x_e``, ``x_e = 1`` when cut).

Solver: greedy additive edge contraction (GAEC: contract the edge of largest positive
cost, summing parallel edges, until none is positive), then Kernighan-Lin with joins
(two-set KL moves between adjacent segments and towards a new segment, keeping the best
prefix of moves; joining two segments when their connecting costs sum positive),
repeated until no improvement. :func:`exact_multicut` (``scipy.optimize.milp`` with
lazily added cycle inequalities) is the oracle the tests compare against.

**Exactly ``k = 2C`` fine models.** The multicut chooses its own number of segments.
It is brought to ``k`` greedily by cost: while there are more than ``k`` segments, the two
adjacent ones whose connecting edges have the largest *mean* cost are merged (summed costs
let long borders dominate and mixed motions: 9.1 % fine-model impurity on Hopkins155
against 1.6 % with the mean); while
there are fewer, the segment whose best two-way split (GAEC on its subgraph down to two
parts) cuts the smallest summed cost is split. Both steps change the objective as little
as any single merge or split can. Segments are numbered by decreasing size.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

import numpy as np

from .graph import AtomGraph

__all__ = ["Multicut", "solve_multicut", "gaec", "kernighan_lin", "exact_multicut",
           "multicut_objective"]


@dataclass(frozen=True, eq=False)
class Multicut:
    """Fine segmentation of the atoms.

    Attributes
    ----------
    atom_labels : ndarray of shape (N,), int64
        Fine model of each atom in ``0 .. n_models-1`` (0 = largest).
    n_models : int
        Number of fine models (``2C`` unless there are fewer atoms).
    multicut_labels : ndarray of shape (N,), int64
        The minimum cost multicut itself (GAEC + KL), before the count adjustment.
    n_segments : int
        Segments of the multicut itself.
    cut : ndarray of shape (E,), bool
        Whether each graph edge separates two fine models.
    objective : float
        Summed cost of the multicut's own cut edges.
    contractions : ndarray of shape (K, 2), int64
        GAEC's contractions in order, as ``(kept, merged)`` atom representatives: replaying
        them one by one rebuilds the GAEC segmentation.
    contraction_costs : ndarray of shape (K,)
        Cost of the contracted edge at each step.
    """

    atom_labels: np.ndarray
    n_models: int
    multicut_labels: np.ndarray
    n_segments: int
    cut: np.ndarray
    objective: float
    contractions: np.ndarray
    contraction_costs: np.ndarray


def multicut_objective(edges: np.ndarray, costs: np.ndarray, labels: np.ndarray) -> float:
    """Summed cost of the edges whose endpoints carry different labels."""
    if edges.shape[0] == 0:
        return 0.0
    cut = labels[edges[:, 0]] != labels[edges[:, 1]]
    return float(costs[cut].sum())


def _relabel(labels: np.ndarray) -> np.ndarray:
    """Renumber segments 0.. by decreasing size (ties by smallest member)."""
    uniq, inv, counts = np.unique(labels, return_inverse=True, return_counts=True)
    first = np.full(uniq.size, labels.size)
    np.minimum.at(first, inv, np.arange(labels.size))
    order = np.lexsort((first, -counts))
    rank = np.empty(uniq.size, dtype=np.int64)
    rank[order] = np.arange(uniq.size)
    return rank[inv]


def gaec(n_nodes: int, edges: np.ndarray, costs: np.ndarray, n_clusters: int | None = None):
    """Greedy additive edge contraction.

    Parameters
    ----------
    n_nodes : int
    edges : ndarray of shape (E, 2)
    costs : ndarray of shape (E,)
    n_clusters : int, optional
        Without it, contract while some edge cost is positive (the multicut heuristic).
        With it, keep contracting the largest-cost edge, negative or not, until that many
        components remain (or no edge is left).

    Returns
    -------
    labels : ndarray of shape (N,), int64
    contractions : ndarray of shape (K, 2), int64
    contraction_costs : ndarray of shape (K,)
    """
    adj: list[dict] = [dict() for _ in range(n_nodes)]
    for (u, v), w in zip(edges.tolist(), costs.tolist()):
        if u == v:
            continue
        adj[u][v] = adj[u].get(v, 0.0) + w
        adj[v][u] = adj[v].get(u, 0.0) + w
    heap = [(-w, u, v) for u in range(n_nodes) for v, w in adj[u].items() if u < v]
    heapq.heapify(heap)
    alive = np.ones(n_nodes, dtype=bool)
    parent = np.arange(n_nodes)
    n_comp = n_nodes
    steps, step_costs = [], []
    while heap:
        negw, u, v = heapq.heappop(heap)
        if not (alive[u] and alive[v]) or v not in adj[u] or adj[u][v] != -negw:
            continue
        w = -negw
        if n_clusters is None:
            if w <= 0:
                break
        elif n_comp <= n_clusters:
            break
        if len(adj[u]) < len(adj[v]):
            u, v = v, u  # merge the smaller adjacency into the larger
        alive[v] = False
        parent[v] = u
        n_comp -= 1
        steps.append((u, v))
        step_costs.append(w)
        del adj[u][v]
        del adj[v][u]
        for x, wx in adj[v].items():
            del adj[x][v]
            nw = adj[u].get(x, 0.0) + wx
            adj[u][x] = nw
            adj[x][u] = nw
            heapq.heappush(heap, (-nw, min(u, x), max(u, x)))
        adj[v].clear()
    root = parent.copy()
    for i in range(n_nodes):
        r = i
        while root[r] != r:
            r = root[r]
        root[i] = r
    return (_relabel(root), np.asarray(steps, dtype=np.int64).reshape(-1, 2),
            np.asarray(step_costs, dtype=np.float64))


def _two_set_kl(W: np.ndarray, nodes: np.ndarray, side: np.ndarray) -> tuple[np.ndarray, float]:
    """One Kernighan-Lin pass between two sets; returns the best side vector and its gain."""
    Ws = W[np.ix_(nodes, nodes)]
    s = side.astype(bool).copy()
    sign = np.where(s, 1.0, -1.0)
    # gain of moving u to the other side = sum to other side - sum to own side
    gain = -(Ws @ sign) * sign
    locked = np.zeros(nodes.size, dtype=bool)
    cum, best, best_k = 0.0, 0.0, 0
    order = []
    for k in range(nodes.size):
        g = np.where(locked, -np.inf, gain)
        u = int(np.argmax(g))
        if not np.isfinite(g[u]):
            break
        cum += g[u]
        locked[u] = True
        order.append(u)
        # u changes side: neighbours on u's old side gain +2w, on its new side -2w
        same = s == s[u]
        gain += np.where(same, 2.0, -2.0) * Ws[u]
        gain[u] = -gain[u] + 0.0
        s[u] = ~s[u]
        if cum > best + 1e-9:
            best, best_k = cum, k + 1
    out = side.astype(bool).copy()
    for u in order[:best_k]:
        out[u] = ~out[u]
    return out, best


def kernighan_lin(n_nodes: int, edges: np.ndarray, costs: np.ndarray, labels: np.ndarray,
                  max_rounds: int = 20) -> np.ndarray:
    """Improve a multicut by Kernighan-Lin moves with joins.

    Parameters
    ----------
    n_nodes : int
    edges : ndarray of shape (E, 2)
    costs : ndarray of shape (E,)
    labels : ndarray of shape (N,)
        Start segmentation.
    max_rounds : int

    Returns
    -------
    labels : ndarray of shape (N,), int64
        A segmentation with objective no larger than the start.
    """
    W = np.zeros((n_nodes, n_nodes))
    if edges.shape[0]:
        np.add.at(W, (edges[:, 0], edges[:, 1]), costs)
        np.add.at(W, (edges[:, 1], edges[:, 0]), costs)
    # A start labelling may hold disconnected segments; KL must work on the real ones
    # (a no-op for GAEC's output, whose segments are connected).
    lab = _split_disconnected(n_nodes, edges, np.asarray(labels, dtype=np.int64))
    for _ in range(max_rounds):
        improved = False
        # joins: merge the adjacent pair with the largest positive connecting sum
        while True:
            segs = np.unique(lab)
            onehot = (lab[:, None] == segs[None, :]).astype(float)
            between = onehot.T @ W @ onehot
            np.fill_diagonal(between, -np.inf)
            a, b = np.unravel_index(np.argmax(between), between.shape)
            if segs.size < 2 or between[a, b] <= 1e-9:
                break
            lab[lab == segs[b]] = segs[a]
            improved = True
        # moves between each adjacent pair, and from each segment to a new one
        segs = np.unique(lab)
        onehot = (lab[:, None] == segs[None, :]).astype(float)
        between = onehot.T @ (W != 0) @ onehot
        pairs = [(segs[i], segs[j]) for i in range(segs.size) for j in range(i + 1, segs.size)
                 if between[i, j] > 0]
        new_id = lab.max() + 1
        pairs += [(s, None) for s in segs]
        for a, b in pairs:
            if b is None:
                nodes = np.flatnonzero(lab == a)
                if nodes.size < 2:
                    continue
                side = np.zeros(nodes.size, dtype=bool)
            else:
                nodes = np.flatnonzero((lab == a) | (lab == b))
                if not ((lab[nodes] == a).any() and (lab[nodes] == b).any()):
                    continue
                side = lab[nodes] == b
            new_side, gain = _two_set_kl(W, nodes, side)
            if gain > 1e-9:
                target = new_id if b is None else b
                if b is None:
                    new_id += 1
                lab[nodes[new_side]] = target
                lab[nodes[~new_side]] = a
                improved = True
        if not improved:
            # A move that took out a cut vertex can leave a segment disconnected. Split
            # such segments (free: no edge joins the parts) and, if any was split, go on
            # improving: the parts are new segments that moves and joins have not tried.
            split = _split_disconnected(n_nodes, edges, lab)
            if np.unique(split).size == np.unique(lab).size:
                break
            lab = split
    # a segment must be connected: split disconnected ones into their components
    return _split_disconnected(n_nodes, edges, _relabel(lab))


def _split_disconnected(n_nodes, edges, lab):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if edges.shape[0] == 0:
        return _relabel(np.arange(n_nodes))
    keep = lab[edges[:, 0]] == lab[edges[:, 1]]
    e = edges[keep]
    A = coo_matrix((np.ones(e.shape[0]), (e[:, 0], e[:, 1])), shape=(n_nodes, n_nodes))
    _, comp = connected_components(A, directed=False)
    return _relabel(comp)


def _adjust_count(n_nodes, edges, costs, labels, k):
    """Greedy merges or splits by cost until exactly ``min(k, N)`` segments remain."""
    lab = labels.copy()
    W = np.zeros((n_nodes, n_nodes))
    if edges.shape[0]:
        np.add.at(W, (edges[:, 0], edges[:, 1]), costs)
        np.add.at(W, (edges[:, 1], edges[:, 0]), costs)
    A = np.zeros((n_nodes, n_nodes))
    if edges.shape[0]:
        A[edges[:, 0], edges[:, 1]] = A[edges[:, 1], edges[:, 0]] = 1.0
    k = min(k, n_nodes)
    while np.unique(lab).size > k:
        segs = np.unique(lab)
        onehot = (lab[:, None] == segs[None, :]).astype(float)
        between = onehot.T @ W @ onehot
        n_between = onehot.T @ A @ onehot
        # mean (not summed) connecting cost: a long shared border must not outweigh
        # how strongly the two segments disagree (measured: fine-model impurity on
        # Hopkins155 9.1 % with sums, 1.6 % with means)
        score = np.where(n_between > 0, between / np.maximum(n_between, 1.0), -1e12)
        np.fill_diagonal(score, -np.inf)
        a, b = np.unravel_index(np.argmax(score), score.shape)
        lab[lab == segs[b]] = segs[a]
    while np.unique(lab).size < k:
        best = None
        for s in np.unique(lab):
            nodes = np.flatnonzero(lab == s)
            if nodes.size < 2:
                continue
            pos = {n: i for i, n in enumerate(nodes.tolist())}
            inside = np.isin(edges[:, 0], nodes) & np.isin(edges[:, 1], nodes)
            sub = np.array([[pos[u], pos[v]] for u, v in edges[inside].tolist()],
                           dtype=np.int64).reshape(-1, 2)
            sl, _, _ = gaec(nodes.size, sub, costs[inside], n_clusters=2)
            if np.unique(sl).size < 2:  # disconnected inside: any component split is free
                sl = (np.arange(nodes.size) > 0).astype(np.int64) if sub.shape[0] == 0 else sl
            part = sl == sl[0]
            cut_cost = W[np.ix_(nodes[part], nodes[~part])].sum()
            if best is None or cut_cost < best[0]:
                best = (cut_cost, nodes[~part])
        if best is None:
            break
        lab[best[1]] = lab.max() + 1
    return _relabel(lab)


def solve_multicut(graph: AtomGraph, n_models: int) -> Multicut:
    """Minimum cost multicut of the atom graph, then exactly ``n_models`` fine models.

    Parameters
    ----------
    graph : AtomGraph
    n_models : int
        Number of fine models wanted (``2C``; fewer when there are fewer atoms).

    Returns
    -------
    Multicut
    """
    N = graph.n_nodes
    if N == 0:
        z = np.zeros(0, np.int64)
        return Multicut(z, 0, z, 0, np.zeros(0, bool), 0.0, np.zeros((0, 2), np.int64),
                        np.zeros(0))
    g_labels, steps, step_costs = gaec(N, graph.edges, graph.costs)
    mc = kernighan_lin(N, graph.edges, graph.costs, g_labels)
    fine = _adjust_count(N, graph.edges, graph.costs, mc, n_models)
    cut = fine[graph.edges[:, 0]] != fine[graph.edges[:, 1]] if graph.n_edges else np.zeros(0, bool)
    return Multicut(
        atom_labels=fine,
        n_models=int(np.unique(fine).size),
        multicut_labels=mc,
        n_segments=int(np.unique(mc).size),
        cut=cut,
        objective=multicut_objective(graph.edges, graph.costs, mc),
        contractions=steps,
        contraction_costs=step_costs,
    )


def exact_multicut(n_nodes: int, edges: np.ndarray, costs: np.ndarray,
                   max_rounds: int = 200) -> np.ndarray:
    """Optimal multicut by integer programming with lazily added cycle inequalities.

    For small graphs only (tests). Returns node labels of the optimal decomposition.
    """
    import networkx as nx
    from scipy.optimize import Bounds, LinearConstraint, milp

    E = edges.shape[0]
    if E == 0:
        return np.arange(n_nodes)
    index = {(min(u, v), max(u, v)): e for e, (u, v) in enumerate(edges.tolist())}
    rows: list[np.ndarray] = []
    x = np.zeros(E)
    for _ in range(max_rounds):
        cons = []
        if rows:
            A = np.array(rows)
            cons = [LinearConstraint(A, -np.inf, 0.0)]
        res = milp(c=costs, integrality=np.ones(E), bounds=Bounds(0, 1), constraints=cons)
        x = np.round(res.x)
        G = nx.Graph()
        G.add_nodes_from(range(n_nodes))
        G.add_edges_from(edges[x == 0].tolist())
        comp = {n: i for i, cc in enumerate(nx.connected_components(G)) for n in cc}
        new = 0
        for e in np.flatnonzero(x == 1):
            u, v = edges[e]
            if comp[u] == comp[v]:
                path = nx.shortest_path(G, u, v)
                row = np.zeros(E)
                row[e] = 1.0
                for a, b in zip(path[:-1], path[1:]):
                    row[index[(min(a, b), max(a, b))]] -= 1.0
                rows.append(row)
                new += 1
        if new == 0:
            return _relabel(np.array([comp[n] for n in range(n_nodes)]))
    raise RuntimeError("exact multicut did not converge")
