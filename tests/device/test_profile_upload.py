"""Device profiles reach the device (spec/device-protocol.md 9.5, protocol 1.1): upload, atomic
swap, refusal with the previous profile kept, the device's own limits, and the way back."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hcard import build
from hcard.device import open_device
from hcard.device.errors import DeviceError
from hcard.device.play import play
from hcard.device.protocol import Capability, StateFlags, UploadResult
from hcard.device.recording import recording
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_effects import FittedEffect
from hcard.plugins.registry import get_registry
from hcard.track import straight_stroke
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile

EV_CARD = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
    build.texture(1.0, channel="ev", name="plain"), build.texture(1.08, channel="ev", name="ev")],
    texture_index=[0, 1], title="ev step")
STROKE = straight_stroke((2.0, 5.0), (40.0, 0.0), 0.45, normal_force_n=0.5)


def coupled_profile(**changes: float) -> DeviceProfile:
    own = device_profile(DeviceConfig.coupled())
    return own.replace(predictor=own.predictor.with_params(**changes))


def latest(driver):
    """The newest STATE report after 20 ms more of device time."""
    return driver.collect_until(driver.clock() + 0.02)[-1]


def voltage_on_ev_patch(driver, profile: bytes | None) -> float:
    m = recording(play(driver, EV_CARD, STROKE, profile=profile))
    on = (m.device["target_ev"] > 1.0) & m.contact
    return float(np.median(m.voltage[on]))


@pytest.mark.parametrize("uri", ["sim://coupled", "usbip://loopback?device=coupled"])
def test_an_uploaded_profile_changes_the_commands_and_the_device_goes_back(uri):
    smaller = coupled_profile(ev_area=5e-5)  # half the contact area: twice the force per V^2
    with open_device(uri) as driver:
        assert driver.info().capabilities & Capability.PROFILE
        assert (driver.info().protocol_major, driver.info().protocol_minor) >= (1, 1)
        own = voltage_on_ev_patch(driver, None)
        uploaded = voltage_on_ev_patch(driver, smaller.to_json())
        flags = latest(driver).flags
        assert flags & StateFlags.HOST_PROFILE
        driver.use_device_profile()
        assert not latest(driver).flags & StateFlags.HOST_PROFILE
        again = voltage_on_ev_patch(driver, None)
    # F ~ A V^2 (Eq. 3.12): half the area needs sqrt(2) times the voltage for the same force
    assert uploaded / own == pytest.approx(np.sqrt(2.0), rel=0.02)
    assert again == pytest.approx(own, rel=0.01)


def test_a_profile_with_an_effect_renders_through_it():
    air = FittedEffect(get_registry().calibration_effects["air-layer"], {"air_gap": 10e-6})
    profile = coupled_profile().replace(effects=(air,))
    with open_device("sim://coupled") as driver:
        own = voltage_on_ev_patch(driver, None)
        with_air = voltage_on_ev_patch(driver, profile.to_json())
    # independent: the voltage ratio the effect asks for at 0.5 N is 1/sqrt(factor) of Eq. 3.17
    d_e = 200e-6 / 1560.0 + 90e-6 / 3.35
    d, gap = 290e-6, 10e-6 / 0.5
    factor = d_e * d / ((d_e + gap) * (d + gap))
    assert with_air / own == pytest.approx(1.0 / np.sqrt(factor), rel=0.03)


def test_higher_limits_in_a_profile_do_not_raise_the_device_limits():
    limits = coupled_profile().limits
    greedy = coupled_profile().replace(limits=limits.__class__(
        max_amplitude=10e-6, max_voltage=10_000.0, max_current=1.0,
        carrier_frequency=limits.carrier_frequency, plate_frequency=limits.plate_frequency))
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(1.0, channel="ev", name="plain"),
        build.texture(3.0, channel="ev", name="way up")], texture_index=[0, 1])
    with open_device("sim://coupled") as driver:
        m = recording(play(driver, card, STROKE, profile=greedy.to_json()))
    assert m.voltage.max() <= 2000.0 + 1e-9
    assert m.column("current").max() <= 250e-6 + 1e-12


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"not json", "not valid JSON"),
        (json.dumps({"format": "hcard-calibrated-profile/1"}).encode(), "hcard-calibrated-prof"),
        (DeviceProfile(get_registry().get("predictor", "dimensionless-group"),
                       None).to_json(), "EV channel"),
    ],
)
def test_a_bad_profile_is_refused_with_its_reason_and_the_previous_stays(data, reason):
    smaller = coupled_profile(ev_area=5e-5)
    with open_device("sim://coupled") as driver:
        driver.upload_profile(smaller.to_json())
        before = voltage_on_ev_patch(driver, smaller.to_json())
        with pytest.raises(DeviceError, match="profile upload failed: INVALID_PROFILE") as info:
            driver.upload_profile(data)
        assert reason in str(info.value)
        status = driver.upload_status()
        assert status.result == UploadResult.INVALID_PROFILE
        assert latest(driver).flags & StateFlags.HOST_PROFILE  # the previous one stays
        m = recording(play(driver, EV_CARD, STROKE, profile=smaller.to_json()))
    on = (m.device["target_ev"] > 1.0) & m.contact
    assert float(np.median(m.voltage[on])) == pytest.approx(before, rel=0.01)


def test_an_e_vita_refuses_a_coupled_profile():
    with open_device("sim://evita") as driver, pytest.raises(DeviceError,
                                                               match="EV channel: the device"):
        driver.upload_profile(coupled_profile().to_json())
