"""The :class:`Sequence` container: tracked trajectories plus optional ground truth."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["Sequence", "SequenceError", "LaavWarning", "MIN_POINTS", "MIN_FRAMES",
           "check_degenerate"]

#: Fewest trajectories a sequence may hold (the 8-point algorithm needs eight).
MIN_POINTS = 8
#: Fewest frames a sequence may hold (epipolar geometry needs two views).
MIN_FRAMES = 2


class SequenceError(ValueError):
    """A sequence file or array is malformed.

    The message always names the source (file path or ``"<array>"``) and the problem
    in plain words.
    """


class LaavWarning(UserWarning):
    """A result that is probably meaningless: degenerate input, or a single label for C > 1."""


#: Spread (px) of the coordinates outside which a warning says the scale is unusual: the
#: distances of :class:`laav.LaavParams` (``r1``, ``r2``, thresholds, lambda) are in pixels.
PIXEL_SPREAD = (1.0, 1e6)
#: Relative tolerance under which trajectories count as identical, static or collinear.
TOLERANCE = 1e-9


def check_degenerate(seq: Sequence, n_motions: int) -> None:
    """Refuse inputs that cannot hold ``n_motions`` motions; warn about degenerate ones.

    Raises :class:`ValueError` when there are fewer distinct trajectories than motions;
    warns (:class:`LaavWarning`) when there are fewer than :data:`MIN_POINTS` points per
    motion (the 8-point algorithm fits each motion's fundamental matrices), when no point
    moves, when the points are collinear in every frame, or when the coordinates span
    less than 1 or more than 1e6 pixels. Reads the coordinates only: results never change.
    """
    src, pts = seq.source, seq.points
    P = seq.n_points
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
    if np.all(sv[:, 1] <= TOLERANCE * sv[:, 0] + tol):
        warn.append("the points are collinear in every frame (epipolar geometry is degenerate)")
    if not PIXEL_SPREAD[0] <= spread <= PIXEL_SPREAD[1]:
        warn.append(f"the coordinates span {spread:.3g} px, outside {PIXEL_SPREAD[0]:g}-"
                    f"{PIXEL_SPREAD[1]:g}: LaavParams distances are in pixels, rescale the input")
    if warn:
        import warnings

        warnings.warn(f"{src}: " + "; ".join(warn) + " - the labels are probably meaningless",
                      LaavWarning, stacklevel=3)


@dataclass(frozen=True, eq=False)
class Sequence:
    """P feature points tracked over F frames, with optional ground-truth labels.

    Parameters
    ----------
    points : ndarray of shape (F, P, 2), float64
        Pixel coordinates ``(x, y)`` of every point in every frame.
    labels : ndarray of shape (P,), int64, or None
        Ground-truth motion label of each point, 0-based and contiguous
        (``0 .. n_motions - 1``, every label used at least once).
    name : str
        Human readable name (a Hopkins155 sequence name, a file stem, ...).
    image_size : tuple (width, height) or None
        Frame size in pixels when known.
    source : str
        Where the sequence came from (a path or ``"<array>"``); used in error messages.

    Attributes
    ----------
    n_frames, n_points : int
        F and P.
    n_motions : int or None
        Number of distinct ground-truth labels, or None without labels.

    Raises
    ------
    SequenceError
        On construction, when an array has the wrong shape or values.
    """

    points: np.ndarray
    labels: np.ndarray | None = None
    name: str = "sequence"
    image_size: tuple[int, int] | None = None
    source: str = field(default="<array>", repr=False)

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
        if not np.isfinite(pts).all():
            bad = int((~np.isfinite(pts)).any(axis=(0, 2)).sum())
            raise SequenceError(f"{src}: {bad} point(s) have NaN or infinite coordinates")
        pts.setflags(write=False)
        object.__setattr__(self, "points", pts)

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
                raise SequenceError(
                    f"{src}: motion label(s) {missing} have no points (labels must be "
                    f"0..{n_mot - 1} with every label used)"
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

    def with_points(self, points: np.ndarray, name: str | None = None) -> Sequence:
        """Copy with other coordinates (same labels), e.g. after adding noise."""
        return Sequence(
            points=points,
            labels=self.labels,
            name=self.name if name is None else name,
            image_size=self.image_size,
            source=self.source,
        )

    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, xmax, ymin, ymax)`` of all points, or the image frame when known."""
        if self.image_size is not None:
            return 0.0, float(self.image_size[0]), 0.0, float(self.image_size[1])
        x = self.points[..., 0]
        y = self.points[..., 1]
        return float(x.min()), float(x.max()), float(y.min()), float(y.max())

    def __repr__(self) -> str:
        mot = "unlabelled" if self.labels is None else f"{self.n_motions} motions"
        return (
            f"Sequence(name={self.name!r}, frames={self.n_frames}, points={self.n_points}, {mot})"
        )


def as_points(seq: Sequence | np.ndarray) -> np.ndarray:
    """The (F, P, 2) float64 coordinates of a :class:`Sequence` or of an array."""
    return seq.points if isinstance(seq, Sequence) else np.asarray(seq, dtype=np.float64)
