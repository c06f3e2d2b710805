"""``laav-explore --host 0.0.0.0``: the reachable URL, a warning, and a working page."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("0.0.0.0", 0))
        return s.getsockname()[1]


def _serve(tmp_path, *args):
    log = tmp_path / "server.log"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    with open(log, "w") as fh:
        proc = subprocess.Popen([sys.executable, "-m", "explorer.cli", "--no-browser", *args],
                                stdout=fh, stderr=subprocess.STDOUT, env=env, cwd=tmp_path)
    return proc, log


def _page(proc, log, port) -> str:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        assert proc.poll() is None, log.read_text()
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as r:
                return r.read().decode()
        except OSError:
            time.sleep(0.5)
    raise AssertionError(f"no page on port {port}:\n{log.read_text()}")


def _stop(proc):
    proc.terminate()
    try:
        proc.wait(30)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


def test_host_all_interfaces_prints_a_reachable_url_and_a_warning(tmp_path):
    port = _free_port()
    proc, log = _serve(tmp_path, "--host", "0.0.0.0", "--port", str(port))
    try:
        assert "demo_three_motions" in _page(proc, log, port)
        out = log.read_text()
        url = next(ln for ln in out.splitlines() if ln.startswith("laav-explore: demo_three_motions"))
        assert f":{port}/" in url and "localhost" not in url and "0.0.0.0:" not in url
        assert "warning: listening on 0.0.0.0, open to the network" in out
        assert "3-D view is served on another free port" in out
    finally:
        _stop(proc)


def test_default_host_prints_the_loopback_url_without_a_warning(tmp_path):
    port = _free_port()
    proc, log = _serve(tmp_path, "--port", str(port))
    try:
        _page(proc, log, port)
        out = log.read_text()
        assert f"at http://127.0.0.1:{port}/" in out and "warning" not in out
    finally:
        _stop(proc)
