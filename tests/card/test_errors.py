"""One error hierarchy: every exception class the four packages define derives from
:class:`hcard.errors.HcardError`, grouped by kind, and keeps the built-in bases callers catch."""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import click
import pytest
from click.testing import CliRunner

from hcard.cli.errors import EXIT_FAILED, UserErrorGroup
from hcard.errors import HcardError, InputError, UsageError

PACKAGES = ("hcard", "hcard_builtins", "hcard_device", "hcard_conformance")


def _modules() -> list[str]:
    names = []
    for package in PACKAGES:
        root = importlib.import_module(package)
        names.append(package)
        names += [info.name for info in pkgutil.walk_packages(root.__path__, f"{package}.")]
    return names


def _exception_classes() -> dict[str, type[BaseException]]:
    found = {}
    for name in _modules():
        module = importlib.import_module(name)
        for _, cls in inspect.getmembers(module, inspect.isclass):
            if (cls.__module__ == name and issubclass(cls, BaseException)
                    and not issubclass(cls, Warning)):
                found[f"{name}.{cls.__qualname__}"] = cls
    return found


def test_every_exception_class_derives_from_the_root():
    classes = _exception_classes()
    # The walk reaches all four packages (at least the classes named in hcard.errors' tree).
    assert {"hcard.errors.CardError", "hcard.device.errors.DeviceTimeout",
            "hcard_conformance.result.CannotAssess", "hcard.physics.predictor.PredictorError",
            "hcard_device.sim.hidden.catalogue.HiddenEffectError"} <= set(classes)
    outside = sorted(name for name, cls in classes.items() if not issubclass(cls, HcardError))
    assert outside == []


def test_device_timeout_is_a_timeout_error():
    from hcard.device import DeviceError, DeviceTimeout

    message = "usbip://127.0.0.1: GET_REPORT timed out after 1 s"
    with pytest.raises(TimeoutError):
        raise DeviceTimeout(message)
    assert issubclass(DeviceTimeout, DeviceError)


def test_device_timeout_is_one_line_on_the_command_line():
    """A timeout escaping a command is a user error (one line, status 1), not a bug."""
    from hcard.device import DeviceTimeout

    message = "usbip://127.0.0.1: GET_REPORT timed out after 1 s"

    @click.group(cls=UserErrorGroup)
    def cli() -> None:
        pass

    @cli.command()
    def play() -> None:
        raise DeviceTimeout(message)

    result = CliRunner().invoke(cli, ["play"])
    assert result.exit_code == EXIT_FAILED
    assert result.output == f"Error: {message}\n"


@pytest.mark.parametrize(("name", "group", "builtin"), [
    ("hcard.json_text.JsonInputError", InputError, ValueError),
    ("hcard.bounded_read.InputTooLarge", InputError, ValueError),
    ("hcard.quantities.UnitError", InputError, ValueError),
    ("hcard.physics.sweep.SweepError", InputError, ValueError),
    ("hcard_device.sim.hidden.HiddenEffectError", InputError, ValueError),
    ("hcard.calibration.measurement.MeasurementError", InputError, None),
    ("hcard.errors.CardValidationError", InputError, None),
    ("hcard.calibration.plan.PlanError", UsageError, None),
    ("hcard.render.renderer.RenderTooLong", UsageError, None),
    ("hcard.device.errors.PlayTooLong", UsageError, None),
])
def test_groups_and_the_builtin_bases_callers_catch(
    name: str, group: type[HcardError], builtin: type[Exception] | None
):
    """Each class is in its group and, where ``builtin`` is given, still a subclass of the
    built-in exception callers caught before the hierarchy (None: none is promised)."""
    module, _, cls_name = name.rpartition(".")
    cls = getattr(importlib.import_module(module), cls_name)
    assert issubclass(cls, group)
    if builtin is not None:
        assert issubclass(cls, builtin)
