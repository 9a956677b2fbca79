"""``hcard encode``, the device drivers and the simulated device take their plugins from the
plugin registry: with a registry whose ``image`` encoder, ``sim`` driver and UV model are
plugins registered in code (wrapping the built-ins), those are the ones used."""

from __future__ import annotations

import types
from collections.abc import Iterator
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

from hcard.card_io import load
from hcard.cli.main import cli
from hcard.plugins import EncodeResult, hookimpl
from hcard.plugins import registry as registry_module
from hcard.plugins.registry import PluginRegistry
from hcard_builtins.image import ImageEncoder
from hcard_builtins.physics.coupled import Coupled
from hcard_builtins.physics.electrovibration import ChargeLeakage
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from hcard_device.drivers import list_devices, open_device
from hcard_device.drivers.sim import SimDriver
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile


class CountingEncoder(ImageEncoder):
    """The image encoder, counting its calls and titling its cards."""

    calls: ClassVar[list[Path]] = []

    def encode(self, source: Path, **options: Any) -> EncodeResult:
        CountingEncoder.calls.append(Path(source))
        result = super().encode(source, **options)
        result.card.metadata.title = "through the registry"
        return result


class CountingSimDriver(SimDriver):
    """The sim:// driver, counting the devices it opens."""

    name: ClassVar[str] = "sim"
    opened: ClassVar[list[str]] = []

    @classmethod
    def open(cls, uri: Any, *, timeout_s: float = 1.0) -> Any:
        cls.opened.append(uri.text)
        return super().open(uri, timeout_s=timeout_s)


class SlipperyGroup(DimensionlessGroup):
    """The dimensionless group with half its relative friction (a vendor's variant)."""

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        return 0.5 * super()._forward(**inputs)


@pytest.fixture
def own_registry(monkeypatch: pytest.MonkeyPatch) -> Iterator[PluginRegistry]:
    """The process registry replaced by one holding only the plugins registered here."""
    plugin = types.ModuleType("vendor_variants")
    plugin.hcard_encoders = hookimpl(lambda: [CountingEncoder()])  # type: ignore[attr-defined]
    plugin.hcard_drivers = hookimpl(lambda: [CountingSimDriver])  # type: ignore[attr-defined]
    plugin.hcard_predictors = hookimpl(  # type: ignore[attr-defined]
        lambda: [SlipperyGroup(), Coupled(), ChargeLeakage()]
    )
    registry = PluginRegistry()
    registry.register(plugin, package="hcard", version="0")
    monkeypatch.setattr(registry_module, "_default", registry)
    CountingEncoder.calls.clear()
    CountingSimDriver.opened.clear()
    yield registry


def test_encode_uses_the_registered_image_encoder(own_registry: PluginRegistry,
                                                  tmp_path: Path) -> None:
    image = tmp_path / "ramp.png"
    Image.fromarray(np.tile(np.linspace(0, 255, 32, dtype=np.uint8), (16, 1))).save(image)
    card = tmp_path / "ramp.hcard"
    done = CliRunner().invoke(cli, ["-q", "encode", str(image), "-o", str(card),
                                    "--width-mm", "32"])
    assert done.exit_code == 0, done.output
    assert CountingEncoder.calls == [image]
    assert load(card).metadata.title == "through the registry"


def test_drivers_come_from_the_registry(own_registry: PluginRegistry) -> None:
    with open_device("sim://coupled") as driver:
        assert isinstance(driver, CountingSimDriver)
    assert CountingSimDriver.opened == ["sim://coupled"]
    assert {listing.driver for listing in list_devices(())} == {"sim"}
    with pytest.raises(Exception, match="no driver for scheme 'usbip'"):
        open_device("usbip://localhost")  # the built-in is not in this registry


def test_the_simulated_device_models_come_from_the_registry(own_registry: PluginRegistry) -> None:
    config = DeviceConfig.evita()
    model = device_profile(config).predictor
    assert isinstance(model, SlipperyGroup)
    reference = DimensionlessGroup(mu0=config.mu0, psi_star=config.psi_star)
    inputs = {"amplitude": np.asarray([1e-6]), "speed": np.asarray([0.02]),
              "normal_force": np.asarray([0.5])}
    assert model.forward(**inputs) == pytest.approx(0.5 * reference.forward(**inputs), rel=1e-12)
