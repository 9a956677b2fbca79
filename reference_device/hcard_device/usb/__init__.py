"""The reference device on USB: a USB-HID device built on :mod:`usbip` (pinned 0.7.0) and its
USB/IP server.

- :mod:`.device`: the HID interface (report descriptor, interrupt IN/OUT, GET/SET_REPORT) wired
  to the firmware; its strings (the VID:PID and endpoints are the protocol's,
  :mod:`hcard.device.protocol.usb_ids`).
- :mod:`.connection`: one client's connection, bounded and never waited for (spec rule PN15).
- :mod:`.transport`: USB/IP over TCP with ``TCP_NODELAY`` on every socket, connect timeouts, a
  bounded number of connections and a clean stop.
- :mod:`.server_log`: the server's log, which never blocks it.
- :mod:`.server`: :class:`~.server.DeviceServer` (firmware in real time with its report pump,
  listener) and ``python -m hcard_device.usb.server`` / ``hcard device serve``.
"""

from hcard_device.usb.device import HcardHID
from hcard_device.usb.server import DeviceServer
from hcard_device.usb.transport import NoDelayUSBIP

__all__ = ["DeviceServer", "HcardHID", "NoDelayUSBIP"]
