"""Missing data: which (frame, point) entries every stage may read, and the shared rules.

Every stage takes a :class:`laav.Sequence` whose ``visible`` mask (F, P) says where each
point was seen. When every entry is visible the stages run their complete-data code,
unchanged; otherwise they run a masked variant that never reads a hidden entry (see
``docs/ALGORITHM.md``, "Missing data"). The rules the stages share live here:

* :func:`visibility` - the mask of a sequence (or an array and an explicit mask), or None
  when nothing is missing (the complete-data code path);
* :func:`filled` - the coordinates with every hidden entry set to 0, so arithmetic over
  masked arrays never meets NaN or junk and its result cannot depend on them;
* :func:`min_overlap` - the fewest frames two trajectories must share to be compared;
* :func:`pair_pool` - the frame pairs the epipolar stages (fine-to-coarse, Random Voting,
  refinement) draw from, and :func:`decidable`, the points those pairs can label.
"""

from __future__ import annotations

import math

import numpy as np

from ._sequence import Sequence

__all__ = ["visibility", "filled", "min_overlap", "pair_pool", "decidable", "cover_pairs",
           "MIN_OVERLAP_FRAMES", "MIN_OVERLAP_SHARE", "UNLABELLED_REASONS",
           "MIN_ASSIGN_FRAMES"]

#: Two trajectories are compared (neighbourhoods, atoms) only over at least this many
#: frames both are seen in, and at least :data:`MIN_OVERLAP_SHARE` of the sequence.
MIN_OVERLAP_FRAMES = 3
MIN_OVERLAP_SHARE = 0.2

#: Why a point got label -1 (``LaavResult.unlabelled_code`` / ``Voting.unlabelled_code``):
#: code -> sentence. 0 means labelled.
UNLABELLED_REASONS = {
    1: ("seen too briefly: it is visible in both frames of no frame pair the voting uses "
        "(frames at least max(1, F // 3) apart that enough points share), so no epipolar "
        "vote can reach it, and in fewer than 4 frames, too few to tell the motions' "
        "trajectory subspaces apart"),
}
#: The code of :data:`UNLABELLED_REASONS` for a point no voting frame pair sees and too
#: few frames (:data:`MIN_ASSIGN_FRAMES`) place in a motion's trajectory subspace.
NO_FRAME_PAIR = 1
#: Fewest frames a point no voting frame pair sees must be visible in to be assigned by
#: the motions' trajectory subspaces (:func:`laav.refine.assign_by_subspace`): its 2f
#: coordinates must outnumber the rank-4 subspace's 4 coefficients twice over.
MIN_ASSIGN_FRAMES = 4


def visibility(seq, visible=None) -> np.ndarray | None:
    """The (F, P) bool mask of ``seq``, or None when every entry is visible.

    Parameters
    ----------
    seq : Sequence or ndarray of shape (F, P, 2)
    visible : ndarray of shape (F, P), optional
        For an array ``seq`` (a :class:`Sequence` carries its own; giving both raises).

    Raises
    ------
    ValueError
        For a mask of the wrong shape, or a mask given with a :class:`Sequence`.
    """
    if isinstance(seq, Sequence):
        if visible is not None:
            raise ValueError("give the visibility with the Sequence (Sequence(..., visible=)), "
                             "not as a separate argument")
        return None if seq.is_complete else seq.visible
    if visible is None:
        return None
    vis = np.asarray(visible, dtype=bool)
    shape = np.shape(seq)[:2]
    if vis.shape != tuple(shape):
        raise ValueError(f"visible must have shape (frames, points) = {tuple(shape)}, got {vis.shape}")
    return None if vis.all() else vis


def filled(points: np.ndarray, vis: np.ndarray) -> np.ndarray:
    """``points`` (F, P, 2) as float64 with every entry hidden by ``vis`` (F, P) set to 0."""
    return np.where(vis[..., None], np.asarray(points, dtype=np.float64), 0.0)


def min_overlap(n_frames: int) -> int:
    """Fewest frames two trajectories must share to be compared:
    ``max(MIN_OVERLAP_FRAMES, ceil(MIN_OVERLAP_SHARE F))``, at most F."""
    return int(min(n_frames, max(MIN_OVERLAP_FRAMES, math.ceil(MIN_OVERLAP_SHARE * n_frames))))


def pair_pool(vis: np.ndarray, min_points: int) -> np.ndarray:
    """The frame pairs the epipolar stages use on incomplete data.

    Every pair ``(l, r)``, ``l < r``, at least ``gap`` frames apart that at least
    ``min_points`` points are visible in together; ``gap`` is ``max(1, F // 3)`` (as on
    complete data), lowered one frame at a time only when no pair qualifies.

    Parameters
    ----------
    vis : ndarray of shape (F, P), bool
    min_points : int

    Returns
    -------
    pairs : ndarray of shape (K, 2), int64, K >= 1, in increasing order of ``(l, r)``

    Raises
    ------
    ValueError
        When no two frames share ``min_points`` visible points.
    """
    F = vis.shape[0]
    v = vis.astype(np.float64)
    shared = v @ v.T  # (F, F): points visible in both frames (exact small integers)
    left, right = np.triu_indices(F, 1)
    enough = shared[left, right] >= min_points
    for gap in range(max(1, F // 3), 0, -1):
        ok = enough & (right - left >= gap)
        if ok.any():
            return np.stack([left[ok], right[ok]], axis=1).astype(np.int64)
    raise ValueError(f"no two frames share {min_points} visible points: too much is missing "
                     "to fit one fundamental matrix per motion")


def decidable(vis: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """(P,) bool: the points visible in both frames of at least one of ``pairs`` (K, 2)."""
    both = vis[pairs[:, 0]] & vis[pairs[:, 1]]  # (K, P)
    return both.any(axis=0)


def cover_pairs(vis: np.ndarray, pool: np.ndarray, n_pairs: int) -> np.ndarray:
    """Frame pairs of ``pool`` for the refinement on incomplete data, deterministic.

    ``n_pairs`` pairs evenly spread over the pool (the widest one first, as
    :func:`laav.refine.frame_pairs` does on complete data), then, greedily, the pool's
    pair that sees the most points no chosen pair sees yet, until every point some pool
    pair sees is seen by a chosen one.

    Returns
    -------
    pairs : ndarray of shape (K, 2), int64
    """
    K = pool.shape[0]
    both = vis[pool[:, 0]] & vis[pool[:, 1]]  # (K, P)
    widest = int(np.argmax(pool[:, 1] - pool[:, 0]))
    pick = [widest] + [int(k) for k in np.round(np.linspace(0, K - 1, max(n_pairs - 1, 0)))]
    pick = list(dict.fromkeys(pick))  # unique, in order
    need = both.any(axis=0) & ~both[pick].any(axis=0)
    while need.any():
        k = int(np.argmax(both[:, need].sum(axis=1)))
        pick.append(k)
        need &= ~both[k]
    return pool[pick]
