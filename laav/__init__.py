"""laav: motion segmentation of tracked feature trajectories by Locally Affine Atom Voting.

The algorithm package. The algorithm (:func:`segment`, :class:`Pipeline`, the stages,
:func:`random_voting`) needs numpy, scipy, scikit-learn and threadpoolctl only; the
scikit-learn estimators :class:`LAAV` and :class:`RandomVoting` load on first use. The
benchmark runner (:mod:`laav.bench`, :mod:`laav.report`) also uses joblib, tqdm and
matplotlib, imported when needed. Nothing here imports GUI code or OpenCV, and networkx
only in :func:`laav.multicut.exact_multicut`, the tests' reference solver (both come with
the ``test`` extra); the browser explorer lives in the separate ``explorer`` package and
uses only the public API exported here.
"""

from ._sequence import (
    MIN_POINTS,
    IncompleteSequenceError,
    LaavWarning,
    Sequence,
    SequenceError,
    require_complete,
)
from ._visibility import UNLABELLED_REASONS
from .io import find_truth_files, load_sequence, load_sequence_isolated, safe_name, save_sequence
from .metrics import best_label_map, confusion_matrix, labelling_distance, misclassification_rate

__version__ = "0.1.0"

__all__ = [
    "Sequence",
    "SequenceError",
    "IncompleteSequenceError",
    "require_complete",
    "MIN_POINTS",
    "UNLABELLED_REASONS",
    "LaavWarning",
    "load_sequence",
    "load_sequence_isolated",
    "save_sequence",
    "find_truth_files",
    "safe_name",
    "misclassification_rate",
    "labelling_distance",
    "best_label_map",
    "confusion_matrix",
]

from .atoms import Atoms, build_atoms  # noqa: E402
from .coarse import Coarse, merge_models  # noqa: E402
from .graph import AtomGraph, atom_graph  # noqa: E402
from .motions import MotionCount, estimate_motions  # noqa: E402
from .multicut import Multicut, solve_multicut  # noqa: E402
from .params import LaavParams  # noqa: E402
from .pipeline import LaavResult, Pipeline, preload, segment  # noqa: E402
from .voting import Voting, random_voting  # noqa: E402

__all__ += [
    "LaavParams", "segment", "random_voting", "Pipeline", "LAAV", "RandomVoting",
    "LaavResult", "Atoms", "AtomGraph", "Multicut", "Coarse", "Voting",
    "build_atoms", "atom_graph", "solve_multicut", "merge_models", "preload", "VotingHelper",
]
__all__ += ["estimate_motions", "MotionCount"]


def __getattr__(name: str):
    # The scikit-learn estimators load on first use: importing sklearn.base costs ~0.3-2 s,
    # which ``import laav`` (the explorer, the CLI) does not pay.
    if name in ("LAAV", "RandomVoting"):
        from . import estimator

        return getattr(estimator, name)
    if name == "VotingHelper":  # (multiprocessing only for those who use it)
        from .helper import VotingHelper

        return VotingHelper
    raise AttributeError(f"module 'laav' has no attribute {name!r}")
