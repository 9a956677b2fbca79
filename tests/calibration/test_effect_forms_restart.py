"""Filters with state at lifts: charge leakage restarts at every touch-down
(the skin arrives uncharged); the actuator's envelope runs through lifts (the plate vibrates
with or without a finger).

The recordings are written here from the continuous-time step responses of a first-order
high-pass (Eq. 3.22) and low-pass, summed over the input's steps, and Kaczmarek's force law
(Eq. 3.12) written out: a code path other than the effects' recursive filters.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.constants

from hcard.calibration.fit import fit_predictor
from hcard.calibration.time_series import high_pass, touchdowns
from hcard.physics import PredictorError
from hcard.physics.effects import augment
from hcard_builtins.effects import ActuatorBandwidth, ChargeLeakage
from hcard_builtins.physics.electrovibration import Kaczmarek

EPS0 = scipy.constants.epsilon_0
AREA = 1.2e-4  # m^2
SC_D, SC_EPS, INS_D, INS_EPS = 200e-6, 1560.0, 90e-6, 3.35  # section 3.6.1
TAU_D = 20e-3  # s
RATE_HZ = 1000.0
DT = 1.0 / RATE_HZ


def kaczmarek_force(voltage: np.ndarray, area: float = AREA) -> np.ndarray:
    """Eq. 3.12: ``eps0 A v^2 / (2 (d_sc/eps_sc + d_i/eps_i)(d_sc + d_i))``, N."""
    return EPS0 * area * voltage**2 / (2 * (SC_D / SC_EPS + INS_D / INS_EPS) * (SC_D + INS_D))


def strokes_with_lifts(seed: int) -> dict[str, np.ndarray]:
    """8 s at 1 kHz: contacts of 0.25-0.45 s and lifts of 0.1-0.3 s; the drive (a square wave
    of random levels, 40-90 ms per level, 100-500 V) stays on through the lifts."""
    rng = np.random.default_rng(seed)
    n = int(8 * RATE_HZ)
    contact = np.zeros(n)
    k = int(rng.integers(50, 150))
    while k < n:
        on = int(rng.integers(250, 450))
        contact[k : k + on] = 1.0
        k += on + int(rng.integers(100, 300))
    levels = []
    while sum(len(x) for x in levels) < n:
        hold = int(rng.integers(40, 90))
        levels.append(np.full(hold, rng.uniform(100.0, 500.0) * rng.choice([-1.0, 1.0])))
    voltage = np.concatenate(levels)[:n]
    return {"time": np.arange(n) * DT, "voltage": voltage, "contact": contact}


def leaked_voltage(data: dict[str, np.ndarray], tau: float, restart: bool) -> np.ndarray:
    """The effective voltage behind the leaking skin, from step responses: every change of the
    input (the voltage, or contact beginning) first seen at sample ``j`` happened half a
    sample earlier, and contributes ``dv exp(-(t - t_j + dt/2) / tau)``. With ``restart`` each
    contact starts uncharged (the voltage at touch-down is a step from 0); without, the
    recording's first sample is the only start."""
    t, v, on = data["time"], data["voltage"], data["contact"] > 0.5
    out = np.zeros_like(v)
    n = v.size
    start = 0
    for k in range(n):
        if restart and on[k] and (k == 0 or not on[k - 1]):
            start = k
        steps = [(start, v[start])] + [
            (j, v[j] - v[j - 1]) for j in range(start + 1, k + 1) if v[j] != v[j - 1]
        ]
        out[k] = sum(dv * np.exp(-(t[k] - t[j] + DT / 2) / tau) for j, dv in steps)
    return out


def held_out(n: int) -> np.ndarray:
    """Every fourth 0.5 s block."""
    return (np.arange(n) // 500) % 4 == 1


@pytest.mark.parametrize("noise_n", [5e-5, 2e-4])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_charge_leakage_restarted_at_touch_down_reaches_the_noise_floor(
    seed: int, noise_n: float
) -> None:
    data = strokes_with_lifts(seed)
    n = data["time"].size
    clean = kaczmarek_force(leaked_voltage(data, TAU_D, restart=True))
    observed = clean + np.random.default_rng(100 + seed).normal(0.0, noise_n, n)
    on = data["contact"] > 0.5
    test = on & held_out(n)
    train = on & ~held_out(n)
    model = augment(Kaczmarek(), [ChargeLeakage()])
    free = ("area", "charge-leakage.time_constant")
    restarted = fit_predictor(model, data, observed, free=free, train=train, test=test,
                              dynamic=True)
    through = fit_predictor(
        model, {k: v for k, v in data.items() if k != "contact"}, observed, free=free,
        train=train, test=test, dynamic=True,
    )
    assert restarted.test_rmse == pytest.approx(noise_n, rel=0.10)
    assert restarted.params["area"] == pytest.approx(AREA, rel=0.01)
    assert restarted.params["charge-leakage.time_constant"] == pytest.approx(TAU_D, rel=0.03)
    tau_sigma = restarted.uncertainties["charge-leakage.time_constant"]
    assert abs(restarted.params["charge-leakage.time_constant"] - TAU_D) < 4 * tau_sigma
    # A filter run straight through the lifts is left far above the noise.
    assert through.test_rmse > 1.5 * noise_n


def test_high_pass_restarts_from_rest_at_each_touch_down() -> None:
    """Deterministic: the recursive filter with restarts equals the sum of step responses."""
    data = strokes_with_lifts(7)
    restart = touchdowns(data["contact"], data["time"])
    assert restart is not None and restart.sum() == np.count_nonzero(
        np.diff(data["contact"], prepend=0.0) == 1.0
    )
    got = high_pass(data["voltage"], data["time"], TAU_D, restart=restart)
    on = data["contact"] > 0.5
    expected = leaked_voltage(data, TAU_D, restart=True)
    assert np.allclose(got[on], expected[on], rtol=1e-9, atol=1e-9)
    without = high_pass(data["voltage"], data["time"], TAU_D)
    assert np.allclose(without, leaked_voltage(data, TAU_D, restart=False), rtol=1e-9,
                       atol=1e-9)
    assert np.max(np.abs(without[on] - expected[on])) > 50.0  # V: the restart matters


def test_touchdowns_mark_contact_onsets_and_new_recordings() -> None:
    contact = np.array([0, 1, 1, 0, 0, 1, 1, 1, 1, 0], dtype=float)
    t = np.array([0, 1, 2, 3, 4, 5, 6, 0.5, 1.5, 2.5])  # a second recording from sample 7
    assert touchdowns(contact, t).tolist() == [
        False, True, False, False, False, True, False, True, False, False
    ]
    assert touchdowns(1.0) is None
    with pytest.raises(PredictorError, match="contact"):
        touchdowns(np.array([1.0, np.nan]))


def test_actuator_envelope_runs_through_lifts() -> None:
    """The plate's amplitude at touch-down is the command low-passed through the lift: the
    effect ignores contact and equals ``sum dA (1 - exp(-(t - t_j) / tau))`` over the command's
    steps (step offset 0: a step at the sample instant)."""
    data = strokes_with_lifts(3)
    n = data["time"].size
    rng = np.random.default_rng(3)
    command = np.repeat(rng.uniform(0.0, 3e-6, n // 60 + 1), 60)[:n]
    tau = 8e-3
    effect = ActuatorBandwidth()
    assert "contact" not in {v.name for v in effect.inputs}
    got = effect.transform_inputs(
        {"amplitude": command, "time": data["time"], "contact": data["contact"]},
        {"time_constant": tau, "step_offset": 0.0},
    )["amplitude"]
    t = data["time"]
    changes = [(0, command[0])] + [
        (j, command[j] - command[j - 1]) for j in range(1, n) if command[j] != command[j - 1]
    ]
    expected = np.zeros(n)
    for j, da in changes:
        expected[j:] += da * -np.expm1(-(t[j:] - t[j]) / tau)
    assert np.allclose(got, expected, rtol=0, atol=1e-15)
