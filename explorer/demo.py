"""The bundled demo sequence (package data in ``explorer/assets/``, shipped in the wheel)."""

from __future__ import annotations

from importlib import resources
from typing import TYPE_CHECKING

import laav

if TYPE_CHECKING:
    from importlib.resources.abc import Traversable

__all__ = ["assets_dir", "demo_path", "demo_sequence"]


def assets_dir() -> Traversable:
    """The ``assets`` folder of the installed ``explorer`` package (via :mod:`importlib.resources`)."""
    return resources.files(__package__) / "assets"


def demo_path() -> Traversable | None:
    """``demo_three_motions.mat`` if present, else the first ``demo_*.mat`` / ``.npz`` of the assets."""
    d = assets_dir()
    best = d / "demo_three_motions.mat"
    if best.is_file():
        return best
    if not d.is_dir():
        return None
    found = [p for p in d.iterdir() if p.name.startswith("demo_") and p.name.endswith((".mat", ".npz"))]
    found.sort(key=lambda p: (p.name.endswith(".npz"), p.name))  # .mat first, as before
    return found[0] if found else None


def demo_sequence() -> laav.Sequence:
    """The demo sequence: a bundled file, else a synthetic one made in memory.

    Raises
    ------
    FileNotFoundError
        When there is no demo file and ``laav.synthetic`` is unavailable.
    """
    p = demo_path()
    if p is not None:
        with resources.as_file(p) as path:  # a real file even if the package is zipped
            return laav.load_sequence(path)
    try:
        from laav.synthetic import make_sequence
    except ImportError:
        raise FileNotFoundError(
            f"no demo sequence: {assets_dir()} holds no demo_*.mat and laav.synthetic is missing; "
            "pass a sequence FILE") from None
    return make_sequence(n_objects=2, n_frames=30, n_points=300, noise=0.5, rng=0,
                         name="synthetic demo (3 motions)")
