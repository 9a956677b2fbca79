"""The limit maths of hcard.physics.device_limits, on their own: Eq. 3.8's capacitance of the
finger's layers, and the voltage the user-current limit allows (I = 2 pi f C V)."""

from __future__ import annotations

import math

import pytest
import scipy.constants

from hcard.physics.device_limits import (
    COUPLED_STIMULATOR_LIMITS,
    LAYER_PARAMETERS,
    binding_voltage_limit,
    layer_capacitance,
)

EPS0 = scipy.constants.epsilon_0
SECTION_3_6_1 = {"area": 1e-4, "sc_thickness": 200e-6, "sc_permittivity": 1560.0,
                 "insulator_thickness": 90e-6, "insulator_permittivity": 3.35}
"""The finger pad of section 3.6.1: 1 cm^2, 200 um of stratum corneum (eps_r 1560) on 90 um of
insulator (eps_r 3.35)."""


def test_layer_capacitance_is_the_two_layers_in_series() -> None:
    # Independently: two parallel-plate capacitors in series, C_i = 33 pF and C_sc = 6.9 nF.
    c_insulator = EPS0 * 3.35 * 1e-4 / 90e-6
    c_skin = EPS0 * 1560.0 * 1e-4 / 200e-6
    series = 1.0 / (1.0 / c_insulator + 1.0 / c_skin)
    assert layer_capacitance(SECTION_3_6_1) == pytest.approx(series, rel=1e-12)
    assert layer_capacitance(SECTION_3_6_1) == pytest.approx(32.8e-12, rel=0.01)


@pytest.mark.parametrize("missing", LAYER_PARAMETERS)
def test_a_model_without_every_layer_parameter_gives_no_capacitance(missing: str) -> None:
    params = {name: value for name, value in SECTION_3_6_1.items() if name != missing}
    assert layer_capacitance({**params, "mu0": 0.5}) is None


@pytest.mark.parametrize(
    ("capacitance", "expected"),
    [
        # 250 uA / (2 pi 440 Hz 100 pF) = 904.29 V, under the amplifier's 2000 V
        (100e-12, (250e-6 / (2 * math.pi * 440.0 * 100e-12), "max_current")),
        # 32.8 pF allows 2757 V: the amplifier's 2000 V binds first
        (32.8e-12, (2000.0, "max_voltage")),
        # no EV load: nothing draws current
        (None, (2000.0, "max_voltage")),
    ],
)
def test_the_binding_voltage_limit(capacitance: float | None,
                                   expected: tuple[float, str]) -> None:
    voltage, name = binding_voltage_limit(COUPLED_STIMULATOR_LIMITS, capacitance)
    assert (voltage, name) == (pytest.approx(expected[0], rel=1e-12), expected[1])
    if name == "max_current":
        assert voltage == pytest.approx(904.29, abs=0.01)
