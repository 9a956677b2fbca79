"""The file format of device profiles (``hcard-device-profile/2``, spec/device-profile.md): the
JSON document of a profile's parts, written atomically, and read back with every field checked.

A profile file is a JSON object of the fields :data:`PROFILE_FIELDS` (rule DP1): the predictor
and the optional leakage model (each read by its own class, looked up by model name among the
installed predictors: :func:`predictor_from_profile`), the limits
(:meth:`~hcard.physics.device_limits.DeviceLimits.from_dict`), the effects
(:meth:`~hcard.physics.profile_effects.FittedEffect.from_dict`), and the free-form
``observation`` and ``calibration``. Every error names the file (or the ``source`` given) and
the field; a file of an earlier format is refused with what to do
(:mod:`hcard.physics.old_formats`). :class:`hcard.physics.profile.DeviceProfile` reads and
writes itself through this module.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hcard.atomic import write_atomically
from hcard.bounded_read import MAX_JSON_FILE_BYTES, InputTooLarge, read_bounded
from hcard.errors import HcardError
from hcard.file_errors import reading, writing
from hcard.json_text import JsonInputError, parse_json
from hcard.physics.device_limits import DeviceLimits
from hcard.physics.old_formats import refuse_old_format
from hcard.physics.predictor import Predictor, PredictorError
from hcard.physics.profile_effects import EffectError, FittedEffect
from hcard.physics.profile_error import ProfileError

if TYPE_CHECKING:
    from hcard.plugins.registry import PluginRegistry

PROFILE_FORMAT = "hcard-device-profile/2"
"""Value of the ``format`` field of a device profile file (spec/device-profile.md)."""

PROFILE_FIELDS = ("format", "name", "description", "predictor", "leakage", "limits", "effects",
                  "observation", "calibration")
"""The fields of a profile file (spec/device-profile.md, rule DP1)."""

OBSERVATION_OUTPUTS = ("lateral_force", "output")
"""``observation.output``: the model was fitted to a lateral force, or to its own output."""


def profile_document(
    *,
    name: str,
    description: str,
    predictor: Predictor,
    leakage: Predictor | None,
    limits: DeviceLimits | None,
    effects: Sequence[FittedEffect],
    observation: Mapping[str, Any] | None,
    calibration: Mapping[str, Any] | None,
) -> dict[str, Any]:
    """The JSON-ready profile of these parts (format :data:`PROFILE_FORMAT`)."""
    return {
        "format": PROFILE_FORMAT,
        "name": name,
        "description": description,
        "predictor": predictor.to_profile(),
        "leakage": None if leakage is None else leakage.to_profile(),
        "limits": None if limits is None else limits.to_dict(),
        "effects": [fitted.to_dict() for fitted in effects],
        "observation": None if observation is None else dict(observation),
        "calibration": None if calibration is None else dict(calibration),
    }


def document_json(document: Mapping[str, Any], name: str) -> bytes:
    """``document`` as UTF-8 JSON text (indented, finite numbers only); a number that is not
    finite is a :class:`ProfileError` naming the profile ``name``."""
    try:
        text = json.dumps(document, indent=2, allow_nan=False, ensure_ascii=False)
    except ValueError as exc:
        raise ProfileError(f"profile {name!r}: {exc}") from None
    return (text + "\n").encode("utf-8")


def write_profile_file(path: str | os.PathLike[str], data: bytes) -> None:
    """Write a profile file's bytes, atomically (readers see the old file or the new one)."""
    with writing(path, ProfileError):
        write_atomically(path, data)


def profile_fields(raw: Any, *, source: str,
                   registry: PluginRegistry | None = None) -> dict[str, Any]:
    """The parts of a profile from its JSON object, checked, as the keyword arguments of
    :class:`~hcard.physics.profile.DeviceProfile`; errors name ``source`` and the field."""
    if not isinstance(raw, Mapping):
        raise ProfileError(f"{source}: a device profile must be a JSON object")
    form = raw.get("format")
    if form != PROFILE_FORMAT:
        refuse_old_format(form, source)
        raise ProfileError(f"{source}: format: expected {PROFILE_FORMAT!r}, got {form!r}")
    unknown = sorted(set(raw) - set(PROFILE_FIELDS))
    if unknown:
        raise ProfileError(f"{source}: {unknown[0]}: unknown field; fields: "
                           f"{', '.join(PROFILE_FIELDS)}")
    for text_field in ("name", "description"):
        if not isinstance(raw.get(text_field, ""), str):
            raise ProfileError(f"{source}: {text_field}: must be a string")
    if "predictor" not in raw:
        raise ProfileError(f"{source}: predictor: missing")
    registry = _registry(registry)
    predictor = predictor_from_profile(
        raw["predictor"], source=f"{source}: predictor", registry=registry
    )
    leakage = None
    if raw.get("leakage") is not None:
        leakage = predictor_from_profile(
            raw["leakage"], source=f"{source}: leakage", registry=registry
        )
    limits = None
    if raw.get("limits") is not None:
        limits = DeviceLimits.from_dict(raw["limits"], source=source)
    effects_raw = raw.get("effects", [])
    if not isinstance(effects_raw, list):
        raise ProfileError(f"{source}: effects: must be a list")
    try:
        effects = tuple(
            FittedEffect.from_dict(entry, source=f"{source}: effects[{index}]",
                                   registry=registry)
            for index, entry in enumerate(effects_raw)
        )
    except EffectError as exc:
        raise ProfileError(str(exc)) from None
    extras: dict[str, Mapping[str, Any] | None] = {}
    for key in ("observation", "calibration"):
        value = raw.get(key)
        if value is not None and not isinstance(value, Mapping):
            raise ProfileError(f"{source}: {key}: must be an object or null")
        extras[key] = value
    _check_observation(extras["observation"], source)
    return {
        "predictor": predictor,
        "limits": limits,
        "leakage": leakage,
        "name": raw.get("name", "device"),
        "description": raw.get("description", ""),
        "effects": effects,
        "observation": extras["observation"],
        "calibration": extras["calibration"],
    }


def _check_observation(raw: Mapping[str, Any] | None, source: str) -> None:
    """The ``observation`` object: ``output`` one of :data:`OBSERVATION_OUTPUTS`, and
    ``parameters`` an object of ``{"value": number, "unit": str, ...}`` entries."""
    if raw is None:
        return
    output = raw.get("output")
    if output not in OBSERVATION_OUTPUTS:
        raise ProfileError(f"{source}: observation.output: {output!r}, expected one of "
                           f"{', '.join(OBSERVATION_OUTPUTS)}")
    parameters = raw.get("parameters", {})
    if not isinstance(parameters, Mapping):
        raise ProfileError(f"{source}: observation.parameters: must be an object")
    for name, entry in parameters.items():
        value = entry.get("value") if isinstance(entry, Mapping) else None
        if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(
                value):
            raise ProfileError(f"{source}: observation.parameters.{name}.value: expected a "
                               "finite number")


def _registry(registry: PluginRegistry | None) -> PluginRegistry:
    if registry is not None:
        return registry
    from hcard.plugins.registry import get_registry

    return get_registry()


def predictor_from_profile(
    raw: Any, *, source: str, registry: PluginRegistry | None = None
) -> Predictor:
    """A predictor from a predictor profile object (:meth:`Predictor.to_profile`).

    The model is looked up by name among the installed predictor plugins; its class reads the
    parameters (so a model with its own profile layout, such as ``coupled``, reads its own).
    """
    if not isinstance(raw, Mapping):
        raise ProfileError(f"{source}: must be an object with 'model' and 'parameters'")
    model = raw.get("model")
    if not isinstance(model, str) or not model:
        raise ProfileError(f"{source}.model: missing or not a string")
    try:
        prototype = _registry(registry).get("predictor", model)
    except HcardError as exc:
        raise ProfileError(f"{source}.model: {exc}") from None
    try:
        return type(prototype).from_profile(raw, source=source)
    except ProfileError:
        raise
    except PredictorError as exc:
        raise ProfileError(str(exc)) from None


def parse_profile_json(data: bytes, *, source: str) -> Any:
    """The JSON value of a profile file's bytes (UTF-8 JSON, a byte-order mark allowed, no key
    twice in one object); errors name ``source``."""
    try:
        return parse_json(data)
    except JsonInputError as exc:
        raise ProfileError(f"{source}: not valid JSON ({exc})") from None


def read_json(file: Path) -> Any:
    """The JSON content of ``file``; :class:`ProfileError` naming the file otherwise."""
    return parse_profile_json(read_profile_bytes(file), source=str(file))


def read_profile_bytes(file: Path) -> bytes:
    """The bytes of a profile file (at most :data:`MAX_JSON_FILE_BYTES`); a missing, too large
    or unreadable file is a :class:`ProfileError` naming it."""
    try:
        with reading(file, ProfileError, "a profile"):
            return read_bounded(file, MAX_JSON_FILE_BYTES)
    except InputTooLarge as exc:
        raise ProfileError(f"{file}: {exc} (a device profile)") from None
