"""Each hidden effect of the reference device (hcard_device.sim.hidden) against its physics
worked out here, independently, from the thesis' formula and the frames of the same device
without the effect (same seed: the plate, the amplifier and the sensors give the same measured
amplitude, voltage and forces, so the recorded columns cannot show the effect); its neutral
values give the un-hidden device exactly; its state does not depend on how the frames are cut
into steps."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from hcard import build
from hcard.quantities import ATMOSPHERE_PA
from hcard.track import make_track
from hcard_builtins.physics.electrovibration import geometry
from hcard_device.sim import DeviceConfig, DeviceSimulation, SimBlock
from hcard_device.sim.hidden import HIDDEN_EFFECTS, HiddenEffectError, HiddenPhysics, resolve
from hcard_device.sim.models import device_profile

RATE = 10_000.0
DT = 1.0 / RATE


def quiet(variant: str, **changes: float) -> DeviceConfig:
    """The device without lateral-force noise (so ratios are exact), with ``changes``."""
    config = DeviceConfig.coupled() if variant == "coupled" else DeviceConfig.evita()
    return replace(config, lateral_force_noise_n=0.0, **changes)


def simulate(config: DeviceConfig, effects: dict | None, track, n: int, *, uv: float = 1.0,
             ev: float = 1.0, steps: list[int] | None = None, seed: int = 2,
             card: object = None) -> SimBlock:
    """``n`` frames of the device following ``track``, streamed the targets ``uv``, ``ev``
    (fed in the steps' rhythm) or playing ``card``, with the hidden ``effects``."""
    variant = "coupled" if config.has_ev else "evita"
    hidden = None
    if effects is not None:
        hidden = HiddenPhysics(device_profile(config), resolve(variant, effects),
                               frame_rate_hz=config.frame_rate_hz,
                               ambient_pressure_pa=config.ambient_pressure_pa)
    sim = DeviceSimulation(config, seed=seed, hidden=hidden)
    if card is not None:
        sim.load_card(card)
    sim.use_internal_finger(track)
    sim.start()
    blocks = []
    for size in steps or [50] * (n // 50):
        if card is None:
            sim.stream_frames(np.full(size, uv), np.full(size, ev))
            sim.feed_watchdog()
        blocks.append(sim.step(size))
    return SimBlock.concatenate(blocks)


def stroke(seconds: float, force: float, speed_mm_s: float = 40.0, x0: float = 10.0):
    """A straight stroke along x at ``speed_mm_s`` and constant ``force`` (N), from t = 0."""
    t = np.arange(0.0, seconds + 1e-9, 0.01)
    return make_track(t, x0 + speed_mm_s * t, np.full(t.size, 25.0), force, True)


def pressing(block: SimBlock) -> np.ndarray:
    return block.contact & (block.normal_force_n > 0)


def test_every_effect_is_served_with_its_parameters_and_neutral_values():
    assert set(HIDDEN_EFFECTS) >= {
        "load-index", "occlusion-drift", "actuator-bandwidth", "charge-leakage",
        "ultrasonic-speed", "air-layer", "skin-recovery", "squeeze-film-share",
        "finger-geometry", "plate-load-damping", "force-sensor-resonance"}
    for effect in HIDDEN_EFFECTS.values():
        names = {p.name for p in effect.parameters}
        assert set(effect.neutral) <= names and effect.devices
        for parameter in effect.parameters:
            parameter.check(parameter.default)
            assert parameter.source and parameter.description
        for name, value in effect.neutral.items():
            (p,) = [p for p in effect.parameters if p.name == name]
            assert p.check(value) == value and p.default != value  # the default hides something


@pytest.mark.parametrize("name", sorted(HIDDEN_EFFECTS))
def test_an_effect_at_its_neutral_values_is_the_unhidden_device_exactly(name):
    variant = "coupled"
    config = replace(DeviceConfig.coupled(), ambient_pressure_pa=0.5 * ATMOSPHERE_PA)
    track = stroke(0.12, 0.4)
    plain = simulate(config, None, track, 1000, uv=0.6, ev=1.5)
    neutral = simulate(config, {name: HIDDEN_EFFECTS[name].neutral}, track, 1000, uv=0.6,
                       ev=1.5)
    hidden = simulate(config, {name: {}}, track, 1000, uv=0.6, ev=1.5)
    assert variant in HIDDEN_EFFECTS[name].devices
    np.testing.assert_array_equal(neutral.lateral_force_n, plain.lateral_force_n)
    np.testing.assert_array_equal(neutral.friction, plain.friction)
    # the default changes what the finger feels, never what the device measures
    assert not np.allclose(hidden.lateral_force_n, plain.lateral_force_n, rtol=1e-4, atol=0)
    for column in ("amplitude_m", "voltage_v", "normal_force_n", "corner_forces_n", "touch"):
        np.testing.assert_array_equal(getattr(hidden, column), getattr(plain, column))


def test_load_index_is_the_power_law_of_eq_2_35():
    # F = k Fn^n: at 0.4 N the lateral force with n = 0.75 is 0.4^(0.75 - 0.91) = 1.158 times
    # that of the device's finger (n = 0.91)
    config = quiet("evita")
    plain = simulate(config, None, stroke(0.1, 0.4), 1000, uv=0.7)
    hidden = simulate(config, {"load-index": {"load_index": 0.75}}, stroke(0.1, 0.4), 1000,
                      uv=0.7)
    on = pressing(plain)
    ratio = hidden.lateral_force_n[on] / plain.lateral_force_n[on]
    np.testing.assert_allclose(ratio, 0.4 ** (0.75 - 0.91), rtol=1e-12)
    assert ratio[0] == pytest.approx(1.1579, abs=1e-4)
    np.testing.assert_array_equal(hidden.friction, plain.friction)  # the finger, not the plate


def test_occlusion_drift_counts_the_time_in_contact_and_pauses_while_lifted():
    # 1 s in contact, 1 s lifted, 1 s in contact: at the end the occlusion time is 2 s (not 3 s,
    # and not 1 s as it would be if a lift restarted it), so with g = 1 and tau = 1 s the
    # friction is 1 + (1 - exp(-2)) = 1.8647 times the device's own
    t = np.arange(0.0, 3.0 + 1e-9, 0.01)
    contact = (t < 1.0) | (t >= 2.0)
    track = make_track(t, 20.0 + 5.0 * np.sin(t), np.full(t.size, 25.0), 0.5, contact)
    config = quiet("evita")
    effects = {"occlusion-drift": {"gain": 1.0, "time_constant": 1.0}}
    plain = simulate(config, None, track, 29900)
    hidden = simulate(config, effects, track, 29900)
    on = pressing(plain)
    occlusion_time = np.cumsum(plain.contact) * DT
    expected = 1.0 + (1.0 - np.exp(-occlusion_time[on] / 1.0))
    np.testing.assert_allclose(hidden.lateral_force_n[on] / plain.lateral_force_n[on], expected,
                               rtol=1e-12)
    last = np.flatnonzero(on)[-1]
    assert hidden.lateral_force_n[last] / plain.lateral_force_n[last] == pytest.approx(
        1.0 + (1.0 - math.exp(-2.0)), abs=2e-3)


def test_skin_recovery_counts_strokes_since_the_finger_rested():
    # strokes (reversals along x in contact, touch-downs after short lifts) since the last rest
    # (a lift of 0.5 s or more): 0, 1, 2 on a back-and-forth, 3 after a 0.2 s lift, 0 after a
    # 0.8 s lift; the friction is 1 - D exp(-k / k_r) times the device's own
    legs = [  # (duration s, contact, x velocity mm/s, expected stroke number)
        (0.2, True, 50.0, 0), (0.2, True, -50.0, 1), (0.2, True, 50.0, 2),
        (0.2, False, 0.0, None), (0.2, True, 50.0, 3),
        (0.8, False, 0.0, None), (0.2, True, -50.0, 0), (0.2, True, 50.0, 1)]
    t, x, contact = [0.0], [20.0], [True]
    for duration, touching, velocity, _ in legs:
        for _ in range(20):
            t.append(t[-1] + duration / 20)
            x.append(x[-1] + velocity * duration / 20)
            contact.append(touching)
    track = make_track(np.array(t), np.array(x), np.full(len(t), 25.0), 0.5, np.array(contact))
    config = quiet("evita")
    plain = simulate(config, None, track, 22000)
    hidden = simulate(config, {"skin-recovery": {"depth": 0.3, "strokes": 2.0}}, track, 22000)
    start = 0.0
    for duration, touching, _, k in legs:
        middle = round((start + duration / 2) * RATE)
        start += duration
        if not touching:
            continue
        ratio = hidden.lateral_force_n[middle] / plain.lateral_force_n[middle]
        assert ratio == pytest.approx(1.0 - 0.3 * math.exp(-k / 2.0), rel=1e-12), (start, k)


def lag(x: np.ndarray, tau: float) -> np.ndarray:
    """First-order lag of a held input, from rest: y_k = a y_(k-1) + (1 - a) x_(k-1)."""
    a, y, out = math.exp(-DT / tau), 0.0, np.empty(x.size)
    for k in range(x.size):
        out[k] = y
        y = a * y + (1.0 - a) * x[k]
    return out


def felt(config: DeviceConfig, block: SimBlock, amplitude: np.ndarray,
         voltage: np.ndarray) -> np.ndarray:
    """The friction the device's own models give for the amplitude and voltage under the
    finger."""
    uv, ev = device_profile(config).forward(amplitude, voltage, block.finger_speed_m_s,
                                            block.normal_force_n)
    return np.where(block.contact, uv * ev, 1.0)


def test_actuator_bandwidth_lags_the_amplitude_the_recording_shows():
    # section 4.3.2: the plate's mechanical response; the vibration under the finger is the
    # sensed amplitude through 1 / (1 + tau s); a step of the sensed amplitude reaches the
    # finger 63 % after tau
    config = quiet("evita")
    tau = 3e-3
    plain = simulate(config, None, stroke(0.1, 0.5), 1000, uv=0.5)
    hidden = simulate(config, {"actuator-bandwidth": {"time_constant": tau}}, stroke(0.1, 0.5),
                      1000, uv=0.5)
    np.testing.assert_array_equal(hidden.amplitude_m, plain.amplitude_m)  # the recorded column
    under = lag(plain.amplitude_m, tau)
    np.testing.assert_allclose(hidden.friction, felt(config, plain, under, plain.voltage_v),
                               rtol=1e-12)
    held = np.full(200, 2e-6)
    assert lag(held, tau)[30] == pytest.approx(2e-6 * (1 - math.exp(-1.0)), rel=1e-9)
    assert np.max(np.abs(hidden.friction - plain.friction)) > 0.05  # while the plate rises


def test_plate_load_damping_lowers_the_amplitude_under_a_pressing_finger():
    # A_finger = A_sensed / (1 + Fn / F_d): at 0.5 N and F_d = 2 N the finger feels 80 %
    config = quiet("evita")
    plain = simulate(config, None, stroke(0.1, 0.5), 1000, uv=0.5)
    hidden = simulate(config, {"plate-load-damping": {"damping_force": 2.0}}, stroke(0.1, 0.5),
                      1000, uv=0.5)
    np.testing.assert_array_equal(hidden.amplitude_m, plain.amplitude_m)
    on = pressing(plain)
    assert np.all(plain.normal_force_n[on] == pytest.approx(0.5))
    np.testing.assert_allclose(
        hidden.friction, felt(config, plain, plain.amplitude_m * 0.8, plain.voltage_v),
        rtol=1e-12)
    settled = on & (np.arange(len(plain)) > 500)
    assert np.all(hidden.friction[settled] > plain.friction[settled] + 0.02)  # less reduction


def carrier_gain(tau_d_10hz: float, carrier_hz: float = 440.0) -> float:
    """|H| of Eq. 3.22's high pass ``tau s / (1 + tau s)`` at the carrier, with ``tau_d``
    falling with frequency as Fig. 3.13 (slope -0.7 from its value at 10 Hz)."""
    omega_tau = 2.0 * math.pi * carrier_hz * tau_d_10hz * (carrier_hz / 10.0) ** -0.7
    return omega_tau / math.sqrt(1.0 + omega_tau**2)


def test_charge_leakage_is_the_finger_s_carrier_gain_on_the_envelope():
    # Eqs. 3.19-3.23: a finger with tau_d = 3 ms at 10 Hz (the profile's: 7.7 ms) passes the
    # 440 Hz carrier with gain 0.506 instead of 0.833: the envelope acts scaled by 0.607 and
    # the EV force (~ v^2) by 0.369
    config = quiet("coupled")
    track = stroke(0.1, 0.5)
    plain = simulate(config, None, track, 1000, ev=1.6)
    hidden = simulate(config, {"charge-leakage": {"time_constant": 3e-3}}, track, 1000, ev=1.6)
    np.testing.assert_array_equal(hidden.voltage_v, plain.voltage_v)
    ratio = carrier_gain(3e-3) / carrier_gain(7.7e-3)
    assert carrier_gain(7.7e-3) == pytest.approx(0.833, abs=0.001)
    assert ratio == pytest.approx(0.607, abs=0.001)
    np.testing.assert_allclose(hidden.friction, felt(config, plain, plain.amplitude_m,
                                                     plain.voltage_v * ratio), rtol=1e-9)
    on = pressing(plain) & (plain.voltage_v > 100.0)
    assert on.sum() > 100
    force_ratio = (hidden.friction[on] - 1.0) / (plain.friction[on] - 1.0)
    np.testing.assert_allclose(force_ratio, ratio**2, rtol=1e-6)


def test_ultrasonic_speed_scales_the_reduction_by_a_power_of_the_speed():
    # Fig. 2.21e: 1 - mu' becomes (1 - mu') (U / U_ref)^a; at 100 mm/s, U_ref = 25 mm/s and
    # a = -0.5 the reduction is halved
    config = quiet("evita")
    track = stroke(0.1, 0.5, speed_mm_s=100.0)
    plain = simulate(config, None, track, 1000, uv=0.5)
    hidden = simulate(config, {"ultrasonic-speed": {"speed_exponent": -0.5,
                                                    "reference_speed": 0.025}}, track, 1000, uv=0.5)
    on = pressing(plain)
    assert plain.finger_speed_m_s[on] == pytest.approx(0.1)
    np.testing.assert_allclose(1.0 - hidden.friction[on], 0.5 * (1.0 - plain.friction[on]),
                               rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize(("pressure", "gamma"), [(0.5 * ATMOSPHERE_PA, 0.75),
                                                 (ATMOSPHERE_PA, 1.0)])
def test_squeeze_film_share_scales_the_reduction_with_the_ambient_pressure(pressure, gamma):
    # Eq. 2.10: gamma = 1 - s (1 - p / p0); s = 0.5 at p0 / 2 leaves 75 % of the reduction
    config = quiet("evita", ambient_pressure_pa=pressure)
    plain = simulate(config, None, stroke(0.1, 0.5), 1000, uv=0.5)
    hidden = simulate(config, {"squeeze-film-share": {"share": 0.5}}, stroke(0.1, 0.5), 1000,
                      uv=0.5)
    np.testing.assert_allclose(1.0 - hidden.friction, gamma * (1.0 - plain.friction), rtol=1e-9,
                               atol=1e-15)


def pad_force_per_volt(depth: float) -> float:
    """Eq. 3.18 over the Table 3.2 pad pressed flat to ``depth`` (m), N/V^2: the patches whose
    sag is under the depth touch, the others keep the air ``sag - depth`` plus the ridge
    valley."""
    pad = geometry.FingerGeometry()
    patches = pad.patches()
    half = pad["finger_width"] / 2
    sag = pad["finger_height"] / 2 * (1 - np.sqrt(1 - np.minimum(
        (patches.x**2 + patches.y**2) / half**2, 1.0)))
    gap = np.maximum(sag - depth, 0.0) + np.maximum(patches.offset - sag, 0.0)
    return float(geometry.discretised_force(
        1.0, patches.area, pad["sc_thickness"], gap, sc_permittivity=pad["sc_permittivity"],
        insulator_thickness=pad["insulator_thickness"],
        insulator_permittivity=pad["insulator_permittivity"]))


def test_finger_geometry_is_the_flattened_pad_of_eq_3_18():
    # h = 1.75 mm (Fn / 1 N)^m; at Fn = 0.2 N and m = 2/3 the pad flattens to 0.598 mm and its
    # EV force is C(0.598 mm) / C(1.75 mm) of the device's own at that voltage
    config = quiet("coupled")
    track = stroke(0.1, 0.2)
    plain = simulate(config, None, track, 1000, ev=1.5)
    hidden = simulate(config, {"finger-geometry": {"area_index": 2 / 3}}, track, 1000, ev=1.5)
    ratio = pad_force_per_volt(1.75e-3 * 0.2 ** (2 / 3)) / pad_force_per_volt(1.75e-3)
    assert 0.3 < ratio < 0.7
    settled = pressing(plain) & (plain.friction > 1.05)
    assert settled.sum() > 500
    np.testing.assert_allclose((hidden.friction[settled] - 1.0) / (plain.friction[settled] - 1.0),
                               ratio, rtol=5e-3)


def test_the_force_sensor_rings_at_its_own_resonance():
    # a second-order sensor (f0 = 150 Hz, zeta = 0.1) under the step of a touch-down: it reads
    # F (1 - exp(-zeta w0 t) (cos w_d t + zeta w0 / w_d sin w_d t)), overshooting by
    # exp(-pi zeta / sqrt(1 - zeta^2)) = 73 % at t = pi / w_d = 3.35 ms
    config = quiet("evita")
    track = make_track(np.array([0.0, 1.0]), 20.0, 25.0, 0.5, True)  # a finger at rest
    plain = simulate(config, None, track, 500)
    hidden = simulate(config, {"force-sensor-resonance": {"natural_frequency": 150.0,
                                                          "damping_ratio": 0.1}}, track, 500)
    w0, zeta = 2 * math.pi * 150.0, 0.1
    wd = w0 * math.sqrt(1 - zeta**2)
    time = np.arange(500) * DT
    step = 1 - np.exp(-zeta * w0 * time) * (np.cos(wd * time)
                                            + zeta * w0 / wd * np.sin(wd * time))
    force = plain.lateral_force_n  # nearly constant from the first frame (occlusion: 20 s)
    assert force[0] > 0.1 and np.ptp(force) < 5e-3 * force[0]
    np.testing.assert_allclose(hidden.lateral_force_n, step * force, rtol=0, atol=5e-4 * force[0])
    peak = int(np.argmax(hidden.lateral_force_n))
    assert peak * DT == pytest.approx(math.pi / wd, abs=DT)
    assert hidden.lateral_force_n[peak] / force[peak] == pytest.approx(
        1 + math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), abs=2e-3)


EVERY_STATEFUL = {name: {} for name in (
    "occlusion-drift", "skin-recovery", "charge-leakage", "actuator-bandwidth",
    "force-sensor-resonance", "plate-load-damping", "load-index", "finger-geometry",
    "ultrasonic-speed", "squeeze-film-share", "air-layer")}


def test_several_effects_at_once_do_not_depend_on_how_the_frames_are_cut():
    t = np.arange(0.0, 1.5 + 1e-9, 0.01)
    contact = ~(((t > 0.3) & (t < 0.45)) | ((t > 0.8) & (t < 1.4)))  # a short and a long lift
    track = make_track(t, 40 + 25 * np.sin(2 * np.pi * t / 0.4), 25 + 3 * np.cos(5 * t),
                       0.5 + 0.2 * np.sin(7 * t), contact)
    config = replace(DeviceConfig.coupled(), ambient_pressure_pa=0.7 * ATMOSPHERE_PA)
    uv = build.texture(0.6, [build.grating_period(3.0, 0.3)], channel="uv", name="uv")
    ev = build.texture(1.8, [build.grating_period(2.0, 0.5)], channel="ev", name="ev")
    card = build.card(80.0, 50.0, taxtel_mm=10.0, textures=[uv, ev],
                      texture_index=[i % 2 for i in range(40)])
    one = simulate(config, EVERY_STATEFUL, track, 15000, steps=[15000], seed=5, card=card)
    sizes = [7, 43, 333, 1, 616, 1000, 50] * 5
    many = simulate(config, EVERY_STATEFUL, track, 15000, steps=[*sizes, 15000 - sum(sizes)],
                    seed=5, card=card)
    assert one.contact.any() and not one.contact.all()
    np.testing.assert_allclose(many.lateral_force_n, one.lateral_force_n, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(many.friction, one.friction, rtol=1e-9)
    plain = simulate(config, None, track, 15000, steps=[15000], seed=5, card=card)
    assert np.max(np.abs(one.lateral_force_n - plain.lateral_force_n)) > 0.05


def test_a_new_finger_starts_its_history_over_but_the_sensor_runs_on():
    config = quiet("evita")
    effects = resolve("evita", {"occlusion-drift": {"gain": 1.0, "time_constant": 1.0}})
    sim = DeviceSimulation(config, seed=1, hidden=HiddenPhysics(device_profile(config), effects))
    sim.use_internal_finger(stroke(1.0, 0.5))
    sim.start()
    first = sim.step(5000)
    sim.use_internal_finger(stroke(1.0, 0.5))
    again = sim.step(5000)
    np.testing.assert_allclose(again.lateral_force_n[100:], first.lateral_force_n[100:],
                               rtol=1e-6)


@pytest.mark.parametrize(
    ("variant", "effects", "message"),
    [
        ("evita", {"charge-leakage": {}}, "effect charge-leakage needs the coupled device"),
        ("evita", {"finger-geometry": {}}, "effect finger-geometry needs the coupled device"),
        ("coupled", {"plate-load-damping": {"force": 1.0}},
         "effect plate-load-damping has no parameter.*force.*its parameters: damping_force"),
        ("coupled", {"force-sensor-resonance": {"natural_frequency": 0.1}},
         "force-sensor-resonance: parameter natural_frequency = 0.1 Hz is outside its bounds"),
        ("coupled", {"skin-recovery": {"depth": 1.0}},
         "skin-recovery: parameter depth = 1 +is outside its bounds"),
        ("coupled", {"stribeck": {}}, "unknown hidden effect 'stribeck'"),
    ],
)
def test_bad_effects_are_named(variant, effects, message):
    with pytest.raises(HiddenEffectError, match=message):
        resolve(variant, effects)
