"""Both websockets of the explorer (the page's and the 3-D view's) accept only their own origin.

Raw websocket clients claiming another ``Origin`` (as a foreign web page in the user's
browser would) are refused at the handshake. Loopback servers only.
"""

from __future__ import annotations

import asyncio
import re
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request

import pytest

import laav

pn = pytest.importorskip("panel")
websockets = pytest.importorskip("websockets")
pytest.importorskip("viser")

from explorer import cli  # noqa: E402
from explorer.viser_view import ViserView  # noqa: E402

EVIL = "http://evil.example"


def _try(url: str, origin: str | None, protocols: list[str]) -> str:
    """'accepted' (and a first message arrived) or 'refused <status>'."""
    async def go():
        try:
            async with websockets.connect(url, origin=origin, subprotocols=protocols,
                                          open_timeout=10) as ws:
                await asyncio.wait_for(ws.recv(), 10)
                return "accepted"
        except websockets.exceptions.InvalidStatus as exc:
            return f"refused {exc.response.status_code}"
    return asyncio.run(go())


def test_viser_websocket_accepts_only_its_own_page():
    view = ViserView(host="127.0.0.1")
    try:
        port, path = view.port, view.path.rstrip("/")
        url, proto = f"ws://127.0.0.1:{port}{path}", [f"viser-v{__import__('viser').__version__}"]
        assert _try(url, EVIL, proto) == "refused 403"
        assert _try(url, None, proto) == "refused 403"
        assert _try(url, "http://127.0.0.1:1", proto) == "refused 403"  # another local page
        assert _try(url, f"http://127.0.0.1:{port}", proto) == "accepted"
        assert _try(url, f"http://localhost:{port}", proto) == "accepted"
        assert _try(url + "/", f"http://127.0.0.1:{port}", proto) == "accepted"  # the page's own form
        assert urllib.request.urlopen(view.url()).status == 200  # the page itself
    finally:
        view.close()


def test_viser_view_answers_only_under_its_tabs_secret_path():
    """The 3-D view belongs to one tab: a client without its token (another tab, another
    program on this machine or the network, even with the right Origin) gets nothing."""
    import viser

    view = ViserView(host="127.0.0.1")
    other = ViserView(host="127.0.0.1")
    try:
        port, own = view.port, f"http://127.0.0.1:{view.port}"
        proto = [f"viser-v{viser.__version__}"]
        assert len(view.token) >= 32 and view.token != other.token
        for path in ("", "/", "/x", f"/{view.token[:-1]}", f"/{other.token}", f"/{view.token}/x",
                     f"/{view.token}x", f"/?{view.token}"):
            assert _try(f"ws://127.0.0.1:{port}{path}", own, proto) == "refused 403", path
        for path in ("/", "/index.html", f"/{other.token}/", f"/{view.token}", f"/x/{view.token}/",
                     f"/{view.token}x/"):
            with pytest.raises(urllib.error.HTTPError) as err:
                urllib.request.urlopen(f"{own}{path}", timeout=10)
            assert err.value.code == 404, path
        page = urllib.request.urlopen(view.url(), timeout=10).read()
        assert b"<html" in page.lower()
        assert _try(f"ws://127.0.0.1:{port}/{view.token}", own, proto) == "accepted"
    finally:
        view.close()
        other.close()


@pytest.mark.slow
def test_page_websocket_accepts_only_its_own_origin():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen([sys.executable, "-m", "explorer.cli", "--no-browser", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60
        while True:
            try:
                html = urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=5).read().decode()
                break
            except OSError:
                assert time.monotonic() < deadline and proc.poll() is None, "the server did not start"
                time.sleep(0.3)
        token = re.search(r'"token":\s*"([^"]+)"', html).group(1)
        url, proto = f"ws://127.0.0.1:{port}/ws", ["bokeh", token]
        assert _try(url, EVIL, proto) == "refused 403"
        assert _try(url, f"http://127.0.0.1:{port + 1}", proto) == "refused 403"
        assert _try(url, f"http://127.0.0.1:{port}", proto) == "accepted"
    finally:
        proc.terminate()
        out = proc.communicate(timeout=30)[0]
    assert "warning" not in out  # loopback: no network warning


def _fake_serve(monkeypatch):
    seen: dict = {}

    class Loop:
        def add_callback(self, fn):
            pass

        def start(self):
            pass

    class Server:
        io_loop = Loop()

        def start(self):
            pass

        def stop(self):
            pass

    def serve(panels, **kw):
        seen.update(kw)
        return Server()

    monkeypatch.setattr(pn, "serve", serve)
    return seen


@pytest.mark.parametrize("host", ["0.0.0.0", "192.0.2.7"])
def test_network_host_prints_url_and_warning_and_keeps_origins(monkeypatch, capsys, tmp_path, host):
    seen = _fake_serve(monkeypatch)
    monkeypatch.setattr(cli, "_port_free", lambda h, p: True)
    p = laav.save_sequence(laav.Sequence(__import__("numpy").random.default_rng(0).uniform(
        0, 500, (5, 30, 2)), name="s"), tmp_path / "s.npz")
    assert cli.main([str(p), "--motions", "2", "--no-browser", "--port", "5999", "--host", host]) == 0
    # a viser server an earlier test started may print "(viser) Server stopped" from its own
    # thread while this test captures: not this command's output
    out = [ln for ln in capsys.readouterr().out.splitlines() if not ln.startswith("(viser)")]
    assert re.search(r" at http://[^ ]+:5999/$", out[0])
    warn = [ln for ln in out if "warning" in ln]
    assert len(warn) == 1 and f"--host {host} opens the app to the network" in warn[0]
    origins = seen["websocket_origin"]
    assert "*" not in origins and all(o.endswith(":5999") for o in origins)
    if host != "0.0.0.0":
        assert f"{host}:5999" in origins
