"""Input checks shared by the ultrasonic predictors: finite, signed as required, broadcastable."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hcard.physics import PredictorError
from hcard.quantities import SI_UNITS

UNITS = {
    **SI_UNITS,
    "normal_stiffness": "N/m",
    "lateral_stiffness": "N/m",
    "mu0": "",
    "lateral_recovery_speed": "m/s",
}
"""SI unit of each predictor input, for the error messages."""


def check_inputs(
    model: str,
    arrays: Mapping[str, object],
    *,
    positive: tuple[str, ...] = (),
) -> dict[str, np.ndarray]:
    """The arrays as float64, broadcast to one shape, after checking them.

    Every array must be finite and >= 0; those named in ``positive`` must be > 0. A failure
    raises :class:`PredictorError` naming the model and the input, e.g.
    ``"spring-slider: input amplitude must be >= 0 m, got -1e-06"``.
    """
    checked: dict[str, np.ndarray] = {}
    for name, value in arrays.items():
        array = np.asarray(value, dtype=np.float64)
        unit = UNITS.get(name, "")
        bad = ~np.isfinite(array)
        if bad.any():
            raise PredictorError(
                f"{model}: input {name} must be finite, got {array[bad].flat[0]}"
            )
        strict = name in positive
        bad = array <= 0 if strict else array < 0
        if bad.any():
            relation = "> 0" if strict else ">= 0"
            raise PredictorError(
                f"{model}: input {name} must be {relation}{' ' + unit if unit else ''}, "
                f"got {array[bad].flat[0]:g}"
            )
        checked[name] = array
    try:
        shaped = np.broadcast_arrays(*checked.values())
    except ValueError:
        shapes = ", ".join(f"{name} {array.shape}" for name, array in checked.items())
        raise PredictorError(f"{model}: inputs do not broadcast together: {shapes}") from None
    return {name: np.array(array) for name, array in zip(checked, shaped, strict=True)}
