"""Section 3.6.3: the EV force on a finger in contact under the trapezium 0-1000 V (Fig. 3.15).

The thesis: "The absolute value of the measured force varies from 2 to 5 mN whereas the model,
for a thickness of the stratum corneum about 0.2 mm, predicts 2.5 mN". What the model is:

- the layers are those stated in section 3.6.1 (A = 1 cm^2, d_sc = 200 um, eps_sc = 1560,
  d_i = 90 um, eps_i = 3.35; C_i = 32 pF, C_sc = 6.9 nF), with which Eq. 3.23 at a steady
  v_e = 1000 V gives 56.6 mN, consistent with section 3.7 (10-20 % more friction at 0.5 N and
  v_e = 1000 V, i.e. 50-100 mN). No static reading of these layers gives 2.5 mN: it would need
  A = 4.4 mm^2, and then C_i = 1.5 pF, not the 32 pF the thesis prints;
- so the 2.5 mN is the transient of the leak (Eqs. 3.22-3.23): on the rising edge of the
  trapezium ``v_e`` follows ``r tau_d (1 - exp(-t / tau_d))`` (a ramp of slope ``r`` through the
  high pass) and on the plateau it decays, the "discharge phenomenon" of Fig. 3.15. The rise
  time of the trapezium is not printed; 2.5 mN is the peak for a 1000 V rise in 36 ms with
  tau_d = 7.7 ms, and the measured 2-5 mN spread corresponds to rises of 25-41 ms.

The defaults are therefore kept; these tests check the model against the thesis values and the
ramp response written out here (independent of :meth:`ChargeLeakage.simulate`'s filter).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from hcard_builtins.physics.electrovibration import ChargeLeakage, Kaczmarek

EPS0 = 8.8542e-12
AREA, D_SC, EPS_SC, D_I, EPS_I = 1e-4, 200e-6, 1560.0, 90e-6, 3.35  # section 3.6.1
TAU_D = 7.7e-3  # section 3.6.3, slow drive
K = EPS0 * AREA / (2 * (D_SC / EPS_SC + D_I / EPS_I) * (D_SC + D_I))  # Eq. 3.23, N/V^2


def ramp_response(t: np.ndarray, rise: float, top: float, start: float) -> np.ndarray:
    """Eq. 3.22 for a trapezium edge 0 -> ``top`` V over ``rise`` s from ``start`` s, in closed
    form: ``r tau (1 - exp(-s/tau))`` on the ramp, then an exponential decay on the plateau."""
    rate = top / rise
    s = np.clip(t - start, 0.0, None)
    on_ramp = rate * TAU_D * -np.expm1(-np.minimum(s, rise) / TAU_D)
    return np.where(s <= rise, on_ramp, on_ramp * np.exp(-(s - rise) / TAU_D))


def rise_for(force: float) -> float:
    """The 1000 V rise time, s, whose peak force through Eqs. 3.22-3.23 is ``force`` N."""
    peak_voltage = math.sqrt(force / K)
    return brentq(lambda T: 1000 / T * TAU_D * -math.expm1(-T / TAU_D) - peak_voltage, 1e-4, 10)


def test_static_defaults_are_the_section_3_6_1_layers():
    model = ChargeLeakage()
    assert Kaczmarek().params == pytest.approx(
        {"area": AREA, "sc_thickness": D_SC, "sc_permittivity": EPS_SC,
         "insulator_thickness": D_I, "insulator_permittivity": EPS_I}
    )
    static = float(Kaczmarek().forward(voltage=1000.0))
    assert static == pytest.approx(K * 1e6, rel=1e-4)
    assert static == pytest.approx(0.0566, abs=1e-4)
    # Section 3.7: 10-20 % more friction at ~0.5 N for v_e = 1000 V (Eq. 3.23).
    assert 0.10 <= static / 0.5 <= 0.20
    # 2.5 mN at a steady 1000 V would need an area of 4.4 mm^2; the thesis' C_i = 32 pF (with
    # eps_i = 3.35, d_i = 90 um) fixes the area to ~1 cm^2 instead.
    area_for_2_5_mN = 2.5e-3 / static * AREA
    assert area_for_2_5_mN == pytest.approx(4.4e-6, rel=0.01)
    area_from_c_i = 32e-12 * D_I / (EPS0 * EPS_I)
    assert area_from_c_i == pytest.approx(AREA, rel=0.035)
    assert EPS0 * EPS_I * area_for_2_5_mN / D_I < 2e-12  # 1.5 pF, not 32 pF
    assert model.insulator_capacitance == pytest.approx(32e-12, rel=0.035)


@pytest.mark.parametrize("measured", [2e-3, 2.5e-3, 5e-3])
def test_the_trapezium_edge_gives_the_section_3_6_3_forces(measured):
    rise = rise_for(measured)
    model = ChargeLeakage()
    fs = 50_000.0
    t = np.arange(0.0, rise + 0.1, 1 / fs)
    start = 0.005
    v = 1000.0 * np.clip((t - start) / rise, 0.0, 1.0)
    result = model.simulate(t, v, frequency=0.0)  # slow drive: tau_d = 7.7 ms
    assert result.tau_d == TAU_D
    expected = ramp_response(t, rise, 1000.0, start)
    np.testing.assert_allclose(result.effective_voltage, expected, atol=1e-3 * expected.max())
    peak = float(result.force.max())
    assert peak == pytest.approx(measured, rel=2e-3)
    # The peak is at the top of the edge; on the plateau the force decays with tau_d / 2.
    assert t[np.argmax(result.force)] == pytest.approx(start + rise, abs=2 / fs)
    plateau = (t > start + rise + 0.005) & (t < start + rise + 0.03)
    slope, _ = np.polyfit(t[plateau], np.log(result.force[plateau]), 1)
    assert -1 / slope == pytest.approx(TAU_D / 2, rel=1e-3)
    assert result.force[-1] < 1e-4 * peak


def test_the_measured_spread_is_a_spread_of_rise_times():
    # 2.5 mN: a 36 ms edge; the measured 2-5 mN: edges of 41 to 25 ms (the thesis gives no
    # rise time, so this is what its 2.5 mN implies, not a check of it).
    assert rise_for(2.5e-3) == pytest.approx(0.0363, abs=5e-4)
    assert rise_for(2e-3) == pytest.approx(0.0407, abs=5e-4)
    assert rise_for(5e-3) == pytest.approx(0.0249, abs=5e-4)
    # Giraud et al. measured tau_d = 6 ms for a square wave; the model's 7.7 ms is within 30 %.
    assert ChargeLeakage()["tau_d"] == pytest.approx(6e-3, rel=0.3)
