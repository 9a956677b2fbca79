"""Reading an Interhaptics .haps file (JSON, ``m_version`` "5") into checked texture notes
(spec/interchange/haps.md IH1-IH6).

Everything is read within stated bounds: the file's size (:data:`MAX_HAPS_BYTES`), its nesting
(:data:`MAX_HAPS_DEPTH`), the notes (:data:`MAX_NOTES`) and keyframes (:data:`MAX_KEYFRAMES`)
of the texture perception. Every refusal is an :class:`~hcard.errors.AssetError` naming the
file, the JSON path of the field and why, in one line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hcard.errors import AssetError
from hcard.json_text import JsonInputError, parse_json

from .asset_files import read_asset

MAX_HAPS_BYTES = 16 * 1024 * 1024
"""Largest .haps file read, bytes (the public samples are 2-12 kB; Haptic Composer's longest
audio conversions stay under 1 MB)."""
MAX_HAPS_DEPTH = 16
"""Deepest nesting of arrays and objects accepted (a v5 .haps nests 10 deep)."""
MAX_NOTES = 4096
"""Most notes of the texture perception, over all its melodies."""
MAX_KEYFRAMES = 100_000
"""Most keyframes of the texture perception, amplitude and frequency together (the public
texture sample has 42)."""
MAX_GAIN = 1e6
"""Largest gain accepted at any level (the samples use 0.89-1.0)."""

PERCEPTION = "m_texture"
"""The perception imported (IH2)."""
OTHER_PERCEPTIONS = ("m_vibration", "m_stiffness")
"""Perceptions read only to be reported as not imported (IH2)."""


@dataclass(frozen=True)
class Curve:
    """Keyframes of one modulation: positions ``t`` (length units, from the note's start,
    non-decreasing) and values ``v`` (amplitude 0..1, or frequency in cycles per length
    unit)."""

    t: tuple[float, ...]
    v: tuple[float, ...]


@dataclass(frozen=True)
class Note:
    """One texture note: where it lies on the position axis and its two curves.

    Attributes:
        path: JSON path of the note (``m_texture.m_melodies[1].m_notes[0]``).
        start: ``m_startingPoint``, length units.
        length: ``m_length``, length units (> 0).
        gain: product of the gains above and at the note (IH4).
        amplitude: ``m_amplitudeModulation`` keyframes.
        frequency: ``m_frequencyModulation`` keyframes.
    """

    path: str
    start: float
    length: float
    gain: float
    amplitude: Curve
    frequency: Curve


@dataclass
class HapsTexture:
    """The texture perception of a .haps file and what else the file holds.

    Attributes:
        notes: the imported notes (at least one).
        version: ``m_version``.
        length_unit_code: ``m_length_unit`` (meaning undocumented, IH3).
        description: ``m_description``.
        name: ``m_name`` when the file has one.
        melodies: melodies of the texture perception, muted ones included.
        notes_skipped: notes not imported, with why (muted, transient).
        ignored: fields read and not applied, with their values.
        others: notes per other perception (``m_vibration``, ``m_stiffness``).
    """

    notes: list[Note]
    version: str = ""
    length_unit_code: int | None = None
    description: str = ""
    name: str = ""
    melodies: int = 0
    notes_skipped: list[str] = field(default_factory=list)
    ignored: list[str] = field(default_factory=list)
    others: dict[str, int] = field(default_factory=dict)

    @property
    def extent(self) -> float:
        """Where the last note ends, length units."""
        return max(note.start + note.length for note in self.notes)


class _Reader:
    """Checks of the values of one file, each failure an AssetError naming the file."""

    def __init__(self, source: Path) -> None:
        self.source = source
        self.keyframes = 0

    def fail(self, where: str, reason: str) -> AssetError:
        return AssetError(reason, source=self.source, field=where)

    def obj(self, value: Any, where: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(where, f"must be an object, not {_kind(value)}")
        return value

    def array(self, value: Any, where: str) -> list[Any]:
        if not isinstance(value, list):
            raise self.fail(where, f"must be an array, not {_kind(value)}")
        return value

    def number(self, parent: dict[str, Any], key: str, where: str, *,
               default: float | None = None, low: float | None = None,
               high: float | None = None) -> float:
        """``parent[key]`` as a finite number in [low, high] (``default`` when absent)."""
        path = f"{where}.{key}" if where else key
        if key not in parent:
            if default is None:
                raise self.fail(path, "missing")
            return default
        value = parent[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(path, f"must be a number, not {_kind(value)}")
        number = float(value) if not isinstance(value, int) or abs(value) < 1e300 else math.inf
        if not math.isfinite(number):
            raise self.fail(path, f"must be a finite number, not {value!r}")
        if low is not None and number < low:
            raise self.fail(path, f"{number:g} is below {low:g}")
        if high is not None and number > high:
            raise self.fail(path, f"{number:g} is above {high:g}")
        return number

    def curve(self, effect: dict[str, Any], key: str, where: str, *, low: float,
              high: float, positive: bool = False) -> Curve:
        """The keyframes of ``effect[key]``: positions non-decreasing and >= 0, values in
        [low, high] (> low when ``positive``)."""
        path = f"{where}.{key}"
        block = self.obj(effect[key], path)
        if "m_keyframes" not in block:
            raise self.fail(f"{path}.m_keyframes", "missing")
        frames = self.array(block["m_keyframes"], f"{path}.m_keyframes")
        if not frames:
            raise self.fail(f"{path}.m_keyframes", "empty: a modulation needs a keyframe")
        self.keyframes += len(frames)
        if self.keyframes > MAX_KEYFRAMES:
            raise self.fail(f"{path}.m_keyframes", f"more than {MAX_KEYFRAMES} keyframes in "
                            f"the texture perception")
        times: list[float] = []
        values: list[float] = []
        for i, frame in enumerate(frames):
            here = f"{path}.m_keyframes[{i}]"
            frame = self.obj(frame, here)
            t = self.number(frame, "m_time", here, low=0.0)
            v = self.number(frame, "m_value", here, low=low, high=high)
            if positive and v <= low:
                raise self.fail(f"{here}.m_value", f"{v:g} must be above {low:g}")
            if times and t < times[-1]:
                raise self.fail(f"{here}.m_time", f"{t:g} comes before the previous "
                                f"keyframe's {times[-1]:g} (positions must not decrease)")
            times.append(t)
            values.append(v)
        return Curve(tuple(times), tuple(values))


def read_haps(source: Path) -> HapsTexture:
    """The texture perception of the .haps file ``source`` (IH1-IH6).

    Raises:
        AssetError: the file is too large, not JSON, not a .haps object, or its texture
            perception is missing, empty or holds a bad value (the message names the field).
    """
    data = read_asset(source, MAX_HAPS_BYTES, "a .haps file")
    try:
        root = parse_json(data, max_depth=MAX_HAPS_DEPTH)
    except JsonInputError as exc:
        raise AssetError(f"not JSON: {exc}", source=source) from None
    reader = _Reader(source)
    if not isinstance(root, dict):
        raise reader.fail("", f"a .haps file is a JSON object, not {_kind(root)}")
    texture = _header(reader, root)
    texture.others = {key: _note_count(root.get(key)) for key in OTHER_PERCEPTIONS
                      if isinstance(root.get(key), dict)}
    if PERCEPTION not in root:
        held = ", ".join(k for k in OTHER_PERCEPTIONS if k in root) or "no perception"
        raise reader.fail(PERCEPTION, f"missing: the file holds no texture perception ({held})")
    _read_texture(reader, root, texture)
    return texture


def _header(reader: _Reader, root: dict[str, Any]) -> HapsTexture:
    version = root.get("m_version", "")
    texture = HapsTexture(notes=[], version=str(version)[:32])
    unit = root.get("m_length_unit")
    if unit is not None:
        if isinstance(unit, bool) or not isinstance(unit, int):
            raise reader.fail("m_length_unit", f"must be an integer, not {_kind(unit)}")
        texture.length_unit_code = unit
    for key, attribute in (("m_description", "description"), ("m_name", "name")):
        value = root.get(key, "")
        if not isinstance(value, str):
            raise reader.fail(key, f"must be a string, not {_kind(value)}")
        setattr(texture, attribute, value[:1024])
    return texture


def _read_texture(reader: _Reader, root: dict[str, Any], texture: HapsTexture) -> None:
    perception = reader.obj(root[PERCEPTION], PERCEPTION)
    gain = reader.number(root, "m_gain", "", default=1.0, low=0.0, high=MAX_GAIN)
    gain *= reader.number(perception, "m_gain", PERCEPTION, default=1.0, low=0.0, high=MAX_GAIN)
    for key in ("m_loop", "m_signalEvaluationMethod", "m_maximum"):
        if key in perception:
            texture.ignored.append(f"{PERCEPTION}.{key} = {str(perception[key])[:40]}")
    melodies = reader.array(perception.get("m_melodies", []), f"{PERCEPTION}.m_melodies")
    texture.melodies = len(melodies)
    count = 0
    for m, melody in enumerate(melodies):
        where = f"{PERCEPTION}.m_melodies[{m}]"
        melody = reader.obj(melody, where)
        notes = reader.array(melody.get("m_notes", []), f"{where}.m_notes")
        count += len(notes)
        if count > MAX_NOTES:
            raise reader.fail(f"{where}.m_notes", f"more than {MAX_NOTES} notes in the "
                              "texture perception")
        if reader.number(melody, "m_mute", where, default=0.0) != 0:
            texture.notes_skipped += [f"{where}.m_notes[{n}] (melody muted)"
                                      for n in range(len(notes))]
            continue
        melody_gain = gain * reader.number(melody, "m_gain", where, default=1.0, low=0.0,
                                           high=MAX_GAIN)
        for n, note in enumerate(notes):
            read = _note(reader, note, f"{where}.m_notes[{n}]", melody_gain)
            if isinstance(read, str):
                texture.notes_skipped.append(read)
            else:
                texture.notes.append(read)
    if not texture.notes:
        why = "; skipped: " + ", ".join(texture.notes_skipped[:3]) if texture.notes_skipped \
            else ""
        held = "".join(f"; {key} holds {n} notes, not imported" for key, n
                       in texture.others.items() if n)
        raise reader.fail(PERCEPTION, f"no texture notes to import ({len(melodies)} melodies, "
                          f"{count} notes{why}{held})")


def _note(reader: _Reader, note: Any, where: str, gain: float) -> Note | str:
    """The note at ``where``, or why it is skipped (a transient: no modulation curves)."""
    note = reader.obj(note, where)
    if "m_hapticEffect" not in note:
        raise reader.fail(f"{where}.m_hapticEffect", "missing")
    effect = reader.obj(note["m_hapticEffect"], f"{where}.m_hapticEffect")
    here = f"{where}.m_hapticEffect"
    if "m_amplitudeModulation" not in effect or "m_frequencyModulation" not in effect:
        kind = f"m_type {effect['m_type']}" if "m_type" in effect else "no modulation"
        return f"{where} ({kind}: a note without amplitude and frequency keyframes)"
    start = reader.number(note, "m_startingPoint", where, default=0.0, low=0.0, high=1e9)
    length = reader.number(note, "m_length", where, low=0.0, high=1e9)
    if length <= 0:
        raise reader.fail(f"{where}.m_length", f"{length:g} must be above 0")
    total = gain * reader.number(note, "m_gain", where, default=1.0, low=0.0, high=MAX_GAIN)
    total *= reader.number(effect, "m_gain", here, default=1.0, low=0.0, high=MAX_GAIN)
    amplitude = reader.curve(effect, "m_amplitudeModulation", here, low=0.0, high=1.0)
    frequency = reader.curve(effect, "m_frequencyModulation", here, low=0.0, high=1e9,
                             positive=True)
    return Note(where, start, length, total, amplitude, frequency)


def _note_count(perception: Any) -> int:
    """Notes of a perception not imported, counted without checking them."""
    melodies = perception.get("m_melodies") if isinstance(perception, dict) else None
    if not isinstance(melodies, list):
        return 0
    return sum(len(m["m_notes"]) for m in melodies
               if isinstance(m, dict) and isinstance(m.get("m_notes"), list))


def _kind(value: Any) -> str:
    """A JSON value's kind in words."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "a boolean"
    if isinstance(value, int | float):
        return "a number"
    if isinstance(value, str):
        return "a string"
    if isinstance(value, list):
        return "an array"
    return "an object"
