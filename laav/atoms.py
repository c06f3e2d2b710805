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
  for the whole sequence and its affine premise holds.
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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._sequence import Sequence, as_points
from .geometry import affine_residuals, fit_affine, fit_affine_leverage
from .params import LaavParams

__all__ = ["Atoms", "build_atoms", "trajectory_distances"]

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
        Each atom's affine map from frame 0 to every frame, fitted on its members.
    residuals : tuple of N ndarrays
        RMS residual (px) over all frames of each member under its atom's affine model.
    unassigned : ndarray of shape (K,), int64
        Features that belong to no atom.
    r1, r2 : float
        The radii used (px).
    n_points : int
        P.
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

    def centers(self, points: np.ndarray) -> np.ndarray:
        """Mean position of each atom's members in every frame, shape (F, N, 2)."""
        if self.n_atoms == 0:
            return np.zeros((points.shape[0], 0, 2))
        return np.stack([points[:, m].mean(axis=1) for m in self.members], axis=1)


def trajectory_distances(points: np.ndarray, n_frames: int = _NEIGHBOURHOOD_FRAMES) -> np.ndarray:
    """Largest distance between two trajectories over evenly spaced frames.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    n_frames : int
        Frames sampled (evenly spaced, first and last included).

    Returns
    -------
    D : ndarray of shape (P, P)
    """
    F = points.shape[0]
    frames = np.unique(np.round(np.linspace(0, F - 1, min(n_frames, F))).astype(int))
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


def _ransac_affine(points, cand, seed_pos, params, rng, skip_first=False):
    """Inliers (bool over cand) of the best affine consensus containing cand[seed_pos].

    ``points`` (F, P, 2): the maps go from its frame 0 to every frame, or, with
    ``skip_first``, to every later frame only (the paper's frame pair: ``points`` is then
    frames (l, r), see ``atom_frames`` in :func:`build_atoms`).

    Each hypothesis is the affine map through the seed and two other candidates (all
    pairs when few, random otherwise; near-collinear triples rejected), scored by its
    inlier count. The best is refitted by least squares on its consensus, with
    leave-one-out residuals for the fitted points, until the consensus stops changing.
    Predictions are matrix products of the homogeneous candidates ``X`` (n, 3) with the
    maps stacked over frames (3, 2F): a few numpy calls per seed, which is what this
    Python loop over seeds costs.
    """
    n = cand.size
    src = points[0, cand]
    tgt = points[1:] if skip_first else points  # (Fn, P, 2): the frames the maps go to
    Fn = tgt.shape[0]
    X = np.concatenate([src, np.ones((n, 1))], axis=1)  # (n, 3) homogeneous
    Y = np.transpose(tgt[:, cand], (1, 0, 2)).reshape(n, 2 * Fn)  # (n, 2F): x0 y0 x1 y1 ...
    others = np.arange(n - 1)
    others[seed_pos:] += 1
    B = params.ransac_hypotheses
    # pairs of other candidates (all pairs when few, random otherwise)
    if others.size * (others.size - 1) // 2 <= B:
        iu = np.triu_indices(others.size, 1)
        pairs = np.stack([others[iu[0]], others[iu[1]]], axis=1)
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
    if not ok.any():
        return None
    samp = samp[ok]
    sol = np.linalg.solve(X[samp], Y[samp])  # (B, 3, 2F)
    res = _rms_rows(X, sol, Y, Fn)  # (B, n)
    inl = res < params.affine_threshold
    best = int(np.argmax(inl.sum(1) - 1e-6 * (np.add.reduce(res, 1) / n)))
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
            break
        mask = new
    return mask


def build_atoms(seq: Sequence | np.ndarray, params: LaavParams | None = None,
                rng: np.random.Generator | None = None,
                distances: np.ndarray | None = None) -> Atoms:
    """Group neighbouring trajectories into overlapping locally affine atoms.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    params : LaavParams
        Uses ``r1``, ``r2``, ``atom_min_size``, ``affine_threshold``, ``ransac_hypotheses``.
    rng : numpy.random.Generator
        Seed order and RANSAC samples.
    distances : ndarray of shape (P, P), optional
        Precomputed :func:`trajectory_distances` (reused when only the radii change).

    Returns
    -------
    Atoms
    """
    points = as_points(seq)
    params = LaavParams() if params is None else params
    rng = np.random.default_rng(0) if rng is None else rng
    F, P, _ = points.shape
    D = trajectory_distances(points) if distances is None else distances
    near2 = D <= params.r2
    pair_mode = params.atom_frames == "pair" and F > 2
    gap = max(1, F // 3)
    owner = np.full(P, -1, dtype=np.int64)
    tried = np.zeros(P, dtype=bool)
    members, seeds, affines, residuals = [], [], [], []
    for s in rng.permutation(P):
        if owner[s] >= 0 or tried[s]:
            continue
        tried[s] = True
        cand = np.flatnonzero(near2[s] & (owner < 0))
        if cand.size < params.atom_min_size:
            continue
        seed_pos = int(np.searchsorted(cand, s))
        if pair_mode:  # the paper: one random, well separated frame pair per atom
            left = int(rng.integers(0, F - gap))
            right = int(rng.integers(left + gap, F))
            mask = _ransac_affine(points[[left, right]], cand, seed_pos, params, rng,
                                  skip_first=True)
        else:
            mask = _ransac_affine(points, cand, seed_pos, params, rng)
        if mask is None or not mask[seed_pos] or mask.sum() < params.atom_min_size:
            continue
        mem = cand[mask]
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
        inner = mem[D[s, mem] <= params.r1]
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
