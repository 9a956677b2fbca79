"""A predictor evaluated at parameter values that differ from sample to sample.

An effect may change a base model's parameters per sample (:meth:`hcard.physics.effects.Effect.
transform_params`: the dry friction coefficient ``mu0`` drifting with occlusion, for example);
:func:`forward_per_sample` evaluates the base at such values, fast for the parameters its
forward map broadcasts (:func:`samplewise_parameters`) and once per distinct value otherwise.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping
from typing import Any, TypeAlias

import numpy as np

from hcard.physics.predictor import Predictor, PredictorError

ParameterValue: TypeAlias = float | np.ndarray
"""A base parameter's value as :meth:`~hcard.physics.effects.Effect.transform_params` passes
it: one number, or an array aligned with the samples (a value per sample)."""

SAMPLEWISE_PARAMETERS: dict[str, frozenset[str]] = {
    "dimensionless-group": frozenset(
        {"mu0", "poisson_ratio", "psi_star", "psi_star_normal_force_slope"}
    ),
    "spring-slider": frozenset(
        {"normal_stiffness", "lateral_stiffness", "mu0", "lateral_recovery_speed"}
    ),
    "ev-air-layer": frozenset(
        {
            "area",
            "sc_thickness",
            "sc_permittivity",
            "insulator_thickness",
            "insulator_permittivity",
            "air_permittivity",
        }
    ),
    "finger-friction": frozenset(
        {
            "friction_initial",
            "friction_occluded",
            "occlusion_time",
            "load_index",
            "peak_speed",
            "speed_sensitivity",
        }
    ),
}
"""Built-in predictors (by name) whose forward map reads these parameters at call time and
broadcasts them with the inputs, so that a value per sample gives each sample's output exactly
(tests/calibration/test_effect_forms_params.py checks each against one evaluation per sample).
A vendor predictor declares the same with a class attribute ``samplewise_parameters``. Any other
parameter given per sample is evaluated once per distinct value (:func:`forward_per_sample`):
exact, and slower by the number of distinct values."""


def samplewise_parameters(base: Predictor) -> frozenset[str]:
    """The parameters of ``base`` its forward map broadcasts per sample: the class attribute
    ``samplewise_parameters`` when it sets one, else :data:`SAMPLEWISE_PARAMETERS` by name."""
    declared = getattr(type(base), "samplewise_parameters", None)
    if declared is not None:
        return frozenset(declared)
    return SAMPLEWISE_PARAMETERS.get(base.name, frozenset())


def _checked_values(
    base: Predictor, changed: Mapping[str, ParameterValue]
) -> dict[str, np.ndarray]:
    """The changed parameters as float arrays, or :class:`PredictorError` naming the parameter
    when a value is not finite or below the parameter's lower bound (its physical domain, e.g.
    a positive ``mu0``; the upper bound only limits a fit's search, and a drift may pass it)."""
    lows = {p.name: p.bounds[0] for p in base.parameters}
    out = {}
    for name, value in changed.items():
        array = np.asarray(value, dtype=np.float64)
        bad = ~np.isfinite(array)
        if bad.any():
            raise PredictorError(
                f"{base.name}: parameter {name} per sample must be finite, got "
                f"{array[bad].flat[0]}"
            )
        if np.any(array < lows[name]):
            raise PredictorError(
                f"{base.name}: parameter {name} per sample must be >= {lows[name]:g}, got "
                f"{float(np.min(array)):g}"
            )
        out[name] = array
    return out


def forward_per_sample(
    base: Predictor, params: Mapping[str, ParameterValue], inputs: Mapping[str, Any]
) -> np.ndarray:
    """``base``'s output at parameter values that may differ from sample to sample.

    ``params`` maps base parameter names to one number or an array aligned with the samples
    (broadcast with the inputs); names not given keep ``base``'s values. Where every value is
    ``base``'s own, this is ``base.forward(**inputs)`` exactly; where every changed value is one
    number, the base at those values (bounds checked). Parameters the base broadcasts
    (:func:`samplewise_parameters`) are handed to its forward map as arrays; otherwise the base
    is evaluated once per distinct combination of the per-sample values (exact, slower).

    Per-sample values are checked for being finite and above the parameters' lower bounds, not
    against the upper bounds (a drifting ``mu0`` may leave the range a fit searches).

    Raises:
        PredictorError: an unknown parameter, a non-finite value or one below its lower bound,
            or values whose shape does not broadcast with the inputs.
    """
    known = {p.name for p in base.parameters}
    unknown = sorted(set(params) - known)
    if unknown:
        raise PredictorError(f"{base.name}: unknown parameter(s) {', '.join(unknown)}")
    changed = {
        name: value
        for name, value in params.items()
        if not (np.ndim(value) == 0 and float(value) == base[name])
    }
    if not changed:
        return base.forward(**inputs)
    if all(np.ndim(value) == 0 for value in changed.values()):
        return base.with_params(**{k: float(v) for k, v in changed.items()}).forward(**inputs)
    arrays = _checked_values(base, changed)
    if set(arrays) <= samplewise_parameters(base):
        view = copy.copy(base)
        # Samplewise parameters: arrays where the attribute is typed for floats.
        view._values = {**base.params, **arrays}  # type: ignore[dict-item]
        return view.forward(**inputs)
    return _forward_by_distinct_values(base, arrays, inputs)


def _forward_by_distinct_values(
    base: Predictor, arrays: Mapping[str, np.ndarray], inputs: Mapping[str, Any]
) -> np.ndarray:
    """:func:`forward_per_sample` for a base that does not broadcast its parameters: one
    evaluation per distinct combination of parameter values, on the samples that have it."""
    given = {k: np.asarray(v, dtype=np.float64) for k, v in inputs.items()}
    names = list(arrays)
    try:
        shaped = np.broadcast_arrays(*arrays.values(), *given.values())
    except ValueError:
        shapes = ", ".join(f"{k} {np.shape(v)}" for k, v in {**arrays, **given}.items())
        raise PredictorError(
            f"{base.name}: parameters per sample do not broadcast with the inputs: {shapes}"
        ) from None
    values = np.stack([a.ravel() for a in shaped[: len(names)]], axis=1)
    flat_inputs = {k: a.ravel() for k, a in zip(given, shaped[len(names) :], strict=True)}
    combos, which = np.unique(values, axis=0, return_inverse=True)
    which = which.ravel()
    out = np.empty(values.shape[0])
    for index, combo in enumerate(combos):
        rows = which == index
        model = base.with_params(**{n: float(v) for n, v in zip(names, combo, strict=True)})
        out[rows] = model.forward(**{k: v[rows] for k, v in flat_inputs.items()})
    return out.reshape(shaped[0].shape)
