"""Stage 1: atoms, small overlapping groups of trajectories explained by one affine motion.

Construction follows the paper (section 3.1): seeds are drawn in random order; the
candidate members of an atom are the features within ``r2`` of the seed; RANSAC looks for
an affine consensus that contains the seed; if it has at least ``atom_min_size`` features
the atom is accepted, and its members within ``r1`` of the seed are then *owned* by it:
they are never seeds or members of later atoms, while members in the ring ``r1..r2``
may be shared (the overlaps the atom graph is built on).

Choices where the paper is vague (measured on Hopkins155):

* **Neighbourhoods over the whole sequence.** "Within ``r`` of the seed" means within
  ``r`` in every one of 6 evenly spaced frames (not one frame), so an atom stays small
  for the whole sequence and its affine premise holds. They come from a KD-tree
  (:class:`Neighbourhoods`), never from a P x P matrix: a point within ``r`` in every
  frame is within ``r`` in each coordinate, so a ball query in the max-norm over the
  sampled frames' coordinates gives the candidates, and the exact distance (computed
  as :func:`trajectory_distances` does, bit for bit) decides.
* **All frames, not one pair** (``atom_frames="all"``, ours). An atom's motion model is
  one affine map from frame 0 to every frame (fitted jointly); a feature is an inlier when
  its RMS residual over all frames is below ``affine_threshold``. A single random frame
  pair often shows too little motion to reject a feature of another object. The paper's
  way, ``atom_frames="pair"`` (:meth:`LaavParams.paper`): RANSAC on one random frame pair
  at least ``F // 3`` apart, drawn for each atom; the accepted members' affine
  trajectory over all frames is then fitted for the graph, without a check over all
  frames.
* **Minimal samples contain the seed**, so the atom is built around it, and all
  ``ransac_hypotheses`` samples are scored in one batched solve. The best consensus is
  refitted by least squares and its inliers recomputed until stable, judging fitted
  features by their *leave-one-out* residual (residual / (1 - leverage)): a feature of
  another motion far from the others otherwise drags the fit onto itself. An atom is
  kept only if its final least-squares model holds every member within the threshold.

**Missing data** (a sequence with hidden entries): :class:`MaskedNeighbourhoods` compares
two tracks over the frames both are seen in (at least ``min_overlap(F)`` of them), and
each atom's maps start from a reference frame its members are seen in, fitted frame by
frame on the members visible there (``_build_atoms_masked``; ``docs/ALGORITHM.md``,
"Missing data").
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from ._sequence import Sequence, as_points
from .geometry import affine_residuals, fit_affine, fit_affine_leverage, fit_affine_masked
from .noise import adapted_params
from .params import LaavParams

__all__ = ["Atoms", "Neighbourhoods", "MaskedNeighbourhoods", "build_atoms",
           "trajectory_distances"]

_NEIGHBOURHOOD_FRAMES = 6


@dataclass(frozen=True, eq=False)
class Atoms:
    """Result of atom construction.

    Attributes
    ----------
    members : tuple of N ndarrays of int64
        Feature indices of each atom (sorted, the seed included).
    seeds : ndarray of shape (N,), int64
        Seed feature of each atom.
    owner : ndarray of shape (P,), int64
        Atom that owns each feature (member within ``r1`` of that atom's seed), -1 if none.
    affines : ndarray of shape (N, F, 2, 3)
        Each atom's affine map from frame 0 (on incomplete data: from its reference frame,
        ``ref_frames``) to every frame, fitted on its members.
    residuals : tuple of N ndarrays
        RMS residual (px) over all frames (on incomplete data: the frames it is seen in
        where its atom has a map) of each member under its atom's affine model.
    unassigned : ndarray of shape (K,), int64
        Features that belong to no atom.
    r1, r2 : float
        The radii used (px).
    n_points : int
        P.
    ref_frames : ndarray of shape (N,), int64, or None
        Missing data only (None on complete data, where every map starts at frame 0):
        the frame each atom's affine maps start from (``affines[i, f]`` maps atom i's
        members from frame ``ref_frames[i]`` to frame f); every member is seen there.
    seen : ndarray of shape (N, F), bool, or None
        Missing data only: the frames each atom has a map for (at least 3 members
        visible); ``affines`` is NaN elsewhere. None on complete data (every frame).
    """

    members: tuple
    seeds: np.ndarray
    owner: np.ndarray
    affines: np.ndarray
    residuals: tuple
    unassigned: np.ndarray
    r1: float
    r2: float
    n_points: int
    ref_frames: np.ndarray | None = None
    seen: np.ndarray | None = None

    @property
    def n_atoms(self) -> int:
        return len(self.members)

    @property
    def coverage(self) -> float:
        """Fraction of features in at least one atom."""
        return 1.0 - self.unassigned.size / max(self.n_points, 1)

    def membership(self) -> np.ndarray:
        """Boolean (N, P) matrix: feature j is a member of atom i."""
        M = np.zeros((self.n_atoms, self.n_points), dtype=bool)
        for i, m in enumerate(self.members):
            M[i, m] = True
        return M

    def centers(self, points: np.ndarray, visible: np.ndarray | None = None) -> np.ndarray:
        """Mean position of each atom's members in every frame, shape (F, N, 2).

        With ``visible`` (F, P) (missing data) the mean of the members visible in each
        frame, NaN where none is."""
        if self.n_atoms == 0:
            return np.zeros((points.shape[0], 0, 2))
        if visible is None:
            return np.stack([points[:, m].mean(axis=1) for m in self.members], axis=1)
        out = []
        for m in self.members:
            v = visible[:, m]  # (F, n)
            k = v.sum(axis=1)[:, None]
            tot = np.where(v[..., None], points[:, m], 0.0).sum(axis=1)
            with np.errstate(invalid="ignore", divide="ignore"):
                out.append(np.where(k > 0, tot / k, np.nan))
        return np.stack(out, axis=1)


def _sampled_frames(F: int, n_frames: int = _NEIGHBOURHOOD_FRAMES) -> np.ndarray:
    """The evenly spaced frames (first and last included) neighbourhoods are judged on."""
    return np.unique(np.round(np.linspace(0, F - 1, min(n_frames, F))).astype(int))


class Neighbourhoods:
    """Which trajectories are near which, without a P x P matrix.

    The distance of two trajectories is the largest distance between them over
    :data:`_NEIGHBOURHOOD_FRAMES` evenly spaced frames, exactly :func:`trajectory_distances`
    (same arithmetic, same bits) but computed only for pairs a KD-tree proposes: a pair
    within ``r`` in every sampled frame is within ``r`` in each of its ``2K`` sampled
    coordinates, so a max-norm ball query (``scipy.spatial.cKDTree``, ``p=inf``) finds a
    superset and the exact distances decide.

    One object serves every radius: :meth:`within` keeps the pairs of the largest radius
    asked so far and answers a smaller one by filtering them (what :class:`laav.Pipeline`
    reuses when R1 or R2 change), a larger one by a new query.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    n_frames : int
        Frames sampled.
    """

    def __init__(self, points: np.ndarray, n_frames: int = _NEIGHBOURHOOD_FRAMES):
        points = np.asarray(points, dtype=np.float64)
        F, P, _ = points.shape
        self.n_points = P
        self.frames = _sampled_frames(F, n_frames)
        # (P, 2K): x, y of every sampled frame in turn
        self.coords = np.ascontiguousarray(np.transpose(points[self.frames], (1, 0, 2)).reshape(P, -1))
        self._columns = np.ascontiguousarray(self.coords.T)  # (2K, P): one coordinate per row
        self._tree = None
        self._cache = None  # (radius, counts, cols, dist): every ordered pair within radius

    @property
    def tree(self):
        if self._tree is None:
            from scipy.spatial import cKDTree  # lazy: off `import laav`

            self._tree = cKDTree(self.coords)
        return self._tree

    def distances(self, i, j) -> np.ndarray:
        """Exact distances of the pairs ``(i[k], j[k])`` (1-D index arrays), as
        :func:`trajectory_distances` computes them (the largest squared distance over the
        sampled frames, then its square root)."""
        i, j = np.asarray(i), np.asarray(j)
        out = np.zeros(np.broadcast(i, j).shape)
        c = self._columns
        for k in range(0, c.shape[0], 2):
            dx = c[k][i] - c[k][j]
            dy = c[k + 1][i] - c[k + 1][j]
            dx *= dx
            dy *= dy
            dx += dy
            np.maximum(out, dx, out=out)
        return np.sqrt(out, out=out)

    def _query(self, radius: float):
        P = self.n_points
        r = float(radius)
        # a slightly larger max-norm ball (relative margin: any scale of the coordinates):
        # only a superset is needed, the exact test follows
        pairs = self.tree.query_pairs(r * (1.0 + 1e-9), p=np.inf, output_type="ndarray")
        keys, dists = [np.arange(P, dtype=np.int64) * (P + 1)], [np.zeros(P)]  # i itself
        for s in range(0, pairs.shape[0], 1 << 20):  # bounded temporaries
            i = pairs[s:s + (1 << 20), 0].astype(np.int64)
            j = pairs[s:s + (1 << 20), 1].astype(np.int64)
            d = self.distances(i, j)
            keep = d <= r
            i, j, d = i[keep], j[keep], d[keep]
            keys += [i * P + j, j * P + i]
            dists += [d, d]
        del pairs
        keys = np.concatenate(keys)
        order = np.argsort(keys)
        keys = keys[order]
        dist = np.concatenate(dists)[order]
        del order
        counts = np.bincount(keys // P, minlength=P)
        self._cache = (r, counts, keys % P, dist)

    def within(self, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Every trajectory within ``radius`` of every other, as compressed rows.

        Returns
        -------
        indptr : ndarray of shape (P + 1,), int64
        indices : ndarray of int64
            Row ``i``'s neighbours are ``indices[indptr[i]:indptr[i + 1]]``, in increasing
            order, ``i`` itself included.
        dist : ndarray
            Their distances (the values :func:`trajectory_distances` has there).
        """
        if self._cache is None or self._cache[0] < radius:
            self._query(radius)
        r, counts, cols, dist = self._cache
        if r > radius:
            keep = dist <= radius
            rows = np.repeat(np.arange(self.n_points), counts)
            counts = np.bincount(rows[keep], minlength=self.n_points)
            cols, dist = cols[keep], dist[keep]
        indptr = np.zeros(self.n_points + 1, dtype=np.int64)
        np.cumsum(counts, out=indptr[1:])
        return indptr, cols, dist


class _DenseNeighbourhoods:
    """A precomputed :func:`trajectory_distances` matrix behind :class:`Neighbourhoods`'
    interface (callers that still hold one)."""

    def __init__(self, D: np.ndarray):
        self.D = np.asarray(D)
        self.n_points = self.D.shape[0]

    def distances(self, i, j) -> np.ndarray:
        return self.D[i, j]

    def within(self, radius: float):
        rows, cols = np.nonzero(self.D <= radius)
        indptr = np.zeros(self.n_points + 1, dtype=np.int64)
        np.cumsum(np.bincount(rows, minlength=self.n_points), out=indptr[1:])
        return indptr, cols.astype(np.int64), self.D[rows, cols]


#: Distance :class:`MaskedNeighbourhoods` gives two trajectories that share too few
#: frames to be compared: farther than any radius at any scale of the coordinates, finite
#: so that nearest-neighbour and spanning-tree searches still order them.
FAR = 1e300


def _pair_counts(listed, n: int, least: int):
    """``(i, j, count)``: the pairs ``i < j`` listed ``count >= least`` times in ``listed``
    (an iterable of pairs of int arrays ``(i, j)``), ordered by ``i`` then ``j``, as
    ``np.unique`` of ``i n + j`` would give them. Counted by ``bincount`` over blocks of
    rows (a table of about 4M cells each), each array's pairs grouped by block with a radix
    sort, instead of sorting all the listed pairs at once (0.3 s against 1.5 s for the
    19.6M pairs of 5,000 tracks x 100 frames at 50 % visible)."""
    rows = max(1, (1 << 22) // n)  # rows per block
    n_blocks = (n + rows - 1) // rows
    small = np.int16 if n_blocks < 32768 else np.int64  # int16: numpy's stable sort is radix
    per: list[list] = [[] for _ in range(n_blocks)]
    for x, y in listed:
        x, y = np.asarray(x, np.int64), np.asarray(y, np.int64)
        blk = (x // rows).astype(small)
        order = np.argsort(blk, kind="stable")
        key = ((x - blk.astype(np.int64) * rows) * n + y)[order]
        cut = np.concatenate([[0], np.cumsum(np.bincount(blk, minlength=n_blocks))])
        for k in np.flatnonzero(cut[1:] > cut[:-1]):
            per[k].append(key[cut[k]:cut[k + 1]])
    out_i, out_j, out_c = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
    for k in range(n_blocks):
        if not per[k]:
            continue
        cnt = np.bincount(np.concatenate(per[k]), minlength=rows * n)
        per[k] = None
        cell = np.flatnonzero(cnt >= least)
        out_i.append(k * rows + cell // n)
        out_j.append(cell % n)
        out_c.append(cnt[cell])
    return np.concatenate(out_i), np.concatenate(out_j), np.concatenate(out_c)


class MaskedNeighbourhoods:
    """:class:`Neighbourhoods` for missing data.

    The distance of two trajectories is the largest distance between them over **every
    frame both are visible in**, when they share at least :func:`laav._visibility.min_overlap`
    frames, and :data:`FAR` otherwise (they are never neighbours). A pair within ``r`` in
    all its shared frames is within ``r`` in at least that many single frames, so per-frame
    KD-tree pair queries on the visible points, counted, propose a superset, and the exact
    distance decides.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
        Hidden entries are never read.
    visible : ndarray of shape (F, P), bool
    """

    def __init__(self, points: np.ndarray, visible: np.ndarray):
        from ._visibility import filled, min_overlap

        self.visible = np.asarray(visible, dtype=bool)
        self.points = filled(points, self.visible)
        F, P, _ = self.points.shape
        self.n_points = P
        # per point, its frames contiguous: a pair's rows are gathered whole (2.7x faster
        # distances than gathering a column of every frame; the same numbers)
        self._points_t = np.ascontiguousarray(self.points.transpose(1, 0, 2))  # (P, F, 2)
        self._visible_t = np.ascontiguousarray(self.visible.T)  # (P, F)
        self.min_overlap = min_overlap(F)
        self._cache = None

    def distances(self, i, j) -> np.ndarray:
        """Distances of the pairs ``(i[k], j[k])``: the largest over their shared frames
        (:data:`FAR` when they share fewer than ``min_overlap``)."""
        i, j = np.broadcast_arrays(np.asarray(i), np.asarray(j))
        out = np.empty(i.shape)
        fi, fj = i.ravel(), j.ravel()
        flat = out.reshape(-1)
        step = max(1, (1 << 22) // max(self.points.shape[0], 1))
        for s in range(0, fi.size, step):  # bounded (chunk, F) temporaries
            a, b = fi[s:s + step], fj[s:s + step]
            both = self._visible_t[a] & self._visible_t[b]  # (n, F)
            d = self._points_t[a] - self._points_t[b]
            dx, dy = d[..., 0], d[..., 1]  # dx^2 + dy^2: the sum over the last axis, bit for bit
            d2 = np.where(both, dx * dx + dy * dy, 0.0).max(axis=1, initial=0.0)
            flat[s:s + step] = np.where(both.sum(axis=1) >= self.min_overlap, np.sqrt(d2), FAR)
        return out

    def _query(self, radius: float):
        from scipy.spatial import cKDTree

        P = self.n_points
        r = float(radius)

        def listed():  # per frame, the visible pairs within r there
            for f in range(self.points.shape[0]):
                idx = np.flatnonzero(self.visible[f])
                if idx.size < 2:
                    continue
                # a slightly larger ball (relative margin): a superset, the exact test follows
                pairs = cKDTree(self.points[f, idx]).query_pairs(r * (1.0 + 1e-9),
                                                                  output_type="ndarray")
                if pairs.size:
                    a, b = idx[pairs[:, 0]], idx[pairs[:, 1]]
                    yield np.minimum(a, b), np.maximum(a, b)

        i, j, count = _pair_counts(listed(), P, self.min_overlap)
        # within r in every shared frame: found in each of them (a necessary condition,
        # tested on a popcount of the packed masks before the exact distances)
        bits = np.packbits(self.visible, axis=0)  # (ceil(F / 8), P)
        sure = count == np.bitwise_count(bits[:, i] & bits[:, j]).sum(axis=0, dtype=np.int64)
        i, j = i[sure], j[sure]
        d = self.distances(i, j)
        keep = d <= r
        i, j, d = i[keep], j[keep], d[keep]
        allk = np.concatenate([np.arange(P, dtype=np.int64) * (P + 1), i * P + j, j * P + i])
        alld = np.concatenate([np.zeros(P), d, d])
        order = np.argsort(allk)
        allk, alld = allk[order], alld[order]
        self._cache = (r, np.bincount(allk // P, minlength=P), allk % P, alld)

    within = Neighbourhoods.within

    def row(self, i: int, others: np.ndarray) -> np.ndarray:
        """Distances of trajectory ``i`` to ``others`` (1-D), as :meth:`distances`."""
        return self.distances(np.full(others.shape, i), others)


def as_neighbourhoods(points: np.ndarray, distances=None, visible: np.ndarray | None = None):
    """``distances`` (a :class:`Neighbourhoods`, a dense :func:`trajectory_distances`
    matrix, or None: built from ``points``, a :class:`MaskedNeighbourhoods` with
    ``visible``) as a :class:`Neighbourhoods`-like object."""
    if distances is None:
        return Neighbourhoods(points) if visible is None else MaskedNeighbourhoods(points, visible)
    if isinstance(distances, np.ndarray):
        return _DenseNeighbourhoods(distances)
    return distances


def trajectory_distances(points: np.ndarray, n_frames: int = _NEIGHBOURHOOD_FRAMES) -> np.ndarray:
    """Largest distance between two trajectories over evenly spaced frames, dense.

    A P x P matrix (8 bytes x P^2): the reference the stages' :class:`Neighbourhoods`
    equal; the pipeline never builds it.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    n_frames : int
        Frames sampled (evenly spaced, first and last included).

    Returns
    -------
    D : ndarray of shape (P, P)
    """
    frames = _sampled_frames(points.shape[0], n_frames)
    from scipy.spatial.distance import cdist  # lazy: 0.17 s off `import laav`

    D = np.zeros((points.shape[1], points.shape[1]))
    for f in frames:  # scipy's cdist: exact differences, and 2.6x faster than |x|^2 - 2 x.y + |y|^2
        np.maximum(D, cdist(points[f], points[f], "sqeuclidean"), out=D)
    return np.sqrt(D, out=D)


def _rms_residuals(A: np.ndarray, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """RMS over frames of ``|A_f src - dst_f|``; A (..., F, 2, 3), src (n, 2), dst (F, n, 2)."""
    ex, ey = affine_residuals(A, src, dst)  # (..., F, n)
    # np.add.reduce / n is np.mean bit for bit, without its Python overhead (hot path)
    return np.sqrt(np.add.reduce(ex * ex + ey * ey, axis=-2) / ex.shape[-2])


def _rms_rows(X, sol, Y, n_frames):
    """RMS over frames of ``X @ sol - Y``: X (n, 3), sol (..., 3, 2F), Y (n, 2F) -> (..., n)."""
    r = X @ sol - Y
    return np.sqrt(np.add.reduce(r * r, axis=-1) / n_frames)


def _hypothesis_residuals(src: np.ndarray, Y: np.ndarray, seed_pos: int, pairs: np.ndarray) -> np.ndarray:
    """Residuals (B, n, 2F) of every candidate under each hypothesis: the affine map through
    the seed ``src[seed_pos]`` and the candidates ``pairs`` (B, 2) (predicted minus actual,
    coordinates interleaved as in ``Y`` (n, 2F)).

    Written in the seed's frame: with ``u = src - src[seed]`` and ``dY = Y - Y[seed]`` a map
    is ``dY ≈ u M``, ``M = E^-1 dY[pairs]`` with ``E`` (2, 2) the two other samples' ``u``
    as rows, inverted in closed form (``det E`` is twice the triangle's signed area, which
    the caller keeps away from 0). The same maps as solving the homogeneous 3 x 3 systems,
    in a third of the time (no LAPACK call per hypothesis), and better conditioned: the
    coordinates are relative to the seed, not the image corner.
    """
    u = src - src[seed_pos]  # (n, 2)
    dY = Y - Y[seed_pos]  # (n, 2F)
    e = u[pairs]  # (B, 2, 2): rows e1, e2
    det = e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]
    inv = np.empty(e.shape)
    inv[:, 0, 0] = e[:, 1, 1]
    inv[:, 0, 1] = -e[:, 0, 1]
    inv[:, 1, 0] = -e[:, 1, 0]
    inv[:, 1, 1] = e[:, 0, 0]
    inv /= det[:, None, None]
    return u @ (inv @ dY[pairs]) - dY


@functools.lru_cache(maxsize=64)
def _all_pairs(m: int) -> np.ndarray:
    """(m (m - 1) / 2, 2): every pair ``i < j`` of ``range(m)``, in ``np.triu_indices``
    order; cached (read-only) because RANSAC asks for the same few sizes at every seed."""
    pairs = np.stack(np.triu_indices(m, 1), axis=1)
    pairs.flags.writeable = False
    return pairs


def _hypothesis_samples(src: np.ndarray, seed_pos: int, params: LaavParams,
                        rng: np.random.Generator) -> np.ndarray | None:
    """RANSAC's minimal samples, (B', 3) indices into the candidates ``src`` (n, 2): the seed
    ``seed_pos`` and two others each; every pair of others when there are at most
    B = ``ransac_hypotheses`` pairs, else B pairs drawn from ``rng``; samples whose triangle
    is (nearly) flat, twice its area under ``0.05 r2^2``, are left out (so B' <= B). None
    when every one is."""
    n = src.shape[0]
    others = np.arange(n - 1)
    others[seed_pos:] += 1
    B = params.ransac_hypotheses
    if others.size * (others.size - 1) // 2 <= B:
        pairs = others[_all_pairs(others.size)]
    else:
        a = rng.integers(0, others.size, size=(B, 2))
        a[:, 1] = (a[:, 0] + 1 + rng.integers(0, others.size - 1, size=B)) % others.size
        pairs = others[a]
    samp = np.concatenate([np.full((pairs.shape[0], 1), seed_pos), pairs], axis=1)  # (B, 3)
    S = src[samp]
    e1 = S[:, 1] - S[:, 0]
    e2 = S[:, 2] - S[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])  # twice the triangle's area
    ok = area2 > 0.05 * params.r2 ** 2  # reject (near-)collinear samples
    return samp[ok] if ok.any() else None


def _ransac_affine(points, cand, seed_pos, params, rng, skip_first=False):
    """Inliers (bool over cand) of the best affine consensus containing cand[seed_pos], and
    their least-squares maps (Fn, 2, 3) when the last refit confirmed them (else None).

    ``points`` (F, P, 2): the maps go from its frame 0 to every frame, or, with
    ``skip_first``, to every later frame only (the paper's frame pair: ``points`` is then
    frames (l, r), see ``atom_frames`` in :func:`build_atoms`).

    Each hypothesis is the affine map through the seed and two other candidates (all
    pairs when few, random otherwise; near-collinear triples rejected), scored by its
    inlier count. The best is refitted by least squares on its consensus, with
    leave-one-out residuals for the fitted points, until the consensus stops changing.
    The hypotheses' residuals come from :func:`_hypothesis_residuals` (in the seed's frame);
    the refits' predictions are matrix products of the homogeneous candidates ``X`` (n, 3)
    with the maps stacked over frames (3, 2F): a few numpy calls per seed, which is what
    this Python loop over seeds costs.

    Returns ``(None, None)`` when every hypothesis is degenerate.
    """
    n = cand.size
    src = points[0, cand]
    tgt = points[1:] if skip_first else points  # (Fn, P, 2): the frames the maps go to
    Fn = tgt.shape[0]
    X = np.concatenate([src, np.ones((n, 1))], axis=1)  # (n, 3) homogeneous
    Y = np.transpose(tgt[:, cand], (1, 0, 2)).reshape(n, 2 * Fn)  # (n, 2F): x0 y0 x1 y1 ...
    samp = _hypothesis_samples(src, seed_pos, params, rng)
    if samp is None:
        return None, None
    r = _hypothesis_residuals(src, Y, seed_pos, samp[:, 1:])  # (B, n, 2F)
    res = np.sqrt(np.add.reduce(r * r, axis=-1) / Fn)  # (B, n)
    inl = res < params.affine_threshold
    # most inliers; among equals the smallest mean residual, in units of the threshold
    # (1e-6 px at the default 2 px: never worth one inlier, at any scale of the coordinates)
    tie = 1e-6 * (params.affine_threshold / LaavParams.affine_threshold)
    best = int(np.argmax(inl.sum(1) - tie * (np.add.reduce(res, 1) / n)))
    mask = inl[best]
    for _ in range(4):
        if mask.sum() < 4:
            break
        A, h = fit_affine_leverage(src[mask], tgt[:, cand[mask]])
        r = _rms_rows(X, A.transpose(2, 0, 1).reshape(3, 2 * Fn), Y, Fn)
        # a fitted point's residual divided by 1 - h (h its leverage) is its residual
        # under the fit without it: a point of another motion far from the rest (high
        # leverage) pulls the fit through itself and would otherwise look like an inlier
        r[mask] = r[mask] / np.maximum(1.0 - h, 1e-3)
        new = r < params.affine_threshold
        if np.array_equal(new, mask):
            return mask, A  # A: the fit of exactly these inliers
        mask = new
    return mask, None


def _masked_rms(A, defined, src, dst, vis, loo=None):
    """RMS over frames of ``|A_f src - dst_f|``, each point over the frames it is visible
    in and ``A`` defined; with ``loo`` (F, n) the per-frame residuals are divided by it
    (leave-one-out). A (F, 2, 3) (NaN where not ``defined`` (F,)), src (n, 2), dst and
    vis (F, n, 2) / (F, n). Returns (rms (n,), frames judged (n,))."""
    A0 = np.where(defined[:, None, None], A, 0.0)
    ex, ey = affine_residuals(A0, src, dst)  # (F, n)
    e2 = ex * ex + ey * ey
    if loo is not None:
        e2 = e2 / (loo * loo)
    ok = vis & defined[:, None]
    cnt = ok.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt(np.where(ok, e2, 0.0).sum(axis=0) / cnt)
    return rms, cnt


def _ransac_affine_masked(points, vis, cand, seed_pos, ref, params, rng, min_frames):
    """:func:`_ransac_affine` on incomplete data (``atom_frames="all"``).

    ``points`` (F, P, 2) with hidden entries 0, ``vis`` (F, P); every candidate is visible
    in the reference frame ``ref``, which the maps start from. A hypothesis (the seed and
    two candidates, drawn as on complete data) has a map in the frames all three are seen
    in; a candidate's residual is its RMS over the frames it is seen in where the map is
    defined, and it is an inlier below ``affine_threshold`` when judged on at least 2
    frames. The least-squares refits (:func:`laav.geometry.fit_affine_masked`) fit each
    frame on the members visible there (no map with fewer than 3) and judge fitted points
    by their per-frame leave-one-out residuals; a candidate needs ``min_frames`` judged
    frames to be a member.
    """
    n = cand.size
    src = points[ref, cand]
    F = points.shape[0]
    dst = points[:, cand]  # (F, n, 2), 0 where hidden
    V = vis[:, cand]  # (F, n)
    Y = np.transpose(dst, (1, 0, 2)).reshape(n, 2 * F)
    samp = _hypothesis_samples(src, seed_pos, params, rng)
    if samp is None:
        return None
    # (frames the seed is hidden in are never judged: it is in every sample, see hyp)
    r = _hypothesis_residuals(src, Y, seed_pos, samp[:, 1:])  # (B, n, 2F)
    e2f = r[..., 0::2] ** 2 + r[..., 1::2] ** 2  # (B, n, F)
    hyp = V.T[samp].all(axis=1)  # (B, F): frames all three sampled points are seen in
    judged = hyp[:, None, :] & V.T[None]  # (B, n, F)
    cnt = judged.sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        res = np.sqrt(np.where(judged, e2f, 0.0).sum(-1) / cnt)  # (B, n)
    inl = (cnt >= 2) & (res < params.affine_threshold)
    tie = 1e-6 * (params.affine_threshold / LaavParams.affine_threshold)  # as _ransac_affine
    best = int(np.argmax(inl.sum(1) - tie * (np.where(inl, res, 0.0).sum(1) / n)))
    mask = inl[best]
    for _ in range(4):
        if mask.sum() < 4:
            break
        A, h, defined = fit_affine_masked(src[mask], dst[:, mask], V[:, mask])
        if not defined.any():
            return None
        # leverage of every candidate under the fit (the fitted ones: leave-one-out)
        loo = np.ones((F, n))
        loo[:, mask] = np.maximum(1.0 - np.nan_to_num(h, nan=0.0), 1e-3)
        rms, cnt = _masked_rms(A, defined, src, dst, V, loo)
        new = (cnt >= min_frames) & (rms < params.affine_threshold)
        if np.array_equal(new, mask):
            break
        mask = new
    return mask


def _build_atoms_masked(points, vis, params, rng, nb) -> Atoms:
    """:func:`build_atoms` on incomplete data (see ``docs/ALGORITHM.md``, "Missing data").

    As on complete data, with three changes: neighbourhoods are those of
    :class:`MaskedNeighbourhoods` (within the radius over the frames both are seen in,
    which must be at least ``min_overlap``); an atom's maps start from a **reference
    frame**, the frame among the seed's where most of its free neighbours are seen (ties:
    the earliest), and only neighbours seen there are candidates; RANSAC and the fits are
    those of :func:`_ransac_affine_masked`. With ``atom_frames="pair"`` the frame pair is
    drawn among the seed's visible frames, ``F // 3`` apart when it can be, and the
    candidates are the neighbours seen in both.
    """
    from ._visibility import filled, min_overlap

    F, P, _ = points.shape
    pts = filled(points, vis)
    m = min_overlap(F)
    indptr, near, near_d = nb.within(params.r2)
    pair_mode = params.atom_frames == "pair" and F > 2
    gap = max(1, F // 3)
    owner = np.full(P, -1, dtype=np.int64)
    tried = np.zeros(P, dtype=bool)
    members, seeds, affines, residuals, refs, seen = [], [], [], [], [], []
    for s in rng.permutation(P):
        if owner[s] >= 0 or tried[s]:
            continue
        tried[s] = True
        row = slice(indptr[s], indptr[s + 1])
        free = owner[near[row]] < 0
        cand = near[row][free]
        cand_d = near_d[row][free]
        if cand.size < params.atom_min_size:
            continue
        if pair_mode:
            fs = np.flatnonzero(vis[:, s])
            far = fs[fs <= fs[-1] - gap]
            g = gap
            if far.size == 0:  # the seed is not seen F // 3 apart: its widest pair
                far, g = fs[:1], fs[-1] - fs[0]
            left = int(far[rng.integers(far.size)])
            rights = fs[fs >= left + g]
            right = int(rights[rng.integers(rights.size)])
            keep = vis[left, cand] & vis[right, cand]
            cand, cand_d = cand[keep], cand_d[keep]
            if cand.size < params.atom_min_size:
                continue
            seed_pos = int(np.searchsorted(cand, s))
            mask, _ = _ransac_affine(pts[[left, right]], cand, seed_pos, params, rng, skip_first=True)
            ref = left
        else:
            counts = vis[:, cand].sum(axis=1) * vis[:, s]  # candidates seen in each seed frame
            ref = int(np.argmax(counts))
            keep = vis[ref, cand]
            cand, cand_d = cand[keep], cand_d[keep]
            if cand.size < params.atom_min_size:
                continue
            seed_pos = int(np.searchsorted(cand, s))
            mask = _ransac_affine_masked(pts, vis, cand, seed_pos, ref, params, rng, m)
        if mask is None or not mask[seed_pos] or mask.sum() < params.atom_min_size:
            continue
        mem = cand[mask]
        A, _, defined = fit_affine_masked(pts[ref, mem], pts[:, mem], vis[:, mem])
        res, cnt = _masked_rms(A, defined, pts[ref, mem], pts[:, mem], vis[:, mem])
        if not pair_mode and ((res >= params.affine_threshold).any() or (cnt < m).any()):
            continue  # the final model does not hold all its members: no atom here
        if not (np.abs(np.linalg.det(A[defined][:, :, :2])) > 1e-9).all():
            continue  # a degenerate map (members on a line): the graph must invert it
        atom = len(members)
        members.append(mem)
        seeds.append(s)
        affines.append(A)
        residuals.append(res)
        refs.append(ref)
        seen.append(defined)
        inner = mem[cand_d[mask] <= params.r1]
        owner[inner] = atom
        tried[inner] = True
    covered = np.zeros(P, dtype=bool)
    for mm in members:
        covered[mm] = True
    N = len(members)
    return Atoms(
        members=tuple(members),
        seeds=np.asarray(seeds, dtype=np.int64),
        owner=owner,
        affines=np.asarray(affines).reshape(N, F, 2, 3),
        residuals=tuple(residuals),
        unassigned=np.flatnonzero(~covered).astype(np.int64),
        r1=float(params.r1),
        r2=float(params.r2),
        n_points=P,
        ref_frames=np.asarray(refs, dtype=np.int64),
        seen=np.asarray(seen, dtype=bool).reshape(N, F),
    )


def build_atoms(seq: Sequence | np.ndarray, params: LaavParams | None = None,
                rng: np.random.Generator | None = None,
                distances: Neighbourhoods | np.ndarray | None = None, *,
                visible: np.ndarray | None = None) -> Atoms:
    """Group neighbouring trajectories into overlapping locally affine atoms.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    params : LaavParams
        Uses ``r1``, ``r2``, ``atom_min_size``, ``affine_threshold``, ``ransac_hypotheses``,
        ``atom_frames``; with ``noise_adaptive`` the threshold of
        :meth:`LaavParams.for_noise` for the noise measured on ``seq``
        (:func:`laav.noise.estimate_noise`; :class:`laav.Pipeline` measures it once and
        passes the adapted parameters).
    rng : numpy.random.Generator
        Seed order and RANSAC samples.
    distances : Neighbourhoods, optional
        Precomputed :class:`Neighbourhoods` of ``seq`` (reused when only the radii change);
        a dense :func:`trajectory_distances` matrix is accepted too. On incomplete data a
        :class:`MaskedNeighbourhoods`.
    visible : ndarray of shape (F, P), bool, optional
        For an array ``seq`` with missing entries (a :class:`Sequence` carries its own).
        When some entry is hidden the missing-data variant runs (``docs/ALGORITHM.md``,
        "Missing data"); hidden coordinates are never read.

    Returns
    -------
    Atoms
    """
    from ._visibility import visibility

    vis = visibility(seq, visible)
    points = as_points(seq)
    params = LaavParams() if params is None else params
    params, _ = adapted_params(points, params, vis)  # noise_adaptive: thresholds for σ̂
    rng = np.random.default_rng(0) if rng is None else rng
    if vis is not None:
        return _build_atoms_masked(points, vis, params, rng,
                                   as_neighbourhoods(points, distances, vis))
    F, P, _ = points.shape
    indptr, near, near_d = as_neighbourhoods(points, distances).within(params.r2)
    pair_mode = params.atom_frames == "pair" and F > 2
    gap = max(1, F // 3)
    owner = np.full(P, -1, dtype=np.int64)
    tried = np.zeros(P, dtype=bool)
    members, seeds, affines, residuals = [], [], [], []
    for s in rng.permutation(P):
        if owner[s] >= 0 or tried[s]:
            continue
        tried[s] = True
        row = slice(indptr[s], indptr[s + 1])
        free = owner[near[row]] < 0
        cand = near[row][free]  # increasing, as the seed's free neighbours within r2
        if cand.size < params.atom_min_size:
            continue
        seed_pos = int(np.searchsorted(cand, s))
        if pair_mode:  # the paper: one random, well separated frame pair per atom
            left = int(rng.integers(0, F - gap))
            right = int(rng.integers(left + gap, F))
            mask, _ = _ransac_affine(points[[left, right]], cand, seed_pos, params, rng,
                                     skip_first=True)
            A = None  # (its maps go from frame l, the atom's from frame 0)
        else:
            mask, A = _ransac_affine(points, cand, seed_pos, params, rng)
        if mask is None or not mask[seed_pos] or mask.sum() < params.atom_min_size:
            continue
        mem = cand[mask]
        if A is None:  # (when RANSAC's last refit confirmed the inliers, A is their fit)
            A = fit_affine(points[0, mem], points[:, mem])
        res = _rms_residuals(A, points[0, mem], points[:, mem])
        if not pair_mode and (res >= params.affine_threshold).any():
            continue  # the final model does not hold all its members: no atom here
        if not (np.abs(np.linalg.det(A[:, :, :2])) > 1e-9).all():
            continue  # a degenerate map (members on a line): the graph must invert it
        atom = len(members)
        members.append(mem)
        seeds.append(s)
        affines.append(A)
        residuals.append(res)
        inner = mem[near_d[row][free][mask] <= params.r1]
        owner[inner] = atom
        tried[inner] = True
    covered = np.zeros(P, dtype=bool)
    for m in members:
        covered[m] = True
    return Atoms(
        members=tuple(members),
        seeds=np.asarray(seeds, dtype=np.int64),
        owner=owner,
        affines=np.asarray(affines).reshape(len(members), F, 2, 3),
        residuals=tuple(residuals),
        unassigned=np.flatnonzero(~covered).astype(np.int64),
        r1=float(params.r1),
        r2=float(params.r2),
        n_points=P,
    )
