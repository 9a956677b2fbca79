"""The faulty device (``faulty://FAULT?strength=S``, spec/conformance.md QN2): its URI grammar
and errors, its registration as a vendor's plugin, the physics of its plate with each device
fault, and each driver fault of its rendering on the host. The known-fault table itself is
``test_known_faults.py``."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard import build
from hcard.device import open_device
from hcard.device.errors import UriError
from hcard.device.protocol import FaultBits
from hcard.device.published_profiles import published_profile
from hcard.plugins import get_registry
from hcard.render import RenderOptions
from hcard.v1 import card_pb2 as pb
from hcard_conformance.faulty.driver import FaultyDriver
from hcard_conformance.faulty.faults import FAULTS, NO_FAULT, fault_uri
from hcard_conformance.faulty.host_faults import FaultyRendering, RenderingFaults, misread
from hcard_conformance.faulty.plate import TAU_S, FaultyPlate, PlateFaults
from hcard_conformance.faulty.plugin import FAULTY_DRIVER
from hcard_conformance.faulty.profile import PLATE, plate_profile
from tests.helpers.cli import assert_one_line_error, run_hcard

RATE = PLATE.frame_rate_hz
EPS0 = 8.8541878128e-12
"""Vacuum permittivity, F/m (CODATA 2018)."""


# ---------------------------------------------------------------- the URI grammar

@pytest.mark.parametrize(("uri", "fragments"), [
    ("faulty://bogus", ("unknown fault 'bogus'", "known: none, output-latency, slow-plate")),
    ("faulty://", ("the URI names no fault", "known: none,")),
    ("faulty://?strength=3", ("the URI names no fault",)),
    ("faulty://output-latency", ("option strength is required",
                                 "latency added between a frame and the plate playing it, ms",
                                 "a number in [0, 1000]")),
    ("faulty://output-latency?strength=abc", ("option strength='abc' must be",
                                              "a number in [0, 1000]")),
    ("faulty://output-latency?strength=-1", ("option strength='-1'", "[0, 1000]")),
    ("faulty://output-latency?strength=1001", ("option strength='1001'", "[0, 1000]")),
    ("faulty://weak-ev?strength=nan", ("option strength='nan'", "[0, 100]")),
    ("faulty://late-watchdog?strength=inf", ("option strength='inf'", "[0, 10000]")),
    ("faulty://output-latency?strength=3&seed=1", ("unknown option 'seed'",
                                                   "the one option is strength")),
    ("faulty://none?strength=1", ("fault none takes no option strength",)),
    ("faulty://none/plate", ("takes no path",)),
])
def test_a_bad_uri_names_the_option_and_what_it_allows(uri: str,
                                                       fragments: tuple[str, ...]) -> None:
    with pytest.raises(UriError) as caught:
        open_device(uri)
    message = str(caught.value)
    assert message.startswith(f"bad device URI {uri!r}: ")
    assert "expected e.g. faulty://output-latency?strength=30 or faulty://none" in message
    for fragment in fragments:
        assert fragment in message, message


def test_the_command_line_refuses_a_bad_uri_in_one_line() -> None:
    result = run_hcard("conformance", "--driver", "faulty://slow-plate?strength=fast",
                       "--level", "device")
    assert_one_line_error(result, "cannot open driver", "option strength='fast' must be",
                          "a number in [0, 100]", status=2, after_usage=True)


def test_every_fault_opens_at_both_ends_of_its_range() -> None:
    for fault in FAULTS:
        for strength in (0.0, fault.most):
            with open_device(fault_uri(fault.name, strength)) as driver:
                assert driver.info().plate_frequency_hz == PLATE.plate_frequency_hz
    with open_device(f"faulty://{NO_FAULT}") as driver:
        assert isinstance(driver, FaultyDriver)
        assert driver.device.faults == PlateFaults()  # type: ignore[attr-defined]


# ---------------------------------------------------------------- a vendor's plugin

def test_it_is_registered_as_a_vendors_driver_and_profile() -> None:
    registry = get_registry()
    assert registry.drivers["faulty"] == FAULTY_DRIVER  # a row: nothing imported to list it
    assert (FAULTY_DRIVER.name, FAULTY_DRIVER.description, FAULTY_DRIVER.schemes) == (
        FaultyDriver.name, FaultyDriver.description, FaultyDriver.schemes)
    assert FAULTY_DRIVER.load() is FaultyDriver
    assert "faulty-plate" in registry.device_profiles
    with open_device("faulty://none") as driver:
        assert published_profile(driver.info()) is plate_profile()
        assert driver.renders_on_host and not driver.realtime
    with open_device("sim://") as driver:  # the E-ViTa is not the faulty device
        assert published_profile(driver.info()) is not plate_profile()


# ---------------------------------------------------------------- the plate

def _play_held(plate: FaultyPlate, amplitude_m: float, voltage_v: float, frames: int,
               first: int = 0) -> None:
    plate.play(first, np.full(frames, amplitude_m), np.full(frames, voltage_v))


def test_the_plate_rises_with_its_time_constant() -> None:
    """10-90 % of a first-order rise: tau ln 9 (tau = 0.1 ms + the slow-plate strength)."""
    plate = FaultyPlate(PlateFaults(added_tau_s=0.9e-3))
    _play_held(plate, 2e-6, 0.0, 200)
    measured = plate.measure(199 / RATE)
    level = measured.amplitude_m / 2e-6
    t_10 = np.interp(0.1, level, measured.t_s)
    t_90 = np.interp(0.9, level, measured.t_s)
    assert t_90 - t_10 == pytest.approx((TAU_S + 0.9e-3) * math.log(9), abs=1 / RATE)
    assert level[-1] == pytest.approx(1.0, abs=1e-6)


def test_the_plate_plays_each_frame_its_output_delay_late() -> None:
    plate = FaultyPlate(PlateFaults(output_delay_s=3e-3))
    plate.play(0, np.zeros(10), np.zeros(10))
    _play_held(plate, 2e-6, 0.0, 100, first=10)
    amplitude = plate.measure(99 / RATE).amplitude_m
    first_on = int(np.flatnonzero(amplitude > 0)[0])
    assert first_on == 10 + 30  # 3 ms at 10 kHz


def test_the_hardware_clamps_act_on_the_commands() -> None:
    """Amplitude to 2.5 um and voltage to 2000 V whatever is sent (NaN: off); the current is
    the 440 Hz carrier's into the electrode capacitance of Eq. 3.8."""
    plate = FaultyPlate()
    plate.play(0, np.array([5e-6] * 100 + [math.nan] * 100),
               np.array([3000.0] * 100 + [-1.0] * 100))
    m = plate.measure(199 / RATE)
    assert m.amplitude_m[99] == pytest.approx(PLATE.max_amplitude_m)
    assert np.all(m.faults[:100] & FaultBits.AMPLITUDE_LIMIT)
    assert np.all(m.faults[:100] & FaultBits.VOLTAGE_LIMIT)
    assert np.all(m.voltage_v[:100] == PLATE.max_voltage_v)
    layers = 2e-4 / 1560.0 + 9e-5 / 3.35  # stratum corneum and insulator (thesis 3.6)
    capacitance = EPS0 * 1e-4 / layers
    assert m.current_a[0] == pytest.approx(2 * math.pi * 440.0 * capacitance * 2000.0, rel=1e-6)
    assert m.amplitude_m[-1] < 1e-12 and m.voltage_v[-1] == 0.0 and m.faults[-1] == 0


def test_gain_errors_and_residual_vibration_are_the_hardware_s() -> None:
    plate = FaultyPlate(PlateFaults(uv_gain_error=0.01, ev_gain_error=-0.5,
                                    residual_amplitude_m=30e-9))
    _play_held(plate, PLATE.max_amplitude_m, 1000.0, 100)
    m = plate.measure(99 / RATE)
    assert m.amplitude_m[-1] == pytest.approx(1.01 * PLATE.max_amplitude_m + 30e-9, rel=1e-9)
    assert m.faults[-1] == 0  # the command was within the limit: the clamp does not see it
    assert m.voltage_v[-1] == pytest.approx(500.0)
    idle = FaultyPlate(PlateFaults(residual_amplitude_m=30e-9)).measure(10 / RATE)
    assert np.allclose(idle.amplitude_m, 30e-9)  # on from power-up: no frame needed


@pytest.mark.parametrize("delay_s", [0.0, 0.015])
def test_the_watchdog_acts_its_time_after_the_last_frame(delay_s: float) -> None:
    plate = FaultyPlate(PlateFaults(watchdog_delay_s=delay_s))
    _play_held(plate, 1e-6, 100.0, 10)
    m = plate.measure(0.1)
    off = (PLATE.watchdog_s + delay_s) * RATE + 9  # the last frame sent is frame 9
    tripped = np.flatnonzero(m.faults & FaultBits.WATCHDOG)
    assert tripped[0] == math.floor(off) + 1
    assert np.all(m.voltage_v[tripped] == 0) and m.amplitude_m[-1] < 1e-12
    assert m.amplitude_m[tripped[0] - 1] == pytest.approx(1e-6)  # held until then


# ---------------------------------------------------------------- the rendering on the host

def _card() -> pb.Card:
    return build.card(120, 80, taxtel_mm=(60, 80), textures=[
        build.texture(0.75, [build.grating_period(40.0, 0.2)], channel="uv",
                      locking="position"),
        build.texture(0.5, [build.spatial(1.0, 0.1, phase=3.0)], channel="uv",
                      locking="velocity")], texture_index=[0, 1])


def test_the_driver_misreads_the_card_as_its_faults_say() -> None:
    options = RenderOptions()
    card = _card()
    read = misread(card, RenderingFaults(phase_offset_rad=1.0, frequency_error=0.1,
                                         amplitude_error=-0.5, depth_error=-0.2), options)
    coarse, fine = read.textures[0].components[0], read.textures[1].components[0]
    assert coarse.frequency == pytest.approx(1.1 / 40.0)
    assert coarse.amplitude == pytest.approx(0.2 * 0.5 * 0.8)
    assert fine.phase == pytest.approx(4.0 - 2 * math.pi)  # wrapped to [-pi, pi]
    assert read.textures[1].baseline == pytest.approx(1.0 - 0.5 * 0.8)
    assert card.textures[0].components[0].frequency == 0.025  # the card itself untouched
    unlocked = misread(card, RenderingFaults(velocity_locked_below_mm=50.0), options)
    assert unlocked.textures[0].locking == pb.LOCKING_VELOCITY
    kept = misread(card, RenderingFaults(velocity_locked_below_mm=30.0), options)
    assert kept.textures[0].locking == pb.LOCKING_POSITION  # 40 mm is not below 30 mm
    assert misread(card, RenderingFaults(), options) == card


def test_the_driver_takes_the_finger_and_the_band_limit_as_its_faults_say() -> None:
    rendering = FaultyRendering(plate_profile(), RATE,
                                RenderingFaults(touch_offset_mm=2.0, touch_lag_s=0.004,
                                                band_limit_excess_hz=500.0))
    assert rendering.options.band_limit_hz == 1500.0
    rendering.load(_card())
    rendering.finger(0.010, 0.011, 30.0, 40.0, 0.5, True, 10_000)
    block = rendering.frames(100, 200, running=True, limits=(2.5e-6, 0.0))
    applied = [f for f in block.finger if f is not None]
    assert applied[0].x_mm == 32.0 and applied[0].placed_s == pytest.approx(0.015)
    assert block.finger.index(applied[0]) == 50  # frame 150, 15 ms: arrival + 4 ms
