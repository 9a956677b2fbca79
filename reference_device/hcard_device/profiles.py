"""The configurations of the reference devices (E-ViTa and coupled stimulator) by name.

Each device publishes its own profile, the firmware's model at its hardware limits, as a
``device-profile`` plugin (:data:`hcard_device.plugins.REFERENCE_PROFILES`).
"""

from __future__ import annotations

from hcard_device.sim.config import DeviceConfig


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
