"""``faulty://FAULT?strength=S`` — the conformance suite's faulty device, as a vendor's driver
of a frame device: the host renders the card (:class:`~hcard.device.frame_driver.FrameDriver`)
and the simulated plate (:mod:`.plate`) plays the frames. The fault and its strength
(:mod:`.faults`) go to the plate (device faults) or to the rendering on the host (driver
faults, :mod:`.host_faults`); ``faulty://none`` has none.
"""

from __future__ import annotations

from hcard.device.frame_device import FrameDevice
from hcard.device.frame_driver import FrameDriver
from hcard.device.host_rendering import HostRendering
from hcard.device.uri import DeviceUri
from hcard.physics.profile import DeviceProfile
from hcard_conformance.faulty.faults import DEVICE, DRIVER, SCHEME, parse_fault
from hcard_conformance.faulty.host_faults import FaultyRendering, RenderingFaults
from hcard_conformance.faulty.plate import FaultyPlate, PlateFaults


class FaultyDriver(FrameDriver):
    """The faulty device, simulated in this process on its own clock."""

    name = "faulty"
    description = ("the conformance suite's faulty device (one fault, one strength), rendered "
                   "on the host: faulty://FAULT?strength=S")
    schemes = (SCHEME,)

    def open_frame_device(self, uri: DeviceUri) -> FrameDevice:
        """The plate, with the device fault ``uri`` names.

        Raises:
            UriError: a URI :func:`~.faults.parse_fault` refuses.
        """
        return FaultyPlate(PlateFaults(**parse_fault(uri).on(DEVICE)))

    def host_rendering(self, profile: DeviceProfile, frame_rate_hz: float) -> HostRendering:
        """The rendering on the host, with the driver fault the URI names."""
        faults = RenderingFaults(**parse_fault(self.uri).on(DRIVER))
        return FaultyRendering(profile, frame_rate_hz, faults)
