"""A plugin registered only through the registry (pluggy's register, in code) is used by the
tool: its subcommand runs from ``hcard`` and its predictor is evaluated by ``hcard predict``
and rendered by a device profile. A broken command plugin is warned about by name and the rest
of ``hcard`` keeps working."""

from __future__ import annotations

import math
import sys
import types
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import ClassVar

import click
import numpy as np
import pytest
from click.testing import CliRunner

from hcard.cli.main import cli
from hcard.physics import Parameter, Predictor, Variable
from hcard.physics.device_limits import DeviceLimits
from hcard.physics.profile import DeviceProfile
from hcard.plugins import HcardPluginWarning, LazyCommand, hookimpl
from hcard.plugins.registry import get_command_registry, get_registry
from tests.helpers.cli import run_python
from tests.helpers.distributions import install_distribution

MODULE = "hcardtest_contrib_commands"


class ExponentialFriction(Predictor):
    """``mu'(a) = exp(-a / a0)``: a relative friction falling with plate amplitude ``a``."""

    name: ClassVar[str] = "acme-exponential"
    description: ClassVar[str] = "exp(-a/a0) friction reduction"
    parameters: ClassVar[tuple[Parameter, ...]] = (
        Parameter("decay_amplitude", "m", 1.5e-6, (1e-9, 1e-3), "vendor fit", "a0"),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (Variable("amplitude", "m", "plate amplitude"),)
    inverse_input: ClassVar[str | None] = "amplitude"

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        return np.exp(-inputs["amplitude"] / self["decay_amplitude"])

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        return -self["decay_amplitude"] * np.log(np.clip(target, 1e-12, 1.0))


@click.command("acme-hello")
@click.argument("who")
def hello(who: str) -> None:
    """Greet WHO from the acme plugin."""
    click.echo(f"hello {who} from acme")


@pytest.fixture
def acme_plugin(monkeypatch: pytest.MonkeyPatch) -> Iterator[types.ModuleType]:
    """A plugin module with a subcommand and a predictor, registered in code in the registry
    of plugins and in that of commands; both are rediscovered afterwards."""
    commands = types.ModuleType(MODULE)
    commands.hello = hello  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, MODULE, commands)

    plugin = types.ModuleType("acme_plugin")
    plugin.hcard_commands = hookimpl(  # type: ignore[attr-defined]
        lambda: [LazyCommand("acme-hello", f"{MODULE}:hello", "Greet WHO from the acme plugin.")]
    )
    plugin.hcard_predictors = hookimpl(lambda: [ExponentialFriction()])  # type: ignore[attr-defined]
    get_registry().register(plugin, package="acme", version="1.0")
    get_command_registry().register(plugin, package="acme", version="1.0")
    yield plugin
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)
        get_registry(refresh=True)
        get_command_registry(refresh=True)


def test_a_registered_plugin_contributes_a_command(acme_plugin: types.ModuleType) -> None:
    runner = CliRunner()
    listing = runner.invoke(cli, ["--help"])
    assert listing.exit_code == 0
    assert "  acme-hello   Greet WHO from the acme plugin." in listing.output
    assert "  device " in listing.output  # the installed contributions are still there
    done = runner.invoke(cli, ["acme-hello", "Ada"])
    assert done.exit_code == 0, done.output
    assert done.output == "hello Ada from acme\n"


def test_a_registered_predictor_is_evaluated_by_predict(acme_plugin: types.ModuleType) -> None:
    done = CliRunner().invoke(
        cli, ["predict", "acme-exponential", "--input", "amplitude=3um", "--param",
              "decay_amplitude=1um"]
    )
    assert done.exit_code == 0, done.output
    last = done.stdout.strip().splitlines()[-1].split()
    # exp(-3 um / 1 um), as predict prints it: 6 significant digits (format_table in
    # hcard/cli/predict_cmd.py), within half a unit of the sixth, at most 5e-6 of the value
    assert float(last[-1]) == pytest.approx(math.exp(-3.0), rel=5e-6)


def test_a_registered_predictor_renders_through_a_device_profile(
    acme_plugin: types.ModuleType,
) -> None:
    model = get_registry().get("predictor", "acme-exponential").with_params(decay_amplitude=2e-6)
    limits = DeviceLimits(max_amplitude=5e-6, max_voltage=0.0, max_current=1e-15,
                          carrier_frequency=440.0, plate_frequency=38_220.0,
                          load_capacitance=None)
    profile = DeviceProfile(predictor=model, limits=limits, name="acme")
    amplitude = profile.amplitude_for(np.asarray([0.5]), np.asarray([0.02]), np.asarray([0.5]))
    # exp(-a/a0) = 1/2; the profile (no UV effects) calls the model's analytic inverse
    # -a0 * log(uv): equal up to rounding (numpy's log and math.log may differ by an ulp)
    assert amplitude == pytest.approx([2e-6 * math.log(2.0)], rel=1e-15)


BROKEN_COMMANDS = """
raise ImportError("acme CLI toolkit missing")
"""


def test_a_broken_command_plugin_is_named_and_hcard_keeps_working(tmp_path: Path) -> None:
    install_distribution(tmp_path, "broken-cli",
                         "[hcard.commands]\nbroken = hcardtest_broken_cli\n",
                         {"hcardtest_broken_cli": BROKEN_COMMANDS}, version="0.4")
    done = run_python("-m", "hcard", "--help", site=tmp_path, cache=tmp_path / "cache")
    assert done.returncode == 0, done.stderr
    assert ("warning: plugin 'broken' from package 'broken-cli' (version 0.4) failed to import "
            "'hcardtest_broken_cli': ImportError: acme CLI toolkit missing") in done.stderr
    assert "Traceback" not in done.stderr
    for name in ("conformance", "device", "play", "validate"):
        assert f"  {name} " in done.stdout
