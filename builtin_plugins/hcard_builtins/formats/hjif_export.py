"""A card as an MPEG-I haptics .hjif (rules IJ1-IJ19 of spec/interchange/hjif.md): one
perception per card channel in use, one channel per palette texture, a curve band for the
baseline and a vectorial band of sine effects per spatial grating; what the format cannot hold
goes into the ``hcard:`` extension in the top-level description (IJ30-IJ36) and the taxtel map
into the glTF companion (IJ50-IJ55).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hcard import __version__, limits
from hcard.channels import CHANNELS
from hcard.plugins.kinds import ExportResult, Loss
from hcard.v1 import card_pb2 as pb

from . import hjif_eval
from .hjif_model import (
    ELECTROTACTILE,
    FREQUENCY_MAX,
    FRICTION,
    LEVEL1_MAX_BANDS,
    LEVEL1_MAX_CHANNELS,
    dumps,
    float32,
    sine_phase,
)

EXTENSION_PREFIX = "hcard:"
"""Start of the top-level description that carries the extension (IJ30)."""
EXTENSION_VERSION = 1
DEFAULT_FRICTION_RANGE: dict[str, tuple[float, float]] = {
    "uv": (0.3, 1.0), "ev": (1.0, 1.6), "bipolar": (0.5, 1.5)}
"""Relative friction of signal -1 and +1 per card channel (IJ8), the image encoder's ranges
(hcard_builtins.image.encoder.DEFAULT_FRICTION_RANGE)."""
TICK_MM = 0.025
"""Length of one position tick, mm (IJ5)."""
PHASE_BUDGET_RAD = 0.02
"""Largest phase error a segment of a rounded-frequency grating may reach at its ends (IJ12)."""
MAX_SEGMENTS = 64
"""Most effects (segments) per grating band (IJ12)."""
SEGMENT_BUDGET = 16384
"""Most grating effects in one export: each band gets ``SEGMENT_BUDGET // gratings`` at most
(about 150 bytes each: an export stays under 3 MB, far below the reader's 16 MiB)."""
CHANNEL_ORDER = ("uv", "ev", "bipolar")
MODALITY = {"uv": FRICTION, "ev": ELECTROTACTILE, "bipolar": FRICTION}
"""Perception modality of each card channel (IJ2)."""
DEVICE = {
    "uv": ("ultrasonic friction modulation (hcard UV: lowers friction)", "Piezo"),
    "ev": ("electroadhesion / electrovibration (hcard EV: raises friction)", "Unknown"),
    "bipolar": ("coupled ultrasonic and electroadhesion stimulator (hcard bipolar)",
                "Unknown"),
}
"""Reference device (name, actuator type) of each card channel's perception (IJ3)."""
GENERATOR = f"hcard {__version__} hjif exporter"
NAMES: dict[int, str] = {c.value: c.name for c in CHANNELS}
"""Channel name (``"uv"``) by enum value."""


@dataclass(frozen=True)
class Axis:
    """The position axis of an export (IJ5): ``position / timescale`` is in units of
    ``10^unit_exponent`` m; a tick is :data:`TICK_MM`."""

    unit_exponent: int

    @property
    def unit_mm(self) -> float:
        """Length of one unit, mm (1000 for metres, 100 for decimetres)."""
        return 10.0 ** (self.unit_exponent + 3)

    @property
    def timescale(self) -> int:
        """Ticks per unit."""
        return round(self.unit_mm / TICK_MM)

    @classmethod
    def for_card(cls, card: pb.Card) -> Axis:
        """Metres when every spatial frequency times 1000 mm fits the schema's 10000, else
        decimetres (50 cycles/mm, the card maximum, is 5000 cycles per 100 mm)."""
        k_max = max((c.frequency for t in card.textures for c in t.components
                     if c.domain == pb.DOMAIN_SPATIAL), default=0.0)
        return cls(0 if k_max * 1000.0 <= FREQUENCY_MAX else -1)


@dataclass(frozen=True)
class Grating:
    """One spatial component as written: rounded frequency, amplitude signal, segments."""

    k: float
    f_int: int
    amplitude: float
    segments: tuple[tuple[int, int, float], ...]
    """(start tick, length in ticks, sine phase) of each effect."""


def export_card(card: pb.Card) -> tuple[dict[str, Any], list[Loss], dict[str, Any]]:
    """The .hjif document of ``card`` (a dict in the reference's key order), what it loses,
    and figures (counts, axis, the hjif's own friction against the card in JND)."""
    axis = Axis.for_card(card)
    used = [ch for ch in CHANNEL_ORDER if any(NAMES.get(t.channel) == ch for t in card.textures)]
    ranges = {ch: friction_range(card, ch) for ch in used}
    length_ticks = max(1, math.ceil(math.hypot(card.surface.width_mm, card.surface.height_mm)
                                    / TICK_MM - 1e-9))
    perceptions = []
    extension_textures = [_texture_extension(texture) for texture in card.textures]
    gratings = sum(1 for t in card.textures for c in t.components
                   if c.domain == pb.DOMAIN_SPATIAL)
    cap = max(1, min(MAX_SEGMENTS, SEGMENT_BUDGET // max(1, gratings)))
    max_bands = 0
    for p, ch in enumerate(used):
        channels = []
        for t, texture in enumerate(card.textures):
            if NAMES.get(texture.channel) != ch:
                continue
            bands = _bands(texture, ranges[ch], axis, length_ticks, cap)
            max_bands = max(max_bands, len(bands))
            channels.append({
                "id": t, "description": f"hcard palette texture {t}", "gain": 1.0,
                "mixing_coefficient": 1.0, "body_part_mask": 0, "reference_device_id": 1,
                "bands": bands})
        perceptions.append(_perception(p, ch, ranges[ch], axis, channels))
    level = 1 if (max_bands <= LEVEL1_MAX_BANDS and all(
        len(p["channels"]) <= LEVEL1_MAX_CHANNELS for p in perceptions)) else 2
    extension = _extension(card, ranges, extension_textures)
    document = {
        "version": "2023", "profile": "Main", "level": level, "date": _date(),
        "description": EXTENSION_PREFIX + json.dumps(extension, separators=(",", ":"),
                                                     ensure_ascii=False, allow_nan=False),
        "timescale": axis.timescale, "avatars": [], "perceptions": perceptions, "syncs": []}
    stats = _stats(card, document, axis, ranges)
    return document, losses(card, ranges, axis), stats


def friction_range(card: pb.Card, channel: str) -> tuple[float, float]:
    """The range of ``channel``'s perception (IJ8): the default, widened symmetrically about
    its middle so that every baseline and every grating amplitude of the channel's textures
    is a signal within -1..1."""
    low, high = DEFAULT_FRICTION_RANGE[channel]
    mid, half = (low + high) / 2, (high - low) / 2
    widest = half
    for texture in card.textures:
        if NAMES.get(texture.channel) != channel:
            continue
        widest = max(widest, abs(texture.baseline - mid), *(
            c.amplitude for c in texture.components if c.domain == pb.DOMAIN_SPATIAL))
    return (low, high) if widest == half else (mid - widest, mid + widest)


def _perception(pid: int, ch: str, rng: tuple[float, float], axis: Axis,
                channels: list[dict[str, Any]]) -> dict[str, Any]:
    low, high = rng
    name, kind = DEVICE[ch]
    return {
        "id": pid, "avatar_id": 0,
        "description": (f"hcard {ch.upper() if ch != 'bipolar' else 'bipolar'} textures: "
                        f"relative friction = {(low + high) / 2:.6g} + {(high - low) / 2:.6g} "
                        f"x signal; position / timescale in 10^{axis.unit_exponent} m"),
        "perception_modality": MODALITY[ch], "unit_exponent": axis.unit_exponent,
        "reference_devices": [{"id": 1, "name": name, "type": kind}],
        "effect_library": [], "channels": channels}


def _bands(texture: pb.Texture, rng: tuple[float, float], axis: Axis,
           length_ticks: int, cap: int) -> list[dict[str, Any]]:
    """The curve band of the baseline, then one vectorial band per spatial grating in the
    texture's order (IJ9-IJ13)."""
    mid, half = (rng[0] + rng[1]) / 2, (rng[1] - rng[0]) / 2
    level = _signal((texture.baseline - mid) / half)
    bands: list[dict[str, Any]] = [{
        "band_type": "Curve", "curve_type": "Linear", "lower_frequency_limit": 0,
        "upper_frequency_limit": 0, "effects": [{
            "effect_type": "Basis", "position": 0, "keyframes": [
                {"relative_position": 0, "amplitude_modulation": level},
                {"relative_position": length_ticks, "amplitude_modulation": level}]}]}]
    for component in texture.components:
        if component.domain != pb.DOMAIN_SPATIAL:
            continue
        grating = grating_of(component, half, axis, length_ticks, cap)
        effects = [{
            "effect_type": "Basis", "position": start, "phase": phase, "base_signal": "Sine",
            "keyframes": [{"relative_position": 0, "amplitude_modulation": grating.amplitude,
                           "frequency_modulation": grating.f_int},
                          {"relative_position": length, "amplitude_modulation":
                           grating.amplitude}]}
            for start, length, phase in grating.segments]
        bands.append({"band_type": "VectorialWave", "lower_frequency_limit": grating.f_int,
                      "upper_frequency_limit": grating.f_int, "effects": effects})
    return bands


def grating_of(component: pb.Component, half: float, axis: Axis,
               length_ticks: int, cap: int = MAX_SEGMENTS) -> Grating:
    """A spatial component as sine effects (IJ10-IJ13): frequency rounded to whole cycles
    per unit (at least 1), amplitude ``A / half`` in float32, the cosine phase turned into a
    sine phase, and as many segments (at most ``cap``) as keep the phase error of the rounding
    within :data:`PHASE_BUDGET_RAD` at their ends, each anchored at its middle."""
    k = component.frequency
    f_int = max(1, round(k * axis.unit_mm))
    dk = k - f_int / axis.unit_mm
    length_mm = length_ticks * TICK_MM
    count = min(cap, max(1, math.ceil(math.pi * abs(dk) * length_mm
                                               / PHASE_BUDGET_RAD - 1e-12)))
    bounds = [round(j * length_ticks / count) for j in range(count + 1)]
    phi_sine = component.phase + math.pi / 2
    segments = []
    for start, end in itertools.pairwise(bounds):
        s_mm, seg_mm = start * TICK_MM, (end - start) * TICK_MM
        phase = phi_sine + 2 * math.pi * k * s_mm + math.pi * dk * seg_mm
        segments.append((start, end - start, sine_phase(phase)))
    return Grating(k, f_int, _signal(component.amplitude / half), tuple(segments))


def _signal(value: float) -> float:
    """A signal value in float32 within -1..1."""
    return min(1.0, max(-1.0, float32(min(1.0, max(-1.0, value)))))


def _texture_extension(texture: pb.Texture) -> dict[str, Any]:
    """What the format cannot hold of a texture (IJ32): name, channel, locking, and per
    component in the card's order either the band of its grating with the exact frequency,
    orientation and channel, or the whole temporal component."""
    components: list[dict[str, Any]] = []
    band = 1
    for component in texture.components:
        entry: dict[str, Any]
        if component.domain == pb.DOMAIN_SPATIAL:
            entry = {"band": band, "k": component.frequency, "o": component.orientation}
            band += 1
        else:
            entry = {"hz": component.frequency, "a": component.amplitude,
                     "p": component.phase}
        if component.channel != pb.CHANNEL_UNSPECIFIED:
            entry["ch"] = NAMES[component.channel]
        components.append(entry)
    entry_texture: dict[str, Any] = {"channel": NAMES[texture.channel],
                                     "locking": _LOCKING_NAMES[texture.locking],
                                     "components": components}
    if texture.name:
        entry_texture["name"] = texture.name
    return entry_texture


_LOCKING_NAMES = {pb.LOCKING_POSITION: "position", pb.LOCKING_VELOCITY: "velocity",
                  pb.LOCKING_AUTO: "auto"}


def _extension(card: pb.Card, ranges: dict[str, tuple[float, float]],
               textures: list[dict[str, Any]]) -> dict[str, Any]:
    """The ``hcard:`` extension (IJ31): its version, metadata, surface and grid, the
    perceptions' friction ranges and the textures' extensions."""
    meta = card.metadata
    metadata = {name: getattr(meta, name) for name in
                ("title", "author", "licence", "description", "generator")
                if getattr(meta, name)}
    return {"hcard_hjif": EXTENSION_VERSION, "metadata": metadata,
            "surface": [card.surface.width_mm, card.surface.height_mm],
            "taxtel": [card.grid.taxtel_width_mm, card.grid.taxtel_height_mm],
            "grid": [card.grid.cols, card.grid.rows],
            "ranges": {ch: list(rng) for ch, rng in ranges.items()},
            "textures": textures}


def _date() -> str:
    """The export's date (IJ1): ``SOURCE_DATE_EPOCH`` when set (reproducible exports), else
    now; RFC 3339 UTC to the second."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH", "")
    seconds = int(epoch) if epoch.isascii() and epoch.isdigit() else int(time.time())
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(seconds))


def losses(card: pb.Card, ranges: dict[str, tuple[float, float]], axis: Axis) -> list[Loss]:
    """What the .hjif cannot hold of ``card`` and where the export keeps it (IJ40-IJ47)."""
    ext = "the hcard extension (top-level description, spec/interchange/hjif.md IJ30)"
    spatial = [c for t in card.textures for c in t.components if c.domain == pb.DOMAIN_SPATIAL]
    temporal = sum(1 for t in card.textures for c in t.components
                   if c.domain == pb.DOMAIN_TEMPORAL)
    found = [Loss("channel", "no UV/EV channel in the format: UV and bipolar textures are "
                  "'Friction' perceptions (reference device Piezo for UV), EV textures "
                  "'Electrotactile'" + ("; components' own channels dropped" if any(
                      c.channel != pb.CHANNEL_UNSPECIFIED for t in card.textures
                      for c in t.components) else ""), ext)]
    lockings = sorted({_LOCKING_NAMES[t.locking] for t in card.textures if t.components})
    if spatial:
        found.append(Loss("locking", "positions are surface positions (position-locked); "
                          f"the card's locking ({', '.join(lockings)}) is not in the format",
                          ext))
    if any(math.remainder(c.orientation, 2 * math.pi) != 0 for c in spatial):
        found.append(Loss("orientation", "each grating is written along its own wave vector "
                          "(1-D positions); orientations are not in the format", ext))
    text = ", ".join(f"{ch} {lo:g}..{hi:g}" for ch, (lo, hi) in ranges.items())
    found.append(Loss("friction-scale", "relative friction written as signal -1..1: friction "
                      f"= middle + half-range x signal over {text} (float32)", ext))
    if spatial:
        found.append(Loss("phase", "cosine phases written as sine phases (phase + pi/2 mod "
                          "2 pi) in float32, at most 6.28318", ""))
    worst = max((abs(c.frequency - max(1, round(c.frequency * axis.unit_mm)) / axis.unit_mm)
                 for c in spatial), default=0.0)
    if worst > 0 or temporal:
        detail = []
        if worst > 0:
            detail.append(f"frequencies rounded to whole cycles per {axis.unit_mm:g} mm "
                          f"(worst {worst:.3g} cycles/mm off; phase re-anchored in segments)")
        if temporal:
            detail.append(f"{temporal} temporal component(s) not written (time-based in a "
                          "spatial perception)")
        found.append(Loss("components", "; ".join(detail), ext))
    if card.grid.cols * card.grid.rows > 1:
        found.append(Loss("taxtel-map", "the format has no surface map: each palette texture "
                          f"is a channel; the {card.grid.cols} x {card.grid.rows} taxtel map is "
                          "an index image", "the glTF companion (.gltf, MPEG_haptic_material)"))
    if any(getattr(card.metadata, n) for n in ("title", "author", "licence", "description")):
        found.append(Loss("metadata", "no title, author or licence fields", ext))
    return found


def _stats(card: pb.Card, document: dict[str, Any], axis: Axis,
           ranges: dict[str, tuple[float, float]]) -> dict[str, Any]:
    """Counts, the axis, and the fidelity of the hjif's own friction to the card's textures
    along each grating's axis (IJ60)."""
    from .hjif_import import parse_dict

    parsed = parse_dict(document)
    errors = []
    jnd = limits.RELATIVE_FRICTION_JND
    n_channels = sum(len(p.channels) for p in parsed.perceptions)
    length_mm = math.hypot(card.surface.width_mm, card.surface.height_mm)
    for perception, ch in zip(parsed.perceptions, ranges, strict=True):
        low, high = ranges[ch]
        for channel in perception.channels:
            texture = card.textures[channel.id]
            k_max = max((c.frequency for c in texture.components), default=0.0)
            u = hjif_eval.sample_grid(length_mm, k_max,
                                      hjif_eval.MAX_SAMPLES // max(1, n_channels))
            signal = hjif_eval.channel_signal(channel, parsed.timescale, u / TICK_MM)
            own = (low + high) / 2 + (high - low) / 2 * signal
            want = np.clip(hjif_eval.texture_profile(texture, u), low, high)
            errors.append(own - want)
    error = np.concatenate(errors) if errors else np.zeros(1)
    counts = parsed.counts
    return {
        "perceptions": len(parsed.perceptions), "channels": n_channels,
        "bands": counts["bands"], "effects": counts["effects"],
        "keyframes": counts["keyframes"], "timescale": axis.timescale,
        "unit_exponent": axis.unit_exponent, "tick_mm": TICK_MM,
        "friction_ranges": {ch: list(r) for ch, r in ranges.items()},
        "rms_error_jnd": float(np.sqrt(np.mean(error**2))) / jnd,
        "max_error_jnd": float(np.max(np.abs(error))) / jnd,
        "fidelity_basis": "the hjif's own signal (numpy, IJ60) against each texture along "
                          "its gratings' axes, both clamped to the perception's range",
    }


def export_bytes(card: pb.Card) -> ExportResult:
    """The files of the export (the .hjif, and the glTF companion when the card has more than
    one taxtel), the losses and the figures."""
    document, lost, stats = export_card(card)
    files = [("", dumps(document).encode("utf-8"))]
    if card.grid.cols * card.grid.rows > 1:
        from .gltf_material import gltf_bytes

        files.append((".gltf", gltf_bytes(card, GENERATOR)))
    return ExportResult(files=files, losses=lost, stats=stats)
