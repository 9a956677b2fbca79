"""Check ``device.profile-upload`` (spec/conformance.md 4.10, rules U4-U5; protocol PU9-PU11):
device profiles a host uploads are checked, put in force, never raise a limit, and CONTROL
DEVICE_PROFILE puts the device's own profile back.

A device renders a card through its *profile*, the map from relative friction to plate
amplitude and EV voltage (spec/device-profile.md); a device with capability PROFILE also takes
one from the host (UPLOAD_END COMMIT_PROFILE). Which profile a device renders with is read from
what it renders (:func:`~.host_profiles.friction_error`): the card's target must come back,
within the A1 threshold, from the measured amplitude and voltage through the profile that
should be in force. The profile the check puts in force, P, is the device's published profile
(the one ``device.friction`` judges it by) with one parameter of its model scaled so that the
two cannot pass for each other (:func:`~.host_profiles.distinct_profile`).

While the host's finger circles on the surface (:class:`~.link_session.LinkSession`, an
anonymous session: a session with a token refuses COMMIT_PROFILE and DEVICE_PROFILE, PN5) over
a uniform card K (:data:`CARD_FRICTION`), the cases are:

``profile-committed`` (PU9)
    from the device's own profile (DEVICE_PROFILE sent first), the distinct profile P uploaded:
    COMMITTED, the card's CRC-32 and generation unchanged, card K playing in every report,
    HOST_PROFILE set from the switch on, and K rendered through P;
``profile-bad-crc``, ``profile-truncated``, ``invalid-profile`` (PU9)
    with P in force, the device's own profile uploaded with its CRC-32 one bit off (FAILED
    CRC_MISMATCH), without its last chunk (SHORT), or, intact, a profile whose models do not
    render the device's channels (:func:`~.host_profiles.wrong_channels`; INVALID_PROFILE with
    a reason in ``detail``): P stays in force and rendered, HOST_PROFILE set throughout;
``limits-not-raised`` (PU10)
    with the limits lowered to :data:`LOWERED_FRACTION` of those in force and a card asking
    more than any device renders playing (driving the output to its limit), the device's own
    profile uploaded with ``limits`` above the hardware limits
    (:func:`~.host_profiles.raised_limits`): COMMITTED, no report over the lowered limits
    (S1's count), LIMITS read back unchanged;
``own-profile-restored`` (PU11)
    with P in force, CONTROL DEVICE_PROFILE: HOST_PROFILE clears and stays clear, card K plays,
    and K is rendered through the device's own profile again.

The check leaves the device's own profile in force (DEVICE_PROFILE), card K active (a device
keeps no copy of the card it had that the host could read back), the limits, the touch source
and RUNNING as it found them. Each case is measured again when it failed in a run not kept in
real time (spec QT3, :func:`~.upload_integrity.kept`).
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hcard.device.base import Driver
from hcard.device.errors import DeviceError
from hcard.device.protocol import (
    FRICTION_SCALE,
    Capability,
    DeviceInfo,
    Limits,
    State,
    StateFlags,
    UploadAction,
    UploadBegin,
    UploadEnd,
    UploadResult,
    UploadState,
    crc32,
)
from hcard.device.published_profiles import published_profile
from hcard.physics.profile import DeviceProfile
from hcard.quantities import NM_PER_M, S_PER_US, UA_PER_A
from hcard_conformance.check_names import DEVICE_PROFILE_UPLOAD as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, on_one_driver
from hcard_conformance.device_checks.friction import FRICTION_JND
from hcard_conformance.device_checks.friction import SETTLE_S as FRICTION_SETTLE_S
from hcard_conformance.device_checks.host_profiles import (
    DistinctProfile,
    distinct_profile,
    friction_error,
    raised_limits,
    wrong_channels,
)
from hcard_conformance.device_checks.link_session import TIME_MODULO, LinkSession
from hcard_conformance.device_checks.safety import over_limits
from hcard_conformance.device_checks.upload_integrity import (
    MIN_PLAYING_REPORTS,
    SEE_TIMEOUT_S,
    SHOWS,
    Attempt,
    CommittedNotPlaying,
    LinkCard,
    Step,
    chunks,
    classify,
    clipped_card,
    ensure_card,
    kept,
    link_card,
    off_card,
    run_attempt,
    status_text,
    upload,
)
from hcard_conformance.realtime import attempted_case
from hcard_conformance.result import CannotAssess, CheckResult

PROFILE_CASES = ("profile-committed", "profile-bad-crc", "profile-truncated", "invalid-profile",
                 "limits-not-raised", "own-profile-restored")
"""The cases of ``device.profile-upload``, in order."""
CARD_FRICTION = 0.7
"""Relative friction of card K (uniform; UV 0.7, or EV 1.7 on a device without UV): a target
both profiles render within the limits at the finger's speed (E-ViTa 259 and 518 nm of its
2500 nm) and far enough from 1 that a profile's parameter moves its commands."""
SETTLE_S = FRICTION_SETTLE_S
"""Reports this long (device time) after a profile switch are left out of the friction error,
s: one 20 ms touch period plus the plate's ~5 ms, as ``device.friction`` leaves out after a
target step."""
JUDGED_REPORTS = 60
"""Settled reports the host reads after each action before it judges (60 ms at 1 kHz), at most
:data:`~.upload_integrity.SEE_TIMEOUT_S` of play."""
LOWERED_FRACTION = 0.5
"""Case ``limits-not-raised``: the limits are lowered to this fraction of those in force, so
a device that lets the profile put its (hardware or higher) limits in force drives the output
to at least twice the lowered limit."""
DRIVEN_FRACTION = 0.5
"""Case ``limits-not-raised``: a report counts as driven when its output (amplitude, or EV
voltage on a device without UV) is at least this fraction of its lowered limit; at least
:data:`~.upload_integrity.MIN_PLAYING_REPORTS` with HOST_PROFILE set must be, or nothing was
asked of the limits."""
_HOST_PROFILE = int(StateFlags.HOST_PROFILE)


def card_friction(card: LinkCard) -> float:
    """The relative friction ``card`` asks for in contact (UV x EV targets)."""
    return card.target[0] * card.target[1] / FRICTION_SCALE**2


def profile_upload(data: bytes, *, crc_flip: int = 0, drop_last: bool = False) -> list[Step]:
    """BEGIN with the length and CRC-32 (XOR ``crc_flip``) of ``data``, its chunks (without
    the last, ``drop_last``) and COMMIT_PROFILE."""
    parts = chunks(data)
    if drop_last:
        parts = parts[:-1]
    return [UploadBegin(len(data), crc32(data) ^ crc_flip), *parts,
            UploadEnd(UploadAction.COMMIT_PROFILE)]


def device_times(states: Sequence[State]) -> np.ndarray:
    """Device time of each report from the first's, s (``timestamp_us`` unwrapped)."""
    if not states:
        return np.zeros(0)
    steps = [(b.timestamp_us - a.timestamp_us) % TIME_MODULO
             for a, b in itertools.pairwise(states)]
    return np.concatenate(([0.0], np.cumsum(steps))) * S_PER_US


def settled(states: Sequence[State], since: int, card: LinkCard, generation: int,
            settle_s: float = SETTLE_S) -> list[State]:
    """The reports of ``states`` from index ``since`` on that are at least ``settle_s`` of
    device time after it and show ``card`` playing (:func:`~.upload_integrity.classify`)."""
    if since >= len(states):
        return []
    t = device_times(states)
    return [s for s, ts in zip(states[since:], t[since:], strict=True)
            if ts >= t[since] + settle_s and classify(s, card, generation) == SHOWS]


def play_on(session: LinkSession, attempt: Attempt, since: Callable[[list[State]], int],
            card: LinkCard, generation: int, settle_s: float = SETTLE_S) -> None:
    """Read on, appending to ``attempt.states``, until :data:`JUDGED_REPORTS` reports are
    settled (``settle_s``) after index ``since(states)``, at most :data:`SEE_TIMEOUT_S`; the
    host's longest pause of the whole attempt noted."""
    end = session.driver.clock() + SEE_TIMEOUT_S
    while session.driver.clock() < end:
        if len(settled(attempt.states, since(attempt.states), card, generation, settle_s)) \
                >= JUDGED_REPORTS:
            break
        attempt.states += session.run(SETTLE_S)
    attempt.longest_pause_s = session.longest_pause_s


def first_with(states: Sequence[State], flag_set: bool) -> int | None:
    """Index of the first report with HOST_PROFILE set (``flag_set``) or clear; None."""
    return next((k for k, s in enumerate(states) if bool(s.flags & _HOST_PROFILE) == flag_set),
                None)


def put_in_force(session: LinkSession, profile: bytes) -> None:
    """Upload ``profile`` and see it COMMITTED, then play :data:`SETTLE_S`.

    Raises:
        CannotAssess: it does not commit (the case that needs it in force cannot be judged;
            case ``profile-committed`` judges a device that refuses a good profile)."""
    attempt = run_attempt(session, profile_upload(profile))
    if attempt.status.state != UploadState.COMMITTED:
        raise CannotAssess(f"the check's profile did not commit: {status_text(attempt.status)}")
    session.run(SETTLE_S)


def _card_text(attempt: Attempt, card: LinkCard, generation: int) -> tuple[bool, str]:
    """Whether every report of the attempt shows card K playing (none against it, at least
    :data:`MIN_PLAYING_REPORTS`), and the words saying so."""
    playing, excused, off = off_card(attempt.states, card, generation)
    ok = off == 0 and playing >= MIN_PLAYING_REPORTS
    text = f"{playing} of {len(attempt.states)} reports show card K playing"
    if excused:
        text += f" ({excused} neutral after a gap in the finger stream excused)"
    return ok, text


def _result(case: str, passed: bool, error: float, threshold: float, parts: list[str]
            ) -> CheckResult:
    return CheckResult(CHECK, LEVEL, case, passed and math.isfinite(error) and error <= threshold,
                       "rms_relative_error", error, threshold, "relative", "; ".join(parts))


def judge_committed(attempt: Attempt, card: LinkCard, generation: int,
                    distinct: DistinctProfile, info: DeviceInfo, threshold: float
                    ) -> CheckResult:
    """PU9 for a good profile: COMMITTED, the card's CRC-32 and generation unchanged, no STALL,
    card K playing throughout, HOST_PROFILE set from its first report on, and K rendered
    through the uploaded profile within ``threshold`` (the metric)."""
    status = attempt.status
    committed = (status.state == UploadState.COMMITTED and status.active_crc32 == card.crc
                 and status.card_generation == generation)
    playing, card_text = _card_text(attempt, card, generation)
    switch = first_with(attempt.states, True)
    after = attempt.states[switch:] if switch is not None else []
    flag_off = sum(1 for s in after if not s.flags & _HOST_PROFILE)
    judged = settled(attempt.states, switch, card, generation) if switch is not None else []
    error = friction_error(judged, distinct.profile, card_friction(card), info)
    flagged = switch is not None and flag_off == 0
    enough = len(judged) >= MIN_PLAYING_REPORTS
    parts = [f"expected COMMITTED with the card's CRC 0x{card.crc:08X} gen {generation}, "
             f"device said {status_text(status)}", card_text,
             ("HOST_PROFILE never set" if switch is None else
              f"HOST_PROFILE set from report {switch} on, {flag_off} after it without"),
             f"{len(judged)} settled reports through the uploaded profile ({distinct.parameter} "
             f"x {distinct.factor:g}): RMS relative error {error:.4f}"]
    if attempt.stalls:
        parts.append(f"STALL on {', '.join(attempt.stalls)} (PU6)")
    return _result("profile-committed", committed and playing and flagged and enough
                   and not attempt.stalls, error, threshold, parts)


def judge_refused(case: str, attempt: Attempt, expected: UploadResult, card: LinkCard,
                  generation: int, distinct: DistinctProfile, info: DeviceInfo,
                  threshold: float) -> CheckResult:
    """PU9 for a profile upload the device must refuse: FAILED with ``expected`` (an
    INVALID_PROFILE with a reason in ``detail``), no STALL, the card's CRC-32 and generation
    unchanged, card K playing and HOST_PROFILE set in every report, and K rendered through the
    profile in force before, the distinct one, within ``threshold`` (the metric)."""
    status = attempt.status
    refused = status.state == UploadState.FAILED and status.result == expected
    reason = expected != UploadResult.INVALID_PROFILE or bool(status.detail)
    kept_card = status.active_crc32 == card.crc and status.card_generation == generation
    playing, card_text = _card_text(attempt, card, generation)
    flag_off = sum(1 for s in attempt.states if not s.flags & _HOST_PROFILE)
    judged = settled(attempt.states, 0, card, generation, 0.0)  # in force and settled before
    error = friction_error(judged, distinct.profile, card_friction(card), info)
    enough = len(judged) >= MIN_PLAYING_REPORTS
    parts = [f"expected FAILED {expected.name}, device said {status_text(status)}"
             + (f" ({status.detail!r})" if status.detail else "")]
    if not reason:
        parts.append("no reason in detail (PU9)")
    if not kept_card:
        parts.append(f"the card (CRC 0x{card.crc:08X} gen {generation}) replaced")
    parts += [card_text, f"{flag_off} reports without HOST_PROFILE",
              f"{len(judged)} settled reports through the profile in force before: RMS "
              f"relative error {error:.4f}"]
    if attempt.stalls:
        parts.append(f"STALL on {', '.join(attempt.stalls)} (PU6)")
    return _result(case, refused and reason and kept_card and playing and flag_off == 0
                   and enough and not attempt.stalls, error, threshold, parts)


def judge_restored(attempt: Attempt, card: LinkCard, generation: int, own: DeviceProfile,
                   info: DeviceInfo, threshold: float) -> CheckResult:
    """PU11: after CONTROL DEVICE_PROFILE (``attempt.states`` from the command on), HOST_PROFILE
    clears and stays clear, card K plays throughout, and K is rendered through the device's own
    profile within ``threshold`` (the metric; judged from the command on when the flag never
    clears)."""
    playing, card_text = _card_text(attempt, card, generation)
    switch = first_with(attempt.states, False)
    after = attempt.states[switch:] if switch is not None else []
    flag_on = sum(1 for s in after if s.flags & _HOST_PROFILE)
    judged = settled(attempt.states, switch if switch is not None else 0, card, generation)
    error = friction_error(judged, own, card_friction(card), info)
    cleared = switch is not None and flag_on == 0
    enough = len(judged) >= MIN_PLAYING_REPORTS
    parts = [("HOST_PROFILE never cleared" if switch is None else
              f"HOST_PROFILE clear from report {switch} on, {flag_on} after it with it set"),
             card_text, f"{len(judged)} settled reports through the device's own profile: RMS "
             f"relative error {error:.4f}"]
    return _result("own-profile-restored", playing and cleared and enough, error, threshold,
                   parts)


def judge_limits(attempt: Attempt, in_force: Limits, read_back: Limits, card: LinkCard,
                 generation: int, info: DeviceInfo) -> CheckResult:
    """PU10: the profile asking for higher limits COMMITTED, no report of the attempt over the
    limits in force (one report count tolerated, as S1; the metric ``n_over``), LIMITS read
    back unchanged, and at least :data:`MIN_PLAYING_REPORTS` reports with HOST_PROFILE set
    driven to :data:`DRIVEN_FRACTION` of their limit while the greedy card plays."""
    status = attempt.status
    committed = status.state == UploadState.COMMITTED
    over, worst = over_limits(attempt.states, in_force)
    uv = bool(info.capabilities & Capability.UV)
    limit = in_force.max_amplitude_m if uv else in_force.max_voltage_v
    driven = sum(1 for s in attempt.states if s.flags & _HOST_PROFILE
                 and classify(s, card, generation) == SHOWS
                 and (s.amplitude_m if uv else s.voltage_v) >= DRIVEN_FRACTION * limit)
    unchanged = read_back == in_force
    parts = [f"expected COMMITTED, device said {status_text(status)}",
             f"{over} of {len(attempt.states)} reports over the limits in force "
             f"({in_force.max_amplitude_m * NM_PER_M:.0f} nm, {in_force.max_voltage_v:g} V, "
             f"{in_force.max_current_a * UA_PER_A:g} uA; tolerance one report count); largest "
             f"output {worst:.3f} x its limit",
             f"LIMITS read back {'unchanged' if unchanged else str(read_back)}",
             f"{driven} reports under the profile driven to {DRIVEN_FRACTION:g} x the "
             f"{'amplitude' if uv else 'voltage'} limit"]
    if attempt.stalls:
        parts.append(f"STALL on {', '.join(attempt.stalls)} (PU6)")
    passed = (committed and over == 0 and unchanged and driven >= MIN_PLAYING_REPORTS
              and not attempt.stalls)
    return CheckResult(CHECK, LEVEL, "limits-not-raised", passed, "n_over", float(over), 0.0,
                       "reports", "; ".join(parts))


def _not_playing(case: str, exc: CommittedNotPlaying) -> CheckResult:
    """The FAIL of ``case`` when card K, committed before it, did not play (U2, U3)."""
    return CheckResult(CHECK, LEVEL, case, False, "reports_off_card_k", float(exc.off), 0.0,
                       "reports", str(exc))


@dataclass(frozen=True)
class ProfileRun:
    """What every case of one run shares.

    Attributes:
        session: the finger circling, every report read.
        info: DEVICE_INFO.
        own: the device's published profile.
        distinct: the profile the check puts in force.
        card: card K.
        threshold: the friction error threshold (A1).
    """

    session: LinkSession
    info: DeviceInfo
    own: DeviceProfile
    distinct: DistinctProfile
    card: LinkCard
    threshold: float

    @property
    def driver(self) -> Driver:
        """The open driver."""
        return self.session.driver

    def own_in_force(self) -> None:
        """CONTROL DEVICE_PROFILE, then :data:`SETTLE_S` of play."""
        self.driver.use_device_profile()
        self.session.run(SETTLE_S)

    def committed(self) -> CheckResult:
        """Case ``profile-committed``."""
        generation = ensure_card(self.session, self.card)
        self.own_in_force()
        attempt = run_attempt(self.session, profile_upload(self.distinct.data))
        play_on(self.session, attempt, lambda states: first_with(states, True) or 0,
                self.card, generation)
        return kept(judge_committed(attempt, self.card, generation, self.distinct, self.info,
                                    self.threshold), attempt)

    def refused(self, case: str) -> CheckResult:
        """Case ``profile-bad-crc``, ``profile-truncated`` or ``invalid-profile``."""
        generation = ensure_card(self.session, self.card)
        put_in_force(self.session, self.distinct.data)
        own = self.own.to_json()
        steps, expected = {
            "profile-bad-crc": (profile_upload(own, crc_flip=1), UploadResult.CRC_MISMATCH),
            "profile-truncated": (profile_upload(own, drop_last=True), UploadResult.SHORT),
            "invalid-profile": (profile_upload(wrong_channels(self.info).to_json()),
                                UploadResult.INVALID_PROFILE),
        }[case]
        attempt = run_attempt(self.session, steps)
        play_on(self.session, attempt, lambda states: 0, self.card, generation, 0.0)
        return kept(judge_refused(case, attempt, expected, self.card, generation,
                                  self.distinct, self.info, self.threshold), attempt)

    def restored(self) -> CheckResult:
        """Case ``own-profile-restored``."""
        generation = ensure_card(self.session, self.card)
        put_in_force(self.session, self.distinct.data)
        self.session.mark()
        self.driver.use_device_profile()
        attempt = Attempt(self.driver.upload_status())
        play_on(self.session, attempt, lambda states: first_with(states, False) or 0,
                self.card, generation)
        return kept(judge_restored(attempt, self.card, generation, self.own, self.info,
                                   self.threshold), attempt)

    def limits(self) -> CheckResult:
        """Case ``limits-not-raised``; the limits found are restored, whatever happens."""
        ensure_card(self.session, self.card)
        self.own_in_force()
        found = self.driver.limits()
        try:
            self.driver.set_report(Limits.from_si(found.max_amplitude_m * LOWERED_FRACTION,
                                                  found.max_voltage_v * LOWERED_FRACTION,
                                                  found.max_current_a * LOWERED_FRACTION))
            in_force = self.driver.limits()
            greedy = clipped_card(self.info)
            loaded = upload(self.session, greedy)
            if loaded.status.state != UploadState.COMMITTED:
                raise CannotAssess(f"the card asking more than the device renders did not "
                                   f"commit: {status_text(loaded.status)}")
            generation = loaded.status.card_generation
            self.session.run(SETTLE_S)
            attempt = run_attempt(self.session,
                                  profile_upload(raised_limits(self.own, self.info).to_json()))
            play_on(self.session, attempt, lambda states: first_with(states, True) or 0,
                    greedy, generation)
            read_back = self.driver.limits()
            return kept(judge_limits(attempt, in_force, read_back, greedy, generation,
                                     self.info), attempt)
        finally:  # a device stays powered between runs: leave its limits and profile
            self.driver.set_limits(found.max_amplitude_m, found.max_voltage_v,
                                   found.max_current_a)
            self.driver.use_device_profile()


def _guarded_case(case: str, measure: Callable[[], CheckResult]) -> CheckResult:
    """``measure()``, a case whose card K did not play (committed, in a run kept in real time)
    failing as in ``device.upload-integrity``."""
    try:
        return measure()
    except CommittedNotPlaying as exc:
        return _not_playing(case, exc)


def measure_profile_upload(driver: Driver, wants: Callable[[str], bool] | None = None,
                           threshold: float = FRICTION_JND) -> Iterator[CheckResult]:
    """The cases of ``device.profile-upload`` on one open driver (module docstring); with
    ``wants``, only the cases it is true of. ``threshold``: the RMS relative friction error
    of a profile in force (A1).

    Raises:
        CannotAssess: no installed plugin publishes the device's profile, no profile of its
            own can be told from it (:func:`distinct_profile`), or the profile or card does
            not fit ``max_card_bytes``.
    """
    info = driver.info()
    own = published_profile(info)
    if own is None:
        raise CannotAssess(
            f"no installed device-profile plugin publishes the physics of this device (device "
            f"kind {info.device_kind}, plate {info.plate_frequency_hz} Hz): the check builds the "
            "profile it uploads from it and judges the device's own rendering by it")
    card = link_card(info, CARD_FRICTION)
    distinct = distinct_profile(own, info, card_friction(card), threshold)
    largest = max(len(distinct.data), len(own.to_json()), len(card.data))
    if largest > info.max_card_bytes:
        raise CannotAssess(f"the check's uploads ({largest} B) are larger than max_card_bytes "
                           f"{info.max_card_bytes}")
    session = LinkSession(driver)
    session.begin(anonymous=True)
    run = ProfileRun(session, info, own, distinct, card, threshold)
    measures: dict[str, Callable[[], CheckResult]] = {
        "profile-committed": run.committed,
        "profile-bad-crc": lambda: run.refused("profile-bad-crc"),
        "profile-truncated": lambda: run.refused("profile-truncated"),
        "invalid-profile": lambda: run.refused("invalid-profile"),
        "limits-not-raised": run.limits,
        "own-profile-restored": run.restored,
    }
    try:
        for case in PROFILE_CASES:
            if wants is not None and not wants(case):
                continue
            yield attempted_case(CHECK, LEVEL, case,
                                 functools.partial(_guarded_case, case, measures[case]))
        with contextlib.suppress(CommittedNotPlaying, CannotAssess, DeviceError):
            ensure_card(session, card)  # leave card K in force, as upload-integrity leaves A
    finally:
        with contextlib.suppress(DeviceError):
            driver.use_device_profile()  # the device's own profile in force (PU11)
        session.restore()


def check_profile_upload(ctx: Context) -> Iterator[CheckResult]:
    """Profiles a host uploads are checked and put in force, never raise a limit, and
    DEVICE_PROFILE puts the device's own back (PU9-PU11)."""
    yield from on_one_driver(ctx, CHECK, PROFILE_CASES, measure_profile_upload)

