"""Every built-in plugin implements the Protocol of its kind (hcard.plugins.kinds): the members
are there (isinstance on the runtime-checkable Protocols) and every method takes the Protocol's
parameters, by name and kind (inspect.signature)."""

from __future__ import annotations

import inspect
import warnings
from collections import Counter
from typing import Any

import click
import pytest

from hcard.cli.main import contributed_commands
from hcard.device.driver_table import HOST_DRIVERS
from hcard.physics.contracts import FrequencyResponse, TwoChannelModel
from hcard.physics.profile import channels_of
from hcard.plugins import (
    KINDS,
    PROTOCOL_OF_KIND,
    CommandPlugin,
    EncoderPlugin,
    HcardPluginWarning,
    PredictorPlugin,
    get_registry,
)
from hcard.plugins.lazy_plugins import LazyDriver, LazyEncoder
from hcard_builtins.encoders import BUILTIN_ENCODERS
from hcard_device.plugins import REFERENCE_DRIVERS

_POSITIONAL = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)


def _methods(protocol: type) -> dict[str, Any]:
    """The methods (not properties) a Protocol declares, with those of its bases."""
    found: dict[str, Any] = {}
    for klass in reversed(protocol.__mro__):
        for name, member in vars(klass).items():
            if not name.startswith("_") and inspect.isfunction(member):
                found[name] = member
    return found


def signature_mismatches(obj: Any, protocol: type) -> list[str]:
    """What in ``obj``'s methods does not take the parameters of ``protocol``'s.

    A Protocol parameter must be accepted under the same name and kind (positional or
    keyword-only), or by the implementation's ``*args`` / ``**kwargs``; a parameter the
    implementation adds must have a default.
    """
    problems = []
    for name, declared in _methods(protocol).items():
        wanted = list(inspect.signature(declared).parameters.values())[1:]  # without self
        given = inspect.signature(getattr(obj, name)).parameters
        has_var_kw = any(p.kind is p.VAR_KEYWORD for p in given.values())
        has_var_pos = any(p.kind is p.VAR_POSITIONAL for p in given.values())
        for param in wanted:
            match = given.get(param.name)
            if param.kind in (param.VAR_KEYWORD, param.VAR_POSITIONAL):
                if match is None or match.kind is not param.kind:
                    stars = "**" if param.kind is param.VAR_KEYWORD else "*"
                    problems.append(f"{name}: no {stars}{param.name}")
            elif match is None:
                if not (has_var_kw if param.kind is param.KEYWORD_ONLY else has_var_pos):
                    problems.append(f"{name}: no parameter {param.name!r}")
            elif (param.kind in _POSITIONAL) != (match.kind in _POSITIONAL):
                problems.append(f"{name}: {param.name!r} is {match.kind}, expected {param.kind}")
            elif param.default is not param.empty and match.default is param.empty:
                problems.append(f"{name}: {param.name!r} needs a default")
        named = {p.name for p in wanted}
        for extra in given.values():
            if extra.name not in named and extra.default is extra.empty and extra.kind not in (
                extra.VAR_KEYWORD, extra.VAR_POSITIONAL
            ):
                problems.append(f"{name}: extra parameter {extra.name!r} without a default")
    return problems


def _builtin_plugins() -> list[tuple[str, str, Any]]:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)  # third parties are not tested here
        registry = get_registry()
    return [(info.kind, info.name, info.obj) for info in registry.all() if info.package == "hcard"]


BUILTINS = _builtin_plugins()


def test_every_kind_has_builtins_and_a_protocol() -> None:
    assert set(PROTOCOL_OF_KIND) == set(KINDS)
    assert {kind for kind, _, _ in BUILTINS} == set(KINDS)
    # the 59 built-ins by kind (a new one is counted here on purpose)
    assert Counter(kind for kind, _, _ in BUILTINS) == {
        "encoder": 1, "predictor": 10, "driver": 6, "device-profile": 3, "calibration-effect": 9,
        "conformance-check": 23, "importer": 4, "exporter": 3,
    }


@pytest.mark.parametrize(
    ("kind", "name", "obj"), BUILTINS, ids=[f"{k}:{n}" for k, n, _ in BUILTINS]
)
def test_builtin_plugin_implements_the_protocol_of_its_kind(kind: str, name: str, obj: Any) -> None:
    protocol = PROTOCOL_OF_KIND[kind]
    assert isinstance(obj, protocol)
    assert (obj.kind, obj.name) == (kind, name)
    assert isinstance(obj.description, str) and obj.description
    assert signature_mismatches(obj, protocol) == []


def test_the_signature_check_finds_a_mismatch() -> None:
    class WrongEncoder:
        kind, name, description = "encoder", "wrong", "takes a path positionally only"

        def options(self, **values):  # type: ignore[no-untyped-def]
            return values

        def encode(self, path, options):  # type: ignore[no-untyped-def]
            return None

    wrong = WrongEncoder()
    assert isinstance(wrong, EncoderPlugin)  # the members are there ...
    assert signature_mismatches(wrong, EncoderPlugin) == [  # ... but not the parameters
        "encode: no parameter 'source'",
        "encode: no parameter 'progress'",
        "encode: no **options",
        "encode: extra parameter 'path' without a default",
    ]
    assert not isinstance(object(), PredictorPlugin)


def test_contributed_commands_implement_the_command_protocol() -> None:
    commands = contributed_commands()
    assert {"device", "play", "conformance"} <= set(commands)
    for name, command in commands.items():
        assert isinstance(command, CommandPlugin)
        assert signature_mismatches(command, CommandPlugin) == []
        loaded = command.load()
        assert isinstance(loaded, click.Command) and loaded.name == name


def test_device_profile_contracts_are_implemented_by_the_builtins() -> None:
    registry = get_registry()
    coupled = registry.get("predictor", "coupled")
    leakage = registry.get("predictor", "ev-charge-leakage")
    assert isinstance(coupled, TwoChannelModel)
    assert isinstance(leakage, FrequencyResponse)
    assert signature_mismatches(leakage, FrequencyResponse) == []
    uv, ev = channels_of(coupled)
    assert (uv, ev) == (coupled.uv, coupled.ev)
    two_channel = {name for name, obj in registry.predictors.items()
                   if isinstance(obj, TwoChannelModel)}
    assert two_channel == {"coupled"}


@pytest.mark.parametrize("lazy", HOST_DRIVERS + REFERENCE_DRIVERS, ids=lambda lazy: lazy.name)
def test_a_lazy_builtin_driver_says_what_its_class_says(lazy: LazyDriver) -> None:
    """The built-in drivers are listed without importing them (``hcard plugins`` stays fast);
    what they are listed as is their class's own, which implements the driver Protocol too."""
    driver = lazy.load()
    assert (lazy.name, lazy.description, lazy.schemes) == (
        driver.name, driver.description, driver.schemes)
    assert isinstance(driver, PROTOCOL_OF_KIND["driver"])
    assert signature_mismatches(driver, PROTOCOL_OF_KIND["driver"]) == []


@pytest.mark.parametrize("lazy", BUILTIN_ENCODERS, ids=lambda lazy: lazy.name)
def test_a_lazy_builtin_encoder_says_what_its_encoder_says(lazy: LazyEncoder) -> None:
    encoder = lazy.load()
    assert (lazy.name, lazy.description) == (encoder.name, encoder.description)
    assert isinstance(encoder, EncoderPlugin)
    assert signature_mismatches(encoder, EncoderPlugin) == []
    assert lazy.load() is encoder  # made once
