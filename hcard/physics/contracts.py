"""Optional contracts a predictor offers beyond :class:`~hcard.physics.Predictor`.

A device profile (:class:`~hcard.physics.profile.DeviceProfile`) asks for them with
``isinstance`` on these runtime-checkable Protocols instead of looking for attributes:

- :class:`TwoChannelModel`: a model rendering both channels, which exposes its UV
  relative-friction model and its EV force model (the coupled model of Eq. 4.1);
- :class:`FrequencyResponse`: a model with a gain over frequency (the stratum-corneum charge
  leakage of Eqs. 3.19-3.23), which scales the EV force at the carrier.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

if TYPE_CHECKING:
    import numpy as np

    from hcard.physics.predictor import Predictor


@runtime_checkable
class TwoChannelModel(Protocol):
    """A predictor composed of a UV and an EV model (``F_t = mu(w)(Fn + Fe)``, Eq. 4.1)."""

    @property
    def uv(self) -> Predictor:
        """The UV model: plate amplitude (m) to relative friction ``mu(w)/mu0``."""

    @property
    def ev(self) -> Predictor:
        """The EV model: voltage (V) to electrostatic force (N)."""


@runtime_checkable
class FrequencyResponse(Protocol):
    """A model with a gain over frequency."""

    def frequency_response(self, frequency: Any) -> np.ndarray:
        """Gain (dimensionless) at each ``frequency`` (Hz)."""
