"""FrameDriver: rendering on the host for a device that takes actuator frames, on an ideal
frame device (its plate is exactly the command; it records every frame it is sent)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hcard import build
from hcard.device.errors import DeviceError
from hcard.device.frame_device import FrameDevice, FrameDeviceInfo, Measurement
from hcard.device.frame_driver import HOST_SILENCE_S, FrameDriver
from hcard.device.host_rendering import FrameBlock, HostRendering
from hcard.device.protocol import ClipReason, FaultBits, Limits, StateFlags
from hcard.device.uri import DeviceUri
from hcard.physics.device_limits import DeviceLimits
from hcard.physics.profile import DeviceProfile
from hcard.plugins import get_registry

INFO = FrameDeviceInfo(model="ideal plate", frame_rate_hz=8000.0, plate_frequency_hz=30_000.0,
                       ev_carrier_hz=0.0, max_amplitude_m=2e-6, max_voltage_v=0.0,
                       max_current_a=0.0, width_mm=100.0, height_mm=60.0, watchdog_s=0.01)


class IdealPlate(FrameDevice):
    """Plays each frame's command exactly; remembers the frames it was sent."""

    def __init__(self) -> None:
        self.info = INFO
        self.frame = 0
        self.sent: dict[int, float] = {}

    def clock(self) -> float:
        return self.frame / INFO.frame_rate_hz

    def play(self, first_frame: int, amplitude_m: np.ndarray, voltage_v: np.ndarray) -> None:
        for k, value in enumerate(amplitude_m.tolist()):
            self.sent[first_frame + k] = value

    def measure(self, until_s: float) -> Measurement:
        last = math.floor(until_s * INFO.frame_rate_hz + 1e-9)
        frames = np.arange(self.frame, last + 1)
        self.frame = last + 1
        amplitude = np.array([self.sent.get(int(k), 0.0) for k in frames])
        zeros = np.zeros(frames.size)
        return Measurement(frames / INFO.frame_rate_hz, amplitude, zeros, zeros,
                           np.full(frames.size, np.nan), np.zeros(frames.size, dtype=np.uint16))


class IdealDriver(FrameDriver):
    name, schemes = "ideal", ("ideal",)

    def open_frame_device(self, uri: DeviceUri) -> FrameDevice:
        return IdealPlate()

    def device_profile(self) -> DeviceProfile:
        uv = get_registry().predictors["dimensionless-group"]
        return DeviceProfile(predictor=uv, limits=DeviceLimits(2e-6, 0.0, 1e-15, 1000.0, 30_000.0))


def opened() -> IdealDriver:
    return IdealDriver(DeviceUri("ideal://plate", "ideal"))


def uniform(friction: float) -> object:
    return build.card(100, 60, taxtel_mm=(100, 60),
                      textures=[build.texture(friction, channel="uv")])


def test_reports_come_every_millisecond_and_echo_the_finger() -> None:
    driver = opened()
    driver.upload_card(uniform(0.7))
    driver.set_touch_source(host=True)
    driver.start()
    driver.send_finger(0.0, 30.0, 30.0, 0.5, True)
    driver.send_finger(0.01, 30.6, 30.0, 0.5, True)
    states = driver.collect_until(0.02)
    stamps = np.array([s.timestamp_us for s in states])
    assert np.all(np.diff(stamps) == 1000) and np.all(stamps % 1000 == 0)
    assert [s.sequence for s in states] == list(range(len(states)))
    last = states[-1]
    assert last.host_time_echo_us == 10_000
    assert last.echo_age_us == last.timestamp_us - 10_000      # placed at its own time
    assert last.flags & StateFlags.RUNNING and last.flags & StateFlags.CONTACT
    assert last.target_uv == pytest.approx(0.7)
    assert last.amplitude_m > 0.1e-6


def test_lowered_limits_clamp_every_command_and_a_greedy_card_is_reported_clipped() -> None:
    driver = opened()
    outcome = driver.upload_card(uniform(0.0))            # needs an infinite amplitude
    assert outcome.clip.item_count == 1 and outcome.clip.reason == ClipReason.AMPLITUDE
    driver.set_limits(0.5e-6)
    assert driver.limits() == Limits(500, 0, 0)
    driver.set_touch_source(host=True)
    driver.start()
    states = []
    for k in range(20):
        driver.send_finger(k * 0.01, 20.0 + 0.6 * k, 30.0, 0.5, True)
        states += driver.collect_until((k + 1) * 0.01)
    played = [s for s in states if s.timestamp_us > 20_000]
    assert max(s.amplitude_m for s in played) == pytest.approx(0.5e-6, abs=1e-9)
    assert all(s.faults & FaultBits.AMPLITUDE_LIMIT for s in played)
    assert all(s.faults & FaultBits.CARD_CLIPPED for s in played)


class HalvedRendering(HostRendering):
    """Renders every command at half the amplitude the profile asks (a driver's own rendering)."""

    def frames(self, first: int, count: int, *, running: bool,
               limits: tuple[float, float]) -> FrameBlock:
        block = super().frames(first, count, running=running, limits=limits)
        block.amplitude_m[:] *= 0.5
        return block


class HalvingDriver(IdealDriver):
    def host_rendering(self, profile: DeviceProfile, frame_rate_hz: float) -> HostRendering:
        return HalvedRendering(profile, frame_rate_hz)


def test_a_driver_renders_with_the_host_rendering_it_makes() -> None:
    """FrameDriver.host_rendering is where a driver brings a rendering of its own: every frame
    the device plays comes from it (half the ideal driver's amplitude here)."""
    plain, halving = opened(), HalvingDriver(DeviceUri("ideal://plate", "ideal"))
    played = []
    for driver in (plain, halving):
        driver.upload_card(uniform(0.5))
        driver.set_touch_source(host=True)
        driver.start()
        for k in range(3):
            driver.send_finger(k * 0.01, 20.0 + 0.6 * k, 30.0, 0.5, True)
            states = driver.collect_until((k + 1) * 0.01)
        played.append(states[-1].amplitude_m)
    assert played[0] > 0.1e-6
    assert played[1] == pytest.approx(played[0] / 2, abs=1e-9)


def test_frames_stop_host_silence_after_the_last_output() -> None:
    driver = opened()
    device = driver.device
    assert isinstance(device, IdealPlate)
    driver.upload_card(uniform(0.5))
    driver.start()                                        # the last output, at t = 0
    driver.collect_until(0.2)
    fed_until = max(device.sent) / INFO.frame_rate_hz
    assert fed_until == pytest.approx(HOST_SILENCE_S, abs=1.5 / INFO.frame_rate_hz)
    assert driver.info().watchdog_ms == round((HOST_SILENCE_S + INFO.watchdog_s) * 1000)


def test_an_invalid_card_is_refused_and_the_previous_one_stays() -> None:
    driver = opened()
    driver.upload_card(uniform(0.5))
    bad = uniform(0.5)
    bad.grid.texture_index[0] = 3
    with pytest.raises(DeviceError, match=r"INVALID_CARD at grid.texture_index\[0\]"):
        driver.upload_card(bad)
    status = driver.upload_status()
    assert status.card_generation == 1 and status.detail.startswith("grid.texture_index")


def test_protocol_reports_a_frame_device_has_not_are_refused_by_name() -> None:
    from hcard.device.protocol import UploadBegin

    driver = opened()
    with pytest.raises(DeviceError, match="a frame device has no UPLOAD_BEGIN report"):
        driver.get_report(UploadBegin)


def test_without_a_published_profile_the_driver_says_whose_physics_is_missing() -> None:
    class Unpublished(IdealDriver):
        device_profile = FrameDriver.device_profile

    with pytest.raises(DeviceError, match="no installed device-profile plugin publishes the "
                                          "physics of the ideal plate"):
        Unpublished(DeviceUri("ideal://plate", "ideal"))


def test_the_wire_protocol_checks_apply_to_sim_but_not_to_a_frame_driver() -> None:
    from hcard_conformance.context import Context
    from hcard_conformance.wire_protocol import speaks_wire_protocol

    frame = Context("ideal://plate", opened)
    assert not speaks_wire_protocol(frame)
    assert speaks_wire_protocol(Context.for_driver("sim://"))
    assert not speaks_wire_protocol(Context.for_driver("reference"))
