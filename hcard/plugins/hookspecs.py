"""Hook specifications of the hcard plugin system (pluggy project name ``hcard``).

A plugin is a module (or object) registered through the entry-point group ``hcard.plugins``
that implements one or more of these hooks with :data:`hcard.plugins.hookimpl`. Each hook
returns a list of plugin objects of one kind; every object has a ``name`` (unique within its
kind) and a one-line ``description``.
"""

from __future__ import annotations

from typing import Any

import pluggy

PROJECT = "hcard"
ENTRY_POINT_GROUP = "hcard.plugins"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def hcard_encoders() -> list[Any]:
    """Return encoders: objects turning a source (image, recipe, recording) into a card.

    See :class:`hcard.plugins.kinds.Encoder`.
    """


@hookspec
def hcard_predictors() -> list[Any]:
    """Return physics predictors: actuation and finger state to friction, and back."""


@hookspec
def hcard_drivers() -> list[Any]:
    """Return device drivers: transports that upload cards and stream tracks to a device."""


@hookspec
def hcard_calibration_effects() -> list[Any]:
    """Return calibration effects: physical effects a fitted model may lack."""


@hookspec
def hcard_conformance_checks() -> list[Any]:
    """Return conformance checks run by ``hcard conformance``."""
