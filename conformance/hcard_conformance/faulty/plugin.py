"""The faulty device's hcard plugin (entry point ``faulty-device`` in the group
``hcard.plugins``), registered as a vendor's would be: the ``faulty://`` driver as a row
(:class:`~hcard.plugins.lazy_plugins.LazyDriver`, imported when a ``faulty://`` device is
opened) and the device's profile."""

from __future__ import annotations

from typing import Any

from hcard.plugins import hookimpl
from hcard.plugins.lazy_plugins import LazyDriver

FAULTY_DRIVER = LazyDriver(
    "faulty", "the conformance suite's faulty device (one fault, one strength), rendered on "
    "the host: faulty://FAULT?strength=S", ("faulty",),
    "hcard_conformance.faulty.driver:FaultyDriver")
"""The driver's row; its name, description and schemes are the class's own (a test compares)."""


@hookimpl
def hcard_drivers() -> list[Any]:
    """The ``faulty://`` driver."""
    return [FAULTY_DRIVER]


class FaultyPlateProfile:
    """The faulty device's ``device-profile`` plugin: whatever its fault, a faulty device
    publishes one profile (a fault changes what the device does, never what it says it is);
    the device and the profile are imported when first asked for, not to list the plugin."""

    kind = "device-profile"
    name = "faulty-plate"
    description = "the conformance suite's faulty device: coupled UV+EV, 40 kHz plate"

    def matches(self, info: Any) -> bool:
        """``info`` (DEVICE_INFO) is a faulty device's
        (:func:`~hcard_conformance.faulty.profile.is_faulty_plate`)."""
        from hcard_conformance.faulty import profile

        return profile.is_faulty_plate(info)

    def profile(self) -> Any:
        """:func:`~hcard_conformance.faulty.profile.plate_profile`."""
        from hcard_conformance.faulty import profile

        return profile.plate_profile()


@hookimpl
def hcard_device_profiles() -> list[Any]:
    """The faulty device's profile."""
    return [FaultyPlateProfile()]
