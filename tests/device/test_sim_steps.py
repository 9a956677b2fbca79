"""The device simulation gives the same frames however a run is cut into steps (a real-time server
wakes every 5 ms: ``step(50)``), and the work it does ahead or in batches gives the numbers of a
direct computation: the internal finger's frames worked out ahead, the sensors' noise drawn in
batches, the plate loop's sample-by-sample path for a chattering loop, one load capacitance for
the amplifier.

Tolerances (stated in the simulation's module documentation): every frame field is identical
except those downstream of the plate loop, whose vectorised solution rounds differently for
other cut points: amplitude within 1e-15 m (1e-9 of the 2.5 um limit), felt friction within
1e-9, lateral force within 1e-10 N."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard import build
from hcard.render.finger_speed import TouchSamples
from hcard.track import FingerTrack, make_track
from hcard_device.sim import DeviceConfig, DeviceSimulation, SimBlock
from hcard_device.sim.amplifier import EVAmplifier
from hcard_device.sim.finger import TrackFinger
from hcard_device.sim.hidden import HiddenPhysics, resolve
from hcard_device.sim.models import device_profile
from hcard_device.sim.plate import DRIVE_SLACK, PIGains, PlateLoop, PlateModel
from hcard_device.sim.sensors import NOISE_BATCH, CornerForceSensors

EVITA, COUPLED = DeviceConfig.evita(), DeviceConfig.coupled()

TOLERANCES = {"amplitude_m": 1e-15, "friction": 1e-9, "lateral_force_n": 1e-10}
"""Largest difference between step patterns of the fields the plate loop's rounding reaches
(measured: 6e-16 m, 3e-11 and 4e-12 N on a card that holds the plate at its limit)."""


def wandering_track(surface: tuple[float, float], seconds: float, lifts: bool) -> FingerTrack:
    """A finger sweeping back and forth at up to ~200 mm/s, its force swelling between 0.25 and
    0.75 N, lifted for 0.1 s of every 0.5 s when ``lifts``."""
    t = np.arange(0.0, seconds + 1e-9, 1e-3)
    x = surface[0] * (0.5 + 0.4 * np.sin(2 * np.pi * t / 0.9))
    y = surface[1] / 2 + 3 * np.cos(7 * t)
    contact = ~((t % 0.5) > 0.4) if lifts else np.ones(t.size, dtype=bool)
    return make_track(t, x, y, 0.5 * (1 + 0.5 * np.sin(2 * np.pi * t / 0.37)), contact)


def cards() -> dict[str, object]:
    uv = build.texture(0.7, [build.grating_period(3.0, 0.15)], channel="uv", name="grating")
    strong = build.texture(0.2, [build.grating_period(2.0, 0.6)], channel="uv", name="strong")
    bipolar = build.texture(0.95, [build.grating_period(4.0, 0.15)], channel="bipolar",
                            name="bumps")
    ev = build.texture(1.8, [build.grating_period(2.0, 0.5)], channel="ev", name="ev")
    return {
        "uv": build.card(81.0, 54.0, taxtel_mm=(81.0, 54.0), textures=[uv]),
        "strong": build.card(81.0, 54.0, taxtel_mm=(81.0, 54.0), textures=[strong]),
        "bipolar": build.card(80.0, 50.0, taxtel_mm=(80.0, 50.0), textures=[bipolar]),
        "mixed": build.card(80.0, 50.0, taxtel_mm=10.0, textures=[uv, bipolar, strong, ev],
                            texture_index=[(i * 7) % 4 for i in range(40)]),
    }


CASES = [
    # (device, card, seed, hidden effects, lifts)
    (EVITA, "uv", 0, None, False),
    (EVITA, "strong", 5, None, True),
    (EVITA, "mixed", 4, None, True),
    (COUPLED, "bipolar", 1, None, False),
    (COUPLED, "mixed", 2, None, True),
    (COUPLED, "mixed", 3, {"air-layer": {}}, False),
    # every effect with a state (the finger's history, the leakage, the lag, the sensor), at once
    (COUPLED, "mixed", 6, {name: {} for name in (
        "occlusion-drift", "skin-recovery", "charge-leakage", "actuator-bandwidth",
        "force-sensor-resonance", "plate-load-damping", "finger-geometry", "load-index",
        "ultrasonic-speed")}, True),
    (EVITA, "strong", 8, {name: {} for name in (
        "occlusion-drift", "skin-recovery", "actuator-bandwidth", "force-sensor-resonance")},
     True),
]


def run(config: DeviceConfig, card: object, seed: int, effects: dict | None, lifts: bool,
        steps: list[int]) -> tuple[SimBlock, FingerTrack]:
    hidden = None
    if effects:
        hidden = HiddenPhysics(device_profile(config), resolve("coupled", effects))
    sim = DeviceSimulation(config, seed=seed, hidden=hidden)
    sim.load_card(card)
    track = wandering_track(config.surface_mm, 0.35, lifts)
    sim.use_internal_finger(track)
    sim.start()
    return SimBlock.concatenate([sim.step(n) for n in steps]), track


@pytest.mark.parametrize(("config", "card", "seed", "effects", "lifts"), CASES)
def test_twenty_5_ms_steps_give_the_frames_of_one_100_ms_step(config, card, seed, effects,
                                                               lifts):
    long, _ = run(config, cards()[card], seed, effects, lifts, [1000, 1000, 1000])
    short, _ = run(config, cards()[card], seed, effects, lifts, [50] * 60)
    uneven, _ = run(config, cards()[card], seed, effects, lifts, [7, 43, 333, 1, 616, 1000, 1000])
    assert long.contact.any() and np.ptp(long.amplitude_m) > 1e-7  # the plate was driven
    for other in (short, uneven):
        for name in SimBlock.__dataclass_fields__:
            if name in TOLERANCES:
                np.testing.assert_allclose(getattr(other, name), getattr(long, name), rtol=0,
                                           atol=TOLERANCES[name], err_msg=name)
            else:
                np.testing.assert_array_equal(getattr(other, name), getattr(long, name),
                                              err_msg=name)


def test_the_frames_ahead_and_batched_noise_are_the_direct_computation():
    """The internal finger's state, the touch samples and the corner forces of a 5 ms-stepped
    run against the track's state at the frame and touch times worked out directly, plus the
    jitter and the lever rule with the noise of generators seeded as the simulation's touch
    panel and force sensors, drawn in one go."""
    seed = 7
    block, track = run(EVITA, cards()["uv"], seed, None, True, [50] * 100)  # past the track
    direct = TrackFinger(track, 0.0, EVITA.surface_mm).state(block.t_s)
    for name in ("x_mm", "y_mm", "normal_force_n", "contact", "speed_m_s"):
        field = {"x_mm": "finger_x_mm", "y_mm": "finger_y_mm", "normal_force_n": "normal_force_n",
                 "contact": "contact", "speed_m_s": "finger_speed_m_s"}[name]
        np.testing.assert_array_equal(getattr(block, field), getattr(direct, name))
    force_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[1])
    noise = force_rng.normal(0.0, 1.0, size=(len(block), 4)) * EVITA.force_noise_n
    split = CornerForceSensors(*EVITA.surface_mm, 0.0, np.random.default_rng()).split(
        direct.normal_force_n, direct.x_mm, direct.y_mm)
    np.testing.assert_array_equal(block.corner_forces_n, split + noise)
    assert len(block) * 4 > NOISE_BATCH  # the draws ran over a batch boundary
    touch_rng = np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[0])
    sample_times = np.arange(0, len(block), 200) / EVITA.frame_rate_hz  # the 50 Hz panel
    jitter = touch_rng.normal(0.0, 1.0, size=(sample_times.size, 2)) * EVITA.touch_noise_mm
    at_samples = TrackFinger(track, 0.0, EVITA.surface_mm).state(sample_times)
    held = block.touch[::200]  # the frames at the sample times hold those samples
    np.testing.assert_array_equal(held["t_s"], sample_times)
    np.testing.assert_array_equal(held["x_mm"], at_samples.x_mm + jitter[:, 0])
    np.testing.assert_array_equal(held["y_mm"], at_samples.y_mm + jitter[:, 1])
    np.testing.assert_array_equal(held["contact"], at_samples.contact)
    assert not held["contact"].all() and held["contact"].any()  # lifts and touches


def coupled_loop() -> PlateLoop:
    plate = PlateModel(COUPLED.limits.plate_frequency, COUPLED.plate_quality_factor,
                       COUPLED.finger_damping_per_n, COUPLED.full_drive_amplitude_m)
    gains = PIGains.ziegler_nichols(plate, COUPLED.pi_dead_time_s, COUPLED.pi_tuning_force_n)
    return PlateLoop(plate, gains, COUPLED.loop_rate_hz, COUPLED.limits.max_amplitude)


def loop_recursion(loop: PlateLoop, ref: np.ndarray, force: float) -> tuple[np.ndarray, ...]:
    """The loop of the plate module's documentation, sample by sample (one finger force)."""
    plate, kp, ki, period, lim = loop.plate, loop.gains.kp, loop.gains.ki, loop.period_s, \
        loop.limit_m
    a = math.exp(-plate.decay_rate(force) * period)
    g = (1 - a) * plate.full_drive_amplitude(force)
    amp, integ, out, drive = 0.0, 0.0, [], []
    for r in np.clip(ref, 0.0, lim):
        e = r - amp
        u_lin, u_hi = kp * e + integ, min(1.0, max((lim - a * amp) / g, 0.0))
        if u_lin < -DRIVE_SLACK:
            u, integ = 0.0, max(integ + ki * period * e, min(integ, 0.0))
        elif u_lin > u_hi + DRIVE_SLACK:
            u = u_hi
            if u_hi < 1.0:
                integ = u_hi - kp * e
        else:
            u, integ = u_lin, integ + ki * period * e
        amp = a * amp + g * u
        out.append(amp)
        drive.append(min(max(u, 0.0), 1.0))
    return np.array(out), np.array(drive)


def test_a_chattering_plate_loop_is_the_sample_recursion(monkeypatch):
    """A 45 Hz reference held for each 10 kHz frame (a grating under a fast stroke) falls in
    steps the coupled stimulator's slow plate follows by switching its one-sided PI between
    zero drive and the linear loop every few samples; the loop then runs sample by sample, and
    gives the recursion's amplitude and drive, whether it is run in 5 ms steps or at once, and
    never exceeds its limit."""
    calls = []
    original = PlateLoop._steps
    monkeypatch.setattr(PlateLoop, "_steps",
                        lambda self, *args: calls.append(1) or original(self, *args))
    frames = np.arange(1200) / COUPLED.frame_rate_hz
    ref = np.repeat(1.3e-6 + 1.4e-6 * np.sin(2 * np.pi * 45.0 * frames), 6)  # 60 kHz samples
    expected, drive = loop_recursion(coupled_loop(), ref, 0.5)
    at_once = coupled_loop().run(ref, np.full(ref.size, 0.5))
    stepped_loop = coupled_loop()
    stepped = [stepped_loop.run(ref[k : k + 300], np.full(300, 0.5))
               for k in range(0, ref.size, 300)]
    assert len(calls) >= 5  # the sample-by-sample path ran
    modes = np.where(drive <= 0, 0, np.where(drive >= 1, 2, 1))
    assert np.count_nonzero(np.diff(modes)) > 60  # through zero drive, linear and full drive
    for result in (at_once.amplitude, np.concatenate([s.amplitude for s in stepped])):
        np.testing.assert_allclose(result, np.maximum(expected, 0.0), rtol=0, atol=1e-15)
        assert result.max() <= COUPLED.limits.max_amplitude * (1 + 1e-9) + 1e-14
    np.testing.assert_allclose(at_once.drive, drive, rtol=0, atol=1e-6)
    assert (at_once.drive == 0).any() and (at_once.drive == 1).any() and at_once.clamped.any()


@pytest.mark.parametrize("capacitance", [0.0, 33e-12, 150e-12])
def test_one_load_capacitance_gives_the_amplifier_the_numbers_of_a_per_frame_load(
        capacitance):
    """The amplifier with one number for the load gives what it gives with that number for
    every frame: voltage, current and both limit flags, through the current limit, the slew
    limit, a lowered voltage limit and a stop."""
    rng = np.random.default_rng(5)
    command = np.concatenate((np.full(40, 1800.0), rng.uniform(0, 2500, 60), np.zeros(30)))
    results = []
    for load in (capacitance, np.full(command.size, capacitance)):
        amplifier = EVAmplifier(440.0, 10_000.0, 2000.0, 250e-6, 40e6)
        parts = [amplifier.run(command[:70], load if np.ndim(load) == 0 else load[:70])]
        amplifier.max_voltage_v = 700.0
        parts.append(amplifier.run(command[70:], load if np.ndim(load) == 0 else load[70:]))
        results.append(parts)
    for scalar, array in zip(*results, strict=True):
        for name in ("voltage", "current", "voltage_limited", "current_limited"):
            np.testing.assert_array_equal(getattr(scalar, name), getattr(array, name))
    flags = np.concatenate([p.current_limited | p.voltage_limited for p in results[0]])
    assert flags.any() or capacitance == 0.0


@pytest.mark.parametrize("count", [1, 2, 3, 4, 6])
def test_a_tail_of_touch_samples_has_the_kinematics_of_those_samples_alone(count):
    """The kinematics a tail takes from the samples it is cut from are those its own samples
    give, with lifts and a repeated time among them."""
    rng = np.random.default_rng(count)
    t = np.cumsum(rng.choice([0.0, 0.02], 9, p=[0.1, 0.9])) + 1.0
    samples = TouchSamples(t, rng.normal(30, 5, 9), rng.normal(20, 5, 9), rng.uniform(size=9) > 0.2)
    _ = samples.kinematics  # known, so the tail takes it
    tail = samples.tail(count)
    alone = TouchSamples(tail.t.copy(), tail.x.copy(), tail.y.copy(), tail.contact.copy())
    assert "kinematics" in tail.__dict__
    for derived, direct in zip(tail.kinematics, alone.kinematics, strict=True):
        np.testing.assert_array_equal(derived, direct)
