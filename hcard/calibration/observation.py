"""From a predictor's output to what a tribometer measures: the lateral force.

A tribometer records the lateral (friction) force ``F_l`` in N; the predictors output a relative
friction ``mu'``, an electrostatic force ``F_e`` or a lateral force. :func:`lateral_force_model`
wraps a predictor (with or without effects) into one whose output is ``F_l``:

- ``relative_friction``: ``F_l = mu0 Fn mu'`` (the definition ``mu' = mu / mu0``, Eqs. 2.28,
  2.29 and 4.1), with the model's own ``mu0`` (or ``uv_mu0``) when it has one, else a new
  parameter ``friction_coefficient``;
- ``electrostatic_force``: ``F_l = mu (Fn + F_e)`` (Eq. 3.1: the electrostatic attraction adds to
  the normal force), with a new parameter ``friction_coefficient``;
- ``lateral_force``: unchanged.

Every wrapped model also gets ``force_offset`` (N): the tribometer's zero, fitted like any
parameter (a force sensor is never exactly zeroed).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from hcard.calibration import forward_cache
from hcard.physics import Parameter, Predictor, PredictorError, Variable

FRICTION_COEFFICIENT = "friction_coefficient"
FORCE_OFFSET = "force_offset"
OUTPUTS = ("relative_friction", "electrostatic_force", "lateral_force")
"""Predictor outputs a lateral-force model can be built from."""

LATERAL_FORCE = Variable("lateral_force", "N", "lateral (friction) force a tribometer measures")
NORMAL_FORCE = Variable("normal_force", "N", "normal force pressing the finger on the surface", 0.5)

_COEFFICIENT = Parameter(
    FRICTION_COEFFICIENT,
    "",
    0.5,
    (1e-3, 5.0),
    "Eq. 3.1 (F_l = mu (Fn + F_e)); Figs. 2.21, 2.24 (mu0 ~ 0.5)",
    "friction coefficient mu of the finger on the surface",
)
_OFFSET = Parameter(
    FORCE_OFFSET,
    "N",
    0.0,
    (-1.0, 1.0),
    "tribometer zero (not from the thesis)",
    "offset of the lateral force sensor",
)


def _mu0_name(model: Predictor) -> str | None:
    names = [p.name for p in model.parameters]
    for name in ("mu0", "uv_mu0"):
        if name in names:
            return name
    return None


def lateral_force_model(model: Predictor) -> Predictor:
    """``model`` with its output turned into the lateral force in N (module docstring).

    The wrapped predictor's parameters are ``model``'s (same names), then
    ``friction_coefficient`` when needed, then ``force_offset``; its inputs are ``model``'s plus
    ``normal_force`` if absent. The wrapped model is available as the attribute ``inner`` and
    ``with_params`` keeps the wrapping.

    Raises:
        PredictorError: an output that is none of :data:`OUTPUTS`.
    """
    output = model.output.name
    if output not in OUTPUTS:
        raise PredictorError(
            f"model {model.name} outputs {output}, which cannot be compared with a measured "
            f"lateral force (supported outputs: {', '.join(OUTPUTS)})"
        )
    mu0 = _mu0_name(model) if output == "relative_friction" else None
    extra: tuple[Parameter, ...] = (_OFFSET,)
    if output in ("relative_friction", "electrostatic_force") and mu0 is None:
        extra = (_COEFFICIENT, _OFFSET)
    inner_names = tuple(p.name for p in model.parameters)
    wrapped_inputs = model.inputs
    if "normal_force" not in {v.name for v in wrapped_inputs}:
        wrapped_inputs = (*wrapped_inputs, NORMAL_FORCE)
    inner_inputs = tuple(v.name for v in model.inputs)
    prototype = model

    class LateralForce(Predictor):
        kind: ClassVar[str] = prototype.kind
        name: ClassVar[str] = prototype.name
        description: ClassVar[str] = f"lateral force from {prototype.name}"
        parameters: ClassVar[tuple[Parameter, ...]] = (*prototype.parameters, *extra)
        inputs: ClassVar[tuple[Variable, ...]] = tuple(wrapped_inputs)
        output: ClassVar[Variable] = LATERAL_FORCE
        inverse_input: ClassVar[str | None] = None
        wrapped: ClassVar[Predictor] = prototype

        def __init__(self, **params: float) -> None:
            defaults = {name: prototype[name] for name in inner_names}
            super().__init__(**{**defaults, **params})
            self._inner = prototype.with_params(
                **{name: self._values[name] for name in inner_names}
            )

        @property
        def inner(self) -> Predictor:
            """The wrapped model at this instance's parameter values."""
            return self._inner

        def _forward(self, **given: np.ndarray) -> np.ndarray:
            out = forward_cache.forward(
                (type(self), "inner"), self._inner, {k: given[k] for k in inner_inputs})
            fn = given["normal_force"]
            if output == "relative_friction":
                mu = self._values[mu0] if mu0 else self._values[FRICTION_COEFFICIENT]
                force = mu * fn * out
            elif output == "electrostatic_force":
                force = self._values[FRICTION_COEFFICIENT] * (fn + out)
            else:
                force = out
            return force + self._values[FORCE_OFFSET]

    LateralForce.__name__ = LateralForce.__qualname__ = f"LateralForce_{type(model).__name__}"
    return LateralForce()
