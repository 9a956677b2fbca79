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

from hcard import build
from hcard.card_io import load
from hcard.cli.main import cli
from hcard.device import list_devices, open_device
from hcard.errors import UsageError
from hcard.plugins import EncodeResult, hookimpl
from hcard.plugins import registry as registry_module
from hcard.plugins.registry import PluginRegistry
from hcard_builtins.image import ImageEncoder
from hcard_builtins.physics.coupled import Coupled
from hcard_builtins.physics.electrovibration import ChargeLeakage
from hcard_builtins.physics.ultrasonic import DimensionlessGroup
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile
from hcard_device.sim_driver import SimDriver


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


class ContractOnlyEncoder:
    """An ``image`` encoder that is not the built-in (no EncodeOptions, no ImageEncoder): it
    keeps what ``hcard encode`` asks of it, and refuses a taxtel under 1 mm in options()."""

    kind, name, description = "encoder", "image", "a vendor's image encoder"

    def __init__(self) -> None:
        self.asked: list[dict[str, Any]] = []
        self.encoded: list[tuple[Path, dict[str, Any]]] = []

    def options(self, **values: Any) -> dict[str, Any]:
        self.asked.append(values)
        if values["taxtel_mm"] < 1.0:
            raise UsageError(f"taxtel_mm must be at least 1 mm here, got {values['taxtel_mm']}")
        return {"taxtel_mm": values["taxtel_mm"], "vendor_level": 3}

    def encode(self, source: Path, *, progress: Any = None, **options: Any) -> EncodeResult:
        self.encoded.append((Path(source), options))
        progress("vendor encoder at work")
        card = build.card(10.0, 10.0, taxtel_mm=options["taxtel_mm"],
                          textures=[build.texture(1.0, channel="uv", name="flat")],
                          texture_index=[0, 0, 0, 0], title="vendor")
        return EncodeResult(card=card, stats=dict(SUMMARY_STATS))


SUMMARY_STATS = {
    "image": "any.png", "image_width_px": 4, "image_height_px": 4, "image_mode": "L",
    "width_mm": 10.0, "height_mm": 10.0, "pixel_pitch_mm": [2.5, 2.5], "size_source": "given",
    "cols": 2, "rows": 2, "taxtel_mm": 5.0, "tile_px": [2, 2], "textures": 1,
    "distinct_textures": 1, "textured_taxtels": 0, "components": 0, "channel": "uv",
    "friction_range": [0.3, 1.0], "locking": "auto", "card_bytes": 40, "raw_bitmap_bytes": 10000,
    "rms_error": 0.0, "max_error": 0.0,
}
"""What the summary of ``hcard encode`` prints (the keys of the image encoder's stats)."""


@pytest.fixture
def contract_only(monkeypatch: pytest.MonkeyPatch) -> Iterator[ContractOnlyEncoder]:
    """The process registry replaced by one whose ``image`` encoder is a
    :class:`ContractOnlyEncoder`."""
    encoder = ContractOnlyEncoder()
    plugin = types.ModuleType("vendor_image_encoder")
    plugin.hcard_encoders = hookimpl(lambda: [encoder])  # type: ignore[attr-defined]
    registry = PluginRegistry()
    registry.register(plugin, package="hcard", version="0")
    monkeypatch.setattr(registry_module, "_default", registry)
    yield encoder


def test_encode_reaches_the_encoder_through_its_contract_only(
        contract_only: ContractOnlyEncoder, tmp_path: Path) -> None:
    """The command's options go to options(), and what it returns (not the command's options)
    to encode(), with progress: nothing of the built-in encoder is needed (on main, the command
    built hcard_builtins.image.EncodeOptions itself and handed it to encode)."""
    card = tmp_path / "vendor.hcard"
    done = CliRunner().invoke(cli, ["encode", str(tmp_path / "any.png"), "-o", str(card),
                                    "--taxtel-mm", "5", "--channel", "ev"])
    assert done.exit_code == 0, done.output
    (asked,) = contract_only.asked
    assert (asked["taxtel_mm"], asked["channel"], asked["max_error"]) == (5.0, "ev", None)
    assert contract_only.encoded == [(tmp_path / "any.png", {"taxtel_mm": 5.0,
                                                              "vendor_level": 3})]
    assert "hcard encode: vendor encoder at work" in done.stderr
    assert load(card).metadata.title == "vendor"


def test_an_option_the_encoder_refuses_is_a_usage_error_naming_it(
        contract_only: ContractOnlyEncoder, tmp_path: Path) -> None:
    card = tmp_path / "vendor.hcard"
    done = CliRunner().invoke(cli, ["encode", str(tmp_path / "any.png"), "-o", str(card),
                                    "--taxtel-mm", "0.5"])
    assert done.exit_code == 2
    assert done.stderr.splitlines()[-1] == (
        "Error: --taxtel-mm must be at least 1 mm here, got 0.5")
    assert contract_only.encoded == [] and not card.exists()
