"""The noise-adaptive thresholds (``LaavParams(noise_adaptive=True)``, laav/noise.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import laav
from laav.atoms import build_atoms
from laav.noise import estimate_noise, threshold_factor
from laav.synthetic import make_sequence


def _scene(noise: float, seed: int = 1):
    return make_sequence(n_objects=2, n_frames=20, n_points=300, noise=noise, rng=seed)


@pytest.mark.parametrize("sigma", [0.5, 1.0, 2.0])
def test_the_estimate_finds_the_pixel_noise_of_a_synthetic_scene(sigma):
    est = estimate_noise(_scene(sigma).points)
    assert abs(est - sigma) < 0.1 * sigma


def test_the_estimate_is_near_zero_on_clean_tracks_and_scales_with_the_coordinates():
    seq = _scene(0.0)
    assert estimate_noise(seq.points) < 0.05
    noisy = _scene(1.0).points
    assert estimate_noise(noisy * 8.0) == 8.0 * estimate_noise(noisy)  # exact: a power of two


def test_the_estimate_reads_only_visible_entries():
    pts = _scene(1.0).points.copy()
    vis = np.ones(pts.shape[:2], bool)
    vis[5:12, :100] = False
    pts[~vis] = 1e9  # junk where hidden
    assert abs(estimate_noise(pts, vis) - 1.0) < 0.1


def test_the_batched_pairs_give_the_numbers_of_one_pair_at_a_time():
    # complete tracks fit all frame pairs in one batch, missing data one pair at a time:
    # with every entry visible both read the same points, so the estimate is the same bits
    for sigma in (0.0, 1.0):
        pts = _scene(sigma).points
        assert estimate_noise(pts) == estimate_noise(pts, np.ones(pts.shape[:2], bool))


def test_the_batches_are_bounded_and_give_the_same_numbers(monkeypatch):
    # many tracks: the pairs go in several passes of bounded size, the same bits as one pass
    import laav.noise as N

    pts = _scene(1.0).points
    whole = estimate_noise(pts)
    monkeypatch.setattr(N, "_BATCH_ENTRIES", pts.shape[1] * N.NOISE_NEIGHBORS * 3)  # 3 pairs a pass
    assert estimate_noise(pts) == whole
    monkeypatch.setattr(N, "_BATCH_ENTRIES", 1)  # one pair a pass
    assert estimate_noise(pts) == whole


def test_threshold_factor_is_the_chi_square_quantile_of_the_noise_model():
    assert threshold_factor("all") == pytest.approx(math.sqrt(-2 * math.log(0.01) + 2))
    assert threshold_factor("pair") == pytest.approx(math.sqrt(-4 * math.log(0.01)))


def test_the_default_adapts_and_the_paper_preset_does_not():
    assert laav.LaavParams().noise_adaptive and laav.LaavParams.own_chain().noise_adaptive
    assert not laav.LaavParams.paper().noise_adaptive


def test_for_noise_raises_the_thresholds_only_above_the_clean_ones():
    p = laav.LaavParams(noise_adaptive=True)
    assert p.for_noise(0.3) == p.replace(noise_adaptive=False)  # k * 0.3 < 2 px
    q = p.for_noise(1.0)
    k = threshold_factor("all")
    assert q.affine_threshold == pytest.approx(k)
    rho = k / p.affine_threshold
    assert q.edge_scale == pytest.approx(p.edge_scale * rho)
    assert q.lam == pytest.approx(p.lam / rho ** 2)
    assert q.rv_lambda == pytest.approx(p.rv_lambda / rho ** 2)
    assert (q.r1, q.r2, q.coding_eps) == (p.r1, p.r2, p.coding_eps)
    assert not q.noise_adaptive
    with pytest.raises(ValueError):
        p.for_noise(-1.0)


def test_atoms_cover_a_noisy_scene_only_with_noise_adaptive_thresholds():
    # at sigma = 1 px the clean 2 px threshold rejects nearly every feature (issue 12)
    seq = _scene(1.0)
    fixed = build_atoms(seq, laav.LaavParams(noise_adaptive=False)).coverage
    adaptive = build_atoms(seq, laav.LaavParams()).coverage  # noise_adaptive: the default
    assert fixed < 0.1
    assert adaptive > 0.45
    clean = build_atoms(_scene(0.0), laav.LaavParams(noise_adaptive=False)).coverage
    assert adaptive > 0.6 * clean


def test_clean_tracks_give_identical_labels_and_the_pipeline_reports_the_estimate():
    seq = _scene(0.0, seed=2)
    for preset in (laav.LaavParams, laav.LaavParams.paper):
        a = laav.segment(seq, 3, preset(noise_adaptive=False), seed=0)
        b = laav.segment(seq, 3, preset(noise_adaptive=True), seed=0)
        assert np.array_equal(a.labels, b.labels)
        assert np.array_equal(a.coarse.point_labels, b.coarse.point_labels)
        assert a.noise_sigma is None and b.noise_sigma < 0.05
        assert b.run_params == b.params.replace(noise_adaptive=False)


def test_pipeline_update_equals_a_fresh_segmentation_with_noise_adaptive():
    seq = _scene(1.0, seed=3)
    p = laav.LaavParams(rv_max_iter=30, rv_trials=2, noise_adaptive=False)
    pipe = laav.Pipeline(seq, 3, p, seed=0)
    before = pipe.result.atoms.coverage
    res = pipe.update(noise_adaptive=True)
    fresh = laav.segment(seq, 3, p.replace(noise_adaptive=True), seed=0)
    assert np.array_equal(res.labels, fresh.labels)
    assert res.atoms.coverage == fresh.atoms.coverage > before + 0.3
    assert res.noise_sigma == fresh.noise_sigma
    assert res.run_params.affine_threshold > p.affine_threshold
