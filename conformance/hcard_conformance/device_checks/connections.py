"""The cases of ``device.session-ownership`` that apply where the device tells its hosts'
connections apart (spec/device-protocol.md PN10, PN12-PN15; spec/conformance.md 4.8, O5-O9).

A USB/IP server knows which connection each request came from (one per importing host), and
then a session belongs to the connection whose START or TAKE_OVER began it (PN12): the other
connections cannot change the device under it, keep it alive or halt its pipes (PN13, PN14).
The suite knows it reaches the device so from its driver: :attr:`hcard.device.base.Driver.
separate_connections` (the ``usbip`` and ``pyusb`` drivers: one import per driver). Over USB HID
two processes share one connection, and ``sim://``'s second host is no connection at all: the
device cannot tell them apart, PN12 attributes nothing there, and these cases are not named.

``other-connection-refused`` (PN12, PN13; O5)
    The owner's connection STARTs (and, on a device with HOST_FINGER, sends a FINGER: the
    device is then host-driven) and sends KEEPALIVE every :data:`FEED_FRACTION` of
    ``watchdog_ms``; meanwhile a second connection sends, one at a time, each request of
    :func:`other_requests` that changes the device (FINGER, STREAM and every CONTROL command
    but TAKE_OVER, START and STOP *with the owner's token*, SETs of LIMITS, CLIP_REPORT where
    the card in force has a clipped item, and UPLOAD_BEGIN) and GETs every feature report.
    Each change must be refused as PN13 says: ``rejected_requests`` (COUNTERS, read by the
    second connection before and after) moves by exactly 1, a SET is STALLed (PE1), an output
    report flags INVALID_REQUEST (PE2), and SESSION_BUSY is flagged in a report read after
    it; each GET must be answered, counted nowhere. Afterwards the owner's session, LIMITS,
    UPLOAD_STATUS and finger echo are those of before. Metric: the requests handled
    otherwise, and those effects; must be 0.
``ends-despite-other-connection`` (PN13 with PN7 and PS3; O6)
    The owner sends a FINGER (where it can), STARTs and falls silent; the second connection
    sends KEEPALIVE and a GET of COUNTERS every :data:`FEED_FRACTION` of ``watchdog_ms``
    until the device's clock (the newest report it read) is :data:`OTHER_FEEDS_UNTIL` of
    ``watchdog_ms`` past the report that granted the session. Metric: device time from that
    report to the first one with flag SESSION cleared (PN7; infinite when none within the
    threshold); must be at most ``watchdog_ms`` + :data:`~hcard_conformance.device_checks.
    session_ownership.SILENCE_MARGIN_S` (O4's bound), and on a host-driven device the
    watchdog must have tripped (PS3: COUNTERS ``watchdog_trips`` or a report flagged
    WATCHDOG). A device that let the second connection's reports feed either holds the session
    at least ``watchdog_ms`` past their last one, beyond the bound. Timed on the device's
    clock, the verdict does not depend on when the host read the reports; a run whose
    KEEPALIVEs left a gap over ``watchdog_ms / 2`` (PS3's period) did not test the rule and is
    measured again (QT3).
``takeover-attributed`` (PN6, PN12; O7)
    The owner STARTs; the second connection sends TAKE_OVER and keeps its session fed. Its own
    KEEPALIVE must be carried out (not counted in ``rejected_requests``), and the former
    owner's KEEPALIVE, START and STOP with the new owner's token and SET of LIMITS refused as
    in ``other-connection-refused``: the session is now attributed to the connection of the
    TAKE_OVER. Metric: the requests handled otherwise; must be 0.
``halts-per-connection`` (PN14; O8), named only where the driver offers the standard
    endpoint requests (``set_endpoint_halt``, ``endpoint_halted``, ``set_configuration``:
    the ``usbip`` driver). While the owner's session is live the second connection halts its
    interrupt-OUT pipe: GET_STATUS shows it halted to that connection only, the second
    connection's KEEPALIVE is STALLed, the owner's KEEPALIVEs are carried out (COUNTERS
    ``output_reports``), and the owner's SET_CONFIGURATION leaves the second connection's
    halt as it was; then the second connection halts its interrupt-IN pipe and the owner's
    STATE stream runs on (its pipe not halted, its report sequence advancing by at least
    :data:`MIN_REPORTS_AFTER` while it reads :data:`IN_HALT_READ_S`). Metric: the effects on
    the other connection's pipes, and halts not kept; must be 0.

``beside-non-reader``, ``beside-urb-flood``, ``beside-giant-transfer``, ``beside-out-flood``,
``beside-idle-importers`` (PN15; O9), named only where the driver's URI is a USB/IP server's
``usbip://HOST:PORT/BUSID`` (:data:`BOUND_CASES`): a driver reads whatever arrives, so a
misbehaving client takes the transport's own protocol, spoken on raw sockets by
:mod:`hcard_conformance.usbip_clients`. A well-behaved client (the hcard link, 4 interrupt-IN
URBs outstanding) reads STATE reports :data:`BOUND_MEASURE_S` alone, then again beside one
hostile client in a process of its own (started once it holds its connection and given
:data:`BESIDE_SETTLE_S` to take effect): one that parks IN URBs and stops reading its socket,
one that submits IN URBs far faster than reports complete them, one that declares a 2 GiB OUT
transfer and feeds it, one that floods FINGER output reports, or 300 connections that import
the device and do nothing. Metric: the share of STATE reports received beside the hostile
client over the share received alone; must be at least the device's stated fraction
(``--option delivery_share=F``, default :data:`DELIVERY_SHARE`), with no gap of
:data:`MAX_ARRIVAL_GAP_S` or more between two reports. A run whose alone measurement shows the
host could not keep real time (a share under :data:`MIN_ALONE_SHARE`, or the host not running
for :data:`~hcard_conformance.realtime.HOST_LATE_S`), or that failed while the host did not run
beside the hostile client, is not kept (QT3); a device that starves a connection fails every
run.

A run in which the owner's session ended by PN7 before a request could be judged (the host did
not run for :data:`~hcard_conformance.realtime.HOST_LATE_S`, or its KEEPALIVEs left a gap of
``watchdog_ms``), or in which the one report carrying SESSION_BUSY may have been lost, is a run
not kept (spec QT3) and measured again; a request carried out or not counted fails whatever the
timing.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field

from hcard.device.base import Driver
from hcard.device.errors import DeviceError, DeviceStall, SessionLost
from hcard.device.protocol import (
    ClipReport,
    Command,
    Control,
    Counters,
    DeviceInfo,
    FaultBits,
    Finger,
    Limits,
    Report,
    State,
    Stream,
    UploadBegin,
    UploadStatus,
)
from hcard.device.protocol.constants import Capability, TouchSource
from hcard.device.protocol.usb_ids import IN_ENDPOINT, OUT_ENDPOINT
from hcard.quantities import MS_PER_S, S_PER_US
from hcard_conformance import usbip_clients
from hcard_conformance.check_names import DEVICE_SESSION_OWNERSHIP as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, READ_CATCH_UP_S
from hcard_conformance.realtime import HostWatch, NotKept, device_lag, reasons
from hcard_conformance.result import CannotAssess, CheckResult, measured

CONNECTION_CASES = ("other-connection-refused", "ends-despite-other-connection",
                    "takeover-attributed")
"""The cases named where the device tells connections apart (PN12, PN13)."""
HALT_CASE = "halts-per-connection"
"""The case of PN14, named where the driver also offers the standard endpoint requests."""
HALT_METHODS = ("set_endpoint_halt", "endpoint_halted", "set_configuration")
"""What a driver offers for :data:`HALT_CASE` (:class:`hcard.device.transports.usbip_client.
UsbipDriver` does)."""
BOUND_CASES = {
    "beside-non-reader": "non-reader",
    "beside-urb-flood": "parked-urb-flood",
    "beside-giant-transfer": "giant-out-urb",
    "beside-out-flood": "out-report-flood",
    "beside-idle-importers": "idle-importers",
}
"""The cases of PN15 (O9), named where the URI reaches a USB/IP server over TCP, and the
hostile client each runs (:data:`hcard_conformance.usbip_clients.HOSTILE_KINDS`)."""
DELIVERY_SHARE = 0.9
"""O9's default: the share of STATE reports a connection receives beside a hostile client,
over its share alone, at least (the reference device's stated fraction, spec/device-protocol.md
section 13; a device class may state its own with ``--option delivery_share=F``)."""
MAX_ARRIVAL_GAP_S = 1.0
"""Longest time between two STATE reports of the well-behaved connection beside a hostile
client, s: a stream stopped for that long is stopped (PN15), whatever the share."""
BOUND_MEASURE_S = 1.0
"""Length of each delivery measurement of the PN15 cases, s (1000 reports: a share to 0.1 %)."""
BESIDE_SETTLE_S = 1.5
"""Time a hostile client is given to take effect before the measurement beside it, s: the
non-reader fills its socket's and the server's buffers in well under a second."""
MIN_ALONE_SHARE = 0.5
"""A run whose alone measurement received less than this share of the 1000 reports a second
measured the host, not the device, and is not kept (QT3)."""
CONNECTIONS_KEY = "separate-connections"
"""``Context.cache`` key of what the driver tells of its connections (read once per run)."""

FEED_FRACTION = 0.2
"""Period of a feeding host's KEEPALIVE, in ``watchdog_ms`` (PS3 asks for at most a half)."""
OTHER_FEEDS_UNTIL = 0.75
"""How far into the owner's silence, in ``watchdog_ms`` of device time, the second connection
of ``ends-despite-other-connection`` keeps sending: a device its reports fed would hold the
session until at least 1.75 ``watchdog_ms``, beyond O4's ``watchdog_ms`` + 50 ms, and its
last KEEPALIVE reaches the device well before the owner's ``watchdog_ms`` ends."""
SLICE_S = 0.005
"""Reads of a waiting host between two looks at its KEEPALIVEs and its stop condition, s."""
SETTLE_S = 0.02
"""Reports read after a request before judging it, at least, s (20 report periods)."""
COUNT_WAIT_S = 0.25
"""Longest read after a request for the report that shows it counted, s (plus the timing
class's read lag)."""
OWNER_FEEDS = 10
"""KEEPALIVEs the owner sends while the other connection's OUT pipe is halted."""
MIN_REPORTS_AFTER = 10
"""Reports the owner's sequence must advance by while the other's IN pipe is halted (the
least the refusals of X1 ask to see after a request)."""
IN_HALT_READ_S = 0.05
"""How long the owner reads while the other's IN pipe is halted, s."""
_U16, _U32 = 1 << 16, 1 << 32


@dataclass(frozen=True)
class Connections:
    """What the implementation's driver tells of its connections.

    Attributes:
        separate: every driver is a connection the device tells apart (PN10, PN12).
        halts: the driver offers the standard endpoint requests (:data:`HALT_METHODS`).
        server: the USB/IP server's (host, port) where the URI names one reached over TCP
            (raw clients can then misbehave beside the driver: :data:`BOUND_CASES`).
    """

    separate: bool = False
    halts: bool = False
    server: tuple[str, int] | None = None


def usbip_server(driver: Driver) -> tuple[str, int] | None:
    """(host, port) of the USB/IP server ``driver``'s URI names (``usbip://HOST:PORT/BUSID``),
    None for another scheme or a device served in the host's process (``loopback``)."""
    uri = getattr(driver, "uri", None)
    if getattr(uri, "scheme", "") != "usbip" or getattr(uri, "loopback", True):
        return None
    host, port = getattr(uri, "host", ""), getattr(uri, "port", 0)
    return (host, port) if host and port else None


def connections(ctx: Context) -> Connections:
    """What ``ctx``'s driver tells of its connections, asked once per run (its driver opened
    and closed; a device that cannot be opened tells nothing, and its cases report why)."""
    if ctx.open_driver is None:
        return Connections()
    if CONNECTIONS_KEY not in ctx.cache:
        try:
            with ctx.open_driver() as driver:
                separate = bool(getattr(driver, "separate_connections", False))
                halts = all(callable(getattr(driver, m, None)) for m in HALT_METHODS)
                server = usbip_server(driver) if separate else None
        except DeviceError:
            return Connections()
        ctx.cache[CONNECTIONS_KEY] = Connections(separate, separate and halts, server)
    found: Connections = ctx.cache[CONNECTIONS_KEY]
    return found


def connection_case_names(ctx: Context) -> tuple[str, ...]:
    """The cases of this module ``ctx``'s implementation gets (none where the device cannot
    tell connections apart)."""
    found = connections(ctx)
    if not found.separate:
        return ()
    return (CONNECTION_CASES + ((HALT_CASE,) if found.halts else ())
            + (tuple(BOUND_CASES) if found.server else ()))


# ---------------------------------------------------------------------- the requests

@dataclass(frozen=True)
class Request:
    """One request of a connection that is not the session's owner.

    Attributes:
        name: what it is, for the detail.
        report: the report sent.
        feature: a SET of a feature report (else an output report).
    """

    name: str
    report: Report
    feature: bool = False

    def send(self, driver: Driver) -> bool:
        """Send it from ``driver``; True when the device STALLed it (a SET only)."""
        if not self.feature:
            driver.send_raw(self.report.encode())
            return False
        try:
            driver.set_report(self.report)
        except DeviceStall:
            return True
        return False


def host_time_us(driver: Driver) -> int:
    """The FINGER ``host_time_us`` of a sample taken now on ``driver``'s clock (PO2: the host's
    clock, as :func:`hcard.device.play.play` sends it; never 0, which means none)."""
    return round(driver.clock() * 1e6) % _U32 or 1


def send_finger(driver: Driver, info: DeviceInfo) -> int:
    """A FINGER in contact at the middle of the surface, taken now; its ``host_time_us``."""
    host_us = host_time_us(driver)
    driver.send_finger(host_us * S_PER_US, info.surface_width_10um * 0.005,
                       info.surface_height_10um * 0.005, 0.5, True)
    return host_us


def other_requests(info: DeviceInfo, token: int, limits: Limits, clip: ClipReport,
                   host_us: int) -> list[Request]:
    """The requests of PN13 that change the device, as another connection sends them while
    the owner's session (token ``token``) is live: its own FINGER (at ``host_us``, host time)
    and STREAM where the device takes them, every CONTROL command but TAKE_OVER (START and
    STOP with the owner's token: only the connection tells them from the owner's), SETs of
    LIMITS (halved), CLIP_REPORT (item 0, where the card in force has a clipped item: else no
    SET of it is well formed) and UPLOAD_BEGIN. STOP comes last: carried out, it ends the
    session the others are judged against."""
    capabilities = info.capabilities
    requests = []
    if capabilities & Capability.HOST_FINGER:
        requests.append(Request("FINGER", Finger.from_si(
            host_us * S_PER_US, info.surface_width_10um * 0.01 * 0.9,
            info.surface_height_10um * 0.01 * 0.9, 0.5, True)))
    if capabilities & Capability.DIRECT_STREAMING:
        requests.append(Request("STREAM", Stream(0, (5000,), (10000,))))
    requests += [
        Request("CONTROL KEEPALIVE", Control(Command.KEEPALIVE)),
        Request("CONTROL CLEAR_COUNTERS", Control(Command.CLEAR_COUNTERS)),
        Request("CONTROL SET_TOUCH_SOURCE internal",
                Control(Command.SET_TOUCH_SOURCE, int(TouchSource.INTERNAL))),
        Request("CONTROL PLAY_CARD", Control(Command.PLAY_CARD)),
    ]
    if capabilities & Capability.PROFILE:
        requests.append(Request("CONTROL DEVICE_PROFILE", Control(Command.DEVICE_PROFILE)))
    requests += [
        Request("CONTROL START with the owner's token", Control(Command.START, token)),
        Request("SET LIMITS", Limits(limits.max_amplitude_nm // 2, limits.max_voltage_dv // 2,
                                     limits.max_current_10na // 2), feature=True),
    ]
    if clip.item_count:  # a SET of an item the card does not have is malformed (PE1) first
        requests.append(Request("SET CLIP_REPORT", dataclasses.replace(clip, item_index=0),
                                feature=True))
    requests += [
        Request("SET UPLOAD_BEGIN", UploadBegin(16, 0), feature=True),
        Request("CONTROL STOP with the owner's token", Control(Command.STOP, token)),
    ]
    return requests


GETS: tuple[type[Report], ...] = (DeviceInfo, Limits, Counters, UploadStatus, ClipReport)
"""The feature reports another connection GETs (PN13: answered whoever asks)."""


# ---------------------------------------------------------------------- a fed session

@dataclass
class Fed:
    """A session kept alive by its owner's KEEPALIVE every :data:`FEED_FRACTION` of
    ``watchdog_ms`` while a driver reads (the owner itself or another connection).

    Attributes:
        feeder: the session owner's driver.
        reader: the driver whose reports are read.
        period_s: the KEEPALIVE period, s.
        watch: the host's clock (its loop ticks).
        longest_gap_s: longest time between two KEEPALIVEs, s.
        lost: why the reader's session was lost while it read (PN9), when it was.
    """

    feeder: Driver
    reader: Driver
    period_s: float
    watch: HostWatch
    longest_gap_s: float = 0.0
    lost: str = ""
    _last_feed: float = field(default=-math.inf, init=False)

    def feed(self) -> None:
        """KEEPALIVE now when one is due (raw: the feeder's driver checks nothing)."""
        now = self.feeder.clock()
        if now - self._last_feed >= self.period_s:
            if math.isfinite(self._last_feed):
                self.longest_gap_s = max(self.longest_gap_s, now - self._last_feed)
            self.feeder.send_raw(Control(Command.KEEPALIVE).encode())
            self._last_feed = now

    def stop_feeding(self) -> None:
        """Send no more KEEPALIVE; the time since the last one counts as a gap."""
        if math.isfinite(self.period_s) and math.isfinite(self._last_feed):
            self.longest_gap_s = max(self.longest_gap_s, self.feeder.clock() - self._last_feed)
        self.period_s = math.inf

    def read(self, seconds: float, done: Callable[[list[State]], bool] | None = None
             ) -> list[State]:
        """The reports of ``seconds``, fed meanwhile; with ``done``, read on until ``done``
        of the reports so far holds or ``seconds`` pass."""
        states: list[State] = []
        end = self.reader.clock() + seconds
        while self.reader.clock() < end:
            self.feed()
            self.watch.tick()
            try:
                states += self.reader.collect_until(min(end, self.reader.clock() + SLICE_S))
            except SessionLost as exc:
                self.lost = self.lost or str(exc)
            if done is not None and done(states):
                break
        self.feed()
        return states


def counted(after: int, before: int) -> int:
    """How far a u32 counter moved (negative when it went back: the counters were cleared)."""
    moved = (after - before) % _U32
    return moved - _U32 if moved >= _U32 // 2 else moved


@dataclass
class Judged:
    """What a run found: the requests handled otherwise than PN13 says, the reasons the run
    was not kept, and what it saw."""

    problems: list[str] = field(default_factory=list)
    not_kept: list[str] = field(default_factory=list)
    states: list[State] = field(default_factory=list)


def judge_refused(request: Request, sender: Driver, fed: Fed, found: Judged,
                  read_lag_s: float) -> list[str]:
    """Send ``request`` from ``sender`` and judge its refusal (PN13) from the reports and
    COUNTERS of ``fed``'s reader: counted once in ``rejected_requests``, STALLed when a SET,
    INVALID_REQUEST flagged when an output report, SESSION_BUSY flagged. The reports read
    after it are added to ``found.states``; returns what was wrong (empty: refused as PN13
    says), the caller deciding whether it counts (:func:`judge_requests`)."""
    reader = fed.reader
    before = reader.counters().rejected_requests
    lost_before = reader.reports_lost
    stalled = request.send(sender)

    def shows_count(states: list[State]) -> bool:
        return any(s.rejected_requests != before % _U16 for s in states)

    states = fed.read(SETTLE_S)
    if not shows_count(states):
        states += fed.read(COUNT_WAIT_S + read_lag_s, shows_count)
    found.states = states
    moved = counted(reader.counters().rejected_requests, before)
    lost = reader.reports_lost - lost_before
    wrong = []
    if moved != 1:
        wrong.append(f"counted {moved} times in rejected_requests, not once")
    if request.feature and not stalled:
        wrong.append("answered, not STALLed (PE1)")
    flags = [(FaultBits.SESSION_BUSY, "SESSION_BUSY")]
    if not request.feature:
        flags.append((FaultBits.INVALID_REQUEST, "INVALID_REQUEST (PE2)"))
    for bit, name in flags:
        if not any(s.faults & bit for s in states):
            if lost:  # the one report that carries the flag may be among those lost
                found.not_kept.append(f"the reader lost {lost} reports after {request.name}, "
                                      f"so its {name} flag could not be seen")
            else:
                wrong.append(f"not flagged {name}")
    return [f"{request.name}: {', '.join(wrong)}"] if wrong else []


def judge_requests(requests: list[Request], sender: Driver, fed: Fed, found: Judged,
                   session: tuple[int, int], watchdog_s: float, read_lag_s: float) -> int:
    """Judge each of ``requests`` in turn (:func:`judge_refused`) while ``session`` (number,
    token) is live; returns how many were judged. When the reports after a request show the
    session ended or changed, the judging stops there: the request did it (a problem), unless
    the feeding host was starved meanwhile (:func:`starved`), when its session may have ended
    by PN7 and nothing is judged of that request (the run is not kept)."""
    number, token = session
    for judged, request in enumerate(requests, start=1):
        wrong = judge_refused(request, sender, fed, found, read_lag_s)
        ended = session_changed(found.states, number, token)
        if ended is None and not fed.lost:
            found.problems += wrong
            continue
        how = fed.lost or (
            f"session {number} (token {token}) shows as session {ended.session_number}, "
            f"token {ended.session_token}, flag SESSION {int(ended.session_live)}"
            if ended is not None else "")
        why = starved(fed, watchdog_s, found.states)
        if why:  # ended by the feeding host's own silence (PN7): nothing to judge
            found.not_kept.append(f"{why}; after {request.name}, {how}")
        else:
            found.problems += wrong
            found.problems.append(f"after {request.name}, {how}")
        return judged
    return len(requests)


def session_changed(states: list[State], number: int, token: int) -> State | None:
    """The first of ``states`` that does not show session ``number`` of ``token`` live."""
    return next((s for s in states if not s.session_live or s.session_number != number
                 or s.session_token != token), None)


def starved(fed: Fed, watchdog_s: float, states: list[State]) -> str:
    """Why the owner's session may have ended by its own silence (PN7), empty when it was fed
    in time: the host did not run, the KEEPALIVEs left a gap of ``watchdog_s``, or the device
    fell behind its clock."""
    return reasons(fed.watch.late, device_lag(states),
                   f"the owner's KEEPALIVEs left a gap of {fed.longest_gap_s * MS_PER_S:.0f} ms"
                   if fed.longest_gap_s >= watchdog_s else "")


@contextlib.contextmanager
def two_connections(open_driver: Callable[[], Driver]) -> Iterator[tuple[Driver, Driver]]:
    """The owner's driver and another connection's, each opened on the implementation's URI
    (the second one closed first)."""
    with open_driver() as owner, open_driver() as other:
        yield owner, other


def no_sessions(owner: Driver, case: str, metric: str, unit: str) -> CheckResult | None:
    """The case's FAIL on a device without sessions (protocol before 1.2): it has none to
    attribute (PN12); None on a device with sessions."""
    if owner.sessions_supported():
        return None
    info = owner.info()
    return measured(CHECK, LEVEL, case, metric, math.inf, 0.0, unit=unit, detail=(
        f"the device speaks protocol {info.protocol_major}.{info.protocol_minor}: no sessions, "
        "so none is attributed to a connection (PN12) and another connection's requests are "
        "carried out (PN13)"))


# ---------------------------------------------------------------------- cases

def case_other_connection_refused(open_driver: Callable[[], Driver],
                                  read_lag_s: float = 0.0) -> CheckResult:
    """``other-connection-refused`` (module docstring; rules PN12, PN13)."""
    case = CONNECTION_CASES[0]
    found = Judged()
    with two_connections(open_driver) as (owner, other), HostWatch() as watch:
        if (failed := no_sessions(owner, case, "mishandled_requests", "requests")) is not None:
            return failed
        info = owner.info()
        watchdog_s = info.watchdog_ms / MS_PER_S
        finger = bool(info.capabilities & Capability.HOST_FINGER)
        owner.start()
        number, token = owner.session_number, owner.session_token
        assert number is not None and token is not None  # granted, or start() raised
        fed = Fed(owner, other, watchdog_s * FEED_FRACTION, watch)
        echo = send_finger(owner, info) if finger else 0
        fed.read(SETTLE_S)
        # GETs of another connection: answered, counted nowhere (PN13)
        rejected = other.counters().rejected_requests
        got: dict[type[Report], Report] = {}
        for cls in GETS:
            try:
                got[cls] = other.get_report(cls)
            except DeviceStall:
                found.problems.append(f"GET {cls.name()}: STALLed (PN13: answered whoever "
                                      "asks)")
            fed.feed()
        moved = counted(other.counters().rejected_requests, rejected)
        if moved:
            found.problems.append(f"the GETs were counted {moved} times in rejected_requests")
        limits = got.get(Limits) or other.limits()
        upload = got.get(UploadStatus) or other.upload_status()
        clip = got.get(ClipReport) or other.clip_report()
        assert isinstance(limits, Limits) and isinstance(clip, ClipReport)
        requests = other_requests(info, token, limits, clip, host_time_us(other))
        judged = judge_requests(requests, other, fed, found, (number, token), watchdog_s,
                                read_lag_s)
        fed.read(SETTLE_S)
        after_limits, after_upload = other.limits(), other.upload_status()
        states = fed.read(SETTLE_S)
        if after_limits != limits:
            found.problems.append(f"LIMITS changed from {limits} to {after_limits}")
            with contextlib.suppress(DeviceError):  # leave the device as found
                owner.set_report(limits)
        if after_upload != upload:
            found.problems.append(f"UPLOAD_STATUS changed from {upload} to {after_upload}")
            with contextlib.suppress(DeviceError):
                owner.abort_upload()
        if finger and states and states[-1].host_time_echo_us != echo:
            found.problems.append(f"the reports echo host time {states[-1].host_time_echo_us}"
                                  f" us, not the owner's FINGER ({echo} us)")
        with contextlib.suppress(DeviceError):
            owner.stop()
    if found.not_kept and not found.problems:
        raise NotKept(reasons(*found.not_kept))
    detail = "; ".join(found.problems) or (
        f"{judged} requests of another connection refused during session {number} (each "
        f"counted once, flagged SESSION_BUSY, the SETs STALLed), its {len(GETS)} GETs "
        f"answered; LIMITS, UPLOAD_STATUS and the owner's session unchanged")
    return measured(CHECK, LEVEL, case, "mishandled_requests", len(found.problems), 0,
                    unit="requests", detail=detail)


def device_elapsed_s(later: State, earlier: State) -> float:
    """Device time from ``earlier`` to ``later`` (their ``timestamp_us``, wrapping u32), s."""
    return ((later.timestamp_us - earlier.timestamp_us) % _U32) * S_PER_US


def case_ends_despite_other_connection(open_driver: Callable[[], Driver],
                                       margin_s: float) -> CheckResult:
    """``ends-despite-other-connection`` (module docstring; rules PN13, PN7, PS3).
    ``margin_s``: O4's margin past ``watchdog_ms``. Timed on the device's clock: the host's
    read lag is not in the figure, and a host too late to read past the bound is a run not
    kept."""
    case = CONNECTION_CASES[1]
    with two_connections(open_driver) as (owner, other), HostWatch() as watch:
        if (failed := no_sessions(owner, case, "time_to_end", "ms")) is not None:
            return failed
        info = owner.info()
        watchdog_s = info.watchdog_ms / MS_PER_S
        limit_s = watchdog_s + margin_s
        host_driven = bool(info.capabilities & Capability.HOST_FINGER)
        trips = other.counters().watchdog_trips
        if host_driven:  # before START, which is then the owner's last report
            send_finger(owner, info)
        owner.start()
        granted, number = owner.granted_state, owner.session_number
        assert granted is not None and number is not None
        fed = Fed(other, other, watchdog_s * FEED_FRACTION, watch)
        feeding_s = watchdog_s * OTHER_FEEDS_UNTIL
        seen: list[State] = []
        ended: State | None = None
        wall_end = other.clock() + limit_s + COUNT_WAIT_S + READ_CATCH_UP_S
        while ended is None and other.clock() < wall_end:
            newest_s = device_elapsed_s(seen[-1], granted) if seen else 0.0
            if newest_s > limit_s:
                break  # still live past the bound, on the device's own clock
            if newest_s < feeding_s:
                fed.feed()
                other.get_report(Counters)  # a GET of another connection feeds nothing
            else:
                fed.stop_feeding()
            watch.tick()
            for state in other.collect_until(other.clock() + SLICE_S):
                if state.session_number != number or device_elapsed_s(state, granted) > 1.0:
                    continue  # a report of before the START
                seen.append(state)
                if not state.session_live:
                    ended = state
                    break
        fed.stop_feeding()
        tripped = other.counters().watchdog_trips != trips or any(
            s.faults & FaultBits.WATCHDOG for s in seen)
    late = reasons(watch.late, device_lag(seen))
    if fed.longest_gap_s > watchdog_s / 2:
        raise NotKept(reasons(late, f"the second connection's KEEPALIVEs left a gap of "
                                    f"{fed.longest_gap_s * MS_PER_S:.0f} ms (PS3: at most "
                                    "watchdog_ms / 2): the run did not test the rule"))
    newest_s = device_elapsed_s(seen[-1], granted) if seen else 0.0
    if ended is None and newest_s <= limit_s:
        raise NotKept(reasons(late, f"the host read reports up to {newest_s * MS_PER_S:.0f} ms "
                                    f"of device time after the START in {READ_CATCH_UP_S:g} s"))
    problems = []
    value = math.inf
    if ended is None:
        problems.append(f"flag SESSION still set {newest_s * MS_PER_S:.0f} ms of device time "
                        "after the owner's START, its last report, while another connection "
                        f"sent KEEPALIVE until {feeding_s * MS_PER_S:.0f} ms (PN13, PN7)")
    else:
        value = device_elapsed_s(ended, granted) * MS_PER_S
    if host_driven and not tripped:
        problems.append("the watchdog did not trip: another connection's KEEPALIVEs fed it "
                        "(PS3, PN13)")
        value = math.inf
    detail = "; ".join(problems) or (
        f"session {number} ended {value:.0f} ms of device time after the owner's START "
        f"(watchdog_ms {info.watchdog_ms}) though another connection sent KEEPALIVE and GET "
        f"COUNTERS, at most {fed.longest_gap_s * MS_PER_S:.0f} ms apart, until "
        f"{feeding_s * MS_PER_S:.0f} ms" + ("; the watchdog tripped" if host_driven else ""))
    return measured(CHECK, LEVEL, case, "time_to_end", value, limit_s * MS_PER_S, unit="ms",
                    detail=detail)


def case_takeover_attributed(open_driver: Callable[[], Driver],
                             read_lag_s: float = 0.0) -> CheckResult:
    """``takeover-attributed`` (module docstring; rules PN6, PN12)."""
    case = CONNECTION_CASES[2]
    found = Judged()
    with two_connections(open_driver) as (former, owner), HostWatch() as watch:
        if (failed := no_sessions(owner, case, "mishandled_requests", "requests")) is not None:
            return failed
        info = owner.info()
        watchdog_s = info.watchdog_ms / MS_PER_S
        former.start()
        previous = former.session_number
        try:
            owner.take_over()
        except DeviceError as exc:
            return measured(CHECK, LEVEL, case, "mishandled_requests", math.inf, 0,
                            unit="requests", detail=f"TAKE_OVER from another connection "
                                                    f"was not granted (PN6): {exc}")
        number, token = owner.session_number, owner.session_token
        assert number is not None and token is not None
        fed = Fed(owner, owner, watchdog_s * FEED_FRACTION, watch)
        fed.read(SETTLE_S)
        before = owner.counters()
        owner.send_raw(Control(Command.KEEPALIVE).encode())
        fed.read(SETTLE_S)
        after = owner.counters()
        if counted(after.rejected_requests, before.rejected_requests):
            found.problems.append("the new owner's own KEEPALIVE was refused: the session "
                                  "is not attributed to the connection of its TAKE_OVER")
        limits = owner.limits()
        requests = [
            Request("the former owner's CONTROL KEEPALIVE", Control(Command.KEEPALIVE)),
            Request("the former owner's CONTROL START with the new owner's token",
                    Control(Command.START, token)),
            Request("the former owner's SET LIMITS",
                    Limits(limits.max_amplitude_nm // 2, limits.max_voltage_dv // 2,
                           limits.max_current_10na // 2), feature=True),
            Request("the former owner's CONTROL STOP with the new owner's token",
                    Control(Command.STOP, token)),
        ]
        judge_requests(requests, former, fed, found, (number, token), watchdog_s, read_lag_s)
        if owner.limits() != limits:
            found.problems.append("the former owner's SET LIMITS changed the limits")
            with contextlib.suppress(DeviceError):
                owner.set_report(limits)
        with contextlib.suppress(DeviceError):
            owner.stop()
        with contextlib.suppress(SessionLost):  # its driver learns of the loss (PN9) and
            former.collect_until(former.clock() + SETTLE_S)  # sends no STOP on closing
    if found.not_kept and not found.problems:
        raise NotKept(reasons(*found.not_kept))
    detail = "; ".join(found.problems) or (
        f"session {previous} taken over by another connection as session {number}: its "
        f"KEEPALIVE carried out, the former owner's {len(requests)} requests refused (each "
        "counted once, flagged SESSION_BUSY, the SET STALLed)")
    return measured(CHECK, LEVEL, case, "mishandled_requests", len(found.problems), 0,
                    unit="requests", detail=detail)


def _halt(driver: Driver, endpoint: int, halted: bool) -> None:
    """SET_FEATURE or CLEAR_FEATURE(ENDPOINT_HALT) from ``driver`` (:data:`HALT_METHODS`)."""
    getattr(driver, "set_endpoint_halt")(endpoint, halted)  # noqa: B009


def _halted(driver: Driver, endpoint: int) -> bool:
    """GET_STATUS of ``endpoint`` as ``driver``'s connection sees it."""
    return bool(getattr(driver, "endpoint_halted")(endpoint))  # noqa: B009


def case_halts_per_connection(open_driver: Callable[[], Driver]) -> CheckResult:
    """``halts-per-connection`` (module docstring; rule PN14)."""
    problems: list[str] = []
    with two_connections(open_driver) as (owner, other), HostWatch() as watch:
        watchdog_s = owner.info().watchdog_ms / MS_PER_S
        owner.start()
        fed = Fed(owner, owner, watchdog_s * FEED_FRACTION, watch)
        fed.read(SETTLE_S)
        _halt(other, OUT_ENDPOINT, True)
        if not _halted(other, OUT_ENDPOINT):
            problems.append("the halting connection's GET_STATUS does not show its OUT pipe "
                            "halted")
        if _halted(owner, OUT_ENDPOINT):
            problems.append("the owner's GET_STATUS shows its OUT pipe halted by another "
                            "connection")
        before = owner.counters().output_reports
        for _ in range(OWNER_FEEDS):
            with contextlib.suppress(DeviceStall):  # STALLed: not carried out, counted below
                owner.send_raw(Control(Command.KEEPALIVE).encode())
        carried = counted(owner.counters().output_reports, before)
        if carried < OWNER_FEEDS:
            problems.append(f"{carried} of the owner's {OWNER_FEEDS} KEEPALIVEs carried out "
                            "while another connection's OUT pipe was halted")
        try:
            other.send_raw(Control(Command.KEEPALIVE).encode())
        except DeviceStall:
            pass
        else:
            problems.append("the halting connection's KEEPALIVE was not STALLed on its halted "
                            "OUT pipe")
        getattr(owner, "set_configuration")()  # noqa: B009
        if not _halted(other, OUT_ENDPOINT):
            problems.append("the owner's SET_CONFIGURATION cleared another connection's halt")
        _halt(other, OUT_ENDPOINT, False)
        if _halted(other, OUT_ENDPOINT):
            problems.append("CLEAR_FEATURE(ENDPOINT_HALT) left the OUT pipe halted")
        fed.read(SETTLE_S)
        try:
            _halt(other, IN_ENDPOINT, True)
        except DeviceStall as exc:  # its own IN URBs STALL at once: the halt took effect
            if "interrupt IN" not in str(exc):
                raise
        if _halted(owner, IN_ENDPOINT):
            problems.append("the owner's GET_STATUS shows its IN pipe halted by another "
                            "connection")
        states = fed.read(IN_HALT_READ_S)
        advance = ((states[-1].sequence - states[0].sequence) % _U16) if states else 0
        if advance < MIN_REPORTS_AFTER:
            problems.append(f"the owner's STATE sequence advanced by {advance} in "
                            f"{IN_HALT_READ_S * MS_PER_S:.0f} ms while another connection's "
                            f"IN pipe was halted (at least {MIN_REPORTS_AFTER})")
        with contextlib.suppress(DeviceError):
            owner.stop()
    late = reasons(watch.late, device_lag(states))
    if problems and late and all("advanced" in p for p in problems):
        raise NotKept(reasons(late, *problems))
    detail = "; ".join(problems) or (
        f"another connection's OUT halt: its own GET_STATUS halted, its KEEPALIVE STALLed, "
        f"the owner's {OWNER_FEEDS} KEEPALIVEs carried out and its SET_CONFIGURATION left "
        f"the halt; its IN halt: the owner's sequence advanced by {advance} in "
        f"{IN_HALT_READ_S * MS_PER_S:.0f} ms")
    return measured(CHECK, LEVEL, HALT_CASE, "shared_pipe_effects", len(problems), 0,
                    unit="effects", detail=detail)


# ---------------------------------------------------------------------- bounded connections

@dataclass(frozen=True)
class Beside:
    """One run of a PN15 case: what the well-behaved connection received alone and beside
    the hostile client, and how late the host ran meanwhile.

    Attributes:
        alone, beside: the two measurements.
        late_alone, late_beside: why the host did not keep real time during each (empty when
            it did).
        hostile: what the hostile client did (``connections``, ``refused``, ``urbs``,
            ``held``).
    """

    alone: usbip_clients.Delivery
    beside: usbip_clients.Delivery
    late_alone: str = ""
    late_beside: str = ""
    hostile: dict[str, int] = field(default_factory=dict)


def measure_beside(server: tuple[str, int], kind: str, seconds: float = BOUND_MEASURE_S,
                   settle_s: float = BESIDE_SETTLE_S) -> Beside:
    """The well-behaved client's delivery alone, then beside the hostile client ``kind`` in a
    process of its own (:func:`hcard_conformance.usbip_clients.hostile_process`), read at the
    real-time priority where permitted, each under a :class:`HostWatch`."""
    host, port = server
    stats: dict[str, int] = {}

    @contextlib.contextmanager
    def hostile() -> Iterator[None]:
        with usbip_clients.hostile_process(kind, host, port) as found:
            yield
        stats.update(found)

    with usbip_clients.real_time_thread():
        with HostWatch() as watch:
            alone = usbip_clients.measure_delivery(host, port, seconds)
        late_alone = watch.late
        with HostWatch() as watch:
            beside = usbip_clients.measure_delivery(host, port, seconds, beside=hostile,
                                                    beside_settle_s=settle_s)
        late_beside = watch.late
    return Beside(alone, beside, late_alone, late_beside, stats)


def judge_beside(case: str, run: Beside, share: float = DELIVERY_SHARE) -> CheckResult:
    """``run``'s result for ``case`` (O9): the share beside over the share alone, at least
    ``share``, and no arrival gap of :data:`MAX_ARRIVAL_GAP_S`.

    Raises:
        NotKept: the alone measurement shows the host could not keep real time, or the case
            failed while the host did not run beside the hostile client (QT3).
    """
    alone, beside = run.alone, run.beside
    low = (f"alone, the client received {alone.fraction:.3f} of the reports (under "
           f"{MIN_ALONE_SHARE:g})" if alone.fraction < MIN_ALONE_SHARE else "")
    if why := reasons(low, run.late_alone):
        raise NotKept(why)
    ratio = (beside.received * alone.seconds) / (alone.received * beside.seconds)  # exact
    gap_s = beside.max_arrival_gap_ms / MS_PER_S
    found = (f"{beside.fraction:.3f} of the 1000 reports a second beside the client, "
             f"{alone.fraction:.3f} alone: {ratio:.3f} of its share (at least {share:g}); "
             f"longest gap {beside.max_arrival_gap_ms:.0f} ms")
    problems = []
    if ratio < share:
        problems.append("the share fell by more than the stated fraction")
    if gap_s >= MAX_ARRIVAL_GAP_S:
        problems.append(f"the STATE stream stopped for {gap_s:.1f} s "
                        f"(gaps must stay under {MAX_ARRIVAL_GAP_S:g} s)")
    if problems and run.late_beside:
        raise NotKept(reasons(run.late_beside, f"the case failed so: {found}"))
    did = ", ".join(f"{k} {v}" for k, v in sorted(run.hostile.items()))
    lag = (f"; the device flagged {beside.lagged} of them REALTIME_LAG (PI4)"
           if beside.lagged else "")
    detail = f"{found}{lag}" + (f"; {'; '.join(problems)} (PN15)" if problems else "") + (
        f"; the hostile client: {did}" if did else "")
    result = measured(CHECK, LEVEL, case, "delivery_share", ratio, share, unit="ratio",
                      detail=detail, higher_is_better=True)
    return dataclasses.replace(result, passed=not problems, outcome="")  # outcome from passed


def case_beside(open_driver: Callable[[], Driver], case: str,
                share: float = DELIVERY_SHARE) -> CheckResult:
    """One PN15 case (module docstring; rule PN15, O9), on the server of a driver opened on
    the implementation's URI and held open meanwhile (it reads nothing: its IN URBs complete
    and none is parked again), so that a device served while it has a client stays served."""
    with open_driver() as holder:
        server = usbip_server(holder)
        if server is None:
            raise CannotAssess(f"{holder.uri} names no USB/IP server reached over TCP: raw "
                               "clients cannot misbehave beside the driver")
        return judge_beside(case, measure_beside(server, BOUND_CASES[case]), share)
