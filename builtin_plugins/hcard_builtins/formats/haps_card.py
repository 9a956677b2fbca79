"""A .haps texture perception as a card: a row of taxtels along x, each playing the notes
under it as position-locked gratings (spec/interchange/haps.md IH7-IH12).

The source's friction along x (millimetres) is, with ``u = x / L`` the position in the .haps
length unit (``L`` = ``length_unit_mm``) and ``h`` half the friction range (IH9):

    mu(x) = rest + d h E(x) + h sum_n g_n A_n(u - s_n) sin(phi_n(u - s_n)),
    E(x) = sum_n g_n A_n(u - s_n),    phi_n(w) = 2 pi int_0^w f_n,

for each note ``n`` (start ``s_n``, gain ``g_n``, amplitude curve ``A_n``, frequency curve
``f_n`` in cycles per length unit, both zero outside the note). A taxtel plays, per note under
it, one grating of the note's frequency at the taxtel's centre, the note's mean amplitude over
the taxtel and the phase of ``phi_n`` at the centre; its baseline is ``rest + d h`` times the
mean of ``E`` (IH10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hcard import build, limits
from hcard.errors import AssetError, UsageError
from hcard.v1 import card_pb2 as pb

from .haps_parse import Curve, HapsTexture, Note

POINTS_PER_TAXTEL = 32
"""Points at which a note's amplitude is averaged over one taxtel."""
MIN_AMPLITUDE = 1e-9
"""Component amplitudes below this (relative friction) are left out."""


@dataclass(frozen=True)
class FrictionMapping:
    """How the .haps amplitude becomes relative friction (IH9).

    Attributes:
        low, high: the device's friction range, relative friction.
        rest: friction where the texture is silent (``high`` for UV, ``low`` for EV, the middle
            for a range across 1).
        direction: -1 (UV: a signal lowers friction), +1 (EV: raises it), 0 (bipolar).
        channel: ``"uv"``, ``"ev"`` or ``"bipolar"``.
    """

    low: float
    high: float

    @property
    def half(self) -> float:
        """Half the range: the amplitude of a full-scale note, relative friction."""
        return (self.high - self.low) / 2.0

    @property
    def channel(self) -> str:
        if self.high <= 1.0:
            return "uv"
        if self.low >= 1.0:
            return "ev"
        return "bipolar"

    @property
    def direction(self) -> int:
        return {"uv": -1, "ev": 1, "bipolar": 0}[self.channel]

    @property
    def rest(self) -> float:
        return {"uv": self.high, "ev": self.low,
                "bipolar": (self.low + self.high) / 2.0}[self.channel]


def curve_at(curve: Curve, w: np.ndarray) -> np.ndarray:
    """The curve's value at note positions ``w`` (linear between keyframes, the first and last
    values held outside them; IH5)."""
    return np.interp(w, curve.t, curve.v)


def turns_at(curve: Curve, w: np.ndarray) -> np.ndarray:
    """``int_0^w f`` in cycles, exactly, for the piecewise-linear frequency ``curve`` held
    constant outside its keyframes."""
    t = np.asarray(curve.t, dtype=float)
    v = np.asarray(curve.v, dtype=float)
    knots = np.concatenate(([0.0], t[t > 0.0]))
    values = np.interp(knots, t, v)
    cumulative = np.concatenate(([0.0], np.cumsum(np.diff(knots) * (values[1:] + values[:-1])
                                                  / 2.0)))
    w = np.asarray(w, dtype=float)
    i = np.clip(np.searchsorted(knots, w, side="right") - 1, 0, len(knots) - 1)
    dw = w - knots[i]
    f0 = values[i]
    nxt = np.minimum(i + 1, len(knots) - 1)
    span = knots[nxt] - knots[i]
    slope = np.where(span > 0, (values[nxt] - f0) / np.where(span > 0, span, 1.0), 0.0)
    return cumulative[i] + f0 * dw + 0.5 * slope * dw * dw


def envelope_peak(notes: list[Note]) -> float:
    """Largest ``E`` (the summed gained amplitudes) anywhere: a sum of piecewise-linear curves
    peaks at one of its knots (IH8)."""
    knots = np.unique(np.concatenate(
        [np.concatenate(([n.start, n.start + n.length], n.start + np.asarray(n.amplitude.t)))
         for n in notes]))
    total = np.zeros_like(knots)
    for note in notes:
        w = knots - note.start
        inside = (w >= 0.0) & (w <= note.length)
        total += np.where(inside, note.gain * curve_at(note.amplitude, w), 0.0)
    return float(total.max(initial=0.0))


@dataclass
class Layout:
    """The card's geometry: ``cols`` taxtels of ``taxtel_mm`` along ``width_mm``."""

    width_mm: float
    height_mm: float
    taxtel_mm: float
    length_unit_mm: float

    @property
    def cols(self) -> int:
        return build.grid_count(self.width_mm, self.taxtel_mm)


def taxtel_textures(texture: HapsTexture, layout: Layout, mapping: FrictionMapping,
                    scale: float, source: str) -> tuple[list[pb.Texture], list[int], int]:
    """One texture per taxtel, deduplicated: the palette, each taxtel's index into it, and the
    components left out for the 16-per-texture limit."""
    cols = layout.cols
    edges = np.minimum(np.arange(cols + 1) * layout.taxtel_mm, layout.width_mm)
    edges[-1] = layout.width_mm
    frac = (np.arange(POINTS_PER_TAXTEL) + 0.5) / POINTS_PER_TAXTEL
    points = edges[:-1, None] + (edges[1:] - edges[:-1])[:, None] * frac[None, :]  # (cols, P)
    centres = (edges[:-1] + edges[1:]) / 2.0
    per_note = [_note_gratings(note, points, centres, layout, mapping, scale, source)
                for note in texture.notes]
    palette: list[pb.Texture] = []
    index: list[int] = []
    seen: dict[tuple[object, ...], int] = {}
    dropped = 0
    for k in range(cols):
        gratings = [(amp[k], freq[k], phase[k]) for amp, freq, phase in per_note
                    if amp[k] > MIN_AMPLITUDE]
        envelope = sum(amp[k] for amp, _, _ in per_note) / mapping.half if mapping.half else 0.0
        baseline = mapping.rest + mapping.direction * mapping.half * envelope
        gratings.sort(key=lambda g: -g[0])
        dropped += max(0, len(gratings) - limits.MAX_COMPONENTS_PER_TEXTURE)
        kept = gratings[:limits.MAX_COMPONENTS_PER_TEXTURE]
        key = (round(baseline, 12), *((round(a, 12), round(f, 12), round(p, 10))
                                      for a, f, p in kept))
        if key not in seen:
            seen[key] = len(palette)
            palette.append(build.texture(
                baseline, [build.spatial(float(f), float(a), float(p)) for a, f, p in kept],
                channel=mapping.channel, locking="position"))
        index.append(seen[key])
    if len(palette) > limits.MAX_TEXTURES:
        need = layout.taxtel_mm * len(palette) / limits.MAX_TEXTURES
        raise UsageError(f"taxtel_mm {layout.taxtel_mm:g} gives {cols} taxtels with "
                         f"{len(palette)} distinct textures, over the card's "
                         f"{limits.MAX_TEXTURES}; give taxtel_mm of at least {need:.3g}")
    return palette, index, dropped


def _note_gratings(note: Note, points: np.ndarray, centres: np.ndarray, layout: Layout,
                   mapping: FrictionMapping, scale: float, source: str,
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per taxtel: the note's grating amplitude (relative friction), frequency (cycles/mm)
    and phase (rad, of ``cos``) (IH10)."""
    unit = layout.length_unit_mm
    w = points / unit - note.start
    inside = (w >= 0.0) & (w <= note.length)
    mean = np.where(inside, curve_at(note.amplitude, w), 0.0).mean(axis=1)
    amplitude = mapping.half * scale * note.gain * mean
    wc = np.clip(centres / unit - note.start, 0.0, note.length)
    frequency = curve_at(note.frequency, wc) / unit
    active = amplitude > MIN_AMPLITUDE
    if np.any(frequency[active] > limits.MAX_SPATIAL_FREQUENCY):
        worst = float(frequency[active].max())
        raise AssetError(
            f"{worst * unit:g} cycles per length unit is {worst:g} cycles/mm at "
            f"{unit:g} mm per unit, above the card's {limits.MAX_SPATIAL_FREQUENCY:g}; give a "
            f"larger length_unit_mm", source=source,
            field=f"{note.path}.m_hapticEffect.m_frequencyModulation")
    # sin(phi) = cos(phi - pi/2), phi linearised about the taxtel's centre xc:
    # phi(x) ~ phi(xc) + 2 pi F (x - xc), so cos(2 pi F x + p) with p = phi(xc) - 2 pi F xc - pi/2
    turns = turns_at(note.frequency, wc) - frequency * (note.start * unit + wc * unit) - 0.25
    phase = 2.0 * math.pi * (turns - np.round(turns))
    return amplitude, frequency, phase


def build_card(texture: HapsTexture, layout: Layout, mapping: FrictionMapping, *,
               title: str, author: str, licence: str, source: str,
               ) -> tuple[pb.Card, list[str]]:
    """The card of ``texture`` and notes on what the mapping did (IH7-IH12)."""
    log: list[str] = []
    peak = envelope_peak(texture.notes)
    scale = 1.0 if peak <= 1.0 else 1.0 / peak
    if peak > 1.0:
        log.append(f"the notes' summed amplitude peaks at {peak:.4g}: every gain divided by "
                   f"it to fit the friction range (IH8)")
    palette, index, dropped = taxtel_textures(texture, layout, mapping, scale, source)
    if dropped:
        log.append(f"{dropped} gratings left out where more than "
                   f"{limits.MAX_COMPONENTS_PER_TEXTURE} notes overlap one taxtel (the weakest)")
    description = texture.description
    card = build.card(layout.width_mm, layout.height_mm,
                      taxtel_mm=(layout.taxtel_mm, layout.height_mm), textures=palette,
                      texture_index=index, title=title, author=author, licence=licence,
                      description=description)
    return card, log
