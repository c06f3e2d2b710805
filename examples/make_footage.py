"""Write the synthetic test clip ``assets/two_objects/``: frame PNGs plus ``truth.npz``.

Run from anywhere (needs OpenCV, the ``track`` extra, to write PNGs)::

    python examples/make_footage.py            # writes <repo>/assets/two_objects/
    python examples/make_footage.py --out DIR  # writes DIR/two_objects/

The clip comes from :func:`laav.synthetic_video.render_clip` with a fixed seed: 24 grey
frames of 320 x 240 px, a textured background under camera motion (pan, turn, zoom) and two
textured objects moving independently, the disc passing in front of the rectangle.
``truth.npz`` holds ``masks`` (F, H, W) uint8 (front-most layer of every pixel: 0 background,
1 rectangle, 2 disc), ``motions`` (3, F, 2, 3) (each layer's affine map from its texture to
the image, frame by frame; the true motion of every pixel) and ``name``. The pixels are the
same on every run (the PNG bytes may differ with the zlib version).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from laav.synthetic_video import TRUTH_FILE, render_clip

SEED = 0
NAME = "two_objects"
REPO = Path(__file__).resolve().parent.parent


def write_clip(out_dir: str | Path, seed: int = SEED, name: str = NAME) -> Path:
    """Render the clip into ``out_dir/name/`` (replacing its frames); return that folder."""
    import cv2

    clip = render_clip(seed, name=name)
    folder = Path(out_dir) / name
    folder.mkdir(parents=True, exist_ok=True)
    for old in folder.glob("frame_*.png"):
        old.unlink()
    for t, frame in enumerate(clip.frames):
        if not cv2.imwrite(str(folder / f"frame_{t:03d}.png"), frame, [cv2.IMWRITE_PNG_COMPRESSION, 9]):
            raise OSError(f"cannot write {folder / f'frame_{t:03d}.png'}")
    with open(folder / TRUTH_FILE, "wb") as fh:
        np.savez_compressed(fh, masks=clip.masks, motions=clip.motions, name=np.asarray(name))
    return folder


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=REPO / "assets", type=Path, help="folder to write the clip in")
    folder = write_clip(ap.parse_args(argv).out)
    size = sum(f.stat().st_size for f in folder.iterdir())
    print(f"{folder}: {len(list(folder.glob('frame_*.png')))} frames, {size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
