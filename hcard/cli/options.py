"""Option values the commands read themselves, as usage errors: a plugin named on the command
line that is not installed, a quantity whose unit does not parse. Each is a
:class:`~hcard.errors.UsageError`, which the command line reports in one line with exit
status 2 (:mod:`hcard.cli.errors`)."""

from __future__ import annotations

from typing import Any

from hcard.cli.errors import option_values
from hcard.errors import UsageError
from hcard.physics.sweep import quantity
from hcard.plugins.registry import get_registry


def plugin_option(kind: str, name: str, option: str) -> Any:
    """The installed plugin ``name`` of ``kind`` that ``option`` names.

    Raises:
        UsageError: no plugin of that name is installed (the message lists the names).
        PluginError: the plugin is installed but cannot be used.
    """
    registry = get_registry()
    if name not in registry.of_kind(kind):
        installed = ", ".join(sorted(registry.of_kind(kind))) or "none installed"
        raise UsageError(f"{option}: no {kind} plugin named '{name}'; available: {installed}")
    return registry.get(kind, name)


def quantity_option(text: str, unit: str, option: str) -> float:
    """The value of ``option`` in SI ``unit`` (``"5s"``, ``"15 mN"``; a bare number is SI).

    Raises:
        UsageError: not a number, an unknown unit, a unit of another dimension, not finite.
    """
    with option_values():
        return quantity(text, unit, option)
