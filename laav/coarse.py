"""Stage 4: fine-to-coarse, merging the ``2C`` fine models into ``C`` motions.

For every pair of fine models (j, k) and each of ``coarse_frames`` random, well separated
frame pairs (l, r), ``coarse_samples`` times: two atoms are drawn from each model, one
fundamental matrix is fitted (normalised 8-point) to the features of the four atoms, and
the Sampson distances of the features are averaged per model. The pair's epipolar
distance is the larger of the two averages (paper, eq. 3), ``d = max(avg d_jk, avg d_kj)``:
if the models move rigidly together one F explains both and ``d`` is small. All fits of
all pairs are one batched call.

Affinity (where the paper's eq. 4 has a sign/inverse inconsistency we use the form that
measures best): ``Z_jk = mean over samples of exp(-lam d) * exp(-motion_weight m_jk)``,
with ``m_jk`` the motion difference of the models' mean trajectories (largest frame-to-
frame velocity difference over the sequence, divided by the spread of all velocities at
that frame, as in Keuper et al.). The diagonal is 1. Spectral clustering
of Z (scikit-learn's ``SpectralClustering(affinity="precomputed",
assign_labels="cluster_qr")``, computed by :func:`laav._spectral.affinity_clustering`
without importing scikit-learn; the same labels) gives C groups.

**Missing data** (``docs/ALGORITHM.md``, "Missing data"): frame pairs come from
:func:`laav._visibility.pair_pool`; the pairwise votes and pooled voting use only the
features seen in both frames of a pair; the coding merge falls back to this epipolar one.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from ._sequence import Sequence, as_points
from .atoms import Atoms
from .coding import best_partition, merge_cost, model_stats, shortlist
from .geometry import fit_fundamental, sampson_distance
from .multicut import Multicut
from .noise import adapted_params
from .params import LaavParams
from .refine import TINY2, capped_mean, pair_distances
from .voting import frame_pairs

__all__ = ["Coarse", "PairwiseVotes", "Shortlist", "VoteSamples", "merge_models",
           "point_labels_from_atoms", "pooled_voting", "voting_features"]

_PER_ATOM = 6  # features drawn from each atom for one fit
_POOLED_ALPHA = 0.9  # forgetting factor of pooled voting
_JOINT_PAIRS = 8  # frame pairs of the joint merge's epipolar cost


@dataclass(frozen=True, eq=False)
class Shortlist:
    """The partitions the joint merge (``coarse_merge="joint"``) compared.

    The ``coarse_candidates`` partitions of least coding length, scored by increasing coding
    length up to the last one that could still score below the best (by default; every one
    with :func:`merge_models`' ``full_shortlist``): K of them.

    Attributes
    ----------
    assign : ndarray of shape (K, n_fine), int64
        Motion of each fine model, per partition (by increasing coding length).
    coding_length : ndarray of shape (K,)
        Total coding length (nats).
    epipolar_cost : ndarray of shape (K,)
        Sum over the points in atoms of ``log(1 + d)``, ``d`` the point's mean Sampson
        distance to its motion's robust fundamental matrices (units of ``2 / lam``).
    score : ndarray of shape (K,)
        ``coding_length + coarse_epipolar_weight * epipolar_cost``.
    chosen : int
        Index of the partition of least score.
    complete : bool
        Whether every partition of the shortlist was scored (``full_shortlist``, or none
        could be left out); False: the first K only, the rest could not win.
    """

    assign: np.ndarray
    coding_length: np.ndarray
    epipolar_cost: np.ndarray
    score: np.ndarray
    chosen: int
    complete: bool = True


@dataclass(frozen=True, eq=False)
class VoteSamples:
    """For every pair of fine models, one of the samples their pairwise epipolar vote was
    built from: the sample of median distance among the ``K x S`` drawn (K frame pairs,
    S four-atom samples each), so that a viewer sees a typical F the vote used, not one
    refitted for drawing. Entries ``[j, j]`` are empty (frames -1, F zero).

    Attributes
    ----------
    frames : ndarray of shape (n_fine, n_fine, 2), int64
        The sample's frame pair (l, r).
    fundamental : ndarray of shape (n_fine, n_fine, 3, 3)
        Its F, fitted (normalised 8-point) on ``points``: ``x_r^T F x_l = 0``.
    points : ndarray of shape (n_fine, n_fine, 4 m), int64
        The features it was fitted on: two atoms of model j (first half of ``[j, k]``),
        two of model k (m features drawn from each atom, with repeats for small atoms).
    distance : ndarray of shape (n_fine, n_fine)
        Its distance: the larger of the two models' mean Sampson distances (px^2); the
        vote it cast is ``exp(-lam * distance)``.
    """

    frames: np.ndarray
    fundamental: np.ndarray
    points: np.ndarray
    distance: np.ndarray

    @classmethod
    def empty(cls, n: int, width: int) -> VoteSamples:
        return cls(np.full((n, n, 2), -1, dtype=np.int64), np.zeros((n, n, 3, 3)),
                   np.full((n, n, width), -1, dtype=np.int64), np.zeros((n, n)))


@dataclass(frozen=True, eq=False)
class Coarse:
    """Result of the fine-to-coarse merge.

    Attributes
    ----------
    fine_to_coarse : ndarray of shape (n_fine,), int64
        Motion each fine model was merged into.
    affinity : ndarray of shape (n_fine, n_fine)
        The affinity Z that spectral clustering split.
    epipolar_distance : ndarray of shape (n_fine, n_fine)
        Mean epipolar distance ``d`` of each model pair (px^2), 0 on the diagonal
        (``pairwise.distance``).
    motion_distance : ndarray of shape (n_fine, n_fine)
        Motion difference of each model pair.
    atom_labels : ndarray of shape (N,), int64
        Motion of each atom.
    fine_point_labels : ndarray of shape (P,), int64
        Fine model of each feature in an atom, -1 elsewhere.
    point_labels : ndarray of shape (P,), int64
        Motion of each feature in an atom, -1 elsewhere.
    frame_pairs : ndarray of shape (K, 2), int64
        Frame pairs used for voting.
    pair_frames : ndarray of shape (2,), int64
        The frame pair of :meth:`pair_fundamental` (the first and the last frame).
    pairwise : PairwiseVotes
        The paper's pairwise votes. With the joint or coding merge (which do not use
        them) they are fitted when first read: ``epipolar_distance``, ``pairwise_vote``
        and ``vote_samples`` read them.
    method : str
        ``params.coarse_merge``: ``"coding"`` (the partition of least coding length
        decided; ``affinity`` is then ``exp(-max(merge_cost, 0))``) or ``"epipolar"``
        (spectral clustering of the epipolar affinity decided).
    merge_cost : ndarray of shape (n_fine, n_fine)
        Coding length (nats per point) that merging each pair of fine models adds
        (:func:`laav.coding.merge_cost`; computed in both methods, for comparison).
    coding_length : float
        Total coding length of the chosen partition (nats); NaN with the epipolar merge.
    vote_samples : VoteSamples
        One typical sample of every pair's epipolar vote (what the explorer draws;
        ``pairwise.samples``).
    shortlist : Shortlist or None
        ``method="joint"``: the partitions compared and their scores (the first of the
        ``coarse_candidates`` by coding length, up to the last that could still win; all of
        them with :func:`merge_models`' ``full_shortlist``).
    pairwise_vote, coassociation : ndarray of shape (n_fine, n_fine) or None
        The two terms of the epipolar merge's Z, apart: the paper's pairwise vote (mean of
        ``exp(-lam d)`` over the samples, ``pairwise.vote``) and the co-association of the
        pooled-voting trials (identity when pooled voting does not run). ``affinity`` is
        ``(1 - w) coassociation + w pairwise_vote`` times the motion term, w =
        ``pairwise_weight`` (1 without pooled voting).
    """

    fine_to_coarse: np.ndarray
    affinity: np.ndarray
    motion_distance: np.ndarray
    atom_labels: np.ndarray
    fine_point_labels: np.ndarray
    point_labels: np.ndarray
    frame_pairs: np.ndarray
    pair_frames: np.ndarray
    pairwise: PairwiseVotes
    method: str = "epipolar"
    merge_cost: np.ndarray | None = None
    coding_length: float = float("nan")
    coassociation: np.ndarray | None = None
    shortlist: Shortlist | None = None

    @property
    def epipolar_distance(self) -> np.ndarray:
        """``pairwise.distance``: the mean epipolar distance ``d`` of each model pair (px^2)."""
        return self.pairwise.distance

    @property
    def pairwise_vote(self) -> np.ndarray:
        """``pairwise.vote``: the paper's pairwise vote of each model pair."""
        return self.pairwise.vote

    @property
    def vote_samples(self) -> VoteSamples:
        """``pairwise.samples``: one typical sample of every pair's epipolar vote."""
        return self.pairwise.samples

    def pair_fundamental(self, points: np.ndarray, j: int, k: int) -> np.ndarray:
        """F fitted (normalised 8-point) on every feature of fine models ``j`` and ``k``
        over ``pair_frames``, for drawing epipolar lines (``j == k``: model j alone).

        Parameters
        ----------
        points : ndarray of shape (F, P, 2)

        Returns
        -------
        ndarray of shape (3, 3); zeros when the models hold fewer than 8 features.
        """
        g = np.flatnonzero(np.isin(self.fine_point_labels, (j, k)))
        if g.size < 8:
            return np.zeros((3, 3))
        fl, fr = (int(v) for v in self.pair_frames)
        return fit_fundamental(points[fl, g], points[fr, g])


def point_labels_from_atoms(atoms: Atoms, atom_labels: np.ndarray) -> np.ndarray:
    """Label of every feature from the atoms that hold it (-1 for features in none).

    A feature takes its owner atom's label; a shared ring feature the majority label of
    the atoms that hold it (ties to the smallest label).
    """
    P = atoms.n_points
    out = np.full(P, -1, dtype=np.int64)
    if atoms.n_atoms == 0:
        return out
    L = int(atom_labels.max()) + 1
    counts = np.zeros((P, L))
    for i, m in enumerate(atoms.members):
        counts[m, atom_labels[i]] += 1
    has = counts.sum(1) > 0
    out[has] = counts[has].argmax(1)
    owned = atoms.owner >= 0
    out[owned] = atom_labels[atoms.owner[owned]]
    return out


def _motion_distance_masked(points: np.ndarray, vis: np.ndarray, groups: list,
                            floor: float = 1e-3) -> np.ndarray:
    """:func:`_motion_distance` on incomplete data: velocities of the points visible in
    both frames of a step; a model's mean trajectory over its members seen in each frame;
    the largest difference over the steps where both models have one."""
    v = vis[1:] & vis[:-1]  # (F-1, P)
    vel = np.where(v[..., None], np.diff(points, axis=0), 0.0)
    k = np.maximum(v.sum(axis=1), 1)[:, None]
    mean = vel.sum(axis=1) / k
    var = (np.where(v[..., None], (vel - mean[:, None]) ** 2, 0.0).sum(axis=1) / k).sum(-1)
    sigma = np.sqrt(var) + floor  # (F-1,)
    means = []
    for g in groups:
        vg = vis[:, g]
        n = vg.sum(axis=1)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.where(vg[..., None], points[:, g], 0.0).sum(axis=1) / n  # (F, 2), NaN unseen
        means.append(np.diff(c, axis=0))
    means = np.stack(means)  # (n, F-1, 2)
    diff = np.linalg.norm(means[:, None] - means[None, :], axis=-1) / sigma
    if not diff.shape[-1]:
        return np.zeros(diff.shape[:2])
    return np.nan_to_num(np.fmax.reduce(diff, axis=-1), nan=0.0)


def _pairwise_votes_masked(points, vis, atoms, model_atoms, pairs, jj, kk, S, lam, rng, n):
    """The paper's pairwise votes on incomplete data.

    For each frame pair, an atom takes part when at least 3 of its members are visible in
    both frames, and its ``_PER_ATOM`` features are drawn among those; a sample draws two
    such atoms from each model, and the mean Sampson distances of each model are taken as
    on complete data. A model pair with no taking-part atom in a model for a frame pair
    has no sample there. Returns (vote (pairs,), distance (pairs,), VoteSamples), the
    first two NaN where a model pair has no sample at all (and its VoteSamples entry
    empty); the sample kept is the one of median distance among the valid ones.
    """
    K = pairs.shape[0]
    n_pairs = jj.size
    idx = np.zeros((n_pairs, K, S, 4 * _PER_ATOM), dtype=np.int64)
    valid = np.zeros((n_pairs, K, S), dtype=bool)
    for k, (fl, fr) in enumerate(pairs):
        both = vis[fl] & vis[fr]
        table = np.full((atoms.n_atoms, _PER_ATOM), -1, dtype=np.int64)
        for i, m in enumerate(atoms.members):
            vm = m[both[m]]
            if vm.size >= 3:
                table[i] = rng.choice(vm, _PER_ATOM, replace=vm.size < _PER_ATOM)
        ok_atom = table[:, 0] >= 0
        for p, (j, kk_) in enumerate(zip(jj, kk)):
            aj = model_atoms[j][ok_atom[model_atoms[j]]]
            ak = model_atoms[kk_][ok_atom[model_atoms[kk_]]]
            if aj.size == 0 or ak.size == 0:
                continue
            pick = np.concatenate([rng.choice(aj, size=(S, 2)), rng.choice(ak, size=(S, 2))], axis=1)
            idx[p, k] = table[pick].reshape(S, 4 * _PER_ATOM)
            valid[p, k] = True
    half = 2 * _PER_ATOM
    depi = np.empty((n_pairs, K, S))
    cnt = valid.sum(axis=(1, 2))
    samples = VoteSamples.empty(n, 4 * _PER_ATOM)
    per = max(1, _PAIRWISE_BATCH // (K * S))  # model pairs fitted a batch (memory)
    for lo in range(0, n_pairs, per):
        Fm, depi[lo:lo + per] = _sample_fits(points, pairs, idx[lo:lo + per])
        for p in np.flatnonzero(cnt[lo:lo + per] > 0) + lo:
            ks, ss = np.nonzero(valid[p])
            order = np.argsort(depi[p, ks, ss], kind="stable")
            k, s_ = ks[order[order.size // 2]], ss[order[order.size // 2]]
            for a, b, feats in ((jj[p], kk[p], idx[p, k, s_]),
                                (kk[p], jj[p], np.roll(idx[p, k, s_], half))):
                samples.frames[a, b] = pairs[k]
                samples.fundamental[a, b] = Fm[p - lo, k, s_]
                samples.points[a, b] = feats
                samples.distance[a, b] = depi[p, k, s_]
    with np.errstate(invalid="ignore", divide="ignore"):
        vote = np.where(valid, np.exp(-lam * depi), 0.0).sum(axis=(1, 2)) / cnt
        dist = np.where(valid, depi, 0.0).sum(axis=(1, 2)) / cnt
    return np.where(cnt > 0, vote, np.nan), np.where(cnt > 0, dist, np.nan), samples


def _motion_distance(points: np.ndarray, groups: list, floor: float = 1e-3) -> np.ndarray:
    """Largest velocity difference of the groups' mean trajectories over the frames, in
    units of the spread of all velocities at that frame (plus ``floor``, px per frame, so
    a frame where nothing moves divides by no zero): (n, n) for ``n`` groups."""
    v_all = np.diff(points, axis=0)  # (F-1, P, 2)
    sigma = np.sqrt(v_all.var(axis=1).sum(-1)) + floor  # (F-1,)
    means = np.stack([np.diff(points[:, g].mean(axis=1), axis=0) for g in groups])  # (n, F-1, 2)
    diff = np.linalg.norm(means[:, None] - means[None, :], axis=-1) / sigma  # (n, n, F-1)
    return diff.max(axis=-1) if diff.shape[-1] else np.zeros(diff.shape[:2])


#: :func:`voting_features` keeps at least this many features of every fine model (all of a
#: smaller one).
MIN_MODEL_FEATURES = 32


def voting_features(features: np.ndarray, models: np.ndarray, n_models: int, n_keep: int,
                    rng: np.random.Generator) -> np.ndarray:
    """A seeded sample of about ``n_keep`` of ``features`` (sorted indices), stratified by
    fine model: model ``j`` with ``n_j`` of the ``N`` features keeps ``min(n_j, max(MIN,
    ceil(n_keep n_j / N)))`` of them (``MIN`` = :data:`MIN_MODEL_FEATURES`).

    Parameters
    ----------
    features : ndarray of shape (N,), int
    models : ndarray of shape (N,), int
        The fine model of each feature, in ``0 .. n_models - 1``.
    n_models, n_keep : int
    rng : numpy.random.Generator

    Returns
    -------
    ndarray of shape (K,), int: a sorted subset of ``features``
    """
    N = features.size
    keep = []
    for j in range(n_models):
        own = np.flatnonzero(models == j)
        k = min(own.size, max(MIN_MODEL_FEATURES, int(np.ceil(n_keep * own.size / N))))
        keep.append(own if k == own.size else rng.choice(own, k, replace=False))
    return np.sort(features[np.concatenate(keep)]) if keep else features[:0]


def pooled_voting(points: np.ndarray, fine_labels: np.ndarray, n_models: int, n_motions: int,
                  params: LaavParams, rng: np.random.Generator, n_trials: int = 8,
                  max_iter: int = 80, patience: int = 10,
                  visible: np.ndarray | None = None,
                  max_features: int | None = None) -> np.ndarray:
    """Random Voting in which every fine model votes as one unit.

    Each trial starts from a random assignment of the fine models to ``n_motions``
    motions; all trials run at once (batched fits). Every iteration draws a frame pair,
    fits one fundamental matrix per motion to 8 of its features (normalised 8-point),
    lets every atom feature vote
    ``exp(-lam d)`` (Sampson distance ``d``), averages the votes over each model's
    features and moves each model to its best motion; votes decay by 0.9 (RV's usual
    forgetting factor; a fixed constant so that the coarse stage does not depend on the
    fine-tuning's ``rv_alpha``).
    Voting stops when, in every trial, no model moved for ``patience`` iterations.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    fine_labels : ndarray of shape (P,)
        Fine model of each feature, -1 for features in no atom (they do not vote).
    n_models, n_motions : int
    params : LaavParams
        Uses ``lam``.
    rng : numpy.random.Generator
    n_trials, max_iter, patience : int
    visible : ndarray of shape (F, P), bool, optional
        Missing data: each iteration's frame pair is drawn from the pairs of
        :func:`laav._visibility.pair_pool` over the atom features (8 per motion seen in
        both frames), only features seen in both frames are sampled and vote
        (:func:`laav.rv.vote`), and a model none of whose features has voted yet keeps
        its motion. Raises ValueError (from the pool) when no frame pair qualifies.
    max_features : int, optional
        With more atom features than this (thousands of tracks), only a seeded sample of
        this many votes (:func:`voting_features`: every fine model keeps a share in
        proportion to its size, and at least :data:`MIN_MODEL_FEATURES`); a model's vote
        is a mean over its features, which a sample of them estimates. None: all vote.

    Returns
    -------
    assignments : ndarray of shape (n_trials, n_models), int64
        The motion of every fine model at the end of each trial.
    """
    from .voting import vote

    cov = np.flatnonzero(fine_labels >= 0)
    if max_features is not None and cov.size > max_features:
        # a child generator: the voting's own draws below stay those of the parent's stream
        cov = voting_features(cov, fine_labels[cov], n_models, max_features, rng.spawn(1)[0])
    if visible is not None:
        return _pooled_voting_masked(points, visible, fine_labels, cov, n_models, n_motions,
                                     params, rng, n_trials, max_iter, patience)
    pts = points[:, cov]
    f = fine_labels[cov]
    F = points.shape[0]
    gap = max(1, F // 3)
    onehot = np.zeros((n_models, cov.size))
    onehot[f, np.arange(cov.size)] = 1.0
    onehot /= np.maximum(onehot.sum(1, keepdims=True), 1.0)
    # all trials advance together: one batched fit of n_trials x n_motions matrices
    ml = np.stack([rng.permutation(np.arange(n_models) % n_motions) for _ in range(n_trials)])
    hv = np.zeros((n_trials, cov.size, n_motions))
    still = np.zeros(n_trials, dtype=np.int64)
    for _ in range(max_iter):
        left = int(rng.integers(0, F - gap))
        right = int(rng.integers(left + gap, F))
        hv += vote(pts, ml[:, f], hv, (left, right), params.lam, 8, rng)
        new = (onehot @ hv).argmax(-1)  # (trials, models): each model's mean votes
        still = np.where((new == ml).all(axis=1), still + 1, 0)
        ml = new
        hv *= _POOLED_ALPHA
        if (still >= patience).all():
            break
    out = ml
    return out


def _pooled_voting_masked(points, visible, fine_labels, cov, n_models, n_motions, params, rng,
                          n_trials, max_iter, patience):
    """:func:`pooled_voting` on incomplete data (see there)."""
    from ._visibility import filled, pair_pool
    from .voting import vote

    vis = visible[:, cov]
    pts = filled(points[:, cov], vis)
    pool = pair_pool(vis, 8 * n_motions)
    f = fine_labels[cov]
    onehot = np.zeros((n_models, cov.size))
    onehot[f, np.arange(cov.size)] = 1.0
    onehot /= np.maximum(onehot.sum(1, keepdims=True), 1.0)
    ml = np.stack([rng.permutation(np.arange(n_models) % n_motions) for _ in range(n_trials)])
    hv = np.zeros((n_trials, cov.size, n_motions))
    still = np.zeros(n_trials, dtype=np.int64)
    for _ in range(max_iter):
        left, right = pool[int(rng.integers(pool.shape[0]))]
        hv += vote(pts, ml[:, f], hv, (left, right), params.lam, 8, rng, visible=vis)
        mv = onehot @ hv  # (trials, models, motions)
        new = np.where(np.abs(mv).sum(-1) > 0, mv.argmax(-1), ml)  # no vote yet: stays
        still = np.where((new == ml).all(axis=1), still + 1, 0)
        ml = new
        hv *= _POOLED_ALPHA
        if (still >= patience).all():
            break
    return ml


def merge_models(seq: Sequence | np.ndarray, atoms: Atoms, multicut: Multicut, n_motions: int,
                 params: LaavParams | None = None,
                 rng: np.random.Generator | None = None, *,
                 visible: np.ndarray | None = None, memo: dict | None = None,
                 full_shortlist: bool = False) -> Coarse:
    """Merge the fine models of the multicut into ``n_motions`` motions.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    atoms : Atoms
    multicut : Multicut
    n_motions : int
        C.
    params : LaavParams
        Uses ``lam``, ``coarse_frames``, ``coarse_samples``, ``motion_weight``,
        ``rv_max_points`` (how many atom features pooled voting lets vote); with
        ``noise_adaptive`` the ``lam`` of :meth:`LaavParams.for_noise` for the noise
        measured on ``seq`` (:func:`laav.noise.estimate_noise`).
    rng : numpy.random.Generator
    visible : ndarray of shape (F, P), bool, optional
        For an array ``seq`` with missing entries (a :class:`Sequence` carries its own).
        On incomplete data (``docs/ALGORITHM.md``, "Missing data"): the frame pairs are
        drawn from :func:`laav._visibility.pair_pool`; the pairwise votes use, per frame
        pair, the atoms with 3 or more members seen in both frames and only those members
        (a model pair without any sample gets no pairwise term: Z is then the
        co-association alone there, ``pairwise_vote`` and ``epipolar_distance`` NaN);
        pooled voting is :func:`pooled_voting` with the
        mask; the motion term uses the frames where the models are seen. The coding
        length needs whole trajectories: ``merge_cost`` is NaN and
        ``coarse_merge="coding"`` falls back to the epipolar merge, with a
        :class:`laav.LaavWarning` (``method`` then says ``"epipolar"``).
    memo : dict, optional
        Speed only (a live caller's λ moves): a dict the caller keeps for one sequence,
        ``atoms`` and ``multicut`` (and empties when they change). On complete tracks it
        keeps what does not depend on ``lam``: the pairwise votes' samples and their fits
        (keyed on the generator's state before they are drawn, which is restored after
        them as if drawn again), the coding statistics and merge gains, and the joint
        merge's coding-length shortlist and its motions' robust fits (at most
        :data:`_JOINT_ROWS_KEPT` distances; a λ move may score partitions the first run
        did not, whose motions are then fitted). The result is the same, bit for bit.
    full_shortlist : bool
        The joint merge scores every partition of its shortlist (``Coarse.shortlist``), not
        only those that could still win (the default): the same motions, more of the
        comparison to show (the explorer's card 3 draws every pair's margin from it).

    Returns
    -------
    Coarse
    """
    from ._visibility import filled, pair_pool, visibility

    vis = visibility(seq, visible)
    points = as_points(seq)
    params = LaavParams() if params is None else params
    params, _ = adapted_params(points, params, vis)  # noise_adaptive: lam for σ̂
    rng = np.random.default_rng(0) if rng is None else rng
    F, P, _ = points.shape
    n = multicut.n_models
    fine_pts = point_labels_from_atoms(atoms, multicut.atom_labels)
    if vis is None:
        pairs = frame_pairs(F, params.coarse_frames, rng)
    else:
        points = filled(points, vis)
        pool = pair_pool(vis, 8 * max(n_motions, 1))
        pairs = pool[rng.integers(0, pool.shape[0], size=params.coarse_frames)]
        flip = rng.random(params.coarse_frames) < 0.5
        pairs[flip] = pairs[flip][:, ::-1]
    widest = np.array([0, F - 1], dtype=np.int64)
    method = params.merge_for(vis is None)
    coding = method in ("coding", "joint")
    if params.coarse_merge in ("coding", "joint") and vis is not None:
        import warnings

        from ._sequence import LaavWarning, user_stacklevel

        warnings.warn(f"{getattr(seq, 'source', '<array>')}: coarse_merge="
                      f"'{params.coarse_merge}' needs complete trajectories; the epipolar "
                      "merge was used on this incomplete sequence", LaavWarning,
                      stacklevel=user_stacklevel())
    if n == 0:
        e = np.zeros((0, 0))
        none = np.zeros(0, np.int64)
        return Coarse(none, e, e, none, fine_pts, fine_pts.copy(), pairs, widest,
                      PairwiseVotes.computed(0, none, none, e, e, VoteSamples.empty(0, 4 * _PER_ATOM)),
                      method, e, coassociation=e)

    model_atoms = [np.flatnonzero(multicut.atom_labels == j) for j in range(n)]
    groups = [np.flatnonzero(fine_pts == j) for j in range(n)]
    # padded member table: _PER_ATOM features per atom (repeats when smaller)
    table = np.stack([rng.choice(m, _PER_ATOM, replace=m.size < _PER_ATOM)
                      for m in atoms.members])  # (N, _PER_ATOM)
    jj, kk = np.triu_indices(n, 1)
    S = params.coarse_samples
    if jj.size and vis is not None:
        vote, dist, samples = _pairwise_votes_masked(points, vis, atoms, model_atoms, pairs, jj,
                                                     kk, S, params.lam, rng, n)
        votes = PairwiseVotes.computed(n, jj, kk, vote, dist, samples)
    elif jj.size:
        key = ("pairwise", S, repr(rng.bit_generator.state))  # the draws to come: the same
        hit = None if memo is None else memo.get(key)
        if hit is None:  # drawn now, fitted when read (never, by the joint merge alone)
            fits = _PairwiseFits(points, pairs, table,
                                 _pairwise_draws(model_atoms, pairs.shape[0], S, rng, jj, kk),
                                 jj, kk, n)
            _remember(memo, key, (fits, rng.bit_generator.state))
        else:  # λ alone changed: the same samples, the generator where they left it
            fits, after = hit
            rng.bit_generator.state = after
        votes = PairwiseVotes(n, params.lam, fits, jj, kk)
    else:
        votes = PairwiseVotes.computed(n, jj, kk, np.zeros(0), np.zeros(0),
                                       VoteSamples.empty(n, 4 * _PER_ATOM))
    floor = 1e-3 * np.sqrt(LaavParams.lam / params.lam)  # 1e-3 px at the default lam
    if params.motion_weight <= 0:
        Mdist = np.zeros((n, n))
    elif vis is None:
        Mdist = _motion_distance(points, groups, floor)
    else:
        Mdist = _motion_distance_masked(points, vis, groups, floor)
    if vis is None:
        stats = _cached(memo, ("stats",), lambda: model_stats(points, fine_pts, n))
        gain = _cached(memo, ("gain", params.coding_eps),
                       lambda: merge_cost(stats, params.coding_eps))
    else:  # the coding length needs whole trajectories (see the docstring)
        gain = np.full((n, n), np.nan)
        np.fill_diagonal(gain, 0.0)
    pooled = n > n_motions and params.pooled_trials > 0 and not coding
    if pooled and vis is not None:
        try:
            assign = pooled_voting(points, fine_pts, n, n_motions, params, rng,
                                   params.pooled_trials, visible=vis,
                                   max_features=params.rv_max_points)
        except ValueError:  # no frame pair shares enough atom features: pairwise votes only
            pooled = False
    elif pooled:
        assign = pooled_voting(points, fine_pts, n, n_motions, params, rng, params.pooled_trials,
                               max_features=params.rv_max_points)
    if pooled:
        coassoc = (assign[:, :, None] == assign[:, None, :]).mean(axis=0)
    else:
        coassoc = np.eye(n)
    if not coding:  # the epipolar merge's Z (the coding merges build their own below)
        w = params.pairwise_weight if params.pooled_trials > 0 else 1.0
        if vis is not None and not pooled:
            w = 1.0
        pairwise = votes.vote
        Z = (1.0 - w) * coassoc + w * pairwise
        if vis is not None:  # no pairwise sample: the co-association alone (0 without it)
            Z = np.where(np.isnan(pairwise), coassoc if pooled else 0.0, Z)
        Z = Z * np.exp(-params.motion_weight * Mdist)
        np.fill_diagonal(Z, 1.0)

    length = float("nan")
    listed = None
    if coding:  # the partition is searched only when it decides
        if method == "joint" and n > n_motions:
            listed = _joint_shortlist(points, fine_pts, stats, n_motions, params, memo,
                                      full_shortlist)
        if listed is not None:
            assign, length = listed.assign[listed.chosen], float(listed.coding_length[listed.chosen])
        else:  # the coding merge (also the joint one when no partition has 8 points a motion)
            assign, length = best_partition(stats, n_motions, params.coding_eps)
        Z = np.exp(-np.maximum(gain, 0.0))
    if n <= n_motions:
        f2c = np.arange(n, dtype=np.int64)
    elif coding:
        f2c = _canonical(assign)
    else:
        from ._spectral import affinity_clustering

        rng.integers(2**31 - 1)  # (was scikit-learn's random_state: the stream stays as it was)
        f2c = _canonical(affinity_clustering(Z + 1e-9, n_motions))
    atom_coarse = f2c[multicut.atom_labels]
    coarse_pts = np.where(fine_pts >= 0, f2c[np.maximum(fine_pts, 0)], -1)

    return Coarse(
        fine_to_coarse=f2c,
        affinity=Z,
        motion_distance=Mdist,
        atom_labels=atom_coarse,
        fine_point_labels=fine_pts,
        point_labels=coarse_pts,
        frame_pairs=pairs,
        pair_frames=widest,
        method=method,
        merge_cost=gain,
        coding_length=length,
        coassociation=coassoc,
        shortlist=listed,
        pairwise=votes,
    )


#: Entries of each kind a :func:`merge_models` memo keeps (the most recent): a slider over
#: ``coding_eps`` or ``coarse_samples`` would otherwise add one per value.
MEMO_KEPT = 4


def _remember(memo: dict | None, key: tuple, value) -> None:
    """``memo[key] = value``, keeping the :data:`MEMO_KEPT` most recent entries of its kind
    (``key[0]``)."""
    if memo is None:
        return
    memo.pop(key, None)
    memo[key] = value
    same = [k for k in memo if k[0] == key[0]]
    for k in same[:-MEMO_KEPT]:
        del memo[k]


def _cached(memo: dict | None, key: tuple, compute):
    """``memo[key]``, or ``compute()`` remembered there (:func:`_remember`)."""
    if memo is not None and key in memo:
        return memo[key]
    value = compute()
    _remember(memo, key, value)
    return value


def _joint_shortlist(points, fine_pts, stats, n_motions, params, memo=None,
                     full=False) -> Shortlist | None:
    """The joint merge: the ``coarse_candidates`` partitions of least coding length whose
    motions hold 8 points or more (what one fundamental matrix needs), each scored by its
    coding length plus ``coarse_epipolar_weight`` times its epipolar cost; None when no
    partition gives every motion 8 points. They are scored by increasing coding length,
    and (unless ``full``) only until one's coding length alone exceeds the best score so
    far: no later one can score lower (an epipolar cost is >= 0), so the partition chosen is
    the same, and its fits are spared (most of the stage's time). ``memo``: see
    :func:`merge_models` (the shortlist does not depend on ``lam``)."""
    assign, coding = _cached(
        memo, ("shortlist", n_motions, params.coding_eps, params.coarse_candidates),
        lambda: shortlist(stats, n_motions, params.coding_eps, params.coarse_candidates,
                          min_count=8))
    if assign.shape[0] == 0:
        return None
    cov = fine_pts >= 0
    pts, fine = points[:, cov], fine_pts[cov]
    unit2 = LaavParams.lam / params.lam  # the Sampson distance's unit: 1 px^2 at the default
    pairs = frame_pairs(points.shape[0], _JOINT_PAIRS)  # deterministic: no draw from rng
    x1, x2 = pts[pairs[:, 0]], pts[pairs[:, 1]]
    floor2 = TINY2 * _coordinate_unit2(pts)  # the fits' floor: in the coordinates' unit, not λ's
    w = params.coarse_epipolar_weight
    epi = np.full(assign.shape[0], np.nan)
    best = np.inf
    # a motion's per-pair distances, by its fine models: candidates share motions, and the
    # fits do not depend on λ (kept in the memo across λ moves for the present multicut)
    rows = _cached(memo, ("joint rows",), dict)  # (K, its members) per motion
    complete = True
    for i, a in enumerate(assign):
        if not full and w >= 0 and coding[i] > best:
            # the partitions come by increasing coding length and an epipolar cost is >= 0:
            # this one and every later one score above the best so far
            assign, coding, epi = assign[:i], coding[:i], epi[:i]
            complete = False
            break
        lab = a[fine]
        own = np.empty(lab.size)
        for g in range(n_motions):
            key = (a == g).tobytes()
            mem = lab == g
            if key not in rows:
                if sum(r.size for r in rows.values()) > _JOINT_ROWS_KEPT:
                    rows.clear()  # (many coding_eps values over one multicut)
                rows[key] = pair_distances(x1, x2, np.flatnonzero(mem), floor2)[:, mem]
            own[mem] = capped_mean(rows[key], unit2)
        epi[i] = np.log1p(own / unit2).sum()
        s_i = coding[i] + w * epi[i]
        best = min(best, s_i)
        # (a NaN score, which NaN distances would make, ends the pruning: np.argmin below
        # then chooses among all of them, as when every partition is scored)
        full = full or bool(np.isnan(s_i))
    score = coding + w * epi
    return Shortlist(assign, coding, epi, score, int(np.argmin(score)), complete)


#: Most distances (floats) the joint merge keeps for λ moves (:func:`_joint_shortlist`): 32 MB.
_JOINT_ROWS_KEPT = 4_000_000


def _coordinate_unit2(points: np.ndarray) -> float:
    """A squared length unit of the coordinates, 1.0 for a spread of 128-256 px: the
    power of two 4^(e - 8), 2^e the coordinates' RMS distance from their centroid rounded
    up to a power of two. Scaling the coordinates by a power of two scales it exactly; it
    takes the place of λ's unit for the joint merge's fit floor (:data:`laav.refine.TINY2`),
    so that the fits do not depend on λ."""
    x = points.reshape(-1, 2)
    c = np.add.reduce(x, axis=0) / x.shape[0]
    spread = np.sqrt(np.add.reduce(((x - c) ** 2).sum(axis=1)) / x.shape[0])
    e = min(max(int(np.frexp(spread)[1]) - 8, -500), 500)  # (no 0 for a point cloud of one)
    return float(np.ldexp(1.0, 2 * e))


#: Samples (model pair x frame pair x draw) fitted in one batch by the pairwise votes, about
#: 3 KB each: a batch is whole model pairs, so it holds max(this, ``coarse_frames`` x
#: ``coarse_samples``) samples (at the defaults, 56 per pair, every pair at once; at the
#: bounds, 100 x 1,000, one pair: ~300 MB, instead of every pair's at once).
_PAIRWISE_BATCH = 16384


def _sample_fits(points, pairs, idx):
    """One fundamental matrix per sample and its distance: ``idx`` (batch, K, S, 4 m) the
    features of two atoms of each model (model j's first), ``pairs`` (K, 2) the frame pairs.
    Returns (F (batch, K, S, 3, 3), the larger of the two models' mean Sampson distances
    (batch, K, S))."""
    fl = np.broadcast_to(pairs[None, :, None, 0], idx.shape[:3])
    fr = np.broadcast_to(pairs[None, :, None, 1], idx.shape[:3])
    x1 = points[fl[..., None], idx]  # (batch, K, S, 4m, 2)
    x2 = points[fr[..., None], idx]
    Fm = fit_fundamental(x1, x2)
    d = sampson_distance(Fm, x1, x2)  # (batch, K, S, 4m)
    half = 2 * _PER_ATOM
    return Fm, np.maximum(d[..., :half].mean(-1), d[..., half:].mean(-1))


def _pairwise_draws(model_atoms, K, S, rng, jj, kk) -> list:
    """The draws of the paper's pairwise votes on complete tracks: for every model pair
    (jj, kk), frame pair and draw, 2 + 2 atoms, in pair order from ``rng``. Returns the
    atoms drawn, a list of (batch, K, S, 4) int32 arrays of whole model pairs
    (:data:`_PAIRWISE_BATCH` samples a batch; their features are ``table[pick]``)."""
    per = max(1, _PAIRWISE_BATCH // (K * S))  # model pairs a batch
    batches = []
    for lo in range(0, jj.size, per):
        sel = slice(lo, min(lo + per, jj.size))
        pick = np.empty((sel.stop - lo, K, S, 4), dtype=np.int32)
        for p, (j, k) in enumerate(zip(jj[sel], kk[sel])):
            # rng.choice(atoms, size) draw for draw (Generator.choice with replacement indexes
            # by the same integers), without its call overhead
            aj, ak = model_atoms[j], model_atoms[k]
            pick[p, :, :, :2] = aj[rng.integers(0, aj.size, size=(K, S, 2))]
            pick[p, :, :, 2:] = ak[rng.integers(0, ak.size, size=(K, S, 2))]
        batches.append(pick)
    return batches


class _PairwiseFits:
    """The λ-free part of the paper's pairwise votes on complete tracks, fitted when first
    asked (:meth:`get`): one fundamental matrix per drawn sample (:func:`_pairwise_draws`;
    ``table`` (N, ``_PER_ATOM``) the features drawn from each atom), the larger of the two
    models' mean Sampson distances. The joint and coding merges do not use the votes (a
    viewer may draw them), so they are not fitted unless read. Thread-safe (the explorer's
    worker and page threads may both read them); holds ``points`` until fitted (a copy
    when the caller's array is writeable)."""

    def __init__(self, points, pairs, table, batches, jj, kk, n):
        if points.flags.writeable:  # the caller may change it before the votes are read
            points = points.copy()
        self._args = (points, pairs, table, batches, jj, kk, n)
        self._out = None
        self._lock = threading.Lock()

    def get(self) -> tuple:
        """(distances d (n_pairs, K, S), the median samples (:class:`VoteSamples`))."""
        with self._lock:
            if self._out is None:
                self._out = self._fit(*self._args)
                self._args = None  # the points and draws are no longer needed
            return self._out

    @staticmethod
    def _fit(points, pairs, table, batches, jj, kk, n) -> tuple:
        depis = []
        mids = []  # per batch: (frame pair index, F, features, d) of each median sample
        for pick in batches:
            K, S = pick.shape[1:3]
            idx = table[pick].reshape(pick.shape[0], K, S, 4 * _PER_ATOM)
            Fm, depi = _sample_fits(points, pairs, idx)
            depis.append(depi)
            flat = depi.reshape(depi.shape[0], -1)
            mid = np.argsort(flat, axis=1, kind="stable")[:, flat.shape[1] // 2]
            ki, si = np.unravel_index(mid, depi.shape[1:])
            b = np.arange(depi.shape[0])
            mids.append((ki, Fm[b, ki, si], idx[b, ki, si], depi[b, ki, si]))
        ki, Fmid, pts, dmid = (np.concatenate(parts) for parts in zip(*mids))
        return np.concatenate(depis), _median_samples(ki, Fmid, pts, dmid, pairs, jj, kk, n)

    @property
    def done(self) -> bool:
        """Whether the fits are made, without waiting for a fit in progress (whose lock
        :meth:`pending` takes: a viewer's thread asks this while a worker fits)."""
        return self._out is not None

    def pending(self) -> tuple | None:
        """The arguments of :func:`fit_pairwise` still to run, or None when fitted."""
        with self._lock:
            return None if self._out is not None else self._args

    def put(self, out: tuple) -> None:
        """The value of :func:`fit_pairwise` on :meth:`pending`'s arguments, computed
        elsewhere (the voting helper's process): the same numbers :meth:`get` makes."""
        with self._lock:
            if self._out is None:
                self._out, self._args = out, None

    def __getstate__(self):  # pickled (a pipeline's state sent between processes): fitted
        return {"_out": self.get()}

    def __setstate__(self, state):
        self._args, self._out, self._lock = None, state["_out"], threading.Lock()


def fit_pairwise(*args) -> tuple:
    """:meth:`_PairwiseFits.get`'s fit on its arguments (:meth:`_PairwiseFits.pending`), by
    name: what another process runs for it."""
    return _PairwiseFits._fit(*args)


class PairwiseVotes:
    """The paper's pairwise epipolar votes of every pair of fine models, and what they were
    built from (Z's term in the epipolar merge).

    Attributes (read-only properties)
    ----------
    distance : ndarray of shape (n_fine, n_fine)
        Mean epipolar distance ``d`` of each model pair over its samples (px^2), 0 on the
        diagonal (NaN on incomplete tracks where a pair has no sample).
    vote : ndarray of shape (n_fine, n_fine)
        Mean of ``exp(-lam d)`` over the samples, 1 on the diagonal (NaN as ``distance``).
    samples : VoteSamples
        The sample of median distance of every pair.

    On complete tracks the samples are drawn when the merge runs, so the generator's
    stream is the same whether or not they are read, and fitted when one of these is
    first read: the joint and coding merges do not need them (the default on complete
    tracks), the epipolar merge and a viewer do.
    """

    def __init__(self, n: int, lam: float, fits: _PairwiseFits | None, jj, kk):
        """Votes of strength ``lam`` for the model pairs (jj, kk) of ``n`` fine models,
        from ``fits`` when first read (see :meth:`computed` for votes already made)."""
        self._n, self._lam, self._fits, self._jj, self._kk = n, lam, fits, jj, kk
        self._vote = self._distance = self._samples = None

    @classmethod
    def computed(cls, n: int, jj, kk, vote, distance, samples: VoteSamples) -> PairwiseVotes:
        """Votes already computed: ``vote``, ``distance`` (n_pairs,) for the pairs (jj, kk)."""
        out = cls(n, float("nan"), None, jj, kk)
        out._fill(jj, kk, vote, distance, samples)
        return out

    def _fill(self, jj, kk, vote, distance, samples) -> None:
        D = np.zeros((self._n, self._n))
        D[jj, kk] = D[kk, jj] = distance
        V = np.eye(self._n)
        V[jj, kk] = V[kk, jj] = vote
        self._distance, self._samples = D, samples
        self._vote = V  # last: a reader that sees it sees the others

    def unfitted(self):
        """The fits still to make, for a caller that makes them elsewhere (``pending()``,
        then ``put(fit_pairwise(*args))``), or None when the votes are fitted already."""
        fits = self._fits
        if self._vote is not None or fits is None or fits.pending() is None:
            return None
        return fits

    @property
    def fitted(self) -> bool:
        """Whether reading the votes is immediate (no fit to make or wait for); never
        waits itself."""
        fits = self._fits
        return self._vote is not None or fits is None or fits.done

    def _ensure(self) -> None:
        fits = self._fits
        if self._vote is None and fits is not None:  # (two threads may both get here: the
            depi, samples = fits.get()  # fits are made once, the same values filled twice)
            self._fill(self._jj, self._kk, np.exp(-self._lam * depi).mean(axis=(1, 2)),
                       depi.mean(axis=(1, 2)), samples)

    @property
    def distance(self) -> np.ndarray:
        self._ensure()
        return self._distance

    @property
    def vote(self) -> np.ndarray:
        self._ensure()
        return self._vote

    @property
    def samples(self) -> VoteSamples:
        self._ensure()
        return self._samples


def _median_samples(ki, Fmid, pts, dmid, pairs, jj, kk, n) -> VoteSamples:
    """The sample of median distance of every model pair (j < k, mirrored to k > j), from
    each pair's median sample: its frame pair index ``ki`` (n_pairs,) into ``pairs`` (K, 2),
    fundamental matrix ``Fmid`` (n_pairs, 3, 3), features ``pts`` (n_pairs, 4 m) and
    distance ``dmid`` (n_pairs,)."""
    out = VoteSamples.empty(n, pts.shape[-1])
    half = pts.shape[-1] // 2
    for a, b, first_a in ((jj, kk, pts), (kk, jj, np.roll(pts, half, axis=-1))):
        out.frames[a, b] = pairs[ki]
        out.fundamental[a, b] = Fmid
        out.points[a, b] = first_a  # [a, b]: model a's features first
        out.distance[a, b] = dmid
    return out


def _canonical(labels: np.ndarray) -> np.ndarray:
    """Renumber labels in order of first appearance."""
    _, first = np.unique(labels, return_index=True)
    order = np.argsort(first)
    rank = np.empty(order.size, dtype=np.int64)
    rank[order] = np.arange(order.size)
    return rank[np.searchsorted(np.unique(labels), labels)]
