"""The synthetic test clip: ``assets/two_objects/`` is what ``render_clip(0)`` renders, and its truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from laav.synthetic_video import TRUTH_FILE, load_clip, render_clip

CLIP = Path(__file__).resolve().parent.parent / "assets" / "two_objects"


@pytest.fixture(scope="module")
def clip():
    return load_clip(CLIP)


def test_shipped_clip_is_what_the_generator_renders(clip):
    cv2 = pytest.importorskip("cv2")
    files = sorted(CLIP.glob("frame_*.png"))
    size = sum(f.stat().st_size for f in CLIP.iterdir())
    assert size <= 2_000_000
    fresh = render_clip(0, name="two_objects")
    assert len(files) == fresh.n_frames == clip.n_frames == 24
    for f, frame in zip(files, fresh.frames):
        np.testing.assert_array_equal(cv2.imread(str(f), cv2.IMREAD_UNCHANGED), frame)
    np.testing.assert_array_equal(clip.masks, fresh.masks)
    np.testing.assert_array_equal(clip.motions, fresh.motions)
    # every layer is seen in every frame, and the disc hides part of the rectangle
    assert all(set(np.unique(m)) == {0, 1, 2} for m in clip.masks)
    rect_area = [(m == 1).sum() for m in clip.masks]
    assert min(rect_area) < 0.9 * max(rect_area)


def test_true_positions_follow_the_layers(clip):
    # a point maps to itself in its own frame, and elsewhere by its layer's motions
    xy = np.array([[100.0, 50.0], [160.0, 120.0]])
    layers = clip.layer_at(5, xy)
    pos = clip.true_positions(5, xy, layers)
    assert pos.shape == (clip.n_frames, 2, 2)
    np.testing.assert_allclose(pos[5], xy, atol=1e-9)
    for i, k in enumerate(layers):
        M5, M9 = (np.vstack([clip.motions[k, t], [0, 0, 1]]) for t in (5, 9))
        want = (M9 @ np.linalg.solve(M5, [*xy[i], 1.0]))[:2]
        np.testing.assert_allclose(pos[9, i], want, atol=1e-9)


def test_truth_file_name():
    assert (CLIP / TRUTH_FILE).is_file()


def test_render_is_reproducible_and_checks_its_arguments():
    a, b = render_clip(3, n_frames=4, size=(160, 120)), render_clip(3, n_frames=4, size=(160, 120))
    np.testing.assert_array_equal(a.frames, b.frames)
    assert a.frames.shape == (4, 120, 160)
    with pytest.raises(ValueError, match="size"):
        render_clip(0, size=(100, 100))
    with pytest.raises(ValueError, match="n_frames"):
        render_clip(0, n_frames=1)
