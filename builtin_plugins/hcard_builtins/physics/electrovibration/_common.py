"""Shared pieces of the electrovibration models: constants, the layered-capacitor force laws
(Eqs. 3.3, 3.12, 3.17, 3.18), parameter definitions and input checks.

SI units throughout: m, m^2, V, N, F, s.
"""

from __future__ import annotations

import numpy as np

from hcard.physics import Parameter, PredictorError
from hcard.quantities import EPSILON_0

THICKNESS_BOUNDS = (1e-9, 1e-2)
"""Allowed layer thicknesses in m (1 nm to 10 mm)."""
PERMITTIVITY_BOUNDS = (1.0, 1e6)
"""Allowed relative permittivities."""
AREA_BOUNDS = (1e-12, 1e-2)
"""Allowed contact areas in m^2 (1 um^2 to 100 cm^2)."""


def area_parameter(default: float, source: str) -> Parameter:
    """The contact area ``A`` of Eq. 3.12 and its relatives, in m^2."""
    return Parameter(
        "area", "m^2", default, AREA_BOUNDS, source, "area of the finger facing the electrode"
    )


def sc_parameters(thickness: float, permittivity: float, source: str) -> tuple[Parameter, ...]:
    """Thickness ``d_sc`` (m) and relative permittivity ``eps_sc`` of the stratum corneum."""
    return (
        Parameter(
            "sc_thickness",
            "m",
            thickness,
            THICKNESS_BOUNDS,
            source,
            "stratum corneum thickness d_sc",
        ),
        Parameter(
            "sc_permittivity",
            "",
            permittivity,
            PERMITTIVITY_BOUNDS,
            source,
            "stratum corneum relative permittivity eps_sc",
        ),
    )


def insulator_parameters(
    thickness: float, permittivity: float, source: str
) -> tuple[Parameter, ...]:
    """Thickness ``d_i`` (m) and relative permittivity ``eps_i`` of the insulator film."""
    return (
        Parameter(
            "insulator_thickness",
            "m",
            thickness,
            THICKNESS_BOUNDS,
            source,
            "insulator thickness d_i",
        ),
        Parameter(
            "insulator_permittivity",
            "",
            permittivity,
            PERMITTIVITY_BOUNDS,
            source,
            "insulator relative permittivity eps_i",
        ),
    )


def air_permittivity_parameter() -> Parameter:
    """Relative permittivity ``eps_a`` of the air layer (Table 3.2: 1.00)."""
    return Parameter(
        "air_permittivity",
        "",
        1.0,
        PERMITTIVITY_BOUNDS,
        "Table 3.2",
        "relative permittivity of the air layer eps_a",
    )


# -- force laws -------------------------------------------------------------------------------
def kaczmarek_coefficient(
    area: np.ndarray | float,
    electrical_thickness: np.ndarray | float,
    mechanical_thickness: np.ndarray | float,
) -> np.ndarray:
    """``F_e / v^2`` in N/V^2 of the co-energy force law (Eqs. 3.12, 3.17, 3.18).

    ``F_e = eps0 A v^2 / (2 sum(d_k / eps_k) sum(d_k))``: ``electrical_thickness`` is
    ``sum(d_k / eps_k)`` (m) and ``mechanical_thickness`` is ``sum(d_k)`` (m) over the
    dielectric layers in series (stratum corneum, air, insulator).
    """
    return np.asarray(
        EPSILON_0 * np.asarray(area) / (2.0 * electrical_thickness * mechanical_thickness)
    )


def strong_troxel_coefficient(
    area: np.ndarray | float, electrical_thickness: np.ndarray | float
) -> np.ndarray:
    """``F_e / v^2`` in N/V^2 of the Strong-Troxel law, Eq. 3.3:
    ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)^2)``."""
    return np.asarray(EPSILON_0 * np.asarray(area) / (2.0 * np.square(electrical_thickness)))


def voltage_for_force(target: np.ndarray, coefficient: np.ndarray) -> np.ndarray:
    """The voltage amplitude (V, >= 0) that gives ``target`` N when ``F = coefficient v^2``."""
    check_finite("target", target)
    if np.any(target < 0):
        raise PredictorError("target: an electrostatic force is attractive, it must be >= 0 N")
    return np.sqrt(target / coefficient)


# -- input checks ---------------------------------------------------------------------------
def check_finite(name: str, value: np.ndarray) -> np.ndarray:
    """``value``, or :class:`PredictorError` naming ``name`` if any element is not finite."""
    if not np.all(np.isfinite(value)):
        raise PredictorError(f"{name}: all values must be finite (no NaN or infinity)")
    return value


def check_non_negative(name: str, value: np.ndarray, unit: str) -> np.ndarray:
    """``value``, or :class:`PredictorError` naming ``name`` if not finite or negative."""
    check_finite(name, value)
    if np.any(value < 0):
        raise PredictorError(f"{name}: must be >= 0 {unit}, got {float(np.min(value)):g}")
    return value
