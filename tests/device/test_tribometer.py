"""Synthetic tribometer recordings with hidden effects (hcard_device.sim.tribometer)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from hcard.calibration.measurement import read_measurement, write_measurement
from hcard.calibration.splits import stroke_ids
from hcard_builtins.physics.electrovibration import AirLayer, Kaczmarek
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.tribometer import Protocol, available_effects, synthesize

MU0 = 0.5
CLEAN = {"lateral_noise_n": 0.0, "normal_noise_n": 0.0}
SHORT = Protocol(duration_s=10.0)


def friction(m):
    """The recorded lateral force with the direction of motion taken out (rule MF3: signed)."""
    return m.lateral_force * np.where(m.speed < 0, -1.0, 1.0)


def _uv_model(device: str = "uv") -> tuple[DimensionlessGroup, float]:
    config = DeviceConfig.evita() if device == "uv" else DeviceConfig.coupled()
    uv = DimensionlessGroup(mu0=config.mu0, psi_star=config.psi_star)
    return uv, config.limits.plate_frequency


def _contact(m) -> np.ndarray:
    return m.normal_force >= 0.01


def _t63(y: np.ndarray, target: float) -> float:
    """Time (samples, linear interpolation) for ``y`` to cover 1 - 1/e of its way from
    ``y[0]`` to ``target``; NaN if it does not get there."""
    frac = (y - y[0]) / (target - y[0])
    level = 1.0 - math.exp(-1.0)
    reached = np.flatnonzero(frac >= level)
    if reached.size == 0:
        return math.nan
    j = int(reached[0])
    return j - 1 + (level - frac[j - 1]) / (frac[j] - frac[j - 1])


# -- clean physics ----------------------------------------------------------------------------
def test_clean_uv_is_coulomb_times_dimensionless_group():
    (m,) = synthesize("uv", **CLEAN)
    assert m.amplitude is not None and m.voltage is None and m.stroke is None
    dg, frequency = _uv_model()
    on = _contact(m)
    expected = (
        MU0
        * m.normal_force
        * dg.forward(
            amplitude=m.amplitude,
            frequency=frequency,
            speed=np.abs(m.speed),
            normal_force=m.normal_force,
        )
    )
    np.testing.assert_allclose(friction(m)[on], expected[on], rtol=1e-12, atol=0)
    assert np.all(m.lateral_force[~on] == 0.0)
    assert 0.05 < on.mean() < 0.95
    assert np.all(m.y == m.y[0])
    assert m.conditions["plate_frequency_hz"] == 60750.0


def test_clean_coupled_and_ev_follow_eq_4_1():
    (m,) = synthesize("coupled", **CLEAN)
    dg, frequency = _uv_model("coupled")
    kacz = Kaczmarek()
    on = _contact(m)
    uv = dg.forward(
        amplitude=m.amplitude,
        frequency=frequency,
        speed=np.abs(m.speed),
        normal_force=m.normal_force,
    )
    expected = MU0 * uv * (m.normal_force + kacz.forward(voltage=m.voltage))
    np.testing.assert_allclose(friction(m)[on], expected[on], rtol=1e-12)
    (e,) = synthesize("ev", **CLEAN)
    assert e.amplitude is None and e.voltage is not None
    assert e.conditions["plate_frequency_hz"] is None
    on = _contact(e)
    excess = friction(e)[on] / MU0 - e.normal_force[on]
    np.testing.assert_allclose(excess, kacz.forward(voltage=e.voltage[on]), rtol=1e-9)
    assert np.all(np.abs(e.voltage) >= 200) and np.all(np.abs(e.voltage) <= 1500)


def test_protocol_kinematics_and_commands():
    (m,) = synthesize("coupled", protocol=SHORT, seed=3)
    on = _contact(m)
    speed = np.abs(m.speed[on])
    assert speed.min() >= 0.02 and speed.max() <= 0.15
    assert np.all(m.speed[~on] == 0.0)
    assert np.all(np.abs(m.normal_force[~on]) < 0.01)
    assert m.normal_force[on].min() > 0.19 and m.normal_force[on].max() < 1.51
    assert m.x.min() >= 0.005 - 1e-12 and m.x.max() <= 0.035 + 1e-12
    assert m.amplitude.min() >= 0 and m.amplitude.max() <= 3e-6
    # Amplitude piecewise constant over 30 ms segments, voltage flips every 40 ms.
    changes = np.flatnonzero(np.diff(m.amplitude) != 0) + 1
    assert np.all(changes % 30 == 0)
    flips = np.flatnonzero(np.sign(m.voltage[1:]) != np.sign(m.voltage[:-1])) + 1
    assert np.all(flips % 40 == 0) and flips.size == len(m) // 40 - (len(m) % 40 == 0)


def test_deterministic_and_fast():
    start = time.perf_counter()
    a = synthesize("coupled", drift_n=1e-3, seed=5)
    elapsed = time.perf_counter() - start
    b = synthesize("coupled", drift_n=1e-3, seed=5)
    c = synthesize("coupled", drift_n=1e-3, seed=6)
    assert elapsed < 1.0
    for name in ("t", "normal_force", "lateral_force", "amplitude", "voltage", "x", "speed"):
        np.testing.assert_array_equal(getattr(a[0], name), getattr(b[0], name))
    assert not np.array_equal(a[0].lateral_force, c[0].lateral_force)


def test_noise_and_drift():
    clean = synthesize("uv", protocol=SHORT, **CLEAN)[0]
    drifted = synthesize("uv", protocol=SHORT, drift_n=1e-3, **CLEAN)[0]
    offset = drifted.lateral_force - clean.lateral_force
    assert np.ptp(offset) == pytest.approx(1e-3, rel=1e-9)
    assert np.max(np.abs(np.diff(offset))) < 1e-5  # smooth
    noisy = synthesize("uv", protocol=SHORT, lateral_noise_n=0.002, normal_noise_n=0.003)[0]
    on = _contact(clean)
    assert np.std(noisy.lateral_force - clean.lateral_force) == pytest.approx(0.002, rel=0.05)
    assert np.std(noisy.normal_force[on] - clean.normal_force[on]) == pytest.approx(0.003, rel=0.05)
    assert np.all(np.abs(noisy.normal_force[~on]) < 0.01)


# -- effects --------------------------------------------------------------------------------
def test_charge_leakage_force_decays_with_half_tau_d():
    tau = 0.010
    (m,) = synthesize("ev", {"charge-leakage": {"time_constant": tau}}, **CLEAN)
    on = _contact(m)
    ids = stroke_ids(m)
    excess = friction(m) / MU0 - m.normal_force  # F_e (mu' = 1 on the ev device)
    flips = np.flatnonzero(np.sign(m.voltage[1:]) != np.sign(m.voltage[:-1])) + 1
    fitted = []
    for k in flips:
        window = slice(k + 1, k + 30)
        if k + 30 > len(m) or not on[k : k + 30].all() or np.unique(ids[k : k + 30]).size > 1:
            continue
        slope = np.polyfit(m.t[window], np.log(excess[window]), 1)[0]
        fitted.append(-1.0 / slope)
    assert len(fitted) > 100
    assert np.median(fitted) == pytest.approx(tau / 2, rel=0.05)
    clean = synthesize("ev", **CLEAN)[0]
    np.testing.assert_array_equal(clean.voltage, m.voltage)  # the applied voltage is recorded


def test_actuator_bandwidth_friction_lags_the_commanded_amplitude():
    tau = 0.010
    (m,) = synthesize("uv", {"actuator-bandwidth": {"time_constant": tau}}, **CLEAN)
    dg, frequency = _uv_model()
    on = _contact(m)
    ids = stroke_ids(m)
    mu = friction(m) / (MU0 * np.where(on, m.normal_force, 1.0))
    steps = np.flatnonzero(np.diff(m.amplitude) != 0) + 1
    amplitude_t63, friction_t63 = [], []
    for k in steps:
        span = slice(k, k + 29)
        if k + 29 > len(m) or not on[span].all() or np.unique(ids[span]).size > 1:
            continue
        speed, force, command = abs(m.speed[k]), m.normal_force[k], m.amplitude[k]
        # Friction over the step, and the plate amplitude that produces it (Eq. 2.33 inverted).
        plate = dg.inverse(
            np.minimum(mu[span], 1 - 1e-15), frequency=frequency, speed=speed, normal_force=force
        )
        amplitude_t63.append(_t63(plate, command) * 1e-3)
        settled = dg.forward(
            amplitude=command, frequency=frequency, speed=speed, normal_force=force
        )
        friction_t63.append(_t63(mu[span], float(settled)) * 1e-3)
    assert len(amplitude_t63) > 500
    assert np.median(amplitude_t63) == pytest.approx(tau, rel=0.01)
    assert np.nanmedian(friction_t63) == pytest.approx(tau, rel=0.10)


def test_air_layer_force_ratio_matches_ev_air_layer():
    gap = 20e-6
    ratios = {}
    for force in (0.2, 1.5):
        protocol = Protocol(duration_s=5.0, force_range_n=(force, force))
        (m,) = synthesize("ev", {"air-layer": {"air_gap": gap}}, protocol=protocol, **CLEAN)
        on = _contact(m)
        fe = friction(m)[on] / MU0 - m.normal_force[on]
        ratios[force] = fe / np.square(m.voltage[on])
    kacz = Kaczmarek()
    air = AirLayer(**{p.name: kacz[p.name] for p in Kaczmarek.parameters})
    predicted = float(air.forward(voltage=1.0, air_gap=gap / 0.2)) / float(
        air.forward(voltage=1.0, air_gap=gap / 1.5)
    )
    measured = ratios[0.2] / ratios[1.5]
    np.testing.assert_allclose(measured, predicted, rtol=1e-9)
    assert predicted < 0.5  # the gap matters at light load
    # At 1.5 N the force is the air-layer law at a 13 um gap.
    np.testing.assert_allclose(ratios[1.5], air.forward(voltage=1.0, air_gap=gap / 1.5), rtol=1e-9)


def test_load_index_and_occlusion_follow_finger_friction():
    clean = synthesize("uv", protocol=SHORT, **CLEAN)[0]
    on = _contact(clean)
    (m,) = synthesize("uv", {"load-index": {"load_index": 0.8}}, protocol=SHORT, **CLEAN)
    ratio = m.lateral_force[on] / clean.lateral_force[on]
    np.testing.assert_allclose(ratio, m.normal_force[on] ** -0.2, rtol=1e-12)
    (o,) = synthesize(
        "uv", {"occlusion-drift": {"gain": 1.0, "time_constant": 4.0}}, protocol=SHORT, **CLEAN
    )
    ratio = o.lateral_force[on] / clean.lateral_force[on]
    # occlusion runs on the time in contact (Fig. 1.11b): it pauses through the rests
    in_contact = np.cumsum(np.diff(o.t, prepend=o.t[0]) * on)
    np.testing.assert_allclose(ratio, 2.0 - np.exp(-in_contact[on] / 4.0), rtol=1e-12)
    assert o.t[on][-1] - in_contact[on][-1] > 1.0  # the rests are long enough to tell


def test_the_load_index_acts_on_the_reaction_force_with_electrovibration():
    """Eq. 2.35 on R = Fn + F_e (Eq. 3.1): with the clean lateral force mu0 R, the ratio of the
    load-index recording to it is (R / 1 N)^(n - 1), not (Fn / 1 N)^(n - 1)."""
    clean = synthesize("ev", protocol=SHORT, **CLEAN)[0]
    on = _contact(clean)
    (m,) = synthesize("ev", {"load-index": {"load_index": 0.8}}, protocol=SHORT, **CLEAN)
    reaction = friction(clean)[on] / DeviceConfig.coupled().mu0
    assert np.max(reaction / m.normal_force[on]) > 1.05  # F_e is a visible share of R
    np.testing.assert_allclose(friction(m)[on] / friction(clean)[on], reaction ** -0.2,
                               rtol=1e-9)


def test_plugin_effects_and_surface_patch():
    clean = synthesize("uv", protocol=SHORT, **CLEAN)[0]
    on = _contact(clean)
    ids = stroke_ids(clean)
    (s,) = synthesize(
        "uv", {"skin-recovery": {"depth": 0.4, "strokes": 1.0}}, protocol=SHORT, **CLEAN
    )
    ratio = s.lateral_force / np.where(on, clean.lateral_force, 1.0)
    first = np.flatnonzero(on)[0]
    assert ratio[first] == pytest.approx(0.6, rel=1e-12)  # first stroke after a rest: k = 0
    second = np.flatnonzero(on & (ids == ids[first] + 1))[0]
    assert ratio[second] == pytest.approx(1 - 0.4 * math.exp(-1), rel=1e-12)
    (p,) = synthesize("uv", {"surface-patch": {"depth": 0.5}}, protocol=SHORT, **CLEAN)
    ratio = p.lateral_force[on] / clean.lateral_force[on]
    x = p.x[on]
    inside = (x > 0.0105) & (x < 0.0175)
    outside = (x < 0.0095) | (x > 0.0185)
    np.testing.assert_allclose(ratio[inside], 1.5, rtol=1e-12)
    np.testing.assert_allclose(ratio[outside], 1.0, rtol=1e-12)
    assert inside.sum() > 100 and outside.sum() > 100
    # Squeeze film: the reduction shrinks with pressure.
    protocol = Protocol(duration_s=5.0, pressures_pa=(101325.0, 50662.5))
    high, low = synthesize("uv", {"squeeze-film-share": {"share": 1.0}}, protocol=protocol, **CLEAN)
    assert high.conditions["ambient_pressure_pa"] == 101325.0
    assert low.conditions["ambient_pressure_pa"] == 50662.5
    everything = synthesize("coupled", {name: {} for name in available_effects()}, protocol=SHORT)
    assert np.all(np.isfinite(everything[0].lateral_force))


# -- format and errors ----------------------------------------------------------------------
def test_round_trip_and_strokes(tmp_path):
    protocol = Protocol(duration_s=10.0, speed_range_m_s=(0.1, 0.1))  # 0.3 s strokes
    (m,) = synthesize("coupled", protocol=protocol, drift_n=1e-3)
    path = tmp_path / "rec.csv"
    write_measurement(m, path)
    back = read_measurement(path)
    for name in ("t", "normal_force", "lateral_force", "amplitude", "voltage", "x", "y", "speed"):
        np.testing.assert_array_equal(getattr(back, name), getattr(m, name))
    assert back.stroke is None
    assert back.conditions == m.conditions
    assert "effect" not in (tmp_path / "rec.csv.json").read_text()
    ids = stroke_ids(back)
    # Sessions of 5 x 0.3 s strokes + 1 s rest: 4 sessions in 10 s.
    assert ids.max() + 1 == 20
    counts = np.bincount(ids[ids >= 0])
    assert np.all(np.abs(counts - 300) <= 1)
    (default,) = synthesize("uv")
    ids = stroke_ids(default)
    assert ids.max() + 1 > 50


def test_bad_names_raise_value_error():
    with pytest.raises(ValueError, match=r"unknown effect 'nope'.*charge-leakage"):
        synthesize("uv", {"nope": {}})
    with pytest.raises(ValueError, match=r"unknown parameter\(s\) tau.*time_constant"):
        synthesize("ev", {"charge-leakage": {"tau": 0.01}})
    with pytest.raises(ValueError, match="unknown device"):
        synthesize("ultrasound")
    with pytest.raises(ValueError, match="outside its bounds"):
        synthesize("uv", {"load-index": {"load_index": 5.0}})
