"""Tests of laav.synthetic: determinism, ground truth, noise, geometry, the demo assets."""

from __future__ import annotations

import importlib.util
import itertools
from pathlib import Path

import cv2
import numpy as np
import pytest

from laav import Sequence, load_sequence
from laav.synthetic import MIN_POINTS_PER_MOTION, add_noise, make_sequence

REPO = Path(__file__).resolve().parent.parent
ASSETS = REPO / "explorer" / "assets"
SCRIPT = REPO / "examples" / "make_demo_assets.py"


def _sampson(F: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Sampson distances (px^2) of correspondences a -> b (n, 2) under b^T F a = 0."""
    x1 = np.column_stack([a, np.ones(len(a))])
    x2 = np.column_stack([b, np.ones(len(b))])
    fx1 = x1 @ F.T
    ftx2 = x2 @ F
    num = (x2 * fx1).sum(axis=1) ** 2
    return num / (fx1[:, 0] ** 2 + fx1[:, 1] ** 2 + ftx2[:, 0] ** 2 + ftx2[:, 1] ** 2)


def _median_epipolar(a: np.ndarray, b: np.ndarray) -> float:
    """Median Sampson distance of an 8-point fundamental matrix fitted to a -> b."""
    F, _ = cv2.findFundamentalMat(a, b, cv2.FM_8POINT)
    assert F is not None and F.shape == (3, 3)
    return float(np.median(_sampson(F, a, b)))


# ----------------------------------------------------------------------------- determinism


def test_same_seed_gives_identical_bytes():
    a = make_sequence(rng=7)
    b = make_sequence(rng=7)
    assert a.points.tobytes() == b.points.tobytes()
    assert a.labels.tobytes() == b.labels.tobytes()


def test_generator_and_int_seed_agree():
    a = make_sequence(rng=11, noise=0.3, outlier_fraction=0.05)
    b = make_sequence(rng=np.random.default_rng(11), noise=0.3, outlier_fraction=0.05)
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.labels, b.labels)


def test_different_seeds_differ():
    a = make_sequence(rng=1)
    b = make_sequence(rng=2)
    assert a.points.shape == b.points.shape
    assert not np.allclose(a.points, b.points)


def test_generator_is_advanced():
    gen = np.random.default_rng(5)
    a = make_sequence(rng=gen)
    b = make_sequence(rng=gen)
    assert not np.allclose(a.points, b.points)


# ----------------------------------------------------------------------------- ground truth


@pytest.mark.parametrize("n_objects", [1, 2, 3, 4, 5])
def test_labels_one_per_motion(n_objects):
    n_points = 300
    seq = make_sequence(n_objects=n_objects, n_points=n_points, rng=100 + n_objects)
    assert isinstance(seq, Sequence)
    assert seq.points.shape == (30, n_points, 2)
    assert seq.points.dtype == np.float64
    assert seq.labels.shape == (n_points,)
    assert seq.n_motions == n_objects + 1
    counts = np.bincount(seq.labels)
    assert counts.size == n_objects + 1
    assert counts.min() >= MIN_POINTS_PER_MOTION
    assert counts.sum() == n_points


@pytest.mark.parametrize("seed", range(4))
def test_objects_are_compact_and_background_is_spread(seed):
    """An object's points form one compact blob; the background covers the image."""
    seq = make_sequence(n_objects=2, rng=seed)
    w, h = seq.image_size
    first = seq.points[0]
    for k in range(1, seq.n_motions):
        pts = first[seq.labels == k]
        extent = pts.max(axis=0) - pts.min(axis=0)
        assert extent[0] < 0.6 * w and extent[1] < 0.6 * h, (k, extent)
    bg = first[seq.labels == 0]
    extent = bg.max(axis=0) - bg.min(axis=0)
    assert extent[0] > 0.6 * w and extent[1] > 0.6 * h


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(),
        dict(n_objects=5, n_points=200),
        dict(articulated=True),
        dict(nonrigid=True, n_objects=3),
        dict(noise=2.0),
        dict(outlier_fraction=0.2),
        dict(image_size=(320, 240), n_frames=12),
        dict(image_size=(1280, 720), n_frames=2),
    ],
)
def test_points_inside_image(kwargs):
    seq = make_sequence(rng=3, **kwargs)
    w, h = seq.image_size
    assert (w, h) == kwargs.get("image_size", (640, 480))
    x, y = seq.points[..., 0], seq.points[..., 1]
    assert x.min() >= 0 and x.max() <= w
    assert y.min() >= 0 and y.max() <= h
    if not kwargs.get("noise") and not kwargs.get("outlier_fraction"):
        assert x.min() >= 10 and x.max() <= w - 10  # the documented margin
        assert y.min() >= 10 and y.max() <= h - 10


def test_name_and_frames():
    seq = make_sequence(n_frames=17, name="my_scene", rng=0)
    assert seq.name == "my_scene"
    assert seq.n_frames == 17


# ----------------------------------------------------------------------------- noise, outliers


def test_noise_has_requested_std():
    sigma = 1.5
    clean = make_sequence(rng=21)
    noisy = make_sequence(rng=21, noise=sigma)
    np.testing.assert_array_equal(clean.labels, noisy.labels)
    diff = (noisy.points - clean.points).ravel()  # 18000 independent draws
    assert abs(diff.mean()) < 0.05
    assert abs(diff.std() / sigma - 1.0) < 0.03
    # Both coordinates get noise, and independently of each other.
    d = (noisy.points - clean.points).reshape(-1, 2)
    assert abs(d[:, 0].std() / sigma - 1.0) < 0.04
    assert abs(d[:, 1].std() / sigma - 1.0) < 0.04
    assert abs(np.corrcoef(d.T)[0, 1]) < 0.05


def test_add_noise():
    seq = make_sequence(rng=4)
    noisy = add_noise(seq, 0.8, rng=9)
    assert noisy is not seq
    np.testing.assert_array_equal(noisy.labels, seq.labels)
    assert noisy.image_size == seq.image_size and noisy.name == seq.name
    diff = (noisy.points - seq.points).ravel()
    assert abs(diff.mean()) < 0.03
    assert abs(diff.std() / 0.8 - 1.0) < 0.03
    again = add_noise(seq, 0.8, rng=9)
    np.testing.assert_array_equal(again.points, noisy.points)
    np.testing.assert_array_equal(add_noise(seq, 0.0, rng=1).points, seq.points)


def test_outliers_keep_labels():
    clean = make_sequence(rng=8)
    dirty = make_sequence(rng=8, outlier_fraction=0.1)
    np.testing.assert_array_equal(clean.labels, dirty.labels)
    changed = np.any(dirty.points != clean.points, axis=(0, 2))
    assert changed.sum() == 30  # 10 % of 300, rounded
    # Outliers start where the point was, then wander off.
    np.testing.assert_array_equal(dirty.points[0], clean.points[0])
    moved = np.linalg.norm(dirty.points[-1, changed] - clean.points[-1, changed], axis=1)
    assert np.median(moved) > 5.0


# ----------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("seed", range(5))
def test_each_rigid_motion_fits_one_fundamental_matrix(seed):
    seq = make_sequence(n_objects=2, rng=seed)
    first, last = seq.points[0], seq.points[-1]
    single = []
    for k in range(seq.n_motions):
        m = seq.labels == k
        single.append(_median_epipolar(first[m], last[m]))
    assert max(single) < 1e-3, single
    # Two motions together do not fit one F. Equal numbers of each, so that the larger
    # group cannot dominate the fit.
    for i, j in itertools.combinations(range(seq.n_motions), 2):
        mi = np.flatnonzero(seq.labels == i)
        mj = np.flatnonzero(seq.labels == j)
        n = min(mi.size, mj.size)
        idx = np.concatenate([mi[:n], mj[:n]])
        union = _median_epipolar(first[idx], last[idx])
        assert union > 0.05, (i, j, union)
        assert union > 1e4 * max(single[i], single[j], 1e-12), (i, j, union, single)


@pytest.mark.parametrize("seed", range(3))
def test_objects_move_against_the_background(seed):
    """The objects' image motion is not the background's: tens of pixels apart."""
    seq = make_sequence(n_objects=2, rng=seed)
    flow = seq.points[-1] - seq.points[0]
    bg = np.median(flow[seq.labels == 0], axis=0)
    for k in range(1, seq.n_motions):
        obj = np.median(flow[seq.labels == k], axis=0)
        assert np.linalg.norm(obj - bg) > 5.0


@pytest.mark.parametrize("seed", range(3))
def test_articulated_arm_is_one_label_but_not_rigid(seed):
    seq = make_sequence(n_objects=1, articulated=True, rng=seed)
    assert seq.n_motions == 2
    m = seq.labels == 1
    assert m.sum() >= MIN_POINTS_PER_MOTION
    assert _median_epipolar(seq.points[0, m], seq.points[-1, m]) > 1e-2
    bg = seq.labels == 0
    assert _median_epipolar(seq.points[0, bg], seq.points[-1, bg]) < 1e-3


@pytest.mark.parametrize("seed", range(3))
def test_nonrigid_object_builds(seed):
    seq = make_sequence(n_objects=2, nonrigid=True, rng=seed)
    assert seq.n_motions == 3
    assert np.bincount(seq.labels).min() >= MIN_POINTS_PER_MOTION
    rigid = seq.labels == 2  # the bending object is label 1, the other stays rigid
    assert _median_epipolar(seq.points[0, rigid], seq.points[-1, rigid]) < 1e-3


def test_articulated_and_nonrigid_together():
    seq = make_sequence(n_objects=3, articulated=True, nonrigid=True, rng=0)
    assert seq.n_motions == 4


# ----------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    "kwargs",
    [
        dict(n_objects=0),
        dict(n_objects=6),
        dict(n_objects=2.0),
        dict(n_objects=True),
        dict(n_frames=1),
        dict(n_frames="30"),
        dict(n_points=59),  # 3 motions need 60
        dict(n_points=300.5),
        dict(noise=-0.1),
        dict(noise=float("nan")),
        dict(noise=float("inf")),
        dict(noise="1"),
        dict(outlier_fraction=-0.01),
        dict(outlier_fraction=1.0),
        dict(outlier_fraction=None),
        dict(articulated=1),
        dict(nonrigid="yes"),
        dict(articulated=True, nonrigid=True, n_objects=1),
        dict(image_size=(640,)),
        dict(image_size=(640, 480, 3)),
        dict(image_size=(0, 480)),
        dict(image_size=(32, 480)),
        dict(image_size=(640.0, 480)),
        dict(image_size=640),
        dict(rng=-1),
        dict(rng=1.5),
        dict(rng="seed"),
        dict(rng=np.random.RandomState(0)),
        dict(name=""),
        dict(name=3),
    ],
)
def test_invalid_arguments_raise_value_error(kwargs):
    with pytest.raises(ValueError):
        make_sequence(**kwargs)


def test_error_message_names_the_parameter():
    with pytest.raises(ValueError, match="n_points"):
        make_sequence(n_objects=4, n_points=80)
    with pytest.raises(ValueError, match="outlier_fraction"):
        make_sequence(outlier_fraction=2)


@pytest.mark.parametrize(
    "args", [("not a sequence", 1.0), (None, 1.0), ("seq", -1.0), ("seq", float("nan"))]
)
def test_add_noise_invalid(args):
    seq = make_sequence(rng=0)
    target, sigma = args
    with pytest.raises(ValueError):
        add_noise(seq if target == "seq" else target, sigma, rng=0)


# ----------------------------------------------------------------------------- demo assets


def _load_script():
    spec = importlib.util.spec_from_file_location("make_demo_assets", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


ASSET_NAMES = ["demo_two_objects.mat", "demo_articulated.mat", "demo_three_motions.mat"]


@pytest.mark.parametrize(
    "filename, motions, points",
    [
        ("demo_two_objects.mat", 2, 250),
        ("demo_articulated.mat", 2, 250),
        ("demo_three_motions.mat", 3, 350),
    ],
)
def test_assets_load(filename, motions, points):
    seq = load_sequence(ASSETS / filename)
    assert seq.n_motions == motions
    assert seq.n_points == points
    assert seq.n_frames == 30
    assert seq.image_size == (640, 480)


def test_assets_match_a_fresh_regeneration(tmp_path):
    module = _load_script()
    assert sorted(module.DEMOS) == sorted(ASSET_NAMES)
    written = module.write_assets(tmp_path)
    assert sorted(p.name for p in written) == sorted(ASSET_NAMES)
    for name in ASSET_NAMES:
        fresh = (tmp_path / name).read_bytes()
        stored = (ASSETS / name).read_bytes()
        if fresh != stored:  # say how far apart they are before failing
            a, b = load_sequence(tmp_path / name), load_sequence(ASSETS / name)
            same_shape = a.points.shape == b.points.shape
            gap = np.abs(a.points - b.points).max() if same_shape else "shape differs"
            pytest.fail(f"{name}: regenerated bytes differ (max coordinate gap {gap})")
        # The stored file is exactly what make_sequence gives for the recorded arguments.
        seq = make_sequence(**module.DEMOS[name])
        np.testing.assert_array_equal(load_sequence(ASSETS / name).points, seq.points)
        np.testing.assert_array_equal(load_sequence(ASSETS / name).labels, seq.labels)


def test_assets_readme_mentions_every_file():
    text = (ASSETS / "README.md").read_text()
    for name in ASSET_NAMES:
        assert name in text
    assert "Hopkins155" in text and "make_demo_assets.py" in text


def test_assets_live_in_the_explorer_package():
    # the script writes the package data by default; the top-level assets/ points there
    assert _load_script().OUT == ASSETS
    pointer = (REPO / "assets" / "README.md").read_text()
    assert "explorer/assets/" in pointer and not list((REPO / "assets").glob("*.mat"))
