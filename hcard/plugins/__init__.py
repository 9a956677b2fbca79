"""The hcard plugin system: pluggy hooks, plugin kinds and the registry of installed plugins.

A vendor package declares an entry point in the ``hcard.plugins`` group whose module implements
hooks of :mod:`hcard.plugins.hookspecs` with :data:`hookimpl`::

    # pyproject.toml of the vendor package
    [project.entry-points."hcard.plugins"]
    acme = "acme_hcard.plugin"

    # acme_hcard/plugin.py
    from hcard.plugins import hookimpl

    @hookimpl
    def hcard_encoders():
        return [AcmeEncoder()]

Each kind's contract is a Protocol of :mod:`hcard.plugins.kinds`. A package adds subcommands
to ``hcard`` with the ``hcard_commands`` hook, in a light module named by an entry point of the
``hcard.commands`` group (``hcard --help`` imports only those modules).

``hcard plugins`` lists what is installed; :func:`get_registry` gives it to code.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "ENTRY_POINT_GROUP": "hookspecs", "PROJECT": "hookspecs", "hookimpl": "hookspecs",
    "hookspec": "hookspecs", "BrokenPlugin": "records", "HcardPluginWarning": "records",
    "PluginInfo": "records", "PluginRegistry": "registry", "get_registry": "registry",
    "COMMAND_ENTRY_POINT_GROUP": "hookspecs", "get_command_registry": "registry",
    **dict.fromkeys(
        ("KINDS", "KIND_TABLE", "PROTOCOL_OF_KIND", "CheckPlugin", "CommandPlugin", "DriverPlugin",
         "EffectPlugin", "EncodeResult", "Encoder", "EncoderPlugin", "Plugin", "PredictorPlugin",
         "ExportResult", "ExporterPlugin", "ImporterPlugin", "Loss", "LOSS_FIELDS",
         "SNIFF_BYTES"),
        "kinds",
    ),
    "LazyCommand": "lazy_command",
    "LazyDriver": "lazy_plugins",
    "LazyEncoder": "lazy_plugins",
}
"""The module of each name, imported on first use: the plugin kinds alone (an encoder's base
class) do not need pluggy or the entry-point machinery (importlib.metadata), and ``hcard --help``
reads remembered commands without the kinds."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hcard.plugins' has no attribute {name!r}")
    return getattr(importlib.import_module(f"hcard.plugins.{module}"), name)


__all__ = [
    "COMMAND_ENTRY_POINT_GROUP",
    "ENTRY_POINT_GROUP",
    "KINDS",
    "KIND_TABLE",
    "LOSS_FIELDS",
    "PROJECT",
    "PROTOCOL_OF_KIND",
    "SNIFF_BYTES",
    "BrokenPlugin",
    "CheckPlugin",
    "CommandPlugin",
    "DriverPlugin",
    "EffectPlugin",
    "EncodeResult",
    "Encoder",
    "EncoderPlugin",
    "ExportResult",
    "ExporterPlugin",
    "HcardPluginWarning",
    "ImporterPlugin",
    "LazyCommand",
    "LazyDriver",
    "LazyEncoder",
    "Loss",
    "Plugin",
    "PluginInfo",
    "PluginRegistry",
    "PredictorPlugin",
    "get_command_registry",
    "get_registry",
    "hookimpl",
    "hookspec",
]
