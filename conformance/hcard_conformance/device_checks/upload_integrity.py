"""Check ``device.upload-integrity`` (spec/conformance.md 4.6, rules U1-U3; protocol PU1-PU4,
9.3, 9.4): refused uploads leave the card in force playing.

A known card A is committed and playing (the host's finger circles on the surface; STATE
reports show A's targets and generation, UPLOAD_STATUS its CRC-32 and generation). Then
uploads of a card B that the device must refuse, one case each, crafted from raw
UPLOAD_BEGIN / UPLOAD_DATA / UPLOAD_END reports (:func:`bad_uploads`): ``bad-crc``,
``truncated``, ``out-of-order``, ``interrupted`` (2 s of upload silence, then the host
resumes), ``restarted`` (a new BEGIN, then the old upload's remaining chunks), ``oversize``,
two uploads transferred intact whose card the device must not read (PU3): ``unknown-major``
(major version 2) and ``invalid-card`` (a baseline that is not finite, T3), and
``clipped-card``, a valid card asking more than the device renders, which must be committed and
played clipped, flagged CARD_CLIPPED and listed in CLIP_REPORT (PU5, PF3). A case passes
when UPLOAD_STATUS is FAILED with the expected result (U1), A's
CRC-32 and generation are still active, and every STATE report during and after the attempt
shows A playing (U2; a neutral frame is excused only when the finger sample it applies came
after a gap in the finger stream, :func:`off_card`). Last, ``valid-after``: a good upload of
B still commits and plays, the swap atomic (U3). The device is started with START argument 0
(an anonymous session on a protocol 1.2 device, where COMMIT works as in 1.1; in a session
with a token every COMMIT fails with BUSY, PN5). The check leaves card A active (a device
keeps no copy of the card it had that the host could read back), its limits untouched, and
the touch source and RUNNING state as it found them.

The check works through the driver's raw reports while the host's finger plays on the surface
(:class:`~.link_session.LinkSession`) and is session-relative: it needs neither a fresh device
nor its uptime, so it passes twice in a row against one device that stays powered.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field

from hcard import build
from hcard.card_io import to_bytes
from hcard.device.base import COMMIT_TIMEOUT_S, Driver
from hcard.device.errors import DeviceError, DeviceStall
from hcard.device.protocol import (
    FRICTION_SCALE,
    UPLOAD_CHUNK_BYTES,
    Capability,
    ClipReport,
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
from hcard.errors import HcardError
from hcard.quantities import MS_PER_S, S_PER_US, US_PER_S
from hcard.v1 import card_pb2 as pb
from hcard_conformance.check_names import DEVICE_UPLOAD_INTEGRITY as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, on_one_driver
from hcard_conformance.device_checks.host_finger import FINGER_PERIOD_S
from hcard_conformance.device_checks.link_session import (
    HOST_PAUSE_MAX_S,
    POLL_S,
    TIME_MODULO,
    LinkSession,
)
from hcard_conformance.realtime import NotKept, attempted_case, device_lag, reasons
from hcard_conformance.result import CannotAssess, CheckResult, unassessed

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
COMMITS = (UploadAction.COMMIT, UploadAction.COMMIT_PROFILE)
"""UPLOAD_END actions whose SET the device holds until its checks end (PU12): the host waits
for it up to the driver's commit timeout, not the 1 s of any other request."""
PROBE = "probe"
"""Step of an attempt: GET UPLOAD_STATUS now; it must already be FAILED with the result."""
UPLOAD_CASES = ("bad-crc", "truncated", "out-of-order", "interrupted", "restarted", "oversize",
                "unknown-major", "invalid-card", "clipped-card", "valid-after")
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


def clipped_card(info: DeviceInfo) -> LinkCard:
    """A valid card that asks more than any device renders: uniform UV 0 (no friction left:
    an amplitude no plate reaches at 120 mm/s, the clip report's reference speed) on a device
    with UV, else EV 4 (a voltage no EV electrode reaches at 0.5 N). Committed and played
    clipped, never refused (protocol PU5)."""
    uv = bool(info.capabilities & Capability.UV)
    return link_card(info, 0.0) if uv else link_card(info, 3.0)


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


INVALID_CARD_DETAILS = {"unknown-major": "version.major", "invalid-card": "textures[0].baseline"}
"""The UPLOAD_STATUS ``detail`` each INVALID_CARD case must give: the field path of the card's
first error (protocol PU8; README 1.4)."""


def unknown_major(data: bytes) -> bytes:
    """``data``, a valid card, as a card of major version 2: every byte intact and well formed,
    but of a format version no v1 reader may read (README V1; protocol PU3: INVALID_CARD)."""
    card = pb.Card.FromString(data)
    card.version.major = 2
    return card.SerializeToString(deterministic=True)


def broken_rule(data: bytes) -> bytes:
    """``data``, a valid card, with its first texture's baseline not finite: it parses and is
    of version 1, but breaks an error rule of README section 5 (T3; protocol PU3:
    INVALID_CARD)."""
    card = pb.Card.FromString(data)
    card.textures[0].baseline = math.nan
    return card.SerializeToString(deterministic=True)


def complete_upload(data: bytes) -> list[Step]:
    """BEGIN with the length and CRC-32 of ``data``, its chunks in order, and COMMIT: an upload
    whose transfer is right, so that only the card's content can refuse it."""
    return [UploadBegin(len(data), crc32(data)), *chunks(data), UploadEnd(UploadAction.COMMIT)]


def bad_uploads(data: bytes, max_card_bytes: int) -> dict[str, tuple[list[Step], UploadResult]]:
    """The uploads of ``data`` (a valid card) that a device must refuse, by case: the steps and
    the result UPLOAD_STATUS must give (protocol 9.4). Every attempt ends with COMMIT, as a host
    that ignored the failure would send."""
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
        # transferred intact, but a card of a major version the device cannot read (PU3, V1)
        "unknown-major": (complete_upload(unknown_major(data)), UploadResult.INVALID_CARD),
        # transferred intact, version 1, but an error rule broken (PU3, T3)
        "invalid-card": (complete_upload(broken_rule(data)), UploadResult.INVALID_CARD),
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


def run_attempt(session: LinkSession, steps: Sequence[Step]) -> Attempt:
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
            run_quiet(session, step)
            continue
        else:
            held = isinstance(step, UploadEnd) and step.action in COMMITS
            try:  # the status stage of a COMMIT comes once the device has checked (PU12)
                with driver.waiting_at_most(max(driver.timeout_s, COMMIT_TIMEOUT_S)) if held \
                        else contextlib.nullcontext():
                    driver.set_report(step)
            except DeviceStall:
                stalls.append(step.name())
        session.run(POLL_S)
    session.run(AFTER_S)
    status = driver.upload_status()
    return Attempt(status, probes, stalls, session.states[first:], session.longest_pause_s)


def run_quiet(session: LinkSession, seconds: float) -> list[State]:
    """:meth:`LinkSession.run` for ``seconds`` of the host's clock and of the device's: a
    device that fell behind its real-time clock (device protocol PI4) counts less time than the
    host, and an upload silence must last ``seconds`` on the clock of the device's timeout (PU4:
    "2 s of device time"). The device's time is that of the reports read, from the newest one
    read before; at most ``seconds`` more of the host's clock are added."""
    since = session.states[-1].timestamp_us if session.states else None
    got = session.run(seconds)
    deadline = session.driver.clock() + seconds
    while (since is not None and session.driver.clock() < deadline
           and (not got or ((got[-1].timestamp_us - since) % TIME_MODULO) * S_PER_US
                < seconds)):
        got += session.run(SETTLE_S)
    return got


def upload(session: LinkSession, card: LinkCard) -> Attempt:
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
            device_us += (state.timestamp_us - states[k - 1].timestamp_us) % TIME_MODULO
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


def play_until_shown(session: LinkSession, card: LinkCard, generation: int) -> list[State]:
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


def see_playing(session: LinkSession, card: LinkCard, generation: int) -> list[State]:
    """:func:`play_until_shown`, from the first report of ``generation`` on."""
    return from_generation(play_until_shown(session, card, generation), generation)


class CommittedNotPlaying(HcardError):
    """Card A was committed (UPLOAD_STATUS COMMITTED with its CRC-32) in a run kept in real
    time, but the reports after it do not show it playing: the device fails the case (U2: the
    card in force plays; U3: a committed card plays), which :func:`failed_case` reports.

    Attributes:
        off: the reports that do not show card A playing.
    """

    def __init__(self, detail: str, off: int) -> None:
        super().__init__(detail)
        self.off = off


def failed_case(case: str, exc: CommittedNotPlaying) -> CheckResult:
    """The FAIL of ``case`` when card A, committed before it, did not play."""
    return CheckResult(CHECK, LEVEL, case, False, "reports_off_card_a", float(exc.off), 0.0,
                       "reports", str(exc))


def ensure_card(session: LinkSession, card: LinkCard) -> int:
    """Make ``card`` the card in force and see it play; its generation.

    When UPLOAD_STATUS already names its CRC-32 and the reports show it playing
    (:func:`see_playing`), nothing is sent; otherwise it is uploaded (which also ends a
    streaming mode left by an earlier session).

    Raises:
        CannotAssess: it does not commit.
        NotKept: it committed and did not play, while the host paused longer than
            :data:`HOST_PAUSE_MAX_S` or the device flagged REALTIME_LAG (spec QT3).
        CommittedNotPlaying: it committed and did not play in a run kept in real time: a
            COMMITTED card that never plays once failed nothing (UNASSESSED)."""
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
    states = see_playing(session, card, generation)
    kinds = [classify(s, card, generation) for s in states]
    if OTHER in kinds or kinds.count(SHOWS) < MIN_PLAYING_REPORTS:
        detail = (f"card A committed, UPLOAD_STATUS {status_text(attempt.status)}, but "
                  f"{kinds.count(SHOWS)} of {len(kinds)} STATE reports after it show it playing "
                  f"(targets {card.target}, generation {generation}; at least "
                  f"{MIN_PLAYING_REPORTS} and none against it required): a committed card "
                  "must play (U2, U3)")
        host = (f"the host paused {session.longest_pause_s * MS_PER_S:.0f} ms between reads"
                if session.longest_pause_s > HOST_PAUSE_MAX_S else "")
        why = reasons(host, device_lag(states))
        if why:
            raise NotKept(f"{why}; {detail}")
        raise CommittedNotPlaying(detail, len(kinds) - kinds.count(SHOWS))
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
    probe; an INVALID_CARD naming the field of :data:`INVALID_CARD_DETAILS`, PU8), no STALL,
    A's CRC-32 and ``generation`` still active, at least :data:`MIN_PLAYING_REPORTS` reports
    showing A playing and none against it (:func:`off_card`). The metric is the number of
    reports against A."""
    status = attempt.status
    refused = status.state == UploadState.FAILED and status.result == expected
    detail = INVALID_CARD_DETAILS.get(case)
    named = detail is None or not refused or status.detail == detail
    probes_ok = all(p.state == UploadState.FAILED and p.result == expected
                    for p in attempt.probes)
    kept = status.active_crc32 == card_a.crc and status.card_generation == generation
    playing, excused, off = off_card(attempt.states, card_a, generation)
    passed = (refused and named and probes_ok and kept and off == 0
              and playing >= MIN_PLAYING_REPORTS and not attempt.stalls)
    parts = [f"expected FAILED {expected.name}, device said {status_text(status)}"]
    if not named:
        parts.append(f"detail {status.detail!r}, not the field path {detail!r} (PU8)")
    parts += [f"while sending: {status_text(p)}" for p in attempt.probes
              if not (p.state == UploadState.FAILED and p.result == expected)]
    if not kept:
        parts.append(f"card A (CRC 0x{card_a.crc:08X} gen {generation}) replaced")
    parts.append(f"{playing} of {len(attempt.states)} reports show A playing"
                 + _excused_text(attempt, excused))
    if attempt.stalls:
        parts.append(f"STALL on {', '.join(attempt.stalls)} (PU6)")
    return CheckResult(CHECK, LEVEL, case, passed, "reports_off_card_a",
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
    return CheckResult(CHECK, LEVEL, "valid-after", passed,
                       "reports_off_card", float(wrong), 0.0, "reports", detail)


def measure_upload_integrity(driver: Driver, wants: Callable[[str], bool] | None = None,
                             ) -> Iterator[CheckResult]:
    """The cases of ``device.upload-integrity`` on one open driver (module docstring); with
    ``wants``, only the cases it is true of (each case is an attempt of its own on card A)."""
    info = driver.info()
    card_a, card_b = link_card(info, CARD_A_FRICTION), link_card(info, CARD_B_FRICTION)
    if info.max_card_bytes < len(card_b.data):
        raise CannotAssess(f"the test card ({len(card_b.data)} B) is larger than "
                           f"max_card_bytes {info.max_card_bytes}")
    session = LinkSession(driver)
    session.begin(anonymous=True)
    try:
        uploads = bad_uploads(card_b.data, info.max_card_bytes)
        for case, (steps, expected) in uploads.items():
            if wants is not None and not wants(case):
                continue
            if case == "oversize" and info.max_card_bytes >= 0xFFFF_FFFF:
                yield unassessed(CHECK, LEVEL, case, "max_card_bytes is "
                                 "the largest u32: no announced size is above it")
                continue

            def refusal(case: str = case, steps: list[Step] = steps,
                        expected: UploadResult = expected) -> CheckResult:
                try:
                    generation = ensure_card(session, card_a)
                except CommittedNotPlaying as exc:
                    return failed_case(case, exc)
                attempt = run_attempt(session, steps)
                return kept(judge_refusal(case, attempt, expected, card_a, generation), attempt)

            yield attempted_case(CHECK, LEVEL, case, refusal)

        def clipped() -> CheckResult:
            try:
                generation = ensure_card(session, card_a)
            except CommittedNotPlaying as exc:
                return failed_case("clipped-card", exc)
            card_c = clipped_card(info)
            attempt = upload(session, card_c)
            if attempt.status.state == UploadState.COMMITTED:  # read on until it plays
                attempt.states += session.run(SEE_TIMEOUT_S / 4)
            try:
                clip: ClipReport | None = driver.clip_report()
            except DeviceError:
                clip = None
            return kept(judge_clipped(attempt, card_c, generation, clip), attempt)

        if wants is None or wants("clipped-card"):
            yield attempted_case(CHECK, LEVEL, "clipped-card", clipped)

        def commit() -> CheckResult:
            try:
                generation = ensure_card(session, card_a)
            except CommittedNotPlaying as exc:
                return failed_case("valid-after", exc)
            attempt = upload(session, card_b)
            if attempt.status.state == UploadState.COMMITTED:  # a slow host: B's reports lag
                attempt.states += play_until_shown(session, card_b, next_generation(generation))
            return kept(judge_commit(attempt, card_b, generation, card_a), attempt)

        if wants is None or wants("valid-after"):
            yield attempted_case(CHECK, LEVEL, "valid-after", commit)
        with contextlib.suppress(CommittedNotPlaying):  # its cases have failed already
            ensure_card(session, card_a)  # leave card A in force (module docstring)
    finally:
        session.restore()


def judge_clipped(attempt: Attempt, card_c: LinkCard, generation_a: int,
                  clip: ClipReport | None) -> CheckResult:
    """PU5 and PF3: the card that asks too much is COMMITTED with its CRC-32 and the next
    generation (not refused), at least :data:`MIN_PLAYING_REPORTS` reports of that generation
    carry fault CARD_CLIPPED, and CLIP_REPORT, read after, is of that generation and lists at
    least one item. The metric is the number of that generation's reports without the fault."""
    status = attempt.status
    generation = next_generation(generation_a)
    committed = (status.state == UploadState.COMMITTED and status.active_crc32 == card_c.crc
                 and status.card_generation == generation)
    mine = [s for s in attempt.states if s.card_generation == generation]
    flagged = sum(1 for s in mine if s.faults & FaultBits.CARD_CLIPPED)
    listed = clip is not None and clip.card_generation == generation and clip.item_count >= 1
    passed = committed and listed and flagged >= MIN_PLAYING_REPORTS and flagged == len(mine)
    clip_text = ("CLIP_REPORT unreadable" if clip is None else
                 f"CLIP_REPORT gen {clip.card_generation}, {clip.item_count} item(s)")
    detail = (f"expected COMMITTED gen {generation} CRC 0x{card_c.crc:08X} (PU5: a card asking "
              f"too much is played clipped), device said {status_text(status)}; "
              f"{flagged} of {len(mine)} reports of it flag CARD_CLIPPED; {clip_text} (PF3)")
    return CheckResult(CHECK, LEVEL, "clipped-card", passed, "reports_unflagged",
                       float(len(mine) - flagged), 0.0, "reports", detail)


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
    yield from on_one_driver(ctx, CHECK, UPLOAD_CASES, measure_upload_integrity)
