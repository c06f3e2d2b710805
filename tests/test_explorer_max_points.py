"""laav-explore --max-points: a FILE over the limit is refused before any server starts."""

import numpy as np
import pytest

import laav

pytest.importorskip("panel")
from explorer.cli import main  # noqa: E402


def test_explore_max_points(tmp_path, capsys):
    pts = np.random.default_rng(0).uniform(0, 100, (3, 30, 2))
    path = laav.save_sequence(laav.Sequence(pts, labels=np.arange(30) % 2), tmp_path / "s.npz")
    assert main([str(path), "--max-points", "20", "--no-browser"]) == 2
    err = capsys.readouterr().err
    assert "30 points exceed the limit of 20" in err and str(path) in err
    assert main([str(path), "--max-points", "0", "--no-browser"]) == 2
    assert "--max-points must be at least 1" in capsys.readouterr().err
