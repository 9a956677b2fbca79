"""USB/IP over TCP with ``TCP_NODELAY`` on every socket, timeouts, bounded connections and a
clean stop.

:class:`usbip.USBIP` (usbip 0.7.0) sets ``TCP_NODELAY`` on the sockets its server accepts but not
on the socket its client connects, has no connect timeout, cannot close the connections it
serves, and serves each with ``usbip.protocol.serve_connection``, which trusts the client (see
:mod:`hcard_device.usb.connection`). :class:`NoDelayUSBIP` fixes these for the hcard device and
its host drivers; :class:`BoundedLoopback` serves the same way over in-process socket pairs.

Bounds of a server (spec/device-protocol.md section 13): at most :data:`MAX_CONNECTIONS`
connections at once (handshakes included); a further one is closed as soon as it is accepted,
and logged; at most :data:`ACCEPT_RATE_HZ` connections are accepted per second. Each
connection is bounded by
:class:`~hcard_device.usb.connection.ConnectionLimits`. The log
(:mod:`~hcard_device.usb.server_log`) never blocks the server.

Why ``TCP_NODELAY`` matters: the USB/IP client sends a URB as a 48-byte header then its payload
in two ``sendall`` calls, and the server answers an IN URB the same way. With Nagle's algorithm
the second segment waits until the first is acknowledged, and the peer delays that ACK by about
40 ms (Linux delayed ACK), so every OUT transfer costs ~44 ms instead of ~0.1 ms on loopback
(``bench/bench_device_latency.py`` measures both). ``nodelay=False`` exists only for that
measurement.
"""

from __future__ import annotations

import contextlib
import itertools
import socket
import threading
import time
from collections.abc import Callable
from typing import Any

import usbip

from hcard.device.transports.usbip_connect import (
    DEFAULT_BUSID,
    DEFAULT_CONNECT_TIMEOUT_S,
    DEFAULT_HOST,
    DEFAULT_PORT,
    UsbipConnector,
    set_nodelay,
)
from hcard_device.usb.connection import DEFAULT_LIMITS, Connection, ConnectionLimits
from hcard_device.usb.server_log import DEFAULT_LOG

MAX_CONNECTIONS = 8
"""Connections one server serves at once (import handshakes and device lists included); a
further one is closed when accepted (spec/device-protocol.md section 13)."""
ACCEPT_RATE_HZ = 50.0
"""New connections accepted per second at most (after a burst of :data:`ACCEPT_BURST`): a
client that reconnects as fast as it is closed costs the server at most this many handshakes
a second; the others wait in the kernel's listen backlog."""
ACCEPT_BURST = 16
"""Connections accepted at once before :data:`ACCEPT_RATE_HZ` applies."""


class ConnectionTable:
    """The connections one server serves: at most ``max_connections``, numbered from 1 (the
    ``origin`` of their requests, spec rule PN12), each on its own daemon thread.

    Args:
        max_connections: connections served at once.
        limits: the bounds of each connection.
        log: writes one line to the server's log.
    """

    connection_class: type[Connection] = Connection
    """What serves each connection (a negative control serves them otherwise:
    :mod:`hcard_device.served_controls`)."""

    def __init__(self, *, max_connections: int = MAX_CONNECTIONS,
                 limits: ConnectionLimits = DEFAULT_LIMITS,
                 log: Callable[[str], None] = DEFAULT_LOG) -> None:
        if max_connections < 1:
            raise ValueError(f"max_connections must be >= 1, got {max_connections}")
        self.max_connections = max_connections
        self.limits = limits
        self.log = log
        self.device: Any = None
        self.refused = 0
        self._numbers = itertools.count(1)
        self._connections: dict[int, Connection] = {}
        self._lock = threading.Lock()
        self._stopped = False

    def serve(self, sock: socket.socket, peer: str) -> bool:
        """Serve ``sock`` on a new thread; False (and ``sock`` closed) when the server is
        stopped or full."""
        with self._lock:
            stopped, full = self._stopped, len(self._connections) >= self.max_connections
            if not (stopped or full):
                connection = self.connection_class(sock, next(self._numbers), peer,
                                                   limits=self.limits, log=self.log)
                self._connections[connection.number] = connection
            elif not stopped:
                self.refused += 1
        if stopped or full:
            with contextlib.suppress(OSError):
                sock.close()
            if not stopped:
                self.log(f"refused a connection from {peer}: {self.max_connections} "
                         "connections are served already")
            return False
        threading.Thread(target=self._run, args=(connection,), daemon=True,
                         name=f"usbip-conn-{connection.number}").start()
        return True

    def _run(self, connection: Connection) -> None:
        device = self.device
        try:
            connection.serve([device], device.connection_view)
        finally:
            with self._lock:
                self._connections.pop(connection.number, None)

    @property
    def connections(self) -> list[Connection]:
        """The connections served now."""
        with self._lock:
            return list(self._connections.values())

    def stop(self) -> None:
        """Close every connection (clients see end of stream) and refuse new ones."""
        with self._lock:
            self._stopped = True
            connections = list(self._connections.values())
        for connection in connections:
            connection.close("")


class NoDelayUSBIP(usbip.USBIP):
    """A USB/IP transport (server and client side) with ``TCP_NODELAY``, timeouts and bounds.

    Args:
        host: address to bind (server) or connect to (client).
        port: TCP port; 0 when serving binds a free port, readable from :attr:`port` after
            :meth:`serve`.
        nodelay: set ``TCP_NODELAY`` on every socket (only benchmarks turn it off).
        connect_timeout_s: longest wait for :meth:`connect`, s.
        max_connections: connections served at once (:data:`MAX_CONNECTIONS`).
        limits: the bounds of each served connection.
        log: the server's log (one line per call).

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
        max_connections: int = MAX_CONNECTIONS,
        limits: ConnectionLimits = DEFAULT_LIMITS,
        log: Callable[[str], None] = DEFAULT_LOG,
    ) -> None:
        super().__init__(host, port)
        self.nodelay = nodelay
        self.connect_timeout_s = connect_timeout_s
        self.table = ConnectionTable(max_connections=max_connections, limits=limits, log=log)
        self._server: socket.socket | None = None

    # ------------------------------------------------------------------ server side

    def serve(self, dev: Any) -> None:
        """Bind, listen and serve ``dev`` (a :class:`usbip.USBDevice` with a
        ``connection_view``) on a daemon thread.

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
            server.listen(16)
        except OSError:
            server.close()
            raise
        self.port = server.getsockname()[1]
        self._server, self.table.device = server, dev
        threading.Thread(target=self._accept_loop, args=(server,), daemon=True,
                         name="usbip-accept").start()

    def _accept_loop(self, server: socket.socket) -> None:
        tokens, refilled = float(ACCEPT_BURST), time.monotonic()
        while True:
            now = time.monotonic()
            tokens = min(tokens + (now - refilled) * ACCEPT_RATE_HZ, float(ACCEPT_BURST))
            refilled = now
            if tokens < 1.0:
                time.sleep((1.0 - tokens) / ACCEPT_RATE_HZ)
                continue
            tokens -= 1.0
            try:
                conn, addr = server.accept()
            except OSError:
                if self._server is not server:
                    return  # closed by stop()
                time.sleep(0.01)  # e.g. out of file descriptors: try again, never spin
                continue
            try:
                set_nodelay(conn, self.nodelay)  # fails on a connection already reset
                self.table.serve(conn, f"{addr[0]}:{addr[1]}")
            except (OSError, RuntimeError) as exc:  # RuntimeError: no thread to be had
                self.table.log(f"dropped a connection from {addr[0]}:{addr[1]} ({exc})")
                with contextlib.suppress(OSError):
                    conn.close()

    @property
    def connections(self) -> list[Connection]:
        """The connections served now."""
        return self.table.connections

    @property
    def connection_count(self) -> int:
        """Connections being served now (devlist requests included while they last)."""
        return len(self.table.connections)

    def stop(self, dev: Any = None) -> None:
        """Stop listening and close every served connection (clients see end of stream)."""
        server, self._server = self._server, None
        if server is not None:
            # shutdown() wakes the thread blocked in accept(); close() alone would leave the
            # kernel socket listening until that accept() returns.
            with contextlib.suppress(OSError):
                server.shutdown(socket.SHUT_RDWR)
            server.close()
        self.table.stop()

    # ------------------------------------------------------------------ client side

    def connect(self) -> socket.socket:
        """A connected TCP socket to the server (:meth:`UsbipConnector.connect`)."""
        return UsbipConnector(self.host, self.port, nodelay=self.nodelay,
                              connect_timeout_s=self.connect_timeout_s).connect()


class BoundedLoopback(usbip.Loopback):
    """Device and host in one process over socket pairs, each served as a bounded
    :class:`~hcard_device.usb.connection.Connection` (the same code and bounds as TCP).

    Args:
        max_connections, limits, log: as :class:`NoDelayUSBIP`.
    """

    def __init__(self, *, max_connections: int = MAX_CONNECTIONS,
                 limits: ConnectionLimits = DEFAULT_LIMITS,
                 log: Callable[[str], None] = DEFAULT_LOG) -> None:
        super().__init__()
        self.table = ConnectionTable(max_connections=max_connections, limits=limits, log=log)

    def serve(self, dev: Any) -> None:
        """Serve ``dev`` to every :meth:`connect` from now on."""
        if not getattr(dev, "busid", None):
            dev.busid = DEFAULT_BUSID
        dev.busnum, dev.devnum = 1, 2
        self.table.device = dev

    def connect(self) -> socket.socket:
        """The host end of a new socket pair whose device end is served.

        Raises:
            OSError: the server is stopped or full (the host end is closed: end of stream).
        """
        device_end, host_end = socket.socketpair()
        self.table.serve(device_end, "loopback")
        return host_end

    @property
    def connections(self) -> list[Connection]:
        """The connections served now."""
        return self.table.connections

    def stop(self, dev: Any = None) -> None:
        """Close every connection."""
        self.table.stop()
