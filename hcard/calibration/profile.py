"""A calibration's final model as a device profile, and a profile as the model it was fitted as.

``hcard calibrate`` writes one profile format, the device profile of spec/device-profile.md
(``hcard-device-profile/2``): :func:`profile_of` turns a
:class:`~hcard.calibration.results.CalibrationResult` into a
:class:`~hcard.physics.profile.DeviceProfile` holding

- ``predictor``: the base predictor at its fitted values (for a calibration of a device's own
  profile, that profile's predictor; its leakage and limits are kept);
- ``effects``: the effects added, in order, with their fitted values and uncertainties;
- ``observation``: ``output`` (``"lateral_force"`` or ``"output"``) and the observation's own
  fitted parameters (``friction_coefficient`` when it was added, ``force_offset``);
- ``calibration``: the base it started from, every fitted parameter with its uncertainty, the
  held-out errors before and after, the verdict, the split and the recordings with their
  conditions (each sidecar, without the profile it embeds).

:func:`fitted_model` rebuilds, from such a profile, the predictor exactly as it was fitted (the
profile's total relative friction, or the bare predictor with its effects, wrapped to the lateral
force when that was observed), which ``hcard predict --profile`` evaluates.
"""

from __future__ import annotations

import math
from datetime import datetime, timezone
from typing import TYPE_CHECKING, Any

from hcard.calibration.device_model import FINGER_PREFIX, fitted_profile, profile_model
from hcard.calibration.fit import FitResult
from hcard.calibration.observation import FORCE_OFFSET, FRICTION_COEFFICIENT, lateral_force_model
from hcard.physics import Predictor, PredictorError
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_effects import FittedEffect, with_effects
from hcard.physics.profile_error import ProfileError
from hcard.physics.profile_format import predictor_from_profile

if TYPE_CHECKING:
    from hcard.calibration.results import CalibrationResult

BASE_PROFILE = "profile"
"""``calibration.base.kind`` of a calibration of a device profile (:mod:`.device_model`)."""
BASE_PREDICTOR = "predictor"
"""``calibration.base.kind`` of a calibration of a bare predictor (``--model NAME``)."""


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


def _without_profiles(conditions: dict[str, Any]) -> dict[str, Any]:
    """A sidecar without the profile content it may embed (the profile is named, by name and
    SHA-256, not nested)."""
    out = dict(conditions)
    if isinstance(out.get("profile"), dict):
        out["profile"] = {k: v for k, v in out["profile"].items() if k != "content"}
    return out


def profile_of(result: CalibrationResult, base: DeviceProfile | None = None, *,
               voltage_form: str = "envelope") -> DeviceProfile:
    """The final model of ``result`` as a device profile (module docstring).

    Args:
        result: what the loop found.
        base: the device profile that was calibrated (None: a bare predictor was).
        voltage_form: what the voltage input was (``"envelope"`` or ``"instantaneous"``).
    """
    fit = result.after.fit
    table = parameter_table(fit)
    model = fit.predictor
    inner = model.inner if result.observation == "lateral_force" else model  # type: ignore[attr-defined]
    finger = None
    if base is not None:
        fitted = fitted_profile(inner)
        predictor, effects = fitted.predictor, fitted.effects
        finger = _finger_of(inner)
    else:
        added = getattr(inner, "effect_list", ())
        # with effects, ``inner`` is physics.effects' augmented predictor: it has ``base``
        predictor = inner.base if added else inner  # type: ignore[union-attr]
        effects = tuple(
            FittedEffect(e, {p.name: table[f"{e.name}.{p.name}"]["value"] for p in e.parameters})
            for e in added
        )
    effects = tuple(
        FittedEffect(f.effect, f.values,
                     {p.name: table[f"{f.name}.{p.name}"]["uncertainty"]
                      for p in f.effect.parameters})
        for f in effects
    )
    observation_parameters = {name: table[name] for name in (FRICTION_COEFFICIENT, FORCE_OFFSET)
                              if name in table}
    observation: dict[str, Any] = {"output": result.observation,
                                   "parameters": observation_parameters}
    if finger is not None:
        observation["finger"] = {
            **finger.to_profile(),
            "uncertainties": {p.name: table[f"{FINGER_PREFIX}{p.name}"]["uncertainty"]
                              for p in finger.parameters},
        }
    base_names = {p.name for p in predictor.parameters}
    calibration = {
        "base": {
            "kind": BASE_PREDICTOR if base is None else BASE_PROFILE,
            "name": result.model if base is None else base.name,
            "voltage_form": voltage_form,
        },
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "verdict": result.verdict,
        "summary": result.summary,
        "held_out_rmse_before": _finite(result.before.test_rmse),
        "held_out_rmse_after": _finite(result.after.test_rmse),
        "train_rmse_after": _finite(result.after.train_rmse),
        "unit": result.unit,
        "parameters": {name: entry for name, entry in table.items() if name in base_names},
        "split": result.data.split,
        "recordings": list(result.data.sources),
        "conditions": [_without_profiles(c) for c in result.data.conditions],
    }
    name = f"{base.name if base is not None else result.model} (calibrated)"
    description = (f"{result.verdict}; held-out error "
                   f"{_finite(result.before.test_rmse)} -> {_finite(result.after.test_rmse)} "
                   f"{result.unit}")
    values: dict[str, Any] = {
        "predictor": predictor,
        "effects": effects,
        "observation": observation,
        "calibration": calibration,
        "name": name,
        "description": description,
    }
    if base is not None:
        return base.replace(**values)
    return DeviceProfile(limits=None, **values)


def _finger_of(model: Predictor) -> Predictor | None:
    """The finger model inside a fitted profile model (None without one)."""
    return getattr(model, "finger", None)


def fitted_model(profile: DeviceProfile) -> Predictor:
    """The predictor ``profile`` describes, as a calibration fitted it (module docstring): a
    profile with a UV or EV channel as its total relative friction, a bare predictor with its
    effects; wrapped to the lateral force (with the fitted coefficient and offset) when that is
    what was observed.

    Raises:
        ProfileError: the model cannot be built from the profile.
    """
    base = (profile.calibration or {}).get("base", {})
    renders = profile.uv_model is not None or profile.ev_model is not None
    kind = base.get("kind") if isinstance(base, dict) else None
    kind = kind or (BASE_PROFILE if renders else BASE_PREDICTOR)
    try:
        if kind == BASE_PROFILE:
            envelope = base.get("voltage_form", "envelope") == "envelope"
            finger = (profile.observation or {}).get("finger")
            finger_model = None
            if finger is not None:
                finger_model = predictor_from_profile(
                    {k: v for k, v in finger.items() if k != "uncertainties"},
                    source="observation.finger")
            model = profile_model(profile, envelope=envelope, finger=finger_model)
        else:
            model = with_effects(profile.predictor, profile.effects)
        observation = profile.observation or {}
        if observation.get("output", "lateral_force") == "lateral_force":
            model = lateral_force_model(model)
            values = {name: float(entry["value"])
                      for name, entry in observation.get("parameters", {}).items()}
            known = {p.name for p in model.parameters}
            unknown = sorted(set(values) - known)
            if unknown:
                raise ProfileError(f"observation.parameters: unknown parameter(s) "
                                   f"{', '.join(unknown)}; the model has {', '.join(known)}")
            model = model.with_params(**values)
    except ProfileError:
        raise
    except PredictorError as exc:  # an effect that cannot act on this model, a bad value
        raise ProfileError(f"profile {profile.name!r}: {exc}") from None
    return model
