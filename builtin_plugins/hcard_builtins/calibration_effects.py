"""Built-in calibration effects as an hcard plugin (entry point ``builtin-effects`` in the
``hcard.plugins`` group).

The effects (:mod:`hcard_builtins.effects`) need SciPy and the calibration package; this module
imports them only when the hook is called, so discovering the plugins (to find an encoder or a
driver) does not.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.plugins.hookspecs import hookimpl

if TYPE_CHECKING:
    from hcard.physics.effects import Effect


@hookimpl
def hcard_calibration_effects() -> list[Effect]:
    """The built-in calibration effects (spec/calibration.md), one instance each."""
    from hcard_builtins.effects import hcard_calibration_effects as builtin_effects

    return builtin_effects()
