"""The host driver base class: one protocol codec shared by every transport.

A :class:`Driver` subclass supplies five transport primitives (write an output report, set and
get a feature report, read an input report with a timeout, close); everything else (device
information, limits, card upload with integrity check and commit, start/stop, finger state,
direct streaming, decoding of STATE reports, loss accounting) is implemented once, here, with
:mod:`hcard_device.protocol`.

Every wait is bounded by a timeout; a device that vanishes raises :class:`DeviceError`, never a
hang. A driver is used from one thread at a time.

>>> from hcard_device.drivers import open_device
>>> with open_device("sim://") as driver:                       # doctest: +SKIP
...     driver.upload_card(card); driver.start()
...     driver.send_finger(0.0, 10.0, 20.0, 0.5, True)
...     states = driver.read_inputs(0.05)
"""

from __future__ import annotations

import abc
import time
from collections.abc import Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import ClassVar

from hcard.card_io import to_bytes
from hcard.v1 import card_pb2 as pb
from hcard_device.drivers.errors import DeviceError, DeviceStall
from hcard_device.drivers.uri import DeviceUri
from hcard_device.protocol import (
    PROTOCOL_MAJOR,
    Capability,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    Finger,
    Limits,
    ProtocolError,
    Report,
    State,
    TouchSource,
    UploadAction,
    UploadEnd,
    UploadResult,
    UploadState,
    UploadStatus,
    decode_input,
    stream_reports,
    upload_reports,
)

DEFAULT_TIMEOUT_S = 1.0
"""Longest wait for one transfer (or for one report in :meth:`Driver.read_inputs`), s."""
COMMIT_TIMEOUT_S = 5.0
"""Longest wait for the device to validate and commit an uploaded card, s."""
_SEQUENCE_MODULO = 1 << 16


@dataclass(frozen=True)
class DeviceListing:
    """One reachable device, as ``hcard device list`` prints it.

    Attributes:
        uri: the URI that opens it.
        driver: name of the driver plugin.
        description: product, variant or server details.
    """

    uri: str
    driver: str
    description: str


@dataclass(frozen=True)
class UploadOutcome:
    """What an upload achieved: the final UPLOAD_STATUS and the CLIP_REPORT of the new card."""

    status: UploadStatus
    clip: ClipReport
    bytes_sent: int
    reports_sent: int


def upload_error(status: UploadStatus, what: str = "card") -> str:
    """A one-line reason for a failed upload of a ``what`` (card or profile), from its
    UPLOAD_STATUS."""
    try:
        result = UploadResult(status.result).name
    except ValueError:
        result = f"result {status.result}"
    detail = f" at {status.detail}" if status.detail else ""
    if status.result == UploadResult.INVALID_PROFILE and status.detail:
        detail = f": {status.detail}"
    return (f"{what} upload failed: {result}{detail} ({status.received} of "
            f"{status.total_length} bytes received); the previous {what} stays in force")


class Driver(abc.ABC):
    """A connection to one hcard device (see the module docstring).

    Class attributes (the plugin metadata; a driver class is its own plugin object):
        name: plugin name (``sim``, ``usbip``, ``pyusb``, ``hid``).
        description: one line.
        schemes: URI schemes this driver opens.
        realtime: True when the device runs on the wall clock; False when the driver advances
            the device itself (``sim://``), so a track is played as fast as the CPU allows.

    Attributes:
        uri: the URI it was opened with.
        timeout_s: longest wait of one transfer, s.
        reports_received: STATE reports decoded.
        reports_lost: STATE reports missed, from gaps in their sequence numbers.
        malformed_inputs: input reports that could not be decoded (skipped).
    """

    kind: ClassVar[str] = "driver"
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    schemes: ClassVar[tuple[str, ...]] = ()
    realtime: ClassVar[bool] = True

    def __init__(self, uri: DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        self.uri = uri
        self.timeout_s = float(timeout_s)
        self.reports_received = 0
        self.reports_lost = 0
        self.malformed_inputs = 0
        self._last_sequence: int | None = None
        self._stream_seq = 0
        self._info: DeviceInfo | None = None
        self._closed = False

    # ------------------------------------------------------------------ plugin interface

    @classmethod
    @abc.abstractmethod
    def open(cls, uri: DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> Driver:
        """Connect to the device ``uri`` names; raise :class:`DeviceError` when unreachable."""

    @classmethod
    def enumerate(cls, hosts: Sequence[tuple[str, int]] = (),
                  *, timeout_s: float = DEFAULT_TIMEOUT_S) -> list[DeviceListing]:
        """Devices this driver can reach now (``hosts``: USB/IP servers to ask). Never raises
        for a missing device: an unreachable one is simply not listed."""
        return []

    # ------------------------------------------------------------------ transport primitives

    @abc.abstractmethod
    def _write_output(self, report: bytes) -> None:
        """Send an output report (interrupt OUT or SET_REPORT(Output))."""

    @abc.abstractmethod
    def _set_feature(self, report: bytes) -> None:
        """SET_REPORT(Feature); raise :class:`DeviceStall` when the device refuses."""

    @abc.abstractmethod
    def _get_feature(self, report_id: int, size: int) -> bytes:
        """GET_REPORT(Feature) of ``size`` bytes (ID included); DeviceStall when refused."""

    @abc.abstractmethod
    def _read_input(self, timeout_s: float) -> bytes | None:
        """The next input report (ID first), waiting up to ``timeout_s``; None on timeout."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the transport."""

    def clock(self) -> float:
        """The device-side time base of :meth:`collect_until`, s (wall clock by default)."""
        return time.monotonic()

    # ------------------------------------------------------------------ feature reports

    def get_report(self, cls: type[Report]) -> Report:
        """GET_REPORT(Feature) of a report class, decoded."""
        self._check_open()
        data = self._get_feature(cls.REPORT_ID, cls.size())
        try:
            return cls.decode(data)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: the device sent a malformed {cls.name()} ({exc})")\
                from None

    def set_report(self, report: Report) -> None:
        """SET_REPORT(Feature) of a feature report."""
        self._check_open()
        self._set_feature(report.encode())

    def info(self) -> DeviceInfo:
        """DEVICE_INFO (read once, then cached). Raises DeviceError for another major version."""
        if self._info is None:
            info = self.get_report(DeviceInfo)
            assert isinstance(info, DeviceInfo)
            if info.protocol_major != PROTOCOL_MAJOR:
                raise DeviceError(
                    f"{self.uri}: the device speaks protocol {info.protocol_major}."
                    f"{info.protocol_minor}; this driver speaks {PROTOCOL_MAJOR}.x"
                )
            self._info = info
        return self._info

    def limits(self) -> Limits:
        """LIMITS in force."""
        report = self.get_report(Limits)
        assert isinstance(report, Limits)
        return report

    def set_limits(self, max_amplitude_m: float | None = None, max_voltage_v: float | None = None,
                   max_current_a: float | None = None) -> Limits:
        """Lower the safety limits (m peak-to-peak, V, A; None keeps the current one); the
        device clamps them to its hardware limits. Returns the limits now in force."""
        now = self.limits()
        self.set_report(Limits.from_si(
            now.max_amplitude_m if max_amplitude_m is None else max_amplitude_m,
            now.max_voltage_v if max_voltage_v is None else max_voltage_v,
            now.max_current_a if max_current_a is None else max_current_a,
        ))
        return self.limits()

    def upload_status(self) -> UploadStatus:
        """UPLOAD_STATUS."""
        report = self.get_report(UploadStatus)
        assert isinstance(report, UploadStatus)
        return report

    def clip_report(self) -> ClipReport:
        """CLIP_REPORT of the active card."""
        report = self.get_report(ClipReport)
        assert isinstance(report, ClipReport)
        return report

    def counters(self) -> Counters:
        """COUNTERS."""
        report = self.get_report(Counters)
        assert isinstance(report, Counters)
        return report

    def upload_card(self, card: pb.Card | bytes, *,
                    commit_timeout_s: float = COMMIT_TIMEOUT_S) -> UploadOutcome:
        """Upload a card (a message or its binary bytes) in chunks and commit it.

        Returns the final status and the card's clip report. Raises :class:`DeviceError` when
        the device rejects the upload (CRC, invalid card, ...): the previous card stays active.
        """
        data = card if isinstance(card, bytes) else to_bytes(card)
        reports = self._upload(data, UploadAction.COMMIT, commit_timeout_s)
        status = self.upload_status()
        return UploadOutcome(status, self.clip_report(), len(data), reports)

    def upload_profile(self, data: bytes, *,
                       commit_timeout_s: float = COMMIT_TIMEOUT_S) -> UploadStatus:
        """Upload a device profile (the bytes of a profile file, spec/device-profile.md) and
        put it in force (UPLOAD_END COMMIT_PROFILE, protocol 1.1). Raises
        :class:`DeviceError` when the device does not take profiles or refuses this one (the
        reason and field from UPLOAD_STATUS); the profile in force stays."""
        if not self.info().capabilities & Capability.PROFILE:
            raise DeviceError(f"{self.uri}: the device does not take profiles (capability "
                              "PROFILE is not set; protocol 1.1)")
        self._upload(data, UploadAction.COMMIT_PROFILE, commit_timeout_s)
        return self.upload_status()

    def use_device_profile(self) -> None:
        """Render with the device's own profile again (CONTROL DEVICE_PROFILE)."""
        self.command(Command.DEVICE_PROFILE)

    def _upload(self, data: bytes, action: UploadAction, commit_timeout_s: float) -> int:
        """Send ``data`` in chunks, commit it with ``action``, wait for COMMITTED; the number
        of reports sent. DeviceError naming the failure otherwise."""
        what = "profile" if action == UploadAction.COMMIT_PROFILE else "card"
        try:
            reports = upload_reports(data, action)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: {exc}") from None
        for report in reports:
            try:
                self._check_open()
                self._set_feature(report)
            except DeviceStall:
                status = self.upload_status()
                if status.state == UploadState.FAILED:
                    raise DeviceError(f"{self.uri}: {upload_error(status, what)}") from None
                raise
        self._wait_committed(commit_timeout_s, what)
        return len(reports)

    def abort_upload(self) -> None:
        """Abort an upload in progress (the previous card stays active)."""
        self.set_report(UploadEnd(UploadAction.ABORT))

    def _wait_committed(self, timeout_s: float, what: str = "card") -> UploadStatus:
        deadline = self.clock() + timeout_s
        while True:
            status = self.upload_status()
            if status.state == UploadState.COMMITTED:
                return status
            if status.state == UploadState.FAILED:
                raise DeviceError(f"{self.uri}: {upload_error(status, what)}")
            if self.clock() >= deadline:
                raise DeviceError(
                    f"{self.uri}: the device did not commit the {what} within {timeout_s:g} s"
                )
            self._idle(0.005)

    def _idle(self, seconds: float) -> None:
        """Let ``seconds`` of device time pass (a sleep on real devices)."""
        time.sleep(seconds)

    # ------------------------------------------------------------------ output reports

    def send(self, report: Report) -> None:
        """Send an output report."""
        self._check_open()
        self._write_output(report.encode())

    def command(self, command: Command, argument: int = 0) -> None:
        """Send a CONTROL command."""
        self.send(Control(int(command), argument))

    def start(self) -> None:
        """Start rendering (the active card, or streamed frames)."""
        self.command(Command.START)

    def stop(self) -> None:
        """Stop: the device ramps its outputs to zero."""
        self.command(Command.STOP)

    def keepalive(self) -> None:
        """Feed the device's watchdog without changing anything."""
        self.command(Command.KEEPALIVE)

    def clear_counters(self) -> None:
        """Zero the device's counters and latched faults."""
        self.command(Command.CLEAR_COUNTERS)

    def set_touch_source(self, host: bool) -> None:
        """Take the finger state from FINGER reports (``host``) or the device's own sensor."""
        self.command(Command.SET_TOUCH_SOURCE,
                     int(TouchSource.HOST if host else TouchSource.INTERNAL))

    def send_finger(self, t_s: float, x_mm: float, y_mm: float, fn_n: float,
                    contact: bool) -> None:
        """Send the host's finger state: host time (s), position (mm), normal force (N)."""
        try:
            report = Finger.from_si(t_s, x_mm, y_mm, fn_n, contact)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: cannot send the finger state ({exc})") from None
        self.send(report)

    def stream_frames(self, uv: Sequence[float], ev: Sequence[float]) -> int:
        """Stream frames of target relative friction (UV in [0, 1], EV in [1, 4]), 15 per
        report; returns the number of reports sent."""
        try:
            reports = stream_reports(uv, ev, self._stream_seq)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: cannot stream these frames ({exc})") from None
        for report in reports:
            self._check_open()
            self._write_output(report)
        self._stream_seq = (self._stream_seq + len(reports)) % _SEQUENCE_MODULO
        return len(reports)

    # ------------------------------------------------------------------ input reports

    def parse_input(self, data: bytes) -> State | None:
        """Decode one input report; None (counted in :attr:`malformed_inputs`) when it is not
        a valid STATE report. Tracks sequence gaps in :attr:`reports_lost`. Never raises."""
        try:
            state = decode_input(bytes(data))
        except (ProtocolError, TypeError, ValueError):
            self.malformed_inputs += 1
            return None
        if self._last_sequence is not None:
            gap = (state.sequence - self._last_sequence - 1) % _SEQUENCE_MODULO
            if gap < _SEQUENCE_MODULO // 2:  # a large "gap" is a restart, not a loss
                self.reports_lost += gap
        self._last_sequence = state.sequence
        self.reports_received += 1
        return state

    def read_inputs(self, timeout_s: float | None = None,
                    max_count: int | None = None) -> list[State]:
        """STATE reports: waits up to ``timeout_s`` (default :attr:`timeout_s`) for the first,
        then takes those already waiting without further wait (at most ``max_count``).
        Returns [] on timeout; raises :class:`DeviceError` when the device is gone."""
        self._check_open()
        wait = self.timeout_s if timeout_s is None else max(float(timeout_s), 0.0)
        states: list[State] = []
        data = self._read_input(wait)
        while data is not None:
            state = self.parse_input(data)
            if state is not None:
                states.append(state)
                if max_count is not None and len(states) >= max_count:
                    break
            data = self._read_input(0.0)
        return states

    def collect_until(self, t_s: float) -> list[State]:
        """Every STATE report that arrives until :meth:`clock` reaches ``t_s``."""
        states: list[State] = []
        while True:
            remaining = t_s - self.clock()
            if remaining <= 0:
                return states
            states += self.read_inputs(remaining)

    # ------------------------------------------------------------------ lifetime

    def _check_open(self) -> None:
        if self._closed:
            raise DeviceError(f"{self.uri}: the driver is closed")

    def close(self) -> None:
        """Close the connection (idempotent)."""
        if not self._closed:
            self._closed = True
            self._close()

    def __enter__(self) -> Driver:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
