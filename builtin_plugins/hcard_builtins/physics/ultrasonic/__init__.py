"""Ultrasonic (UV) friction predictors of thesis chapter 2.

- :class:`SqueezeFilm`: squeeze film levitation (Eqs. 2.1-2.8, Table 2.1), the classic model;
- :class:`SpringSlider`: intermittent contact of a massless spring-slider (Eqs. 2.19-2.28);
- :class:`DimensionlessGroup`: ``mu' = 1 - exp(-Psi/Psi*)`` with ``Psi = U / (w f mu0 (1+nu))``
  (Eqs. 2.29-2.33) and its closed-form inverse, for velocity-compensated rendering.

All take SI inputs (amplitude peak-to-peak in m, frequency in Hz, speed in m/s, normal force in
N, pressure in Pa) and give the relative friction ``mu' = mu / mu0``.
"""

from hcard_builtins.physics.ultrasonic.dimensionless import (
    PSI_STAR_PRESETS,
    DimensionlessGroup,
    PsiStarFit,
    PsiStarPreset,
    fit_psi_star,
)
from hcard_builtins.physics.ultrasonic.spring_slider import SpringSlider, relative_friction
from hcard_builtins.physics.ultrasonic.squeeze_film import SqueezeFilm

__all__ = [
    "PSI_STAR_PRESETS",
    "DimensionlessGroup",
    "PsiStarFit",
    "PsiStarPreset",
    "SpringSlider",
    "SqueezeFilm",
    "fit_psi_star",
    "relative_friction",
]
