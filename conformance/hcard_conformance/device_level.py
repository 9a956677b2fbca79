"""Device-level conformance checks: through a driver, what the device physically renders.

Every check opens a fresh driver from the :class:`~hcard_conformance.context.Context` and
reads STATE input reports (spec/device-protocol.md). Thresholds (spec/conformance.md):

``device.friction``
    Rendered relative friction vs the card's target. Rendered friction is the device's
    *measured* actuation (plate amplitude, EV voltage, normal force in STATE) through the
    forward map of the device's physics profile (:func:`device_profile_for`), at the finger
    speed of the track the host drove; the target is :func:`hcard.render.render` of the card
    along that track (hybrid, 10 kframes/s). Reports before the device has the stroke's
    second touch sample (its first speed estimate, from the echo; transport delay is judged
    by ``device.latency``) plus :data:`PLATE_SETTLE_S`, and within :data:`SETTLE_S` of
    touch-down or of a step of the target larger than the JND, are left out (the loop
    settling; boundary placement is judged by the renderer level). Metric: RMS relative error
    ``(rendered - target) / target``; threshold :data:`FRICTION_JND` (8 %).
``device.dynamics`` (D1 bandwidth, D2 rise time)
    Direct streaming of sinusoidal and step UV targets while the host's finger slides at
    60 mm/s; the plate amplitude in STATE is fitted (sinusoids, least squares at the known
    frequency) or timed 10-90 % (step). Thresholds per device class (:data:`CLASS_DYNAMICS`).
    The plate amplitude is used rather than rendered friction held still (spec 4.1 method):
    with the finger still the UV forward map saturates (zero speed gives zero friction at any
    amplitude), so a still finger cannot show the dynamics.
``device.latency``
    Median, over :data:`LATENCY_TRIALS` moves of the host finger across a texture boundary,
    of the time from sending the FINGER report to the measured plate amplitude crossing half
    way to its new settled value; threshold from the timing class (real time: 10 ms: half the
    20 ms period of a 50 Hz touch screen, so a change is felt before the next touch sample).
``device.safety`` (S1)
    Cards, host-set limits and streamed frames asking for more than the limits; metric: the
    number of reports whose measured amplitude / voltage / current exceeds the limit in force
    (one report count of quantisation allowed) or whose targets leave [0, 1] x [1, 4]; must be 0.
    Case ``limits-while-driven`` (PS1, PS5) lowers the limits to :data:`LOWERED_FRACTION` of
    those in force while streamed frames drive the plate at its limit, and counts the reports
    after the change (those echoing a FINGER sent after the SET returned) with an output above
    the new limit.
``device.watchdog``
    The host goes silent while driving the finger; metric: time from the last host report to
    outputs off (amplitude <= :data:`OFF_AMPLITUDE_M`, voltage <= 1 V) with fault WATCHDOG
    reported; threshold ``watchdog_ms`` + :data:`WATCHDOG_ALLOWANCE_S`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hcard import build
from hcard.device.base import Driver
from hcard.device.play import play
from hcard.device.play_result import PlayResult
from hcard.device.protocol import (
    Capability,
    DeviceInfo,
    DeviceKind,
    FaultBits,
    Finger,
    Limits,
    State,
)
from hcard.device.published_profiles import published_profile
from hcard.physics.profile import DeviceProfile
from hcard.quantities import M_PER_MM, MS_PER_S, NM_PER_M, S_PER_MS, S_PER_US, UA_PER_A, US_PER_S
from hcard.render import render
from hcard.render.touch import segment_speeds
from hcard.track import FingerTrack, straight_stroke
from hcard.v1 import card_pb2 as pb
from hcard_conformance.check_names import (
    DEVICE_DYNAMICS,
    DEVICE_FRICTION,
    DEVICE_LATENCY,
    DEVICE_SAFETY,
    DEVICE_WATCHDOG,
)
from hcard_conformance.context import Context, session_times
from hcard_conformance.realtime import (
    HostWatch,
    NotKept,
    attempts,
    collection_deferred,
    device_lag,
    reasons,
)
from hcard_conformance.result import CannotAssess, CheckResult, guarded
from hcard_conformance.streaming import FINGER_PERIOD_S, lead_frames, require_fed, stream_fed
from hcard_conformance.timing import timing_class

LEVEL = "device"
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
STROKE_SPEED_MM_S = 60.0
"""Speed of the device-level strokes (moderate class of section 5.4), mm/s."""
STROKE_S = 0.6
"""Duration of the device-level strokes, s."""
LATENCY_TRIALS = 10
READ_CATCH_UP_S = 5.0
"""Longest a measurement reads on while the host catches up with its reports, s."""
SEND_READ_BATCH = 10
"""Reports a sending loop reads at a time between two FINGER reports (:func:`_read_briefly`)."""
OFF_AMPLITUDE_M = 50e-9
"""Plate amplitude counted as off, m (the E-ViTa loop's 50 nm amplitude tolerance)."""
BANDWIDTH_TOLERANCE = 0.05
"""Measurement tolerance of D1: the swept -3 dB point may fall this fraction below the class
bandwidth (an 8-point sweep interpolated in log f; spec/conformance.md 4.1)."""
WATCHDOG_ALLOWANCE_S = 0.050
"""Time allowed after ``watchdog_ms`` for the 10 ms ramp and the plate's decay, s."""


@dataclass(frozen=True)
class Dynamics:
    """Plate dynamics required of a device class.

    Attributes:
        min_bandwidth_hz: -3 dB bandwidth of the plate amplitude at least, Hz.
        max_rise_s: 10-90 % rise time of the plate amplitude at most, s.
        why: where the numbers come from.
    """

    min_bandwidth_hz: float
    max_rise_s: float
    why: str


CLASS_DYNAMICS = {
    "e-vita": Dynamics(
        400.0, 0.002, "e-vita class (spec/conformance.md D1, D2): 400 Hz at 2 um (thesis "
        "5.1.2); rise-time JND 2 ms"),
    "coupled": Dynamics(
        20.0, 0.015, "coupled class: standalone plate of thesis 4.3.2, ~15 ms response "
        "(tau 6.8 ms, 23 Hz)"),
}
"""Required plate dynamics by device class (``--option device_class=...``; by default from
DEVICE_INFO.device_kind: 1 e-vita, 2 coupled)."""
BANDWIDTH_FREQUENCIES_HZ = (50.0, 110.0, 190.0, 290.0, 350.0, 390.0, 430.0, 470.0)
"""Sweep of D1, Hz: under the 500 Hz Nyquist frequency of 1 kHz STATE reports, and none a
simple fraction of the report rate. The plate's response to a sine carries harmonics (the UV
map is nonlinear, and the loop's drive saturates on fast swings); sampled at 1 kHz, the k-th
harmonic of f folds onto f itself when k f = +-f mod 1 kHz. At 400 Hz the 4th and 6th do, and
the fitted 400 Hz amplitude then depends on the phase at which the sine starts against the report
clock: measured on the reference over usbip, 0.1333-0.1366 from session to session (1 %
spread, 0.25 dB), where 390 Hz gave 0.13667 +- 0.009 %. Here no harmonic up to the 12th folds
within 10 Hz of its fundamental (:func:`folded_harmonics`)."""
BANDWIDTH_REFERENCE_HZ = 25.0
"""Reference of D1, Hz: the plate loop's gain there is its DC gain to 0.02 dB."""
GAIN_WINDOW_S = 0.04
"""Shortest window of one sinusoid fit of D1, s (whole periods of the stimulus)."""
UNDERRUN_GUARD_S = 0.010
"""Reports left out of D1 after a report with an empty stream queue, s: the device played
neutral frames there and the plate needs a few time constants (0.6 ms on the E-ViTa) to return
to the stimulus; 1 ms before it as well (the queue may have emptied since the last report)."""
MIN_CLEAN_WINDOW_FRACTION = 0.5
"""Fraction of D1's windows that must be clear of empty-queue reports for a gain to count."""
BANDWIDTH_UV_MEAN, BANDWIDTH_UV_SWING = 0.25, 0.05
"""Streamed UV target of D1, ``mean + swing sin``: about 2 um of plate amplitude at
60 mm/s and 0.5 N on the E-ViTa, the operating point of its 400 Hz bandwidth."""


def device_class(ctx: Context, info: DeviceInfo) -> str:
    """The device class of the run: ``ctx.options["device_class"]``, else by device kind."""
    name = str(ctx.options.get("device_class", ""))
    if name:
        if name not in CLASS_DYNAMICS:
            raise ValueError(f"unknown device class {name!r}; known: {', '.join(CLASS_DYNAMICS)}")
        return name
    return "coupled" if info.device_kind == DeviceKind.COUPLED else "e-vita"


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


def _result(name: str, case: str, metric: str, value: float, threshold: float, unit: str,
            detail: str, *, at_most: bool = True) -> CheckResult:
    passed = math.isfinite(value) and (value <= threshold if at_most else value >= threshold)
    return CheckResult(name, LEVEL, case, passed, metric, value, threshold, unit, detail)


# ---------------------------------------------------------------------- (a) friction

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
    (:func:`track_speed`) and the measured normal force."""
    track = result.track
    keep, t = session_times(result.states, track, result.host_us)
    applied = [s for s, ok in zip(result.states, keep, strict=True) if ok]
    t = t[keep]
    v = track_speed(track, t)
    amplitude = np.array([s.amplitude_m for s in applied])
    voltage = np.array([s.voltage_v for s in applied])
    fn = np.array([s.normal_force_n for s in applied])
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
            yield _result(DEVICE_FRICTION, case, "rms_relative_error", m.rms_relative_error,
                          FRICTION_JND, "relative", f"{m.reports} settled reports in contact")

        yield from guarded(DEVICE_FRICTION, LEVEL, [case], measure)


# ---------------------------------------------------------------------- (b) dynamics

def _fit_sinusoid(t: np.ndarray, y: np.ndarray, frequency_hz: float) -> tuple[float, float]:
    """Amplitude and offset of the least-squares sinusoid at ``frequency_hz`` in y(t)."""
    basis = np.column_stack([np.sin(2 * np.pi * frequency_hz * t),
                             np.cos(2 * np.pi * frequency_hz * t), np.ones(t.shape[0])])
    coef = np.linalg.lstsq(basis, y, rcond=None)[0]
    return float(np.hypot(coef[0], coef[1])), float(coef[2])


def folded_harmonics(frequency_hz: float, report_rate_hz: float = 1000.0,
                     highest: int = 12, within_hz: float = 10.0) -> list[int]:
    """Harmonics ``k`` (2..``highest``) of ``frequency_hz`` that reports at ``report_rate_hz``
    fold to within ``within_hz`` of the fundamental (an alias a sinusoid fit cannot tell from
    it)."""
    folded = []
    for k in range(2, highest + 1):
        alias = (k * frequency_hz) % report_rate_hz
        alias = min(alias, report_rate_hz - alias)
        if abs(alias - frequency_hz) < within_hz:
            folded.append(k)
    return folded


@dataclass(frozen=True)
class Gain:
    """The plate amplitude's response to a streamed sinusoid.

    Attributes:
        relative: median over the clean windows of the fitted oscillation at the stimulus
            frequency divided by the fitted mean amplitude. The velocity compensation scales
            both with the finger speed the firmware estimates; their ratio is the plate loop's
            alone (its gain at DC is 1).
        windows: clean windows fitted (whole periods, at least :data:`GAIN_WINDOW_S` each).
        skipped: windows left out for an empty stream queue (:data:`UNDERRUN_GUARD_S`).
        underruns: reports in the stream with an empty queue (the host fell behind).
    """

    relative: float
    windows: int
    skipped: int
    underruns: int


def windowed_gain(t_s: np.ndarray, amplitude_m: np.ndarray, empty: np.ndarray,
                  frequency_hz: float, start_s: float, end_s: float) -> tuple[float, int, int]:
    """Median relative oscillation ``A / mean`` of ``amplitude_m`` at ``frequency_hz`` over
    windows of whole periods (at least :data:`GAIN_WINDOW_S`) tiling ``[start_s, end_s]``,
    each fitted on its own, and the numbers of windows used and skipped. A window with a report
    in the guard of an ``empty`` one (:data:`UNDERRUN_GUARD_S`) is skipped: the device played
    neutral frames there and resumed the sine late, at another phase, which one fit over the
    whole record reads as a lower gain (19 empty reports of ~700 once put a 400 Hz gain 6 dB
    low)."""
    period = 1.0 / frequency_hz
    width = math.ceil(GAIN_WINDOW_S / period - 1e-9) * period
    disturbed = np.zeros(t_s.shape[0], dtype=bool)
    for t_empty in t_s[empty]:
        disturbed |= (t_s >= t_empty - 0.001) & (t_s <= t_empty + UNDERRUN_GUARD_S)
    ratios, skipped = [], 0
    begin = start_s
    while begin + width <= end_s + 1e-9:
        inside = (t_s >= begin) & (t_s < begin + width)
        begin += width
        if disturbed[inside].any():
            skipped += 1
            continue
        if np.count_nonzero(inside) < 4:
            continue
        oscillation, mean = _fit_sinusoid(t_s[inside], amplitude_m[inside], frequency_hz)
        if mean > 0:
            ratios.append(oscillation / mean)
    return (float(np.median(ratios)) if ratios else 0.0), len(ratios), skipped


def amplitude_gain(driver: Driver, frequency_hz: float, duration_s: float = 0.6) -> Gain:
    """The plate amplitude's response at ``frequency_hz`` to a streamed UV target
    :data:`BANDWIDTH_UV_MEAN` + :data:`BANDWIDTH_UV_SWING` sin (:func:`windowed_gain`). The
    stimulus is found in the targets the device reports (session-relative); its first
    :data:`FINGER_SETTLE_S` are left out. The UV model is a static map before the plate's linear
    dynamics, so gains relative to the reference frequency are those of the plate loop."""
    rate = driver.info().frame_rate_hz
    t = np.arange(round((duration_s + FINGER_SETTLE_S) * rate)) / rate
    session = stream_fed(driver, BANDWIDTH_UV_MEAN
                         + BANDWIDTH_UV_SWING * np.sin(2 * np.pi * frequency_hz * t),
                         what=f"the {frequency_hz:g} Hz sine")
    target, amp = session.column("target_uv"), session.column("amplitude_m")
    playing = np.flatnonzero(np.abs(target - BANDWIDTH_UV_MEAN) <= 2 * BANDWIDTH_UV_SWING)
    if playing.size < 10:
        raise CannotAssess(f"the device reported the streamed {frequency_hz:g} Hz target "
                               f"in {playing.size} reports (target_uv of STATE)")
    t0, t1 = session.t_s[playing[0]], session.t_s[playing[-1]]
    empty = session.column("stream_queued") == 0
    relative, windows, skipped = windowed_gain(session.t_s, amp, empty, frequency_hz,
                                               t0 + FINGER_SETTLE_S, t1)
    if windows < MIN_CLEAN_WINDOW_FRACTION * (windows + skipped) or windows == 0:
        raise CannotAssess(f"the {frequency_hz:g} Hz sine: {skipped} of {windows + skipped} "
                           "windows hold reports with an empty stream queue")
    return Gain(relative, windows, skipped, session.underruns)


def measure_bandwidth(open_driver: Callable[[], Driver]) -> tuple[float, int]:
    """-3 dB frequency of the plate amplitude (Hz), log-interpolated between the sweep points
    of :data:`BANDWIDTH_FREQUENCIES_HZ` (the last one when never reached), and the stream
    underruns over the sweep."""
    with open_driver() as driver:
        reference = amplitude_gain(driver, BANDWIDTH_REFERENCE_HZ)
    underruns = reference.underruns
    previous_f, previous_db = BANDWIDTH_REFERENCE_HZ, 0.0
    for f in BANDWIDTH_FREQUENCIES_HZ:
        with open_driver() as driver:
            gain = amplitude_gain(driver, f)
        underruns += gain.underruns
        db = 20 * math.log10(max(gain.relative, 1e-15) / max(reference.relative, 1e-15))
        if db <= -3.0:
            x = (-3.0 - previous_db) / (db - previous_db)
            return float(math.exp(math.log(previous_f) + x * math.log(f / previous_f))), underruns
        previous_f, previous_db = f, db
    return BANDWIDTH_FREQUENCIES_HZ[-1], underruns


FINGER_SETTLE_S = 0.1
"""Streamed time before a dynamics measurement starts, s: the host finger's first samples
reach the device in real time at no fixed phase with the stream, and the firmware's speed
estimate (velocity compensation) needs four of them (30 ms at 100 Hz) before it is steady; a
step or a sine measured earlier carries the estimate's start-up in the commanded amplitude."""
RISE_STEP_UV = 0.3
"""UV target after each step of the rise-time stimulus (from 1)."""
RISE_STEPS = 8
"""Steps of the rise-time stimulus, each from rest."""
RISE_MARKER_FRAMES = 10
"""Frames at the start of each step whose targets count down in 1e-4 steps to 0.3 (a frame
index in the reported target: the report that first shows the step says which frame of it
was playing, so the onset is known to one frame, 0.1 ms)."""
RISE_PHASE_FRAMES = 3
"""Frames added to each cycle beyond a whole number of report periods, so the steps fall at
different phases of the 1 kHz report clock (equivalent-time sampling)."""


def rise_stimulus(rate_hz: float, hold_s: float) -> np.ndarray:
    """UV frames of the rise-time stimulus: :data:`RISE_STEPS` cycles of ``hold_s`` at rest
    (UV 1) and ``hold_s`` at :data:`RISE_STEP_UV`, the first :data:`RISE_MARKER_FRAMES` frames
    of each step marked ``0.3 + (10 - j) 1e-4``."""
    hold = round(hold_s * rate_hz / 10) * 10
    marker = RISE_STEP_UV + (RISE_MARKER_FRAMES - np.arange(RISE_MARKER_FRAMES)) * 1e-4
    cycle = np.concatenate([np.ones(hold + RISE_PHASE_FRAMES), marker,
                            np.full(hold - RISE_MARKER_FRAMES, RISE_STEP_UV)])
    return np.tile(cycle, RISE_STEPS)


def rise_time(t_s: np.ndarray, target: np.ndarray, amplitude: np.ndarray, frame_s: float,
              hold_s: float) -> float:
    """10-90 % rise time (s) of the plate amplitude from the reports of :func:`rise_stimulus`:
    each step's onset from its marker, every report normalised to its step's settled value
    and placed at its time since the onset; the pooled samples (eight phases of the report
    clock) give the response at ~0.1-0.2 ms resolution, where one step sampled at 1 kHz
    would put the crossings anywhere within a report period."""
    counts = np.rint(target * 1e4).astype(int)
    base = round(RISE_STEP_UV * 1e4)
    marked = (counts > base) & (counts <= base + RISE_MARKER_FRAMES)
    rest = np.concatenate(([False], counts[:-1] >= 9900))
    onsets = [t_s[k] - (base + RISE_MARKER_FRAMES - counts[k]) * frame_s
              for k in np.flatnonzero(marked & rest)]
    if len(onsets) < RISE_STEPS // 2:
        raise CannotAssess(f"the device reported {len(onsets)} of {RISE_STEPS} marked UV steps "
                           f"(target_uv of STATE)")
    tau, level = [], []
    for onset in onsets:
        settled = (t_s >= onset + 0.8 * hold_s) & (t_s < onset + hold_s)
        window = (t_s >= onset - 0.002) & (t_s < onset + 0.8 * hold_s)
        final = float(np.median(amplitude[settled])) if settled.any() else math.nan
        if not final > 0:
            continue
        tau.append(t_s[window] - onset)
        level.append(amplitude[window] / final)
    if not tau:
        raise CannotAssess("no UV step settled to a plate amplitude above 0")
    order = np.argsort(np.concatenate(tau))
    x, y = np.concatenate(tau)[order], np.concatenate(level)[order]

    def crossing(fraction: float) -> float:
        above = np.flatnonzero(y >= fraction)
        if above.size == 0:
            return math.inf
        k = int(above[0])
        if k == 0 or y[k] == y[k - 1]:
            return float(x[k])
        return float(x[k - 1] + (fraction - y[k - 1]) / (y[k] - y[k - 1]) * (x[k] - x[k - 1]))

    return crossing(0.9) - crossing(0.1)


def measure_rise_time(driver: Driver, max_rise_s: float) -> float:
    """10-90 % rise time (s) of the plate amplitude after streamed UV steps 1 ->
    :data:`RISE_STEP_UV` (:func:`rise_stimulus`, :func:`rise_time`); each step holds for
    three times ``max_rise_s`` (at least 20 ms)."""
    rate = driver.info().frame_rate_hz
    hold_s = max(0.02, 3 * max_rise_s)
    session = stream_fed(driver, rise_stimulus(rate, hold_s), what="the rise-time steps")
    return rise_time(session.t_s, session.column("target_uv"), session.column("amplitude_m"),
                     1.0 / rate, hold_s)


def check_dynamics(ctx: Context) -> Iterator[CheckResult]:
    """Bandwidth and rise time of the plate amplitude under direct streaming."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver
    with open_driver() as driver:
        dyn = CLASS_DYNAMICS[device_class(ctx, driver.info())]

    def bandwidth() -> Iterator[CheckResult]:
        value, underruns = measure_bandwidth(open_driver)
        yield _result(DEVICE_DYNAMICS, "bandwidth", "bandwidth_-3dB", value,
                      dyn.min_bandwidth_hz * (1.0 - BANDWIDTH_TOLERANCE), "Hz",
                      f"{dyn.why}; stream underruns in the sweep: {underruns}", at_most=False)

    def rise_time() -> Iterator[CheckResult]:
        with open_driver() as driver:
            rise = measure_rise_time(driver, dyn.max_rise_s)
        yield _result(DEVICE_DYNAMICS, "rise-time", "rise_10_90", rise * MS_PER_S,
                      dyn.max_rise_s * MS_PER_S, "ms", dyn.why)

    yield from guarded(DEVICE_DYNAMICS, LEVEL, ["bandwidth"], bandwidth)
    yield from guarded(DEVICE_DYNAMICS, LEVEL, ["rise-time"], rise_time)


# ---------------------------------------------------------------------- (c) latency

LATENCY_LATE_S = 0.005
"""Largest lateness of the host in a kept latency trial timed when the host read its reports
(a device before protocol 1.3; spec QT3), s: its loop not iterating, or a FINGER report's send
call taking longer. Half the 10 ms D3 bound, as PI4's own margin. A trial in which the device
flagged a report REALTIME_LAG (device protocol PI4) is never kept."""
READ_WINDOW_S = 0.1
"""Window of the host's reads of which a real-time run keeps the freshest (smallest read lag)
for ``host-read-lag``, s: a host that falls behind reads a backlog, oldest first, and catches
up within a few ms once it runs; over 100 ms it reads at least one report as fresh as the
delivery makes it, unless it did not run for the whole window."""
MIN_READ_LAGS = 10
"""Windows a real-time run needs for its ``host-read-lag``."""


def freshest_reads(reads: Sequence[tuple[float, float]],
                   window_s: float = READ_WINDOW_S) -> list[float]:
    """The smallest read lag (s) of each ``window_s`` of the host's clock that holds reads:
    ``reads`` are (host clock of the read, read lag), s. The host's backlog (its own lateness)
    is left out; what stays is the device's and the transport's delivery (spec QT3)."""
    best: dict[int, float] = {}
    for at, lag in reads:
        key = math.floor(at / window_s)
        best[key] = min(best.get(key, math.inf), lag)
    return [best[key] for key in sorted(best)]
MIN_KEPT_TRIALS = LATENCY_TRIALS // 2
"""Kept trials a latency run needs, else it is measured again (the median of fewer says more
about which trials were kept than about the device)."""


@dataclass(frozen=True)
class LatencyRun:
    """What :func:`measure_latency` saw.

    Attributes:
        latencies_s: per trial, the time from the first FINGER report on the new texture to
            the first report past half the amplitude change, s (NaN: never crossed).
        read_lag_s: per report, how long after its own time on the host clock (PI3: echoed
            sample's host time + echo age) the host read it, s: the host's read backlog
            (with the fastest one-way transit); for a real-time host the freshest read of
            each :data:`READ_WINDOW_S` (:func:`freshest_reads`: the delivery, the host's own
            lateness left out, spec QT3). Empty when the device does not date its reports
            (protocol before 1.3).
        kept: per trial, whether the host and the device kept real time in it (spec QT3).
        not_kept: why each trial that was not kept was not (one line each).
        host_late_s: the host's longest lateness over the run (loop gaps, sends), s.
        dated_reports: reports read that the device dated (PI3), on time or not.
    """

    latencies_s: list[float]
    read_lag_s: list[float]
    kept: list[bool]
    not_kept: list[str]
    host_late_s: float = 0.0
    dated_reports: int = 0

    @property
    def kept_latencies_s(self) -> list[float]:
        """The latencies of the kept trials, s."""
        return [lat for lat, ok in zip(self.latencies_s, self.kept, strict=True) if ok]


def measure_latency(driver: Driver, trials: int = LATENCY_TRIALS, *,
                    dated: bool = False) -> LatencyRun:
    """Latencies from a FINGER report moving onto a UV 0.4 taxtel to the measured plate
    amplitude crossing half its settled value (method of bench/bench_device_latency.py).

    A real-time host times the crossing report by its own time on the host clock (PI3: echoed
    sample + echo age) plus the run's smallest read lag (the fastest delivery of a report to
    the host, with the fastest one-way transit the device's clock offset took out, PO2): that
    is the time from the send to the report's frame plus the fastest delivery, the transport
    included and the host's own lateness in reading left out. A trial is kept unless a report
    of it carries REALTIME_LAG (spec QT3). A device before protocol 1.3 is timed when the host
    read the report, and a trial is kept only when also the host's loop never went
    :data:`LATENCY_LATE_S` without iterating and no send took longer. With ``dated`` (a host
    that cannot read in real time, timing class ``software-emulation``) a report is timed at
    its own time on the host clock alone and every trial is kept. Each position is held until
    the host has read the reports of the whole hold, however late it reads them."""
    info = driver.info()
    width, height = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    card = build.card(width, height, taxtel_mm=(width / 2, height), textures=[
        build.texture(1.0, channel="uv"), build.texture(0.4, channel="uv")],
        texture_index=[0, 1])
    left, right, y = width / 4, 3 * width / 4, height / 2
    driver.upload_card(card)
    driver.set_touch_source(host=True)
    driver.start()
    read_lag: list[float] = []

    @dataclass
    class Hold:
        """The reports of one hold: (state, time since the first send by read, by own time),
        the host's longest lateness in sending (from the time a FINGER carries to the end of
        its send) and in its loop (between two iterations), s."""

        seen: list[tuple[State, float, float | None]]
        send_late_s: float
        loop_late_s: float

    reads: list[tuple[float, float]] = []  # (host clock of the read, read lag), s

    def hold(x: float, seconds: float, poll_s: float = 0.0005) -> Hold:
        """Send the finger at ``x`` (twice: zero velocity) every 10 ms until the host has read
        the reports of ``seconds`` after the first send (at most :data:`READ_CATCH_UP_S`
        more); the reports that echo a sample of this hold (the device applied it: those
        still echoing an earlier one, read late, belong to an earlier position)."""
        seen: list[tuple[State, float, float | None]] = []
        start = driver.clock()
        start_us = Finger.from_si(start, 0.0, 0.0, 0.0, False).host_time_us
        sent: set[int] = set()
        next_send = start
        covered = -math.inf  # time since the first send that the reports read reach, s
        send_late, loop_late, last = 0.0, 0.0, start
        while True:
            now = driver.clock()
            loop_late, last = max(loop_late, now - last), now
            if now >= next_send:
                t = start if next_send == start else now
                driver.send_finger(t, x, y, 0.5, True)
                driver.send_finger(t, x, y, 0.5, True)
                sent.add(Finger.from_si(t, 0.0, 0.0, 0.0, False).host_time_us)
                next_send += 0.01
                send_late = max(send_late, driver.clock() - t)  # from the time they carry
            for state in driver.collect_until(driver.clock() + poll_s):
                now_read = driver.clock()
                read = now_read - start
                own = _host_time_since(state, start_us)
                if own is not None:
                    read_lag.append(read - own)
                    reads.append((now_read, read - own))
                if state.host_time_echo_us in sent:
                    seen.append((state, read, own))
                    covered = max(covered, own if dated and own is not None else read)
            if covered >= seconds or now >= start + seconds + READ_CATCH_UP_S:
                return Hold(seen, send_late, loop_late)

    holds: list[Hold] = []
    with collection_deferred():  # a collection's pause is host lateness (spec QT3)
        hold(left, 0.05)
        for _ in range(trials):
            holds.append(hold(right, 0.06))
            hold(left, 0.04)
    driver.stop()
    floor = min(read_lag, default=math.nan)
    latencies: list[float] = []
    kept: list[bool] = []
    why: list[str] = []
    for k, h in enumerate(holds):
        own_times = all(own is not None for _, _, own in h.seen)
        if own_times and (dated or math.isfinite(floor)):
            # by the device's account (PI3), plus the fastest delivery when timed as read
            shift = 0.0 if dated else floor
            timed = [(s, own + shift) for s, _, own in h.seen if own is not None]
            if dated:  # reports past the hold were read early; their own times are not lag
                timed = [(s, t) for s, t in timed if t <= 0.06]
        else:
            timed = [(s, read) for s, read, _ in h.seen]
        seen = sorted((pair for pair in timed if pair[1] >= 0.0), key=lambda pair: pair[1])
        settled = float(np.mean([s.amplitude_m for s, _ in seen[-10:]])) if seen else math.nan
        latencies.append(next((dt for s, dt in seen if s.amplitude_m >= settled / 2), math.nan))
        # timed by own time, the host's lateness in reading is left out (and a FINGER is
        # written to the link at once: lateness there would need the process preempted
        # between reading the clock and writing, a rare event the median absorbs); timed by
        # read, every gap of the host's loop counts
        late_s = 0.0 if own_times else max(h.send_late_s, h.loop_late_s)
        problems = [] if dated else [p for p in (
            f"the host ran {late_s * MS_PER_S:.0f} ms late" if late_s > LATENCY_LATE_S else "",
            device_lag([s for s, _, _ in h.seen])) if p]
        kept.append(not problems)
        if problems:
            why.append(f"trial {k + 1}: {'; '.join(problems)}")
    return LatencyRun(latencies, read_lag if dated else freshest_reads(reads), kept, why,
                      max((max(h.loop_late_s, h.send_late_s) for h in holds), default=0.0),
                      len(read_lag))


def _host_time_since(state: State, start_us: int) -> float | None:
    """The report's time on the host clock (PI3: echoed sample's host time + echo age) less
    the host time ``start_us``, s (modulo the 32-bit host time; within +-35 min); None when
    the device does not say (no echo yet, or protocol before 1.3)."""
    age = state.echo_age_s
    if age is None or state.host_time_echo_us == 0:
        return None
    modulo = 1 << 32
    since_us = (state.host_time_echo_us - start_us + modulo // 2) % modulo - modulo // 2
    return since_us * S_PER_US + age


def check_latency(ctx: Context) -> Iterator[CheckResult]:
    """End-to-end latency from a host finger update to the plate's change, and (case
    ``host-read-lag``) how late the host read the device's reports."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver
    timing = timing_class(ctx)
    runs: list[LatencyRun] = []

    def latency_run() -> LatencyRun:
        """One run, kept when at least :data:`MIN_KEPT_TRIALS` of its trials were (QT3)."""
        with open_driver() as driver:
            run = measure_latency(driver, dated=not timing.keeps_real_time)
        if len(run.kept_latencies_s) < MIN_KEPT_TRIALS:
            raise NotKept(f"{len(run.kept_latencies_s)} of {len(run.latencies_s)} trials kept "
                          f"(at least {MIN_KEPT_TRIALS} needed): {'; '.join(run.not_kept)}")
        if timing.keeps_real_time and run.dated_reports and len(run.read_lag_s) < MIN_READ_LAGS:
            raise NotKept(f"the host read reports in {len(run.read_lag_s)} windows of "
                          f"{READ_WINDOW_S * MS_PER_S:.0f} ms (at least {MIN_READ_LAGS} needed "
                          f"for host-read-lag; it did not run for up to "
                          f"{run.host_late_s * MS_PER_S:.0f} ms)")
        return run

    def measure() -> Iterator[CheckResult]:
        run = attempts(latency_run, "the latency run")
        runs.append(run)
        lat = run.kept_latencies_s
        timed = ("reports timed on the host clock by the device (PI3), without the host's "
                 "read backlog or the fastest transit" if not timing.keeps_real_time
                 else "reports timed by their own time on the host clock (PI3) plus the "
                 "fastest delivery (the host's lateness in reading left out)")
        left_out = (f"; {len(run.latencies_s) - len(lat)} trials not kept in real time and "
                    f"left out ({run.not_kept[0]}{', ...' if len(run.not_kept) > 1 else ''})"
                    if len(lat) < len(run.latencies_s) else "")
        yield _result(DEVICE_LATENCY, "boundary-move", "median_latency",
                      float(np.median(lat)) * MS_PER_S, timing.latency_s * MS_PER_S, "ms",
                      f"{len(lat)} moves, max {np.nanmax(lat) * MS_PER_S:.1f} ms; {timed}"
                      f"{left_out}; {timing.why}")

    def read_lag() -> Iterator[CheckResult]:
        if not runs:
            raise CannotAssess("the latency run did not complete")
        if not runs[0].read_lag_s:
            raise CannotAssess("the device does not date its reports (echo age, protocol 1.3 "
                               "PI3)")
        lags = np.asarray(runs[0].read_lag_s)
        yield _result(DEVICE_LATENCY, "host-read-lag", "median_read_lag",
                      float(np.median(lags)) * MS_PER_S, timing.read_lag_s * MS_PER_S, "ms",
                      f"{lags.size} {'windows' if timing.keeps_real_time else 'reports'}, "
                      "90th percentile "
                      f"{np.percentile(lags, 90) * MS_PER_S:.1f}"
                      f" ms (read time less the report's own time on the host clock, PI3"
                      f"{'; the freshest read of each 100 ms' if timing.keeps_real_time else ''}"
                      f"); {timing.why}")

    yield from guarded(DEVICE_LATENCY, LEVEL, ["boundary-move"], measure)
    yield from guarded(DEVICE_LATENCY, LEVEL, ["host-read-lag"], read_lag)


# ---------------------------------------------------------------------- (d) safety

def _over(states: Sequence[State], driver: Driver) -> tuple[int, float]:
    """Reports with a measured output above its limit in force (one report count of
    quantisation allowed) or a target outside [0, 1] x [1, 4], and the worst output/limit."""
    limits = driver.limits()
    over = np.zeros(len(states), dtype=bool)
    worst = 0.0
    for value, limit, count in (
        (np.array([s.amplitude_m for s in states]), limits.max_amplitude_m, 1e-9),
        (np.array([s.voltage_v for s in states]), limits.max_voltage_v, 0.1),
        (np.array([s.current_a for s in states]), limits.max_current_a, 1e-8),
    ):
        over |= value > limit + count
        if limit > 0 and value.size:
            worst = max(worst, float(value.max()) / limit)
    targets = np.array([(s.target_uv, s.target_ev) for s in states]).reshape(-1, 2)
    over |= (targets[:, 0] < 0) | (targets[:, 0] > 1) | (targets[:, 1] < 1) | (targets[:, 1] > 4)
    return int(np.count_nonzero(over)), worst


def _wait_for_rest(driver: Driver, timeout_s: float = 0.5) -> None:
    """Read STATE reports until the outputs are off (a device that stays powered may still be
    ramping down from the previous session), at most ``timeout_s``."""
    end = driver.clock() + timeout_s
    while driver.clock() < end:
        states = driver.collect_until(driver.clock() + 0.005)
        if states and all(s.amplitude_m <= OFF_AMPLITUDE_M and s.voltage_v <= 1.0
                          for s in states[-3:]):
            return


SAFETY_CASES = ("card-over-limit", "host-limits", "stream-extremes", "limits-while-driven")
"""The cases of the safety check, in order."""

LOWERED_FRACTION = 0.25
"""Case ``limits-while-driven``: the limits are lowered to this fraction of those in force. The
plate, driven at the amplitude limit, is then 4 times over the new one: left to decay at its own
rate it takes ``tau ln 4`` to get under it (E-ViTa 2.2 ms, coupled stimulator 9.5 ms, two and
nine report periods), so a device that does not brake it shows in the reports after the SET."""
DRIVEN_S = 0.08
"""Streaming before the limits are lowered, s (the plate settles at its limit in ~5 ms)."""
AFTER_CHANGE_S = 0.05
"""Streaming after the limits are lowered, s, at least."""
MIN_REPORTS_AFTER = 30
"""Reports after the change the case waits for (a loaded host or transport may deliver the first
FINGER after the SET late), at most :data:`AFTER_CHANGE_TIMEOUT_S`."""
AFTER_CHANGE_TIMEOUT_S = 1.0
"""Longest streaming after the change while waiting for :data:`MIN_REPORTS_AFTER`, s."""
MIN_OVER_NEW_LIMIT = 2.0
"""The plate must be at least this many times the new amplitude limit just before the change,
or the case assesses nothing (UNASSESSED)."""
REPORT_QUANTA = (1e-9, 0.1, 1e-8)
"""One report count of amplitude (m), voltage (V) and current (A): the measurement tolerance of
the safety cases."""


@dataclass(frozen=True)
class LimitsChange:
    """The reports after lowering the limits while the plate is driven.

    Attributes:
        reports: STATE reports after the change (echoing a FINGER sent after the SET).
        over: those with a measured output above the new limit plus one report count.
        worst: largest measured output / new limit among them.
        before_m: median plate amplitude of the last 5 reports before the change, m.
        lowered: the limits set (wire counts).
        read_back: LIMITS read right after the SET.
    """

    reports: int
    over: int
    worst: float
    before_m: float
    lowered: Limits
    read_back: Limits

    @property
    def detail(self) -> str:
        """One line for the result."""
        low = self.lowered
        return (f"{self.over} of {self.reports} reports after the SET over the new limits "
                f"({low.max_amplitude_m * NM_PER_M:.0f} nm, {low.max_voltage_v:g} V, "
                f"{low.max_current_a * UA_PER_A:g} uA; read back "
                f"{'the same' if self.read_back == low else str(self.read_back)}); plate at "
                f"{self.before_m * NM_PER_M:.0f} nm before; largest output {self.worst:.3f} x its "
                f"new limit (tolerance one report count)")


class _Finger:
    """FINGER reports of a stroke at :data:`STROKE_SPEED_MM_S` and 0.5 N, each with a host time
    (us) later than the previous one's, remembering those sent after :meth:`mark`."""

    def __init__(self, driver: Driver, x0_mm: float, y_mm: float) -> None:
        self.driver, self.x0_mm, self.y_mm = driver, x0_mm, y_mm
        self.start_s = driver.clock()
        self.last_us = -1
        self.marked = False
        self.after_us: set[int] = set()

    def send(self) -> None:
        """Send the finger where the stroke is now."""
        now = self.driver.clock()
        host_us = max(round(now * US_PER_S), self.last_us + 1)
        x = self.x0_mm + STROKE_SPEED_MM_S * (now - self.start_s)
        self.driver.send_finger(host_us * S_PER_US, x, self.y_mm, 0.5, True)
        self.last_us = host_us
        if self.marked:
            self.after_us.add(host_us % (1 << 32))

    def mark(self) -> None:
        """From now on, reports echoing a FINGER sent are after the change."""
        self.marked = True


def _over_new_limits(states: list[State], new: Limits) -> tuple[int, float]:
    """Reports with an output above its limit in ``new`` plus :data:`REPORT_QUANTA`, and the
    largest output / limit."""
    over = np.zeros(len(states), dtype=bool)
    worst = 0.0
    for field, limit, quantum in zip(
            ("amplitude_m", "voltage_v", "current_a"),
            (new.max_amplitude_m, new.max_voltage_v, new.max_current_a), REPORT_QUANTA,
            strict=True):
        value = np.array([getattr(s, field) for s in states], dtype=float)
        over |= value > limit + quantum
        if limit > 0 and value.size:
            worst = max(worst, float(value.max()) / limit)
    return int(np.count_nonzero(over)), worst


def measure_limits_while_driven(driver: Driver, base: Limits) -> LimitsChange:
    """Stream UV 0 (EV 4 with EV) with the host's finger sliding so the plate runs at its
    amplitude limit, SET LIMITS to :data:`LOWERED_FRACTION` of ``base`` after :data:`DRIVEN_S`,
    send a FINGER at once and keep streaming for :data:`AFTER_CHANGE_S` (longer, up to
    :data:`AFTER_CHANGE_TIMEOUT_S`, until :data:`MIN_REPORTS_AFTER` arrived). Every report echoing
    a FINGER sent after the SET returned is after the change (session-relative: the echoes name
    this session's finger reports, never the device's uptime) and must be under the new limits
    (PS1, PS5).

    Raises:
        CannotAssess: no HOST_FINGER, the plate was not driven over the new limit, or no report
            echoed a FINGER sent after the change.
    """
    info = driver.info()
    if not info.capabilities & Capability.HOST_FINGER:
        raise CannotAssess("the device takes no FINGER reports: the reports after the change "
                           "cannot be told apart")
    rate = float(info.frame_rate_hz)
    ev = 4.0 if info.capabilities & Capability.EV else 1.0
    lead = lead_frames(int(info.stream_capacity_frames), rate)
    lowered = Limits.from_si(base.max_amplitude_m * LOWERED_FRACTION,
                             base.max_voltage_v * LOWERED_FRACTION,
                             base.max_current_a * LOWERED_FRACTION)
    finger = _Finger(driver, info.surface_width_10um * 0.0025, info.surface_height_10um * 0.005)
    watch = HostWatch(clock=driver.clock)
    driver.set_touch_source(host=True)
    driver.start()
    start = finger.start_s
    states: list[State] = []
    before: list[State] = []
    read_back: Limits | None = None
    sent, next_finger, end, timeout, n_after = 0, start, math.inf, math.inf, 0
    while driver.clock() < timeout and (driver.clock() < end or n_after < MIN_REPORTS_AFTER):
        now = driver.clock()
        if read_back is None:
            watch.tick()  # the host's loop before the change: a late one starves the plate
        if now >= next_finger:
            finger.send()
            next_finger += FINGER_PERIOD_S
        due = lead + int((now - start) * rate)
        if due > sent:
            driver.stream_frames(np.zeros(due - sent), np.full(due - sent, ev))
            sent = due
        new = driver.collect_until(driver.clock() + 0.001)
        n_after += sum(s.host_time_echo_us in finger.after_us for s in new)
        states += new
        if read_back is None and driver.clock() >= start + DRIVEN_S:
            before = list(states)
            driver.set_report(lowered)
            finger.mark()
            finger.send()  # the first FINGER after the change, as soon as the SET returned
            read_back = driver.limits()
            next_finger = driver.clock() + FINGER_PERIOD_S
            end = driver.clock() + AFTER_CHANGE_S
            timeout = driver.clock() + AFTER_CHANGE_TIMEOUT_S
    driver.stop()
    assert read_back is not None
    driven = float(np.median([s.amplitude_m for s in before[-5:]])) if before else 0.0
    settled = before[len(before) // 2:]
    require_fed(sum(s.stream_queued == 0 for s in settled), len(settled),
                f"the stream before the change (plate at {driven * NM_PER_M:.0f} nm)")
    if not driven >= MIN_OVER_NEW_LIMIT * lowered.max_amplitude_m:
        reason = (f"the plate was at {driven * NM_PER_M:.0f} nm before the change, not "
                  f"{MIN_OVER_NEW_LIMIT:g} x the new {lowered.max_amplitude_m * NM_PER_M:.0f} nm "
                  "limit")
        watchdog = ("the watchdog tripped (the host's finger came late)"
                    if any(s.faults & FaultBits.WATCHDOG for s in settled) else "")
        late = reasons(watch.late if driver.realtime else "", device_lag(before), watchdog)
        if late:  # the host or the device did not keep real time (spec QT3)
            raise NotKept(f"{reason}: {late}")
        raise CannotAssess(reason)
    after = [s for s in states if s.host_time_echo_us in finger.after_us]
    if not after:
        raise CannotAssess("no report echoed a FINGER sent after the change")
    over, worst = _over_new_limits(after, lowered)
    return LimitsChange(len(after), over, worst, driven, lowered, read_back)


def measure_safety(open_driver: Callable[[], Driver]) -> Iterator[tuple[str, int, float, str]]:
    """Per case as it is measured (case, reports over a limit, the worst measured output /
    limit, a detail line): a card asking for more than the device can do, the same under host
    limits halved, streamed extreme frames, and limits lowered while the plate is driven
    (:func:`measure_limits_while_driven`)."""
    out: dict[str, tuple[int, float]] = {}
    with open_driver() as driver:
        info = driver.info()
        w, h = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
        greedy = build.card(w, h, taxtel_mm=(w / 2, h), textures=[
            build.texture(0.0, channel="uv"),
            build.texture(4.0, channel="ev") if info.capabilities & Capability.EV
            else build.texture(0.0, channel="uv")],
            texture_index=[0, 1])
    track = straight_stroke((w / 4, h / 2), (100.0, 0.0), 0.4)
    with open_driver() as driver:
        out["card-over-limit"] = _over(play(driver, greedy, track).states, driver)
    with open_driver() as driver:
        _wait_for_rest(driver)  # lowered at rest; lowering while driven is another matter
        hw = driver.limits()
        driver.set_limits(hw.max_amplitude_m / 2, hw.max_voltage_v / 2, hw.max_current_a / 2)
        try:
            out["host-limits"] = _over(play(driver, greedy, track).states, driver)
        finally:  # a device stays powered between runs: leave its limits as they were
            driver.set_limits(hw.max_amplitude_m, hw.max_voltage_v, hw.max_current_a)
    with open_driver() as driver:
        driver.send_finger(driver.clock(), w / 2, h / 2, 0.5, True)
        n = round(0.1 * info.frame_rate_hz)
        uv = np.zeros(n)
        driver.start()
        states: list[State] = []
        for k in range(0, n, 100):
            driver.stream_frames(uv[k:k + 100], np.full(100, 4.0))
            driver.send_finger(driver.clock(), w / 2, h / 2, 0.5, True)
            states += driver.collect_until(driver.clock() + 0.01)
        driver.stop()
        out["stream-extremes"] = _over(states, driver)
    for case, (n, worst) in out.items():
        yield case, n, worst, f"largest measured output {worst:.3f} x its limit in force"

    def lowered_while_driven() -> LimitsChange:
        with open_driver() as driver:
            _wait_for_rest(driver)
            base = driver.limits()
            try:
                with collection_deferred():  # a collection's pause would starve the plate
                    return measure_limits_while_driven(driver, base)
            finally:  # leave the limits as they were, as host-limits does
                driver.set_limits(base.max_amplitude_m, base.max_voltage_v, base.max_current_a)

    change = attempts(lowered_while_driven, "the limits-while-driven run")
    yield "limits-while-driven", change.over, change.worst, change.detail


def check_safety(ctx: Context) -> Iterator[CheckResult]:
    """Outputs stay within the limits in force whatever is asked (spec PS1)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def measure() -> Iterator[CheckResult]:
        for case, n_over, _worst, detail in measure_safety(open_driver):
            yield _result(DEVICE_SAFETY, case, "n_over", n_over, 0.0, "reports", detail)

    yield from guarded(DEVICE_SAFETY, LEVEL, SAFETY_CASES, measure)


# ---------------------------------------------------------------------- (e) watchdog

def measure_watchdog(driver: Driver) -> tuple[float, bool, float]:
    """Stroke the host finger over a UV 0.3 card for 0.2 s, then go silent.

    Returns the time (s) from the last host report to outputs off (inf when they never go
    off), whether WATCHDOG was reported, and the plate amplitude before the silence (m). The
    silence is timed by the reports that echo the last FINGER report: by their echo age (the
    device's own account, PI3), or when read on a device without one; a host that reads its
    reports late keeps reading until they cover the silence (:data:`READ_CATCH_UP_S`)."""
    info = driver.info()
    w, h = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    card = build.card(w, h, taxtel_mm=(w, h), textures=[build.texture(0.3, channel="uv")])
    driver.upload_card(card)
    driver.set_touch_source(host=True)
    driver.start()
    start = driver.clock()
    read: list[tuple[State, float]] = []  # each report and when it was read
    sent: list[int] = []
    last = start
    while driver.clock() < start + 0.2:
        last = driver.clock()
        driver.send_finger(last, w / 4 + STROKE_SPEED_MM_S * (last - start), h / 2, 0.5, True)
        sent.append(Finger.from_si(last, 0.0, 0.0, 0.0, False).host_time_us)
        read += [(s, driver.clock()) for s in _read_briefly(driver, 0.02)]
    silence_s = info.watchdog_ms * S_PER_MS + 0.2

    def since_last(batch: list[tuple[State, float]]) -> list[tuple[State, float]]:
        """The reports of ``batch`` after the last FINGER report, each with its time since
        it, s."""
        return [(s, s.echo_age_s if s.echo_age_s is not None else t - last)
                for s, t in batch if s.host_time_echo_us == sent[-1]]

    seen = since_last(read)
    covered = max((t for _, t in seen), default=-math.inf)  # silence the reports read cover
    catch_up = driver.clock() + silence_s + READ_CATCH_UP_S
    while driver.clock() < catch_up and covered < silence_s:
        batch = [(s, driver.clock()) for s in driver.collect_until(driver.clock() + 5e-4)]
        read += batch
        new = since_last(batch)
        seen += new
        covered = max([covered, *(t for _, t in new)])
    driver.stop()
    stroke = set(sent[:-1])
    driven_states = [s for s, _ in read if s.host_time_echo_us in stroke][-10:]
    driven = float(np.median([s.amplitude_m for s in driven_states])) if driven_states else 0.0
    watchdog = any(s.faults & FaultBits.WATCHDOG for s, _ in seen)
    on = [t for s, t in seen if s.amplitude_m > OFF_AMPLITUDE_M or s.voltage_v > 1.0]
    off = max(on, default=0.0)
    if not seen or seen[-1][0].amplitude_m > OFF_AMPLITUDE_M or seen[-1][0].voltage_v > 1.0:
        off = math.inf
    return off, watchdog, driven


def _read_briefly(driver: Driver, seconds: float) -> list[State]:
    """The reports read for ``seconds``, in batches of :data:`SEND_READ_BATCH`, so that a
    host with a backlog of reports (software emulation) returns on time to send its next
    FINGER report rather than drain the backlog while the device's watchdog runs out."""
    end = driver.clock() + seconds
    states: list[State] = []
    while (remaining := end - driver.clock()) > 0:
        states += driver.read_inputs(remaining, max_count=SEND_READ_BATCH)
    return states


def check_watchdog(ctx: Context) -> Iterator[CheckResult]:
    """Fault behaviour on host silence (spec PS3)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def measure() -> Iterator[CheckResult]:
        with open_driver() as driver:
            limit = driver.info().watchdog_ms * S_PER_MS + WATCHDOG_ALLOWANCE_S
            off, reported, driven = measure_watchdog(driver)
        yield _result(DEVICE_WATCHDOG, "host-silent", "time_to_off", off * MS_PER_S,
                      limit * MS_PER_S, "ms",
                      f"plate at {driven * NM_PER_M:.0f} nm before the host went silent; "
                      f"off means <= {OFF_AMPLITUDE_M * NM_PER_M:.0f} nm and <= 1 V")
        yield CheckResult(DEVICE_WATCHDOG, LEVEL, "fault-reported", reported,
                          "watchdog_fault", float(reported), 1.0, "bool",
                          "fault WATCHDOG in STATE")

    yield from guarded(DEVICE_WATCHDOG, LEVEL, ["host-silent", "fault-reported"], measure)
