"""The reference device as an hcard plugin (entry point ``reference-device`` in the
``hcard.plugins`` group):

* its drivers, each a :class:`~hcard.plugins.lazy_plugins.LazyDriver`: ``sim://``, the
  device simulated in this process, which also provides the ``loopback`` host of ``usbip://``
  and ``pyusb://`` (:mod:`hcard.device.in_process`), and ``control:NAME``, the negative
  controls of the conformance suite (:mod:`hcard_device.controls`);
* the profiles its two devices publish (kind ``device-profile``), recognised from DEVICE_INFO
  by device kind and plate frequency.

Listing the plugins imports neither the firmware nor the simulation. The driver's name,
description and schemes below are its class's own, and the plate frequencies the devices'
configurations' (tests compare them).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from hcard.plugins.hookspecs import hookimpl
from hcard.plugins.lazy_plugins import LazyDriver

REFERENCE_DRIVERS: tuple[LazyDriver, ...] = (
    LazyDriver("sim", "in-process firmware and simulation on the driver's clock: "
               "sim://[evita|coupled]", ("sim",), "hcard_device.sim_driver:SimDriver"),
    LazyDriver("control", "negative controls of the conformance suite (faulty devices): "
               "control:NAME", ("control",), "hcard_device.controls:ControlDriver"),
)
"""sim:// and control:NAME, in the order ``hcard plugins`` lists them."""


@dataclass(frozen=True)
class ReferenceProfile:
    """The profile a reference device publishes: the firmware's model
    (:func:`hcard_device.sim.models.device_profile`) at the device's hardware limits.

    Attributes:
        variant: ``evita`` or ``coupled``.
        device_kind: its DEVICE_INFO ``device_kind``.
        plate_frequency_hz: its DEVICE_INFO ``plate_frequency_hz``.
        description: one line.
    """

    variant: str
    device_kind: int
    plate_frequency_hz: int
    description: str

    @property
    def kind(self) -> str:
        """``"device-profile"``."""
        return "device-profile"

    @property
    def name(self) -> str:
        """``reference-<variant>``."""
        return f"reference-{self.variant}"

    def matches(self, info: Any) -> bool:
        """The device ``info`` describes is this reference device (kind and plate frequency)."""
        return (int(info.device_kind) == self.device_kind
                and int(info.plate_frequency_hz) == self.plate_frequency_hz)

    def profile(self) -> Any:
        """The profile (:class:`hcard.physics.profile.DeviceProfile`)."""
        from hcard_device.profiles import variant_config
        from hcard_device.sim.models import device_profile

        return device_profile(variant_config(self.variant))


REFERENCE_PROFILES: tuple[ReferenceProfile, ...] = (
    ReferenceProfile("evita", 1, 60_750, "the reference E-ViTa's own profile (UV, thesis 5.1)"),
    ReferenceProfile("coupled", 2, 38_220,
                     "the reference coupled stimulator's own profile (UV + EV, thesis 4.2)"),
)
"""The profiles of the E-ViTa (device kind 1) and the coupled stimulator (device kind 2)."""


@hookimpl
def hcard_drivers() -> list[LazyDriver]:
    """The sim:// and control: drivers (:data:`REFERENCE_DRIVERS`)."""
    return list(REFERENCE_DRIVERS)


@hookimpl
def hcard_device_profiles() -> list[ReferenceProfile]:
    """The reference devices' own profiles (:data:`REFERENCE_PROFILES`)."""
    return list(REFERENCE_PROFILES)
