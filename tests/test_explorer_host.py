"""``laav-explore --host 0.0.0.0``: the reachable URL, a warning, and a working page."""

from __future__ import annotations

import os
import re
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import pytest
from conftest import session_text, stop_process

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


def test_host_all_interfaces_prints_a_reachable_url_and_a_warning(tmp_path):
    port = _free_port()
    proc, log = _serve(tmp_path, "--host", "0.0.0.0", "--port", str(port))
    try:
        _page(proc, log, port)
        assert "demo_three_motions" in session_text(f"http://127.0.0.1:{port}/")
        out = log.read_text()
        url = next(ln for ln in out.splitlines() if ln.startswith("laav-explore: demo_three_motions"))
        assert f":{port}/" in url and "localhost" not in url and "0.0.0.0:" not in url
        assert "warning: --host 0.0.0.0 opens the app to the network" in out
        assert "3-D view is served on another free port" in out
        # a session (a script client, as a browser tab would) starts its 3-D view: its address
        import panel.models  # noqa: F401 - registers the models the client receives
        import panel.models.file_dropper  # noqa: F401 - the upload box (not in panel.models)
        from bokeh.client import pull_session

        with pull_session(url=f"http://127.0.0.1:{port}/"):
            deadline = time.monotonic() + 60
            while "3-D view is served at" not in log.read_text() and time.monotonic() < deadline:
                time.sleep(0.5)
        viser_line = next(ln for ln in log.read_text().splitlines() if "3-D view is served at" in ln)
        viser_port = int(re.search(r"served at http://[^ ]+:(\d+)/ ", viser_line).group(1))
        assert viser_port != port
        # it listens, but answers only under the tab's secret path (not printed)
        with pytest.raises(urllib.error.HTTPError) as err:
            urllib.request.urlopen(f"http://127.0.0.1:{viser_port}/", timeout=30)
        assert err.value.code == 404
    finally:
        stop_process(proc)


def test_default_host_prints_the_loopback_url_without_a_warning(tmp_path):
    import errno

    port = _free_port()
    proc, log = _serve(tmp_path, "--port", str(port))
    try:
        _page(proc, log, port)
        out = log.read_text()
        assert f"at http://127.0.0.1:{port}/" in out and "warning" not in out
        if _ipv6_loopback():  # [::1] at the page's port held (a browser tries localhost there)
            with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as other:
                with pytest.raises(OSError) as exc:
                    other.bind(("::1", port))
                assert exc.value.errno == errno.EADDRINUSE
    finally:
        stop_process(proc)


@pytest.mark.parametrize("host, loopback", [("127.0.0.1", True), ("::1", True), ("localhost", True),
                                            ("0.0.0.0", False), ("::", False), ("192.0.2.7", False)])
def test_which_hosts_are_this_machine_only(host, loopback):
    from explorer.cli import _is_loopback

    assert _is_loopback(host) is loopback


LOOP = frozenset({"127.0.0.1", "localhost"})


@pytest.mark.parametrize("page, configured, names, expect", [
    ("127.0.0.1", "127.0.0.1", LOOP, "localhost"),  # laav-explore's default
    ("localhost", "127.0.0.1", LOOP, "127.0.0.1"),
    ("127.0.0.1", None, LOOP, "localhost"),  # a wildcard bind, reached on the loopback
    ("127.0.0.1", "127.0.0.1", frozenset({"127.0.0.1"}), "127.0.0.1"),  # [::1] not held
    ("localhost", "localhost", frozenset(), "localhost"),  # bound to "localhost": as given
    ("192.0.2.7", None, frozenset(), "192.0.2.7"),  # reached from another machine
    ("::1", "::1", frozenset(), "::1"),
    (None, "127.0.0.1", LOOP, "127.0.0.1"),  # a notebook: the page's name unknown
    (None, None, LOOP, "127.0.0.1"),
])
def test_the_3d_iframe_is_another_site_than_a_loopback_page(page, configured, names, expect):
    """A page at one loopback name has the 3-D iframe at the other, where the 3-D server is
    safely reachable by it (a browser isolating sites renders it in its own process); else as
    configured, or the page's own name."""
    from explorer.cards.view3d import iframe_host

    assert iframe_host(page, configured, names) == expect


def _ipv6_loopback() -> bool:
    try:
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:
            s.bind(("::1", 0))
        return True
    except OSError:
        return False


@pytest.mark.skipif(not _ipv6_loopback(), reason="no IPv6 loopback here")
def test_the_3d_server_holds_its_port_on_the_ipv6_loopback():
    """A browser tries ``localhost`` at ::1 first: a 3-D server on 127.0.0.1 holds [::1] at
    its port (no other program can listen there for its secret address) and names
    ``localhost`` only then; an address taken already keeps it off."""
    import errno

    pytest.importorskip("viser")
    from explorer.loopback import hold_ipv6_loopback, netloc
    from explorer.viser_view import ViserView

    view = ViserView(host="127.0.0.1")
    try:
        assert view.loopback_names == {"127.0.0.1", "localhost"}
        # no other program can listen there, however it asks
        for opts in ((), (socket.SO_REUSEADDR,), (getattr(socket, "SO_REUSEPORT", None),)):
            with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as other:
                for opt in opts:
                    if opt is not None:
                        other.setsockopt(socket.SOL_SOCKET, opt, 1)
                with pytest.raises(OSError) as exc:
                    other.bind(("::1", view.port))
                    other.listen()
                assert exc.value.errno == errno.EADDRINUSE, opts
        with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as probe:  # refused at once
            assert probe.connect_ex(("::1", view.port)) == errno.ECONNREFUSED
    finally:
        view.close()
    with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as s:  # released on close
        s.bind(("::1", view.port))
    with socket.socket(socket.AF_INET6, socket.SOCK_STREAM) as taken:
        taken.bind(("::1", 0))
        taken.listen()
        assert hold_ipv6_loopback(taken.getsockname()[1]) == (None, False)
    assert netloc("::1", 80) == "[::1]:80" and netloc("localhost", 80) == "localhost:80"
    # a wildcard bind "" is 0.0.0.0's: one port, reachable at 127.0.0.1 as the iframe says
    view = ViserView(host="")
    try:
        assert view.loopback_names == {"127.0.0.1", "localhost"}
        with socket.create_connection(("127.0.0.1", view.port), timeout=5):
            pass
    finally:
        view.close()
