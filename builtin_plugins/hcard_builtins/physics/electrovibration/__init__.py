"""Electrovibration predictors (thesis chapter 3): the electrostatic force a voltage on an
insulated electrode exerts on a finger.

- :class:`StrongTroxel` (Eq. 3.3) and :class:`Kaczmarek` (Eq. 3.12): static parallel-plate
  laws; Strong-Troxel overestimates by orders of magnitude and is kept for comparison.
- :class:`AirLayer` (Eq. 3.17): an air layer in series, for a hovering finger.
- :class:`FingerGeometry` (Eq. 3.18): Eq. 3.17 summed over a curved, ridged finger pad
  (Table 3.2 dimensions).
- :class:`ChargeLeakage` (Eqs. 3.19-3.23): the stratum corneum leak turns the applied voltage
  into a high-passed effective voltage; time-domain :meth:`ChargeLeakage.simulate` and
  frequency response, with an optional ``tau_d(f)`` curve (Fig. 3.13).

All models output ``electrostatic_force`` in N and invert for the voltage amplitude.
"""

from .air_layer import AirLayer
from .geometry import FingerGeometry, FingerPatches, discretised_force
from .leakage import FIG_3_13_TREND, ChargeLeakage, LeakageResult, dominant_frequency
from .static import Kaczmarek, StrongTroxel

__all__ = [
    "FIG_3_13_TREND",
    "AirLayer",
    "ChargeLeakage",
    "FingerGeometry",
    "FingerPatches",
    "Kaczmarek",
    "LeakageResult",
    "StrongTroxel",
    "discretised_force",
    "dominant_frequency",
]
