"""Parallel-plate force with an air layer between finger and insulator, Eq. 3.17 (section 3.5.2).

A finger hovering at ``d_a`` above the insulator, or the air trapped between fingerprint
ridges, adds a third dielectric in series (Fig. 3.7):

``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_a/eps_a + d_i/eps_i)(d_sc + d_a + d_i))``.

With ``d_a = 0`` it is Kaczmarek's Eq. 3.12. Defaults are the hovering experiment of
section 3.5.3 (Table 3.2 layers, A = 30 mm^2 which fits the voltage sweep of Fig. 3.11a):
3.55 mN at 0.25 mm and 2000 V, 1.28 mN at 0.5 mm and 2000 V, 1.78 mN at 0.25 mm and 1414 V.
The flat model falls with distance faster than measured (Fig. 3.11b); :mod:`.geometry`
integrates the same law over a curved, ridged finger (Eq. 3.18).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, Variable

from ._common import (
    air_permittivity_parameter,
    area_parameter,
    check_finite,
    check_non_negative,
    insulator_parameters,
    kaczmarek_coefficient,
    sc_parameters,
    voltage_for_force,
)
from .static import FORCE, VOLTAGE

AIR_GAP = Variable("air_gap", "m", "air layer thickness d_a between finger and insulator", 0.0)


class AirLayer(Predictor):
    """Electrostatic force across stratum corneum, air and insulator in series, Eq. 3.17.

    Inputs: ``voltage`` (V) and ``air_gap`` ``d_a`` (m, >= 0, default 0 = contact).
    Output: ``electrostatic_force`` in N. Inverse: the voltage amplitude for a target force
    at the given gap (``F ~ v^2``).
    """

    name: ClassVar[str] = "ev-air-layer"
    calibrated: ClassVar[tuple[str, ...]] = ("area",)
    description: ClassVar[str] = "Electrovibration force with an air layer in series (Eq. 3.17)"
    parameters: ClassVar[tuple[Parameter, ...]] = (
        area_parameter(30e-6, "Fig. 3.11a (best analytical fit, A = 30 mm^2)"),
        *sc_parameters(200e-6, 1650.0, "Table 3.2"),
        *insulator_parameters(90e-6, 3.35, "Table 3.2"),
        air_permittivity_parameter(),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (VOLTAGE, AIR_GAP)
    output: ClassVar[Variable] = FORCE
    inverse_input: ClassVar[str | None] = "voltage"

    def coefficient(self, air_gap: np.ndarray | float) -> np.ndarray:
        """``F_e / v^2`` in N/V^2 at the air gap ``d_a`` (m), Eq. 3.17."""
        gap = check_non_negative("air_gap", np.asarray(air_gap, dtype=np.float64), "m")
        electrical = (
            self["sc_thickness"] / self["sc_permittivity"]
            + gap / self["air_permittivity"]
            + self["insulator_thickness"] / self["insulator_permittivity"]
        )
        mechanical = self["sc_thickness"] + gap + self["insulator_thickness"]
        return kaczmarek_coefficient(self["area"], electrical, mechanical)

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        voltage = check_finite("voltage", inputs["voltage"])
        return self.coefficient(inputs["air_gap"]) * np.square(voltage)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        return voltage_for_force(target, self.coefficient(inputs["air_gap"]))
