"""The client side of a USB/IP connection: where a server listens and how to reach it.

:class:`usbip.USBIP` (usbip 0.7.0) connects without ``TCP_NODELAY`` and without a timeout.
With Nagle's algorithm the client's URB (a 48-byte header, then its payload, in two sends)
waits for the peer's delayed ACK, about 40 ms per OUT transfer on loopback instead of ~0.1 ms
(``bench/bench_device_latency.py``). :class:`UsbipConnector` connects with both.
"""

from __future__ import annotations

import socket

DEFAULT_HOST = "127.0.0.1"
"""Address a USB/IP server binds and a client connects to by default."""
DEFAULT_PORT = 3240
"""The USB/IP port (IANA)."""
DEFAULT_BUSID = "1-1"
"""Bus ID of the first exported device."""
DEFAULT_CONNECT_TIMEOUT_S = 2.0
"""Longest wait for a TCP connection to a USB/IP server, s."""


def set_nodelay(sock: socket.socket, enabled: bool = True) -> None:
    """Set (or clear) ``TCP_NODELAY`` on a TCP socket; a no-op on other socket families."""
    if sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1 if enabled else 0)


class UsbipConnector:
    """Connects to one USB/IP server (what ``usbip.host`` calls a transport: an object with
    ``connect()``).

    Args:
        host, port: the server.
        nodelay: set ``TCP_NODELAY`` (only benchmarks turn it off).
        connect_timeout_s: longest wait for :meth:`connect`, s.
    """

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, *,
                 nodelay: bool = True,
                 connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S) -> None:
        self.host, self.port = host, port
        self.nodelay = nodelay
        self.connect_timeout_s = connect_timeout_s

    def connect(self) -> socket.socket:
        """A connected TCP socket to the server, ``TCP_NODELAY`` set, in blocking mode.

        Raises:
            OSError: refused, unreachable, or no answer within :attr:`connect_timeout_s`
                (``TimeoutError``).
        """
        sock = socket.create_connection((self.host, self.port), timeout=self.connect_timeout_s)
        set_nodelay(sock, self.nodelay)
        sock.settimeout(None)
        return sock
