"""The reference devices' own profiles, as a host knows them from DEVICE_INFO.

A device renders with its own profile until a host uploads another (protocol 1.1). The
reference devices publish theirs: it is the firmware's model (:func:`hcard_device.sim.models.
device_profile`) at the hardware limits, and a host that recognises the device (its
``device_kind`` and plate frequency in DEVICE_INFO) can write it into a recording's sidecar
(spec/measurement-format.md rule MF9, key ``profile``), where ``hcard calibrate`` finds the base
model to calibrate.
"""

from __future__ import annotations

from typing import Any

from hcard.physics.profile import DeviceProfile
from hcard_device.protocol import DeviceInfo, DeviceKind
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.models import device_profile

VARIANT_OF_KIND = {DeviceKind.EVITA: "evita", DeviceKind.COUPLED: "coupled"}
"""The reference device variant of each DEVICE_INFO device kind."""


def variant_config(variant: str) -> DeviceConfig:
    """The configuration of the reference device ``variant`` (``evita`` or ``coupled``).

    Raises:
        ValueError: another variant.
    """
    if variant == "evita":
        return DeviceConfig.evita()
    if variant == "coupled":
        return DeviceConfig.coupled()
    raise ValueError(f"unknown device {variant!r}; known: evita, coupled")


def reference_profile(info: DeviceInfo) -> DeviceProfile | None:
    """The own profile of the reference device ``info`` describes, or None when ``info`` is not
    one of the reference devices (another kind, or another plate frequency)."""
    try:
        variant = VARIANT_OF_KIND[DeviceKind(info.device_kind)]
    except (KeyError, ValueError):
        return None
    config = variant_config(variant)
    if info.plate_frequency_hz != round(config.limits.plate_frequency):
        return None
    return device_profile(config)


def reference_profile_dict(info: DeviceInfo) -> dict[str, Any] | None:
    """:func:`reference_profile` as a profile file's JSON object, or None."""
    profile = reference_profile(info)
    return None if profile is None else profile.to_dict()
