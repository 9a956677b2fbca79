"""Built-in physics predictors (thesis chapters 1-4), registered through the ``hcard.plugins``
entry point ``builtin-predictors`` like any vendor's plugin.

Each model family has its own implementation of the ``hcard_predictors`` hook (pluggy's
``specname``), and each imports its module only when called. The registry calls every hook
implementation on its own, so if one family fails to import (or to build its defaults) it is
reported as a broken plugin, with the exception and its location, while the other families
still register.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hcard.plugins.hookspecs import hookimpl

if TYPE_CHECKING:
    from hcard.physics import Predictor


@hookimpl(specname="hcard_predictors")
def ultrasonic_predictors() -> list[Predictor]:
    """Ultrasonic friction reduction (chapter 2): squeeze film (Eqs. 2.1-2.8), spring-slider
    intermittent contact (Eqs. 2.19-2.28), dimensionless group (Eqs. 2.29-2.33)."""
    from hcard_builtins.physics.ultrasonic import DimensionlessGroup, SpringSlider, SqueezeFilm

    return [SqueezeFilm(), SpringSlider(), DimensionlessGroup()]


@hookimpl(specname="hcard_predictors")
def electrovibration_predictors() -> list[Predictor]:
    """Electrovibration force (chapter 3): Strong-Troxel (Eq. 3.3), Kaczmarek (Eq. 3.12), air
    layer (Eq. 3.17), finger geometry (Eq. 3.18), charge leakage (Eqs. 3.19-3.23)."""
    from hcard_builtins.physics.electrovibration import (
        AirLayer,
        ChargeLeakage,
        FingerGeometry,
        Kaczmarek,
        StrongTroxel,
    )

    return [StrongTroxel(), Kaczmarek(), AirLayer(), FingerGeometry(), ChargeLeakage()]


@hookimpl(specname="hcard_predictors")
def finger_predictors() -> list[Predictor]:
    """Finger friction (chapter 1, section 2.9.2.2): F_l = k Fn^n, speed and occlusion."""
    from hcard_builtins.physics.finger import FingerFriction

    return [FingerFriction()]


@hookimpl(specname="hcard_predictors")
def coupled_predictors() -> list[Predictor]:
    """The coupled UV + EV model of chapter 4, F_t = mu(w)(Fn + Fe) (Eq. 4.1)."""
    from hcard_builtins.physics.coupled import Coupled

    return [Coupled()]
