"""The :class:`Sequence` container: tracked trajectories plus optional ground truth."""

from __future__ import annotations

import os
import sys
from dataclasses import dataclass, field

import numpy as np

from .params import PIXEL_PARAMS, STRENGTH_PARAMS

__all__ = ["Sequence", "SequenceError", "IncompleteSequenceError", "LaavWarning", "MIN_POINTS",
           "MIN_FRAMES", "check_degenerate", "require_complete", "warn_missing_motions"]

#: Fewest trajectories a sequence may hold (the 8-point algorithm needs eight).
MIN_POINTS = 8
#: Fewest frames a sequence may hold (epipolar geometry needs two views).
MIN_FRAMES = 2


class SequenceError(ValueError):
    """A sequence file or array is malformed.

    The message always names the source (file path or ``"<array>"``) and the problem
    in plain words.
    """


class IncompleteSequenceError(SequenceError):
    """A sequence with missing entries was given to code that needs every point in every
    frame (:func:`require_complete`; every part of ``laav`` takes incomplete tracks).

    Attributes
    ----------
    missing_share : float
        Share of the (frame, point) entries that are not visible, 0-1.
    n_complete : int
        Number of points visible in every frame (what :meth:`Sequence.complete` keeps).
    """

    def __init__(self, message: str, missing_share: float = 0.0, n_complete: int = 0):
        super().__init__(message)
        self.missing_share = missing_share
        self.n_complete = n_complete


def require_complete(seq: Sequence, what: str = "this code") -> None:
    """Raise :class:`IncompleteSequenceError` unless every point of ``seq`` is visible in every frame.

    Every part of ``laav`` and the explorer takes incomplete tracks (``docs/ALGORITHM.md``,
    "Missing data"; :func:`laav.estimate_motions` counts on a stretch of frames and the
    tracks seen in all of them), so nothing here calls it any more: it is for a caller's own
    code that needs whole trajectories, named in ``what``.
    """
    if seq.is_complete:
        return
    missing = 1.0 - seq.visible_share
    n_full = int(np.count_nonzero(seq.visible.all(axis=0)))
    pct = 100.0 * missing
    pct_text = f"{pct:.1f}" if pct >= 0.1 else f"{pct:.2g}"
    keep = (f"keep the {n_full} of {seq.n_points} points visible in every frame with "
            "seq.complete() (command line: --complete-only)")
    if n_full < MIN_POINTS:
        keep += f", though {n_full} are fewer than the {MIN_POINTS} points LAAV needs"
    raise IncompleteSequenceError(
        f"{seq.source}: the sequence has {pct_text} % missing entries ({seq.n_points} points x "
        f"{seq.n_frames} frames); incomplete tracks are not supported yet by {what}: {keep}",
        missing_share=missing, n_complete=n_full)


class LaavWarning(UserWarning):
    """A result that is probably meaningless: degenerate input, or a single label for C > 1."""


#: Spread (px) of the coordinates outside which a warning says the scale is unusual: the
#: lengths of :class:`laav.LaavParams` are in pixels and its strengths in 1/px^2
#: (:data:`laav.params.PIXEL_PARAMS`, :data:`laav.params.STRENGTH_PARAMS`).
PIXEL_SPREAD = (1.0, 1e6)
#: Largest distance of the coordinates from their origin, in units of their spread, above
#: which a warning says rounding costs precision: the fundamental matrices and affine maps
#: are in the input's coordinates (the epipolar distances of the three-motion demo are
#: 0.6 % off at 1e9 px from the origin, 1.6e6 spreads, and meaningless at 1e10).
ORIGIN_RATIO = 1e6
#: Relative tolerance under which trajectories count as identical, static or collinear.
TOLERANCE = 1e-9


#: The package's folder: warnings point at the first frame outside it (:func:`user_stacklevel`).
_PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


def user_stacklevel() -> int:
    """``stacklevel`` for a :func:`warnings.warn` made by the caller of this function, such
    that the warning names the first frame outside the ``laav`` package: the user's line,
    however many of laav's functions (``segment``, ``Pipeline``, ``random_voting``, the
    single-thread wrapper) lie in between."""
    frame, level = sys._getframe(1), 1
    while frame is not None and os.path.dirname(os.path.abspath(frame.f_code.co_filename)) == _PACKAGE_DIR:
        frame, level = frame.f_back, level + 1
    return level


def check_degenerate(seq: Sequence | np.ndarray, n_motions: int, *,
                     visible: np.ndarray | None = None) -> None:
    """Refuse inputs that cannot hold ``n_motions`` motions; warn about degenerate ones.

    Raises :class:`ValueError` when there are fewer distinct trajectories than motions;
    warns (:class:`LaavWarning`) when there are fewer than :data:`MIN_POINTS` points per
    motion (the 8-point algorithm fits each motion's fundamental matrices), when no point
    moves, when the points are collinear in every frame (not tested when they span more
    than 1e6 pixels: the scale warning covers it), or when the coordinates span
    less than 1 or more than 1e6 pixels (the message names the parameters to scale), or
    lie farther from their origin than :data:`ORIGIN_RATIO` times their spread.
    Reads the coordinates only: results never change.
    ``seq`` is a :class:`Sequence` or an (F, P, 2) array of finite coordinates; LAAV
    (:class:`laav.Pipeline`, :func:`laav.segment`) and plain Random Voting
    (:func:`laav.random_voting`) both call it. On incomplete data (an incomplete
    :class:`Sequence`, or an array and its ``visible`` (F, P) mask) only the visible
    entries are read: two trajectories are distinct when they differ in a coordinate or
    in where they are visible; a point moves when it does over its visible frames; the
    collinearity test looks at the frames where 3 or more points are visible.
    """
    src, pts = getattr(seq, "source", "<array>"), as_points(seq)
    if isinstance(seq, Sequence) and not seq.is_complete:
        visible = seq.visible
    if visible is not None and not np.all(visible):
        _check_degenerate_masked(src, pts, np.asarray(visible, dtype=bool), n_motions)
        return
    P = pts.shape[1]
    warn = []
    if n_motions > 1 and P < MIN_POINTS * n_motions:
        warn.append(f"{P} points are too few for {n_motions} motions (the 8-point algorithm "
                    f"fits each motion with at least {MIN_POINTS})")
    spread = float(np.ptp(pts)) if pts.size else 0.0
    tol = TOLERANCE * max(spread, np.abs(pts).max())
    traj = pts.transpose(1, 0, 2).reshape(P, -1)
    distinct = np.unique(traj, axis=0).shape[0] if spread > tol else 1
    if distinct < n_motions:
        raise ValueError(f"{src}: only {distinct} distinct trajector{'y' if distinct == 1 else 'ies'}"
                         f" for {n_motions} motions")
    if np.ptp(pts, axis=0).max() <= tol:
        warn.append("no point moves (every trajectory is static)")
    centred = pts - pts.mean(axis=1, keepdims=True)
    sv = np.linalg.svd(centred, compute_uv=False)  # (F, 2) per frame
    # (above the pixel range the scale warning says it: a single track 1e13 px away made
    # every frame look collinear, the tolerance being relative to it)
    if spread <= PIXEL_SPREAD[1] and np.all(sv[:, 1] <= TOLERANCE * sv[:, 0] + tol):
        warn.append("the points are collinear in every frame (epipolar geometry is degenerate)")
    _warn(src, warn, spread, pts)


def _warn(src, warn: list, spread: float, seen: np.ndarray) -> None:
    """The pixel-scale and distant-origin warnings (from the visible coordinates ``seen``,
    any shape, and their ``spread``) added to ``warn``, then one :class:`LaavWarning` for
    all of them, if any."""
    if not PIXEL_SPREAD[0] <= spread <= PIXEL_SPREAD[1]:
        warn.append(f"the coordinates span {spread:.3g} px, outside {PIXEL_SPREAD[0]:g}-"
                    f"{PIXEL_SPREAD[1]:g}: LaavParams lengths are in pixels and strengths in "
                    f"1/px^2, so rescale the coordinates to pixels or, for coordinates s times "
                    f"pixels, multiply {', '.join(PIXEL_PARAMS)} by s and "
                    f"{', '.join(STRENGTH_PARAMS)} by 1/s^2 (LaavParams.scaled(s))")
    far = float(np.abs(seen).max()) if seen.size else 0.0
    if spread > 0 and far > ORIGIN_RATIO * spread:
        warn.append(f"the points lie up to {far:.3g} px from the coordinates' origin, "
                    f"{far / spread:.3g} times their spread, where rounding costs the "
                    f"epipolar fits their precision: subtract an offset (the image corner, say)")
    if warn:
        import warnings

        warnings.warn(f"{src}: " + "; ".join(warn) + " - the labels are probably meaningless",
                      LaavWarning, stacklevel=user_stacklevel())


def _check_degenerate_masked(src, pts, vis, n_motions) -> None:
    """:func:`check_degenerate` on incomplete data (see there)."""
    P = pts.shape[1]
    warn = []
    if n_motions > 1 and P < MIN_POINTS * n_motions:
        warn.append(f"{P} points are too few for {n_motions} motions (the 8-point algorithm "
                    f"fits each motion with at least {MIN_POINTS})")
    seen = pts[vis]  # (n, 2)
    spread = float(np.ptp(seen)) if seen.size else 0.0
    tol = TOLERANCE * max(spread, np.abs(seen).max() if seen.size else 0.0)
    hidden = np.where(vis[..., None], pts, np.inf)  # the same value wherever hidden
    traj = np.concatenate([hidden.transpose(1, 0, 2).reshape(P, -1), vis.T], axis=1)
    distinct = np.unique(traj, axis=0).shape[0] if spread > tol else 1
    if distinct < n_motions:
        raise ValueError(f"{src}: only {distinct} distinct trajector{'y' if distinct == 1 else 'ies'}"
                         f" for {n_motions} motions")
    hi = np.where(vis[..., None], pts, -np.inf).max(axis=0)  # (P, 2)
    lo = np.where(vis[..., None], pts, np.inf).min(axis=0)
    if (hi - lo).max() <= tol:
        warn.append("no point moves (every trajectory is static)")
    collinear = spread <= PIXEL_SPREAD[1]  # above it, the scale warning (see check_degenerate)
    for f in range(pts.shape[0] if collinear else 0):
        x = pts[f, vis[f]]
        if x.shape[0] < 3:
            continue
        sv = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
        if sv[1] > TOLERANCE * sv[0] + tol:
            collinear = False
            break
    if collinear:
        warn.append("the points are collinear in every frame (epipolar geometry is degenerate)")
    _warn(src, warn, spread, seen)


def warn_missing_motions(seq, labels: np.ndarray, n_motions: int) -> None:
    """Warn (:class:`LaavWarning`) when ``labels`` use fewer than the ``n_motions`` > 1
    motions asked for: every labelled point in one motion, or some motions left empty
    (after LAAV or plain Random Voting; points left unlabelled, -1, do not count)."""
    labels = np.asarray(labels)
    used = np.unique(labels[labels >= 0])
    if n_motions > 1 and used.size < n_motions:
        import warnings

        src = getattr(seq, 'source', '<array>')
        if used.size <= 1:
            msg = f"every point got the same label though {n_motions} motions were asked for"
        else:  # e.g. C larger than the scene supports: some motions end empty
            msg = (f"only {used.size} of the {n_motions} motions asked for got points (labels "
                   f"{', '.join(map(str, used.tolist()))}); fewer motions may fit the tracks")
        warnings.warn(f"{src}: {msg}", LaavWarning, stacklevel=user_stacklevel())


@dataclass(frozen=True, eq=False)
class Sequence:
    """P feature points tracked over F frames, with optional ground-truth labels and visibility.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2), float64
        Pixel coordinates ``(x, y)`` of every point in every frame. Where ``visible`` is
        False they are ignored (they may hold NaN or anything else) and stored as NaN.
    labels : ndarray of shape (P,), int64, or None
        Ground-truth motion label of each point, 0-based and contiguous
        (``0 .. n_motions - 1``, every label used at least once).
    name : str
        Human readable name (a Hopkins155 sequence name, a file stem, ...).
    image_size : tuple (width, height) or None
        Frame size in pixels when known.
    source : str
        Where the sequence came from (a path or ``"<array>"``); used in error messages.
    visible : ndarray of shape (F, P), bool, or None
        Whether each point is seen in each frame (real trackers lose points: tracks start
        late, end early, are occluded). None (default): every point in every frame. Every
        point must be visible in at least 2 frames. After construction the attribute is
        always a read-only (F, P) bool array.

    Attributes
    ----------
    n_frames, n_points : int
        F and P.
    n_motions : int or None
        Number of distinct ground-truth labels, or None without labels.
    is_complete : bool
        Every point visible in every frame.
    visible_share : float
        Share of the F x P entries that are visible (1.0 when complete).
    track_lengths : ndarray of shape (P,), int64
        Number of frames each point is visible in.

    Raises
    ------
    SequenceError
        On construction, when an array has the wrong shape or values: among others a
        ``visible`` mask of another shape than (F, P), a point visible in fewer than 2
        frames, or NaN / infinite coordinates where a point is visible.

    Examples
    --------
    >>> seq = Sequence(points, visible=mask)               # doctest: +SKIP
    >>> seq.is_complete, seq.visible_share                 # doctest: +SKIP
    (False, 0.62)
    >>> full, kept = seq.complete()  # the points seen in every frame, and their indices  # doctest: +SKIP
    """

    points: np.ndarray
    labels: np.ndarray | None = None
    name: str = "sequence"
    image_size: tuple[int, int] | None = None
    source: str = field(default="<array>", repr=False)
    visible: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        src = self.source
        try:
            pts = np.asarray(self.points)
        except Exception as exc:  # ragged nested lists and the like
            raise SequenceError(f"{src}: points cannot be read as an array ({exc})") from None
        if pts.dtype == object or not (
            np.issubdtype(pts.dtype, np.number) or pts.dtype == bool
        ):
            raise SequenceError(f"{src}: points must be numeric, got dtype {pts.dtype}")
        if np.iscomplexobj(pts):
            raise SequenceError(f"{src}: points must be real numbers, got complex values")
        if pts.ndim != 3 or pts.shape[2] != 2:
            raise SequenceError(
                f"{src}: points must have shape (frames, points, 2), got {pts.shape}"
            )
        n_frames, n_points = pts.shape[:2]
        if n_frames < MIN_FRAMES:
            raise SequenceError(
                f"{src}: needs at least {MIN_FRAMES} frames, got {n_frames}"
            )
        if n_points < MIN_POINTS:
            raise SequenceError(
                f"{src}: needs at least {MIN_POINTS} points, got {n_points}"
            )
        pts = np.ascontiguousarray(pts, dtype=np.float64)
        vis = None if self.visible is None else _check_visible(self.visible, n_frames, n_points, src)
        if vis is None or vis.all():
            if not np.isfinite(pts).all():
                bad = int((~np.isfinite(pts)).any(axis=(0, 2)).sum())
                f, q = np.argwhere(~np.isfinite(pts).all(axis=2))[0]
                hint = ""
                if self.visible is None and not np.isinf(pts).any():  # NaN only: not seen?
                    hint = ("; if NaN marks a frame where a point is not seen, give `visible` "
                            "(F x P, False there; in an .npz file an array 'visible')")
                raise SequenceError(f"{src}: {bad} point(s) have NaN or infinite coordinates "
                                    f"(first: point {q} in frame {f}){hint}")
            vis = np.ones((n_frames, n_points), dtype=bool)
            complete = True
        else:
            bad = vis & ~np.isfinite(pts).all(axis=2)  # (F, P)
            if bad.any():
                f, q = np.argwhere(bad)[0]
                n_bad = int(bad.any(axis=0).sum())
                raise SequenceError(
                    f"{src}: {n_bad} point(s) have NaN or infinite coordinates in frames where "
                    f"they are visible (first: point {q} in frame {f})")
            pts = np.where(vis[..., None], pts, np.nan)  # a new array: the caller's stays as it was
            complete = False
        pts.setflags(write=False)
        vis.setflags(write=False)
        object.__setattr__(self, "points", pts)
        object.__setattr__(self, "visible", vis)
        object.__setattr__(self, "_complete", complete)

        if self.labels is not None:
            lab = np.asarray(self.labels)
            if lab.ndim == 2 and 1 in lab.shape:
                lab = lab.ravel()
            if lab.ndim != 1:
                raise SequenceError(f"{src}: labels must be a vector, got shape {lab.shape}")
            if lab.shape[0] != n_points:
                raise SequenceError(
                    f"{src}: {lab.shape[0]} labels for {n_points} points (counts must match)"
                )
            if np.iscomplexobj(lab) or not (
                np.issubdtype(lab.dtype, np.number) or lab.dtype == bool
            ):
                raise SequenceError(f"{src}: labels must be integers, got dtype {lab.dtype}")
            labf = lab.astype(np.float64)
            if not np.isfinite(labf).all() or np.any(labf != np.round(labf)):
                raise SequenceError(f"{src}: labels must be whole numbers")
            if np.any(labf < 0):
                raise SequenceError(f"{src}: labels must be non-negative (0-based)")
            if labf.max() > n_points - 1:  # also keeps the int64 cast and the check below small
                raise SequenceError(
                    f"{src}: label {labf.max():g} is too large for {n_points} points (labels "
                    f"must be 0..n_motions-1 with every label used)"
                )
            lab = labf.astype(np.int64)
            present = np.unique(lab)
            n_mot = int(lab.max()) + 1
            if present.size != n_mot:
                missing = sorted(set(range(n_mot)) - set(present.tolist()))
                hint = ("; they look 1-based: subtract 1" if missing == [0]
                        and present.size == n_mot - 1 else "")
                raise SequenceError(
                    f"{src}: motion label(s) {missing} have no points (labels must be "
                    f"0..{n_mot - 1} with every label used){hint}"
                )
            lab.setflags(write=False)
            object.__setattr__(self, "labels", lab)

        if self.image_size is not None:
            try:
                w, h = (int(v) for v in self.image_size)
            except Exception:
                raise SequenceError(
                    f"{src}: image_size must be (width, height), got {self.image_size!r}"
                ) from None
            if w <= 0 or h <= 0:
                raise SequenceError(f"{src}: image_size must be positive, got {(w, h)}")
            object.__setattr__(self, "image_size", (w, h))

    @property
    def n_frames(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.points.shape[1])

    @property
    def n_motions(self) -> int | None:
        return None if self.labels is None else int(self.labels.max()) + 1

    @property
    def is_complete(self) -> bool:
        """Every point is visible in every frame."""
        return self._complete

    @property
    def visible_share(self) -> float:
        """Share of the F x P entries that are visible, 0-1 (1.0 when complete)."""
        return 1.0 if self._complete else float(np.count_nonzero(self.visible)) / self.visible.size

    @property
    def track_lengths(self) -> np.ndarray:
        """(P,) int64: the number of frames each point is visible in."""
        return np.count_nonzero(self.visible, axis=0).astype(np.int64)

    def with_points(self, points: np.ndarray, name: str | None = None) -> Sequence:
        """Copy with other coordinates (same labels and visibility), e.g. after adding noise."""
        return Sequence(
            points=points,
            labels=self.labels,
            name=self.name if name is None else name,
            image_size=self.image_size,
            source=self.source,
            visible=None if self._complete else self.visible,
        )

    def subset(self, indices) -> Sequence:
        """The points ``indices`` only (an int index array or a (P,) bool mask), in that order.

        Ground-truth labels follow their points; when a motion loses every point, the
        remaining labels are renumbered ``0 .. K-1`` in their order (so ``n_motions`` drops).

        Raises
        ------
        SequenceError
            For indices out of range, or when fewer than :data:`MIN_POINTS` points remain.
        """
        idx = np.asarray(indices)
        if idx.dtype == bool:
            if idx.shape != (self.n_points,):
                raise SequenceError(f"{self.source}: a point mask must have shape ({self.n_points},), "
                                    f"got {idx.shape}")
            idx = np.flatnonzero(idx)
        elif idx.size == 0:
            idx = idx.astype(np.int64)
        if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer):
            raise SequenceError(f"{self.source}: point indices must be a vector of integers, "
                                f"got dtype {idx.dtype} and shape {idx.shape}")
        if idx.size and (idx.min() < -self.n_points or idx.max() >= self.n_points):
            raise SequenceError(f"{self.source}: point index out of range for {self.n_points} points")
        labels = None
        if self.labels is not None:
            labels = np.unique(self.labels[idx], return_inverse=True)[1].reshape(-1)
        vis = None if self._complete else self.visible[:, idx]
        return Sequence(points=self.points[:, idx], labels=labels, name=self.name,
                        image_size=self.image_size, source=self.source, visible=vis)

    def complete(self) -> tuple[Sequence, np.ndarray]:
        """The points visible in every frame, and their indices in this sequence.

        Returns
        -------
        seq : Sequence
            Complete (``is_complete``); ``self`` when it already is. Labels as in :meth:`subset`.
        kept : ndarray of shape (K,), int64
            Indices of the kept points, increasing: ``result.labels`` of the returned
            sequence belong to ``self``'s points ``kept``.

        Raises
        ------
        SequenceError
            When fewer than :data:`MIN_POINTS` points are visible in every frame.
        """
        if self._complete:
            return self, np.arange(self.n_points, dtype=np.int64)
        kept = np.flatnonzero(self.visible.all(axis=0)).astype(np.int64)
        if kept.size < MIN_POINTS:
            raise SequenceError(
                f"{self.source}: only {kept.size} of {self.n_points} points are visible in every "
                f"frame; at least {MIN_POINTS} are needed")
        return self.subset(kept), kept

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of all visible points, or the image frame when known."""
        if self.image_size is not None:
            return 0.0, float(self.image_size[0]), 0.0, float(self.image_size[1])
        x = self.points[..., 0]
        y = self.points[..., 1]
        if self._complete:
            return float(x.min()), float(x.max()), float(y.min()), float(y.max())
        return float(np.nanmin(x)), float(np.nanmax(x)), float(np.nanmin(y)), float(np.nanmax(y))

    def __repr__(self) -> str:
        mot = "unlabelled" if self.labels is None else f"{self.n_motions} motions"
        vis = "" if self._complete else f", {100 * self.visible_share:.1f} % visible"
        return (
            f"Sequence(name={self.name!r}, frames={self.n_frames}, points={self.n_points}, "
            f"{mot}{vis})"
        )


def _check_visible(visible, n_frames: int, n_points: int, src: str) -> np.ndarray:
    """``visible`` as a (F, P) bool array; :class:`SequenceError` for anything else."""
    try:
        vis = np.asarray(visible)
    except Exception as exc:
        raise SequenceError(f"{src}: visible cannot be read as an array ({exc})") from None
    if vis.dtype != bool:
        if vis.dtype == object or np.iscomplexobj(vis) or not np.issubdtype(vis.dtype, np.number):
            raise SequenceError(f"{src}: visible must be a bool (or 0/1) array, got dtype {vis.dtype}")
        if not np.isin(vis, (0, 1)).all():
            raise SequenceError(f"{src}: visible must hold only 0/1 (or True/False)")
        vis = vis != 0
    if vis.shape != (n_frames, n_points):
        hint = " (points x frames: transpose it)" if vis.shape == (n_points, n_frames) else ""
        raise SequenceError(f"{src}: visible must have shape (frames, points) = "
                            f"({n_frames}, {n_points}) like the points, got {vis.shape}{hint}")
    counts = np.count_nonzero(vis, axis=0)
    short = np.flatnonzero(counts < MIN_FRAMES)
    if short.size:
        shown = ", ".join(str(q) for q in short[:5]) + (", ..." if short.size > 5 else "")
        raise SequenceError(f"{src}: {short.size} point(s) are visible in fewer than {MIN_FRAMES} "
                            f"frames (points {shown}); every point needs at least {MIN_FRAMES}")
    return np.array(vis, dtype=bool)  # a copy: read-only without touching the caller's


def as_points(seq: Sequence | np.ndarray) -> np.ndarray:
    """The (F, P, 2) float64 coordinates of a :class:`Sequence` or of an array."""
    return seq.points if isinstance(seq, Sequence) else np.asarray(seq, dtype=np.float64)
