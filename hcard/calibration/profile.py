"""The fitted device profile: a calibration's final model as a JSON file, and back.

:func:`profile_of` turns a :class:`~hcard.calibration.loop.CalibrationResult` into a JSON-ready
dict (format :data:`FORMAT`)::

    {"format": "hcard-calibrated-profile/1",
     "model": "dimensionless-group",             # the base predictor's registered name
     "effects": ["ultrasonic-speed"],            # in the order the loop added them
     "observation": "lateral_force",             # or "output": the model's own output
     "parameters": {"psi_star": {"value": 1.7, "unit": "", "uncertainty": 7e-4,
                                 "fitted": true}, ...},
     "held_out_rmse_n": 0.002, "train_rmse_n": 0.002,
     "data": ["recording 0 (smoke)"]}

``parameters`` holds every parameter of the final lateral-force model
(:func:`~hcard.calibration.observation.lateral_force_model` of the base augmented with the
effects): the base's, the effects' (``"<effect>.<parameter>"``) and the observation's
(``friction_coefficient`` when added, ``force_offset``), SI units. ``uncertainty`` is the
standard uncertainty of a fitted parameter, ``null`` when the parameter was not fitted or the
data do not identify it.

:func:`load_profile` rebuilds that predictor from the plugin registry; its output is the
lateral force in N, exactly as the fitted model's.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hcard.atomic import write_atomically
from hcard.calibration.effects import augment
from hcard.calibration.fit import FitResult
from hcard.calibration.observation import lateral_force_model
from hcard.physics import Predictor, PredictorError
from hcard.physics.profile import ProfileError, read_json

if TYPE_CHECKING:
    from hcard.calibration.loop import CalibrationResult
    from hcard.plugins.registry import PluginRegistry

FORMAT = "hcard-calibrated-profile/1"
"""Value of the ``format`` key of a calibrated profile."""


def _finite(value: float | None) -> float | None:
    if value is None:
        return None
    value = float(value)
    return value if math.isfinite(value) else None


def parameter_table(fit: FitResult) -> dict[str, dict[str, Any]]:
    """Every parameter of ``fit``'s predictor: name -> ``{"value", "unit", "uncertainty",
    "fitted"}`` (uncertainty None when not fitted, infinite or NaN), in the predictor's order."""
    table: dict[str, dict[str, Any]] = {}
    for p in fit.predictor.parameters:
        fitted = p.name in fit.free
        table[p.name] = {
            "value": float(fit.params[p.name]),
            "unit": p.unit,
            "uncertainty": _finite(fit.uncertainties.get(p.name)) if fitted else None,
            "fitted": fitted,
        }
    return table


def profile_of(result: CalibrationResult) -> dict[str, Any]:
    """The final model of ``result`` as a JSON-ready profile dict (module docstring)."""
    after = result.after
    return {
        "format": FORMAT,
        "model": result.model,
        "effects": list(after.effects),
        "observation": result.observation,
        "parameters": parameter_table(after.fit),
        "held_out_rmse_n": _finite(after.test_rmse),
        "train_rmse_n": _finite(after.train_rmse),
        "data": list(result.data.sources),
    }


def profile_json(result: CalibrationResult) -> bytes:
    """:func:`profile_of` as UTF-8 JSON text (indented, finite numbers only)."""
    text = json.dumps(profile_of(result), indent=2, allow_nan=False, ensure_ascii=False)
    return (text + "\n").encode("utf-8")


def save_profile(result: CalibrationResult, path: str | os.PathLike[str]) -> Path:
    """Write :func:`profile_of` ``result`` to ``path`` (atomically) and return the path."""
    target = Path(path)
    write_atomically(target, profile_json(result))
    return target


def _plugin(objects: dict[str, Any], name: str) -> Any | None:
    """The registered object ``name`` (an instance; a registered class is instantiated)."""
    obj = objects.get(name)
    return obj() if isinstance(obj, type) else obj


def _field(raw: dict[str, Any], key: str, kind: type | tuple[type, ...], file: Path) -> Any:
    if key not in raw:
        raise ProfileError(f"{file}: field {key!r} is missing")
    value = raw[key]
    if not isinstance(value, kind) or isinstance(value, bool):
        raise ProfileError(f"{file}: field {key!r} has the wrong type ({type(value).__name__})")
    return value


def load_profile(path: str | os.PathLike[str], registry: PluginRegistry | None = None) -> Predictor:
    """The predictor a calibrated profile describes: ``lateral_force_model(augment(base,
    effects)).with_params(**values)`` (without the lateral-force wrapping when the profile's
    ``observation`` is ``"output"``), base and effects taken from ``registry`` (default: the
    installed plugins, :func:`hcard.plugins.registry.get_registry`).

    Every parameter of the model must be in the profile, in the model's unit; nothing else may.

    Raises:
        PredictorError: (a :class:`~hcard.physics.profile.ProfileError`) a missing or unreadable
            file, bad JSON, another format, an unknown model or effect, an unknown, missing or
            non-finite parameter, a wrong unit, or a value the model refuses; the message names
            the file and the field.
    """
    file = Path(path)
    raw = read_json(file)
    if not isinstance(raw, dict):
        raise ProfileError(f"{file}: not a calibrated profile (a JSON object is expected)")
    if raw.get("format") != FORMAT:
        raise ProfileError(f"{file}: field 'format' is {raw.get('format')!r}, expected {FORMAT!r}")
    if registry is None:
        from hcard.plugins.registry import get_registry

        registry = get_registry()
    model_name = _field(raw, "model", str, file)
    base = _plugin(registry.predictors, model_name)
    if not isinstance(base, Predictor):
        available = ", ".join(sorted(registry.predictors)) or "none installed"
        raise ProfileError(
            f"{file}: field 'model': unknown predictor {model_name!r}; available: {available}"
        )
    effect_names = _field(raw, "effects", list, file)
    effects = []
    for index, name in enumerate(effect_names):
        effect = _plugin(registry.calibration_effects, name) if isinstance(name, str) else None
        if effect is None:
            available = ", ".join(sorted(registry.calibration_effects)) or "none installed"
            raise ProfileError(
                f"{file}: field 'effects[{index}]': unknown calibration effect {name!r}; "
                f"available: {available}"
            )
        effects.append(effect)
    observation = raw.get("observation", "lateral_force")
    if observation not in ("lateral_force", "output"):
        raise ProfileError(
            f"{file}: field 'observation' is {observation!r}, expected 'lateral_force' or 'output'"
        )
    try:
        model = augment(base, effects)
        if observation == "lateral_force":
            model = lateral_force_model(model)
    except PredictorError as exc:
        raise ProfileError(f"{file}: fields 'model'/'effects': {exc}") from None

    parameters = _field(raw, "parameters", dict, file)
    known = {p.name: p for p in model.parameters}
    unknown = sorted(set(parameters) - set(known))
    if unknown:
        raise ProfileError(
            f"{file}: field 'parameters': unknown parameter(s) {', '.join(unknown)} for "
            f"{model.name}; parameters: {', '.join(known)}"
        )
    missing = [name for name in known if name not in parameters]
    if missing:
        raise ProfileError(f"{file}: field 'parameters': missing parameter(s) {', '.join(missing)}")
    values: dict[str, float] = {}
    for name, p in known.items():
        where = f"{file}: field 'parameters.{name}'"
        entry = parameters[name]
        if not isinstance(entry, dict):
            raise ProfileError(f"{where}: expected an object with 'value' and 'unit'")
        value = entry.get("value")
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ProfileError(f"{where}.value: expected a number, got {value!r}")
        if not math.isfinite(value):
            raise ProfileError(f"{where}.value: must be finite, got {value}")
        unit = entry.get("unit")
        if unit != p.unit:
            raise ProfileError(
                f"{where}.unit: {unit!r}, but the model's unit is {p.unit!r} (values are SI)"
            )
        values[name] = float(value)
    try:
        return model.with_params(**values)
    except PredictorError as exc:
        raise ProfileError(f"{file}: field 'parameters': {exc}") from None
