"""Negative controls of the host driver: the ``sim://`` driver with one defect in the protocol
logic the host rules bind (spec/conformance.md section 6, rule QN1; the check
``device.host-driver``, section 4.10). The device behind each is the conforming reference
device; :mod:`hcard_device.controls` registers them as ``control:NAME``.

``host-accepts-any-major``
    DEVICE_INFO of any major version is taken as version 1: the driver uploads, starts and
    plays on a device whose protocol it does not implement (PV2).
``host-refuses-newer-minor``
    A minor version above the one this library implements is refused as if it were another
    major (PV3 asks the host to accept it).
``host-crashes-on-short-report``
    An input report is unpacked as a whole STATE before it is checked, so a short one raises
    ``struct.error`` out of ``read_inputs()`` (PE4: report it, do not crash).
``host-barges-in``
    ``check_free()`` does not look: the driver uploads and STARTs while another host's session
    is live (PN8).
"""

from __future__ import annotations

from hcard.device.base import Driver
from hcard.device.errors import DeviceError
from hcard.device.protocol import PROTOCOL_MINOR, DeviceInfo, State
from hcard_device.sim_driver import SimDriver


class AnyMajorHostDriver(SimDriver):
    """``sim://`` whose driver takes DEVICE_INFO of any major version
    (``host-accepts-any-major``)."""

    def info(self) -> DeviceInfo:
        """DEVICE_INFO, read once, never refused."""
        if self._info is None:
            info = self.get_report(DeviceInfo)
            assert isinstance(info, DeviceInfo)
            self._info = info
        return self._info


class NewerMinorRefusingDriver(SimDriver):
    """``sim://`` whose driver refuses a minor version above :data:`PROTOCOL_MINOR`
    (``host-refuses-newer-minor``)."""

    def info(self) -> DeviceInfo:
        """DEVICE_INFO; DeviceError for a minor this library does not know."""
        info = Driver.info(self)
        if info.protocol_minor > PROTOCOL_MINOR:
            self._info = None
            raise DeviceError(f"{self.uri}: the device speaks protocol {info.protocol_major}."
                              f"{info.protocol_minor}; this driver knows 1.0-1.{PROTOCOL_MINOR}")
        return info


class ShortReportCrashingDriver(SimDriver):
    """``sim://`` whose driver unpacks every input report as a whole STATE first
    (``host-crashes-on-short-report``)."""

    def parse_input(self, data: bytes) -> State | None:
        """Raises ``struct.error`` on a report shorter than STATE."""
        State.STRUCT.unpack_from(bytes(data), 0)
        return super().parse_input(data)


class BargingDriver(SimDriver):
    """``sim://`` whose driver never looks at the session before it changes the device
    (``host-barges-in``)."""

    def check_free(self) -> None:
        """Nothing: another host's session is not looked for."""
