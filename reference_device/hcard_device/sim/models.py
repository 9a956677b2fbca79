"""The physics predictors of a simulated device, as a :class:`~hcard.physics.profile.DeviceProfile`.

The same models serve twice: the firmware's model-based rendering (:mod:`hcard.physics.actuation`)
inverts them to turn targets into commands, and the simulated finger runs them forward on the
measured amplitude and voltage (:mod:`.finger`):

- UV: the dimensionless group ``mu' = 1 - exp(-Psi/Psi*)``, ``Psi = U / (w f mu0 (1 + nu))``
  (Eqs. 2.30-2.33) at the plate frequency;
- EV (coupled stimulator only): Kaczmarek's force (Eq. 3.12) of the carrier through the
  stratum-corneum leak (Eqs. 3.19-3.23, gain at the 440 Hz carrier), coupled by Eq. 4.1.

The models are the predictor plugins of these names in the plugin registry.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

from hcard.physics import Predictor
from hcard.physics.profile import DeviceProfile
from hcard_device.sim.config import DeviceConfig

UV_MODEL = "dimensionless-group"
"""The UV model (Eqs. 2.30-2.33), parameters ``mu0`` and ``psi_star``."""

COUPLED_MODEL = "coupled"
"""The coupled model (Eq. 4.1) of :data:`UV_MODEL` and Kaczmarek's force (Eq. 3.12), UV
parameters prefixed ``uv_``."""

LEAKAGE_MODEL = "ev-charge-leakage"
"""The stratum-corneum charge leakage (Eqs. 3.19-3.23)."""

MIN_PROFILE_CURRENT_A = 1e-15
"""A device profile needs a current limit > 0; a host limit of 0 A is enforced by the amplifier
(and the profile gets no EV voltage)."""


def device_profile(
    config: DeviceConfig,
    *,
    max_amplitude_m: float | None = None,
    max_voltage_v: float | None = None,
    max_current_a: float | None = None,
) -> DeviceProfile:
    """The device profile of ``config`` with its hardware limits, or lower ones.

    The profile is the firmware's model: its limits are ``config.limits`` with the lower ones
    given here, its load capacitance ``config.limits.load_capacitance`` (None: Eq. 3.8's,
    33 pF), whatever the physical finger's (``config.finger_capacitance_f``); the amplifier
    enforces the current limit on the physical load.

    A UV-only device (``limits.max_voltage == 0`` in the config) gets the dimensionless group
    alone; the coupled stimulator gets ``coupled`` (dimensionless group + Kaczmarek) with the
    charge-leakage gain at its carrier.
    """
    hardware = config.limits
    amplitude = hardware.max_amplitude if max_amplitude_m is None else max_amplitude_m
    voltage = hardware.max_voltage if max_voltage_v is None else max_voltage_v
    current = hardware.max_current if max_current_a is None else max_current_a
    if current <= 0:
        voltage, current = 0.0, MIN_PROFILE_CURRENT_A
    uv = _predictor(UV_MODEL).with_params(mu0=config.mu0, psi_star=config.psi_star)
    limits = replace(hardware, max_amplitude=amplitude, max_voltage=voltage, max_current=current)
    if not config.has_ev:
        return DeviceProfile(predictor=uv, limits=limits, name=config.name)
    return DeviceProfile(
        predictor=_predictor(COUPLED_MODEL).with_params(
            uv_mu0=config.mu0, uv_psi_star=config.psi_star
        ),
        limits=limits,
        leakage=_predictor(LEAKAGE_MODEL),
        name=config.name,
    )


def _predictor(name: str) -> Predictor:
    """The predictor plugin ``name`` of the plugin registry, at its default parameters."""
    from hcard.plugins.registry import get_registry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # `hcard plugins` reports broken plugins
        model = get_registry().get("predictor", name)
    if not isinstance(model, Predictor):
        raise TypeError(f"predictor plugin {name!r} is not an hcard.physics.Predictor")
    return model


def finger_capacitance(config: DeviceConfig) -> float:
    """Capacitance the EV amplifier drives through a finger in contact, F: the config's, else
    Eq. 3.8 from the EV model's layers (33 pF); 0 for a device without EV."""
    if not config.has_ev:
        return 0.0
    if config.finger_capacitance_f is not None:
        return config.finger_capacitance_f
    capacitance = device_profile(config).load_capacitance
    return 0.0 if capacitance is None else float(capacitance)
