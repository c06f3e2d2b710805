"""LaavParams validation: one table of types and ranges, numpy scalars, one ValueError."""

import dataclasses

import numpy as np
import pytest

from laav import LaavParams, Pipeline
from laav.params import _BOUNDS
from laav.synthetic import make_sequence


def scene():
    return make_sequence(n_objects=1, n_frames=10, n_points=100, rng=0)


def test_every_field_has_bounds():
    assert [b[0] for b in _BOUNDS] == [f.name for f in dataclasses.fields(LaavParams)]


def test_numpy_scalars_accepted_as_python_numbers():
    p = LaavParams(r1=np.float32(20), rv_trials=np.int64(3), fine_models=np.int32(4),
                   rv_refine=np.bool_(False), lam=np.int64(2))
    assert p.r1 == 20.0 and type(p.r1) is float
    assert p.rv_trials == 3 and type(p.rv_trials) is int
    assert type(p.fine_models) is int and p.rv_refine is False and type(p.lam) is int
    assert p == LaavParams(r1=20.0, rv_trials=3, fine_models=4, rv_refine=False, lam=2)


@pytest.mark.parametrize("change, match", [
    ({"pooled_trials": True}, "pooled_trials must be an integer"),
    ({"r1": True}, "r1 must be a number"),
    ({"rv_refine": 1}, "rv_refine must be True or False"),
    ({"lam": "2"}, "lam must be a number"),
    ({"r2": 1e308}, r"r2 must be in \(0, 1e\+06\]"),
    ({"r1": float("nan")}, "r1 must be a finite number"),
    ({"rv_lambda": float("inf")}, "rv_lambda must be a finite number"),
    ({"cut_prior": -float("inf")}, "cut_prior must be a finite number"),
    ({"r1": 10**400}, "r1 must be in"),
    ({"rv_max_iter": 10**6}, r"rv_max_iter must be in \[1, 10000\]"),
    ({"rv_trials": 101}, "rv_trials"),
    ({"coarse_frames": 10**6}, "coarse_frames"),
    ({"coarse_samples": 10**7}, "coarse_samples"),
    ({"pooled_trials": 10**6}, "pooled_trials"),
    ({"ransac_hypotheses": 1001}, "ransac_hypotheses"),
    ({"graph_neighbors": 101}, "graph_neighbors"),
    ({"fine_models": 2.0}, "fine_models must be an integer"),
    ({"rv_sample_size": 7}, "rv_sample_size"),
    ({"rv_select": 3}, "rv_select must be one of"),
])
def test_invalid_values(change, match):
    with pytest.raises(ValueError, match=match):
        LaavParams(**change)


def test_all_problems_in_one_error():
    with pytest.raises(ValueError) as info:
        LaavParams(r1=float("nan"), rv_max_iter=10**6, lam="x", rv_reassign=None)
    msg = str(info.value)
    for name in ("r1", "rv_max_iter", "lam", "rv_reassign"):
        assert f"{name} must" in msg
    assert "r2 must be larger" not in msg  # r1 already reported


def test_bounds_allow_defaults_and_paper():
    LaavParams()
    LaavParams.paper()
    LaavParams(rv_max_iter=10_000, rv_trials=100, coarse_frames=100, coarse_samples=1000,
               pooled_trials=100, ransac_hypotheses=1000, graph_neighbors=100, r1=1e5, r2=1e6)


@pytest.mark.parametrize("seed", [None, "1", 1.5, True, -1])
def test_bad_seed_is_a_value_error(seed):
    pipe = Pipeline(scene(), 2, LaavParams(rv_max_iter=20, rv_trials=1))
    res = pipe.result
    with pytest.raises(ValueError, match="seed must be an integer"):
        pipe.update(seed=seed)
    assert pipe.result is res and pipe.seed == 0
    with pytest.raises(ValueError, match="seed must be an integer"):
        Pipeline(scene(), 2, seed=seed)
