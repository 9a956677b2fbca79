"""Check ``device.session-ownership`` (O1-O3): session ownership between two hosts on one
device (spec/device-protocol.md section 14).

``device.session-ownership``
    Two hosts on one device. The check opens two drivers on the implementation's URI and first
    makes sure they reach the same device: the second reads COUNTERS ``output_reports``
    before and after the first sends :data:`PROBE_KEEPALIVES` KEEPALIVEs. When it does not
    move by that much the two drivers reach two devices: ``sim://`` opens a new device for
    every driver, and there the second host is ``SimDriver.another_host()`` on the first's
    device (same clock, every report to both, in simulated time), which must pass the same
    probe; a driver that cannot attach one, whose ``another_host()`` fails or reaches another
    device, makes every case UNASSESSED with that reason. What the second host raises while
    the first plays is the cases' ERROR, naming its cause. Cases:

    ``second-host-refused``
        The first host plays a :data:`PLAY_S` stroke (:func:`hcard.device.play.play`);
        :data:`INTRUDE_S` after its START, the second host sends START with another token and
        uploads another card. Metric: the intrusions the device carried out (a START not
        refused with SESSION_BUSY or that changed the session, PN3; an upload not refused, its
        COMMIT with BUSY, PN5, or, on a device that attributes sessions to connections, its
        first report with SESSION_BUSY, PN13; the first host's play failing, its last report
        not echoing its last finger sample, more than :data:`MAX_LOST` of its reports lost,
        or its reports showing another session or card); must be 0. A START whose flag the
        second host could not see, having lost reports after it, is a run not kept (spec/
        conformance.md QT3): the one report that carries the flag may be among those lost.
    ``takeover-reported``
        As above, but the second host sends TAKE_OVER (PN6) and keeps its session fed. Metric:
        time from the TAKE_OVER to the first host's play raising
        :class:`~hcard.device.errors.SessionLost` (PN9), ms (infinite when it never
        does); threshold :data:`LOSS_THRESHOLD_S`, plus the host read lag of the timing class
        when it does not keep real time (the first host learns of the loss from a report).
    ``released-by-stop``
        The first host starts and stops (PN4) and stays connected; the second host then
        starts. Pass: its START is granted and STATE shows its token in the next session
        (``session_number`` + 1, PN1, PN2).
    ``ends-when-silent``
        The first host starts and then sends nothing at all; the second host only reads. Pass
        (PN7): within ``watchdog_ms`` + :data:`SILENCE_MARGIN_S` (plus the timing class's read
        lag) of the silence a report shows flag SESSION cleared with the first host's
        ``session_number``, and the second host's START is then granted the next session.
        Metric: the time from the first host's last report to the second host reading that
        report, ms.

Where the driver opens a connection of its own that the device tells apart
(:attr:`hcard.device.base.Driver.separate_connections`: USB/IP), the check also names the
cases of :mod:`hcard_conformance.device_checks.connections` (rules PN12-PN15):
``other-connection-refused``, ``ends-despite-other-connection``, ``takeover-attributed``,
where the driver offers the standard endpoint requests ``halts-per-connection`` and, where its
URI reaches a USB/IP server over TCP, the cases of bounded connections (rule PN15)
``beside-non-reader``, ``beside-urb-flood``, ``beside-giant-transfer``, ``beside-out-flood``
and ``beside-idle-importers``.
"""

from __future__ import annotations

import contextlib
import functools
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

from hcard import build
from hcard.device.base import Driver
from hcard.device.errors import DeviceError, SessionBusy, SessionLost
from hcard.device.play import play
from hcard.device.play_result import PlayResult
from hcard.device.protocol import Command, Control, DeviceInfo, FaultBits, State, StateFlags
from hcard.quantities import MS_PER_S
from hcard.track import FingerTrack, straight_stroke
from hcard.v1 import card_pb2 as pb
from hcard_conformance.check_names import DEVICE_SESSION_OWNERSHIP as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks import connections as conn
from hcard_conformance.device_checks.common import LEVEL
from hcard_conformance.realtime import HostWatch, NotKept, attempted_case, device_lag, reasons
from hcard_conformance.result import CannotAssess, CheckResult, guarded, measured
from hcard_conformance.timing import timing_class

CASES = ("second-host-refused", "takeover-reported", "released-by-stop", "ends-when-silent")
"""The cases of every implementation the check applies to; :func:`session_case_names` adds
those of connections (:mod:`~hcard_conformance.device_checks.connections`)."""
PROBE_KEEPALIVES = 5
"""KEEPALIVEs the first driver sends to show the second one shares its device."""
PLAY_S = 1.5
"""Length of the first host's stroke, s."""
STROKE_SPEED_MM_S = 30.0
"""Finger speed of the stroke, mm/s (45 mm over :data:`PLAY_S`)."""
INTRUDE_S = 0.4
"""Time after the first host's START at which the second host acts, s."""
SESSION_WAIT_S = 10.0
"""Longest wait for the first host's START (its profile and card upload come first), s: a
software-emulated guest (the QEMU tier) took over 2 s for them once card validation imported
numpy on first use inside the play; a passing run waits only as long as the upload takes."""
MAX_LOST = 0.05
"""Largest fraction of the first host's STATE reports that may be lost in transit (sequence
gaps, PT5) for its recording to count as complete."""
LOSS_THRESHOLD_S = 0.25
"""Longest time from a TAKE_OVER to the former owner's driver reporting the loss, s."""
SILENCE_MARGIN_S = 0.05
"""Time past ``watchdog_ms`` of host silence in which a report must show the session ended
(PN7), s: the watchdog's own margin (spec S2)."""
SETTLE_S = 0.05
"""Reports read after a request before judging its effect, s."""


@dataclass
class Background:
    """A play session of the first host, during which the second host acts (``intrude``):
    its result, or the error it raised and when (the first driver's clock, s).

    On a real-time driver the play runs on a thread and ``intrude`` on the caller's, on the
    wall clock; on ``sim://`` (simulated time) ``intrude`` runs inside the play, between two
    steps of the shared device (:meth:`hcard_device.sim_driver.SharedDevice.call_when`)."""

    driver: Driver
    card: pb.Card
    track: FingerTrack
    result: PlayResult | None = None
    error: BaseException | None = None
    error_at: float = math.nan

    def _run(self) -> None:
        try:
            self.result = play(self.driver, self.card, self.track)
        except Exception as exc:  # reported by the case, never lost
            self.error, self.error_at = exc, self.driver.clock()

    def run(self, intrude: Callable[[], None]) -> None:
        """Play, and call ``intrude`` :data:`INTRUDE_S` after the first host's START took
        effect (:meth:`_rendering`).

        Raises:
            CannotAssess: the first host's play never started (its error is the reason)."""
        if self.driver.realtime:
            self._run_realtime(intrude)
        else:
            self._run_simulated(intrude)

    def _run_realtime(self, intrude: Callable[[], None]) -> None:
        thread = threading.Thread(target=self._run, name="session-check-first-host",
                                  daemon=True)
        thread.start()
        deadline = time.monotonic() + SESSION_WAIT_S
        while not self._rendering() and thread.is_alive() and time.monotonic() < deadline:
            time.sleep(0.002)
        if not self._rendering():
            thread.join(PLAY_S + 10.0)
            raise CannotAssess(f"the first host's play did not start: {self.error}")
        time.sleep(INTRUDE_S)
        try:
            intrude()
        finally:
            thread.join(PLAY_S + 10.0)

    def _run_simulated(self, intrude: Callable[[], None]) -> None:
        """``intrude`` runs inside the first host's play (between two device steps): what it
        raises is kept apart from the play and raised here once the play ends (it once became
        the first host's play error, and the case an IndexError)."""
        seen: list[float] = []
        acted: list[BaseException | None] = []

        def due() -> bool:
            if not seen and self._rendering():
                seen.append(self.driver.clock())
            return bool(seen) and self.driver.clock() >= seen[0] + INTRUDE_S

        def act() -> None:
            try:
                intrude()
            except Exception as exc:  # the second host's, not the first host's play's
                acted.append(exc)
            else:
                acted.append(None)

        self.driver.device.call_when(due, act)  # type: ignore[attr-defined]
        self._run()
        if not seen:
            raise CannotAssess(f"the first host's play did not start: {self.error}")
        if not acted:
            raise CannotAssess(
                f"the second host never acted: the first host's play ended "
                f"{self.driver.clock() - seen[0]:.3f} s after its START took effect, before "
                f"{INTRUDE_S:g} s" + (f" ({self.error})" if self.error is not None else ""))
        if acted[0] is not None:
            raise acted[0]

    def _rendering(self) -> bool:
        """The first host's START took effect: RUNNING in its reports, and its session
        granted (a device without sessions reports session 0)."""
        state = self.driver.last_state
        if state is None or not state.flags & StateFlags.RUNNING:
            return False
        return self.driver.session_number is not None or state.session_number == 0


@dataclass(frozen=True)
class Hosts:
    """How the check puts a second host on the first host's device.

    Attributes:
        open_driver: opens the first host's driver.
        shared_uri: two drivers opened with ``open_driver`` reach one device (USB/IP, hidraw);
            otherwise the second host is the first driver's ``another_host()`` (``sim://``).
    """

    open_driver: Callable[[], Driver]
    shared_uri: bool

    def second(self, first: Driver) -> Driver:
        """A new driver of a second host on ``first``'s device."""
        if self.shared_uri:
            return self.open_driver()
        return first.another_host()  # type: ignore[attr-defined]


def stroke_card(info: DeviceInfo, uv: float) -> pb.Card:
    """A card over the whole surface: friction 1 on the left half, ``uv`` on the right."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    return build.card(width, height, taxtel_mm=(width / 2, height), textures=[
        build.texture(1.0, channel="uv"), build.texture(uv, channel="uv")], texture_index=[0, 1])


def stroke_track(info: DeviceInfo) -> FingerTrack:
    """A :data:`PLAY_S` stroke from a quarter of the surface's width along +x."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    return straight_stroke((width / 4, height / 2), (STROKE_SPEED_MM_S, 0.0), PLAY_S)


def other_token(token: int) -> int:
    """A session token 1..255 that is not ``token``."""
    return token % 255 + 1


def latest_state(driver: Driver) -> State:
    """The newest STATE report the driver can read (waiting up to its timeout for one).

    Raises:
        DeviceError: no report arrived.
    """
    states = driver.read_inputs()
    if not states:
        raise DeviceError(f"{driver.uri}: no STATE report within {driver.timeout_s:g} s")
    return states[-1]


def shares_device(first: Driver, second: Driver) -> int:
    """How far ``second``'s COUNTERS ``output_reports`` moves while ``first`` sends
    :data:`PROBE_KEEPALIVES` KEEPALIVEs: at least that many when they reach one device."""
    before = second.counters().output_reports
    for _ in range(PROBE_KEEPALIVES):
        first.keepalive()
    return int((second.counters().output_reports - before) % (1 << 32))


def two_hosts(open_driver: Callable[[], Driver]) -> Hosts:
    """How to reach one device from two hosts; CannotAssess when the transport cannot.

    Two drivers opened with ``open_driver`` share a device when the second one's COUNTERS
    ``output_reports`` moves by the first one's :data:`PROBE_KEEPALIVES` KEEPALIVEs
    (:func:`shares_device`); otherwise the first driver's ``another_host()``, when it has one,
    must pass the same probe: a driver whose second host fails to attach, or reaches another
    device, cannot put two hosts on one device (the cases once crashed with IndexError, or
    failed the device for intrusions into a device nobody else was using)."""
    with open_driver() as first, open_driver() as second:
        moved = shares_device(first, second)
        attachable = callable(getattr(first, "another_host", None))
    if moved >= PROBE_KEEPALIVES:
        return Hosts(open_driver, True)
    cannot = (f"two drivers opened on this URI reach two devices (the second saw output_reports "
              f"move by {moved} for the first's {PROBE_KEEPALIVES} KEEPALIVEs)")
    advice = ("this transport cannot put two hosts on one device; run the check on usbip:// or "
              "hid://")
    if not attachable:
        raise CannotAssess(f"{cannot} and the driver cannot attach a second host to its "
                           f"device: {advice}")
    with open_driver() as first:
        try:
            attached = first.another_host()  # type: ignore[attr-defined]
        except Exception as exc:
            raise CannotAssess(f"{cannot} and the driver's another_host() failed "
                               f"({type(exc).__name__}: {exc}): {advice}") from exc
        with attached:
            moved = shares_device(first, attached)
    if moved < PROBE_KEEPALIVES:
        raise CannotAssess(f"{cannot}, and so does the driver's another_host() (it saw "
                           f"output_reports move by {moved}): {advice}")
    return Hosts(open_driver, False)


def session_faults(first: Background, owner: State, max_lost: float = MAX_LOST) -> list[str]:
    """What went wrong for the first host of ``second-host-refused`` (empty when its play
    completed up to its last finger sample with at most ``max_lost`` of its reports lost,
    and stayed in session ``owner.session_number`` with one card)."""
    if first.error is not None:
        return [f"the first host's play failed: {first.error}"]
    result = first.result
    if result is None:
        return ["the first host's play did not end"]
    problems = []
    last_sample = int(result.sent_host_us()[-1])
    if not result.states or result.states[-1].host_time_echo_us != last_sample:
        problems.append("the first host's last report does not echo its last finger sample: "
                        "its recording stops short of the track")
    sent = len(result.states) + result.reports_lost
    if not sent or result.reports_lost > max_lost * sent:
        problems.append(f"the first host lost {result.reports_lost} of {sent} reports")
    late = [s for s in result.states if s.timestamp_us >= owner.timestamp_us]
    generations = sorted({s.card_generation for s in late})
    if len(generations) > 1:
        problems.append(f"the card changed under the first host's play (generations "
                        f"{generations})")
    sessions = sorted({s.session_number for s in late})
    if len(sessions) > 1:
        problems.append(f"the first host's reports show sessions {sessions}")
    return problems


def case_second_host_refused(hosts: Hosts, max_lost: float = MAX_LOST,
                             keeps_real_time: bool = True) -> CheckResult:
    """``second-host-refused`` (module docstring; rules PN3, PN5). ``max_lost``: the fraction
    of its reports the first host may lose (the timing class's host report loss when larger
    than :data:`MAX_LOST`); ``keeps_real_time``: whether the timing class's host keeps real
    time. What the device carried out for the second host fails the case whatever the timing;
    the first host's own troubles (reports lost, a recording cut short) count as intrusions
    only in a run the host and the device kept in real time (spec QT3): otherwise, and always
    for a host of a class that does not keep real time, :class:`NotKept`, and the case is
    measured again."""
    intrusions: list[str] = []
    starved: list[tuple[str, bool]] = []  # why, and whether the device's watchdog tripped
    seen_owner: list[State] = []
    with hosts.open_driver() as first_driver, contextlib.ExitStack() as stack:
        info = first_driver.info()

        def intrude() -> None:
            second = stack.enter_context(hosts.second(first_driver))
            owner = latest_state(second)
            seen_owner.append(owner)
            if not owner.session_live and (owner.faults & FaultBits.WATCHDOG or
                                           second.counters().watchdog_trips != trips_before[0]):
                starved.append((
                    "the first host went silent for watchdog_ms before the second host came "
                    "(WATCHDOG flagged, its session ended by PN7): this host cannot hold a "
                    "session in real time, so the refusals of PN3 and PN5 could not be tested",
                    True))
                return
            if not owner.session_live and owner.session_number != 0:
                # a session of this device ended while its host played, the second host having
                # sent nothing: the first host's silence (PN7) or the device's fault
                starved.append((
                    f"the first host's session {owner.session_number} had ended (flag SESSION "
                    "clear) before the second host sent anything", False))
                return
            if not owner.session_live:
                intrusions.append("no live session in STATE while the first host plays (PN2)")
            lost_before = second.reports_lost
            second.send(Control(Command.START, other_token(owner.session_token)))
            seen = second.collect_until(second.clock() + SETTLE_S)
            if owner.session_live and any(not s.session_live for s in seen):
                starved.append((  # ended (PN7) between the look and the START
                    f"the first host's session {owner.session_number} ended (flag SESSION "
                    "clear) before the second host's START took effect", False))
                return
            lost = second.reports_lost - lost_before
            if not any(s.faults & FaultBits.SESSION_BUSY for s in seen):
                if lost:
                    # the one report that carries the refusal's flag may be among those lost
                    # (a host too slow to read them all): nothing to judge, measured again
                    starved.append((
                        f"the second host lost {lost} of its reports after its START, so "
                        "whether the START was flagged SESSION_BUSY (PN3) could not be seen",
                        False))
                    return
                intrusions.append("the second host's START was not flagged SESSION_BUSY (PN3)")
            if any(s.session_number != owner.session_number for s in seen):
                intrusions.append("the second host's START began a new session (PN3)")
            try:
                second.upload_card(stroke_card(info, 0.2))
                tripped = second.counters().watchdog_trips != trips_before[0]
                # the reports of the SETTLE_S after the COMMIT: a session PN7 ended before it
                # shows not live there (collecting until clock() read none: a host slower than
                # real time then saw an intrusion where its own silence had ended the session);
                # a device without sessions has none to end (its intrusion is PN2's, above)
                during = second.collect_until(second.clock() + SETTLE_S)
                ended = owner.session_live and any(
                    not s.session_live or s.faults & FaultBits.WATCHDOG for s in during)
                if tripped or ended:
                    starved.append((
                        "the first host went silent for watchdog_ms while the second uploaded "
                        "(WATCHDOG flagged, its session ended by PN7 before the COMMIT): this "
                        "host cannot hold a session in real time, so the refusal of PN5 could "
                        "not be tested", True))
                    return
                intrusions.append("the second host's COMMIT replaced the card (PN5)")
            except DeviceError as exc:
                if "BUSY" not in str(exc):
                    intrusions.append(f"the second host's upload failed without BUSY: {exc}")

        # the watchdog trips of this device so far: one more by the intrusion's end means the
        # first host went silent for watchdog_ms (its session ended by PN7), not an intrusion
        trips_before = [first_driver.counters().watchdog_trips]
        first = Background(first_driver, stroke_card(info, 0.4), stroke_track(info))
        with HostWatch() as watch:
            first.run(intrude)
    late = reasons(watch.late if first.driver.realtime else "",
                   device_lag(first.result.states if first.result else []),
                   "" if keeps_real_time else "the host's timing class does not keep real time")
    if starved:
        # the first host's session ended by PN7 (no host report for watchdog_ms) before the
        # second host's requests could be judged: nothing was intruded, and the refusals were
        # not tested; a run not kept (spec QT3), measured again
        why, tripped = starved[0]
        raise NotKept(reasons(late, why, "the device's watchdog tripped" if tripped else ""))
    owner = seen_owner[0]
    own = session_faults(first, owner, max_lost)
    if own and not intrusions and late:
        raise NotKept(f"{late}; the first host saw: {'; '.join(own)}")
    intrusions += own
    if intrusions:
        detail = "; ".join(intrusions)
    else:
        result = first.result
        assert result is not None
        detail = (f"second host: START refused (SESSION_BUSY), upload refused (BUSY); first "
                  f"host: {len(result.states)} reports over {result.duration_s:.3f} s in "
                  f"session {owner.session_number}, card generation "
                  f"{result.upload.status.card_generation} throughout")
    return measured(CHECK, LEVEL, CASES[0], "carried_out_intrusions", len(intrusions), 0,
                    unit="requests", detail=detail)


def case_takeover_reported(hosts: Hosts, read_lag_s: float = 0.0) -> CheckResult:
    """``takeover-reported`` (module docstring; rules PN6, PN9). ``read_lag_s``: how late
    the timing class lets the host read a report (the first host learns of the loss from
    one), added to :data:`LOSS_THRESHOLD_S`. A loss reported too late in a run the host or
    the device did not keep in real time raises :class:`NotKept` (spec QT3); a loss never
    reported fails whatever the timing."""
    took_over: list[tuple[Driver, int, float]] = []
    with hosts.open_driver() as first_driver, contextlib.ExitStack() as stack:
        info = first_driver.info()

        def intrude() -> None:
            second = stack.enter_context(hosts.second(first_driver))
            token = other_token(latest_state(second).session_token)
            second.send(Control(Command.TAKE_OVER, token))
            took_over.append((second, token, second.clock()))

        first = Background(first_driver, stroke_card(info, 0.4), stroke_track(info))
        with HostWatch() as watch:
            first.run(intrude)
        second, token, at = took_over[0]
        second.send(Control(Command.STOP, token))  # the second host ends its session (PN4)
    if isinstance(first.error, SessionLost) and first.driver.realtime and (
            first.error_at < at or "taken over by session" not in str(first.error)):
        # lost before the TAKE_OVER was sent, or for another reason than it: the first host's
        # own silence ended its session (PN7), which says nothing of how a takeover is
        # reported (spec QT3)
        raise NotKept(reasons(watch.late, f"the first host's session was lost "
                              f"{(first.error_at - at) * MS_PER_S:.0f} ms from the TAKE_OVER, "
                              f"not by it: {first.error}"))
    if isinstance(first.error, SessionLost):
        delay_ms = (first.error_at - at) * MS_PER_S
        detail = f"the first host's play raised SessionLost {delay_ms:.1f} ms after TAKE_OVER: "
        detail += str(first.error)
        if delay_ms > (LOSS_THRESHOLD_S + read_lag_s) * MS_PER_S and watch.late and \
                first.driver.realtime:
            raise NotKept(f"{watch.late}; {detail}")
    else:
        delay_ms = math.inf
        outcome = ("completed as if nothing happened" if first.error is None
                   else f"failed otherwise: {first.error}")
        detail = f"the takeover was not reported: the first host's play {outcome}"
    if read_lag_s:
        detail += f"; threshold includes the timing class's host read lag {read_lag_s:g} s"
    return measured(CHECK, LEVEL, CASES[1], "time_to_loss", delay_ms,
                    (LOSS_THRESHOLD_S + read_lag_s) * MS_PER_S, unit="ms", detail=detail)


def case_released_by_stop(hosts: Hosts) -> CheckResult:
    """``released-by-stop`` (module docstring; rules PN1, PN2, PN4)."""
    case = CASES[2]
    with hosts.open_driver() as first, hosts.second(first) as second:
        first.start()
        number = first.session_number
        first.collect_until(first.clock() + SETTLE_S)
        first.stop()
        try:
            second.start()
        except SessionBusy as exc:
            return CheckResult(CHECK, LEVEL, case, False, "granted", 0.0, 1.0, "bool",
                               f"after the first host's STOP: {exc}")
        # The report that granted it: one read later may already show the session ended
        # (PN7) when a slow host reads its reports later than the watchdog period.
        state = second.granted_state or latest_state(second)
        first.collect_until(first.clock() + SETTLE_S)  # the former owner sees it, no error
        granted = (number is not None and second.session_number == (number + 1) % (1 << 16)
                   and state.session_number == second.session_number
                   and state.session_live and state.session_token == second.session_token)
        second.stop()
    if granted:
        detail = (f"session {number} stopped; the second host's START was granted session "
                  f"{state.session_number} (token {state.session_token})")
    else:
        detail = (f"no session granted after the first host's STOP: STATE shows session "
                  f"{state.session_number}, token {state.session_token}, flag SESSION "
                  f"{int(state.session_live)} (first host's session {number}; PN1, PN2)")
    return CheckResult(CHECK, LEVEL, case, granted, "granted", float(granted), 1.0, "bool",
                       detail)


def case_ends_when_silent(hosts: Hosts, read_lag_s: float = 0.0) -> CheckResult:
    """``ends-when-silent`` (module docstring; rules PN7, PN1)."""
    case = CASES[3]
    with hosts.open_driver() as first, hosts.second(first) as second, HostWatch() as watch:
        watchdog_s = first.info().watchdog_ms / MS_PER_S
        limit_s = watchdog_s + SILENCE_MARGIN_S + read_lag_s
        first.start()
        silent_from = first.clock()  # the first host's last report: its START
        number = first.session_number
        ended: State | None = None
        live = False  # the second host's first reports may be from before the START
        while ended is None and second.clock() - silent_from <= limit_s:
            for state in second.collect_until(second.clock() + 0.005):
                live = live or (state.session_live and state.session_number == number)
                if live and not state.session_live and ended is None:
                    ended = state
        waited_s = second.clock() - silent_from
        granted = False
        if ended is not None:
            try:
                second.start()
                granted = second.session_number == ((number or 0) + 1) % (1 << 16)
            except SessionBusy:
                granted = False
            with contextlib.suppress(DeviceError):
                second.stop()
    problems = []
    if ended is None:
        problems.append(f"flag SESSION still set {waited_s * MS_PER_S:.0f} ms into the first "
                        f"host's silence (watchdog_ms {watchdog_s * MS_PER_S:.0f})")
    elif ended.session_number != number:
        problems.append(f"the session ended as number {ended.session_number}, not the first "
                        f"host's {number} (PN7: session_number stays)")
    if ended is not None and not granted:
        problems.append("the second host's START was not then granted the next session (PN1)")
    detail = "; ".join(problems) or (
        f"session {number} ended {waited_s * MS_PER_S:.0f} ms into the first host's silence "
        f"(watchdog_ms {watchdog_s * MS_PER_S:.0f}); the second host was granted the next")
    value = waited_s * MS_PER_S if ended is not None and not problems else math.inf
    result = measured(CHECK, LEVEL, case, "time_to_end", value, limit_s * MS_PER_S, unit="ms",
                      detail=detail)
    late = reasons(watch.late if first.realtime else "")
    if not result.passed and late:  # the second host read late: the run measured the host
        raise NotKept(f"{late}; the case failed so: {detail}")
    return result


def session_case_names(ctx: Context) -> tuple[str, ...]:
    """The cases of ``device.session-ownership`` on ``ctx`` (registry declaration): :data:`CASES`,
    and those of :func:`~hcard_conformance.device_checks.connections.connection_case_names`
    where the device tells connections apart (its driver opened once to ask)."""
    return CASES + conn.connection_case_names(ctx)


def check_session_ownership(ctx: Context) -> Iterator[CheckResult]:
    """Session ownership between two hosts on one device (spec section 14)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver
    timing = timing_class(ctx)
    read_lag_s = 0.0 if timing.keeps_real_time else timing.read_lag_s
    names = session_case_names(ctx)

    max_lost = max(MAX_LOST, timing.host_report_loss)

    def measure() -> Iterator[CheckResult]:
        hosts = two_hosts(open_driver)
        if wants(CASES[0]):
            yield attempted_case(CHECK, LEVEL, CASES[0],
                                 lambda: case_second_host_refused(hosts, max_lost,
                                                                  timing.keeps_real_time))
        if wants(CASES[1]):
            yield attempted_case(CHECK, LEVEL, CASES[1],
                                 lambda: case_takeover_reported(hosts, read_lag_s))
        if wants(CASES[2]):
            yield case_released_by_stop(hosts)
        if wants(CASES[3]):
            yield attempted_case(CHECK, LEVEL, CASES[3],
                                 lambda: case_ends_when_silent(hosts, read_lag_s))
        if not any(wants(case) for case in names[len(CASES):]):
            return
        if not hosts.shared_uri:  # the device tells connections apart, the URI reaches two
            raise CannotAssess("two drivers opened on this URI are two connections to two "
                               "devices: no second connection to the first one's device")
        cases: dict[str, Callable[[], CheckResult]] = {
            conn.CONNECTION_CASES[0]:
                lambda: conn.case_other_connection_refused(open_driver, read_lag_s),
            conn.CONNECTION_CASES[1]:
                lambda: conn.case_ends_despite_other_connection(open_driver, SILENCE_MARGIN_S),
            conn.CONNECTION_CASES[2]:
                lambda: conn.case_takeover_attributed(open_driver, read_lag_s),
            conn.HALT_CASE: lambda: conn.case_halts_per_connection(open_driver),
        }
        share = float(ctx.options.get("delivery_share", conn.DELIVERY_SHARE))
        cases.update({case: functools.partial(conn.case_beside, open_driver, case, share)
                      for case in conn.BOUND_CASES})  # named where the URI is a TCP server
        for case in names[len(CASES):]:
            if wants(case):
                yield attempted_case(CHECK, LEVEL, case, cases[case])

    def wants(case: str) -> bool:
        return ctx.wants(CHECK, case)

    yield from guarded(CHECK, LEVEL, [case for case in names if wants(case)], measure)
