"""Each device constant has one definition, with the thesis value (sections 2.4, 3.6.3, 4.2.1,
5.1.1), and the simulated devices, the predictors and the conformance vectors use it."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from hcard.bounded_read import DEFAULT_MAX_PIXELS
from hcard.calibration.dataset import ATMOSPHERE_PA
from hcard.cli.encode_cmd import encode
from hcard.device.protocol import FaultBits
from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS
from hcard.rates import DEFAULT_FRAME_RATE_HZ, TOUCH_RATE_HZ
from hcard.render.options import RenderOptions
from hcard_builtins.effects import ATMOSPHERE as EFFECTS_ATMOSPHERE
from hcard_builtins.image.loading import DEFAULT_MAX_PIXELS as LOADER_MAX_PIXELS
from hcard_builtins.physics.coupled import Coupled
from hcard_builtins.physics.electrovibration._common import EPSILON_0 as EV_EPSILON_0
from hcard_builtins.physics.ultrasonic.squeeze_film import ATMOSPHERE as FILM_ATMOSPHERE
from hcard_conformance.vectors.generate import TOLERANCES
from hcard_conformance.vectors.tracks import TOUCH_RATE_HZ as VECTOR_TOUCH_RATE_HZ
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceSimulation
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile


def test_the_coupled_stimulator_limits_are_the_thesis_values() -> None:
    limits = COUPLED_STIMULATOR_LIMITS
    assert limits.plate_frequency == 38_220.0  # section 4.2.1
    assert limits.carrier_frequency == 440.0  # section 4.2.1
    assert limits.max_current == pytest.approx(250e-6, rel=1e-15)  # section 3.6.3
    assert limits.max_amplitude == pytest.approx(2.5e-6, rel=1e-15)  # section 2.4


def test_the_simulated_devices_take_the_limits_from_the_profile() -> None:
    limits = COUPLED_STIMULATOR_LIMITS
    evita, coupled = DeviceConfig.evita().limits, DeviceConfig.coupled().limits
    assert coupled is limits
    assert (evita.max_amplitude, evita.max_current, evita.carrier_frequency) == (
        2.5e-6, 250e-6, 440.0)  # sections 2.4, 3.6.3
    assert evita.max_voltage == 0.0 and evita.plate_frequency == 60_750.0  # section 5.1.1
    assert Coupled.input_defaults["frequency"] == limits.plate_frequency


def test_the_device_reports_and_its_model_take_the_limits_from_the_config() -> None:
    for config in (DeviceConfig.evita(), DeviceConfig.coupled()):
        sim = DeviceSimulation(config)
        model = device_profile(config).limits
        assert model == config.limits  # the firmware's model renders with the hardware's limits
        assert sim.hardware_limits.max_amplitude_m == config.limits.max_amplitude
        assert sim.hardware_limits.max_voltage_v == config.limits.max_voltage
        assert sim.hardware_limits.max_current_a == config.limits.max_current
        info = Firmware(sim).device_info()
        assert info.plate_frequency_hz == round(config.limits.plate_frequency)
        assert info.ev_carrier_hz == (440 if config.has_ev else 0)
        # 2.5 um peak-to-peak (section 2.4) in nm; the I_s = 250 uA current limit of section
        # 3.6.3 in units of 10 nA; the 2000 V EV amplifier (UVA2kV, section 4.2.1) in 0.1 V
        assert info.max_amplitude_nm == 2500 and info.max_current_10na == 25_000
        assert info.max_voltage_dv == (20_000 if config.has_ev else 0)


def test_rates_are_the_thesis_values_everywhere() -> None:
    assert TOUCH_RATE_HZ == 50.0 and DEFAULT_FRAME_RATE_HZ == 10_000.0  # section 5.1.1
    assert DeviceConfig.evita().touch_rate_hz == TOUCH_RATE_HZ == VECTOR_TOUCH_RATE_HZ
    assert DeviceConfig.evita().frame_rate_hz == DEFAULT_FRAME_RATE_HZ
    assert TOLERANCES["frame_rate_hz"] == DEFAULT_FRAME_RATE_HZ == RenderOptions().frame_rate_hz


def test_physical_constants() -> None:
    assert 8.8541e-12 < EV_EPSILON_0 < 8.8543e-12  # Table 3.2 lists 8.8542e-12
    assert ATMOSPHERE_PA == EFFECTS_ATMOSPHERE == FILM_ATMOSPHERE == 101_325.0


def test_the_encoder_and_its_command_share_the_pixel_limit() -> None:
    option = next(p for p in encode.params if p.name == "max_pixels")
    assert option.default == DEFAULT_MAX_PIXELS == LOADER_MAX_PIXELS == 64_000_000


def _spec_fault_bits() -> dict[str, int]:
    """The fault flag table of spec/device-protocol.md: name -> bit value."""
    text = (Path(__file__).parents[2] / "spec" / "device-protocol.md").read_text()
    table = text[text.index("**Fault flags**"):].split("\n---")[0]
    return {m.group(2): 1 << int(m.group(1))
            for m in re.finditer(r"^\| (\d+) \| ([A-Z_]+) \|", table, re.M)}


def test_the_protocol_fault_bits_are_the_spec_table() -> None:
    spec = _spec_fault_bits()
    assert len(spec) == 11
    assert {flag.name: int(flag) for flag in FaultBits} == spec


def test_the_simulation_raises_the_protocol_bits() -> None:
    """A stream overrun and an invalid target in one step: the first frame carries bits 5 and 7
    of the spec's table, nothing else (the simulation has no fault numbering of its own)."""
    spec = _spec_fault_bits()
    sim = DeviceSimulation(DeviceConfig.coupled(), seed=5)
    sim.start()
    sim.host_finger(0.0, 40.0, 25.0, 0.5, True)
    sim.host_finger(sim.time_s, 40.0, 25.0, 0.5, True)
    sim.stream_frames(np.array([np.nan] * 10), np.full(10, 1.0))
    sim.stream_frames(np.full(DeviceConfig.coupled().stream_queue_frames, 0.9), 1.0)
    sim.feed_watchdog()
    block = sim.step(20)
    assert int(block.faults[0]) == spec["STREAM_OVERRUN"] | spec["INVALID_REQUEST"]
