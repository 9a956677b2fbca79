"""Physics predictors: actuation and finger state to friction, and back (spec/device-profile.md;
thesis chapters 2-4).

SI units inside (m, s, N, V, Hz, Pa); :mod:`hcard.quantities` converts user text such as
``"2um"`` or ``"27.5 kHz"`` at the boundary.
"""

from hcard.physics.predictor import Parameter, Predictor, PredictorError, Variable

__all__ = ["Parameter", "Predictor", "PredictorError", "Variable"]
