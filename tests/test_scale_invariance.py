"""Pixel scale and translation (issue 16 item 8): scaling every coordinate by s together with
the parameters in pixels (by s) and the strengths in 1/px^2 (by 1/s^2), or shifting every
coordinate by 1e6 px, should give the same labels.

What holds today is tested; what does not is a strict xfail naming the cause, so that the
fix flips it (see the closing note of issue 16)."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

import laav
from laav import LaavParams

ASSETS = Path(__file__).resolve().parents[1] / "explorer" / "assets"
FAST = LaavParams(rv_max_iter=60, rv_trials=3)


def scaled(p: LaavParams, s: float) -> LaavParams:
    return p.replace(r1=p.r1 * s, r2=p.r2 * s, affine_threshold=p.affine_threshold * s,
                     edge_scale=p.edge_scale * s, coding_eps=p.coding_eps * s,
                     lam=p.lam / s**2, rv_lambda=p.rv_lambda / s**2)


def _run(method, points, C, params):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", laav.LaavWarning)  # the spread warning at 1e-3 / 1e4
        if method == "laav":
            return laav.segment(points, C, params, 0).labels
        return laav.random_voting(points, C, params, 0).labels


def test_strengths_accept_thousandths_of_a_pixel():
    p = scaled(LaavParams(), 1e-3)
    assert p.lam == pytest.approx(2e6) and p.rv_lambda == pytest.approx(2e6)
    with pytest.raises(ValueError, match="lam must be in"):
        LaavParams(lam=2e12)


@pytest.mark.parametrize("method", ["laav", "rv"])
def test_scale_and_translation_invariance_two_objects(method):
    seq = laav.load_sequence(ASSETS / "demo_two_objects.mat")
    base = _run(method, seq.points, 2, FAST)
    for s in (1e-3, 0.1, 10.0, 1e4):
        lab = _run(method, seq.points * s, 2, scaled(FAST, s))
        assert laav.misclassification_rate(base, lab) == 0, s
    lab = _run(method, seq.points + 1e6, 2, FAST)
    assert laav.misclassification_rate(base, lab) == 0


@pytest.mark.xfail(strict=True, reason="not fixed yet; suspects, unverified: absolute constants "
                   "in px / px^2 (refine.py: the 1e4 px^2 "
                   "cap and the 1e-4 px^2 floor; graph.py: the 1e-6 px error floor; coarse.py: "
                   "+1e-3 px; geometry.py: +1.0 in the affine ridge): even a power-of-two scale, "
                   "exact in floating point, changes the labels")
def test_scale_invariance_articulated_power_of_two():
    seq = laav.load_sequence(ASSETS / "demo_articulated.mat")
    base = _run("laav", seq.points, seq.n_motions, FAST)
    lab = _run("laav", seq.points * 0.125, seq.n_motions, scaled(FAST, 0.125))
    assert laav.misclassification_rate(base, lab) == 0
