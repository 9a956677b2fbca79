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

``hcard plugins`` lists what is installed; :func:`get_registry` gives it to code.
"""

from __future__ import annotations

import importlib
from typing import Any

from hcard.plugins.kinds import KINDS, Encoder, EncodeResult

_LAZY = {
    "ENTRY_POINT_GROUP": "hookspecs", "PROJECT": "hookspecs", "hookimpl": "hookspecs",
    "hookspec": "hookspecs", "BrokenPlugin": "registry", "HcardPluginWarning": "registry",
    "PluginInfo": "registry", "PluginRegistry": "registry", "get_registry": "registry",
}
"""Names of the hook and registry modules, imported on first use: the plugin kinds alone (an
encoder's base class) do not need pluggy or the entry-point machinery (importlib.metadata)."""


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'hcard.plugins' has no attribute {name!r}")
    return getattr(importlib.import_module(f"hcard.plugins.{module}"), name)


__all__ = [
    "ENTRY_POINT_GROUP",
    "KINDS",
    "PROJECT",
    "BrokenPlugin",
    "EncodeResult",
    "Encoder",
    "HcardPluginWarning",
    "PluginInfo",
    "PluginRegistry",
    "get_registry",
    "hookimpl",
    "hookspec",
]
