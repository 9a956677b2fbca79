"""Check ``device.friction``: rendered relative friction against the card's target, through
a driver (spec/conformance.md, A1 at the device level).

Rendered friction is the device's *measured* actuation (plate amplitude, EV voltage, normal
force in STATE) through the forward map of the device's physics profile
(:func:`device_profile_for`), at the finger speed of the track the host drove; the target is
:func:`hcard.render.render` of the card along that track (hybrid, 10 kframes/s). Reports before
the device has the stroke's second touch sample (its first speed estimate, from the echo;
transport delay is judged by ``device.latency``) plus :data:`PLATE_SETTLE_S`, and within
:data:`SETTLE_S` of touch-down or of a step of the target larger than the JND, are left out
(the loop settling; boundary placement is judged by the renderer level). Metric: RMS relative
error ``(rendered - target) / target``; threshold :data:`FRICTION_JND` (8 %).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from hcard import build
from hcard.device.base import Driver
from hcard.device.play import play
from hcard.device.play_result import PlayResult
from hcard.device.protocol import Capability, DeviceInfo
from hcard.device.published_profiles import published_profile
from hcard.physics.profile import DeviceProfile
from hcard.quantities import M_PER_MM
from hcard.render import render
from hcard.render.touch import segment_speeds
from hcard.track import FingerTrack, straight_stroke
from hcard.v1 import card_pb2 as pb
from hcard_conformance.check_names import DEVICE_FRICTION as CHECK
from hcard_conformance.context import Context, session_times
from hcard_conformance.device_checks.common import LEVEL, STROKE_SPEED_MM_S, judged
from hcard_conformance.realtime import HostWatch, NotKept, attempts, device_lag, reasons
from hcard_conformance.result import CannotAssess, CheckResult, guarded

FRICTION_JND = 0.08
"""Relative friction JND: threshold of the RMS relative friction error."""
SETTLE_S = 0.025
"""Reports this long after touch-down or a target step are left out of the friction error, s:
one 20 ms touch period plus the plate's ~5 ms settling."""
PLATE_SETTLE_S = 0.005
"""Reports this long after the device has the stroke's second touch sample are left out too,
s: before it the device has no speed for its velocity compensation (a touch-down is one
sample), and the plate then needs ~5 ms to settle. A second sample that the transport delayed
(9 ms once over USB/IP on a busy host) would otherwise count as a friction error; the delay
itself is judged by ``device.latency``."""
STEP_LEAD_S = 0.002
"""Reports this long before a target step are left out too, s: with report times exact (echo
age, device protocol 1.3) a crossing the device dead-reckoned a report early shows there (0.12
mm at 60 mm/s: a placement judged by A5 at the renderer level, not a friction level; one such
report of 0.5 relative error put coarse-taxtels at 0.02 RMS on the reference)."""
STROKE_S = 0.6
"""Duration of the device-level strokes, s."""


def device_profile_for(info: DeviceInfo) -> DeviceProfile:
    """The physics profile the device ``info`` describes publishes, from its ``device-profile``
    plugin (:func:`hcard.device.published_profiles.published_profile`; the reference devices'
    are the firmware's models).

    Raises:
        CannotAssess: no installed plugin publishes the device's profile.
    """
    profile = published_profile(info)
    if profile is None:
        raise CannotAssess(
            f"no installed device-profile plugin publishes the physics of this device (device "
            f"kind {info.device_kind}, plate {info.plate_frequency_hz} Hz): rendered friction "
            "is judged through the device's own profile")
    return profile


def friction_cases(info: DeviceInfo) -> list[tuple[str, pb.Card, FingerTrack]]:
    """Device-level (card, track) cases, one moderate 60 mm/s stroke at 50 Hz touch: a coarse
    checkerboard of uniform UV textures (10 mm taxtels, friction 1 and 0.5), a dense 4 mm UV
    grating (0.35-0.85), and, for devices with EV, a checkerboard of BIPOLAR textures 0.6 (UV)
    and 1.2 (EV; within what the coupled stimulator reaches at 0.5 N, about 1.23)."""
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    track = straight_stroke((10.0, height / 2), (STROKE_SPEED_MM_S, 0.0), STROKE_S)
    cols = math.ceil(width / 10.0)
    rows = math.ceil(height / 10.0)
    coarse = build.card(width, height, taxtel_mm=10.0, textures=[
        build.texture(1.0, channel="uv"), build.texture(0.5, channel="uv")],
        texture_index=[(r + c) % 2 for r in range(rows) for c in range(cols)], title="coarse")
    dense = build.card(width, height, taxtel_mm=width, textures=[
        build.texture(0.6, [build.grating_period(4.0, 0.25)], channel="uv")], title="dense")
    cases = [("coarse-taxtels", coarse, track), ("dense-grating", dense, track)]
    if info.capabilities & Capability.EV:
        bipolar = build.card(width, height, taxtel_mm=10.0, textures=[
            build.texture(0.6, channel="bipolar"), build.texture(1.2, channel="bipolar")],
            texture_index=[(r + c) % 2 for r in range(rows) for c in range(cols)],
            title="bipolar")
        cases.append(("bipolar", bipolar, track))
    return cases


def friction_case_names(ctx: Context) -> list[str]:
    """Cases of ``device.friction`` (registry declaration): those of :func:`friction_cases`
    for the device's DEVICE_INFO (:meth:`Context.device_info`, which opens the driver once to
    read it: ``bipolar`` only on a device with EV); none without a device."""
    if ctx.open_driver is None:
        return []
    return [name for name, _card, _track in friction_cases(ctx.device_info())]


@dataclass(frozen=True)
class FrictionMeasurement:
    """Rendered against target friction over the settled reports in contact.

    Attributes:
        rms_relative_error: RMS of ``(rendered - target) / target``.
        reports: reports compared.
        t_s: their track times, s; rendered, target: relative friction.
    """

    rms_relative_error: float
    reports: int
    t_s: np.ndarray
    rendered: np.ndarray
    target: np.ndarray


def rendered_friction(result: PlayResult,
                      profile: DeviceProfile) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Track time (s), rendered relative friction and contact of each report of the session:
    the measured amplitude and voltage through ``profile.forward`` at the track's speed
    (:func:`track_speed`) and the measured normal force (the track's, the host finger's, on a
    device without corner force sensors)."""
    track = result.track
    keep, t = session_times(result.states, track, result.host_us)
    applied = [s for s, ok in zip(result.states, keep, strict=True) if ok]
    t = t[keep]
    v = track_speed(track, t)
    amplitude = np.array([s.amplitude_m for s in applied])
    voltage = np.array([s.voltage_v for s in applied])
    if result.info.capabilities & Capability.CORNER_FORCES:
        fn = np.array([s.normal_force_n for s in applied])
    else:
        fn = np.interp(t, track.t, track.normal_force)
    uv, ev = profile.forward(amplitude, voltage, v, np.maximum(fn, 1e-3))
    contact = np.array([bool(s.contact) for s in applied], dtype=bool) & (fn > 0.05)
    return t, uv * ev, contact


def track_speed(track: FingerTrack, t: np.ndarray) -> np.ndarray:
    """The finger's speed along ``track`` at track times ``t`` (s), m/s. The finger moves
    straight between samples (as the simulated finger does), so it is the speed of the segment
    a time falls in: rule R4's estimate at the segment's end sample (the first or last segment
    outside the track)."""
    segment = segment_speeds(track.t, track.x, track.y) * M_PER_MM
    if len(track) < 2:
        return np.zeros(t.shape[0])
    return segment[np.clip(track.t.searchsorted(t, side="right"), 1, len(track) - 1)]


def speed_known_s(result: PlayResult) -> float:
    """Track time (s) of the first report that echoes a touch sample after the stroke's first:
    from it the device has two samples, so a speed; +inf when no report does."""
    from hcard.device.recording import echoed_samples
    from hcard.device.state_log import state_field

    keep, t = session_times(result.states, result.track, result.host_us)
    echo = state_field(result.states, "host_time_echo_us").astype(np.int64)
    later = keep & (echoed_samples(result.sent_host_us(), echo) >= 1)
    return float(t[later][0]) if later.any() else math.inf


def measure_friction(driver: Driver, card: pb.Card, track: FingerTrack) -> FrictionMeasurement:
    """Play ``card`` along ``track`` and compare rendered with target friction. A play over
    the threshold in which the host did not run for more than
    :data:`~hcard_conformance.realtime.HOST_LATE_S` (its finger samples left late: the device
    rendered from stale ones) or the device flagged a report REALTIME_LAG raises
    :class:`NotKept` (spec QT3)."""
    profile = device_profile_for(driver.info())
    with HostWatch() as watch:
        result = play(driver, card, track)
    t, rendered, contact = rendered_friction(result, profile)
    m = friction_error(t, rendered, contact, card, track,
                       start_s=speed_known_s(result) + PLATE_SETTLE_S)
    if not m.rms_relative_error <= FRICTION_JND:
        late = reasons(watch.late if driver.realtime else "", device_lag(result.states))
        if late:
            raise NotKept(f"{late}; RMS relative error {m.rms_relative_error:.3f}")
    return m


def friction_error(t: np.ndarray, rendered: np.ndarray, contact: np.ndarray, card: pb.Card,
                   track: FingerTrack, lead_s: float = STEP_LEAD_S,
                   start_s: float = -math.inf) -> FrictionMeasurement:
    """Rendered friction at track times ``t`` (s) against the card's target along ``track``,
    over the settled reports in contact: after :data:`SETTLE_S` of the stroke and at or after
    ``start_s`` (track time, s; :func:`measure_friction` passes the time the device had a
    speed plus :data:`PLATE_SETTLE_S`), outside ``[step - lead_s, step + SETTLE_S)`` of every
    target step."""
    golden = render(card, track)
    target = np.interp(t, golden.t, golden.friction)
    settled = (contact & (t >= max(track.t[0] + SETTLE_S, start_s))
               & (t <= track.t[-1]))
    steps = golden.t[1:][np.abs(np.diff(golden.friction)) > FRICTION_JND]
    for step in steps:
        settled &= ~((t >= step - lead_s) & (t < step + SETTLE_S))
    error = (rendered[settled] - target[settled]) / target[settled]
    rms = float(np.sqrt(np.mean(error**2))) if error.size else math.nan
    return FrictionMeasurement(rms, int(error.size), t[settled], rendered[settled],
                               target[settled])


def check_friction(ctx: Context) -> Iterator[CheckResult]:
    """Rendered friction from measured actuation vs the card's target, per case."""
    if ctx.open_driver is None:
        return
    with ctx.open_driver() as driver:
        cases = friction_cases(driver.info())
    for case, card, track in cases:
        if not ctx.wants(CHECK, case):  # each case is a play of its own
            continue

        def measure(case: str = case, card: pb.Card = card,
                    track: FingerTrack = track) -> Iterator[CheckResult]:
            open_driver = ctx.open_driver
            assert open_driver is not None

            def one_play() -> FrictionMeasurement:
                with open_driver() as driver:
                    return measure_friction(driver, card, track)

            m = attempts(one_play, f"the play of {case}")
            if m.reports == 0:
                raise CannotAssess("no settled report in contact echoed a finger sample of "
                                   "the session")
            yield judged(CHECK, case, "rms_relative_error", m.rms_relative_error,
                          FRICTION_JND, "relative", f"{m.reports} settled reports in contact")

        yield from guarded(CHECK, LEVEL, [case], measure)
