"""laav: motion segmentation of tracked feature trajectories by Locally Affine Atom Voting.

The algorithm package. It depends on numpy, scipy, scikit-learn, OpenCV and networkx only
and never imports GUI code; the browser explorer lives in the separate ``explorer``
package and uses only the public API exported here.
"""

from ._sequence import Sequence, SequenceError
from .io import find_truth_files, load_sequence, save_sequence
from .metrics import confusion_matrix, misclassification_rate

__version__ = "0.1.0"

__all__ = [
    "Sequence",
    "SequenceError",
    "load_sequence",
    "save_sequence",
    "find_truth_files",
    "misclassification_rate",
    "confusion_matrix",
]
