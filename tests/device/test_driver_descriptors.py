"""The drivers read the device's HID report descriptor and HID descriptor (protocol PD1, PD2;
:meth:`Driver.report_descriptor`, :meth:`Driver.hid_descriptor`): the bytes the reference
device's USB interface declares, through ``sim://`` and the ``loopback`` USB/IP and pyusb
drivers, and a firmware's own descriptor where it declares another; a transport that cannot
read them says so (:class:`DescriptorUnavailable`). The hidapi driver is tested against a served
device in tests/device/test_drivers.py (tier 2).
"""

from __future__ import annotations

import struct

import pytest

from hcard.device import DescriptorUnavailable, DeviceError, Driver, open_device
from hcard.device.protocol import REPORT_DESCRIPTOR
from hcard.device.transports.usb_descriptors import hid_descriptor_in
from hcard.device.transports.usbip_client import UsbipDriver
from hcard_device.controls import open_control, state_declared_short
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import SimDriver
from hcard_device.usb.server import DeviceServer

pytestmark = pytest.mark.wall_clock  # the USB/IP servers run in real time

REFERENCE_HID_DESCRIPTOR = bytes.fromhex("09 21 1101 00 01 22 6f00")
"""bLength 9, HID descriptor, bcdHID 1.11, no country, one class descriptor: a report
descriptor of 0x006F = 111 bytes (HID 1.11 6.2.1)."""


def _fields(hid: bytes) -> tuple[int, int, int, int, int, int]:
    """bLength, bDescriptorType, bcdHID, bNumDescriptors, the first one's type and length."""
    length, kind, bcd, _country, count, first, first_length = struct.unpack("<BBHBBBH", hid)
    return length, kind, bcd, count, first, first_length


@pytest.mark.parametrize("uri", ["sim://", "sim://coupled", "usbip://loopback",
                                 "pyusb://loopback"])
def test_every_transport_reads_the_reference_descriptors(uri: str) -> None:
    with open_device(uri) as driver:
        descriptor = driver.report_descriptor()
        hid = driver.hid_descriptor()
    assert len(descriptor) == 111 and descriptor == REPORT_DESCRIPTOR
    assert descriptor[:6] == bytes.fromhex("0600FF0901A1")  # page 0xFF00, usage 1, Application
    assert hid == REFERENCE_HID_DESCRIPTOR
    assert _fields(hid) == (9, 0x21, 0x0111, 1, 0x22, 111)


class _ExtraByteFirmware(Firmware):
    """A firmware whose descriptor has one byte more than the protocol's (an End Collection
    too many): its HID descriptor must announce 112."""

    report_descriptor = REPORT_DESCRIPTOR + b"\xc0"


def test_a_firmware_declares_its_own_descriptor_and_its_length_follows() -> None:
    """What the firmware declares is what the wire carries, in process and over USB/IP (TCP
    on 127.0.0.1, served in this process)."""
    driver = SimDriver.open("sim://")
    driver.close()
    sim = SimDriver(driver.uri, _ExtraByteFirmware(DeviceSimulation(DeviceConfig.evita())))
    with sim:
        assert len(sim.report_descriptor()) == 112
        assert _fields(sim.hid_descriptor())[-1] == 112
    with DeviceServer(port=0, check_in_process=False,
                      firmware_factory=lambda: _ExtraByteFirmware(
                          DeviceSimulation(DeviceConfig.evita()))) as server, \
            UsbipDriver.open(server.uri) as served:
        assert served.report_descriptor() == REPORT_DESCRIPTOR + b"\xc0"
        assert _fields(served.hid_descriptor())[-1] == 112


def test_the_misdeclared_control_declares_state_one_byte_short() -> None:
    short = state_declared_short()
    differ = [i for i, (a, b) in enumerate(zip(short, REPORT_DESCRIPTOR, strict=True)) if a != b]
    assert differ == [0x13]  # the Report Count of STATE (section 4.2: 0012  95 3A)
    assert (REPORT_DESCRIPTOR[0x13], short[0x13]) == (58, 57)
    with open_control("misdeclared-state") as driver:
        assert driver.report_descriptor() == short
        assert _fields(driver.hid_descriptor())[-1] == 111  # the length is unchanged
    with pytest.raises(ValueError, match="does not declare STATE"):
        state_declared_short(short)


def test_the_hid_descriptor_is_found_after_its_interface() -> None:
    """Two interfaces, the HID one second: the HID descriptor after interface 1 is returned,
    not a class descriptor of interface 0; an interface without one has b"" (nothing
    announced)."""
    config_head = bytes.fromhex("09 02 0000 02 01 00 80 32")
    interface0 = bytes.fromhex("09 04 00 00 00 ff 00 00 00")
    vendor = bytes.fromhex("05 21 aa bb cc")  # a class descriptor of type 0x21 elsewhere
    interface1 = bytes.fromhex("09 04 01 00 01 03 00 00 00")
    hid = bytes.fromhex("09 21 1101 00 01 22 3412")
    endpoint = bytes.fromhex("07 05 81 03 4000 01")
    config = config_head + interface0 + vendor + interface1 + hid + endpoint
    assert hid_descriptor_in(config, 1) == hid
    assert _fields(hid_descriptor_in(config, 1))[-1] == 0x1234
    assert hid_descriptor_in(config, 0) == vendor  # what follows interface 0 is its own
    assert hid_descriptor_in(config, 2) == b""


class _NoDescriptorsSim(SimDriver):
    """``sim://`` as a vendor's driver without the optional primitives would be."""

    name = "plain"
    _report_descriptor = Driver._report_descriptor
    _hid_descriptor = Driver._hid_descriptor


def test_a_driver_without_descriptor_access_says_so() -> None:
    with _NoDescriptorsSim.open("sim://") as driver:
        with pytest.raises(DescriptorUnavailable, match="the plain driver cannot read the "
                           "device's report descriptor"):
            driver.report_descriptor()
        with pytest.raises(DescriptorUnavailable, match="HID descriptor"):
            driver.hid_descriptor()
        assert driver.info().protocol_major == 1  # the rest of the driver works
    with pytest.raises(DeviceError, match="closed"):
        driver.report_descriptor()
