"""The MPEG-I haptics interchange format (.hjif, ISO/IEC 23090-31) as hcard reads and writes
it: the parsed document as small dataclasses, the checked reader, and the writer whose bytes
are those the MPEG reference software writes back (spec/interchange/hjif.md).

Reading checks what the public schemas (MPEGGroup/HapticJSONSchemas) require of the fields
hcard reads, plus what the reference software (MPEGGroup/HapticReferenceSoftware,
``source/IOHaptics/src/IOJson.cpp``) requires beyond them (rules IJ20-IJ29): a field of the
wrong JSON type is an error naming its JSON path, never a value silently dropped as the
reference drops it. Reading is bounded (IJ27): the file size, the nesting depth, and the
counts of perceptions, channels, bands, effects and keyframes.

Writing (:func:`dumps`) emits compact JSON in the key order of ``IOJson::writeFile``, numbers
as rapidjson's ``Writer`` prints them (shortest round-trip digits; ``1.0``, ``1e-7``,
``0.001``) and strings escaped as it escapes them, so that a document made of values the
reference holds exactly (float32 amplitudes, gains and phases, integer ticks) is written back
byte for byte (rule IJ30).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hcard.errors import AssetError

# --- Vocabulary of the format -------------------------------------------------------------

MODALITIES = ("Pressure", "Acceleration", "Velocity", "Position", "Temperature", "Vibrotactile",
              "Water", "Wind", "Force", "Electrotactile", "Vibrotactile Texture", "Stiffness",
              "Friction", "Humidity", "User-defined Temporal", "User-defined Spatial", "Other")
"""``perception_modality`` values the public schema allows (MPEG_haptics.perception)."""
FRICTION = "Friction"
ELECTROTACTILE = "Electrotactile"
VIBROTACTILE_TEXTURE = "Vibrotactile Texture"
IMPORTED_MODALITIES = (FRICTION, ELECTROTACTILE, VIBROTACTILE_TEXTURE)
"""The modalities hcard imports (IJ40); the others are named in the import's log."""
REFERENCE_CRASHES = ("Humidity", "User-defined Temporal", "User-defined Spatial")
"""Modalities the schema allows but the reference software has no name for: it ends with an
uncaught ``std::out_of_range`` (``stringToPerceptionModality.at``) on reading them (IJ24)."""
BAND_TYPES = ("WaveletWave", "VectorialWave", "Curve", "Transient")
CURVE_TYPES = ("Linear", "Cubic", "Akima", "Bezier", "BSpline", "Unknown")
BASE_SIGNALS = ("Sine", "Square", "Triangle", "SawToothUp", "SawToothDown")
EFFECT_TYPES = ("Basis", "Composite", "Reference")
ACTUATOR_TYPES = ("LRA", "VCA", "ERM", "Piezo", "Unknown")

PHASE_MAX = 6.28318
"""Largest ``phase`` the schema allows (MPEG_haptics.effect: 0 to 6.28318, just under 2 pi)."""
FREQUENCY_MAX = 10000
"""Largest ``frequency_modulation`` and band limit the schema allows."""
MAIN_MAX_TIMESCALE = 48000
"""Largest ``timescale`` of the Main profile (reference ``MAX_TIMESCALE_MAIN``)."""
LEVEL1_MAX_CHANNELS = 128
LEVEL1_MAX_BANDS = 7
"""Level 1 limits of the reference's semantic check: channels per perception, bands per
channel (level 2: 65536 each)."""
DEFAULT_UNIT_EXPONENT = -3
"""The schema's default ``unit_exponent``: positions in millimetres."""

# --- Bounds of the reader (IJ27) ------------------------------------------------------------

MAX_PERCEPTIONS = 64
MAX_CHANNELS = 4096
"""Channels in all perceptions together."""
MAX_BANDS = 65536
"""Bands in all channels together."""
MAX_EFFECTS = 131072
"""Effects in all bands together."""
MAX_KEYFRAMES = 524288
"""Keyframes in all effects together (an exported card has at most about 70 000)."""
MAX_POSITION_TICKS = 2**31 - 1
"""Positions are C++ ``int`` in the reference."""


@dataclass(frozen=True)
class Keyframe:
    """One keyframe: ``relative_position`` ticks from the effect's position,
    ``amplitude_modulation`` in -1..1, ``frequency_modulation`` cycles per ``timescale``
    ticks; each may be absent (None)."""

    position: int | None
    amplitude: float | None
    frequency: int | None


@dataclass(frozen=True)
class Effect:
    """A basis effect of a band: ``position`` ticks, ``phase`` rad (sine convention),
    ``base_signal`` and its keyframes; ``path`` is its JSON path (for messages)."""

    position: int
    phase: float
    base_signal: str
    keyframes: tuple[Keyframe, ...]
    effect_type: str
    path: str

    @property
    def length(self) -> int:
        """Ticks from ``position`` to its last keyframe with a position (its extent in the
        reference's ``getEffectTimeLength`` for curve and vectorial bands)."""
        last = [k.position for k in self.keyframes if k.position is not None]
        return last[-1] if last else 0


@dataclass(frozen=True)
class Band:
    """A band: type, curve type, integer frequency limits and effects."""

    band_type: str
    curve_type: str | None
    lower: int
    upper: int
    effects: tuple[Effect, ...]
    path: str


@dataclass(frozen=True)
class Channel:
    """A channel: id, description, gain, body part mask, reference device and bands."""

    id: int
    description: str
    gain: float
    mixing: float
    body_part_mask: int
    reference_device_id: int | None
    bands: tuple[Band, ...]
    path: str


@dataclass(frozen=True)
class ReferenceDevice:
    """A reference device of a perception: id, name and actuator type (or None)."""

    id: int
    name: str
    type: str | None


@dataclass(frozen=True)
class Perception:
    """A perception: id, modality, description, unit exponents, devices and channels."""

    id: int
    modality: str
    description: str
    unit_exponent: int
    perception_unit_exponent: int
    devices: tuple[ReferenceDevice, ...]
    channels: tuple[Channel, ...]
    path: str


@dataclass(frozen=True)
class Document:
    """A parsed .hjif: the top-level fields hcard uses and its perceptions."""

    version: str
    profile: str
    level: int
    date: str
    description: str
    timescale: int
    perceptions: tuple[Perception, ...]
    counts: dict[str, int] = field(default_factory=dict)


# --- Reading ------------------------------------------------------------------------------


class _Reader:
    """Typed access to a parsed JSON value with paths and running counts for messages and
    bounds; every failure is an :class:`AssetError` naming ``source`` and the JSON path."""

    def __init__(self, source: Path) -> None:
        self.source = source
        self.counts = {"perceptions": 0, "channels": 0, "bands": 0, "effects": 0,
                       "keyframes": 0}

    def fail(self, path: str, reason: str) -> AssetError:
        return AssetError(reason, source=self.source, field=path)

    def count(self, what: str, n: int, path: str, limit: int) -> None:
        self.counts[what] += n
        if self.counts[what] > limit:
            raise self.fail(path, f"more than {limit} {what} in the file (hcard's bound on "
                            "an .hjif, spec/interchange/hjif.md IJ27)")

    def obj(self, value: Any, path: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            raise self.fail(path, f"must be a JSON object, not {_kind(value)}")
        return value

    def array(self, parent: dict[str, Any], key: str, path: str) -> list[Any]:
        where = _join(path, key)
        if key not in parent:
            raise self.fail(where, "missing (required)")
        value = parent[key]
        if not isinstance(value, list):
            raise self.fail(where, f"must be a JSON array, not {_kind(value)}")
        return value

    def string(self, parent: dict[str, Any], key: str, path: str, *,
               default: str | None = None, choices: tuple[str, ...] = ()) -> str:
        where = _join(path, key)
        if key not in parent:
            if default is None:
                raise self.fail(where, "missing (required)")
            return default
        value = parent[key]
        if not isinstance(value, str):
            raise self.fail(where, f"must be a JSON string, not {_kind(value)}")
        if choices and value not in choices:
            raise self.fail(where, f"{_short(value)} is not one of the schema's values "
                            f"({', '.join(choices)})")
        return value

    def integer(self, parent: dict[str, Any], key: str, path: str, *,
                default: int | None = None, low: int | None = None,
                high: int | None = None, why: str = "") -> int:
        where = _join(path, key)
        if key not in parent:
            if default is None:
                raise self.fail(where, "missing (required)" + (f" ({why})" if why else ""))
            return default
        value = parent[key]
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and math.isfinite(value) and value.is_integer():
                raise self.fail(where, f"{value!r} must be written as a JSON integer (the "
                                "MPEG reference software drops a number with a fraction or "
                                "an exponent here without a message)")
            raise self.fail(where, f"must be a JSON integer, not {_kind(value)}")
        if (low is not None and value < low) or (high is not None and value > high):
            raise self.fail(where, f"{value} is outside {low}..{high}")
        return value

    def number(self, parent: dict[str, Any], key: str, path: str, *,
               default: float | None = None, low: float | None = None,
               high: float | None = None) -> float:
        where = _join(path, key)
        if key not in parent:
            if default is None:
                raise self.fail(where, "missing (required)")
            return default
        value = parent[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(where, f"must be a JSON number, not {_kind(value)}")
        number = float(value) if abs(value) < 1e308 else math.inf
        if not math.isfinite(number):
            raise self.fail(where, f"{value!r} is not a finite number")
        if (low is not None and number < low) or (high is not None and number > high):
            raise self.fail(where, f"{value!r} is outside {low:g}..{high:g}")
        return number


def read_document(source: Path, data: bytes) -> Document:
    """The document of the .hjif bytes ``data`` read from ``source``, checked (IJ20-IJ29).

    Raises:
        AssetError: not UTF-8 JSON, nested too deep, a required field missing, a field of the
            wrong type or outside its range, or more elements than the bounds of IJ27.
    """
    from hcard.json_text import JsonInputError, parse_json

    try:
        value = parse_json(data)
    except JsonInputError as exc:
        raise AssetError(f"not JSON: {exc}", source=source) from None
    return document_of(value, source)


def document_of(value: Any, source: Path) -> Document:
    """The document of the parsed JSON ``value`` (see :func:`read_document`)."""
    r = _Reader(source)
    top = r.obj(value, "(top level)")
    if "perceptions" not in top:
        raise r.fail("perceptions", "missing: not an MPEG haptics .hjif (no perceptions)")
    version = r.string(top, "version", "")
    if not _version_ok(version):
        raise r.fail("version", f"{_short(version)} is not an edition of ISO/IEC 23090-31 "
                     "(XXXX or XXXX-Y, year 2023 or later)")
    profile = r.string(top, "profile", "")
    level = r.integer(top, "level", "", low=0)
    date = r.string(top, "date", "")
    description = r.string(top, "description", "")
    timescale = r.integer(top, "timescale", "", low=1, high=2**32 - 1,
                          why="the MPEG reference software requires it")
    r.array(top, "avatars", "")
    r.array(top, "syncs", "")
    items = r.array(top, "perceptions", "")
    r.count("perceptions", len(items), "perceptions", MAX_PERCEPTIONS)
    if not items:
        raise r.fail("perceptions", "empty (the schema requires at least one)")
    perceptions = tuple(_perception(r, item, f"perceptions[{i}]")
                        for i, item in enumerate(items))
    return Document(version, profile, level, date, description, timescale, perceptions,
                    dict(r.counts))


def _perception(r: _Reader, value: Any, path: str) -> Perception:
    item = r.obj(value, path)
    modality = r.string(item, "perception_modality", path, choices=MODALITIES)
    pid = r.integer(item, "id", path, low=0)
    description = r.string(item, "description", path)
    r.integer(item, "avatar_id", path, low=0)
    r.array(item, "effect_library", path)
    unit = r.integer(item, "unit_exponent", path, default=DEFAULT_UNIT_EXPONENT, low=-30,
                     high=30)
    perception_unit = r.integer(item, "perception_unit_exponent", path, default=0, low=-30,
                                high=30)
    devices = tuple(_device(r, d, f"{path}.reference_devices[{i}]") for i, d in
                    enumerate(r.array(item, "reference_devices", path)
                              if "reference_devices" in item else []))
    if modality not in IMPORTED_MODALITIES:
        return Perception(pid, modality, description, unit, perception_unit, devices, (), path)
    values = r.array(item, "channels", path)
    r.count("channels", len(values), f"{path}.channels", MAX_CHANNELS)
    channels = tuple(_channel(r, c, f"{path}.channels[{i}]") for i, c in enumerate(values))
    return Perception(pid, modality, description, unit, perception_unit, devices, channels,
                      path)


def _device(r: _Reader, value: Any, path: str) -> ReferenceDevice:
    item = r.obj(value, path)
    kind = r.string(item, "type", path, default="", choices=ACTUATOR_TYPES) or None
    return ReferenceDevice(r.integer(item, "id", path, low=1), r.string(item, "name", path),
                           kind)


def _channel(r: _Reader, value: Any, path: str) -> Channel:
    item = r.obj(value, path)
    cid = r.integer(item, "id", path, low=0)
    description = r.string(item, "description", path)
    gain = r.number(item, "gain", path, low=0.0, high=1e30)
    mixing = r.number(item, "mixing_coefficient", path, low=0.0, high=1e30)
    mask = r.integer(item, "body_part_mask", path, low=0, high=2**32 - 1,
                     why="the MPEG reference software drops a channel without it")
    device = (r.integer(item, "reference_device_id", path, low=0)
              if "reference_device_id" in item else None)
    values = r.array(item, "bands", path)
    r.count("bands", len(values), f"{path}.bands", MAX_BANDS)
    bands = tuple(_band(r, b, f"{path}.bands[{i}]") for i, b in enumerate(values))
    return Channel(cid, description, gain, mixing, mask, device, bands, path)


def _band(r: _Reader, value: Any, path: str) -> Band:
    item = r.obj(value, path)
    band_type = r.string(item, "band_type", path, choices=BAND_TYPES)
    curve = r.string(item, "curve_type", path, default="", choices=CURVE_TYPES) or None
    lower = r.integer(item, "lower_frequency_limit", path, low=0, high=FREQUENCY_MAX)
    upper = r.integer(item, "upper_frequency_limit", path, low=0, high=FREQUENCY_MAX)
    if upper < lower:
        raise r.fail(_join(path, "upper_frequency_limit"),
                     f"{upper} is below lower_frequency_limit {lower}")
    values = r.array(item, "effects", path)
    r.count("effects", len(values), f"{path}.effects", MAX_EFFECTS)
    effects = tuple(_effect(r, e, f"{path}.effects[{i}]", band_type)
                    for i, e in enumerate(values))
    return Band(band_type, curve, lower, upper, effects, path)


def _effect(r: _Reader, value: Any, path: str, band_type: str) -> Effect:
    item = r.obj(value, path)
    effect_type = r.string(item, "effect_type", path, choices=EFFECT_TYPES)
    position = r.integer(item, "position", path, default=0 if effect_type == "Composite"
                         else None, low=0, high=MAX_POSITION_TICKS)
    phase = r.number(item, "phase", path, default=0.0, low=0.0, high=PHASE_MAX)
    signal = r.string(item, "base_signal", path, default="Sine", choices=BASE_SIGNALS)
    frames: tuple[Keyframe, ...] = ()
    if band_type != "WaveletWave" and "keyframes" in item:
        values = r.array(item, "keyframes", path)
        r.count("keyframes", len(values), f"{path}.keyframes", MAX_KEYFRAMES)
        frames = tuple(_keyframe(r, k, f"{path}.keyframes[{i}]")
                       for i, k in enumerate(values))
    return Effect(position, phase, signal, frames, effect_type, path)


def _keyframe(r: _Reader, value: Any, path: str) -> Keyframe:
    item = r.obj(value, path)
    position = (r.integer(item, "relative_position", path, low=0, high=MAX_POSITION_TICKS)
                if "relative_position" in item else None)
    amplitude = (r.number(item, "amplitude_modulation", path, low=-1.0, high=1.0)
                 if "amplitude_modulation" in item else None)
    frequency = (r.integer(item, "frequency_modulation", path, low=0, high=FREQUENCY_MAX)
                 if "frequency_modulation" in item else None)
    return Keyframe(position, amplitude, frequency)


def _version_ok(version: str) -> bool:
    """``XXXX`` or ``XXXX-Y`` with a year from 2023 and an amendment above 0 (the
    reference's ``IOJson::versionCheck``)."""
    head, _, amendment = version.partition("-")
    if len(head) != 4 or not head.isascii() or not head.isdigit() or int(head) < 2023:
        return False
    if "-" in version:
        return (len(amendment) == 1 and amendment.isascii() and amendment.isdigit()
                and int(amendment) > 0)
    return True


def _join(path: str, key: str) -> str:
    return f"{path}.{key}" if path and not key.startswith("[") else path + key


def _kind(value: Any) -> str:
    if isinstance(value, bool):
        return "true/false"
    if value is None:
        return "null"
    return {dict: "an object", list: "an array", str: "a string", int: "an integer",
            float: "a number"}.get(type(value), type(value).__name__)


def _short(text: str) -> str:
    return repr(text if len(text) <= 40 else text[:40] + "...")


# --- Writing --------------------------------------------------------------------------------


def float32(value: float) -> float:
    """``value`` rounded to the nearest IEEE single (the reference holds amplitudes, gains and
    phases as C++ ``float``), as a Python float."""
    result: float = struct.unpack("<f", struct.pack("<f", value))[0]
    return result


def sine_phase(phase: float) -> float:
    """A phase in radians reduced to [0, 2 pi), rounded to float32, and 0 where that float32
    exceeds the schema's maximum 6.28318 (IJ13: at most 5.3e-6 rad off)."""
    reduced = float32(math.fmod(phase, 2 * math.pi) % (2 * math.pi))
    return reduced if reduced <= PHASE_MAX else 0.0


def format_number(value: float) -> str:
    """``value`` as rapidjson's ``Writer::Double`` prints it (:mod:`.grisu_number`)."""
    from .grisu_number import format_double

    return format_double(value)


_ESCAPES = {'"': '\\"', "\\": "\\\\", "\b": "\\b", "\f": "\\f", "\n": "\\n", "\r": "\\r",
            "\t": "\\t"}


def format_string(text: str) -> str:
    """``text`` as a JSON string the way rapidjson's ``Writer`` escapes it: the quote, the
    backslash, ``\\b \\f \\n \\r \\t``, other control characters as ``\\u00XX`` (upper-case
    hex); everything else, ``/`` and non-ASCII included, as it is (UTF-8)."""
    out = []
    for char in text:
        if char in _ESCAPES:
            out.append(_ESCAPES[char])
        elif ord(char) < 0x20:
            out.append(f"\\u{ord(char):04X}")
        else:
            out.append(char)
    return '"' + "".join(out) + '"'


def dumps(value: Any) -> str:
    """``value`` (dicts in the reference's key order, lists, strings, ints, floats) as compact
    JSON printed as the reference software prints it (no spaces, no final newline)."""
    return "".join(_tokens(value))


def _tokens(value: Any) -> Iterator[str]:
    if isinstance(value, dict):
        yield "{"
        for i, (key, item) in enumerate(value.items()):
            if i:
                yield ","
            yield format_string(key)
            yield ":"
            yield from _tokens(item)
        yield "}"
    elif isinstance(value, list | tuple):
        yield "["
        for i, item in enumerate(value):
            if i:
                yield ","
            yield from _tokens(item)
        yield "]"
    elif isinstance(value, bool):
        yield "true" if value else "false"
    elif isinstance(value, int):
        yield str(value)
    elif isinstance(value, float):
        yield format_number(value)
    elif isinstance(value, str):
        yield format_string(value)
    else:
        raise TypeError(f"not a JSON value: {type(value).__name__}")
