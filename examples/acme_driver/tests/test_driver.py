"""acme:// through hcard: found by entry point, refuses bad URIs clearly, and plays a card the way
hcard's own renderer and physics say it should."""

from __future__ import annotations

import numpy as np
import pytest
from hcard import build
from hcard.device import open_device
from hcard.device.errors import DeviceError, UriError
from hcard.device.play import play
from hcard.device.protocol import Capability
from hcard.physics.actuation import actuate
from hcard.plugins import get_registry
from hcard.track import straight_stroke

from acme_haptics.driver import AcmeDriver


def test_the_entry_point_registers_the_driver_and_the_profile() -> None:
    registry = get_registry()
    row = registry.drivers["acme"]
    assert row.load() is AcmeDriver
    assert (row.name, row.description, row.schemes) == \
        (AcmeDriver.name, AcmeDriver.description, AcmeDriver.schemes)
    assert "acme-tx1" in registry.device_profiles
    with open_device("acme://tx1") as driver:
        assert isinstance(driver, AcmeDriver)
        info = driver.info()
        assert info.frame_rate_hz == 10_000 and info.plate_frequency_hz == 31_500
        assert info.capabilities & Capability.UV and not info.capabilities & Capability.EV
        assert info.watchdog_ms == 70          # 50 ms of host feeding + the plate's 20 ms
        assert driver.renders_on_host


@pytest.mark.parametrize(("uri", "fragment"), [
    ("acme://tx9", "unknown model 'tx9'"),
    ("acme://tx1?tau_ms=-1", "option tau_ms='-1' must be a number in [0.01, 100]"),
    ("acme://tx1?seed=x", "option seed='x'"),
    ("acme://tx1?speed=2", "unknown option 'speed'"),
])
def test_a_bad_uri_is_refused_naming_what_is_wrong(uri: str, fragment: str) -> None:
    with pytest.raises(UriError, match="bad device URI") as caught:
        open_device(uri)
    assert fragment in str(caught.value)


def test_an_invalid_card_is_refused_and_the_previous_one_kept() -> None:
    card = build.card(120, 80, taxtel_mm=(120, 80), textures=[build.texture(0.5, channel="uv")])
    with open_device("acme://tx1") as driver:
        driver.upload_card(card)
        bad = build.card(120, 80, taxtel_mm=(120, 80), textures=[build.texture(0.5)])
        bad.grid.texture_index[0] = 7                     # no texture 7
        with pytest.raises(DeviceError, match="INVALID_CARD"):
            driver.upload_card(bad)
        assert driver.upload_status().card_generation == 1


def test_a_played_card_follows_hcards_renderer_and_the_profiles_physics() -> None:
    """The targets the reports carry are the card's taxtel under the finger, and the plate
    amplitude, once settled, is what actuate() commands for them at the stroke's speed."""
    card = build.card(120, 80, taxtel_mm=(60, 80), texture_index=[0, 1], textures=[
        build.texture(0.6, channel="uv"), build.texture(0.8, channel="uv")])
    track = straight_stroke((20.0, 40.0), (60.0, 0.0), 1.0)
    with open_device("acme://tx1?seed=2") as driver:
        result = play(driver, card, track)
        profile = driver.device_profile()
    states = list(result.states)
    t = np.array([s.timestamp_us for s in states]) * 1e-6
    x = np.array([s.x_mm for s in states])
    target = np.array([s.target_uv for s in states])
    amplitude = np.array([s.amplitude_m for s in states])
    moving = (t > 0.1) & (t < 0.95) & (np.abs(x - 60.0) > 2.0)     # off the boundary
    expected = np.where(x[moving] < 60.0, 0.6, 0.8)
    np.testing.assert_allclose(target[moving], expected, atol=1e-4)
    commands = actuate(profile, target[moving], np.ones(moving.sum()), 0.06, 0.5)
    np.testing.assert_allclose(amplitude[moving], commands.amplitude, rtol=0.01, atol=2e-9)
    assert {round(v, 4) for v in target[moving]} == {0.6, 0.8}
