"""Random Voting (Jung, Ju & Kim, CVPR 2014): the paper's algorithm, vectorised.

Each iteration draws one frame pair; every group fits a fundamental matrix to ``m`` of
its points by the normalised 8-point algorithm (all groups, and all trials running side
by side, in one batched call); every point receives, from each group's matrix, the vote
``exp(-lambda d)`` for that group and ``1 - exp(-lambda d)`` for every other group, where
``d`` is its Sampson distance (px^2); labels become the argmax of the vote histogram,
which then decays by the forgetting factor ``alpha``. A trial starts from a random
partition (plain RV) or from given labels (LAAV's fine-tuning, see
:func:`laav.voting.random_voting`), and has converged when no label changed for
``rv_patience`` iterations; plain RV resets its votes once, at iteration 15.

Choices where the RV paper is vague (measured on Hopkins155, ``benchmarks/TUNING.md``):

* **Sampling.** The ``m`` points of a group are drawn without replacement with
  probability proportional to their current vote margin for the group (weighted
  reservoir keys ``log(u) / w``), so confident members dominate but the sample stays
  spread; a group with fewer than ``m`` members samples from all points.
* **Frame pairs.** The two frames are at least ``max(1, F // 3)`` apart. On incomplete
  data a pair is drawn uniformly from those that also share enough visible points
  (:func:`laav._visibility.pair_pool`), only the points visible in both frames are
  sampled and receive votes, and a point not voted on keeps its label and its votes (they
  decay only when it is voted on).
* **No converged trial.** The labellings of all trials are combined into a
  co-association affinity and split by spectral clustering (:func:`consensus`).
* **Trials side by side** (``rv_batch``): speed only; the plain trial kept is the first
  *in start order* to converge, exactly as if the trials ran one after another.

One hook for what is ours: an ``extra`` distance term added to the Sampson distances of
LAAV's informed trial (:func:`run_trials`, :func:`vote`); LAAV passes its subspace votes
(:mod:`laav.subspace_votes`) there. Everything else beyond the paper (refinement, joint
reassignment, model selection, LAAV's own candidates) is in :mod:`laav.voting` (the
entry point), :mod:`laav.selection`, :mod:`laav.own_chain` and :mod:`laav.refine`.
"""

from __future__ import annotations

import numpy as np

from ._interrupt import check as check_interrupt
from .geometry import fit_fundamental, sampson_distance

__all__ = ["vote", "run_trials", "consensus", "consensus_seed", "RESET_AT"]

#: Plain RV resets its votes once, at this iteration (RV paper).
RESET_AT = 15


def _group_weights(labels, votes, C, avail=None):
    """The sampling weights (..., C, P) of :func:`_sample_groups` before its small-group
    rule, and each group's member count (..., C): one voting step's epipolar and subspace
    samples share them."""
    member = labels[..., None, :] == np.arange(C)[:, None]  # (..., C, P)
    if avail is not None:
        member = member & avail[..., None, :]
    # contiguous rows: numpy's reductions over P of the strided view were ~20x slower
    vt = np.ascontiguousarray(np.swapaxes(votes, -1, -2))  # (..., C, P)
    if C == 2:  # the margin over the other group, as below but without the sort
        w = vt - vt[..., ::-1, :]
    elif C > 2:  # the margin over the best other group
        is_top = np.arange(C)[:, None] == np.argmax(vt, axis=-2)[..., None, :]
        top = vt.max(axis=-2, keepdims=True)
        second = np.where(is_top, -np.inf, vt).max(axis=-2, keepdims=True)  # = top on ties
        w = vt - np.where(is_top, second, top)
    else:
        w = vt.copy()
    np.maximum(w, 0.0, out=w)
    w /= w.max(axis=-1, keepdims=True) + 1e-12
    w += 0.05  # the floor keeps every member drawable
    return np.where(member, w, 0.0), member.sum(axis=-1)


def _sample_groups(labels, votes, C, m, rng, avail=None, weights=None):
    """Indices (..., C, m) of the points each group fits its fundamental matrix to.

    ``labels`` (..., P) and ``votes`` (..., P, C) may carry leading batch axes (trials).
    ``avail`` (..., P) bool (missing data): only these points are drawn, and a group with
    fewer than ``m`` of them samples from all available points (there must be ``m``).
    ``weights``: :func:`_group_weights` of the same arguments, when already computed.
    """
    w, count = _group_weights(labels, votes, C, avail) if weights is None else weights
    small = count < m
    if small.any():
        w = np.where(small[..., None], 1.0 if avail is None else avail[..., None, :] * 1.0, w)
    # weighted sampling without replacement (Efraimidis-Spirakis): the m largest keys
    # log(u) / w, i.e. the m smallest of -log(u) / w; non-members never drawn
    if isinstance(rng, np.random.Generator):
        u = rng.random(w.shape)
    else:  # one generator per trial (leading axis): a trial's draws never depend on the batch
        u = np.stack([r.random(w.shape[1:]) for r in rng])
    neg_keys = np.where(w > 0, -np.log(u) / np.maximum(w, 1e-12), np.inf)
    return np.argpartition(neg_keys, m - 1, axis=-1)[..., :m]


def vote(points: np.ndarray, labels: np.ndarray, votes: np.ndarray, pair, lam: float,
         m: int, rng: np.random.Generator, visible: np.ndarray | None = None,
         extra=None) -> np.ndarray:
    """One voting step on frame pair ``pair``: one F per group, the votes of every point.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    labels : ndarray of shape (..., P)
    votes : ndarray of shape (..., P, C)
        Current histogram (guides which points are sampled).
    pair : (int, int) or ndarray of shape (B, 2)
        The frame pair, or one pair per trial when ``labels`` is (B, P) (trials voting
        side by side).
    lam : float
    m : int
        Points per fit.
    rng : numpy.random.Generator, or a sequence of B of them
        With ``labels`` (B, P), one generator per trial makes every trial's sample
        independent of which other trials share the batch.
    visible : ndarray of shape (F, P), bool, optional
        Missing data: only the points visible in both frames of the pair are sampled for
        the fits and receive votes (the others get 0); ``points`` must be finite
        everywhere (hidden entries filled, e.g. with 0) and at least ``m`` points must be
        visible in both frames.
    extra : callable, optional
        Not in the RV paper: ``extra(labels, votes, C, rng, weights)`` returns a term
        (..., C, P) added to the Sampson distances, drawing after the epipolar sample from
        the same generator(s) (LAAV's subspace votes,
        :class:`laav.subspace_votes.SubspaceVotes`); ``weights`` are the step's sampling
        weights (:func:`_group_weights`), for a sample of its own.

    Returns
    -------
    ndarray of shape (..., P, C)
        ``exp(-lam d)`` for the point's vote for a group, ``1 - exp(-lam d)`` from every
        other group's matrix (0 for points not visible in the pair).
    """
    C = votes.shape[-1]
    pair = np.asarray(pair)
    avail = None
    if visible is not None:
        avail = visible[pair[..., 0]] & visible[pair[..., 1]]  # (P,) or (B, P)
        if pair.ndim == 1 and labels.ndim > 1:
            avail = np.broadcast_to(avail, labels.shape)
    weights = _group_weights(labels, votes, C, avail)
    idx = _sample_groups(labels, votes, C, m, rng, avail, weights)  # (..., C, m)
    x1 = points[pair[..., 0]]  # (P, 2), or (B, P, 2) with a pair per trial
    x2 = points[pair[..., 1]]
    if pair.ndim == 1:
        F = fit_fundamental(x1[idx], x2[idx])  # (..., C, 3, 3)
    else:
        b = np.arange(pair.shape[0])[:, None, None]
        F = fit_fundamental(x1[b, idx], x2[b, idx])  # (B, C, 3, 3)
        x1, x2 = x1[:, None], x2[:, None]
    d = sampson_distance(F, x1, x2)  # (..., C, P)
    if extra is not None:
        d += extra(labels, votes, C, rng, weights)
    v = np.exp(-lam * d)
    other = 1.0 - v
    total_other = np.add.reduce(other, axis=-2, keepdims=True)  # (..., 1, P)
    v -= other
    v += total_other
    if avail is not None:
        v *= avail[..., None, :]
    return np.swapaxes(v, -1, -2)


class LabelTrace:
    """A trial's labels at its start and after every iteration, kept as the changes.

    Row 0 is the start; row k the labels after iteration k. Stored as the start plus, per
    iteration, the points whose label changed and their new labels, so a trial that runs
    10,000 iterations over 1,000 points while a few points flip holds kilobytes, not the
    10 MB of the dense array (every trial of every plain-RV run a :class:`laav.Pipeline`
    keeps holds one). A record only, never read by the voting.

    Parameters
    ----------
    start : ndarray of shape (P,)
    index : ndarray of shape (N,), int32
        The changed points of every iteration, one after another.
    value : ndarray of shape (N,)
        Their new labels.
    ends : ndarray of shape (T,), int64
        ``index[ends[k - 1]:ends[k]]`` changed at iteration k + 1 (``ends[-1] == N``).
    """

    __slots__ = ("start", "index", "value", "ends", "_dense")

    def __init__(self, start, index, value, ends):
        self.start, self.index, self.value, self.ends = start, index, value, ends
        self._dense = None

    def __len__(self) -> int:
        return self.ends.size + 1

    @property
    def nbytes(self) -> int:
        return self.start.nbytes + self.index.nbytes + self.value.nbytes + self.ends.nbytes

    def dense(self) -> np.ndarray:
        """The labels of every row: ndarray of shape (T + 1, P), the start's dtype. Made
        once: a trial that is both LAAV's informed one and the one returned gives one
        array to both of a :class:`laav.Voting`'s traces (and to its preview's)."""
        if self._dense is None:
            out = np.empty((len(self), self.start.size), dtype=self.start.dtype)
            out[0] = self.start
            lo = 0
            for k, hi in enumerate(self.ends.tolist(), start=1):
                out[k] = out[k - 1]
                out[k, self.index[lo:hi]] = self.value[lo:hi]
                lo = hi
            out.flags.writeable = False  # shared: nobody may change it
            self._dense = out
        return self._dense


class _Trial:
    """Working state of one voting trial (internal; several run side by side)."""

    def __init__(self, labels, votes, reset, kind, rng):
        self.labels, self.votes, self.rng = labels, votes, rng
        self.reset, self.kind = reset, kind
        self.changed: list = []
        self.margins: list = []
        #: the labels at the start and the changes of every iteration (:class:`LabelTrace`:
        #: what the explorer draws as error per iteration); a record only
        self.dtype = np.int8 if votes.shape[-1] <= 127 else np.int32
        self.start = np.array(labels, dtype=self.dtype)
        self.flips: list = []  # (points, new labels) of every iteration
        self.it = 0
        self.still = 0
        self.converged = False
        self.done = False
        self._result = None

    def result(self) -> tuple:
        """(labels, votes, changed, margins, iterations, converged, :class:`LabelTrace`:
        the start and every iteration's labels, int8 (int32 above 127 motions)). Made once
        per trial (a trial is asked for it several times once it ended: one copy)."""
        if self._result is None or self._result[4] != self.it:
            counts = np.array(self.changed, dtype=np.int64)
            if self.flips:
                index = np.concatenate([f[0] for f in self.flips])
                value = np.concatenate([f[1] for f in self.flips])
            else:
                index, value = np.zeros(0, np.int32), np.zeros(0, self.dtype)
            trace = LabelTrace(self.start, index, value, np.cumsum(counts))
            self._result = (self.labels, self.votes, counts, np.array(self.margins), self.it,
                            self.converged, trace)
        return self._result


def _margins(votes: np.ndarray) -> np.ndarray:
    """Mean normalised vote margin per trial; votes (B, P, C) -> (B,)."""
    C = votes.shape[-1]
    if C == 1:
        return np.ones(votes.shape[0])
    if C == 2:  # as below, without the partition (and the slow reduction over 2 columns)
        v0, v1 = votes[..., 0], votes[..., 1]
        spread = np.abs(v1 - v0)
        return np.add.reduce(spread / (np.abs(v0) + np.abs(v1) + 1e-12), axis=-1) / spread.shape[-1]
    top2 = np.partition(votes, C - 2, axis=-1)[..., -2:]
    spread = top2[..., 1] - top2[..., 0]
    return np.add.reduce(spread / (np.abs(votes).sum(-1) + 1e-12), axis=-1) / spread.shape[-1]


def _frame_pair(F: int, rng: np.random.Generator) -> tuple[int, int]:
    """A random frame pair at least ``max(1, F // 3)`` apart, in random order."""
    gap = max(1, F // 3)
    left = int(rng.integers(0, F - gap))
    right = int(rng.integers(left + gap, F))
    return (right, left) if rng.random() < 0.5 else (left, right)


def _pool_pair(pool: np.ndarray, rng: np.random.Generator) -> tuple[int, int]:
    """Missing data: a pair of ``pool`` (K, 2) drawn uniformly, in random order."""
    left, right = (int(v) for v in pool[int(rng.integers(pool.shape[0]))])
    return (right, left) if rng.random() < 0.5 else (left, right)


def _step(points, trials, params, masks=None, extra=None):
    """One voting iteration of every trial in ``trials``, in one batched call; every
    random draw of a trial comes from its own generator. ``masks`` (missing data): the
    ``(visible, pool)`` of :func:`run_trials`."""
    F, P, _ = points.shape
    labels = np.stack([t.labels for t in trials])  # (B, P)
    votes = np.stack([t.votes for t in trials])  # (B, P, C)
    if masks is None:
        pairs = np.array([_frame_pair(F, t.rng) for t in trials])  # (B, 2)
        votes += vote(points, labels, votes, pairs, params.rv_lambda, params.rv_sample_size,
                      [t.rng for t in trials], extra=extra)
    else:
        visible, pool = masks
        pairs = np.array([_pool_pair(pool, t.rng) for t in trials])  # (B, 2)
        votes += vote(points, labels, votes, pairs, params.rv_lambda, params.rv_sample_size,
                      [t.rng for t in trials], visible=visible)
    if votes.shape[-1] == 2:  # argmax, without numpy's slow reduction over 2 columns
        new = (votes[..., 1] > votes[..., 0]).astype(np.intp)
    else:
        new = votes.argmax(axis=-1)
    if masks is not None:  # a point not voted on this iteration keeps its label
        seen = masks[0][pairs[:, 0]] & masks[0][pairs[:, 1]]  # (B, P)
        new = np.where(seen, new, labels)
    flipped = new != labels
    n_changed = flipped.sum(axis=-1)
    if masks is None:
        votes *= params.rv_alpha
    else:  # each point's votes decay on its own clock: by the iterations that voted on it
        votes *= np.where(seen, params.rv_alpha, 1.0)[..., None]
    margins = _margins(votes)
    for b, t in enumerate(trials):
        t.it += 1
        t.labels, t.votes = new[b], votes[b]
        t.changed.append(int(n_changed[b]))
        t.margins.append(float(margins[b]))
        moved = np.flatnonzero(flipped[b]).astype(np.int32)
        t.flips.append((moved, new[b][moved].astype(t.dtype)))
        if t.reset and t.it == RESET_AT:
            t.votes = np.zeros_like(t.votes)
            t.still = 0
        else:
            t.still = t.still + 1 if n_changed[b] == 0 else 0
            if t.still >= params.rv_patience and (not t.reset or t.it > RESET_AT):
                t.converged = t.done = True
        if t.it >= params.rv_max_iter:
            t.done = True


def run_trials(points, C, params, rng, informed=None, n_plain=None, streams=None, masks=None,
               extra=None):
    """Run LAAV's informed trial and plain RV's random-start trials, ``rv_batch`` side by side.

    Trials advance in lockstep, one batched numpy call per iteration, each with its own
    frame pairs, samples, iteration count and convergence test; a trial starts when a slot
    is free. Plain trials (at most ``n_plain``) start until one converges; the one kept
    is the first *in start order* to converge, as if the trials ran one after another.
    The informed trial always runs to its end. Every trial draws from its own generator
    (spawned from ``rng`` in start order), so the labels do not depend on ``rv_batch``.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2)
    C : int
    params : LaavParams
        Uses the ``rv_*`` fields.
    rng : numpy.random.Generator
        Spawns one generator per trial (:meth:`numpy.random.Generator.spawn`).
    informed : (labels0, votes0) or None
        Start labels (P,) and votes (P, C) of LAAV's informed trial.
    n_plain : int, optional
        Most plain trials to start (default ``rv_trials``).
    streams : sequence of numpy.random.Generator, optional
        The trials' generators, ``[informed, plain 0, plain 1, ...]`` (``1 + n_plain`` of
        them), instead of spawning them from ``rng``: a trial's result depends only on its
        own generator, so a caller may run LAAV's trial and plain RV's apart.
    masks : (visible, pool) or None
        Missing data: ``visible`` (F, P) bool and the frame pairs ``pool`` (K, 2) of
        :func:`laav._visibility.pair_pool`; each iteration draws its pair from the pool
        (uniformly, in random order), fits and votes on the points visible in both frames
        only (:func:`vote`), and a point not voted on keeps its label and its votes (the
        forgetting factor applies to the points voted on: each point's histogram decays
        by its own votes). ``points`` must be finite everywhere (hidden entries filled).
    extra : callable, optional
        Complete data and LAAV's informed trial alone (``n_plain=0``) only: the term
        :func:`vote` adds to the Sampson distances (ours, not the RV paper's:
        :func:`laav.subspace_votes.for_informed_trial`).

    Returns
    -------
    first : tuple or None
        The informed trial's result.
    converged : tuple or None
        The first plain trial to converge.
    trials : list of tuple
        Every trial run (informed first), including cancelled ones.
    plain_trials : list of tuple
        The plain trials that ran to their end (all of them when none converged).
    """
    P = points.shape[1]
    width = params.rv_batch
    n_plain = params.rv_trials if n_plain is None else n_plain
    if extra is not None and (masks is not None or informed is None or n_plain != 0):
        raise ValueError("extra votes are for an informed trial alone on complete data")
    if streams is None:
        streams = rng.spawn(1 + n_plain)  # [informed, plain 0, plain 1, ...]
    active: list = []
    if informed is not None:
        labels0, votes0 = informed
        active.append(_Trial(labels0.copy(), votes0.copy(), False, "informed", streams[0]))
    started = list(active)
    plain: list = []  # in start order
    winner = None

    def may_start_plain():
        # a later trial could no longer be the one kept once an earlier one converged
        return len(plain) < n_plain and not any(t.converged for t in plain)

    while True:
        check_interrupt()  # a caller's stop request (laav._interrupt), once per iteration
        while len(active) < width and may_start_plain():
            trial_rng = streams[1 + len(plain)]
            t = _Trial(trial_rng.integers(0, C, P), np.zeros((P, C)), True, "plain", trial_rng)
            active.append(t)
            started.append(t)
            plain.append(t)
        if not active:
            break
        _step(points, active, params, masks, extra)
        active = [t for t in active if not t.done]
        # the kept plain trial is the first *in start order* to converge, as if the trials
        # ran one after another: a trial that converges sooner than an earlier one is not
        # preferred (fast convergence is no sign of a right partition)
        for t in plain:
            if not t.done:
                break
            if t.converged:
                winner = t
                break
        if winner is not None:  # later plain trials cannot be kept: cancel them
            active = [t for t in active if t.kind != "plain"]
            if not any(t.kind == "informed" for t in active):
                break
    first = started[0].result() if informed is not None else None
    plain_ended = [t.result() for t in plain if t.done]
    return (first, None if winner is None else winner.result(),
            [t.result() for t in started], plain_ended)


def consensus_seed(rng: np.random.Generator) -> int:
    """The one draw :func:`consensus` makes from ``rng``."""
    return int(rng.integers(2**31 - 1))


def consensus(trials, C, rng):
    """Combine the labellings of unconverged trials by spectral clustering of their
    co-association (+ 1e-6), without the P x P matrix (:mod:`laav._spectral`)."""
    from ._spectral import coassociation_clustering

    labs = np.stack([t[0] for t in trials])  # (T, P)
    labels = coassociation_clustering(labs, C, consensus_seed(rng))
    last = trials[-1]  # its traces stand for the consensus's, as its votes do
    return (labels, last[1], last[2], last[3], last[4], False) + tuple(last[6:7])
