"""Negative controls served over USB/IP in this process, for checks that need two hosts on one
device (``device.session-ownership``): two drivers opened on ``sim://`` reach two devices,
two opened on one USB/IP server reach the same one, each over a connection of its own.

``no-ownership``
    The E-ViTa with the behaviour before protocol 1.2 (it reports protocol 1.1): START and STOP
    ignore their argument, STATE names no session, TAKE_OVER is refused as unknown, and a
    second host's START or upload is carried out under the first host's session (spec rules
    PN1-PN6 broken). Served in this process on 127.0.0.1 (a free port, real time) while any
    driver of it is open: every :func:`open_no_ownership` is one more client of that one
    device, and the server stops (the device powers off) when the last one closes.
``no-attribution``
    The E-ViTa with protocol 1.4 sessions, served the same way, whose firmware is not told
    which connection a request came from (as over one USB HID bus): sessions are kept by token
    alone, attributed to no connection (spec rule PN12 broken), so another connection's
    requests that change the device are carried out under the owner's session, and its
    KEEPALIVEs feed the watchdog and keep a silent owner's session alive (PN13 broken). Its
    pipes are still per connection (PN14 holds).
``shared-halts``
    The E-ViTa served the same way, whose interrupt-OUT endpoint has one halt for every
    connection, as a device on one bus has (spec rule PN14 broken): a connection's
    SET_FEATURE(ENDPOINT_HALT) STALLs every connection's output reports, the session owner's
    included, GET_STATUS shows it to all, and any connection's SET_CONFIGURATION clears it.
    Sessions are attributed to connections as the reference's are (PN12, PN13 hold).
``blocking-writes``
    The E-ViTa served the same way, whose connections serve URBs as usbip 0.7.0's
    ``serve_connection`` did (spec rule PN15 broken): every interrupt-IN URB a client sends is
    parked, and each answer is written with a send that waits until the client has taken it.
    The firmware's pump completes every connection's parked IN URBs, so a client that parks IN
    URBs and stops reading stops the STATE stream of every connection once its socket is full.
    Sessions, pipes and the other bounds are the reference's.
"""

from __future__ import annotations

import dataclasses
import select
import socket
import sys
import threading
from typing import Any

from hcard.device.protocol import Command, DeviceInfo
from hcard.device.transports.usbip_client import UsbipDriver
from hcard_device.firmware import Firmware
from hcard_device.usb.connection import DEFAULT_LIMITS, Connection, ConnectionLimits
from hcard_device.usb.device import ConnectionView, HcardHID
from hcard_device.usb.server import SWITCH_INTERVAL_S, DeviceServer, make_firmware

_servers: dict[str, DeviceServer] = {}
_clients: dict[str, int] = {}
_lock = threading.Lock()


class NoOwnershipFirmware(Firmware):
    """Firmware without sessions: protocol 1.1 behaviour (see the module docstring)."""

    def device_info(self) -> DeviceInfo:
        """DEVICE_INFO of a protocol 1.1 device."""
        return dataclasses.replace(super().device_info(), protocol_minor=1)

    def _session_command(self, command: int, token: int, origin: object | None = None) -> bool:
        """START and STOP whatever the token (no session ever begins); TAKE_OVER refused."""
        if command == Command.TAKE_OVER:
            return False
        if command == Command.STOP:
            self.sim.stop()
        else:
            self.sim.start()
        return True


class NoAttributionFirmware(Firmware):
    """Firmware that is not told the connection of a request (see the module docstring)."""

    def get_feature(self, report_id: int, origin: object | None = None) -> bytes:
        """GET_REPORT(Feature), whichever connection asks (``origin`` dropped)."""
        return super().get_feature(report_id)

    def set_feature(self, data: bytes, origin: object | None = None) -> None:
        """SET_REPORT(Feature), whichever connection asks (``origin`` dropped)."""
        super().set_feature(data)

    def handle_output(self, data: bytes, origin: object | None = None) -> None:
        """An output report, whichever connection sent it (``origin`` dropped)."""
        super().handle_output(data)


class _OneHalt:
    """The one halt of the ``shared-halts`` device's interrupt-OUT endpoint."""

    out_halted = False


class SharedHaltView(ConnectionView):
    """A connection's view of the ``shared-halts`` device: its OUT halt is every
    connection's (see the module docstring)."""

    def __init__(self, device: Any, interface: HcardHID, connection: Connection,
                 halt: _OneHalt) -> None:
        self._halt = halt
        super().__init__(device, interface, connection)

    @property
    def out_halted(self) -> bool:
        """The device's one OUT halt."""
        return self._halt.out_halted

    @out_halted.setter
    def out_halted(self, halted: bool) -> None:
        self._halt.out_halted = halted


class SharedHaltServer(DeviceServer):
    """The reference server whose connections share one OUT halt (``shared-halts``)."""

    def start(self) -> DeviceServer:
        """Start as the reference does, each connection then seeing the one halt."""
        started = super().start()
        device, interface, halt = self.usb_device, self.interface, _OneHalt()
        assert device is not None and interface is not None
        device.connection_view = (  # before any client: the server was just started
            lambda _device, connection: SharedHaltView(device, interface, connection, halt))
        return started


class BlockingWritesConnection(Connection):
    """A connection whose answers wait until the client takes them (``blocking-writes``, see
    the module docstring): nothing is buffered, and the thread that completed the URB (the
    pump, for STATE reports) waits on the client's socket; it parks every IN URB."""

    WAIT_S = 0.1
    """Longest single wait for the socket to take more, s (the wait goes on after it)."""

    def __init__(self, sock: socket.socket, number: int, peer: str, *,
                 limits: ConnectionLimits = DEFAULT_LIMITS, **kwargs: Any) -> None:
        super().__init__(sock, number, peer, **kwargs,
                         limits=dataclasses.replace(limits, max_parked_in_urbs=sys.maxsize))

    def send(self, data: bytes) -> None:
        """Write ``data`` whole, waiting for the client as long as it does not read."""
        with self._out_lock:
            view = memoryview(data)
            while view and not self._closed.is_set():
                try:
                    view = view[self.sock.send(view, socket.MSG_DONTWAIT):]
                except (BlockingIOError, InterruptedError):
                    select.select([], [self.sock], [], self.WAIT_S)
                except OSError as exc:
                    self._close_locked(f"socket error while sending ({exc})")


class BlockingWritesServer(DeviceServer):
    """The reference server whose connections wait on their clients (``blocking-writes``)."""

    def start(self) -> DeviceServer:
        """Start as the reference does, each connection then a
        :class:`BlockingWritesConnection`."""
        self.transport.table.connection_class = BlockingWritesConnection  # before any client
        return super().start()


def _no_ownership_firmware() -> Firmware:
    base = make_firmware("evita")
    return NoOwnershipFirmware(base.sim)


def _no_attribution_firmware() -> Firmware:
    base = make_firmware("evita")
    return NoAttributionFirmware(base.sim)


_FACTORIES = {"no-ownership": _no_ownership_firmware,
              "no-attribution": _no_attribution_firmware,
              "shared-halts": lambda: make_firmware("evita"),
              "blocking-writes": lambda: make_firmware("evita")}
_SERVERS: dict[str, type[DeviceServer]] = {"shared-halts": SharedHaltServer,
                                           "blocking-writes": BlockingWritesServer}


class ServedControlDriver(UsbipDriver):
    """A USB/IP client of a served control; closing the last one stops its server."""

    control = ""

    def _close(self) -> None:
        try:
            super()._close()
        finally:
            release(self.control)


def lease(name: str) -> DeviceServer:
    """The in-process server of control ``name``, started when it has no client yet; the
    caller is one more client until :func:`release`."""
    with _lock:
        server = _servers.get(name)
        if server is None or server.stopped:
            sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
            server = _SERVERS.get(name, DeviceServer)(
                "evita", port=0, firmware_factory=_FACTORIES[name]).start()
            _servers[name], _clients[name] = server, 0
        _clients[name] += 1
        return server


def release(name: str) -> None:
    """One client of control ``name`` is gone; the last one stops the server."""
    with _lock:
        _clients[name] = max(_clients.get(name, 0) - 1, 0)
        server = _servers.get(name) if _clients[name] == 0 else None
        if server is not None:
            del _servers[name]
    if server is not None:
        server.stop()


def open_served(name: str) -> ServedControlDriver:
    """A new USB/IP client of the served control ``name`` (one device while any is open)."""
    server = lease(name)
    try:
        driver = ServedControlDriver.open(server.uri)
        assert isinstance(driver, ServedControlDriver)  # open() makes an instance of cls
    except BaseException:
        release(name)
        raise
    driver.control = name
    return driver


def open_no_ownership() -> ServedControlDriver:
    """A new USB/IP client of the ``no-ownership`` device (one device while any is open)."""
    return open_served("no-ownership")


def open_no_attribution() -> ServedControlDriver:
    """A new USB/IP client of the ``no-attribution`` device (one device while any is open)."""
    return open_served("no-attribution")


def open_shared_halts() -> ServedControlDriver:
    """A new USB/IP client of the ``shared-halts`` device (one device while any is open)."""
    return open_served("shared-halts")


def open_blocking_writes() -> ServedControlDriver:
    """A new USB/IP client of the ``blocking-writes`` device (one device while any is open)."""
    return open_served("blocking-writes")
