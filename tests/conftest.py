"""Shared fixtures: where the Hopkins155 ground truth lives, and a table of its sequences.

The data set sits outside the repository. ``$HOPKINS155`` names its folder; without it the
fixtures look for ``<repo>/../shared/data/hopkins155``. Tests that use these fixtures are
skipped (not failed) when the folder holds no ``<seq>/<seq>_truth.mat``. The official
download has no ``sequences.csv``: the table then comes from the files themselves
(:func:`rows_from_files`), with ``dancing`` (5 motions, not one of the 155) marked out.
"""

from __future__ import annotations

import csv
import gc
import os
from pathlib import Path

import pytest

import laav

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_HOPKINS = REPO_ROOT.parent / "shared" / "data" / "hopkins155"


@pytest.fixture(autouse=True)
def _collector_as_it_was():
    """A test that runs ``laav-explore``'s ``main`` in this process freezes the heap
    (``explorer.cli._StartupGC``: ``gc.freeze()`` after the imports), so whatever garbage
    exists then would never be collected for the rest of the session; undone after each
    test, with the collector's on/off state."""
    was, frozen = gc.isenabled(), gc.get_freeze_count()
    yield
    if frozen == 0 and gc.get_freeze_count() > 0:
        gc.unfreeze()
    if was and not gc.isenabled():
        gc.enable()


@pytest.fixture(scope="session")
def hopkins_root() -> Path:
    """Folder of the Hopkins155 ground truth (``<seq>/<seq>_truth.mat``, optional ``sequences.csv``)."""
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else DEFAULT_HOPKINS
    if not (root.is_dir() and any(root.glob("*/*_truth.mat"))):
        how = "$HOPKINS155" if env else "default location (set $HOPKINS155)"
        pytest.skip(f"Hopkins155 data not found at {root} ({how})")
    return root


@pytest.fixture(scope="session")
def hopkins_rows(hopkins_root: Path) -> list[dict[str, str]]:
    """One dict of strings per sequence folder: ``sequences.csv``, else :func:`rows_from_files`."""
    if not (hopkins_root / "sequences.csv").is_file():
        return rows_from_files(hopkins_root)
    with open(hopkins_root / "sequences.csv", newline="") as fh:
        return list(csv.DictReader(fh))


#: Sequences of the original distribution that are not among the 155.
NOT_IN_HOPKINS155 = ("dancing",)


def rows_from_files(root: Path) -> list[dict[str, str]]:
    """The columns of ``sequences.csv`` that the files tell (no ``category``)."""
    rows = []
    for f in laav.find_truth_files(root):
        seq = laav.load_sequence(f)
        w, h = seq.image_size or ("", "")
        rows.append({"sequence": f.parent.name, "num_motions": str(seq.n_motions),
                     "num_points": str(seq.n_points), "num_frames": str(seq.n_frames),
                     "width": str(w), "height": str(h),
                     "in_hopkins155": "no" if f.parent.name in NOT_IN_HOPKINS155 else "yes"})
    return rows


def stop_process(proc) -> None:
    """End a server started by a test: terminate, then kill if it has not gone in 30 s."""
    import subprocess

    proc.terminate()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def session_text(url: str, timeout: float = 60.0) -> str:
    """All text a browser tab of the served app is given (every bokeh model's ``text``),
    read through a script session: the sequence name lives in the page's panes, not in its
    static HTML."""
    import time

    import panel.models  # noqa: F401 - registers the models the client receives
    import panel.models.file_dropper  # noqa: F401 - the upload box (not in panel.models)
    from bokeh.client import pull_session

    with pull_session(url=url) as session:
        deadline = time.monotonic() + timeout
        while True:
            texts = [str(getattr(m, "text", "") or "") for m in session.document.models]
            joined = "\n".join(texts)
            if joined.strip() or time.monotonic() > deadline:
                return joined
            time.sleep(0.5)


def two_motion_sequence(seed: int = 0, P: int = 140, F: int = 12, name: str = "two_motions") -> laav.Sequence:
    """A small two-motion sequence (a translating, slightly scaling object and a rotating
    one), fast to segment: explorer and browser tests use it so they stay short."""
    import numpy as np

    rng = np.random.default_rng(seed)
    a = rng.uniform([40, 60], [260, 400], (P // 2, 2))
    b = rng.uniform([360, 60], [600, 400], (P - P // 2, 2))
    t = np.linspace(0, 1, F)[:, None, None]
    pa = a[None] + t * np.array([60.0, 20.0]) + 0.05 * t * (a[None] - 150)
    ang = 0.35 * t[..., 0]
    rel = b[None] - b.mean(0)
    pb = np.stack([np.cos(ang) * rel[..., 0] - np.sin(ang) * rel[..., 1],
                   np.sin(ang) * rel[..., 0] + np.cos(ang) * rel[..., 1]], -1) + b.mean(0)
    pb = pb + t * np.array([-30.0, 40.0])
    pts = np.concatenate([pa, pb], axis=1) + rng.normal(0, 0.3, (F, P, 2))
    labels = np.r_[np.zeros(P // 2, int), np.ones(P - P // 2, int)]
    return laav.Sequence(pts, labels, name=name, image_size=(640, 480))


class FakeServer:
    """Stands in for ``panel.serve``'s server: ``laav-explore``'s ``main`` returns at once."""

    class io_loop:  # noqa: N801
        @staticmethod
        def add_callback(fn):
            pass

        @staticmethod
        def start():
            pass

    def start(self):
        pass

    def stop(self):
        pass


def fake_serving(monkeypatch) -> dict:
    """``explorer.cli``'s page factory and ``panel.serve`` replaced by stand-ins: ``main``
    sets everything up and returns; the factory's arguments land in the returned dict
    (``n_motions``, ``seed``, ``params``, ``origin``, ``seq``)."""
    import panel as pn

    import explorer.cli as cli

    seen: dict = {}

    def fake_factory(seq, n_motions, seed=0, host="127.0.0.1", **kw):
        seen.update(n_motions=n_motions, seed=seed, params=kw.get("params"),
                    origin=kw.get("origin"), seq=seq)

        def make():
            pass
        make.close_unclaimed = lambda: None
        return make

    monkeypatch.setattr(cli, "app_factory", fake_factory)
    monkeypatch.setattr(pn, "serve", lambda panels, **kw: FakeServer())
    return seen


def wait_for_stop(seconds: float = 120.0) -> None:
    """Wait, checking for a stop request (:mod:`laav._interrupt`) every 50 ms, for up to
    ``seconds``: inside a computation, work that lasts until it is stopped, whatever the
    machine's speed (a test that raced real work failed in CI once the work got faster)."""
    import time

    from laav._interrupt import check

    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        check()
        time.sleep(0.05)


def hold_computation(monkeypatch, name: str, seconds: float = 120.0) -> None:
    """Every pipeline run on a sequence called ``name`` waits in its atoms stage until it is
    stopped (:func:`wait_for_stop`, up to ``seconds``): a "long computation" that lasts until
    it is cancelled, on any machine (a real big sequence took ~12 s once and ~2 s now, and
    the test that raced it failed in CI)."""
    import laav.pipeline as LP

    real = LP.build_atoms

    def held(seq, *args, **kwargs):
        if seq.name == name:
            wait_for_stop(seconds)
        return real(seq, *args, **kwargs)

    monkeypatch.setattr(LP, "build_atoms", held)
