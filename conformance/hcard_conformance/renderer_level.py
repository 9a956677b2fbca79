"""Renderer level (spec/conformance.md Q5-Q6, A0-A5): friction *targets* vs golden renders.

For each golden render ``(card, track)`` of the manifest the implementation renders the card
along the track (:meth:`Context.render`):

* the reference (and any software renderer producing frames at the golden frame times) is held
  to **A0**: the same frames to 1e-5 relative friction, contact and texture equal;
* a driver plays the track through the device; its reported ``target_uv * target_ev`` are put
  on the track's time base (:func:`hcard_conformance.context.reported_frames`: from the echoed
  sample and its ``echo_age_us``) and interpolated linearly at the golden frame times, except
  inside a gap of lost reports (:func:`resample_reports`). A device cannot meet A0 (it
  reports at 1 kHz, quantised to 1e-4), so it is held to the
  perceptual metrics only: **A1** relative friction error (RMS, lag up to 10 ms) <= 0.08 on
  every render, **A2/A3** component amplitude/frequency on ``dense``, ``oriented``,
  ``temporal`` and ``bipolar`` cards, **A4** spatial phase on ``coarse``/``sparse`` cards,
  **A5** boundary placement where the golden texture changes in contact.

A1-A5 also run on frame-exact implementations (they must pass trivially when A0 passes).
A position-only renderer at 50 Hz fails A1/A2 on dense textures (it holds one grating phase
per 20 ms touch sample) and passes A4 on coarse ones, which is the distinction the metrics
are built to make.

Each implementation rendering is computed once per run and shared by the checks
(``Context.cache``). Which entries a check reports on is decided from the golden renders
alone (:func:`applicable_entries`, spec Q6), so each check declares its cases before it runs
(``exact_cases`` ... ``boundary_cases``, named by the registry) and renders only the entries a
run wants (:meth:`Context.wants`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from dataclasses import replace
from typing import Any

import numpy as np

from hcard.render import Frames
from hcard.track import FingerTrack
from hcard_conformance import metrics
from hcard_conformance.check_names import (
    RENDERER_BOUNDARY,
    RENDERER_COMPONENT_AMPLITUDE,
    RENDERER_COMPONENT_FREQUENCY,
    RENDERER_EXACT,
    RENDERER_FRICTION_ERROR,
    RENDERER_SPATIAL_PHASE,
)
from hcard_conformance.context import CLOCK_MISMATCH_KEY, DEVICE_LAG_KEY, REALTIME_KEY, Context
from hcard_conformance.metrics import Metric, Signal, Tolerances
from hcard_conformance.phase_windows import phase_windows
from hcard_conformance.realtime import NOT_KEPT, HostWatch, reasons
from hcard_conformance.result import CannotAssess, CheckResult, guarded, measured, unassessed

LEVEL = "renderer"
COMPONENT_TAGS = frozenset({"dense", "oriented", "temporal", "bipolar"})
"""Card tags selecting A2 and A3 (Q6)."""
PHASE_TAGS = frozenset({"coarse", "sparse"})
"""Card tags selecting A4 (Q6)."""
GAP_PERIODS = 1.5
"""Two consecutive reports further apart than this many report periods have lost reports
between them (Q5): the golden frames in between are not compared."""
MAX_UNREPORTED_FRACTION = 0.05
"""Fraction of the golden in-contact frames that may fall in gaps of lost reports before a
render is played again (report loss itself is judged by ``device.report-loss``, L1-L3)."""
PLAY_LATE_S = 0.01
"""Longest time the host may not run in a kept play of a render through a device (spec QT3),
s: half the 20 ms touch period of the vectors' tracks, so no touch sample leaves more than
half a period late."""
RENDER_PLAYS = 3
"""Most plays of one render whose record keeps losing more than
:data:`MAX_UNREPORTED_FRACTION` of its frames before it is not assessed: one host stall on a
shared machine (a collector pause, another process) loses a run of reports, which says nothing
about how the device renders."""


def tolerances(ctx: Context, entry: Any = None) -> Tolerances:
    """Manifest defaults, overridden by a render entry's own ``tolerance`` and by
    ``ctx.options['tolerances']`` (a device class may tighten them)."""
    merged: dict[str, Any] = dict(ctx.manifest.tolerances)
    if entry is not None:
        merged.update(entry.tolerance)
    merged.update(ctx.options.get("tolerances", {}))
    return Tolerances.from_mapping(merged)


def unreported(frames: Frames, t: np.ndarray) -> np.ndarray:
    """Which times ``t`` fall strictly inside a gap of lost reports: between two consecutive
    reports more than :data:`GAP_PERIODS` median report periods apart."""
    if len(frames.t) < 2:
        return np.zeros(len(t), dtype=bool)
    spacing = np.diff(frames.t)
    gap = spacing > GAP_PERIODS * float(np.median(spacing))
    before = np.searchsorted(frames.t, t, side="right") - 1
    inside = (before >= 0) & (before < len(spacing)) & (t > frames.t[np.maximum(before, 0)])
    return inside & gap[np.clip(before, 0, len(spacing) - 1)]


def resample_reports(frames: Frames, t: np.ndarray) -> Signal:
    """Reported frames at times ``t``: targets interpolated linearly between reports, contact
    and texture held from the last report at or before each time (none yet: no contact).

    A STATE report carries the target of one frame, a point sample of a signal the device
    computes at its own frame rate; reports come at 1 kHz. Holding a sample for a whole report
    period (zero-order hold) adds a staircase error of ``2 pi f A P / sqrt(24)`` RMS, 0.1
    relative friction for a 250 Hz, 0.3-amplitude grating, above the JND although the device
    computed every target exactly; linear interpolation leaves ``(2 pi f)^2 A P^2 / 8`` at
    most (0.09 peak, 0.03 RMS there), well inside it, while a position-only renderer, whose
    targets are wrong between touch samples, still fails.

    Where reports were lost (:func:`unreported`) there is nothing to interpolate: a line drawn
    across 10 lost reports of a dense grating raised A1 from 0.02 to 0.07 on a correct device.
    Those times read as out of contact, so no metric compares them (A-sel).
    """
    def between(values: np.ndarray) -> np.ndarray:
        if len(frames.t) == 0:
            return np.ones(len(t))
        return np.interp(t, frames.t, values)

    uv, ev = between(frames.uv), between(frames.ev)
    contact = metrics.resample_hold(frames.t, frames.contact, t, False).astype(bool)
    return Signal(
        t=np.asarray(t, float),
        m=uv * ev,
        contact=contact & ~unreported(frames, np.asarray(t, float)),
        texture=metrics.resample_hold(frames.t, frames.texture, t, -1).astype(np.int32),
        uv=uv,
        ev=ev,
    )


def case(ctx: Context, entry: Any) -> dict[str, Any]:
    """Everything the checks need for one render entry, computed once per Context:
    ``golden``/``impl`` signals, ``card``, ``track``, ``tags``, ``raw`` (the implementation's
    frames as returned)."""
    key = ("renderer-case", entry.name)
    if key not in ctx.cache:
        try:
            ctx.cache[key] = _render_case(ctx, entry)
        except Exception as exc:  # kept: every check of this entry reports it, none re-plays
            ctx.cache[key] = exc
    found = ctx.cache[key]
    if isinstance(found, Exception):
        raise found
    return found


def golden_of(ctx: Context, entry: Any) -> tuple[Signal, FingerTrack]:
    """The golden render of ``entry`` (its speed onsets as events) and its track, loaded once
    per Context: what the checks compare with and what says which metrics apply (spec Q6)."""
    key = ("renderer-golden", entry.name)
    if key not in ctx.cache:
        track = ctx.manifest.track(entry.track).load_track()
        golden = replace(Signal.of(entry.load_arrays()), events=metrics.speed_onsets(track))
        ctx.cache[key] = (golden, track)
    found: tuple[Signal, FingerTrack] = ctx.cache[key]
    return found


def _render_case(ctx: Context, entry: Any) -> dict[str, Any]:
    manifest = ctx.manifest
    card_entry = manifest.card(entry.card)
    card = ctx.card(entry.card)
    golden, track = golden_of(ctx, entry)
    in_contact = max(int(np.count_nonzero(golden.contact)), 1)
    losses: list[int] = []
    late: list[str] = []
    while True:
        with HostWatch(PLAY_LATE_S) as watch:
            raw = ctx.render(card, track, entry.options())
        # the host's lateness matters only to a device on the wall clock (not sim://)
        realtime = not ctx.frame_exact and ctx.cache.get(REALTIME_KEY, True)
        late.append(reasons(watch.late if realtime else "",
                            "" if ctx.frame_exact else ctx.cache.get(DEVICE_LAG_KEY, "")))
        if ctx.frame_exact:
            impl, lost = Signal.of(raw), 0
            break
        impl = resample_reports(raw, golden.t)
        lost = int(np.count_nonzero(golden.contact & unreported(raw, golden.t)))
        if lost <= MAX_UNREPORTED_FRACTION * in_contact:
            break
        losses.append(lost)
        if len(losses) == RENDER_PLAYS:
            # a host that did not run while it should have read lost the reports in transit:
            # such plays measured the host (spec QT3); else the loss is the link's or the
            # device's, which device.report-loss judges
            why = (f"; the plays {NOT_KEPT}: " + "; ".join(x for x in late if x)
                   if any(late) else "")
            clock = ctx.cache.get(CLOCK_MISMATCH_KEY, "")
            if clock:  # nothing was lost: the device's clock is not the host's
                raise CannotAssess(
                    f"{_counts(losses)} of {in_contact} golden frames in contact fell between "
                    f"reports in {RENDER_PLAYS} plays, but {clock}{why}")
            raise CannotAssess(
                f"{_counts(losses)} of {in_contact} golden frames in contact fell in gaps of "
                f"lost STATE reports in {RENDER_PLAYS} plays (more than "
                f"{MAX_UNREPORTED_FRACTION:.0%}); device.report-loss judges the loss{why}")
    return {"golden": golden, "impl": impl, "card": card, "track": track,
            "tags": set(card_entry.tags), "raw": raw, "unreported_frames": lost,
            "replayed_after": losses, "late": late[-1]}


def _counts(losses: list[int]) -> str:
    return ", ".join(str(n) for n in losses)


def _each_entry(ctx: Context, name: str, entries: Iterable[Any],
                judge: Callable[[Any], CheckResult | None]) -> Iterator[CheckResult]:
    """``judge(entry)`` for every entry (of check ``name``: :func:`_entries`), each guarded:
    an entry whose rendering or metric raises is one ERROR result (spec section 6), the others
    are judged as usual. ``judge`` returns None when its metric does not apply to the entry
    (spec Q6)."""
    for entry in entries:

        def measure(entry: Any = entry) -> Iterator[CheckResult]:
            key = ("renderer-case", entry.name)
            late: list[str] = []
            while True:
                result = judge(entry)
                found = ctx.cache.get(key)
                if result is None or result.passed or not isinstance(found, dict) or \
                        not found["late"]:
                    break
                # failed on a play the host did not keep in real time (spec QT3): play again,
                # three plays of this entry in all; a pass on such a play stands
                late.append(found["late"])
                plays = ctx.cache.get(("renderer-late-plays", entry.name), 1)
                if plays >= RENDER_PLAYS:
                    result = unassessed(name, LEVEL, entry.name,
                                        f"the play {NOT_KEPT} in {plays} plays "
                                        f"({'; '.join(late)}); it failed so: {result.detail}")
                    break
                ctx.cache[("renderer-late-plays", entry.name)] = plays + 1
                del ctx.cache[key]
            if result is not None:
                if isinstance(found, dict):
                    result.detail += _loss_note(found)
                yield result

        yield from guarded(name, LEVEL, [entry.name], measure)


def _loss_note(found: dict[str, Any]) -> str:
    """What a result's detail says of the frames its render lost: those left out of the
    comparison and, when the render was played again, the earlier plays' losses."""
    note = ""
    if found["replayed_after"]:
        note += (f"; played again after {_counts(found['replayed_after'])} golden frames "
                 "fell in gaps of lost reports")
    if found["unreported_frames"]:
        note += f"; {found['unreported_frames']} frames in gaps of lost reports not compared"
    return note


def _metric_applies(ctx: Context, name: str, entry: Any) -> bool:
    """Whether the metric of check ``name`` applies to ``entry``'s golden render (spec Q6),
    from the golden alone, without rendering: A0 and A1 wherever a frame is compared, A2/A3 on
    a card tagged ``dense``, ``oriented``, ``temporal`` or ``bipolar`` whose golden has a
    spectral peak, A4 on a ``coarse`` or ``sparse`` card with a position-locked segment to
    judge, A5 where a golden texture transition in contact is crossed fast enough."""
    golden, track = golden_of(ctx, entry)
    tol = tolerances(ctx, entry)
    if name == RENDERER_EXACT:
        return True
    if name == RENDERER_FRICTION_ERROR:
        return metrics.relative_error_applies(golden, tol)
    if name in (RENDERER_COMPONENT_AMPLITUDE, RENDERER_COMPONENT_FREQUENCY):
        return bool(_tags(ctx, entry) & COMPONENT_TAGS) and metrics.components_apply(
            golden, tol, entry.band_limit_hz)
    if name == RENDERER_SPATIAL_PHASE:
        if not _tags(ctx, entry) & PHASE_TAGS:
            return False
        locked = metrics.position_locked_textures(ctx.card(entry.card), entry.options())
        return metrics.spatial_phase_applies(golden, tol, track, locked)
    if name == RENDERER_BOUNDARY:
        return metrics.boundary_applies(golden, tol, track)
    raise ValueError(f"{name!r} is not a renderer-level check")


def applicable_entries(ctx: Context, name: str) -> list[Any]:
    """The render entries check ``name`` reports on, in manifest order: those of the manifest
    (or of ``ctx.options['renders']``, a subset of entry names, e.g. in tests) whose golden
    render its metric applies to (:func:`_metric_applies`; computed once per Context)."""
    subset = ctx.options.get("renders")
    if isinstance(subset, str):  # from the command line: --option renders=CASE[,CASE]
        subset = subset.split(",")
    found = []
    for entry in ctx.manifest.renders:
        if subset and entry.name not in subset:
            continue
        key = ("renderer-applies", name, entry.name)
        if key not in ctx.cache:
            ctx.cache[key] = _metric_applies(ctx, name, entry)
        if ctx.cache[key]:
            found.append(entry)
    return found


def _entries(ctx: Context, name: str) -> list[Any]:
    """:func:`applicable_entries` that the run wants (:meth:`Context.wants`): each entry is
    rendered and judged on its own, so a run of some cases renders only theirs."""
    return [e for e in applicable_entries(ctx, name) if ctx.wants(name, e.name)]


def declared(ctx: Context, name: str) -> list[str]:
    """The cases check ``name`` reports, before it runs: one per applicable render entry."""
    return [e.name for e in applicable_entries(ctx, name)]


def exact_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.exact`` (registry declaration)."""
    return declared(ctx, RENDERER_EXACT)


def friction_error_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.friction_error`` (registry declaration)."""
    return declared(ctx, RENDERER_FRICTION_ERROR)


def component_amplitude_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.component_amplitude`` (registry declaration)."""
    return declared(ctx, RENDERER_COMPONENT_AMPLITUDE)


def component_frequency_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.component_frequency`` (registry declaration)."""
    return declared(ctx, RENDERER_COMPONENT_FREQUENCY)


def spatial_phase_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.spatial_phase`` (registry declaration)."""
    return declared(ctx, RENDERER_SPATIAL_PHASE)


def boundary_cases(ctx: Context) -> list[str]:
    """Cases of ``renderer.boundary`` (registry declaration)."""
    return declared(ctx, RENDERER_BOUNDARY)


def _result(name: str, entry: Any, metric_id: str, metric: Metric, threshold: float,
            unit: str, *, higher_is_better: bool = False) -> CheckResult:
    result = measured(name, LEVEL, entry.name, metric_id, metric.value, threshold, unit=unit,
                      detail=metric.detail, higher_is_better=higher_is_better)
    if math.isinf(metric.value):
        result.passed = False
    return result


def _unmeasured(name: str, entry: Any, data: dict[str, Any],
                metric_of: Callable[[Signal], Metric], found: Metric) -> CheckResult | None:
    """A metric that did not apply to the implementation's frames: None when it does not apply
    to the golden frames either (spec Q6: not applicable), else the case is UNASSESSED with
    why (the implementation reported nothing the metric can judge; never dropped)."""
    if not metric_of(data["golden"]).applicable:
        return None
    return unassessed(name, LEVEL, entry.name,
                      f"{found.detail} in the implementation's frames (applies to the golden)")


def frame_exact(ctx: Context) -> bool:
    """Whether the implementation claims frame-exact renders (check ``renderer.exact``)."""
    return bool(ctx.frame_exact)


def check_exact(ctx: Context) -> Iterator[CheckResult]:
    """A0 on every golden render (frame-exact implementations only)."""

    def judge(entry: Any) -> CheckResult:
        data = case(ctx, entry)
        tol = tolerances(ctx, entry)
        metric, passed = metrics.exact_error(data["impl"], data["golden"], tol)
        result = _result(RENDERER_EXACT, entry, "A0", metric, tol.friction_abs,
                         "relative friction")
        result.passed = passed
        return result

    name = RENDERER_EXACT
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)


def check_friction_error(ctx: Context) -> Iterator[CheckResult]:
    """A1 on every golden render."""

    def judge(entry: Any) -> CheckResult | None:
        data = case(ctx, entry)
        tol = tolerances(ctx, entry)

        def metric_of(impl: Signal) -> Metric:
            golden = data["golden"]
            windows = phase_windows(golden.t, golden.texture,
                                    metrics.compared_frames(impl, golden, tol), data["card"],
                                    data["track"], entry.options(), tol.correlation_window_s)
            return metrics.relative_error(impl, golden, tol, windows)

        metric = metric_of(data["impl"])
        if not metric.applicable:
            return _unmeasured(RENDERER_FRICTION_ERROR, entry, data, metric_of, metric)
        return _result(RENDERER_FRICTION_ERROR, entry, "A1", metric,
                       tol.friction_rel_jnd, "relative friction")

    name = RENDERER_FRICTION_ERROR
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)


def _tags(ctx: Context, entry: Any) -> set[str]:
    return set(ctx.manifest.card(entry.card).tags)


def _components(ctx: Context, entry: Any, which: int, name: str, metric_id: str,
                threshold: float, unit: str) -> CheckResult | None:
    """A2 (``which`` 0) or A3 (1) of one entry; None where the card has no components."""
    if not _tags(ctx, entry) & COMPONENT_TAGS:
        return None
    data = case(ctx, entry)

    def metric_of(impl: Signal) -> Metric:
        return metrics.component_errors(impl, data["golden"], tolerances(ctx, entry),
                                        entry.band_limit_hz)[which]

    metric = metric_of(data["impl"])
    if not metric.applicable:
        return _unmeasured(name, entry, data, metric_of, metric)
    return _result(name, entry, metric_id, metric, threshold, unit)


def check_component_amplitude(ctx: Context) -> Iterator[CheckResult]:
    """A2 on dense, oriented, temporal and bipolar cards."""

    def judge(entry: Any) -> CheckResult | None:
        return _components(ctx, entry, 0, RENDERER_COMPONENT_AMPLITUDE, "A2",
                           tolerances(ctx, entry).component_amplitude_rel, "relative friction")

    name = RENDERER_COMPONENT_AMPLITUDE
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)


def check_component_frequency(ctx: Context) -> Iterator[CheckResult]:
    """A3 on dense, oriented, temporal and bipolar cards."""

    def judge(entry: Any) -> CheckResult | None:
        return _components(ctx, entry, 1, RENDERER_COMPONENT_FREQUENCY, "A3",
                           tolerances(ctx, entry).component_frequency_rel, "fraction")

    name = RENDERER_COMPONENT_FREQUENCY
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)


def check_spatial_phase(ctx: Context) -> Iterator[CheckResult]:
    """A4 on coarse and sparse cards."""

    def judge(entry: Any) -> CheckResult | None:
        data = case(ctx, entry)
        tol = tolerances(ctx, entry)
        locked = metrics.position_locked_textures(data["card"], entry.options())

        def metric_of(impl: Signal) -> Metric:
            return metrics.spatial_phase_error(impl, data["golden"], tol, data["track"], locked)

        metric = metric_of(data["impl"])
        if not metric.applicable:
            return _unmeasured(RENDERER_SPATIAL_PHASE, entry, data, metric_of, metric)
        return _result(RENDERER_SPATIAL_PHASE, entry, "A4", metric, tol.spatial_phase_mm,
                       "mm")

    name = RENDERER_SPATIAL_PHASE
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)


def check_boundary(ctx: Context) -> Iterator[CheckResult]:
    """A5 on every golden render whose texture changes while in contact."""

    def judge(entry: Any) -> CheckResult | None:
        data = case(ctx, entry)
        tol = tolerances(ctx, entry)

        def metric_of(impl: Signal) -> Metric:
            return metrics.boundary_error(impl, data["golden"], tol, data["track"])

        metric = metric_of(data["impl"])
        if not metric.applicable:
            return _unmeasured(RENDERER_BOUNDARY, entry, data, metric_of, metric)
        return _result(RENDERER_BOUNDARY, entry, "A5", metric, tol.boundary_mm, "mm")

    name = RENDERER_BOUNDARY
    yield from _each_entry(ctx, name, _entries(ctx, name), judge)
