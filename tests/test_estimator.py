"""laav.LAAV and laav.RandomVoting as scikit-learn estimators; random_state in the functions."""

from __future__ import annotations

import functools
import pickle

import numpy as np
import pytest
from sklearn.base import BaseEstimator, ClusterMixin, clone
from sklearn.utils.estimator_checks import parametrize_with_checks

import laav
from laav import LAAV, LaavParams, RandomVoting, misclassification_rate, random_voting, segment
from laav.synthetic import make_sequence

FAST = dict(rv_max_iter=30, rv_trials=2)


@functools.cache
def _seq() -> laav.Sequence:
    return make_sequence(n_objects=1, n_frames=12, n_points=120, rng=3)


def _X(seq: laav.Sequence) -> np.ndarray:
    """(P, 2F): one trajectory x1, y1, ..., xF, yF per row."""
    return seq.points.transpose(1, 0, 2).reshape(seq.n_points, -1)


# ----------------------------------------------------------------------------- the API
@pytest.mark.parametrize("cls", [LAAV, RandomVoting])
def test_is_a_scikit_learn_clusterer(cls):
    est = cls(2, random_state=0)
    assert isinstance(est, BaseEstimator) and isinstance(est, ClusterMixin)
    assert laav.LAAV is LAAV and laav.RandomVoting is RandomVoting
    params = est.get_params()
    assert params["n_motions"] == 2 and params["random_state"] == 0
    assert params["rv_alpha"] == LaavParams().rv_alpha  # stage parameters by name, with defaults
    c = clone(est.set_params(rv_alpha=0.95))
    assert c.get_params() == est.get_params() and c is not est
    with pytest.raises(TypeError, match="rv_alhpa"):
        cls(2, rv_alhpa=0.9)


def test_stage_parameters_follow_laavparams():
    # the signature comes from the dataclass: every field, and RandomVoting's rv_* ones plus
    # the two its selection's joint score reads
    fields = set(LaavParams().to_dict())
    assert set(LAAV().get_params()) == fields | {"n_motions", "random_state"}
    rv = set(RandomVoting().get_params()) - {"n_motions", "random_state"}
    assert rv == {f for f in fields if f.startswith("rv_")} | {"coarse_epipolar_weight", "coding_eps"}
    assert "lam=3.0" in repr(LAAV(lam=3.0)) and "r1" not in repr(LAAV(lam=3.0))


def test_init_only_stores_and_fit_validates():
    est = LAAV(2, r1=50.0)  # r2 < r1: invalid, but only fit says so
    assert est.r1 == 50.0
    with pytest.raises(ValueError, match="r2 must be larger than r1"):
        est.fit(_X(_seq()))
    with pytest.raises(ValueError, match="n_motions"):
        LAAV(0).fit(_X(_seq()))


def test_fit_matches_segment_and_sets_the_stage_results():
    seq = _seq()
    est = LAAV(n_motions=2, random_state=0, lam=3.0, **FAST)
    assert est.fit(_X(seq)) is est
    ref = segment(seq, 2, LaavParams(lam=3.0, **FAST), seed=0)
    np.testing.assert_array_equal(est.labels_, ref.labels)
    assert est.result_.params.lam == 3.0 and est.seed_ == 0 and est.n_features_in_ == 2 * seq.n_frames
    assert est.result_.atoms.n_atoms == ref.atoms.n_atoms
    np.testing.assert_array_equal(est.fit_predict(_X(seq)), est.labels_)
    np.testing.assert_array_equal(LAAV(2, random_state=0, lam=3.0, **FAST).fit(seq).labels_, ref.labels)
    assert misclassification_rate(seq.labels, est.labels_) < 0.01
    assert est.get_params()["lam"] == 3.0  # fit changed no parameter
    assert est.n_motions_ == 2
    # "auto": C as estimated, beside the parameter it leaves as it was
    auto = LAAV("auto", random_state=0, **FAST).fit(seq)
    assert auto.n_motions_ == auto.result_.n_motions == auto.result_.motion_count.n_motions
    assert auto.get_params()["n_motions"] == "auto"


def test_random_voting_estimator_matches_the_function():
    seq = _seq()
    rv = RandomVoting(2, random_state=0, rv_alpha=0.95, **FAST)
    lab = rv.fit_predict(_X(seq))
    ref = random_voting(seq, 2, LaavParams(rv_alpha=0.95, **FAST), 0)
    np.testing.assert_array_equal(lab, ref.labels)
    assert rv.result_.labels is rv.labels_ and rv.n_motions_ == 2
    assert misclassification_rate(seq.labels, lab) < 0.01


def test_single_motion():
    assert LAAV(1, random_state=0).fit_predict(_seq()).tolist() == [0] * _seq().n_points
    assert RandomVoting(1, random_state=0).fit_predict(_seq()).tolist() == [0] * _seq().n_points


@pytest.mark.parametrize("bad, match", [
    (np.zeros((12, 2, 120)), r"shape \(P, 2F\)"),       # (F, P, 2)-like 3-D input
    (np.zeros((120, 7)), "even number of columns"),
    (np.full((120, 24), np.nan), r"X \(rows = points\): 120 point\(s\) are visible in fewer than 2 "),
    (np.full((120, 24), np.inf), "infinity"),
    (np.ones((120, 2)), "minimum of 4"),                 # one frame
    (np.ones((3, 24)), "minimum of 8"),                  # three trajectories
])
def test_bad_input_is_refused(bad, match):
    with pytest.raises(ValueError, match=match):
        LAAV(2).fit(bad)


def test_nan_marks_a_point_not_seen_in_a_frame():
    # laav segments incomplete tracks: a NaN in X hides that frame's entry, as Sequence's
    # `visible` does (not scikit-learn's "does not accept missing values" refusal)
    seq = _seq()
    X = _X(seq).copy()
    X[3, 4:6] = np.nan  # point 3 unseen in frame 2
    X[7, 10] = np.nan  # one coordinate: the entry is hidden
    est = LAAV(2, random_state=0, **FAST).fit(X)
    vis = np.ones((seq.n_frames, seq.n_points), dtype=bool)
    vis[2, 3] = vis[5, 7] = False
    expected = segment(laav.Sequence(seq.points, visible=vis), 2, LaavParams(**FAST), 0).labels
    np.testing.assert_array_equal(est.labels_, expected)
    assert est.n_features_in_ == 2 * seq.n_frames


def test_random_state_kinds():
    seq, p = _seq(), LaavParams(**FAST)
    X = _X(seq)
    # an int is the seed itself; a Generator or RandomState gives one draw, reproducibly
    a = LAAV(2, random_state=np.random.default_rng(5), **FAST).fit(X)
    b = LAAV(2, random_state=np.random.default_rng(5), **FAST).fit(X)
    assert a.seed_ == b.seed_ and np.array_equal(a.labels_, b.labels_)
    c = LAAV(2, random_state=np.random.RandomState(5), **FAST).fit(X)
    np.testing.assert_array_equal(c.labels_, segment(seq, 2, p, seed=c.seed_).labels)
    # None draws from numpy's global state, like scikit-learn
    np.random.seed(7)  # noqa: NPY002
    d = LAAV(2, **FAST).fit(X).seed_
    np.random.seed(7)  # noqa: NPY002
    assert LAAV(2, **FAST).fit(X).seed_ == d
    with pytest.raises(ValueError, match="random_state"):
        LAAV(2, random_state="zero").fit(X)
    # the functions: random_state beside seed, used instead of it when given
    np.testing.assert_array_equal(segment(seq, 2, p, random_state=4).labels,
                                  segment(seq, 2, p, seed=4).labels)
    np.testing.assert_array_equal(random_voting(seq, 2, p, random_state=4).labels,
                                  random_voting(seq, 2, p, seed=4).labels)
    g = np.random.default_rng(9)
    s = int(np.random.default_rng(9).integers(2**31 - 1))
    np.testing.assert_array_equal(segment(seq, 2, p, random_state=g).labels,
                                  segment(seq, 2, p, seed=s).labels)


# ------------------------------- what the skipped generic checks cover, on trajectories
@pytest.mark.parametrize("cls", [LAAV, RandomVoting])
def test_trajectory_versions_of_the_skipped_checks(cls, tmp_path):
    seq = _seq()
    X = _X(seq)
    est = cls(2, random_state=0, **FAST)
    lab = est.fit(X).labels_
    # idempotent fit, fit_predict, pickling a fitted estimator
    np.testing.assert_array_equal(est.fit(X).labels_, lab)
    np.testing.assert_array_equal(cls(2, random_state=0, **FAST).fit_predict(X), lab)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(est)).labels_, lab)
    # other dtypes, Fortran order and a read-only memory map give the same labels
    np.testing.assert_array_equal(clone(est).fit(X.astype(np.float32).astype(np.float64)).labels_,
                                  clone(est).fit(X.astype(np.float32)).labels_)
    np.testing.assert_array_equal(clone(est).fit(np.asfortranarray(X)).labels_, lab)
    np.save(tmp_path / "X.npy", X)
    np.testing.assert_array_equal(clone(est).fit(np.load(tmp_path / "X.npy", mmap_mode="r")).labels_, lab)
    # the input is not modified, inf is refused, n_features_in_ is 2F
    X0 = X.copy()
    clone(est).fit(X)
    np.testing.assert_array_equal(X, X0)
    Xinf = X.copy()
    Xinf[0, 0] = np.inf
    with pytest.raises(ValueError, match="infinity"):
        clone(est).fit(Xinf)
    assert est.n_features_in_ == X.shape[1]


# --------------------------------------------------------- scikit-learn's generic checks
#: Checks that build their own data: blobs or random matrices of 1-5 features. Trajectory
#: data need an even number of columns (x, y per frame), at least 2 frames (4 columns) and
#: 8 points, so these checks stop at validation (ValueError) before testing anything; the
#: test above covers their property on real trajectories where it applies.
NOT_APPLICABLE = {
    "check_clustering": "clusters blobs of 2-D points and scores the ARI: points are not motions",
    "check_dict_unchanged": "3-column data (and no predict/transform to compare)",
    "check_dont_overwrite_parameters": "3-column data (covered: fit changes no parameter)",
    "check_estimators_dtypes": "5-column data (covered: float32 input)",
    "check_estimators_fit_returns_self": "2-column data (covered: fit returns self)",
    "check_estimators_nan_inf": "3-column data (covered: NaN and inf are refused)",
    "check_estimators_overwrite_params": "2-column data (covered: fit changes no parameter)",
    "check_estimators_pickle": "3-column data (covered: pickle of a fitted estimator)",
    "check_f_contiguous_array_estimator": "3-column data (covered: Fortran-ordered X)",
    "check_fit2d_predict1d": "3-column data (and there is no predict)",
    "check_fit_check_is_fitted": "2-column data",
    "check_fit_idempotent": "2-column data (covered: idempotent fit)",
    "check_fit_score_takes_y": "3-column data (fit(X, y=None) takes and ignores y)",
    "check_methods_sample_order_invariance": "3-column data; and a permutation of the "
                                             "trajectories changes the random samples drawn",
    "check_methods_subset_invariance": "3-column data (and no predict/transform)",
    "check_n_features_in": "2-column data (covered: n_features_in_ is 2F)",
    "check_pipeline_consistency": "3-column data",
    "check_readonly_memmap_input": "2-column data (covered: a read-only memory map)",
}


@parametrize_with_checks([LAAV(2, **FAST), RandomVoting(2, **FAST)])
def test_sklearn_estimator_checks(estimator, check):
    name = check.func.__name__ if isinstance(check, functools.partial) else check.__name__
    if name in NOT_APPLICABLE:
        pytest.skip(f"{name} does not apply to trajectories: {NOT_APPLICABLE[name]}")
    check(estimator)
