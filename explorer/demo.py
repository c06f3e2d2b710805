"""The bundled demo sequence."""

from __future__ import annotations

from pathlib import Path

import laav

__all__ = ["assets_dir", "demo_path", "demo_sequence"]


def assets_dir() -> Path:
    """``assets/`` at the top of the repository."""
    return Path(__file__).resolve().parents[1] / "assets"


def demo_path() -> Path | None:
    """``assets/demo_three_motions.mat`` if present, else the first ``assets/demo_*.mat``."""
    d = assets_dir()
    best = d / "demo_three_motions.mat"
    if best.is_file():
        return best
    found = sorted(d.glob("demo_*.mat")) + sorted(d.glob("demo_*.npz"))
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
        return laav.load_sequence(p)
    try:
        from laav.synthetic import make_sequence
    except ImportError:
        raise FileNotFoundError(
            f"no demo sequence: {assets_dir()} holds no demo_*.mat and laav.synthetic is missing; "
            "pass a sequence FILE") from None
    return make_sequence(n_objects=2, n_frames=30, n_points=300, noise=0.5, rng=0,
                         name="synthetic demo (3 motions)")
