"""The README's shell and Python blocks run verbatim, top to bottom.

Each ```bash / ```python block runs from a scratch folder laid out like the repository's
top (links to its folders, ``.venv`` linking to the environment running the tests), so
that what a block writes (``labels.csv``, ``bench-out/``) stays out of the tree; this
tree's code is used (``PYTHONPATH``). Blocks that use ``$HOPKINS155`` are skipped when the
data set is absent. A block right after ``<!-- readme-test: skip (REASON) -->`` is not run
(installing ``.venv``, serving the app until Ctrl-C, ``make test`` itself), and REASON is
reported.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"(?:<!-- readme-test: skip \((?P<skip>[^)]*)\) -->\n)?```(?P<lang>bash|python)\n"
                   r"(?P<code>.*?)```", re.S)


def _blocks() -> list:
    text = (REPO / "README.md").read_text()
    out = []
    for m in BLOCK.finditer(text):
        line = text.count("\n", 0, m.start("code"))
        out.append(pytest.param(m["lang"], m["code"], m["skip"], id=f"{m['lang']}-line{line}"))
    return out


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    wd = tmp_path_factory.mktemp("readme")
    for entry in REPO.iterdir():
        if entry.name not in (".git", ".venv", "bench-out"):
            (wd / entry.name).symlink_to(entry)
    (wd / ".venv").symlink_to(Path(sys.prefix))
    return wd


def _hopkins() -> Path | None:
    env = os.environ.get("HOPKINS155")
    root = Path(env).expanduser() if env else REPO.parent / "shared" / "data" / "hopkins155"
    return root if root.is_dir() and any(root.glob("*/*_truth.mat")) else None


def test_readme_has_runnable_blocks():
    blocks = _blocks()
    assert sum(1 for b in blocks if b.values[2] is None) >= 3
    assert "laav.preload()" in (REPO / "README.md").read_text()


@pytest.mark.slow
@pytest.mark.parametrize("lang, code, skip", _blocks())
def test_readme_block_runs(lang, code, skip, workdir):
    if skip:
        pytest.skip(f"marked in the README: {skip}")
    # as on a fresh machine: no virtual environment on PATH (the README says .venv/bin/...)
    path = [p for p in os.environ.get("PATH", "").split(os.pathsep)
            if p and not Path(p, "activate").is_file()]
    env = {**os.environ, "PYTHONPATH": str(REPO), "MPLBACKEND": "Agg", "PATH": os.pathsep.join(path)}
    env.pop("VIRTUAL_ENV", None)
    if "$HOPKINS155" in code:
        root = _hopkins()
        if root is None:
            pytest.skip("needs Hopkins155 ($HOPKINS155 or ../shared/data/hopkins155)")
        env["HOPKINS155"] = str(root)
    cmd = ["bash", "-euo", "pipefail", "-c", code] if lang == "bash" else [sys.executable, "-c", code]
    proc = subprocess.run(cmd, cwd=workdir, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, f"README block failed:\n{code}\n{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
