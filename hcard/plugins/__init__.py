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

from hcard.plugins.hookspecs import ENTRY_POINT_GROUP, PROJECT, hookimpl, hookspec
from hcard.plugins.kinds import KINDS, Encoder, EncodeResult
from hcard.plugins.registry import (
    BrokenPlugin,
    HcardPluginWarning,
    PluginInfo,
    PluginRegistry,
    get_registry,
)

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
