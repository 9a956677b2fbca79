"""An MPEG-I haptics .hjif as a card (rules IJ70-IJ79 of spec/interchange/hjif.md).

Three readings, by what the file comes with:

- the ``hcard:`` extension (an hcard export): the palette, surface and grid from the
  extension, amplitudes, baselines and phases from the hjif's bands, the taxtel map from the
  glTF companion beside it (IJ71);
- no extension, a glTF companion: one texture per channel, placed by the companion's index
  image (IJ72);
- neither: the channels as rows of taxtels along x, each taxtel playing the bands' state at
  its centre (amplitude modulation becomes per-taxtel amplitudes; a constant channel is one
  texture) (IJ73).

The figures of fidelity compare the card with the hjif's own signal evaluated in numpy
(:mod:`.hjif_eval`, IJ60).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hcard import build, limits
from hcard.errors import AssetError
from hcard.plugins.kinds import EncodeResult
from hcard.v1 import card_pb2 as pb

from . import hjif_eval
from .hjif_export import DEFAULT_FRICTION_RANGE, EXTENSION_PREFIX, EXTENSION_VERSION
from .hjif_model import (
    ELECTROTACTILE,
    IMPORTED_MODALITIES,
    Band,
    Channel,
    Document,
    Effect,
    Perception,
    _Reader,
    document_of,
    read_document,
)

DEFAULT_TAXTEL_MM = 5.0
"""Taxtel side of a file without the extension whose channels vary along position (IJ73)."""
EXT = "description:hcard"
"""JSON path prefix of the extension's fields in messages."""
_LOCKINGS = ("position", "velocity", "auto")


@dataclass(frozen=True)
class ImportOptions:
    """The importer's options (``hcard import`` names): ``width_mm``, ``taxtel_mm`` (files
    without the extension), ``friction_range`` (all perceptions), card metadata."""

    width_mm: float | None = None
    taxtel_mm: float | None = None
    friction_range: tuple[float, float] | None = None
    title: str | None = None
    author: str | None = None
    licence: str | None = None


@dataclass
class Placed:
    """One imported channel for the fidelity: its hjif channel, range, axis and the card's
    friction along it."""

    channel: Channel
    low: float
    high: float
    tick_mm: float
    length_mm: float
    k_max: float
    card_friction: Callable[[np.ndarray], np.ndarray]


@dataclass
class Reading:
    """What an import gathers: the document, its extension, log lines and placed channels."""

    doc: Document
    source: Path
    opts: ImportOptions
    extension: dict[str, Any] | None
    log: list[str] = field(default_factory=list)
    placed: list[Placed] = field(default_factory=list)
    notes: set[str] = field(default_factory=set)

    def note(self, line: str) -> None:
        """Log ``line`` once."""
        if line not in self.notes:
            self.notes.add(line)
            self.log.append(line)


def parse_dict(value: dict[str, Any]) -> Document:
    """The document of a JSON value (the exporter checks its own output with it)."""
    return document_of(value, Path("(export)"))


def import_file(source: Path, opts: ImportOptions) -> EncodeResult:
    """The card of the .hjif ``source`` and its fidelity figures (IJ70-IJ79).

    Raises:
        AssetError: the file (or its glTF companion, or its extension) is not acceptable; the
            message names the file, the JSON path and why.
    """
    from hcard.bounded_read import MAX_JSON_FILE_BYTES

    from .asset_files import read_asset

    data = read_asset(source, MAX_JSON_FILE_BYTES, "an .hjif file")
    doc = read_document(source, data)
    reading = Reading(doc, source, opts, extension_of(doc, source))
    for perception in doc.perceptions:
        if perception.modality not in IMPORTED_MODALITIES:
            reading.note(f"perception {perception.id} ({perception.modality}) not imported: "
                         "hcard imports Friction, Electrotactile and Vibrotactile Texture")
    channels = [(p, c) for p in doc.perceptions for c in p.channels]
    if not channels:
        raise AssetError("no channel in a Friction, Electrotactile or Vibrotactile Texture "
                         "perception: nothing to import", source=source, field="perceptions")
    companion = source.with_suffix(".gltf")
    taxtel_map = None
    if companion.is_file():
        from .gltf_material import read_taxtel_map

        taxtel_map = read_taxtel_map(companion)
    if reading.extension is not None:
        card = _from_extension(reading, channels, taxtel_map)
    elif taxtel_map is not None:
        card = _from_companion(reading, channels, taxtel_map)
    else:
        card = _along_x(reading, channels)
    return EncodeResult(card=card, stats=_stats(reading, card, taxtel_map is not None),
                        log=reading.log)


# --- The extension ------------------------------------------------------------------------


def extension_of(doc: Document, source: Path) -> dict[str, Any] | None:
    """The checked ``hcard:`` extension of ``doc`` (IJ31-IJ33), or None without one.

    Raises:
        AssetError: the description starts with ``hcard:`` but what follows is not the
            extension (not JSON, an unknown version, a field of the wrong type or range).
    """
    from hcard.json_text import JsonInputError, parse_json

    if not doc.description.startswith(EXTENSION_PREFIX):
        return None
    try:
        value = parse_json(doc.description[len(EXTENSION_PREFIX):])
    except JsonInputError as exc:
        raise AssetError(f"the hcard extension is not JSON: {exc}", source=source,
                         field="description") from None
    r = _Reader(source)
    ext = r.obj(value, EXT)
    version = r.integer(ext, "hcard_hjif", EXT)
    if version != EXTENSION_VERSION:
        raise r.fail(f"{EXT}.hcard_hjif", f"extension version {version} is not "
                     f"{EXTENSION_VERSION}, the one this reader knows")
    meta = r.obj(ext.get("metadata", {}), f"{EXT}.metadata")
    for key in meta:
        if len(r.string(meta, key, f"{EXT}.metadata")) > limits.MAX_TEXT_LENGTH:
            raise r.fail(f"{EXT}.metadata.{key}", f"longer than {limits.MAX_TEXT_LENGTH}")
    _pair(r, ext, "surface", 1e-9, limits.MAX_SURFACE_MM)
    _pair(r, ext, "taxtel", limits.MIN_TAXTEL_MM, limits.MAX_SURFACE_MM)
    grid = r.array(ext, "grid", EXT)
    if len(grid) != 2:
        raise r.fail(f"{EXT}.grid", "must be [cols, rows]")
    r.integer({"cols": grid[0]}, "cols", f"{EXT}.grid", low=1, high=limits.MAX_GRID_COLS)
    r.integer({"rows": grid[1]}, "rows", f"{EXT}.grid", low=1, high=limits.MAX_GRID_ROWS)
    ranges = r.obj(ext.get("ranges", {}), f"{EXT}.ranges")
    for key in ranges:
        r.string({"channel": key}, "channel", f"{EXT}.ranges",
                 choices=tuple(DEFAULT_FRICTION_RANGE))
        low, high = _pair(r, ranges, key, 0.0, limits.MAX_RELATIVE_FRICTION, path=f"{EXT}.ranges")
        if not low < high:
            raise r.fail(f"{EXT}.ranges.{key}", f"{low:g}..{high:g} is empty")
    textures = r.array(ext, "textures", EXT)
    if not 1 <= len(textures) <= limits.MAX_TEXTURES:
        raise r.fail(f"{EXT}.textures", f"{len(textures)} textures, not 1..{limits.MAX_TEXTURES}")
    for t, value in enumerate(textures):
        _check_texture(r, value, f"{EXT}.textures[{t}]")
    return ext


def _pair(r: _Reader, parent: dict[str, Any], key: str, low: float, high: float,
          path: str = EXT) -> tuple[float, float]:
    values = r.array(parent, key, path)
    if len(values) != 2:
        raise r.fail(f"{path}.{key}", "must be a pair of numbers")
    where = f"{path}.{key}"
    return (r.number({"[0]": values[0]}, "[0]", where, low=low, high=high),
            r.number({"[1]": values[1]}, "[1]", where, low=low, high=high))


def _check_texture(r: _Reader, value: Any, path: str) -> None:
    texture = r.obj(value, path)
    r.string(texture, "channel", path, choices=tuple(DEFAULT_FRICTION_RANGE))
    r.string(texture, "locking", path, choices=_LOCKINGS)
    if len(r.string(texture, "name", path, default="")) > limits.MAX_TEXT_LENGTH:
        raise r.fail(f"{path}.name", f"longer than {limits.MAX_TEXT_LENGTH}")
    components = r.array(texture, "components", path)
    if len(components) > limits.MAX_COMPONENTS_PER_TEXTURE:
        raise r.fail(f"{path}.components", f"{len(components)} components, more than "
                     f"{limits.MAX_COMPONENTS_PER_TEXTURE}")
    for c, item in enumerate(components):
        where = f"{path}.components[{c}]"
        entry = r.obj(item, where)
        if "band" in entry:
            r.integer(entry, "band", where, low=1, high=limits.MAX_COMPONENTS_PER_TEXTURE)
            r.number(entry, "k", where, low=1e-300, high=limits.MAX_SPATIAL_FREQUENCY)
            r.number(entry, "o", where, low=-1e6, high=1e6)
        else:
            r.number(entry, "hz", where, low=1e-300, high=limits.MAX_TEMPORAL_FREQUENCY)
            r.number(entry, "a", where, low=0.0, high=limits.MAX_RELATIVE_FRICTION)
            r.number(entry, "p", where, low=-1e6, high=1e6)
        if "ch" in entry:
            r.string(entry, "ch", where, choices=tuple(DEFAULT_FRICTION_RANGE))


# --- Readings -------------------------------------------------------------------------------


def _unit_mm(perception: Perception) -> float:
    """Millimetres of one ``position / timescale`` unit (IJ74: ``10^unit_exponent`` m)."""
    return 10.0 ** (perception.unit_exponent + 3)


def _generic_channel(perception: Perception) -> str:
    """The card channel of a perception read without the extension (IJ75)."""
    if perception.modality == ELECTROTACTILE:
        return "ev"
    if perception.modality == "Friction" and any(d.type == "Piezo" for d in perception.devices):
        return "uv"
    return "bipolar"


def _range(reading: Reading, channel: str) -> tuple[float, float]:
    """The friction range of a perception of card channel ``channel`` (IJ76)."""
    if reading.opts.friction_range is not None:
        return reading.opts.friction_range
    ranges = (reading.extension or {}).get("ranges", {})
    if channel in ranges:
        return float(ranges[channel][0]), float(ranges[channel][1])
    return DEFAULT_FRICTION_RANGE[channel]


def _from_extension(reading: Reading, channels: list[tuple[Perception, Channel]],
                    taxtel_map: Any) -> pb.Card:
    """The card of an hcard export (IJ71)."""
    ext = reading.extension
    assert ext is not None
    if reading.opts.width_mm is not None or reading.opts.taxtel_mm is not None:
        reading.note("width_mm and taxtel_mm ignored: the hcard extension gives the surface")
    by_id: dict[int, tuple[Perception, Channel]] = {}
    for perception, channel in channels:
        by_id.setdefault(channel.id, (perception, channel))
    textures = []
    for t, entry in enumerate(ext["textures"]):
        if t not in by_id:
            raise AssetError(f"texture {t} has no channel with id {t} in the file's Friction "
                             "or Electrotactile perceptions", source=reading.source,
                             field=f"{EXT}.textures[{t}]")
        perception, channel = by_id[t]
        texture = _texture_from_extension(reading, entry, perception, channel, t)
        textures.append(texture)
        _place(reading, perception, channel, _range(reading, entry["channel"]),
               _profile_of(texture))
    (width, height), (tw, th), (cols, rows) = ext["surface"], ext["taxtel"], ext["grid"]
    index = _index_from_map(reading, taxtel_map, cols, rows, {t: t for t in range(len(textures))})
    meta = ext.get("metadata", {})
    return _card(reading, width, height, (tw, th), textures, index, meta)


def _texture_from_extension(reading: Reading, entry: dict[str, Any], perception: Perception,
                            channel: Channel, t: int) -> pb.Texture:
    ch = entry["channel"]
    low, high = _range(reading, ch)
    mid, half = (low + high) / 2, (high - low) / 2
    unit_mm = _unit_mm(perception)
    tick_mm = unit_mm / reading.doc.timescale
    where = f"{EXT}.textures[{t}]"
    if not channel.bands or channel.bands[0].band_type != "Curve":
        raise AssetError("the extension expects the baseline as curve band 0",
                         source=reading.source,
                         field=f"{channel.path}.bands[0]")
    baseline = mid + half * _first_amplitude(channel.bands[0], reading, 0.0)
    components = []
    for c, item in enumerate(entry["components"]):
        own = item.get("ch")
        if "band" not in item:
            components.append(build.temporal(item["hz"], item["a"], item["p"], channel=own))
            continue
        b = item["band"]
        if b >= len(channel.bands) or channel.bands[b].band_type != "VectorialWave" or not (
                channel.bands[b].effects):
            raise AssetError(f"component {c} names band {b}, which is not a vectorial band "
                             "with effects", source=reading.source,
                             field=f"{where}.components[{c}]")
        band = channel.bands[b]
        first = min(band.effects, key=lambda e: e.position)
        f_written = _first_frequency(first)
        k = float(item["k"])
        k_written = f_written / unit_mm
        if abs(k - k_written) > 0.5 / unit_mm + 1e-12:
            reading.note(f"texture {t} component {c}: the extension's frequency {k:g} "
                         f"cycles/mm is not the band's {k_written:g} rounded; the band's used")
            k = k_written
        dk = k - k_written
        start_mm, length_mm = first.position * tick_mm, first.length * tick_mm
        amplitude = _first_amplitude(band, reading, 1.0)
        phase = (first.phase - 2 * math.pi * k * start_mm - math.pi * dk * length_mm
                 - math.pi / 2 + (math.pi if amplitude < 0 else 0.0))
        components.append(build.spatial(k, min(abs(amplitude) * half, limits.MAX_RELATIVE_FRICTION),
                                        phase=math.remainder(phase, 2 * math.pi) % (2 * math.pi),
                                        orientation=float(item["o"]), channel=own))
    return build.texture(_clamp_baseline(baseline, ch), components, channel=ch,
                         locking=entry["locking"], name=entry.get("name", ""))


def _first_amplitude(band: Band, reading: Reading, default: float) -> float:
    """The first amplitude keyframe of the band's first effect (constant bands, IJ71)."""
    if not band.effects:
        return 0.0
    first = min(band.effects, key=lambda e: e.position)
    for frame in first.keyframes:
        if frame.amplitude is not None:
            return frame.amplitude
    return default


def _first_frequency(effect: Effect) -> int:
    for frame in effect.keyframes:
        if frame.frequency is not None:
            return frame.frequency
    return 0


def _from_companion(reading: Reading, channels: list[tuple[Perception, Channel]],
                    taxtel_map: Any) -> pb.Card:
    """One texture per channel, placed by the glTF companion's index image (IJ72)."""
    ids = [c.id for _, c in channels]
    if len(set(ids)) != len(ids):
        raise AssetError("channel ids repeat across perceptions: the glTF's index image "
                         "cannot tell them apart", source=reading.source, field="perceptions")
    if len(channels) > limits.MAX_TEXTURES:
        raise AssetError(f"{len(channels)} channels, more than a card's "
                         f"{limits.MAX_TEXTURES} textures", source=reading.source,
                         field="perceptions")
    textures = []
    for perception, channel in channels:
        ch = _generic_channel(perception)
        texture = _texture_at(reading, perception, channel, ch, None)
        textures.append(texture)
        _place(reading, perception, channel, _range(reading, ch),
               _profile_of(texture))
    rows, cols = taxtel_map.ids.shape
    if taxtel_map.surface_mm is None:
        raise AssetError("the glTF companion gives no surface rectangle (POSITION bounds)",
                         source=reading.source.with_suffix(".gltf"), field="accessors")
    width, height = taxtel_map.surface_mm
    index = _index_from_map(reading, taxtel_map, cols, rows,
                            {cid: i for i, cid in enumerate(ids)})
    return _card(reading, width, height, taxtel_map.taxtel_mm, textures, index, {})


def _along_x(reading: Reading, channels: list[tuple[Perception, Channel]]) -> pb.Card:
    """Channels as rows of taxtels along x (IJ73)."""
    lengths = [_channel_length_mm(reading, p, c) for p, c in channels]
    width = reading.opts.width_mm or max(lengths)
    if not 0 < width <= limits.MAX_SURFACE_MM:
        raise AssetError(f"the channels are {width:g} mm long, outside 0..{limits.MAX_SURFACE_MM:g}"
                         " mm; give --width-mm", source=reading.source, field="perceptions")
    constant = all(_is_constant(c) for _, c in channels)
    taxtel = reading.opts.taxtel_mm or (width if constant else min(DEFAULT_TAXTEL_MM, width))
    cols = build.grid_count(width, taxtel)
    if cols > limits.MAX_GRID_COLS or len(channels) > limits.MAX_GRID_ROWS:
        raise AssetError(f"{cols} taxtels along x for {len(channels)} channel(s) exceed the "
                         f"card's {limits.MAX_GRID_COLS} x {limits.MAX_GRID_ROWS}; give a larger "
                         "--taxtel-mm", source=reading.source, field="perceptions")
    palette: dict[bytes, int] = {}
    textures: list[pb.Texture] = []
    index = []
    for perception, channel in channels:
        ch = _generic_channel(perception)
        row = []
        for col in range(cols):
            x_mm = (col * taxtel + min((col + 1) * taxtel, width)) / 2
            texture = _texture_at(reading, perception, channel, ch, x_mm)
            key = texture.SerializeToString(deterministic=True)
            if key not in palette:
                if len(textures) == limits.MAX_TEXTURES:
                    raise AssetError(f"more than {limits.MAX_TEXTURES} distinct textures along "
                                     f"the channels at {taxtel:g} mm taxtels; give a larger "
                                     "--taxtel-mm", source=reading.source, field=channel.path)
                palette[key] = len(textures)
                textures.append(texture)
            row.append(palette[key])
        index.extend(row)
        _place(reading, perception, channel, _range(reading, ch),
               _row_friction(textures, row, taxtel))
    if not constant:
        reading.note(f"channels vary along position: sampled at the centres of {taxtel:g} mm "
                     "taxtels")
    if len(channels) > 1:
        reading.note(f"{len(channels)} channels without a glTF companion: one row of taxtels "
                     "each, in file order")
    return _card(reading, width, taxtel * len(channels), taxtel, textures, index, {})


def _profile_of(texture: pb.Texture) -> Callable[[np.ndarray], np.ndarray]:
    """The friction of ``texture`` along its gratings' axes (IJ60)."""

    def friction(u: np.ndarray) -> np.ndarray:
        return hjif_eval.texture_profile(texture, u)

    return friction


def _row_friction(textures: list[pb.Texture], row: list[int], taxtel: float
                  ) -> Callable[[np.ndarray], np.ndarray]:
    def friction(u: np.ndarray) -> np.ndarray:
        col = np.minimum((u // taxtel).astype(int), len(row) - 1)
        out = np.empty_like(u)
        for c in range(len(row)):
            mask = col == c
            out[mask] = hjif_eval.texture_profile(textures[row[c]], u[mask])
        return out

    return friction


def _is_constant(channel: Channel) -> bool:
    """One effect per band, one amplitude and one frequency throughout."""
    for band in channel.bands:
        if len(band.effects) > 1:
            return False
        for effect in band.effects:
            if len({k.amplitude for k in effect.keyframes if k.amplitude is not None}) > 1 or len(
                    {k.frequency for k in effect.keyframes if k.frequency is not None}) > 1:
                return False
    return True


def _channel_length_mm(reading: Reading, perception: Perception, channel: Channel) -> float:
    tick_mm = _unit_mm(perception) / reading.doc.timescale
    return max((e.position + e.length for b in channel.bands for e in b.effects),
               default=0) * tick_mm


def _texture_at(reading: Reading, perception: Perception, channel: Channel, ch: str,
                x_mm: float | None) -> pb.Texture:
    """The texture a channel plays at ``x_mm`` (its bands' state there), or at each band's
    first effect's start when ``x_mm`` is None (IJ73, IJ77)."""
    low, high = _range(reading, ch)
    mid, half = (low + high) / 2, (high - low) / 2
    unit_mm = _unit_mm(perception)
    tick_mm = unit_mm / reading.doc.timescale
    level = 0.0
    parts: list[tuple[float, float, float]] = []
    for band in channel.bands:
        effect, r = _effect_at(band, None if x_mm is None else x_mm / tick_mm)
        if effect is None:
            continue
        if band.band_type == "Curve":
            if band.curve_type not in (None, "Linear"):
                reading.note(f"{band.curve_type} curves read as linear between keyframes")
            level += float(hjif_eval._amplitude(effect, np.array([r]), default=0.0)[0])
        elif band.band_type == "VectorialWave":
            part = _grating_at(reading, effect, r, unit_mm, tick_mm)
            if part is not None:
                parts.append((part[0], part[1] * half, part[2]))
        else:
            reading.note(f"{band.band_type} bands not imported")
    if len(parts) > limits.MAX_COMPONENTS_PER_TEXTURE:
        reading.note(f"more than {limits.MAX_COMPONENTS_PER_TEXTURE} gratings in a channel: "
                     "the strongest kept")
        parts = sorted(parts, key=lambda p: -p[1])[:limits.MAX_COMPONENTS_PER_TEXTURE]
    components = [build.spatial(k, min(a, limits.MAX_RELATIVE_FRICTION), phase=phase)
                  for k, a, phase in parts if a > 0]
    return build.texture(_clamp_baseline(mid + half * level, ch), components, channel=ch,
                         locking="position")


def _effect_at(band: Band, ticks: float | None) -> tuple[Effect | None, float]:
    """The effect a band plays at ``ticks`` and the position within it (IJ60), or its first
    effect at its start when ``ticks`` is None."""
    if not band.effects:
        return None, 0.0
    ordered = sorted(band.effects, key=lambda e: e.position)
    if ticks is None:
        return ordered[0], 0.0
    before = [e for e in ordered if e.position <= ticks]
    if not before or ticks > before[-1].position + before[-1].length:
        return None, 0.0
    return before[-1], ticks - before[-1].position


def _grating_at(reading: Reading, effect: Effect, r: float, unit_mm: float,
                tick_mm: float) -> tuple[float, float, float] | None:
    """(k cycles/mm, signal amplitude, cosine phase at the surface origin) of a vectorial
    effect at ``r`` ticks from its start, or None for a non-sine or silent one."""
    if effect.base_signal != "Sine":
        reading.note(f"{effect.base_signal} effects not imported (only Sine)")
        return None
    frequencies = [k.frequency for k in effect.keyframes if k.frequency is not None]
    if len(set(frequencies)) > 1:
        reading.note("frequency modulation within an effect read as the keyframe in force")
    f = float(hjif_eval._frequency(effect, np.array([r]))[0])
    amplitude = float(hjif_eval._amplitude(effect, np.array([r]), default=1.0)[0])
    if f <= 0 or amplitude == 0:
        return None
    k = f / unit_mm
    if k > limits.MAX_SPATIAL_FREQUENCY:
        reading.note(f"gratings above {limits.MAX_SPATIAL_FREQUENCY:g} cycles/mm dropped")
        return None
    start_mm = effect.position * tick_mm
    phase = (effect.phase - 2 * math.pi * k * start_mm - math.pi / 2
             + (math.pi if amplitude < 0 else 0.0))
    return k, abs(amplitude), math.remainder(phase, 2 * math.pi) % (2 * math.pi)


def _clamp_baseline(baseline: float, ch: str) -> float:
    """A baseline within its channel's side of 1 and 0..4 (T3, T6: float32 rounding may put a
    UV baseline of 1 a hair above it)."""
    low, high = {"uv": (0.0, 1.0), "ev": (1.0, limits.MAX_RELATIVE_FRICTION)}.get(
        ch, (0.0, limits.MAX_RELATIVE_FRICTION))
    return min(max(baseline, low), high)


def _index_from_map(reading: Reading, taxtel_map: Any, cols: int, rows: int,
                    palette_of: dict[int, int]) -> list[int]:
    """The texture index from the glTF's channel ids (IJ56), or texture 0 everywhere when
    there is no companion (noted)."""
    if taxtel_map is None:
        if cols * rows > 1:
            reading.note(f"no glTF companion {reading.source.with_suffix('.gltf').name}: the "
                         "taxtel map is lost, every taxtel plays texture 0")
        return [0] * (cols * rows)
    companion = reading.source.with_suffix(".gltf")
    if taxtel_map.ids.shape != (rows, cols):
        raise AssetError(f"the taxtel map is {taxtel_map.ids.shape[1]} x "
                         f"{taxtel_map.ids.shape[0]} pixels, the grid {cols} x {rows}",
                         source=companion, field="images")
    index = []
    for value in taxtel_map.ids.ravel().tolist():
        if value not in palette_of:
            raise AssetError(f"pixel value {value} names no channel of the .hjif",
                             source=companion, field="images")
        index.append(palette_of[value])
    return index


def _place(reading: Reading, perception: Perception, channel: Channel,
           rng: tuple[float, float], friction: Callable[[np.ndarray], np.ndarray]) -> None:
    tick_mm = _unit_mm(perception) / reading.doc.timescale
    k_max = max((f / _unit_mm(perception) for b in channel.bands for e in b.effects
                 for f in (k.frequency for k in e.keyframes) if f is not None), default=0.0)
    reading.placed.append(Placed(channel, rng[0], rng[1], tick_mm,
                                 _channel_length_mm(reading, perception, channel), k_max,
                                 friction))


def _card(reading: Reading, width: float, height: float,
          taxtel: float | tuple[float, float] | None, textures: list[pb.Texture],
          index: list[int], meta: dict[str, str]) -> pb.Card:
    opts = reading.opts
    description = meta.get("description", "")
    if reading.extension is None:
        description = reading.doc.description[:limits.MAX_TEXT_LENGTH]
    card = build.card(width, height, taxtel_mm=taxtel if taxtel is not None else width,
                      textures=textures, texture_index=index,
                      title=opts.title if opts.title is not None else meta.get(
                          "title", "" if reading.extension is not None
                          else reading.source.stem[:limits.MAX_TEXT_LENGTH]),
                      author=opts.author if opts.author is not None else meta.get("author", ""),
                      licence=opts.licence if opts.licence is not None else meta.get(
                          "licence", ""),
                      description=description)
    if meta.get("generator"):
        card.metadata.generator = meta["generator"]
    return card


def _stats(reading: Reading, card: pb.Card, companion: bool) -> dict[str, Any]:
    """Fidelity (IJ60, IJ79) and what the file held."""
    jnd = limits.RELATIVE_FRICTION_JND
    budget = hjif_eval.MAX_SAMPLES // max(1, len(reading.placed))
    errors = []
    for placed in reading.placed:
        u = hjif_eval.sample_grid(max(placed.length_mm, 1e-3), placed.k_max, budget)
        signal = hjif_eval.channel_signal(placed.channel, reading.doc.timescale,
                                          u / placed.tick_mm)
        mid, half = (placed.low + placed.high) / 2, (placed.high - placed.low) / 2
        own = mid + half * signal
        want = np.clip(placed.card_friction(u), placed.low, placed.high)
        errors.append(own - want)
    error = np.concatenate(errors)
    doc = reading.doc
    modalities = sorted({p.modality for p in doc.perceptions})
    how = ("hcard extension" if reading.extension is not None else "no hcard extension") + (
        ", glTF taxtel map" if companion else "")
    return {
        "format_detail": f"MPEG-I haptics {doc.version} {doc.profile}@{doc.level}, "
                         f"{len(doc.perceptions)} perception(s) ({', '.join(modalities)}), "
                         f"{len(reading.placed)} channel(s) imported, {how}",
        "perceptions": len(doc.perceptions), "channels": len(reading.placed),
        "timescale": doc.timescale, "width_mm": card.surface.width_mm,
        "height_mm": card.surface.height_mm, "cols": card.grid.cols, "rows": card.grid.rows,
        "textures": len(card.textures),
        "components": sum(len(t.components) for t in card.textures),
        "hcard_extension": reading.extension is not None, "gltf_companion": companion,
        "rms_error": float(np.sqrt(np.mean(error**2))),
        "max_error": float(np.max(np.abs(error))),
        "rms_error_jnd": float(np.sqrt(np.mean(error**2))) / jnd,
        "max_error_jnd": float(np.max(np.abs(error))) / jnd,
        "fidelity_basis": "the hjif's own signal, amp*sin(2 pi f pos/timescale + phase) "
                          "per band summed and clamped per channel (numpy, IJ60), against the "
                          "card along each channel, both within the perception's range",
    }


__all__ = ["ImportOptions", "extension_of", "import_file", "parse_dict"]
