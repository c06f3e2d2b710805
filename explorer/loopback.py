"""Loopback addresses: ``host:port`` with IPv6 brackets, and the IPv6 loopback held at a
port an IPv4 server listens on (no GUI imports; the command and the 3-D view use them).
"""

from __future__ import annotations

__all__ = ["netloc", "hold_ipv6_loopback", "IPV4_BINDS", "LOOPBACK_ALIAS"]

#: Binds that listen on IPv4 alone: ``[::1]`` at their port is left to anyone unless held
#: (:func:`hold_ipv6_loopback`), and both loopback names reach them once it is.
IPV4_BINDS = ("127.0.0.1", "0.0.0.0")
#: The other name of this machine's loopback interface, by the name a page was reached at.
LOOPBACK_ALIAS = {"127.0.0.1": "localhost", "localhost": "127.0.0.1"}


def netloc(host: str, port: int) -> str:
    """``host:port`` as in an address, an IPv6 literal in brackets (``[::1]:8080``)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def hold_ipv6_loopback(port: int):
    """``(socket, safe)``: ``[::1]:port`` bound by this process, not listening.

    A browser resolves ``localhost`` to ``::1`` first and tries ``127.0.0.1`` only when that
    fails. A server listening on IPv4 alone leaves ``[::1]`` at its port free for any program
    on the machine to listen on and receive what the browser sends (the page's session, the
    3-D view's secret address); held here, nothing else can bind it (no ``SO_REUSEADDR`` or
    ``SO_REUSEPORT``; ``SO_EXCLUSIVEADDRUSE`` on Windows), and a browser's connection there
    is refused at once, so it goes on to ``127.0.0.1``. ``safe`` is True when held, or when
    this machine has no IPv6 loopback (no program can listen there either); False (and no
    socket) when something holds it already or the bind fails otherwise."""
    import errno
    import socket

    try:
        sock = socket.socket(socket.AF_INET6, socket.SOCK_STREAM)
    except OSError:
        return None, True  # no IPv6 in this system
    try:
        if hasattr(socket, "SO_EXCLUSIVEADDRUSE"):  # Windows: no other bind, even with SO_REUSEADDR
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_EXCLUSIVEADDRUSE, 1)
        sock.bind(("::1", port))
    except OSError as exc:
        sock.close()
        return None, exc.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT)
    return sock, True
