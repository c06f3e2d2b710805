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
