"""Hook specifications of the hcard plugin system (pluggy project name ``hcard``).

A plugin is a module (or object) registered through the entry-point group ``hcard.plugins``
that implements one or more of these hooks with :data:`hcard.plugins.hookimpl`. Each hook
returns a list of plugin objects of one kind, matching that kind's Protocol in
:mod:`hcard.plugins.kinds`: every object has a ``name`` (unique within its kind) and a
one-line ``description``.

Subcommands come through the same hook system, from modules named in the entry-point group
``hcard.commands`` (:data:`COMMAND_ENTRY_POINT_GROUP`): ``hcard --help`` imports only those, so
they must be light (the command itself is imported when it runs).
"""

from __future__ import annotations

import pluggy

from hcard.plugins.kinds import (
    CheckPlugin,
    CommandPlugin,
    DriverPlugin,
    EffectPlugin,
    EncoderPlugin,
    PredictorPlugin,
)

PROJECT = "hcard"
ENTRY_POINT_GROUP = "hcard.plugins"
COMMAND_ENTRY_POINT_GROUP = "hcard.commands"

hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)


@hookspec
def hcard_encoders() -> list[EncoderPlugin]:
    """Return encoders: objects turning a source (image, recipe, recording) into a card."""


@hookspec
def hcard_predictors() -> list[PredictorPlugin]:
    """Return physics predictors: actuation and finger state to friction, and back."""


@hookspec
def hcard_drivers() -> list[DriverPlugin]:
    """Return device drivers: transports that upload cards and stream tracks to a device."""


@hookspec
def hcard_calibration_effects() -> list[EffectPlugin]:
    """Return calibration effects: physical effects a fitted model may lack."""


@hookspec
def hcard_conformance_checks() -> list[CheckPlugin]:
    """Return conformance checks run by ``hcard conformance``."""


@hookspec
def hcard_commands() -> list[CommandPlugin]:
    """Return subcommands of ``hcard`` (usually :class:`~hcard.plugins.kinds.LazyCommand`:
    name, import path, one-line summary), as pytest plugins add options."""
