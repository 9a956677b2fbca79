"""The accuracy metrics A0-A5 of spec/conformance.md, on arrays (no I/O, no device).

Each function compares an implementation's signal with the golden render at the golden frame
times and returns a :class:`Metric`: the value, a one-line detail, and whether the metric was
applicable at all (spec Q6: a metric that finds nothing to assess is *not applicable*, never
passed). The renderer level applies them to friction targets, the device level to rendered
friction.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from hcard.quantities import MS_PER_S
from hcard.render import RenderOptions
from hcard.render.compiled import velocity_locked
from hcard.render.touch import segment_speeds
from hcard.track import FingerTrack
from hcard.v1 import card_pb2 as pb
from hcard_conformance.phase_windows import PhaseWindows


@dataclass(frozen=True)
class Tolerances:
    """Thresholds and constants of spec/conformance.md section 0 (manifest ``tolerances``)."""

    friction_abs: float = 1e-5
    time_abs_s: float = 1e-9
    friction_rel_jnd: float = 0.08
    component_amplitude_rel: float = 0.08
    component_frequency_rel: float = 0.05
    spatial_phase_mm: float = 2.5
    boundary_mm: float = 2.5
    latency_s: float = 0.010
    guard_s: float = 0.020
    relative_floor: float = 0.1
    peak_min_amplitude: float = 0.02
    segment_min_s: float = 0.2
    correlation_window_s: float = 0.050
    speed_min_mm_s: float = 5.0

    @classmethod
    def from_mapping(cls, data: dict[str, Any] | None) -> Tolerances:
        """Defaults overridden by the keys of ``data`` that name a field (others ignored)."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: float(v) for k, v in (data or {}).items()
                      if k in known and isinstance(v, int | float)})


@dataclass(frozen=True)
class Signal:
    """Friction frames at the golden frame times.

    Attributes:
        t: frame times, s.
        m: relative friction (``uv * ev``).
        contact: finger on the surface.
        texture: active palette index (-1 neutral), or None when not known.
        uv, ev: channel targets, or None when not known.
        events: times of golden discontinuities besides contact and texture changes, s (the
            speed onset of each contact, :func:`speed_onsets`), or None.
    """

    t: np.ndarray
    m: np.ndarray
    contact: np.ndarray
    texture: np.ndarray | None = None
    uv: np.ndarray | None = None
    ev: np.ndarray | None = None
    events: np.ndarray | None = None

    @classmethod
    def of(cls, frames: Any) -> Signal:
        """From :class:`hcard.render.Frames` or a golden dict (``t_s``/``t``, ``uv``, ``ev``,
        ``friction``, ``contact``, ``texture``)."""
        if isinstance(frames, dict):
            t = np.asarray(frames["t_s"] if "t_s" in frames else frames["t"], dtype=float)
            uv = np.asarray(frames["uv"], dtype=float)
            ev = np.asarray(frames["ev"], dtype=float)
            m = np.asarray(frames["friction"], dtype=float) if "friction" in frames else uv * ev
            return cls(t, m, np.asarray(frames["contact"], dtype=bool),
                       np.asarray(frames["texture"]) if "texture" in frames else None, uv, ev)
        return cls(np.asarray(frames.t, float), np.asarray(frames.friction, float),
                   np.asarray(frames.contact, bool), np.asarray(frames.texture),
                   np.asarray(frames.uv, float), np.asarray(frames.ev, float))

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class Metric:
    """One metric's outcome: ``value`` (NaN when not applicable) and a detail line."""

    value: float
    detail: str
    applicable: bool = True


NOT_APPLICABLE = Metric(math.nan, "not applicable", applicable=False)


def frame_rate(golden: Signal) -> float:
    """The golden frame rate, Hz, from its frame times."""
    if len(golden) < 2:
        return 1.0
    return float(round(1.0 / float(np.median(np.diff(golden.t))), 6))


def resample_hold(t_report: np.ndarray, values: np.ndarray, t: np.ndarray,
                  before: float | bool = 0.0) -> np.ndarray:
    """Zero-order hold of reports at times ``t`` (the last report at or before each time);
    ``before`` where no report is yet available."""
    index = np.searchsorted(t_report, t, side="right") - 1
    out = np.asarray(values)[np.clip(index, 0, None)] if len(t_report) else np.zeros(len(t))
    out = np.array(out, copy=True)
    out[index < 0] = before
    return out


# ---------------------------------------------------------------------------------- A0


def exact_error(impl: Signal, golden: Signal, tol: Tolerances) -> tuple[Metric, bool]:
    """A0: ``(metric, passed)``: the largest channel/friction difference; inf when the frame
    counts differ; fails also on frame times beyond ``time_abs_s`` or any contact/texture
    mismatch (named in the detail)."""
    if len(impl) != len(golden):
        return Metric(math.inf, f"{len(impl)} frames, golden has {len(golden)}"), False
    if len(golden) == 0:
        return Metric(0.0, "no frames"), True
    diffs = [np.abs(impl.m - golden.m)]
    for a, b in ((impl.uv, golden.uv), (impl.ev, golden.ev)):
        if a is not None and b is not None:
            diffs.append(np.abs(a - b))
    per_frame = np.max(np.vstack(diffs), axis=0)
    worst = int(np.argmax(per_frame))
    value = float(per_frame[worst])
    problems = []
    dt = float(np.max(np.abs(impl.t - golden.t)))
    if dt > tol.time_abs_s:
        problems.append(f"frame times differ by up to {dt:.3g} s")
    bad_contact = np.flatnonzero(impl.contact != golden.contact)
    if bad_contact.size:
        problems.append(f"contact differs on {bad_contact.size} frames "
                        f"(first at {golden.t[bad_contact[0]]:.4f} s)")
    if impl.texture is not None and golden.texture is not None:
        bad_texture = np.flatnonzero(impl.texture != golden.texture)
        if bad_texture.size:
            problems.append(f"texture differs on {bad_texture.size} frames "
                            f"(first at {golden.t[bad_texture[0]]:.4f} s)")
    detail = (f"largest difference {value:.3g} at t={golden.t[worst]:.4f} s "
              f"(friction {impl.m[worst]:.6f}, golden {golden.m[worst]:.6f})")
    if problems:
        detail += "; " + "; ".join(problems)
    return Metric(value, detail), value <= tol.friction_abs and not problems


# ---------------------------------------------------------------------------------- A-sel


def speed_onsets(track: FingerTrack) -> np.ndarray:
    """Times of the second touch sample of every contact, s: the first speed estimate, where
    a renderer's dead reckoning and odometer start to move (spec A-sel). Before it the golden
    holds the touch-down position, at it the position and the texture phase jump (by about
    speed x touch period); an implementation shows the jump when the sample reaches it, one
    transport delay later, which D3 judges."""
    contact = np.asarray(track.contact, dtype=bool)
    previous = np.concatenate(([False], contact[:-1]))
    second = np.flatnonzero(contact & previous & ~np.concatenate(([False, False], contact[:-2])))
    return np.asarray(track.t, dtype=float)[second]


def compared_frames(impl: Signal, golden: Signal, tol: Tolerances) -> np.ndarray:
    """A-sel: frames in contact in both signals and at least ``guard_s`` from every golden
    discontinuity (a change of golden contact or texture, or an event of ``golden.events``:
    the speed onsets)."""
    fs = frame_rate(golden)
    mask = golden.contact & impl.contact
    change = np.zeros(len(golden), dtype=bool)
    change[1:] = golden.contact[1:] != golden.contact[:-1]
    if golden.texture is not None:
        change[1:] |= golden.texture[1:] != golden.texture[:-1]
    if golden.events is not None and len(golden):
        at = np.searchsorted(golden.t, np.asarray(golden.events, dtype=float))
        change[at[at < len(golden)]] = True
    guard = round(tol.guard_s * fs)
    where = np.flatnonzero(change)
    if where.size:
        near = np.zeros(len(golden) + 1, dtype=int)
        np.add.at(near, np.clip(where - guard, 0, len(golden)), 1)
        np.add.at(near, np.clip(where + guard + 1, 0, len(golden)), -1)
        mask &= np.cumsum(near)[:-1] == 0
    return mask


# ---------------------------------------------------------------------------------- A1


def _squared_errors(impl: Signal, golden: Signal, frames: np.ndarray, lags: np.ndarray,
                    floor: float) -> np.ndarray:
    """``((m_{j+d} - m*_j) / max(m*_j, floor))^2`` for the golden ``frames`` (rows) and the
    ``lags`` (columns); inf where the implementation has no frame ``j + d``."""
    index = frames[:, None] + lags[None, :]
    valid = (index >= 0) & (index < len(impl))
    gold = golden.m[frames][:, None]
    values = impl.m[np.clip(index, 0, len(impl) - 1)]
    return np.where(valid, ((values - gold) / np.maximum(gold, floor)) ** 2, np.inf)


def relative_error(impl: Signal, golden: Signal, tol: Tolerances,
                   windows: PhaseWindows | None = None) -> Metric:
    """A1: RMS relative friction error minimised over a global lag ``d`` of 0..``latency_s``;
    the frames of each phase window (:mod:`hcard_conformance.phase_windows`: velocity-locked
    and temporal textures) take the best lag within its half-width of ``d``."""
    fs = frame_rate(golden)
    selected = np.flatnonzero(compared_frames(impl, golden, tol))
    if selected.size == 0:
        return NOT_APPLICABLE
    window = (windows.window[selected] if windows is not None
              else np.full(selected.size, -1, dtype=int))
    lags = np.arange(round(tol.latency_s * fs) + 1)
    # frames of fixed phase: their sum and count at each global lag
    fixed = _squared_errors(impl, golden, selected[window < 0], lags, tol.relative_floor)
    finite = np.isfinite(fixed)
    total = np.where(finite, fixed, 0.0).sum(axis=0)
    count = finite.sum(axis=0).astype(float)
    shifted = np.zeros(lags.size, dtype=int)
    for w in np.unique(window[window >= 0]):
        assert windows is not None
        h = int(windows.half_width[w])
        frames = selected[window == w]
        sums = _squared_errors(impl, golden, frames, np.arange(-h, lags[-1] + h + 1),
                               tol.relative_floor).sum(axis=0)
        # the best shift within +-h of each global lag (a sliding minimum over 2h + 1 lags)
        spans = np.lib.stride_tricks.sliding_window_view(sums, 2 * h + 1)
        k = np.argmin(spans, axis=1)
        best = spans[np.arange(lags.size), k]
        usable = np.isfinite(best)
        total += np.where(usable, best, 0.0)
        count += np.where(usable, frames.size, 0)
        shifted = np.where(usable, np.maximum(shifted, np.abs(k - h)), shifted)
    with np.errstate(invalid="ignore", divide="ignore"):
        errors = np.sqrt(total / count)
    errors[count == 0] = np.inf
    d = int(np.argmin(errors))
    detail = (f"RMS relative error {errors[d]:.4f} over {selected.size} frames at lag "
              f"{MS_PER_S * d / fs:.1f} ms")
    if np.any(window >= 0):
        detail += (f"; velocity-locked and temporal phase free in "
                   f"{len(np.unique(window[window >= 0]))} windows, shifted up to "
                   f"{MS_PER_S * shifted[d] / fs:.1f} ms")
    return Metric(float(errors[d]), detail)


def relative_error_applies(golden: Signal, tol: Tolerances) -> bool:
    """Whether A1 applies to the golden render (spec Q6: :func:`relative_error` of the golden
    against itself is applicable): some frame is compared, without computing the metric."""
    return bool(np.any(compared_frames(golden, golden, tol)))


# ---------------------------------------------------------------------------------- A2-A4


def segments(impl: Signal, golden: Signal, tol: Tolerances) -> list[tuple[int, int]]:
    """Maximal runs ``[start, stop)`` of compared frames with one golden texture, at least
    ``segment_min_s`` long."""
    mask = compared_frames(impl, golden, tol)
    texture = golden.texture if golden.texture is not None else np.zeros(len(golden), int)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    runs: list[tuple[int, int]] = []
    shortest = round(tol.segment_min_s * frame_rate(golden))
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        cuts = np.flatnonzero(np.diff(texture[start:stop])) + start + 1
        bounds = [start, *cuts.tolist(), stop]
        runs += [(a, b) for a, b in itertools.pairwise(bounds)
                 if b - a >= shortest]
    return runs


def _spectrum(m: np.ndarray, fs: float) -> tuple[np.ndarray, np.ndarray]:
    n = m.size
    w = 0.5 - 0.5 * np.cos(2.0 * np.pi * np.arange(n) / (n - 1))
    k = 8 * 2 ** math.ceil(math.log2(n))
    amplitude = 2.0 * np.abs(np.fft.rfft(w * (m - m.mean()), k)) / w.sum()
    return np.arange(amplitude.size) * fs / k, amplitude


PEAK_MATCH_FRACTION = 0.5
"""Smallest height, as a fraction of the golden peak, of an implementation peak that A2/A3
may pair with it (spec 3.3)."""


def _nearest_peak(spectrum: np.ndarray, window: np.ndarray, k: int, floor: float = 0.0) -> int:
    """The local maximum of ``spectrum`` at least ``floor`` high inside ``window`` nearest to
    bin ``k`` (the larger on a tie); the window's largest bin when it holds none.

    Taking the nearest peak rather than the window's largest keeps a strong neighbouring
    component (a grating's harmonic 15 % away) from being matched to a weaker golden peak,
    which would fail even the golden render against itself. The floor (half the golden peak,
    spec 3.3) keeps the window sidelobes of a component rendered at the wrong frequency from
    being taken for it: a grating 15 % off was once matched to its own leakage at the golden
    frequency and passed A3.
    """
    inner = window[(window > 0) & (window < spectrum.size - 1)]
    rising = spectrum[inner] >= spectrum[inner - 1]
    local = inner[rising & (spectrum[inner] > spectrum[inner + 1]) & (spectrum[inner] >= floor)]
    if local.size == 0:
        return int(window[np.argmax(spectrum[window])])
    order = np.lexsort((-spectrum[local], np.abs(local - k)))
    return int(local[order[0]])


def golden_peaks(golden: Signal, start: int, stop: int, tol: Tolerances,
                 band_limit_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The golden frames ``[start, stop)``'s spectrum and the peaks A2/A3 compare (spec 3.3):
    frequencies (Hz), amplitudes (relative friction), and the bins of the (up to) four largest
    local maxima at least ``peak_min_amplitude`` high, above two bins of the segment's
    resolution and at most ``band_limit_hz``."""
    fs = frame_rate(golden)
    n = stop - start
    f, gold = _spectrum(golden.m[start:stop], fs)
    peak = np.zeros(gold.size, dtype=bool)
    peak[1:-1] = (gold[1:-1] >= gold[:-2]) & (gold[1:-1] > gold[2:])
    peak &= (gold >= tol.peak_min_amplitude) & (f > 2 * fs / n) & (f <= band_limit_hz)
    top = np.flatnonzero(peak)
    return f, gold, top[np.argsort(gold[top])[::-1][:4]]


def components_apply(golden: Signal, tol: Tolerances, band_limit_hz: float) -> bool:
    """Whether A2 and A3 apply to the golden render (spec Q6: :func:`component_errors` of the
    golden against itself is applicable): a segment has a peak to compare."""
    return any(golden_peaks(golden, start, stop, tol, band_limit_hz)[2].size
               for start, stop in segments(golden, golden, tol))


def component_errors(impl: Signal, golden: Signal, tol: Tolerances,
                     band_limit_hz: float) -> tuple[Metric, Metric]:
    """A2 (amplitude, relative to the golden mean) and A3 (relative frequency): the worst over
    the four largest golden spectral peaks of every segment."""
    fs = frame_rate(golden)
    worst_a: tuple[float, str] = (-1.0, "")
    worst_f: tuple[float, str] = (-1.0, "")
    for start, stop in segments(impl, golden, tol):
        n = stop - start
        f, gold, top = golden_peaks(golden, start, stop, tol, band_limit_hz)
        _, mine = _spectrum(impl.m[start:stop], fs)
        mean = float(np.mean(golden.m[start:stop]))
        where = f"{golden.t[start]:.2f}-{golden.t[stop - 1]:.2f} s"
        for k in top:
            window = np.flatnonzero(np.abs(f - f[k]) <= max(0.2 * f[k], 2 * fs / n))
            hat = _nearest_peak(mine, window, int(k), PEAK_MATCH_FRACTION * gold[k])
            e_a = abs(mine[hat] - gold[k]) / mean
            e_f = abs(f[hat] - f[k]) / f[k]
            if e_a > worst_a[0]:
                worst_a = (e_a, f"peak {f[k]:.1f} Hz: amplitude {mine[hat]:.4f} vs golden "
                           f"{gold[k]:.4f} (mean {mean:.3f}), {where}")
            if e_f > worst_f[0]:
                worst_f = (e_f, f"peak {f[k]:.1f} Hz found at {f[hat]:.1f} Hz, {where}")
    if worst_a[0] < 0:
        return NOT_APPLICABLE, NOT_APPLICABLE
    return Metric(*worst_a), Metric(*worst_f)


def sample_speeds(track: FingerTrack) -> np.ndarray:
    """|v_i| of each touch sample, mm/s: rule R4's estimate from the previous sample, in
    contact or not (the first takes the second's)."""
    if len(track) < 2:
        return np.zeros(len(track))
    v = segment_speeds(track.t, track.x, track.y)
    v[0] = v[1]
    return v


def speed_at(track: FingerTrack, t: float) -> float:
    """|v| of the touch sample in effect at ``t`` (the last at or before it), mm/s."""
    i = int(np.searchsorted(track.t, t, side="right")) - 1
    return float(sample_speeds(track)[max(i, 0)])


def position_locked_textures(card: pb.Card, options: RenderOptions) -> set[int]:
    """Palette indices of textures with spatial components all resolving to POSITION (R8)."""
    out = set()
    for index, texture in enumerate(card.textures):
        spatial = [c for c in texture.components if c.domain != pb.DOMAIN_TEMPORAL]
        if spatial and not any(velocity_locked(c, texture.locking, options) for c in spatial):
            out.add(index)
    return out


def phase_correlation(impl: Signal, gold: np.ndarray, start: int, window: int) -> np.ndarray:
    """A4's correlation coefficient of the golden segment ``gold`` (frames ``start`` on) with the
    implementation's friction ``d`` frames later, for ``d = -window..window``.

    Only the implementation's frames in contact take part: after a lift-off (or before a touch)
    a renderer outputs neutral friction, and that step is no feature of the texture. Each lag is
    the Pearson coefficient over the frames it pairs, so the golden render against itself is 1
    at lag 0 and no more anywhere (Cauchy-Schwarz): an unnormalised sum once preferred a lag
    that brought the neutral friction after a lift-off into the window (3 mm on the golden
    render of ``coarse-grating`` along ``liftoff`` against itself). A lag that pairs fewer than
    half of the segment's frames is NaN, as is a lag where either side has no variance."""
    n = gold.size
    total = len(impl)
    lo = start - window
    index = np.arange(lo, start + n + window)
    inside = (index >= 0) & (index < total)
    usable = np.zeros(index.size)
    usable[inside] = impl.contact[index[inside]]
    x = np.zeros(index.size)
    centre = float(np.mean(impl.m[start:start + n]))
    x[inside] = impl.m[index[inside]] - centre
    x *= usable
    y = gold - float(np.mean(gold))
    ones = np.ones(n)
    count = np.correlate(usable, ones, mode="valid")
    sum_x = np.correlate(x, ones, mode="valid")
    sum_xx = np.correlate(x * x, ones, mode="valid")
    sum_y = np.correlate(usable, y, mode="valid")
    sum_yy = np.correlate(usable, y * y, mode="valid")
    sum_xy = np.correlate(x, y, mode="valid")
    with np.errstate(divide="ignore", invalid="ignore"):
        cov = sum_xy - sum_x * sum_y / count
        var = (sum_xx - sum_x * sum_x / count) * (sum_yy - sum_y * sum_y / count)
        r = cov / np.sqrt(var)
    r[(count < 0.5 * n) | ~(var > 0)] = np.nan
    return np.asarray(r)


PHASE_TIE = 1e-9
"""Correlation coefficients of A4 this close to the largest count as equal to it (rounding):
the smallest lag among them is taken."""


def phase_segments(impl: Signal, golden: Signal, tol: Tolerances, track: FingerTrack,
                   locked: set[int]) -> list[tuple[int, int, float]]:
    """The segments A4 judges (spec 3.4), ``(start, stop, mean speed in mm/s)``: those of
    :func:`segments` on a position-locked texture (``locked``), whose golden friction varies
    by at least ``peak_min_amplitude``, with touch samples inside, stroked at
    ``speed_min_mm_s`` or faster."""
    speeds = sample_speeds(track)
    found = []
    for start, stop in segments(impl, golden, tol):
        if golden.texture is not None and int(golden.texture[start]) not in locked:
            continue
        gold = golden.m[start:stop]
        if np.max(np.abs(gold - gold.mean())) < tol.peak_min_amplitude:
            continue
        inside = (track.t >= golden.t[start]) & (track.t <= golden.t[stop - 1])
        if not np.any(inside):
            continue
        vbar = float(np.mean(speeds[inside]))
        if vbar >= tol.speed_min_mm_s:
            found.append((start, stop, vbar))
    return found


def spatial_phase_applies(golden: Signal, tol: Tolerances, track: FingerTrack,
                          locked: set[int]) -> bool:
    """Whether A4 applies to the golden render (spec Q6: :func:`spatial_phase_error` of the
    golden against itself is applicable), without correlating: a segment to judge."""
    return bool(phase_segments(golden, golden, tol, track, locked))


def spatial_phase_error(impl: Signal, golden: Signal, tol: Tolerances, track: FingerTrack,
                        locked: set[int]) -> Metric:
    """A4: the displacement (mm) of position-locked features, from the lag of the largest
    correlation coefficient (:func:`phase_correlation`), worst over segments; a segment where
    the implementation's frames have no variance at any lag counts as not displaced (A1/A2
    judge a missing texture)."""
    fs = frame_rate(golden)
    window = round(tol.correlation_window_s * fs)
    worst: tuple[float, str] | None = None
    for start, stop, vbar in phase_segments(impl, golden, tol, track, locked):
        gold = golden.m[start:stop]
        r = phase_correlation(impl, gold, start, window)
        lags = np.arange(-window, window + 1)
        if np.all(np.isnan(r)):
            d = 0
        else:
            top = np.flatnonzero(r >= np.nanmax(r) - PHASE_TIE)
            d = int(lags[top[np.argmin(np.abs(lags[top]))]])
        dx = vbar * abs(d) / fs
        if worst is None or dx > worst[0]:
            worst = (dx, f"features displaced {dx:.2f} mm (lag {MS_PER_S * d / fs:.1f} ms at "
                     f"{vbar:.0f} mm/s), {golden.t[start]:.2f}-{golden.t[stop - 1]:.2f} s")
    return NOT_APPLICABLE if worst is None else Metric(*worst)


def boundary_transitions(golden: Signal, tol: Tolerances,
                         track: FingerTrack) -> list[tuple[int, float]]:
    """The golden texture transitions A5 judges (spec 3.5), ``(frame, speed in mm/s)``: in
    contact on both sides, crossed at ``speed_min_mm_s`` or faster (none without textures)."""
    if golden.texture is None:
        return []
    gt = golden.texture
    both = golden.contact[1:] & golden.contact[:-1]
    transitions = np.flatnonzero(both & (gt[1:] != gt[:-1])) + 1
    found = []
    for j_star in transitions.tolist():
        v = speed_at(track, float(golden.t[j_star]))
        if v >= tol.speed_min_mm_s:
            found.append((j_star, v))
    return found


def boundary_applies(golden: Signal, tol: Tolerances, track: FingerTrack) -> bool:
    """Whether A5 applies to the golden render (spec Q6: :func:`boundary_error` of the golden
    against itself is applicable): a transition to judge."""
    return bool(boundary_transitions(golden, tol, track))


def boundary_error(impl: Signal, golden: Signal, tol: Tolerances, track: FingerTrack) -> Metric:
    """A5: the worst misplacement (mm) of a golden texture transition in contact."""
    if golden.texture is None:
        return NOT_APPLICABLE
    fs = frame_rate(golden)
    window = round(tol.correlation_window_s * fs)
    gt = golden.texture
    worst: tuple[float, str] | None = None
    for j_star, v in boundary_transitions(golden, tol, track):
        a, b = int(gt[j_star - 1]), int(gt[j_star])
        lo, hi = max(j_star - window, 1), min(j_star + window + 1, len(impl))
        if impl.texture is not None:
            it = impl.texture
            cand = np.flatnonzero((it[lo - 1:hi - 1] == a) & (it[lo:hi] == b)) + lo
        else:
            before = golden.m[max(j_star - int(0.010 * fs), 0):j_star]
            after = golden.m[j_star + int(0.010 * fs):j_star + int(0.020 * fs)]
            level = 0.5 * (float(np.mean(before)) + float(np.mean(after)))
            rising = float(np.mean(after)) > float(np.mean(before))
            side = impl.m >= level if rising else impl.m <= level
            cand = np.flatnonzero(side[lo:hi] & ~side[lo - 1:hi - 1]) + lo
            cand = cand[:1]
        if cand.size == 0:
            db, text = math.inf, "no matching transition found"
        else:
            j = int(cand[np.argmin(np.abs(cand - j_star))])
            db = v * abs(j - j_star) / fs
            text = f"{MS_PER_S * (j - j_star) / fs:+.1f} ms at {v:.0f} mm/s"
        if worst is None or db > worst[0]:
            worst = (db, f"boundary {a}->{b} at t={golden.t[j_star]:.3f} s misplaced "
                     f"{db:.2f} mm ({text})")
    return NOT_APPLICABLE if worst is None else Metric(*worst)
