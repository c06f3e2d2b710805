"""Write the synthetic demo sequences in ``explorer/assets/``, byte for byte reproducibly.

Run from anywhere::

    python examples/make_demo_assets.py            # writes <repo>/explorer/assets/demo_*.mat
    python examples/make_demo_assets.py --out DIR  # writes DIR/demo_*.mat

Every file comes from :func:`laav.synthetic.make_sequence` with a fixed seed, so rerunning
the script rewrites identical bytes. ``scipy.io.savemat`` stamps the MAT header with the
platform and the current time; the script replaces that text with a fixed one (the header
stays a valid MATLAB 5.0 header), which is what makes the files reproducible.

The files are package data of ``explorer`` (they ship inside the wheel, and
``laav-explore`` finds them with :mod:`importlib.resources`). None of these files contain
Hopkins155 data; they are synthetic scenes.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from laav import save_sequence
from laav.synthetic import make_sequence

#: File name -> keyword arguments of ``make_sequence``. The seeds were picked by eye so
#: that the demos look clear; change them only together with explorer/assets/README.md.
DEMOS: dict[str, dict] = {
    # Background + one car-like box (a long, low box sliding and turning on the ground).
    "demo_two_objects.mat": dict(n_objects=1, n_points=250, n_frames=30, rng=2030),
    # Background + an articulated two-link arm (one label for the whole arm).
    "demo_articulated.mat": dict(
        n_objects=1, n_points=250, n_frames=30, articulated=True, rng=2027
    ),
    # Background + two independently moving objects, 0.5 px Gaussian noise.
    "demo_three_motions.mat": dict(
        n_objects=2, n_points=350, n_frames=30, noise=0.5, rng=2026
    ),
}

_HEADER_LEN = 116  # the text part of a MATLAB 5.0 file header
_HEADER = b"MATLAB 5.0 MAT-file, synthetic demo written by laav examples/make_demo_assets.py"

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "explorer" / "assets"


def _fix_header(path: Path) -> None:
    """Replace the time-stamped header text of a MAT file by a fixed one."""
    data = bytearray(path.read_bytes())
    if not data.startswith(b"MATLAB 5.0 MAT-file"):
        raise RuntimeError(f"{path}: not a MATLAB 5.0 file")
    data[:_HEADER_LEN] = _HEADER.ljust(_HEADER_LEN, b" ")
    path.write_bytes(bytes(data))


def write_assets(out_dir: str | Path) -> list[Path]:
    """Write every demo into ``out_dir`` (created if missing); return the paths written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for filename, kwargs in DEMOS.items():
        seq = make_sequence(name=Path(filename).stem, **kwargs)
        path = save_sequence(seq, out / filename)
        _fix_header(path)
        written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", type=Path, default=OUT, help="folder to write (default: explorer/assets/)"
    )
    args = parser.parse_args(argv)
    for path in write_assets(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
