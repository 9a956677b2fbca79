"""Check ``device.dynamics``: the plate amplitude's -3 dB bandwidth (D1, Hz) and 10-90 % rise
time (D2, s) under direct streaming, against the device class (:mod:`.device_classes`).

Sinusoidal and step UV targets are streamed while the host's finger slides at 60 mm/s; the
plate amplitude in STATE is fitted (sinusoids, least squares at the known frequency) or timed
10-90 % (step). The plate amplitude is used rather than rendered friction held still (spec 4.1
method): with the finger still the UV forward map saturates (zero speed gives zero friction at
any amplitude), so a still finger cannot show the dynamics.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np

from hcard.device.base import Driver
from hcard.quantities import MS_PER_S
from hcard_conformance.check_names import DEVICE_DYNAMICS as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import LEVEL, judged
from hcard_conformance.device_checks.device_classes import CLASS_DYNAMICS, device_class
from hcard_conformance.result import CannotAssess, CheckResult, guarded
from hcard_conformance.streaming import stream_fed

BANDWIDTH_TOLERANCE = 0.05
"""Measurement tolerance of D1: the swept -3 dB point may fall this fraction below the class
bandwidth (an 8-point sweep interpolated in log f; spec/conformance.md 4.1)."""
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


DYNAMICS_CASES = ("bandwidth", "rise-time")
"""The cases of ``device.dynamics``, in order; each is measured on its own, so a run that
wants one (:meth:`Context.wants`) measures only it."""


def check_dynamics(ctx: Context) -> Iterator[CheckResult]:
    """Bandwidth and rise time of the plate amplitude under direct streaming."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver
    with open_driver() as driver:
        dyn = CLASS_DYNAMICS[device_class(ctx, driver.info())]

    def bandwidth() -> Iterator[CheckResult]:
        value, underruns = measure_bandwidth(open_driver)
        yield judged(CHECK, DYNAMICS_CASES[0], "bandwidth_-3dB", value,
                      dyn.min_bandwidth_hz * (1.0 - BANDWIDTH_TOLERANCE), "Hz",
                      f"{dyn.why}; stream underruns in the sweep: {underruns}", at_most=False)

    def rise_time() -> Iterator[CheckResult]:
        with open_driver() as driver:
            rise = measure_rise_time(driver, dyn.max_rise_s)
        yield judged(CHECK, DYNAMICS_CASES[1], "rise_10_90", rise * MS_PER_S,
                      dyn.max_rise_s * MS_PER_S, "ms", dyn.why)

    for case, measure in zip(DYNAMICS_CASES, (bandwidth, rise_time), strict=True):
        if ctx.wants(CHECK, case):
            yield from guarded(CHECK, LEVEL, [case], measure)
