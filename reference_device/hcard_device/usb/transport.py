"""USB/IP over TCP with ``TCP_NODELAY`` on every socket, timeouts, and a clean stop.

:class:`usbip.USBIP` (usbip 0.7.0) sets ``TCP_NODELAY`` on the sockets its server accepts but not
on the socket its client connects, has no connect timeout, and cannot close the connections it
serves. :class:`NoDelayUSBIP` fixes the three for the hcard device and its host drivers.

Why ``TCP_NODELAY`` matters: the USB/IP client sends a URB as a 48-byte header then its payload
in two ``sendall`` calls, and the server answers an IN URB the same way. With Nagle's algorithm
the second segment waits until the first is acknowledged, and the peer delays that ACK by about
40 ms (Linux delayed ACK), so every OUT transfer costs ~44 ms instead of ~0.1 ms on loopback
(``bench/bench_device_latency.py`` measures both). ``nodelay=False`` exists only for that
measurement.
"""

from __future__ import annotations

import contextlib
import socket
import threading
from typing import Any

import usbip
from usbip import protocol

DEFAULT_HOST = "127.0.0.1"
"""Loopback: the device is not exposed to the network unless asked."""
DEFAULT_PORT = 3240
"""The IANA port of USB/IP (what ``usbip attach`` uses)."""
DEFAULT_BUSID = "1-1"
"""Bus ID of the one device a server exports."""
DEFAULT_CONNECT_TIMEOUT_S = 2.0
"""Longest wait for a TCP connection to a USB/IP server, s."""


def set_nodelay(sock: socket.socket, enabled: bool = True) -> None:
    """Set (or clear) ``TCP_NODELAY`` on a TCP socket; a no-op on other socket families."""
    if sock.family in (socket.AF_INET, socket.AF_INET6):
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1 if enabled else 0)


class NoDelayUSBIP(usbip.USBIP):
    """A USB/IP transport (server and client side) with ``TCP_NODELAY`` and timeouts.

    Args:
        host: address to bind (server) or connect to (client).
        port: TCP port; 0 when serving binds a free port, readable from :attr:`port` after
            :meth:`serve`.
        nodelay: set ``TCP_NODELAY`` on every socket (only benchmarks turn it off).
        connect_timeout_s: longest wait for :meth:`connect`, s.

    One transport serves one device (bus ID ``1-1`` unless the device was given another).
    """

    host: str
    port: int

    def __init__(
        self,
        host: str = DEFAULT_HOST,
        port: int = DEFAULT_PORT,
        *,
        nodelay: bool = True,
        connect_timeout_s: float = DEFAULT_CONNECT_TIMEOUT_S,
    ) -> None:
        super().__init__(host, port)
        self.nodelay = nodelay
        self.connect_timeout_s = connect_timeout_s
        self._server: socket.socket | None = None
        self._connections: set[socket.socket] = set()
        self._lock = threading.Lock()
        self._device: Any = None

    # ------------------------------------------------------------------ server side

    def serve(self, dev: Any) -> None:
        """Bind, listen and serve ``dev`` (a :class:`usbip.USBDevice`) on a daemon thread.

        Raises:
            OSError: the address cannot be bound (in use, not local, ...).
        """
        if self._server is not None:
            raise RuntimeError("this transport already serves a device")
        if not getattr(dev, "busid", None):
            dev.busid = DEFAULT_BUSID
        dev.busnum, dev.devnum = 1, 2
        server = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            server.bind((self.host, self.port))
            server.listen(4)
        except OSError:
            server.close()
            raise
        self.port = server.getsockname()[1]
        self._server, self._device = server, dev
        threading.Thread(target=self._accept_loop, args=(server,), daemon=True,
                         name="usbip-accept").start()

    def _accept_loop(self, server: socket.socket) -> None:
        while True:
            try:
                conn, _addr = server.accept()
            except OSError:
                return  # closed by stop()
            set_nodelay(conn, self.nodelay)
            with self._lock:
                if self._server is None:
                    conn.close()
                    return
                self._connections.add(conn)
            threading.Thread(target=self._serve_one, args=(conn,), daemon=True,
                             name="usbip-conn").start()

    def _serve_one(self, conn: socket.socket) -> None:
        """Serve one connection; a device with ``connection_view`` (the hcard device) gives
        each connection its own view, so that every importer gets every input report."""
        factory = getattr(self._device, "connection_view", None)
        device = factory() if callable(factory) else self._device
        try:
            protocol.serve_connection(conn, [device])
        finally:
            close = getattr(device, "close", None) if device is not self._device else None
            if callable(close):
                close()
            with self._lock:
                self._connections.discard(conn)

    @property
    def connection_count(self) -> int:
        """Connections being served now (devlist requests included while they last)."""
        with self._lock:
            return len(self._connections)

    def stop(self, dev: Any = None) -> None:
        """Stop listening and close every served connection (clients see end of stream)."""
        with self._lock:
            server, self._server = self._server, None
            connections, self._connections = list(self._connections), set()
        if server is not None:
            # shutdown() wakes the thread blocked in accept(); close() alone would leave the
            # kernel socket listening until that accept() returns.
            with contextlib.suppress(OSError):
                server.shutdown(socket.SHUT_RDWR)
            server.close()
        for conn in connections:
            with contextlib.suppress(OSError):
                conn.shutdown(socket.SHUT_RDWR)
            conn.close()

    # ------------------------------------------------------------------ client side

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
