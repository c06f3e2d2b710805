"""The algorithm package never pulls GUI or plotting code in when it is imported."""

from __future__ import annotations

import subprocess
import sys

FORBIDDEN = ("panel", "viser", "bokeh", "matplotlib")


def test_importing_every_laav_module_loads_no_gui_code():
    code = (
        "import importlib, pkgutil, sys, laav\n"
        "for m in pkgutil.iter_modules(laav.__path__):\n"
        "    importlib.import_module('laav.' + m.name)\n"
        f"bad = sorted(n for n in sys.modules if n.split('.')[0] in {FORBIDDEN!r})\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"laav imported GUI/plotting modules: {out.stdout.strip()}"


def test_import_laav_defers_the_heavy_imports_that_preload_performs():
    code = (
        "import sys, laav\n"
        "lazy = ('scipy.sparse.csgraph', 'scipy.spatial.distance', 'scipy.optimize')\n"
        "print(','.join(m for m in lazy if m in sys.modules))\n"
        "laav.preload()\n"
        "print(','.join(m for m in lazy if m not in sys.modules))\n"
        "print(','.join(m for m in sys.modules if m.split('.')[0] == 'sklearn'))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    loaded_by_import, missing_after_preload, sklearn = out.stdout.split("\n")[:3]
    assert loaded_by_import == "", f"`import laav` loaded {loaded_by_import}"
    assert missing_after_preload == "", f"laav.preload() did not load {missing_after_preload}"
    # the pipeline needs no scikit-learn (0.3-2 s to import): only laav.LAAV / RandomVoting do
    assert sklearn == "", f"laav.preload() loaded scikit-learn: {sklearn}"


def test_the_algorithm_needs_neither_opencv_nor_networkx():
    # what laav/__init__.py and the README say: a segmentation (and the estimator) imports neither
    code = (
        "import sys, numpy as np, laav\n"
        "from laav.synthetic import make_sequence\n"
        "seq = make_sequence(n_objects=1, n_frames=8, n_points=60, rng=0)\n"
        "p = laav.LaavParams(rv_max_iter=10, rv_trials=1)\n"
        "laav.segment(seq, 2, p); laav.random_voting(seq, 2, p)\n"
        "laav.LAAV(2, random_state=0, rv_max_iter=10, rv_trials=1).fit(seq)\n"
        "print(','.join(sorted(n for n in sys.modules if n.split('.')[0] in ('cv2', 'networkx'))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", f"the algorithm imported {out.stdout.strip()}"
