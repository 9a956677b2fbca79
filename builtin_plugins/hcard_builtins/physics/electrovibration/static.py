"""Static parallel-plate models of the electrostatic force on a finger (thesis section 3.2).

Both treat the finger on the electrode as a capacitor with two dielectrics in series, the
stratum corneum (``d_sc``, ``eps_sc``) and the insulator (``d_i``, ``eps_i``), of area ``A``,
driven by the voltage ``v``:

- :class:`StrongTroxel`, Eq. 3.3: ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)^2)``. It does
  not reduce to the single-dielectric Eq. 3.2 (it differs by ``eps``, Eq. 3.4) and overestimates
  measured forces by up to three orders of magnitude (Fig. 3.3: 6-600 N).
- :class:`Kaczmarek`, Eq. 3.12, from the co-energy derivative (Eqs. 3.5-3.11):
  ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)(d_sc + d_i))`` (Fig. 3.3: 0.04-0.36 N, the
  order measured by Meyer et al.). The thesis keeps this one (section 3.3.3).

Both forces go as ``v^2``; the inverse is the voltage amplitude for a target force.
The forces are instantaneous: with a finger in contact the charge leaks through the stratum
corneum and only the high-passed part of ``v`` acts (Eq. 3.22, :mod:`.leakage`).
"""

from __future__ import annotations

from abc import ABCMeta, abstractmethod
from typing import Any, ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, Variable

from ._common import (
    area_parameter,
    check_finite,
    insulator_parameters,
    kaczmarek_coefficient,
    sc_parameters,
    strong_troxel_coefficient,
    voltage_for_force,
)

VOLTAGE = Variable("voltage", "V", "voltage across finger and electrode (instantaneous or peak)")
FORCE = Variable("electrostatic_force", "N", "electrostatic attraction normal to the surface")

_CONTACT_PARAMETERS: tuple[Parameter, ...] = (
    area_parameter(1e-4, "Fig. 3.3 (A = 100 mm^2); section 3.6.1 (A = 1 cm^2)"),
    *sc_parameters(200e-6, 1560.0, "Fig. 3.3, Table 3.2 (d_sc); section 3.6.1 [88] (eps_sc)"),
    *insulator_parameters(90e-6, 3.35, "sections 3.4.1, 3.6.1 (plastic film)"),
)


class _LayeredForce(Predictor, metaclass=ABCMeta):
    """Common part: a force ``coefficient * v^2`` with a closed-form voltage inverse."""

    inputs: ClassVar[tuple[Variable, ...]] = (VOLTAGE,)
    output: ClassVar[Variable] = FORCE
    inverse_input: ClassVar[str | None] = "voltage"
    parameters: ClassVar[tuple[Parameter, ...]] = _CONTACT_PARAMETERS

    @property
    def electrical_thickness(self) -> float:
        """``d_sc/eps_sc + d_i/eps_i`` in m (the denominator of Eq. 3.8)."""
        return (
            self["sc_thickness"] / self["sc_permittivity"]
            + self["insulator_thickness"] / self["insulator_permittivity"]
        )

    @property
    @abstractmethod
    def coefficient(self) -> float:
        """``F_e / v^2`` in N/V^2 (defined by each force law)."""

    @property
    def _coefficient(self) -> float:
        """:attr:`coefficient`, computed once per set of parameter values (N/V^2)."""
        cached = self.__dict__.get("_coefficient_cache")
        if cached is not None and cached[0] is self._values:
            return cached[1]
        value = self.coefficient
        self.__dict__["_coefficient_cache"] = (self._values, value)
        return value

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        voltage = check_finite("voltage", inputs["voltage"])
        return self._coefficient * np.square(voltage)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        return voltage_for_force(target, np.asarray(self._coefficient))

    def forward_trusted(self, **inputs: Any) -> np.ndarray:
        """:meth:`forward` for a finite ``voltage`` (V) already checked: ``coefficient v^2``
        (N) without the input checks."""
        return self._coefficient * np.square(np.asarray(inputs["voltage"], dtype=np.float64))

    def inverse_trusted(self, target: Any, **inputs: Any) -> np.ndarray:
        """:meth:`inverse` for a finite force ``target`` >= 0 (N) already checked: the voltage
        amplitude ``sqrt(F / coefficient)`` (V) without the input checks."""
        return np.sqrt(np.asarray(target, dtype=np.float64) / np.asarray(self._coefficient))


class StrongTroxel(_LayeredForce):
    """Strong and Troxel's electrostatic force, Eq. 3.3 (kept for comparison: it overestimates).

    ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)^2)`` in N for ``v`` in V. For the Fig. 3.3
    case (A = 100 mm^2, d_sc = 0.2 mm, d_i = 1 um, v = 140 V) it gives 6.0 N at
    (eps_sc, eps_i) = (1e3, 1) and 603 N at (1e4, 10).
    """

    name: ClassVar[str] = "ev-strong-troxel"
    calibrated: ClassVar[tuple[str, ...]] = ("area",)
    description: ClassVar[str] = (
        "Electrovibration force, Strong-Troxel double-dielectric law (Eq. 3.3); overestimates"
    )

    @property
    def coefficient(self) -> float:
        """``F_e / v^2`` in N/V^2 (Eq. 3.3)."""
        return float(strong_troxel_coefficient(self["area"], self.electrical_thickness))


class Kaczmarek(_LayeredForce):
    """Kaczmarek's electrostatic force, Eq. 3.12 (derived in Eqs. 3.5-3.11).

    ``F_e = eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)(d_sc + d_i))`` in N for ``v`` in V. For the
    Fig. 3.3 case it gives 0.0360 N at (eps_sc, eps_i) = (1e3, 1) and 0.360 N at (1e4, 10).
    Defaults are the contact situation of section 3.6.1 (A = 1 cm^2, d_sc = 200 um,
    eps_sc = 1560, a 90 um film of eps_i = 3.35).
    """

    name: ClassVar[str] = "ev-kaczmarek"
    calibrated: ClassVar[tuple[str, ...]] = ("area",)
    description: ClassVar[str] = (
        "Electrovibration force, Kaczmarek double-dielectric law (Eq. 3.12)"
    )

    @property
    def coefficient(self) -> float:
        """``F_e / v^2`` in N/V^2 (Eq. 3.12)."""
        return float(
            kaczmarek_coefficient(
                self["area"],
                self.electrical_thickness,
                self["sc_thickness"] + self["insulator_thickness"],
            )
        )
