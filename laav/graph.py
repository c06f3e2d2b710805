"""Stage 2: the atom graph and its forward-backward affine edge costs.

Nodes are atoms. Two atoms are joined by an edge when they share a feature, when one is
among the other's ``graph_neighbors`` nearest atoms (largest seed-to-seed distance over
the sequence), or when the edge is needed to keep the graph connected (minimum spanning
tree of those distances).

Nothing here is quadratic in memory: atom overlaps are a sparse product of the sparse
membership matrix, and the nearest atoms and the spanning tree come from one pass of
Prim's algorithm that computes each seed's distance row once (O(N) memory, O(N^2) time
in N atoms, not points).

**Forward-backward error.** For an edge (a, b) and a frame pair (l, r), atom a's affine
map from l to r (``A_a[r] A_a[l]^-1``) carries b's features from l to r, and its inverse
carries them back from r to l; the error is the mean of the two Euclidean discrepancies
(px). It is averaged over b's features and over 8 evenly spaced frame pairs ``(f, f + g)``
with ``g = max(1, F // 3)``, then symmetrised as the larger of a->b and b->a.

**Cost.** With ``p = 1 / (1 + (err / s)^2)`` the probability that the atoms move together
(``s = edge_scale``), the multicut cost is the log-odds minus a cut prior, as in Keuper
et al. (ICCV 2015): ``w = log(p / (1 - p)) - cut_prior = 2 log(s / err) - cut_prior``.
Positive costs pull atoms together, negative ones push them apart.

**Missing data**: :func:`forward_backward_error_masked` (every pair ``(f, f + g)`` both
atoms have maps in, each member where it is seen in both frames); an edge without such a
pair carries no evidence: error NaN, cost 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._sequence import Sequence, as_points
from .atoms import Atoms, MaskedNeighbourhoods, Neighbourhoods, _DenseNeighbourhoods, as_neighbourhoods
from .geometry import affine_residuals
from .noise import adapted_params
from .params import LaavParams

__all__ = ["AtomGraph", "atom_graph", "forward_backward_error", "forward_backward_error_masked"]

_GRAPH_PAIRS = 8  # frame pairs (f, f + g) the forward-backward error is averaged over


@dataclass(frozen=True, eq=False)
class AtomGraph:
    """The graph over atoms with signed edge costs.

    Attributes
    ----------
    edges : ndarray of shape (E, 2), int64
        Atom index pairs ``(i, j)`` with ``i < j``.
    errors : ndarray of shape (E,)
        Symmetric forward-backward affine error of each edge (px); on incomplete data NaN
        for an edge whose atoms share too few frames.
    costs : ndarray of shape (E,)
        Signed multicut cost (positive = join, negative = cut); 0 where ``errors`` is NaN.
    overlap : ndarray of shape (E,), int64
        Features the two atoms share.
    positions : ndarray of shape (F, N, 2)
        Centre of each atom in every frame (for drawing).
    n_nodes : int
        N.
    """

    edges: np.ndarray
    errors: np.ndarray
    costs: np.ndarray
    overlap: np.ndarray
    positions: np.ndarray
    n_nodes: int

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])

    def dense_costs(self) -> np.ndarray:
        """Symmetric (N, N) cost matrix, 0 where there is no edge."""
        W = np.zeros((self.n_nodes, self.n_nodes))
        if self.n_edges:
            W[self.edges[:, 0], self.edges[:, 1]] = self.costs
            W[self.edges[:, 1], self.edges[:, 0]] = self.costs
        return W


def _homogeneous(A: np.ndarray) -> np.ndarray:
    H = np.zeros(A.shape[:-2] + (3, 3))
    H[..., :2, :] = A
    H[..., 2, 2] = 1.0
    return H


def forward_backward_error(points: np.ndarray, atoms: Atoms, edges: np.ndarray) -> np.ndarray:
    """Symmetric forward-backward affine error of every edge (px).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    atoms : Atoms
    edges : ndarray of shape (E, 2)

    Returns
    -------
    errors : ndarray of shape (E,)
    """
    F = points.shape[0]
    E = edges.shape[0]
    if E == 0:
        return np.zeros(0)
    g = max(1, F // 3)
    left = np.unique(np.round(np.linspace(0, F - 1 - g, min(_GRAPH_PAIRS, F - g))).astype(np.int64))
    right = left + g
    H = _homogeneous(atoms.affines)  # (N, F, 3, 3)
    Hinv = np.linalg.inv(H)
    fwd = H[:, right] @ Hinv[:, left]  # (N, K, 3, 3): l -> r
    bwd = np.linalg.inv(fwd)  # r -> l
    # (not padded to the largest atom's size: on 5,000 tracks sizes range over 5-587, median
    # 20, and the padding was most of the work)
    width, pad, mask = _padded_members(atoms)

    pl, pr = points[left], points[right]  # (K, P, 2)

    def directed(a, b, w):
        """Mean transfer error of b's members under a's maps; b's atoms all of width w."""
        e = _fb_errors(fwd, bwd, pl, pr, a, pad[b, :w]).mean(axis=0)  # (E, w)
        mk = mask[b, :w]
        return (e * mk).sum(1) / mk.sum(1)

    return _both_ways(edges, width, left.size, directed)


def forward_backward_error_masked(points: np.ndarray, visible: np.ndarray, atoms: Atoms,
                                  edges: np.ndarray) -> np.ndarray:
    """:func:`forward_backward_error` on incomplete data.

    The frame pairs are **all** ``(f, f + g)``, ``g = max(1, F // 3)`` (not 8 of them, so
    that atoms seen over part of the sequence still share some); for the edge (a, b) a
    pair counts when **both** atoms have a map in both its frames (``atoms.seen``), and
    in it a member of b (of a) counts when it is visible in both frames. The error of a
    direction is the mean over those (pair, member) entries; the edge's the larger of
    the two directions; NaN when a direction has no entry (the atoms share too few
    frames: no evidence).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Hidden entries are never read.
    visible : ndarray of shape (F, P), bool
    atoms : Atoms
        With ``seen`` (built on the incomplete data).
    edges : ndarray of shape (E, 2)

    Returns
    -------
    errors : ndarray of shape (E,)
    """
    from ._visibility import filled

    F = points.shape[0]
    E = edges.shape[0]
    if E == 0:
        return np.zeros(0)
    pts = filled(points, visible)
    g = max(1, F // 3)
    left = np.arange(F - g, dtype=np.int64)
    right = left + g
    A = np.nan_to_num(atoms.affines, nan=0.0)
    H = _homogeneous(A)  # (N, F, 3, 3)
    H[~atoms.seen] = np.eye(3)  # frames without a map: never used (masked below)
    Hinv = np.linalg.inv(H)
    fwd = H[:, right] @ Hinv[:, left]  # (N, K, 3, 3)
    bwd = np.linalg.inv(fwd)
    both_seen = atoms.seen[:, left] & atoms.seen[:, right]  # (N, K)
    width, pad, mask = _padded_members(atoms)
    pl, pr = pts[left], pts[right]  # (K, P, 2)
    vlr = visible[left] & visible[right]  # (K, P)

    def directed(a, b, w):
        """Mean transfer error of b's members under a's maps; b's atoms all of width w."""
        idx = pad[b, :w]  # (E, w)
        e = _fb_errors(fwd, bwd, pl, pr, a, idx)  # (K, E, w)
        ok = (vlr[:, idx] & mask[b, :w][None]
              & (both_seen[a] & both_seen[b]).T[:, :, None])  # (K, E, w)
        n = ok.sum(axis=(0, 2))
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(n > 0, np.where(ok, e, 0.0).sum(axis=(0, 2)) / n, np.nan)

    # NaN when either direction has no entry
    return _both_ways(edges, width, left.size, directed)


def _fb_errors(fwd, bwd, pl, pr, a, idx) -> np.ndarray:
    """Forward-backward transfer errors (K, E, w) of the points ``idx`` (E, w) under the maps
    of the atoms ``a`` (E,): ``fwd``, ``bwd`` (N, K, 3, 3) their maps l -> r and back, ``pl``,
    ``pr`` (K, P, 2) the points in every pair's two frames."""
    xl = pl[:, idx]  # (K, E, w, 2)
    xr = pr[:, idx]
    Tf = np.transpose(fwd[a], (1, 0, 2, 3))  # (K, E, 3, 3)
    Tb = np.transpose(bwd[a], (1, 0, 2, 3))
    return 0.5 * (_transfer_error(Tf, xl, xr) + _transfer_error(Tb, xr, xl))


def _both_ways(edges: np.ndarray, width: np.ndarray, n_pairs: int, directed) -> np.ndarray:
    """The larger of ``directed(a, b, w)`` and ``directed(b, a, w')`` for every edge (a, b)
    (E,), the edges batched by the width ``width`` (:func:`_padded_members`) of the atom
    whose members move (each edge's result does not depend on the batch it is in; a batch
    holds ``n_pairs`` x chunk x w points)."""
    E = edges.shape[0]

    def one_way(src, dst):
        out = np.empty(E)
        for w in np.unique(width[dst]):
            sel = np.flatnonzero(width[dst] == w)
            chunk = int(np.clip(2**17 // (n_pairs * w), 16, 256))
            for s in range(0, sel.size, chunk):
                e = sel[s : s + chunk]
                out[e] = directed(src[e], dst[e], int(w))
        return out

    return np.maximum(one_way(edges[:, 0], edges[:, 1]), one_way(edges[:, 1], edges[:, 0]))


def _padded_members(atoms: Atoms) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every atom's members padded to the power of two at or above its size (at least 8):
    ``width`` (N,), ``pad`` (N, max width) member indices (0 beyond them), ``mask`` (N, max
    width) True on the members. Edges are batched by their atoms' width, so an edge's sums
    depend on its own atoms only, not on the batch or the largest atom."""
    sizes = np.array([m.size for m in atoms.members])
    width = 1 << np.ceil(np.log2(np.maximum(sizes, 8))).astype(np.int64)
    pad = np.zeros((atoms.n_atoms, int(width.max())), dtype=np.int64)
    mask = np.zeros(pad.shape, dtype=bool)
    for i, m in enumerate(atoms.members):
        pad[i, : m.size] = m
        mask[i, : m.size] = True
    return width, pad, mask


def _transfer_error(T: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``|T x - y|`` per point; T (K, E, 3, 3) affine maps, x and y (K, E, m, 2)."""
    dx, dy = affine_residuals(T, x, y)
    return np.sqrt(dx * dx + dy * dy)


def _seed_graph(nb, seeds: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``k`` nearest seeds of every seed, and the minimum spanning tree of all seeds.

    Distances are those of :class:`~laav.atoms.Neighbourhoods` (the largest over the
    sampled frames); the tree spans the complete graph with these distances as weights
    (coincident seeds, at distance 0, are joined too). One pass of Prim's algorithm computes
    every seed's distance row once, in the order the seeds join the tree, and takes its
    ``k`` nearest from the same row: no N x N array.

    Returns
    -------
    nn : ndarray of shape (N, k), int64
    tree : ndarray of shape (N - 1, 2), int64
        The tree's edges (unordered pairs).
    """
    N = seeds.size
    if isinstance(nb, _DenseNeighbourhoods):
        def row_of(u):
            return nb.D[seeds[u], seeds]
    elif isinstance(nb, MaskedNeighbourhoods):  # missing data: FAR for seeds sharing too few frames
        def row_of(u):
            return nb.row(seeds[u], seeds)
    else:
        # per coordinate rows (2K, N): a row is a few contiguous vector operations
        Xt = np.ascontiguousarray(nb.coords[seeds].T)

        def row_of(u):
            d = Xt - Xt[:, u:u + 1]
            d *= d
            return np.sqrt((d[0::2] + d[1::2]).max(axis=0))  # as Neighbourhoods.distances

    nn = np.empty((N, k), dtype=np.int64)
    key = np.full(N, np.inf)
    parent = np.full(N, -1, dtype=np.int64)
    outside = np.ones(N, dtype=bool)
    tree = np.empty((N - 1, 2), dtype=np.int64)
    u = 0
    for step in range(N):
        outside[u] = False
        row = row_of(u)
        knn = row.copy()
        knn[u] = np.inf
        nn[u] = np.argpartition(knn, k - 1)[:k]
        if step == N - 1:
            break
        better = outside & (row < key)
        key[better] = row[better]
        parent[better] = u
        u = int(np.argmin(np.where(outside, key, np.inf)))
        tree[step] = (parent[u], u)
    return nn, tree


def atom_graph(seq: Sequence | np.ndarray, atoms: Atoms, params: LaavParams | None = None,
               distances: Neighbourhoods | np.ndarray | None = None, *,
               visible: np.ndarray | None = None) -> AtomGraph:
    """Build the atom graph with forward-backward edge errors and signed costs.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    atoms : Atoms
    params : LaavParams
        Uses ``graph_neighbors``, ``edge_scale``, ``cut_prior``; with ``noise_adaptive``
        the ``edge_scale`` of :meth:`LaavParams.for_noise` for the noise measured on
        ``seq`` (:func:`laav.noise.estimate_noise`).
    distances : Neighbourhoods, optional
        Precomputed :class:`~laav.atoms.Neighbourhoods` (a dense
        :func:`~laav.atoms.trajectory_distances` matrix is accepted too; on incomplete
        data a :class:`~laav.atoms.MaskedNeighbourhoods`).
    visible : ndarray of shape (F, P), bool, optional
        For an array ``seq`` with missing entries (a :class:`Sequence` carries its own).
        On incomplete data the errors are :func:`forward_backward_error_masked`; an edge
        whose atoms share too few frames (error NaN) gets cost 0, which is the same as no
        edge in the multicut objective (kept so that the count adjustment can still merge
        an atom that has no other edge with its nearest neighbour).

    Returns
    -------
    AtomGraph
    """
    from ._visibility import visibility

    vis = visibility(seq, visible)
    points = as_points(seq)
    params = LaavParams() if params is None else params
    params, _ = adapted_params(points, params, vis)  # noise_adaptive: edge_scale for σ̂
    N = atoms.n_atoms
    positions = atoms.centers(points, vis)
    if N < 2:
        return AtomGraph(np.zeros((0, 2), np.int64), np.zeros(0), np.zeros(0),
                         np.zeros(0, np.int64), positions, N)
    from scipy.sparse import csr_matrix  # lazy: off `import laav`

    P = atoms.n_points
    sizes = np.array([m.size for m in atoms.members], dtype=np.int64)
    M = csr_matrix((np.ones(int(sizes.sum())), np.concatenate(atoms.members),
                    np.concatenate([[0], np.cumsum(sizes)])), shape=(N, P))
    shared = (M @ M.T).tocoo()  # features two atoms share (exact: small integer sums)
    up = shared.row < shared.col
    sh_i, sh_j = shared.row[up].astype(np.int64), shared.col[up].astype(np.int64)
    sh_n = np.rint(shared.data[up]).astype(np.int64)
    nb = as_neighbourhoods(points, distances, vis)
    k = min(params.graph_neighbors, N - 1)
    nn, tree = _seed_graph(nb, atoms.seeds, k)
    a = np.concatenate([sh_i, np.repeat(np.arange(N), k), tree[:, 0]])
    b = np.concatenate([sh_j, nn.ravel(), tree[:, 1]])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keys = np.unique(lo * N + hi)  # row-major order, as np.nonzero(np.triu(adj, 1))
    i, j = keys // N, keys % N
    edges = np.stack([i, j], axis=1).astype(np.int64)
    overlap = np.zeros(keys.size, dtype=np.int64)
    overlap[np.searchsorted(keys, sh_i * N + sh_j)] = sh_n
    # errors floored at 1e-6 px at the default edge_scale (2 px), scaled with it: the
    # largest cost, 2 log(2e6), is then the same at every scale of the coordinates
    floor = 1e-6 * (params.edge_scale / LaavParams.edge_scale)
    if vis is None:
        errors = forward_backward_error(points, atoms, edges)
        costs = 2.0 * np.log(params.edge_scale / np.maximum(errors, floor)) - params.cut_prior
    else:
        errors = forward_backward_error_masked(points, vis, atoms, edges)
        with np.errstate(invalid="ignore"):
            costs = 2.0 * np.log(params.edge_scale / np.maximum(errors, floor)) - params.cut_prior
        costs = np.where(np.isfinite(errors), costs, 0.0)
    return AtomGraph(edges=edges, errors=errors, costs=costs,
                     overlap=overlap, positions=positions, n_nodes=N)
