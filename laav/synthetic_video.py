"""A synthetic video clip whose every pixel's motion is known: test footage for ``laav track``.

:func:`render_clip` draws a short grey-level clip of planar textured *layers*, back to
front:

* layer 0, the background: a large texture seen by a camera that pans, turns and zooms
  slightly (a similarity transform per frame);
* layers 1..K, the objects: textured rectangles and discs, each with its own smooth
  translation and rotation; the last object passes in front of the one before it (it
  occludes it for part of the clip).

Every layer k has, per frame t, an affine map ``motions[k, t]`` (2 x 3) from its texture
coordinates to image coordinates ``(x, y)`` (x = column, y = row, pixel centres at
integers). The colour of a pixel is the bilinear interpolation of the texture of the
front-most layer covering it (objects have a one-pixel soft edge), so a tracked point's
true position in every frame is known exactly: take the layer under its first
observation (``masks``), map the observation back to texture coordinates, and forward
to the other frames (:meth:`Clip.true_positions`). ``masks[t]`` holds the front-most
layer of every pixel (coverage >= 0.5).

Only numpy and scipy are used; the same seed gives identical arrays.
``examples/make_footage.py`` writes the clip shipped in ``assets/``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Clip", "render_clip", "load_clip", "TRUTH_FILE"]

#: Name of the ground-truth file inside a clip's folder (beside the frame PNGs).
TRUTH_FILE = "truth.npz"


@dataclass(frozen=True, eq=False)
class Clip:
    """A rendered clip and its ground truth.

    Attributes
    ----------
    frames : ndarray (F, H, W) uint8
        The grey-level frames.
    masks : ndarray (F, H, W) uint8
        Front-most layer of every pixel: 0 background, k = 1..K object k.
    motions : ndarray (K + 1, F, 2, 3) float64
        ``motions[k, t]`` maps layer k's texture coordinates ``(u, v, 1)`` to image
        coordinates ``(x, y)`` in frame t.
    name : str
    """

    frames: np.ndarray | None
    masks: np.ndarray
    motions: np.ndarray
    name: str = "clip"

    @property
    def n_frames(self) -> int:
        return int(self.masks.shape[0])

    @property
    def n_layers(self) -> int:
        return int(self.motions.shape[0])

    def layer_at(self, frame: int, xy: np.ndarray) -> np.ndarray:
        """Front-most layer under the points ``xy`` (N, 2) of frame ``frame`` (nearest pixel)."""
        H, W = self.masks.shape[1:]
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        c = np.clip(np.rint(xy[:, 0]).astype(int), 0, W - 1)
        r = np.clip(np.rint(xy[:, 1]).astype(int), 0, H - 1)
        return self.masks[frame, r, c].astype(np.int64)

    def true_positions(self, frame: int, xy: np.ndarray, layers: np.ndarray) -> np.ndarray:
        """(F, N, 2): where points seen at ``xy`` in ``frame`` on ``layers`` are in every frame."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        layers = np.asarray(layers, dtype=np.int64).reshape(-1)
        M = self.motions[layers, frame]  # (N, 2, 3)
        A, b = M[:, :, :2], M[:, :, 2]
        uv = np.einsum("nij,nj->ni", np.linalg.inv(A), xy - b)
        Mt = self.motions[layers]  # (N, F, 2, 3)
        out = np.einsum("nfij,nj->nfi", Mt[..., :2], uv) + Mt[..., 2]
        return out.transpose(1, 0, 2)

    def track_truth(self, points: np.ndarray, visible: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Labels (P,) and true positions (F, P, 2) of tracks ``points`` (F, P, 2) / ``visible`` (F, P).

        A track's label is the layer under its first observation; its true positions
        follow that layer's motion from there.
        """
        points = np.asarray(points, dtype=np.float64)
        visible = np.asarray(visible, dtype=bool)
        if not visible.any(axis=0).all():
            raise ValueError("every track needs at least one visible frame")
        first = np.argmax(visible, axis=0)
        P = points.shape[1]
        xy0 = points[first, np.arange(P)]
        labels = np.empty(P, dtype=np.int64)
        true = np.empty((self.n_frames, P, 2))
        for f in np.unique(first):
            sel = np.flatnonzero(first == f)
            labels[sel] = self.layer_at(f, xy0[sel])
            true[:, sel] = self.true_positions(f, xy0[sel], labels[sel])
        return labels, true


def _similarity(scale: float, angle: float, tx: float, ty: float, centre=(0.0, 0.0)) -> np.ndarray:
    """2 x 3 map: rotate by ``angle`` and scale about ``centre`` (texture), then put it at (tx, ty)."""
    c, s = np.cos(angle) * scale, np.sin(angle) * scale
    A = np.array([[c, -s], [s, c]])
    b = np.array([tx, ty]) - A @ np.asarray(centre, dtype=np.float64)
    return np.hstack([A, b[:, None]])


def _texture(rng: np.random.Generator, shape, sigmas, weights, lo: float, hi: float) -> np.ndarray:
    """Smooth random texture (multi-scale blurred noise) stretched to [lo, hi] grey levels."""
    from scipy.ndimage import gaussian_filter

    tex = np.zeros(shape)
    for s, w in zip(sigmas, weights):
        n = gaussian_filter(rng.standard_normal(shape), s, mode="wrap")
        tex += w * n / n.std()
    q1, q99 = np.percentile(tex, [1, 99])
    return lo + (hi - lo) * np.clip((tex - q1) / (q99 - q1), 0.0, 1.0)


def _sample(tex: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    from scipy.ndimage import map_coordinates

    return map_coordinates(tex, [v, u], order=1, mode="mirror")


def render_clip(seed: int = 0, n_frames: int = 24, size: tuple[int, int] = (320, 240),
                name: str = "two_objects") -> Clip:
    """Render the clip: a panning background and two textured objects, the disc passing in front
    of the rectangle.

    Parameters
    ----------
    seed : int
        Seeds the textures and small variations of the motions.
    n_frames : int
        Number of frames (>= 2).
    size : (width, height)
        Frame size in pixels (>= 160 x 120; the scene is laid out relative to it).
    """
    W, H = (int(v) for v in size)
    if W < 160 or H < 120:
        raise ValueError(f"size must be at least (160, 120), got {size!r}")
    if n_frames < 2:
        raise ValueError(f"n_frames must be >= 2, got {n_frames}")
    rng = np.random.default_rng(seed)
    F = int(n_frames)
    s = np.linspace(0.0, 1.0, F)  # clip time in [0, 1]
    jit = rng.uniform(-1.0, 1.0, 8)  # small per-seed variations of the motions

    # layer 0: background texture larger than the frame, seen by a panning/zooming camera
    mw, mh = int(0.4 * W), int(0.4 * H)
    bg_tex = _texture(rng, (H + 2 * mh, W + 2 * mw), (1.2, 3.5), (0.6, 1.0), 25, 200)
    bg = np.stack([
        _similarity(1.0 + (0.06 + 0.01 * jit[0]) * t, (0.05 + 0.01 * jit[1]) * t,
                    W / 2 - (0.10 + 0.02 * jit[2]) * W * t, H / 2 + (0.06 + 0.02 * jit[3]) * H * t,
                    centre=(W / 2 + mw, H / 2 + mh))
        for t in s])

    # layer 1: a rectangle drifting left and down, turning slowly (behind)
    r = int(0.17 * min(W, H) + 0.5) * 2  # half-size of its texture
    rect_tex = _texture(rng, (2 * r + 8, 2 * r + 8), (1.0, 2.5), (0.8, 1.0), 60, 255)
    rect_half = (0.95 * r, 0.7 * r)
    rect = np.stack([
        _similarity(1.0, (-0.35 + 0.05 * jit[4]) * t,
                    W * (0.58 - 0.12 * t), H * (0.48 + 0.10 * t), centre=(r + 4, r + 4))
        for t in s])

    # layer 2: a disc crossing from left to right in front of the rectangle, turning the other way
    d = int(0.15 * min(W, H) + 0.5) * 2
    disc_tex = _texture(rng, (2 * d + 8, 2 * d + 8), (1.0, 2.0), (0.8, 1.0), 0, 170)
    disc_r = 0.5 * d
    disc = np.stack([
        _similarity(1.0, (0.5 + 0.05 * jit[5]) * t,
                    W * (0.2 + (0.52 + 0.02 * jit[6]) * t), H * (0.35 + 0.2 * t * t),
                    centre=(d + 4, d + 4))
        for t in s])

    motions = np.stack([bg, rect, disc])
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    frames = np.empty((F, H, W), dtype=np.uint8)
    masks = np.empty((F, H, W), dtype=np.uint8)
    for t in range(F):
        img = np.zeros((H, W))
        mask = np.zeros((H, W), dtype=np.uint8)
        for k, (tex, shape) in enumerate([(bg_tex, None), (rect_tex, "rect"), (disc_tex, "disc")]):
            M = motions[k, t]
            Ai = np.linalg.inv(M[:, :2])
            u = Ai[0, 0] * (xx - M[0, 2]) + Ai[0, 1] * (yy - M[1, 2])
            v = Ai[1, 0] * (xx - M[0, 2]) + Ai[1, 1] * (yy - M[1, 2])
            val = _sample(tex, u, v)
            if shape is None:
                alpha = np.ones((H, W))
            else:
                if shape == "rect":
                    c = (r + 4, r + 4)
                    sd = np.minimum(rect_half[0] - np.abs(u - c[0]), rect_half[1] - np.abs(v - c[1]))
                else:
                    c = (d + 4, d + 4)
                    sd = disc_r - np.hypot(u - c[0], v - c[1])
                alpha = np.clip(sd + 0.5, 0.0, 1.0)
            img = alpha * val + (1.0 - alpha) * img
            mask[alpha >= 0.5] = k
        frames[t] = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        masks[t] = mask
    for a in (frames, masks, motions):
        a.setflags(write=False)
    return Clip(frames=frames, masks=masks, motions=motions, name=name)


def load_clip(folder) -> Clip:
    """The ground truth written beside a clip's frames (``folder/truth.npz``); frames not loaded."""
    from pathlib import Path

    with np.load(Path(folder) / TRUTH_FILE, allow_pickle=False) as z:
        return Clip(frames=None, masks=z["masks"], motions=z["motions"], name=str(z["name"]))
