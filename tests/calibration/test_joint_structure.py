"""The residual against the joint cells of an effect's signature regressors
(hcard.calibration.residuals.joint_structure), against values worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from hcard.calibration.residuals import analyse_residuals, joint_structure

N = 40_000


def load_and_voltage(seed: int) -> tuple[np.ndarray, np.ndarray, np.random.Generator]:
    """Balanced loads 1-4 N and a voltage on for half the samples, independent."""
    rng = np.random.default_rng(seed)
    fn = np.repeat([1.0, 2.0, 3.0, 4.0], N // 4)
    voltage = np.tile([0.0, 1000.0], N // 2)
    order = rng.permutation(N)
    return fn[order], voltage[order], rng


@pytest.mark.parametrize("seed", [1, 2])
def test_a_structure_in_the_combination_shows_jointly(seed: int) -> None:
    # residual d (Fn - 2.5) where the voltage is on, 0 where it is off, plus noise sigma:
    # cell means 0 (off) and -1.5d..1.5d (on), so the between-cell variance is
    # 0.5 d^2 (2.25 + 0.25 + 0.25 + 2.25) / 4 = 0.625 d^2; on the load alone the bins average
    # the on and off halves, 0.3125 d^2; on the voltage alone, 0.
    d, sigma = 0.1, 0.1
    fn, voltage, rng = load_and_voltage(seed)
    residual = np.where(voltage > 0, d * (fn - 2.5), 0.0) + rng.normal(0.0, sigma, N)
    joint = joint_structure(residual, {"normal_force": fn, "voltage": voltage}, n_eff=N)
    assert joint.cells == 8 and joint.p_value < 1e-12
    assert joint.eta2 == pytest.approx(0.625 * d**2 / (0.625 * d**2 + sigma**2), abs=0.01)
    one = analyse_residuals(residual, {"normal_force": fn, "voltage": voltage},
                            time_ordered=False)
    assert one.regressors["normal_force"].eta2 == pytest.approx(
        0.3125 * d**2 / (0.3125 * d**2 + 0.3125 * d**2 + sigma**2), abs=0.01)
    assert one.regressors["voltage"].eta2 < 0.001
    # chance correction: 7 degrees of freedom over N samples
    assert joint.adjusted_eta2 == pytest.approx(
        (joint.eta2 - 7 / N) / (1 - 7 / N), rel=1e-9)


def test_noise_alone_adjusts_to_nothing_even_in_many_cells() -> None:
    # 40 cells (10 quantile bins x 4 voltages) of pure independent noise: eta2 about 39 / N
    # by chance, adjusted about 0
    rng = np.random.default_rng(3)
    fn = rng.uniform(0.1, 1.5, N)
    voltage = rng.choice([0.0, 1200.0, 1900.0, 2000.0], N)
    residual = rng.normal(0.0, 1.0, N)
    joint = joint_structure(residual, {"normal_force": fn, "voltage": voltage}, n_eff=N)
    assert joint.cells == 40
    assert joint.eta2 == pytest.approx(39 / N, rel=0.5)
    assert joint.adjusted_eta2 < 5e-4
    assert joint.p_value > 1e-3
