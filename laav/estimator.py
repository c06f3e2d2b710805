"""scikit-learn estimators: :class:`LAAV` (the pipeline) and :class:`RandomVoting` (plain RV).

Both are thin wrappers of :func:`laav.segment` and :func:`laav.random_voting`: ``__init__``
only stores its arguments; :meth:`fit` validates them and the data, runs the function and
stores the result as fitted attributes.

**Input.** ``X`` of shape (P, 2F), scikit-learn's (n_samples, n_features): one row per
tracked point (trajectory), its columns ``x1, y1, x2, y2, ..., xF, yF`` in pixels. A
:class:`laav.Sequence` is accepted as it is. From an array ``points`` of shape (F, P, 2)::

    X = points.transpose(1, 0, 2).reshape(points.shape[1], -1)

A NaN in ``X`` marks a point not seen in that frame (either coordinate NaN: the frame's
entry is hidden), as :class:`laav.Sequence` ``visible`` does, and the missing-data variant
of every stage runs; infinite values are refused.

**Parameters.** ``n_motions``, ``random_state`` and, as keyword-only parameters, every
field of :class:`laav.LaavParams` (:class:`RandomVoting`: its ``rv_*`` fields) with the
dataclass's default. The signature of ``__init__`` is generated from the dataclass when
this module is imported, so :meth:`get_params`, :meth:`set_params`, :func:`sklearn.base.clone`
and the estimator's repr see every stage parameter by name, and a field added to or removed
from :class:`~laav.LaavParams` needs no change here. Values are validated (by building a
:class:`~laav.LaavParams`) in :meth:`fit`, as scikit-learn requires.

**Randomness.** ``random_state`` as in scikit-learn: an int gives the same labels as
``segment(..., seed=random_state)``; a Generator or RandomState gives one draw used as the
seed; None (the default) draws the seed from numpy's global random state. The seed used is
stored as ``seed_``.
"""

from __future__ import annotations

import dataclasses
import inspect

import numpy as np
from sklearn.base import BaseEstimator, ClusterMixin
from sklearn.utils.validation import validate_data

from ._random import as_seed
from ._sequence import Sequence
from .params import STAGE_PARAMS, LaavParams
from .pipeline import segment
from .voting import SELECTION_FIELDS, random_voting

__all__ = ["LAAV", "RandomVoting"]

_P = inspect.Parameter


def _init_with_stage_params(names: list[str]):
    """An ``__init__(self, n_motions=2, *, random_state=None, <names>=<LaavParams defaults>)``
    that stores every argument under its own name and does nothing else."""
    fields = {f.name: f for f in dataclasses.fields(LaavParams)}
    params = [_P("self", _P.POSITIONAL_OR_KEYWORD), _P("n_motions", _P.POSITIONAL_OR_KEYWORD, default=2),
              _P("random_state", _P.KEYWORD_ONLY, default=None)]
    params += [_P(n, _P.KEYWORD_ONLY, default=fields[n].default) for n in names]
    signature = inspect.Signature(params)

    def __init__(self, *args, **kwargs):
        bound = signature.bind(self, *args, **kwargs)  # TypeError for an unknown parameter
        bound.apply_defaults()
        for name, value in list(bound.arguments.items())[1:]:
            setattr(self, name, value)

    __init__.__signature__ = signature
    return __init__


class _Estimator(ClusterMixin, BaseEstimator):
    _stage_params: list[str] = []

    def _params(self) -> LaavParams:
        """The stage parameters as a validated :class:`LaavParams` (ValueError if invalid)."""
        return LaavParams(**{name: getattr(self, name) for name in self._stage_params})

    def _sequence(self, X) -> Sequence:
        """``X`` (P, 2F) or a Sequence, validated, as a Sequence; sets ``n_features_in_``."""
        if isinstance(X, Sequence):
            self.n_features_in_ = 2 * X.n_frames
            return X
        if np.ndim(X) == 3:
            raise ValueError("X must have shape (P, 2F), one trajectory x1, y1, ..., xF, yF per "
                             "row; for points of shape (F, P, 2) pass "
                             "points.transpose(1, 0, 2).reshape(P, -1) or a laav.Sequence")
        # at least 8 points (the 8-point fits of Random Voting) and 2 frames; NaN: not seen
        X = validate_data(self, X, dtype=np.float64, ensure_min_samples=8, ensure_min_features=4,
                          ensure_all_finite="allow-nan")
        if X.shape[1] % 2:
            raise ValueError(f"X must have an even number of columns (x, y per frame), got {X.shape[1]}")
        P, F = X.shape[0], X.shape[1] // 2
        points = X.reshape(P, F, 2).transpose(1, 0, 2)
        seen = ~np.isnan(points).any(axis=-1)  # (F, P)
        # (its checks name X's rows as points, e.g. one seen in fewer than 2 frames)
        return Sequence(points, visible=None if seen.all() else seen, source="X (rows = points)")

    def _fit(self, X, run):
        seq = self._sequence(X)
        params = self._params()
        self.seed_ = as_seed(self.random_state)
        self.result_ = run(seq, self.n_motions, params, self.seed_)
        self.labels_ = self.result_.labels
        self.n_motions_ = int(getattr(self.result_, "n_motions", self.n_motions))
        return self

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.allow_nan = True  # a point not seen in a frame
        return tags


class LAAV(_Estimator):
    """LAAV motion segmentation as a scikit-learn clusterer (see the module docstring).

    Parameters
    ----------
    n_motions : int or "auto", default 2
        C, the number of motions; ``"auto"`` estimates it (:func:`laav.estimate_motions`).
    random_state : None, int, numpy.random.Generator or RandomState, default None
    **stage_params
        Every field of :class:`laav.LaavParams`, keyword-only, with its default.

    Attributes
    ----------
    labels_ : ndarray of shape (P,), int64
        Motion of every trajectory; -1 for one seen (not NaN) in too few frames to decide
        (missing data: ``result_.unlabelled_reason`` says why), as scikit-learn's noise label.
        A row seen in fewer than 2 frames is refused (ValueError naming it): drop it first.
    n_motions_ : int
        C as run: ``n_motions``, or the estimate for ``"auto"`` (``result_.motion_count``).
    result_ : LaavResult
        Every stage's result (``result_.atoms``, ``.graph``, ``.multicut``, ``.coarse``,
        ``.voting``, ``.timings``).
    seed_ : int
        The integer seed the run used (``segment(X, C, params, seed_)`` reproduces it).
    n_features_in_ : int
        2F.

    Examples
    --------
    >>> labels = LAAV(n_motions=2, random_state=0, lam=3.0).fit_predict(X)  # doctest: +SKIP
    """

    _stage_params = [f.name for f in dataclasses.fields(LaavParams)]
    __init__ = _init_with_stage_params(_stage_params)

    def fit(self, X, y=None):
        """Segment the trajectories ``X`` (P, 2F) or a Sequence; ``y`` is ignored."""
        return self._fit(X, segment)


class RandomVoting(_Estimator):
    """Plain Random Voting as a scikit-learn clusterer (see the module docstring).

    Parameters
    ----------
    n_motions : int, default 2
        C, the number of motions.
    random_state : None, int, numpy.random.Generator or RandomState, default None
    **stage_params
        Every ``rv_*`` field of :class:`laav.LaavParams`, and the two its selection's joint
        score reads (``coarse_epipolar_weight``, ``coding_eps``:
        :data:`laav.voting.SELECTION_FIELDS`), keyword-only, with its default.

    Attributes
    ----------
    labels_ : ndarray of shape (P,), int64
        Motion of every trajectory; -1 as in :class:`LAAV`.
    n_motions_ : int
        C as run (``n_motions``).
    result_ : Voting
    seed_ : int
    n_features_in_ : int
    """

    _stage_params = [f.name for f in dataclasses.fields(LaavParams)
                     if f.name in STAGE_PARAMS["voting"] or f.name in SELECTION_FIELDS]
    __init__ = _init_with_stage_params(_stage_params)

    def fit(self, X, y=None):
        """Segment the trajectories ``X`` (P, 2F) or a Sequence; ``y`` is ignored."""
        return self._fit(X, random_voting)
