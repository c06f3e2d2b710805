"""Subspace votes: ours, beyond the RV paper, in LAAV's informed trials only.

Random Voting (:mod:`laav.rv`) lets every group fit one fundamental matrix per frame pair
and every point vote by its Sampson distance to it. The epipolar vote alone cannot tell a
static background from an object translating across it (one fundamental matrix fits
both); their trajectories do not share one rank-4 subspace. So, besides its fundamental
matrix, every group fits a rank-4 trajectory subspace to ``rv_subspace_sample`` of its
points (drawn as the epipolar sample is, from the trial's own generator), and a point's
distance becomes its Sampson distance plus ``rv_subspace_weight`` times its squared
distance to the subspace (px^2 per frame): :class:`SubspaceVotes`, the ``extra`` term of
:func:`laav.rv.run_trials`.

Where they run (:func:`for_informed_trial`): in LAAV's informed trials, on complete data,
from a start that labels at least :data:`SUBSPACE_VOTES_MIN_START` of the points, with
``rv_subspace_weight`` > 0 (the default 1, 0.3 in :meth:`laav.LaavParams.with_plain_rv`;
:meth:`laav.LaavParams.paper` sets 0). Never
in plain RV's random starts: with them plain RV measured 2.48 % against 0.92 % on
Hopkins155 (seed 0), a random start locks in. Measured with and without:
``docs/ALGORITHM.md``, row "5 votes".
"""

from __future__ import annotations

import numpy as np

from .params import LaavParams
from .rv import _sample_groups

__all__ = ["SubspaceVotes", "for_informed_trial", "votes_with_subspace", "SUBSPACE_VOTES_MIN_START"]

#: Subspace votes (``rv_subspace_weight``) are used only in a trial whose start labels at
#: least this share of the points: from a mostly random start they lock a wrong partition
#: in, as for plain RV (2.48 % against 0.92 % on Hopkins155, seed 0) and at σ = 1 px, where
#: the atoms cover 0-30 % of the points (8.5 % against 1.6 % without them, seeds 0-1).
#: A majority, set a priori; at σ = 0 it changes one run of 775 (truck1 seed 1, 0 % either way).
SUBSPACE_VOTES_MIN_START = 0.5


class SubspaceVotes:
    """The trajectories and settings of the subspace votes (complete data only).

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    weight : float
        ``rv_subspace_weight``: squared subspace distance (px^2 per frame) added to the
        Sampson distance (px^2) before ``exp(-lambda d)``.
    sample : int
        ``rv_subspace_sample``: points per group the rank-4 subspace is fitted to.
    """

    RANK = 4

    def __init__(self, points: np.ndarray, weight: float, sample: int):
        from .refine import trajectory_matrix

        self.n_frames = points.shape[0]
        self.W = trajectory_matrix(points)  # (2F, P), origin at the points' corner
        self.norm2 = np.einsum("ij,ij->j", self.W, self.W)
        # never more than the points there are (a group smaller than the sample draws
        # from every point, as the epipolar sample does)
        self.weight, self.sample = float(weight), min(int(sample), points.shape[1])

    def distances(self, idx: np.ndarray) -> np.ndarray:
        """Squared distance (px^2 per frame) of every point to each group's subspace.

        ``idx`` (..., C, m): the points each group's subspace is fitted to; returns
        (..., C, P).
        """
        U = self.basis(np.moveaxis(self.W[:, idx], 0, -2))  # (..., C, 2F, 4)
        # a matrix product, not einsum: the same sums, several times faster here
        proj = np.swapaxes(U, -1, -2) @ self.W  # (..., C, 4, P)
        inside = np.add.reduce(proj * proj, axis=-2)
        return np.maximum(self.norm2 - inside, 0.0) / self.n_frames

    @classmethod
    def basis(cls, X: np.ndarray) -> np.ndarray:
        """An orthonormal basis (..., 2F, RANK) of the leading RANK left singular vectors of
        the samples ``X`` (..., 2F, m).

        From the m x m Gram matrix (m = the sample, 16 by default, against 2F rows): its top
        eigenvectors V are X's leading right singular vectors and X V the left ones times
        the singular values sqrt(lam), orthogonal already: divided by them (about twice as
        fast as X's SVD). When a sample spans (nearly) fewer than RANK dimensions, X V is
        orthonormalised by QR instead (dividing would blow up rounding noise).
        """
        lam, V = np.linalg.eigh(np.swapaxes(X, -1, -2) @ X)
        XV = X @ V[..., :, -cls.RANK:]
        top = lam[..., -cls.RANK:]
        if (top[..., 0] > 1e-8 * top[..., -1]).all():
            return XV / np.sqrt(top)[..., None, :]
        return np.linalg.qr(XV)[0]

    def __call__(self, labels: np.ndarray, votes: np.ndarray, C: int, rng,
                 weights=None) -> np.ndarray:
        """The term added to the Sampson distances of one voting step (the ``extra`` of
        :func:`laav.rv.vote`): each group's subspace fitted to a second sample of it,
        drawn after the epipolar one from the same generator(s); (..., C, P).
        ``weights``: the step's sampling weights (``laav.rv._group_weights``), if known."""
        idx = _sample_groups(labels, votes, C, self.sample, rng, weights=weights)
        return self.weight * self.distances(idx)


def for_informed_trial(points: np.ndarray, params: LaavParams, known: np.ndarray,
                       masks=None) -> SubspaceVotes | None:
    """The subspace votes of an informed trial whose start labels the points ``known``
    (P,), or None where the trial votes as Random Voting does: ``rv_subspace_weight`` 0,
    missing data (``masks``), or a start labelling under :data:`SUBSPACE_VOTES_MIN_START`
    of the points."""
    if not votes_with_subspace(params, known, masks):
        return None
    return SubspaceVotes(points, params.rv_subspace_weight, params.rv_subspace_sample)


def votes_with_subspace(params: LaavParams, known: np.ndarray, masks=None) -> bool:
    """Whether an informed trial whose start labels the points ``known`` (P,) votes with
    the subspace term (:func:`for_informed_trial`)."""
    return (params.rv_subspace_weight > 0 and masks is None
            and np.mean(known) >= SUBSPACE_VOTES_MIN_START)
