"""The host driver base class: one protocol codec shared by every transport.

A :class:`Driver` subclass supplies five transport primitives (write an output report, set and
get a feature report, read an input report with a timeout, close); everything else (device
information, limits, card upload with integrity check and commit, start/stop, finger state,
direct streaming, decoding of STATE reports, loss accounting) is implemented once, here, with
:mod:`hcard.device.protocol`. Two more primitives are optional: reading the HID report
descriptor and the HID descriptor (:meth:`Driver.report_descriptor`, protocol PD1, PD2); a
transport that cannot raises :class:`DescriptorUnavailable`, the default.

Every wait is bounded by a timeout; a device that vanishes raises :class:`DeviceError`, never a
hang. A driver is used from one thread at a time.

Sessions (protocol 1.2, spec section 14): :meth:`Driver.start` sends START with a token this
driver chose and waits until the STATE reports name the session granted to it;
:meth:`Driver.check_free` raises :class:`SessionBusy` while another host's session is live;
afterwards every STATE report of another session, or of another card, raises
:class:`SessionLost` from :meth:`Driver.read_inputs` and :meth:`Driver.collect_until`, and the
driver sends nothing more that changes the device.

>>> from hcard.device import open_device
>>> with open_device("sim://") as driver:                       # doctest: +SKIP
...     driver.upload_card(card); driver.start()
...     driver.send_finger(0.0, 10.0, 20.0, 0.5, True)
...     states = driver.read_inputs(0.05)
"""

from __future__ import annotations

import abc
import contextlib
import random
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, ClassVar

from hcard.card_io import to_bytes
from hcard.device.errors import (
    DescriptorUnavailable,
    DeviceError,
    DeviceStall,
    SessionBusy,
    SessionLost,
)
from hcard.device.protocol import (
    PROTOCOL_MAJOR,
    Capability,
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    FaultBits,
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
from hcard.device.uri import DeviceUri
from hcard.quantities import MS_PER_S, S_PER_MS, S_PER_US
from hcard.v1 import card_pb2 as pb

if TYPE_CHECKING:
    import numpy as np

DEFAULT_TIMEOUT_S = 1.0
"""Longest wait for one transfer (or for one report in :meth:`Driver.read_inputs`), s."""
COMMIT_TIMEOUT_S = 5.0
"""Longest wait for the device to validate and commit an uploaded card, s."""
_SEQUENCE_MODULO = 1 << 16
SESSION_PROTOCOL = (1, 2)
"""First protocol version with sessions (spec section 14)."""
SESSION_PEEK_S = 0.02
READ_BATCH_MAX = 256
"""Input reports one :meth:`Driver.read_inputs` call reads at most. A device streams ~1000
STATE reports/s; a host slower than that (software emulation) always finds another waiting,
so an unbounded "take what is waiting" would never return. 256 is a quarter second of them."""
"""Input reports a real-time driver reads to learn the device's session now, s: long enough
to drain what queued while it was not reading (the reference device's IN queue holds 32 ms),
so the newest report read is current."""
SESSION_MARGIN_S = 0.05
"""Silence beyond ``watchdog_ms`` a driver keeps before judging another host's session still
fed (rule PN8), s."""
_TOKENS = random.SystemRandom()


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
        renders_on_host: True when the card is rendered on the host and the device only plays
            actuator frames (:class:`~hcard.device.frame_driver.FrameDriver`): the wire
            protocol's upload, report sequence and sessions are then the host's bookkeeping,
            not the device's, and the conformance checks of them do not apply.
        separate_connections: True when every driver opened is a connection of its own that
            the device can tell from the others' (one USB/IP import each, protocol PN10): the
            device then attributes a session to the connection that began it and refuses the
            other connections' changes (PN12-PN15). False where the drivers of one host share
            its one connection (processes opening one hidraw node) or the device sees no
            connection at all (``sim://``'s second host).

    Attributes:
        uri: the URI it was opened with.
        timeout_s: longest wait of one transfer, s.
        reports_received: STATE reports decoded.
        reports_lost: STATE reports missed, from gaps in their sequence numbers.
        malformed_inputs: input reports that could not be decoded (skipped).
        input_error: why the newest of them was skipped, naming the report and the reason
            (rule PE4); empty while none was.

    Rule PV2: the first request a driver sends is GET DEVICE_INFO (every request path reads it
    first when it was not read yet), and a device of another major version is refused with
    :class:`DeviceError` naming both versions before anything else is sent to it.
    """

    kind: ClassVar[str] = "driver"
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    schemes: ClassVar[tuple[str, ...]] = ()
    realtime: ClassVar[bool] = True
    renders_on_host: ClassVar[bool] = False
    separate_connections: ClassVar[bool] = False

    def __init__(self, uri: DeviceUri, *, timeout_s: float = DEFAULT_TIMEOUT_S) -> None:
        if not timeout_s > 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        self.uri = uri
        self.timeout_s = float(timeout_s)
        self.reports_received = 0
        self.reports_lost = 0
        self.malformed_inputs = 0
        self.input_error = ""
        self._last_sequence: int | None = None
        self._stream_seq = 0
        self._info: DeviceInfo | None = None
        self._closed = False
        self.session_token: int | None = None
        """Token of the session this driver owns or asked for (rule PN1); None: none."""
        self.session_number: int | None = None
        """STATE ``session_number`` granted to this driver; None while it owns no session."""
        self.session_lost = ""
        """Why this driver's session was lost (rule PN9); empty while it was not."""
        self.granted_state: State | None = None
        """The STATE report that granted this driver's latest session (PN1, PN2)."""
        self._session_card: int | None = None
        self._session_ended = False
        self._previous_session: tuple[int, int] | None = None
        self._last_state: State | None = None

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
        """SET_REPORT(Feature), waiting for its answer at most :attr:`timeout_s` as it is when
        called (longer for the UPLOAD_END that commits, PU12); raise :class:`DeviceStall` when
        the device refuses."""

    @abc.abstractmethod
    def _get_feature(self, report_id: int, size: int) -> bytes:
        """GET_REPORT(Feature) of ``size`` bytes (ID included); DeviceStall when refused."""

    @abc.abstractmethod
    def _read_input(self, timeout_s: float) -> bytes | None:
        """The next input report (ID first), waiting up to ``timeout_s``; None on timeout."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the transport."""

    def _report_descriptor(self) -> bytes:
        """GET_DESCRIPTOR(Report) of the device's HID interface: all the bytes it returns.
        Optional: by default the transport cannot (:class:`DescriptorUnavailable`)."""
        raise DescriptorUnavailable(
            f"{self.uri}: the {self.name or type(self).__name__} driver cannot read the "
            "device's report descriptor (it implements no Driver._report_descriptor)")

    def _hid_descriptor(self) -> bytes:
        """The HID descriptor (HID 1.11 6.2.1) of the device's HID interface, as its
        configuration descriptor carries it. Optional: by default the transport cannot
        (:class:`DescriptorUnavailable`)."""
        raise DescriptorUnavailable(
            f"{self.uri}: the {self.name or type(self).__name__} driver cannot read the "
            "device's HID descriptor (it implements no Driver._hid_descriptor)")

    def clock(self) -> float:
        """The device-side time base of :meth:`collect_until`, s (wall clock by default)."""
        return time.monotonic()

    # ------------------------------------------------------------------ descriptors

    def report_descriptor(self) -> bytes:
        """The HID report descriptor the device returns for GET_DESCRIPTOR(Report), as read
        (protocol PD1: the bytes of spec/device-protocol.md 4.1; PD2 says what they declare).

        Raises:
            DescriptorUnavailable: this driver's transport cannot read descriptors (hidapi
                before it had ``get_report_descriptor``, a vendor's driver without them).
            DeviceStall: the device refused the request.
            DeviceError: the device failed or vanished.
        """
        self._check_open()
        return self._report_descriptor()

    def hid_descriptor(self) -> bytes:
        """The HID descriptor of the device's HID interface (HID 1.11 6.2.1: ``bLength``,
        ``bDescriptorType`` 0x21, ``bcdHID``, ``bCountryCode``, ``bNumDescriptors``, then each
        class descriptor's type and length), which announces the report descriptor's length
        (protocol PD1); b"" when the device's configuration carries none for its HID
        interface.

        Raises:
            DescriptorUnavailable: this driver's transport cannot read it (hidapi reads the
                report descriptor only).
            DeviceStall, DeviceError: as :meth:`report_descriptor`.
        """
        self._check_open()
        return self._hid_descriptor()

    # ------------------------------------------------------------------ feature reports

    def get_report(self, cls: type[Report]) -> Report:
        """GET_REPORT(Feature) of a report class, decoded."""
        self._check_open()
        if cls is not DeviceInfo:
            self._check_version()
        data = self._get_feature(cls.REPORT_ID, cls.size())
        try:
            return cls.decode(data)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: the device sent a malformed {cls.name()} ({exc})")\
                from None

    def set_report(self, report: Report) -> None:
        """SET_REPORT(Feature) of a feature report (:class:`SessionLost` once the session
        was lost: rule PN9)."""
        self._check_open()
        self._check_version()
        self._check_session()
        self._set_feature(report.encode())

    def info(self) -> DeviceInfo:
        """DEVICE_INFO (read once, then cached). Raises DeviceError for another major version."""
        if self._info is None:
            info = self.get_report(DeviceInfo)
            assert isinstance(info, DeviceInfo)
            if info.protocol_major != PROTOCOL_MAJOR:
                raise DeviceError(
                    f"{self.uri}: the device speaks protocol {info.protocol_major}."
                    f"{info.protocol_minor}; this driver implements major {PROTOCOL_MAJOR} "
                    "(spec PV2)"
                )
            self._info = info
        return self._info

    def _check_version(self) -> None:
        """Rule PV2: read DEVICE_INFO before any other request (:meth:`info`, which refuses
        a device of another major version), unless it was read already."""
        if self._info is None:
            self.info()

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
        self._check_open()
        self._check_version()
        try:
            reports = upload_reports(data, action)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: {exc}") from None
        for index, report in enumerate(reports):
            try:
                self._check_open()
                self._check_session()
                if index == len(reports) - 1:  # UPLOAD_END: held while the device checks (PU12)
                    with self.waiting_at_most(max(self.timeout_s, commit_timeout_s)):
                        self._set_feature(report)
                else:
                    self._set_feature(report)
            except DeviceStall:
                status = self.upload_status()
                if status.state == UploadState.FAILED:
                    raise DeviceError(f"{self.uri}: {upload_error(status, what)}") from None
                self._raise_if_refused_for_a_session(what)
                raise
        self._wait_committed(commit_timeout_s, what)
        return len(reports)

    @contextlib.contextmanager
    def waiting_at_most(self, timeout_s: float) -> Iterator[None]:
        """Within the block, the transport primitives wait up to ``timeout_s`` (they read
        :attr:`timeout_s` when called): the UPLOAD_END SET's status stage comes only once the
        device has checked the card or profile (PU12), which on a loaded machine takes longer
        than any other answer (a 1 s wait failed `hcard play --profile` beside two busy
        processes on 2 cores)."""
        saved = self.timeout_s
        self.timeout_s = timeout_s
        try:
            yield
        finally:
            self.timeout_s = saved

    def _raise_if_refused_for_a_session(self, what: str) -> None:
        """After a STALLed upload report: raise :class:`SessionBusy` when the device refused it
        because another host's session is live (SESSION_BUSY in the next STATE report: a
        served device refuses the reports of every connection but the session owner's, rule
        PN13)."""
        if not self.sessions_supported():
            return
        seen = self._observe(SESSION_PEEK_S if self.realtime else 0.0)
        busy = [s for s in seen if s.faults & FaultBits.SESSION_BUSY and self._foreign(s)]
        if busy:
            state = busy[-1]
            raise SessionBusy(
                f"{self.uri}: device busy: the {what} upload was refused (SESSION_BUSY), "
                f"session {state.session_number} of another host "
                f"({_owner(state.session_token)}) is live (spec PN13)") from None

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
        """Send an output report (:class:`SessionLost` once the session was lost: PN9)."""
        self._check_open()
        self._check_version()
        self._check_session()
        self._write_output(report.encode())

    def send_raw(self, data: bytes) -> None:
        """Send ``data`` as an output report exactly as it is (ID first), well formed or not:
        what a conformance check sends to see a device refuse it (protocol PE2, PT7). Refusal
        is the device's to report (STATE fault INVALID_REQUEST, ``rejected_requests``)."""
        self._check_open()
        self._check_version()
        self._write_output(bytes(data))

    def get_raw_feature(self, report_id: int, size: int) -> bytes:
        """GET_REPORT(Feature) of any ``report_id`` and ``size`` (ID included), undecoded:
        what a conformance check asks to see a device STALL (protocol PE1).

        Raises:
            DeviceStall: the device refused the request.
        """
        self._check_open()
        if report_id != DeviceInfo.REPORT_ID:
            self._check_version()
        return self._get_feature(report_id, size)

    def command(self, command: Command, argument: int = 0) -> None:
        """Send a CONTROL command."""
        self.send(Control(int(command), argument))

    def start(self) -> None:
        """Start rendering (the active card, or streamed frames).

        On a protocol 1.2 device this begins a session (rule PN1): :meth:`check_free` first,
        then START with a new token, then wait (up to :attr:`timeout_s`) for a STATE report
        naming the session granted (the reports read meanwhile, from before the session or
        its first, are not returned: a recording starts after START returns). A START of the
        session this driver owns restarts rendering in it. On an older device: START with
        argument 0 (anonymous).

        Raises:
            SessionBusy: another host's session is live (PN3, PN8).
            SessionLost: this driver's session was lost earlier (PN9).
            DeviceError: no session was granted within the timeout.
        """
        self._check_session()
        if not self.sessions_supported():
            self.command(Command.START)
            return
        if self.session_number is not None:
            self.command(Command.START, self.session_token or 0)
            return
        self.check_free()
        self._begin_session(Command.START)

    def take_over(self) -> None:
        """End whatever session is live and begin one owned by this driver (CONTROL
        TAKE_OVER, rule PN6): the other host's driver then raises :class:`SessionLost`.

        Raises:
            DeviceError: the device has no sessions (protocol before 1.2), or none was
                granted within the timeout.
        """
        self._check_session()
        if not self.sessions_supported():
            info = self.info()
            raise DeviceError(f"{self.uri}: the device speaks protocol {info.protocol_major}."
                              f"{info.protocol_minor}: no sessions, no TAKE_OVER (1.2)")
        self.session_number = None
        self._begin_session(Command.TAKE_OVER)

    def stop(self) -> None:
        """Stop: the device ramps its outputs to zero, and this driver's session ends (PN4).
        After a lost session nothing is sent (the device is another host's, PN9)."""
        if self.session_lost:
            return
        token = self.session_token if self.session_number is not None else 0
        self.command(Command.STOP, token or 0)
        self._end_session()

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

    def send_finger(self, t_s: float, x_mm: float, y_mm: float, normal_force_n: float,
                    contact: bool) -> None:
        """Send the host's finger state: host time (s), position (mm), normal force (N)."""
        try:
            report = Finger.from_si(t_s, x_mm, y_mm, normal_force_n, contact)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: cannot send the finger state ({exc})") from None
        self.send(report)

    def stream_frames(self, uv: Sequence[float] | np.ndarray,
                      ev: Sequence[float] | np.ndarray) -> int:
        """Stream frames of target relative friction (UV in [0, 1], EV in [1, 4]), 15 per
        report; returns the number of reports sent."""
        try:
            reports = stream_reports(uv, ev, self._stream_seq)
        except ProtocolError as exc:
            raise DeviceError(f"{self.uri}: cannot stream these frames ({exc})") from None
        self._check_open()
        self._check_version()
        for report in reports:
            self._check_open()
            self._write_output(report)
        self._stream_seq = (self._stream_seq + len(reports)) % _SEQUENCE_MODULO
        return len(reports)

    # ------------------------------------------------------------------ sessions (1.2)

    def sessions_supported(self) -> bool:
        """The device speaks protocol 1.2 or later of major 1 (spec section 14)."""
        info = self.info()
        return (info.protocol_major, info.protocol_minor) >= SESSION_PROTOCOL

    def check_free(self) -> None:
        """Raise :class:`SessionBusy` when another host's session is live (rule PN8).

        Looks at the STATE reports (reading them sends nothing). When they show another
        host's session, the driver stays silent for ``watchdog_ms`` + :data:`SESSION_MARGIN_S`
        and looks again: a session whose host is gone has then ended (PN7); one still live
        is fed by its host, and the device is busy. The reports read (those waiting, at
        least one) precede any session of this driver and are not returned to the caller.
        No-op on a device without sessions.
        """
        if not self.sessions_supported():
            return
        seen = self._observe(SESSION_PEEK_S if self.realtime else 0.0)
        if not seen or not self._foreign(seen[-1]):
            return
        first = seen[-1]
        waited = self.info().watchdog_ms * S_PER_MS + SESSION_MARGIN_S
        later = self._observe(waited)
        now = later[-1] if later else first
        if self._foreign(now) and now.session_number == first.session_number:
            raise SessionBusy(
                f"{self.uri}: device busy: session {now.session_number} of another host "
                f"({_owner(now.session_token)}) is live and still fed after "
                f"{waited * MS_PER_S:.0f} ms of silence from this host; wait for it to stop, or "
                "take it over (spec PN3, PN6)")

    @property
    def last_state(self) -> State | None:
        """The newest STATE report this driver decoded (None before the first)."""
        return self._last_state

    def _foreign(self, state: State) -> bool:
        """``state`` shows a live session this driver does not own."""
        if not state.session_live:
            return False
        return (self.session_number is None or state.session_number != self.session_number
                or state.session_token != self.session_token)

    def _observe(self, seconds: float) -> list[State]:
        """Reports arriving within ``seconds`` (at least one, waiting up to
        :attr:`timeout_s`). They are the driver's own look at the session: the caller of
        :meth:`start` or :meth:`check_free` does not get them."""
        return self.collect_until(self.clock() + seconds) or self.read_inputs()

    def _new_token(self) -> int:
        """A token 1..255 other than the live session's and this driver's previous one."""
        avoid = {0}
        if self._last_state is not None and self._last_state.session_live:
            avoid.add(self._last_state.session_token)
        if self._previous_session is not None:
            avoid.add(self._previous_session[0])
        return _TOKENS.choice([t for t in range(1, 256) if t not in avoid])

    def _begin_session(self, command: Command) -> None:
        """Send START or TAKE_OVER with a new token and wait for the grant (PN1, PN6)."""
        token = self._new_token()
        self.session_token, self.session_lost = token, ""
        self.command(command, token)
        deadline = self.clock() + self.timeout_s
        while True:
            for state in self._observe(0.0):
                if state.session_live and state.session_token == token and \
                        (token, state.session_number) != self._previous_session:
                    self.session_number = state.session_number
                    self.granted_state = state
                    self._session_card = state.card_generation
                    self._session_ended = False
                    return
                if state.faults & FaultBits.SESSION_BUSY and self._foreign(state):
                    self.session_token = None
                    raise SessionBusy(
                        f"{self.uri}: device busy: START refused, session "
                        f"{state.session_number} of another host "
                        f"({_owner(state.session_token)}) is live (spec PN3)")
            if self.clock() >= deadline:
                self.session_token = None
                raise DeviceError(f"{self.uri}: no session granted within {self.timeout_s:g} s "
                                  f"of {command.name} (token {token}; spec PN1)")

    def _end_session(self) -> None:
        if self.session_number is not None and self.session_token is not None:
            self._previous_session = (self.session_token, self.session_number)
        self.session_number = None
        self.session_token = None

    def _track_session(self, state: State) -> None:
        """Raise :class:`SessionLost` when ``state`` belongs to another session than this
        driver's, or shows another card than the one in force when it began (rule PN9)."""
        self._last_state = state
        number = self.session_number
        if number is None or self.session_lost:
            return
        if state.session_number == number and not state.session_live:
            self._session_ended = True  # PN7: the device ended it after host silence
        if state.session_number != number:
            how = ("ended by the device after host silence (PN7), then another host began"
                   if self._session_ended else "taken over by")
            self._lose(f"session {number} was lost: {how} session {state.session_number} "
                       f"({_owner(state.session_token)}) at device time "
                       f"{state.timestamp_us * S_PER_US:.3f} s")
        if self._session_card is not None and state.card_generation != self._session_card:
            ended = ("ended by the device after host silence (PN7), then "
                     if self._session_ended or not state.session_live else "")
            self._lose(f"session {number} was lost: {ended}the active card was replaced "
                       f"(generation {self._session_card} -> {state.card_generation}) by "
                       f"another host at device time {state.timestamp_us * S_PER_US:.3f} s")

    def _lose(self, reason: str) -> None:
        self.session_lost = f"{self.uri}: {reason} (spec PN9)"
        raise SessionLost(self.session_lost)

    def _check_session(self) -> None:
        if self.session_lost:
            raise SessionLost(self.session_lost)

    # ------------------------------------------------------------------ input reports

    def parse_input(self, data: bytes) -> State | None:
        """Decode one input report; None when it is not a valid STATE report: skipped, counted
        in :attr:`malformed_inputs`, and why in :attr:`input_error` (the report and the reason,
        rule PE4). Tracks sequence gaps in :attr:`reports_lost`. Never raises."""
        try:
            state = decode_input(bytes(data))
        except (ProtocolError, TypeError, ValueError) as exc:
            self.malformed_inputs += 1
            self.input_error = f"{self.uri}: input report skipped: {exc} (spec PE4)"
            return None
        if self._last_sequence is not None:
            gap = (state.sequence - self._last_sequence - 1) % _SEQUENCE_MODULO
            if gap < _SEQUENCE_MODULO // 2:  # a large "gap" is a restart, not a loss
                self.reports_lost += gap
        self._last_sequence = state.sequence
        self.reports_received += 1
        return state

    def accept_input(self, data: bytes) -> State | None:
        """:meth:`parse_input`, then session tracking (:class:`SessionLost`, rule PN9)."""
        state = self.parse_input(data)
        if state is not None:
            self._track_session(state)
        return state

    def read_inputs(self, timeout_s: float | None = None,
                    max_count: int | None = None) -> list[State]:
        """STATE reports: waits up to ``timeout_s`` (default :attr:`timeout_s`) for the first,
        then takes those already waiting without further wait (at most ``max_count``, by
        default :data:`READ_BATCH_MAX`, so a host slower than the device's stream still
        returns). Returns [] on timeout; raises :class:`DeviceError` when the device is gone."""
        self._check_open()
        wait = self.timeout_s if timeout_s is None else max(float(timeout_s), 0.0)
        limit = READ_BATCH_MAX if max_count is None else max_count
        states: list[State] = []
        data = self._read_input(wait)
        reads = 0
        while data is not None:
            reads += 1
            state = self.accept_input(data)
            if state is not None:
                states.append(state)
            if len(states) >= limit or reads >= READ_BATCH_MAX:
                break
            data = self._read_input(0.0)
        return states

    def collect_until(self, t_s: float) -> list[State]:
        """Every STATE report that arrives until :meth:`clock` reaches ``t_s``. Raises
        :class:`SessionLost` when a report shows this driver's session lost (rule PN9)."""
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
        """Close the connection (idempotent). A session this driver still owns is ended
        first with STOP (rule PN4), so the next host need not wait for PN7."""
        if not self._closed:
            if self.session_number is not None and not self.session_lost:
                with contextlib.suppress(DeviceError):  # gone: PN7 ends the session
                    self.stop()
            self._closed = True
            self._close()

    def __enter__(self) -> Driver:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


def _owner(token: int) -> str:
    """The owner of a session, for messages: its token, or anonymous (a 1.0/1.1 host)."""
    return f"token {token}" if token else "anonymous, a protocol 1.0/1.1 host"
