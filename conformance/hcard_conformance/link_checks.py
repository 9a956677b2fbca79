"""Device-level link checks: card upload integrity and input report loss.

Both checks work through the driver's raw reports (spec/device-protocol.md) while the host's
finger plays on the surface, and both are session-relative: they need neither a fresh device nor
its uptime, so they pass twice in a row against one device that stays powered.

``device.upload-integrity`` (spec/conformance.md 4.6, rules U1-U3; protocol PU1-PU4, 9.3, 9.4)
    A known card A is committed and playing (the host's finger circles on the surface; STATE
    reports show A's targets and generation, UPLOAD_STATUS its CRC-32 and generation). Then
    uploads of a card B that the device must refuse, one case each, crafted from raw
    UPLOAD_BEGIN / UPLOAD_DATA / UPLOAD_END reports (:func:`bad_uploads`): ``bad-crc``,
    ``truncated``, ``out-of-order``, ``interrupted`` (2 s of upload silence, then the host
    resumes), ``restarted`` (a new BEGIN, then the old upload's remaining chunks) and
    ``oversize``. A case passes when UPLOAD_STATUS is FAILED with the expected result (U1), A's
    CRC-32 and generation are still active, and every STATE report during and after the attempt
    shows A playing (U2; a neutral frame is excused only when the finger sample it applies came
    after a gap in the finger stream, :func:`off_card`). Last, ``valid-after``: a good upload of
    B still commits and plays, the swap atomic (U3). The device is started with START argument 0
    (an anonymous session on a protocol 1.2 device, where COMMIT works as in 1.1; in a session
    with a token every COMMIT fails with BUSY, PN5). The check leaves card A active (a device
    keeps no copy of the card it had that the host could read back), its limits untouched, and
    the touch source and RUNNING state as it found them.
``device.report-loss`` (spec/conformance.md 4.7, rules L1-L3; protocol PT5, section 6, 8.4)
    CONTROL CLEAR_COUNTERS, then :data:`LOSS_SESSION_S` of driven play reading every STATE
    report, then COUNTERS. ``sequence-gaps``: duplicated, reordered, or misnumbered reports (a
    step of ``sequence`` that differs from the step of ``timestamp_us``), must be 0;
    ``loss-fraction``: sequence numbers missing while the host was reading (gaps across the
    host's own pauses of more than :data:`HOST_PAUSE_MAX_S` are excused) over those expected,
    at most the timing class's ``host_report_loss`` (:data:`MAX_LOSS_FRACTION` for a
    real-time host); ``drops-counted``: the gaps the host saw against COUNTERS
    ``input_dropped`` (:func:`count_error`), within :func:`drop_count_limit`. A session that
    the host or a device off real time disturbed is measured again
    (:func:`measure_loss_sessions`). The check zeroes the device's counters (CLEAR_COUNTERS)
    and leaves them counting.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from itertools import pairwise

from hcard import build
from hcard.card_io import to_bytes
from hcard.device.base import Driver
from hcard.device.errors import DeviceStall, SessionLost
from hcard.device.protocol import (
    FRICTION_SCALE,
    UPLOAD_CHUNK_BYTES,
    Capability,
    Command,
    Counters,
    DeviceInfo,
    FaultBits,
    Report,
    State,
    StateFlags,
    UploadAction,
    UploadBegin,
    UploadData,
    UploadEnd,
    UploadResult,
    UploadState,
    UploadStatus,
    crc32,
)
from hcard.device.protocol.constants import UPLOAD_TIMEOUT_S
from hcard.quantities import MS_PER_S, S_PER_US, US_PER_S
from hcard_conformance.check_names import DEVICE_REPORT_LOSS, DEVICE_UPLOAD_INTEGRITY
from hcard_conformance.context import Context
from hcard_conformance.realtime import (
    NOT_KEPT,
    NotKept,
    attempted_case,
    collection_deferred,
    device_lag,
    reasons,
)
from hcard_conformance.result import CannotAssess, CheckResult, guarded, measured, unassessed
from hcard_conformance.timing import REAL_TIME, timing_class

LEVEL = "device"

# ---------------------------------------------------------------------- shared: the finger

FINGER_PERIOD_S = 0.01
"""Host finger reports while a link check works, s (a 100 Hz touch screen; ten per watchdog
period of the reference device, so the outputs never ramp down during an upload)."""
FINGER_SPEED_MM_S = 30.0
"""Speed of the host finger circling on the surface, mm/s."""
FINGER_FORCE_N = 0.5
"""Normal force of the host finger, N."""
POLL_S = 0.001
"""Time the host drives and reads between two upload reports, s (one STATE period)."""
HOST_PAUSE_MAX_S = 0.02
"""A host that does not read (nor send its finger) for longer than this disturbs a session, s
(20 reports at 1 kHz, one 50 Hz touch period): its finger samples arrive late, and a device is
not asked to queue reports for a stalled host beyond that."""


class FingerSession:
    """The host's finger circling on the surface (radius a quarter of the smaller side) while a
    check works: a FINGER report every :data:`FINGER_PERIOD_S` (CONTROL KEEPALIVE on a device
    without HOST_FINGER), every STATE report collected in :attr:`states`.

    Attributes:
        driver: the open driver.
        states: every STATE report read so far, in arrival order.
        found: the state flags of the first report, read before changing anything (for
            :meth:`restore`).
    """

    def __init__(self, driver: Driver) -> None:
        info = driver.info()
        self.driver = driver
        self.host_finger = bool(info.capabilities & Capability.HOST_FINGER)
        width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
        self._centre = (width / 2, height / 2)
        self._radius = min(width, height) / 4
        self.states: list[State] = []
        first = driver.read_inputs(max_count=1)
        self.found = first[0].flags if first else 0
        self._start = driver.clock()
        self._next = self._start
        self._last_read = self._start
        self.longest_pause_s = 0.0
        """Longest driver-clock time between two reads of the host since :meth:`mark`, s (a
        host that stalls leaves the device's queue to fill and its finger samples late)."""
        self.pauses: list[tuple[float, float]] = []
        """Driver-clock intervals (start, end) in which the host did not read for longer than
        :data:`HOST_PAUSE_MAX_S`, s."""
        self.arrivals: list[float] = []
        """Driver-clock time at which each report of :attr:`states` was read, s."""

    def mark(self) -> None:
        """Start measuring :attr:`longest_pause_s` afresh, from now."""
        self._last_read = self.driver.clock()
        self.longest_pause_s = 0.0

    def begin(self, *, anonymous: bool = False) -> None:
        """Take the touch source (when the device has HOST_FINGER) and START: through
        :meth:`Driver.start` (on a protocol 1.2 device, a session this driver owns), or,
        ``anonymous``, CONTROL START with argument 0 as a protocol 1.1 host sends it: a 1.2
        device refuses every COMMIT while a session with a token is live, and accepts them in
        an anonymous one, as a 1.1 device always does."""
        check_free = getattr(self.driver, "check_free", None)
        if anonymous and check_free is not None:
            check_free()  # a session an earlier host left must end first (SessionBusy if fed)
        if self.host_finger:
            self.driver.set_touch_source(host=True)
        if anonymous:
            self.driver.command(Command.START)
        else:
            self.driver.start()
        self._feed()

    def _feed(self) -> None:
        """Send the finger sample (or KEEPALIVE) when one is due."""
        now = self.driver.clock()
        if now < self._next:
            return
        if self.host_finger:
            angle = FINGER_SPEED_MM_S * (now - self._start) / self._radius
            self.driver.send_finger(now, self._centre[0] + self._radius * math.cos(angle),
                                    self._centre[1] + self._radius * math.sin(angle),
                                    FINGER_FORCE_N, True)
        else:
            self.driver.keepalive()
        self._next = max(self._next + FINGER_PERIOD_S, now)

    def run(self, seconds: float) -> list[State]:
        """Drive the finger and read STATE reports for ``seconds`` (s); the reports read."""
        end = self.driver.clock() + seconds
        got: list[State] = []
        while True:
            self._feed()
            now = self.driver.clock()
            if now - self._last_read > HOST_PAUSE_MAX_S:
                self.pauses.append((self._last_read, now))
            self.longest_pause_s = max(self.longest_pause_s, now - self._last_read)
            self._last_read = now
            if now >= end:
                break
            batch = self.driver.collect_until(min(end, now + POLL_S))
            self.arrivals += [self.driver.clock()] * len(batch)
            got += batch
        self.states += got
        return got

    def run_quiet(self, seconds: float) -> list[State]:
        """:meth:`run` for ``seconds`` of the host's clock and of the device's: a device that
        fell behind its real-time clock (device protocol PI4) counts less time than the host,
        and an upload silence must last ``seconds`` on the clock of the device's timeout (PU4:
        "2 s of device time"). The device's time is that of the reports read, from the newest
        one read before; at most ``seconds`` more of the host's clock are added."""
        since = self.states[-1].timestamp_us if self.states else None
        got = self.run(seconds)
        deadline = self.driver.clock() + seconds
        while (since is not None and self.driver.clock() < deadline
               and (not got or ((got[-1].timestamp_us - since) % _TIME_MODULO) * S_PER_US
                    < seconds)):
            got += self.run(SETTLE_S)
        return got

    def restore(self) -> None:
        """STOP unless the device was RUNNING when found; give the touch source back to the
        internal sensor when it had it."""
        if not self.found & StateFlags.RUNNING:
            self.driver.stop()
        if self.host_finger and not self.found & StateFlags.HOST_FINGER:
            self.driver.set_touch_source(host=False)


# ---------------------------------------------------------------------- (f) upload integrity

CARD_A_FRICTION = 0.45
"""Relative friction of card A (uniform; UV, or EV 1 + this on a device without UV)."""
CARD_B_FRICTION = 0.75
"""Relative friction of card B, far enough from A that one report tells them apart."""
CARD_TAXTEL_MM = 2.0
"""Taxtel of cards A and B, mm: a grid of ~1 100 taxtels (one texture) makes ~1.2 kB, about
20 UPLOAD_DATA chunks, so a chunk can go missing in the middle of an upload."""
TARGET_TOLERANCE = 1
"""Largest difference of a reported target from the card's, counts of 1e-4 (rounding)."""
TIMEOUT_MARGIN_S = 0.3
"""Upload silence beyond the 2 s of PU4 before the host looks, s (a device checks its timeout
at its own pace; 0.3 s is 15 % of the timeout)."""
AFTER_S = 0.03
"""Reports read after each attempt, s (the card in force must still play)."""
SETTLE_S = 0.03
"""Play read at a time before each case, to see card A in force, s."""
SEE_TIMEOUT_S = 1.0
"""Longest play before each case to see card A in force, s."""
MIN_PLAYING_REPORTS = 10
"""Fewest reports that must show the card in force around an attempt (a device that stops
reporting while it refuses an upload shows nothing playing)."""
PROBE = "probe"
"""Step of an attempt: GET UPLOAD_STATUS now; it must already be FAILED with the result."""
UPLOAD_CASES = ("bad-crc", "truncated", "out-of-order", "interrupted", "restarted", "oversize",
                "valid-after")
"""The cases of ``device.upload-integrity``, in order."""
_PLAYING = int(StateFlags.CONTACT | StateFlags.RUNNING | StateFlags.CARD_LOADED)

Step = Report | float | str
"""An attempt step: an upload report to SET, a silence of the upload channel (s; the finger
keeps playing), or :data:`PROBE`."""


@dataclass(frozen=True)
class LinkCard:
    """A uniform card the check uploads, and what STATE reports while it plays.

    Attributes:
        data: the card's binary form.
        target: (target_uv_x1e4, target_ev_x1e4) reported in contact.
    """

    data: bytes
    target: tuple[int, int]

    @property
    def crc(self) -> int:
        """CRC-32 of :attr:`data` (protocol 9.3)."""
        return crc32(self.data)


def link_card(info: DeviceInfo, friction: float) -> LinkCard:
    """A card of one uniform texture over :data:`CARD_TAXTEL_MM` taxtels: UV ``friction`` on a
    device with UV, else EV ``1 + friction``."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    uv = bool(info.capabilities & Capability.UV)
    value = friction if uv else 1.0 + friction
    cells = math.ceil(width / CARD_TAXTEL_MM) * math.ceil(height / CARD_TAXTEL_MM)
    card = build.card(width, height, taxtel_mm=CARD_TAXTEL_MM,
                      textures=[build.texture(value, channel="uv" if uv else "ev")],
                      texture_index=[0] * cells, title=f"link check {value:g}")
    counts = round(value * FRICTION_SCALE)
    return LinkCard(to_bytes(card), (counts, FRICTION_SCALE) if uv else (FRICTION_SCALE, counts))


def chunks(data: bytes) -> list[UploadData]:
    """UPLOAD_DATA reports carrying ``data`` in order, 58 bytes each."""
    return [UploadData(offset, data[offset:offset + UPLOAD_CHUNK_BYTES])
            for offset in range(0, len(data), UPLOAD_CHUNK_BYTES)]


def bad_uploads(data: bytes, max_card_bytes: int) -> dict[str, tuple[list[Step], UploadResult]]:
    """The uploads of ``data`` that a device must refuse, by case: the steps and the result
    UPLOAD_STATUS must give (protocol 9.4). Every attempt ends with COMMIT, as a host that
    ignored the failure would send."""
    parts = chunks(data)
    if len(parts) < 4:
        raise ValueError(f"a {len(data)}-byte card is too short to reorder its chunks")
    begin = UploadBegin(len(data), crc32(data))
    commit = UploadEnd(UploadAction.COMMIT)
    half = len(parts) // 2
    silence = UPLOAD_TIMEOUT_S + TIMEOUT_MARGIN_S
    return {
        # every byte right, the declared CRC-32 one bit off (PU3)
        "bad-crc": ([UploadBegin(len(data), begin.crc32 ^ 1), *parts, commit],
                    UploadResult.CRC_MISMATCH),
        # the last chunk never sent (PU3: SHORT before the CRC)
        "truncated": ([begin, *parts[:-1], commit], UploadResult.SHORT),
        # the second chunk late: the third arrives at an offset other than `received` (PU2)
        "out-of-order": ([begin, parts[0], parts[2], PROBE, *parts[3:], parts[1], commit],
                         UploadResult.OUT_OF_ORDER),
        # the host goes silent past the upload timeout, then resumes (PU4, PU2)
        "interrupted": ([begin, *parts[:half], silence, PROBE, *parts[half:], commit],
                        UploadResult.TIMEOUT),
        # a new BEGIN discards the upload in progress: its bytes never join the new one (PU1)
        "restarted": ([begin, *parts[:half], begin, *parts[half:], commit],
                      UploadResult.OUT_OF_ORDER),
        # more than max_card_bytes announced (PU1), then the bytes and COMMIT anyway
        "oversize": ([UploadBegin(max_card_bytes + 1, begin.crc32), PROBE, *parts, commit],
                     UploadResult.TOO_LARGE),
    }


@dataclass
class Attempt:
    """What one upload attempt did.

    Attributes:
        status: UPLOAD_STATUS after it.
        probes: UPLOAD_STATUS at each :data:`PROBE` step.
        stalls: the reports the device answered with a STALL (protocol PU6: an upload failure
            is a result, never a STALL), by name.
        states: the STATE reports from its first step to :data:`AFTER_S` after its last.
        longest_pause_s: the host's longest time between two reads during it, s.
    """

    status: UploadStatus
    probes: list[UploadStatus] = field(default_factory=list)
    stalls: list[str] = field(default_factory=list)
    states: list[State] = field(default_factory=list)
    longest_pause_s: float = 0.0

    @property
    def finger_late(self) -> list[bool]:
        """Per report, whether the finger sample it applies reached the device late
        (:func:`late_finger`)."""
        return late_finger(self.states)


def run_attempt(session: FingerSession, steps: Sequence[Step]) -> Attempt:
    """SET each upload report of ``steps`` (driving the finger for :data:`POLL_S` after each),
    keep the upload channel silent for the float steps, GET UPLOAD_STATUS at the probes; then
    read :data:`AFTER_S` of reports and UPLOAD_STATUS."""
    driver = session.driver
    first = len(session.states)
    session.mark()
    probes: list[UploadStatus] = []
    stalls: list[str] = []
    for step in steps:
        if isinstance(step, str):
            probes.append(driver.upload_status())
        elif isinstance(step, float):
            session.run_quiet(step)
            continue
        else:
            try:
                driver.set_report(step)
            except DeviceStall:
                stalls.append(step.name())
        session.run(POLL_S)
    session.run(AFTER_S)
    status = driver.upload_status()
    return Attempt(status, probes, stalls, session.states[first:], session.longest_pause_s)


def upload(session: FingerSession, card: LinkCard) -> Attempt:
    """Upload and commit ``card`` with good reports, the finger playing."""
    return run_attempt(session, [UploadBegin(len(card.data), card.crc), *chunks(card.data),
                                 UploadEnd(UploadAction.COMMIT)])


SHOWS, NEUTRAL, OTHER = "shows", "neutral", "other"
"""What a STATE report shows of a card (:func:`classify`)."""


def classify(state: State, card: LinkCard, generation: int) -> str:
    """What ``state`` shows of ``card`` (of ``generation``):

    * :data:`SHOWS`: the card playing under the finger: CONTACT, RUNNING and CARD_LOADED set,
      its generation, and its targets within :data:`TARGET_TOLERANCE`;
    * :data:`NEUTRAL`: the card in force (generation, RUNNING, CARD_LOADED) but a neutral
      frame under the finger: no texture, targets 1 (README R5-R7: no usable touch sample);
    * :data:`OTHER`: anything else: another generation, no card, stopped, no contact, or
      targets that are not the card's.
    """
    if (state.flags & _PLAYING != _PLAYING or state.card_generation != generation):
        return OTHER
    if (abs(state.target_uv_x1e4 - card.target[0]) <= TARGET_TOLERANCE
            and abs(state.target_ev_x1e4 - card.target[1]) <= TARGET_TOLERANCE):
        return SHOWS
    if (state.texture == -1 and state.target_uv_x1e4 == FRICTION_SCALE
            and state.target_ev_x1e4 == FRICTION_SCALE):
        return NEUTRAL
    return OTHER


FINGER_GAP_S = FINGER_PERIOD_S + HOST_PAUSE_MAX_S
"""A finger sample that reaches the device more than this after the previous one (device
time), s, comes after a gap in the host's finger stream (the host paused, or the transport held
its reports): the renderer may play neutral frames until the stream is regular again."""


def late_finger(states: Sequence[State]) -> list[bool]:
    """Per report of ``states``, whether the finger sample it applies (``host_time_echo_us``)
    was first seen more than :data:`FINGER_GAP_S` of device time (``timestamp_us``) after the
    sample before it; False for the first sample of ``states`` (no sample before to compare)."""
    late: list[bool] = []
    device_us, first_seen, previous_echo, is_late = 0, None, None, False
    for k, state in enumerate(states):
        if k:
            device_us += (state.timestamp_us - states[k - 1].timestamp_us) % _TIME_MODULO
        if state.host_time_echo_us != previous_echo:
            if first_seen is not None:
                is_late = device_us - first_seen > FINGER_GAP_S * US_PER_S
            first_seen, previous_echo = device_us, state.host_time_echo_us
        late.append(is_late)
    return late


def off_card(states: Sequence[State], card: LinkCard,
             generation: int) -> tuple[int, int, int]:
    """Reports of ``states`` that show ``card`` playing, that are neutral while the finger
    sample they apply came late (:func:`late_finger`: the renderer's answer to a gap in the
    finger stream, excused), and that count against the card: every :data:`OTHER` report, and
    every neutral one with a finger sample on time (the device stopped rendering the card)."""
    kinds = [classify(s, card, generation) for s in states]
    excused = sum(kind == NEUTRAL and late
                  for kind, late in zip(kinds, late_finger(states), strict=True))
    return kinds.count(SHOWS), excused, len(kinds) - kinds.count(SHOWS) - excused


def result_name(value: int) -> str:
    """The name of an UploadResult value (``result N`` for one this version lacks)."""
    try:
        return UploadResult(value).name
    except ValueError:
        return f"result {value}"


def status_text(status: UploadStatus) -> str:
    """UPLOAD_STATUS in a few words: state, result, bytes, active CRC and generation."""
    try:
        state = UploadState(status.state).name
    except ValueError:
        state = f"state {status.state}"
    result = f" {result_name(status.result)}" if status.state == UploadState.FAILED else ""
    return (f"{state}{result} ({status.received}/{status.total_length} B, active CRC "
            f"0x{status.active_crc32:08X} gen {status.card_generation})")


def next_generation(generation: int) -> int:
    """The generation after a successful COMMIT: +1, wrapping past 0xFFFF to 1 (0: no card)."""
    return generation % 0xFFFF + 1


def from_generation(states: Sequence[State], generation: int) -> list[State]:
    """``states`` from the first of ``generation`` on (those the device produced before, still
    on their way to a slow host, are left out)."""
    first = next((k for k, s in enumerate(states) if s.card_generation == generation),
                 len(states))
    return list(states[first:])


def play_until_shown(session: FingerSession, card: LinkCard, generation: int) -> list[State]:
    """Play until :data:`MIN_PLAYING_REPORTS` reports show ``card`` (of ``generation``), or
    one from the first of that generation on does not, at most :data:`SEE_TIMEOUT_S`; every
    report read."""
    end = session.driver.clock() + SEE_TIMEOUT_S
    states: list[State] = []
    while session.driver.clock() < end:
        states += session.run(SETTLE_S)
        kinds = [classify(s, card, generation) for s in from_generation(states, generation)]
        if OTHER in kinds or kinds.count(SHOWS) >= MIN_PLAYING_REPORTS:
            break
    return states


def see_playing(session: FingerSession, card: LinkCard, generation: int) -> list[State]:
    """:func:`play_until_shown`, from the first report of ``generation`` on."""
    return from_generation(play_until_shown(session, card, generation), generation)


def ensure_card(session: FingerSession, card: LinkCard) -> int:
    """Make ``card`` the card in force and see it play; its generation.

    When UPLOAD_STATUS already names its CRC-32 and the reports show it playing
    (:func:`see_playing`), nothing is sent; otherwise it is uploaded (which also ends a
    streaming mode left by an earlier session). Raises CannotAssess when it does not commit
    or play."""
    status = session.driver.upload_status()
    if status.active_crc32 == card.crc:
        kinds = [classify(s, card, status.card_generation)
                 for s in see_playing(session, card, status.card_generation)]
        if OTHER not in kinds and kinds.count(SHOWS) >= MIN_PLAYING_REPORTS:
            return status.card_generation
    attempt = upload(session, card)
    if attempt.status.state != UploadState.COMMITTED or attempt.status.active_crc32 != card.crc:
        raise CannotAssess(f"card A ({len(card.data)} B) did not commit: "
                           f"{status_text(attempt.status)}")
    generation = attempt.status.card_generation
    kinds = [classify(s, card, generation) for s in see_playing(session, card, generation)]
    if OTHER in kinds or kinds.count(SHOWS) < MIN_PLAYING_REPORTS:
        raise CannotAssess(f"card A committed but {kinds.count(SHOWS)} of {len(kinds)} STATE "
                           f"reports show it playing (targets {card.target}, generation "
                           f"{generation})")
    return generation


def _excused_text(attempt: Attempt, excused: int) -> str:
    if not excused:
        return ""
    return (f"; {excused} neutral reports excused (their finger sample came more than "
            f"{FINGER_GAP_S * MS_PER_S:.0f} ms after the one before; host paused at most "
            f"{attempt.longest_pause_s * MS_PER_S:.0f} ms)")


def judge_refusal(case: str, attempt: Attempt, expected: UploadResult, card_a: LinkCard,
                  generation: int) -> CheckResult:
    """U1 and U2 for one refused upload: FAILED with ``expected`` (at the end and at every
    probe), no STALL, A's CRC-32 and ``generation`` still active, at least
    :data:`MIN_PLAYING_REPORTS` reports showing A playing and none against it
    (:func:`off_card`). The metric is the number of reports against A."""
    status = attempt.status
    refused = status.state == UploadState.FAILED and status.result == expected
    probes_ok = all(p.state == UploadState.FAILED and p.result == expected
                    for p in attempt.probes)
    kept = status.active_crc32 == card_a.crc and status.card_generation == generation
    playing, excused, off = off_card(attempt.states, card_a, generation)
    passed = (refused and probes_ok and kept and off == 0 and playing >= MIN_PLAYING_REPORTS
              and not attempt.stalls)
    parts = [f"expected FAILED {expected.name}, device said {status_text(status)}"]
    parts += [f"while sending: {status_text(p)}" for p in attempt.probes
              if not (p.state == UploadState.FAILED and p.result == expected)]
    if not kept:
        parts.append(f"card A (CRC 0x{card_a.crc:08X} gen {generation}) replaced")
    parts.append(f"{playing} of {len(attempt.states)} reports show A playing"
                 + _excused_text(attempt, excused))
    if attempt.stalls:
        parts.append(f"STALL on {', '.join(attempt.stalls)} (PU6)")
    return CheckResult(DEVICE_UPLOAD_INTEGRITY, LEVEL, case, passed, "reports_off_card_a",
                       float(off), 0.0, "reports", "; ".join(parts))


def judge_commit(attempt: Attempt, card_b: LinkCard, generation_a: int,
                 card_a: LinkCard) -> CheckResult:
    """U3: COMMITTED, B's CRC-32 and the next generation active, the swap atomic (every report
    shows A or B, no A after the first B; neutral ones as in :func:`off_card`) and at least
    :data:`MIN_PLAYING_REPORTS` showing B. The metric is the number of reports against that."""
    status = attempt.status
    generation = next_generation(generation_a)
    committed = (status.state == UploadState.COMMITTED and status.active_crc32 == card_b.crc
                 and status.card_generation == generation)
    seen_b, wrong, b_reports, excused = False, 0, 0, 0
    for state, late in zip(attempt.states, attempt.finger_late, strict=True):
        as_b = classify(state, card_b, generation)
        as_a = classify(state, card_a, generation_a)
        if as_b == SHOWS:
            seen_b, b_reports = True, b_reports + 1
        elif late and NEUTRAL in (as_a, as_b):
            excused += 1
        elif seen_b or as_a != SHOWS:
            wrong += 1
    passed = committed and wrong == 0 and b_reports >= MIN_PLAYING_REPORTS and not attempt.stalls
    detail = (f"expected COMMITTED gen {generation} CRC 0x{card_b.crc:08X}, device said "
              f"{status_text(status)}; {b_reports} reports show B playing, "
              f"{wrong} against the swap (neither card, or A after B)"
              + _excused_text(attempt, excused))
    if attempt.stalls:
        detail += f"; STALL on {', '.join(attempt.stalls)}"
    return CheckResult(DEVICE_UPLOAD_INTEGRITY, LEVEL, "valid-after", passed,
                       "reports_off_card", float(wrong), 0.0, "reports", detail)


def measure_upload_integrity(driver: Driver) -> Iterator[CheckResult]:
    """The cases of ``device.upload-integrity`` on one open driver (module docstring)."""
    info = driver.info()
    card_a, card_b = link_card(info, CARD_A_FRICTION), link_card(info, CARD_B_FRICTION)
    if info.max_card_bytes < len(card_b.data):
        raise CannotAssess(f"the test card ({len(card_b.data)} B) is larger than "
                           f"max_card_bytes {info.max_card_bytes}")
    session = FingerSession(driver)
    session.begin(anonymous=True)
    try:
        uploads = bad_uploads(card_b.data, info.max_card_bytes)
        for case, (steps, expected) in uploads.items():
            if case == "oversize" and info.max_card_bytes >= 0xFFFF_FFFF:
                yield unassessed(DEVICE_UPLOAD_INTEGRITY, LEVEL, case, "max_card_bytes is "
                                 "the largest u32: no announced size is above it")
                continue

            def refusal(case: str = case, steps: list[Step] = steps,
                        expected: UploadResult = expected) -> CheckResult:
                generation = ensure_card(session, card_a)
                attempt = run_attempt(session, steps)
                return kept(judge_refusal(case, attempt, expected, card_a, generation), attempt)

            yield attempted_case(DEVICE_UPLOAD_INTEGRITY, LEVEL, case, refusal)

        def commit() -> CheckResult:
            generation = ensure_card(session, card_a)
            attempt = upload(session, card_b)
            if attempt.status.state == UploadState.COMMITTED:  # a slow host: B's reports lag
                attempt.states += play_until_shown(session, card_b, next_generation(generation))
            return kept(judge_commit(attempt, card_b, generation, card_a), attempt)

        yield attempted_case(DEVICE_UPLOAD_INTEGRITY, LEVEL, "valid-after", commit)
        ensure_card(session, card_a)  # leave card A in force (module docstring)
    finally:
        session.restore()


def kept(result: CheckResult, attempt: Attempt) -> CheckResult:
    """``result``, unless it failed in a run not kept in real time (spec QT3): the host paused
    longer than :data:`HOST_PAUSE_MAX_S` between reads, or the device flagged reports
    REALTIME_LAG (device protocol PI4); then :class:`NotKept`, and the case is measured again
    (:func:`~hcard_conformance.realtime.attempted_case`). A result that passed stands."""
    if result.passed:
        return result
    host = (f"the host paused {attempt.longest_pause_s * MS_PER_S:.0f} ms between reads"
            if attempt.longest_pause_s > HOST_PAUSE_MAX_S else "")
    why = reasons(host, device_lag(attempt.states))
    if why:
        raise NotKept(f"{why}; the case failed so: {result.detail}")
    return result


def check_upload_integrity(ctx: Context) -> Iterator[CheckResult]:
    """Bad uploads are refused with their reason and the previous card keeps playing (U1-U3)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def measure() -> Iterator[CheckResult]:
        with open_driver() as driver:
            yield from measure_upload_integrity(driver)

    yield from guarded(DEVICE_UPLOAD_INTEGRITY, LEVEL, UPLOAD_CASES, measure)


# ---------------------------------------------------------------------- (g) report loss

LOSS_SESSION_S = 3.0
"""Driven play over which STATE reports are counted, s (3 000 reports at 1 kHz: one lost
report is 0.033 %, a third of :data:`MAX_LOSS_FRACTION`)."""
WARM_UP_S = 0.1
"""Play before CLEAR_COUNTERS, s (the reports of an earlier session are read and set aside)."""
TAIL_S = 0.05
"""Reports read after GET COUNTERS, s: those the device produced before answering it."""
MAX_LOSS_FRACTION = REAL_TIME.host_report_loss
"""L2 threshold of a real-time host (timing class ``real-time``; another class states its own
``host_report_loss``): at most 0.1 % of STATE reports lost, about one a second at 1 kHz. A
full-speed interrupt pipe polled every 1 ms (PT1) delivers every report when the device queues
as PT5 asks and the host reads; one lost report a second leaves the 1 kHz record of a session
dense enough for the 10 ms touch period and the 2 ms rise-time resolution of the device checks,
and keeps the host's latency and fault tracking (faults are ORed into the next report, PI1)
intact."""
DROP_COUNT_SLACK = 2
"""L3 threshold, plus the host's own loss allowance (:func:`drop_count_limit`): the gaps the
host saw and COUNTERS ``input_dropped`` may differ by this many reports: the CLEAR_COUNTERS at
the start and the GET COUNTERS at the end each fall between two reports, so one report at either
end may be counted on one side only."""
LOSS_CASES = ("sequence-gaps", "loss-fraction", "drops-counted")
"""The cases of ``device.report-loss``, in order."""
LOSS_ATTEMPTS = 3
"""Sessions measured at most: one that lost reports while disturbed (the host stalled, or the
device fell behind real time) is measured again (:func:`measure_loss_sessions`)."""
MIN_RATE_RATIO = 0.95
"""A session in which the device's clock (STATE ``timestamp_us``) advanced less than this
fraction of the host's is disturbed: the device did not run in real time."""
_SEQUENCE_MODULO = 1 << 16
_TIME_MODULO = 1 << 32


@dataclass(frozen=True)
class SequenceStats:
    """Sequence numbers of the STATE reports of a session, as the host received them.

    Attributes:
        received: reports received.
        expected: sequence numbers from the first to the highest received (wrap-around
            unwrapped): the reports the device produced in that span.
        lost: sequence numbers of that span never received.
        duplicates: reports whose sequence number was already received.
        reordered: reports received after a higher sequence number.
        misnumbered: consecutive reports whose sequence step differs from their time step
            (``timestamp_us`` difference in report periods): a device that numbers only the
            reports it sends hides its losses (PT5).
        longest_gap: most consecutive sequence numbers missing.
        excused: of ``lost``, those missing between two reports the host read on either side
            of one of its own pauses (it did not read: a device drops, counted, what the host
            does not take, PT5).
    """

    received: int
    expected: int
    lost: int
    duplicates: int
    reordered: int
    misnumbered: int
    longest_gap: int
    excused: int = 0

    @property
    def unexcused(self) -> int:
        """Reports lost while the host was reading: ``lost - excused``."""
        return max(self.lost - self.excused, 0)

    @property
    def loss_fraction(self) -> float:
        """Reports lost while the host was reading over those expected, ``unexcused /
        expected`` (NaN without reports)."""
        return self.unexcused / self.expected if self.expected else math.nan


def sequence_stats(sequences: Sequence[int], timestamps_us: Sequence[int] | None = None,
                   period_us: float = 1000.0, arrivals_s: Sequence[float] | None = None,
                   pauses: Sequence[tuple[float, float]] = ()) -> SequenceStats:
    """Loss, duplicates, reordering and misnumbering of u16 ``sequences`` in arrival order
    (each unwrapped relative to the previous one: steps of less than 2^15 forward, otherwise
    backward). ``timestamps_us`` (u32, wrapping) and the report period ``period_us`` (us)
    give the time steps that the sequence steps are compared with; ``arrivals_s`` (the host
    clock when each report was read, s) and the host's ``pauses`` ((start, end), s) tell the
    gaps the host's pauses excuse."""
    if not sequences:
        return SequenceStats(0, 0, 0, 0, 0, 0, 0)
    unwrapped = [int(sequences[0])]
    for previous, current in pairwise(sequences):
        step = (int(current) - int(previous)) % _SEQUENCE_MODULO
        unwrapped.append(unwrapped[-1] + (step if step < _SEQUENCE_MODULO // 2
                                          else step - _SEQUENCE_MODULO))
    seen: set[int] = set()
    highest = unwrapped[0]
    duplicates = reordered = 0
    for value in unwrapped:
        if value in seen:
            duplicates += 1
            continue
        if value < highest:
            reordered += 1
        seen.add(value)
        highest = max(highest, value)
    ordered = sorted(seen)
    expected = ordered[-1] - ordered[0] + 1
    longest = max((b - a - 1 for a, b in pairwise(ordered)), default=0)
    misnumbered = 0
    if timestamps_us is not None:
        for k in range(1, len(unwrapped)):
            dt = (int(timestamps_us[k]) - int(timestamps_us[k - 1])) % _TIME_MODULO
            if dt >= _TIME_MODULO // 2:
                dt -= _TIME_MODULO
            if round(dt / period_us) != unwrapped[k] - unwrapped[k - 1]:
                misnumbered += 1
    excused = 0
    if arrivals_s is not None and pauses:
        excused = excused_gaps(unwrapped, arrivals_s, pauses)
    return SequenceStats(len(unwrapped), expected, expected - len(ordered), duplicates,
                         reordered, misnumbered, longest, min(excused, expected - len(ordered)))


def excused_gaps(unwrapped: Sequence[int], arrivals_s: Sequence[float],
                 pauses: Sequence[tuple[float, float]]) -> int:
    """Sequence numbers missing in forward steps between two consecutive reports (arrival
    order) read on either side of, or during, a host pause: its interval overlaps the two
    reads (``arrivals_s``, s)."""
    excused = 0
    for k in range(1, len(unwrapped)):
        step = unwrapped[k] - unwrapped[k - 1]
        if step > 1 and any(start < arrivals_s[k] and end > arrivals_s[k - 1]
                            for start, end in pauses):
            excused += step - 1
    return excused


@dataclass(frozen=True)
class LossSession:
    """A report-loss session.

    Attributes:
        stats: the sequence statistics of the reports read after CLEAR_COUNTERS.
        counters: COUNTERS at the end of the session.
        dropped_field: ``dropped_reports`` of the last report read (u16, since the clear).
        flagged: reports read with fault INPUT_DROPPED.
        duration_s: driver time from CLEAR_COUNTERS to the last report read, s.
        rate_ratio: device time (``timestamp_us``) over host time in the session: 1 for a
            device that keeps real time.
        longest_pause_s: the host's longest time between two reads, s.
        late_s: spread of the reports' delay from the device's clock to the host's read
            (the latest less the earliest), s: reports that reached the host in a burst, late.
        attempt: which session this was (1 = the first, :data:`LOSS_ATTEMPTS` at most).
        device_late: reports read with fault REALTIME_LAG, or COUNTERS ``late_reports`` if
            more (the device fell behind its real-time clock, device protocol PI4).
    """

    stats: SequenceStats
    counters: Counters
    dropped_field: int
    flagged: int
    duration_s: float
    rate_ratio: float
    longest_pause_s: float
    late_s: float = 0.0
    attempt: int = 1
    device_late: int = 0

    @property
    def disturbed(self) -> str:
        """Why the session says little about the link (empty when it does not): the host
        paused longer than :data:`HOST_PAUSE_MAX_S`, or the device's clock advanced less than
        :data:`MIN_RATE_RATIO` of the host's (it did not run in real time: a simulated device
        on a loaded machine)."""
        reasons = []
        if self.longest_pause_s > HOST_PAUSE_MAX_S:
            reasons.append(
                f"the host paused {self.longest_pause_s * MS_PER_S:.0f} ms between reads")
        if self.late_s > HOST_PAUSE_MAX_S:
            reasons.append(f"reports reached the host up to {self.late_s * MS_PER_S:.0f} ms late")
        if self.rate_ratio < MIN_RATE_RATIO:
            reasons.append(f"the device's clock ran at {self.rate_ratio:.0%} of the host's")
        if self.device_late:
            reasons.append(f"the device produced {self.device_late} reports late on its "
                           "real-time clock (REALTIME_LAG, device protocol PI4)")
        return " and ".join(reasons)

    @property
    def lost_while_reading(self) -> bool:
        """Reports were lost while the host read (gaps its own pauses do not excuse)."""
        return self.stats.unexcused > 0

    def conditions(self) -> str:
        """The session's conditions, for a result's detail."""
        text = (f"session {self.attempt}: host paused at most "
                f"{self.longest_pause_s * MS_PER_S:.1f} ms, delay spread "
                f"{self.late_s * MS_PER_S:.1f} ms, device clock at "
                f"{self.rate_ratio:.1%} of the host's")
        if self.disturbed:
            text += f" (disturbed: {self.disturbed})"
        return text


def measure_report_loss(driver: Driver, session_s: float = LOSS_SESSION_S) -> LossSession:
    """Warm up, CLEAR_COUNTERS, play ``session_s`` (s) reading every STATE report, GET
    COUNTERS, read :data:`TAIL_S` more, restore the touch source and RUNNING."""
    info = driver.info()
    session = FingerSession(driver)
    session.begin()
    try:
        session.run(WARM_UP_S)
        driver.clear_counters()
        session.mark()
        first = len(session.states)
        start = driver.clock()
        with collection_deferred():  # a collection's pause would lose reports (QT3)
            session.run(session_s)
        counters = driver.counters()
        session.run(TAIL_S)
        duration = driver.clock() - start
        states, arrivals = session.states[first:], session.arrivals[first:]
        pauses = [p for p in session.pauses if p[1] > start]
    finally:
        session.restore()
    if not states:
        raise CannotAssess(f"no STATE report in {session_s:g} s of play")
    rate = max(info.input_rate_hz, 1)
    stats = sequence_stats([s.sequence for s in states], [s.timestamp_us for s in states],
                           US_PER_S / rate, arrivals, pauses)
    flagged = sum(bool(s.faults & FaultBits.INPUT_DROPPED) for s in states)
    device_late = max(sum(bool(s.faults & FaultBits.REALTIME_LAG) for s in states),
                      counters.late_reports)
    return LossSession(stats, counters, states[-1].dropped_reports, flagged, duration,
                       device_span_s(states) / duration, session.longest_pause_s,
                       delay_spread_s(states, arrivals), device_late=device_late)


def delay_spread_s(states: Sequence[State], arrivals_s: Sequence[float]) -> float:
    """The latest less the earliest delay from a report's device time (``timestamp_us``,
    unwrapped) to its read on the host's clock (``arrivals_s``), s: 0 when every report
    travelled as fast as the fastest; large after a burst (a device that fell behind and
    caught up, or a host that paused)."""
    if not states:
        return 0.0
    device_s, delays = 0.0, [arrivals_s[0]]
    for k in range(1, len(states)):
        ticks = (states[k].timestamp_us - states[k - 1].timestamp_us) % _TIME_MODULO
        device_s += ticks * S_PER_US
        delays.append(arrivals_s[k] - device_s)
    return max(delays) - min(delays)


def device_span_s(states: Sequence[State]) -> float:
    """Device time from the first to the last of ``states`` (``timestamp_us``, unwrapped
    across the u32 wrap step by step), s."""
    total = 0
    for previous, current in pairwise(states):
        total += (current.timestamp_us - previous.timestamp_us) % _TIME_MODULO
    return total * S_PER_US


def measure_loss_sessions(driver: Driver, attempts: int = LOSS_ATTEMPTS) -> LossSession:
    """The session the cases judge: the first that was not disturbed
    (:attr:`LossSession.disturbed`) or lost nothing while the host was reading (no gap but
    those its own pauses excuse, no anomaly); when every one of ``attempts`` was disturbed and
    lost reports, the one that lost fewest: its loss cases are then not assessed (a run not
    kept in real time, spec QT3, :func:`loss_not_kept`), its anomalies are judged."""
    sessions: list[LossSession] = []
    lost: list[str] = []
    for attempt in range(1, attempts + 1):
        try:
            m = replace(measure_report_loss(driver), attempt=attempt)
        except SessionLost as exc:
            # the host went silent for watchdog_ms (PN7 ended its session): a session not
            # kept (spec QT3); a driver that is not real-time never goes silent
            if not driver.realtime:
                raise
            lost.append(f"session {attempt}: {exc}")
            continue
        s = m.stats
        if not m.disturbed or s.unexcused + s.duplicates + s.reordered + s.misnumbered == 0:
            return m
        sessions.append(m)
    if not sessions:
        raise NotKept(f"every session {NOT_KEPT}: {'; '.join(lost)}")
    return min(sessions, key=lambda m: m.stats.unexcused)


def loss_not_kept(m: LossSession, sessions: int) -> str:
    """Why the loss cases (L2, L3) of the judged session ``m`` are not assessed: it lost
    reports while the host read, and it was disturbed (the host paused, reports came in a
    burst, or the device fell behind its real-time clock), as every one of the ``sessions``
    measured was (spec QT3: the loss measured the lateness, not the device; empty when the
    session is judged). Duplicated, reordered or misnumbered reports (L1) owe nothing to
    lateness and are judged whatever the session's conditions."""
    if not m.disturbed or not m.lost_while_reading:
        return ""
    return (f"every one of {sessions} sessions lost reports while disturbed, so the run "
            f"{NOT_KEPT} ({m.conditions()}; {m.stats.unexcused} lost while the host read)")


def count_error(stats: SequenceStats, counted: int) -> int:
    """L3 metric, reports: the drops COUNTERS claims beyond the reports missing
    (``counted - lost``), or the reports missing while the host was reading that it does not
    count (``unexcused - counted``), whichever is larger, at least 0. Gaps at the host's own
    pauses may be the device's counted drops (PT5) or losses behind the device (the host's
    buffers), which no device can count."""
    return max(counted - stats.lost, stats.unexcused - counted, 0)


def drop_count_limit(expected: int, host_loss: float) -> int:
    """L3 threshold for a session of ``expected`` reports, reports: :data:`DROP_COUNT_SLACK`
    plus the reports the host itself may lose (``host_loss``, the timing class's
    ``host_report_loss``): those the device delivered and the host failed to read, which no
    device counts."""
    return DROP_COUNT_SLACK + math.floor(host_loss * expected)


def check_report_loss(ctx: Context) -> Iterator[CheckResult]:
    """Sequence gaps, loss fraction and COUNTERS agreement of the STATE stream (L1-L3)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    timing = timing_class(ctx)

    def measure() -> Iterator[CheckResult]:
        sessions = LOSS_ATTEMPTS if timing.keeps_real_time else 1
        with open_driver() as driver:
            m = measure_loss_sessions(driver, sessions)
        s = m.stats
        not_kept = loss_not_kept(m, sessions) if timing.keeps_real_time else ""
        yield measured(DEVICE_REPORT_LOSS, LEVEL, "sequence-gaps", "n_anomalies",
                       s.duplicates + s.reordered + s.misnumbered, 0.0, unit="reports",
                       detail=f"{s.duplicates} duplicated, {s.reordered} reordered, "
                       f"{s.misnumbered} misnumbered (sequence step != timestamp step) of "
                       f"{s.received} reports; {m.conditions()}")
        if not_kept:
            yield unassessed(DEVICE_REPORT_LOSS, LEVEL, "loss-fraction", not_kept)
            yield unassessed(DEVICE_REPORT_LOSS, LEVEL, "drops-counted", not_kept)
            return
        yield measured(DEVICE_REPORT_LOSS, LEVEL, "loss-fraction", "loss_fraction",
                       s.loss_fraction * 100, timing.host_report_loss * 100, unit="%",
                       detail=f"{s.unexcused} of {s.expected} reports lost while the host "
                       f"read ({s.lost} missing, {s.excused} at its own pauses; longest gap "
                       f"{s.longest_gap}) over {m.duration_s:.2f} s; {m.conditions()}; timing "
                       f"class {timing.name}")
        counted = m.counters.input_dropped
        yield measured(DEVICE_REPORT_LOSS, LEVEL, "drops-counted", "count_error",
                       count_error(s, counted),
                       drop_count_limit(s.expected, timing.host_report_loss), unit="reports",
                       detail=f"host saw {s.lost} missing ({s.excused} at its own pauses), "
                       f"COUNTERS input_dropped {counted} "
                       f"(STATE dropped_reports {m.dropped_field}, {m.flagged} reports flagged "
                       f"INPUT_DROPPED, input_reports {m.counters.input_reports}); "
                       f"{m.conditions()}")

    yield from guarded(DEVICE_REPORT_LOSS, LEVEL, LOSS_CASES, measure)

