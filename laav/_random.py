"""scikit-learn style ``random_state`` for functions that take an integer ``seed``."""

from __future__ import annotations

import numpy as np

__all__ = ["as_seed", "resolve_seed", "check_seed"]

_MAX_SEED = 2**31 - 1


def as_seed(random_state) -> int:
    """An integer seed from a scikit-learn style ``random_state``.

    ``None`` draws from numpy's global random state (so ``np.random.seed`` fixes it, as in
    scikit-learn); an int (>= 0) is used as it is; a :class:`numpy.random.Generator` or
    :class:`numpy.random.RandomState` gives one draw, which advances it.
    """
    if random_state is None:
        return int(np.random.randint(_MAX_SEED))  # noqa: NPY002 - the global state, as sklearn
    if isinstance(random_state, (int, np.integer)) and not isinstance(random_state, bool):
        if random_state < 0:
            raise ValueError(f"random_state must be >= 0, got {random_state}")
        return int(random_state)
    if isinstance(random_state, np.random.Generator):
        return int(random_state.integers(_MAX_SEED))
    if isinstance(random_state, np.random.RandomState):
        return int(random_state.randint(_MAX_SEED))
    raise ValueError(f"random_state must be None, an int, a numpy Generator or RandomState, "
                     f"got {random_state!r}")


def check_seed(seed) -> int:
    """``seed`` as an int, or a ValueError naming it: an integer in [0, 2**63) (bools,
    floats, None and negative numbers are refused: every run is seeded)."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**63:
        raise ValueError(f"seed must be an integer in [0, 2**63), got {seed!r}")
    return int(seed)


def resolve_seed(seed, random_state):
    """``seed`` unless ``random_state`` is given (not None); then ``random_state`` as a seed."""
    return seed if random_state is None else as_seed(random_state)
