"""The device ``device.host-driver`` connects the implementation's driver class to: a device
simulated in this process, altered per case, that records every request the driver sends
(spec/conformance.md 4.10).

A driver of the hcard host library is a subclass of :class:`hcard.device.base.Driver` that
supplies the transport (five primitives: write an output report, SET and GET a feature report,
read an input report, close); everything above it (DEVICE_INFO and the version check, decoding
input reports, sessions) is the protocol logic the host rules bind (PV2, PV3, PE4, PN8). The
check opens the implementation's driver as every device check does, notes its class and the
attributes it was opened with, and closes it; per case it then makes an instance of a subclass
of that class (:func:`on_scripted_device`) whose transport primitives and time base
(``clock()``, ``_idle()``, ``collect_until()``) are a :class:`ScriptedDevice`'s, with the
protocol state of a fresh driver. The driver's own protocol logic runs unchanged.

The scripted device is the device simulated in this process (``sim://``: the host library asks
the driver plugin of the scheme ``sim`` for it, :mod:`hcard.device.in_process`), reached through
its driver's transport primitives and run on its clock (device time, s), so what the driver
does is judged in device time, the same on a loaded machine. Per case it answers DEVICE_INFO
with another protocol version, appends bytes to every STATE report, puts an undecodable report
before the next one, answers one GET with too few bytes, or shows another host's session, fed
by that host's KEEPALIVEs or left to end (PN7).
"""

from __future__ import annotations

import dataclasses
import functools
from collections import deque
from dataclasses import dataclass
from typing import Any, cast

from hcard.device.base import Driver
from hcard.device.protocol import Command, Control, DeviceInfo, ReportId, State
from hcard.errors import HcardError
from hcard_conformance.context import Context
from hcard_conformance.result import CannotAssess
from hcard_conformance.wire_protocol import speaks_wire_protocol

SIMULATED_URI = "sim://"
"""The device simulated in this process that every case scripts (the E-ViTa: HOST_FINGER,
protocol 1.4)."""
FEED_PERIOD_S = 0.02
"""Another host's KEEPALIVE period while its session is fed, s (a 50 Hz host: five per
``watchdog_ms`` of the reference device)."""
GRANT_WAIT_S = 0.1
"""Longest device time the other host waits for its session to be granted, s."""
HOST_DRIVER_KEY = "host-driver"
"""``Context.cache`` key: whether the implementation's driver is an hcard
:class:`~hcard.device.base.Driver` (asked once per run)."""


@dataclass(frozen=True)
class Request:
    """One request the driver under test sent.

    Attributes:
        t_s: device time it was sent, s.
        kind: ``output`` (interrupt OUT), ``set`` or ``get`` (feature report).
        data: the report's bytes (for a GET: the report ID).
    """

    t_s: float
    kind: str
    data: bytes

    @property
    def changes_device(self) -> bool:
        """A request that changes the device (PN8): a SET of a feature report, or an output
        report other than CONTROL KEEPALIVE."""
        if self.kind == "set":
            return True
        if self.kind != "output":
            return False
        keepalive = len(self.data) >= 2 and self.data[0] == ReportId.CONTROL \
            and self.data[1] == Command.KEEPALIVE
        return not keepalive

    def text(self) -> str:
        """``OUTPUT 0x12``, ``SET 0x21``, ``GET 0x20`` at its time, for a detail line."""
        return f"{self.kind.upper()} 0x{self.data[0]:02X} at {self.t_s * 1000:.0f} ms" \
            if self.data else f"{self.kind.upper()} (empty) at {self.t_s * 1000:.0f} ms"


@dataclass
class OtherHost:
    """Another host's session on the scripted device (PN8's "live session it does not own").

    Attributes:
        token: its session token.
        number: its ``session_number``.
        fed: its host sends KEEPALIVEs every :data:`FEED_PERIOD_S` (it is alive); False: its
            host is gone and the device ends the session after ``watchdog_ms`` (PN7).
        next_feed_s: device time of its next KEEPALIVE, s.
    """

    token: int
    number: int
    fed: bool
    next_feed_s: float


class ScriptedDevice:
    """The simulated device as the driver under test sees it (module docstring).

    Attributes:
        device: the open driver of the simulated device, whose transport primitives and clock
            carry the driver's requests.
        requests: every request the driver under test sent, in order.
        delivered: (device time, bytes) of every input report handed to the driver.
        version: (major, minor) DEVICE_INFO says; None: the device's own.
        appended: bytes appended to every STATE report (fields of a later minor, PV4).
        other: another host's session, once :meth:`begin_other_session` began one.
    """

    def __init__(self, device: Driver) -> None:
        self.device = device
        self.requests: list[Request] = []
        self.delivered: list[tuple[float, bytes]] = []
        self.version: tuple[int, int] | None = None
        self.appended = b""
        self.other: OtherHost | None = None
        self._injected: deque[bytes] = deque()
        self._short_answers: dict[int, int] = {}

    @classmethod
    def open(cls) -> ScriptedDevice:
        """A fresh simulated device (:data:`SIMULATED_URI`), through the driver plugins.

        Raises:
            CannotAssess: no driver plugin provides a device simulated in this process.
        """
        from hcard.device.open import open_device

        try:
            return cls(open_device(SIMULATED_URI))
        except HcardError as exc:
            raise CannotAssess(f"no device simulated in this process to connect the driver to "
                               f"({exc})") from None

    def info(self) -> DeviceInfo:
        """The simulated device's own DEVICE_INFO (read by the suite, not recorded)."""
        return DeviceInfo.decode(self.device._get_feature(ReportId.DEVICE_INFO,
                                                          DeviceInfo.size()))

    # ---- what a case scripts ---------------------------------------------------------------

    def inject(self, data: bytes) -> None:
        """Hand ``data`` to the driver as its next input report, before the device's next."""
        self._injected.append(bytes(data))

    def answer_short(self, report_id: int, size: int) -> None:
        """Answer the next GET of ``report_id`` with its first ``size`` bytes only."""
        self._short_answers[report_id] = size

    def begin_other_session(self, token: int, earlier: int, *, fed: bool) -> State:
        """Another host begins and ends ``earlier`` sessions with ``token``, then begins one
        more and keeps it (fed, or left silent: ``fed``); returns the STATE report granting it.
        The reports read meanwhile are that host's, not handed to the driver under test.

        Raises:
            RuntimeError: the device granted no session within :data:`GRANT_WAIT_S`.
        """
        for _ in range(earlier):
            self.device._write_output(Control(int(Command.START), token).encode())
            self.device._write_output(Control(int(Command.STOP), token).encode())
        self.device._write_output(Control(int(Command.START), token).encode())
        deadline = self.device.clock() + GRANT_WAIT_S
        while self.device.clock() < deadline:
            data = self.device._read_input(deadline - self.device.clock())
            if data is None:
                continue
            state = State.decode(data)
            if state.session_live and state.session_token == token:
                self.other = OtherHost(token, state.session_number, fed,
                                       self.device.clock() + FEED_PERIOD_S)
                return state
        raise RuntimeError(f"the simulated device granted no session to token {token} within "
                           f"{GRANT_WAIT_S * 1000:.0f} ms")

    # ---- the transport primitives and time base of the driver under test -------------------

    def write_output(self, report: bytes) -> None:
        """The driver's output report: recorded, then carried to the device."""
        self._tick()
        self.requests.append(Request(self.clock(), "output", bytes(report)))
        self.device._write_output(report)

    def set_feature(self, report: bytes) -> None:
        """The driver's SET_REPORT(Feature): recorded, then carried (a STALL raises as the
        device's driver raises it)."""
        self._tick()
        self.requests.append(Request(self.clock(), "set", bytes(report)))
        self.device._set_feature(report)

    def get_feature(self, report_id: int, size: int) -> bytes:
        """The driver's GET_REPORT(Feature): recorded; the device's answer, altered as the
        case scripts (DEVICE_INFO's version, a short answer)."""
        self._tick()
        self.requests.append(Request(self.clock(), "get", bytes([report_id & 0xFF])))
        data = self.device._get_feature(report_id, size)
        if report_id == ReportId.DEVICE_INFO and self.version is not None:
            info = DeviceInfo.decode(data)
            data = dataclasses.replace(info, protocol_major=self.version[0],
                                       protocol_minor=self.version[1]).encode()
        if report_id in self._short_answers:
            data = data[:self._short_answers.pop(report_id)]
        return data

    def read_input(self, timeout_s: float) -> bytes | None:
        """The next input report for the driver (an injected one first), waiting up to
        ``timeout_s`` of device time; STATE reports with :attr:`appended`."""
        self._tick()
        if self._injected:
            data: bytes | None = self._injected.popleft()
        else:
            data = self.device._read_input(timeout_s)
            self._tick()
            if data is None:
                return None
            self._watch(data)
            if data[:1] == bytes([ReportId.STATE]):
                data += self.appended
        assert data is not None
        self.delivered.append((self.clock(), data))
        return data

    def clock(self) -> float:
        """Device time, s."""
        return self.device.clock()

    def idle(self, seconds: float) -> None:
        """Let ``seconds`` of device time pass (the other host feeding its session)."""
        end = self.clock() + max(seconds, 0.0)
        while self.clock() < end - 1e-12:
            self.device._idle(min(end - self.clock(), FEED_PERIOD_S / 4))
            self._tick()

    def close(self) -> None:
        """Close the simulated device."""
        self.device.close()

    # ---- the other host ---------------------------------------------------------------------

    def _tick(self) -> None:
        """The other host feeds its live session when a KEEPALIVE is due."""
        other = self.other
        while other is not None and other.fed and self.clock() >= other.next_feed_s:
            self.device._write_output(Control(int(Command.KEEPALIVE)).encode())
            other.next_feed_s += FEED_PERIOD_S

    def _watch(self, data: bytes) -> None:
        """The other host stops feeding once a report shows its session gone (PN9)."""
        other = self.other
        if other is None or not other.fed or data[:1] != bytes([ReportId.STATE]):
            return
        state = State.decode(data)
        if state.session_number != other.number or not state.session_live:
            other.fed = False

    def requests_since(self, first: int, *, changing: bool = False) -> list[Request]:
        """The requests from index ``first`` on (only those changing the device: ``changing``)."""
        return [r for r in self.requests[first:] if r.changes_device or not changing]


class ScriptedTransport:
    """Placed before the implementation's driver class: its transport primitives and time base
    are the :class:`ScriptedDevice` in ``_hcard_scripted_device``."""

    _hcard_scripted_device: ScriptedDevice

    def _write_output(self, report: bytes) -> None:
        self._hcard_scripted_device.write_output(report)

    def _set_feature(self, report: bytes) -> None:
        self._hcard_scripted_device.set_feature(report)

    def _get_feature(self, report_id: int, size: int) -> bytes:
        return self._hcard_scripted_device.get_feature(report_id, size)

    def _read_input(self, timeout_s: float) -> bytes | None:
        return self._hcard_scripted_device.read_input(timeout_s)

    def _close(self) -> None:
        self._hcard_scripted_device.close()

    def clock(self) -> float:
        """The scripted device's time, s."""
        return self._hcard_scripted_device.clock()

    def _idle(self, seconds: float) -> None:
        self._hcard_scripted_device.idle(seconds)

    def collect_until(self, t_s: float) -> list[State]:
        """The base class's :meth:`~hcard.device.base.Driver.collect_until` (a simulator's
        driver ties its own to its device)."""
        return Driver.collect_until(cast(Driver, self), t_s)


@functools.cache
def scripted_class(cls: type[Driver]) -> type[Driver]:
    """``cls`` with :class:`ScriptedTransport` before it (made once per class)."""
    made: type[Driver] = type(f"{cls.__name__}OnScriptedDevice", (ScriptedTransport, cls), {})
    return made


@dataclass
class DriverTemplate:
    """The implementation's driver class and the attributes an instance of it was opened with.

    Attributes:
        cls: the driver class.
        attributes: the instance's attributes as opened (its own, beside the protocol state).
        uri: the URI it was opened with.
        timeout_s: its transfer timeout, s (device time on the scripted device).
    """

    cls: type[Driver]
    attributes: dict[str, Any]
    uri: Any
    timeout_s: float

    @classmethod
    def of(cls, driver: Driver) -> DriverTemplate:
        """The template of an opened driver (read before it is closed)."""
        return cls(type(driver), dict(vars(driver)), driver.uri, driver.timeout_s)

    def connect(self, device: ScriptedDevice) -> Driver:
        """A fresh driver of the class on ``device`` (module docstring)."""
        return on_scripted_device(self, device)


def on_scripted_device(template: DriverTemplate, device: ScriptedDevice) -> Driver:
    """An instance of :func:`scripted_class` of the template's class: the attributes it was
    opened with, the protocol state of a fresh :class:`~hcard.device.base.Driver`, and
    ``device`` as its transport and time base."""
    made = scripted_class(template.cls)
    driver = made.__new__(made)
    vars(driver).update(template.attributes)
    Driver.__init__(driver, template.uri, timeout_s=template.timeout_s)
    driver._hcard_scripted_device = device  # type: ignore[attr-defined]
    return driver


def judges_host_driver(ctx: Context) -> bool:
    """Applicability of ``device.host-driver``: the implementation's driver is an hcard
    :class:`~hcard.device.base.Driver` that speaks the wire protocol itself (not one rendering
    on the host, whose protocol is the host library's own bookkeeping with no transport under
    it, :mod:`hcard_conformance.wire_protocol`); a driver that cannot be opened counts as one
    (the check then reports the error)."""
    if not speaks_wire_protocol(ctx):
        return False
    assert ctx.open_driver is not None
    if HOST_DRIVER_KEY not in ctx.cache:
        try:
            with ctx.open_driver() as driver:
                ctx.cache[HOST_DRIVER_KEY] = isinstance(driver, Driver)
        except Exception:  # the check reports why it cannot be opened
            return True
    return bool(ctx.cache[HOST_DRIVER_KEY])
