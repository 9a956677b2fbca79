"""A minimal vendor-defined USB-HID device on the `usbip` package, for the guest tier's smoke mode.

It proves the kernel path on its own (vhci-hcd, usbhid, hidraw, `usbip attach`) without the hcard
reference device: `python3 run_guest.py --mode echo` serves it on 127.0.0.1 and the guest payload
talks to it through `/dev/hidraw0`.

Reports (numbered, 8 data bytes each):
  input   ID 1  the last output report's data with every byte + 1 (mod 256)
  output  ID 2  (interrupt OUT endpoint 0x01)
  feature ID 3  SET stores the data; GET returns it reversed

Run: python3 echo_device.py --host 127.0.0.1 --port 3240   (serves until SIGTERM/SIGINT)
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from types import FrameType

import usbip
from usbip.classes.device import hid

VID, PID = 0x1209, 0x0001  # pid.codes test VID:PID
INPUT_ID, OUTPUT_ID, FEATURE_ID = 1, 2, 3
REPORT_LEN = 8  # data bytes, without the report ID


def report_descriptor() -> bytes:
    """Vendor page 0xFF00: one 8-byte input, output and feature report, IDs 1, 2, 3."""
    return b"".join(
        [
            hid.usage_page(0xFF00),
            hid.usage(0x01),
            hid.collection(0x01),
            hid.logical_min(0),
            hid.logical_max(255),
            hid.report_size(8),
            hid.report_id(INPUT_ID),
            hid.usage(0x01),
            hid.report_count(REPORT_LEN),
            hid.input_(0x02),
            hid.report_id(OUTPUT_ID),
            hid.usage(0x02),
            hid.report_count(REPORT_LEN),
            hid.output(0x02),
            hid.report_id(FEATURE_ID),
            hid.usage(0x03),
            hid.report_count(REPORT_LEN),
            hid.feature(0x02),
            hid.end_collection(),
        ]
    )


def echo_of(data: bytes) -> bytes:
    """The input report data the device answers an output report's data with."""
    return bytes((b + 1) & 0xFF for b in data)


class EchoHID(hid.HID):
    def __init__(self) -> None:
        super().__init__(
            report_descriptor(),
            in_ep=0x81,
            in_mps=64,
            in_interval=1,
            out_ep=0x01,
            out_mps=64,
            out_interval=1,
            get_report=self._get,
            set_report=self._set,
            on_output=self._output,
        )
        self._feature = bytes(REPORT_LEN)
        self.outputs = 0

    def _get(self, rtype: int, rid: int, length: int) -> bytes:
        if rtype == hid.REPORT_FEATURE and rid == FEATURE_ID:
            return bytes([FEATURE_ID]) + self._feature[::-1]
        if rtype == hid.REPORT_INPUT and rid == INPUT_ID:
            return bytes([INPUT_ID]) + bytes(REPORT_LEN)
        raise usbip.Stall

    def _set(self, rtype: int, rid: int, payload: bytes) -> None:
        if rtype == hid.REPORT_FEATURE and rid == FEATURE_ID and len(payload) == 1 + REPORT_LEN:
            self._feature = payload[1:]
            return
        if rtype == hid.REPORT_OUTPUT:
            self._output(payload)
            return
        raise usbip.Stall

    def _output(self, payload: bytes) -> None:
        if len(payload) != 1 + REPORT_LEN or payload[0] != OUTPUT_ID:
            return  # malformed: ignored, as a device would
        self.outputs += 1
        self.send_report(bytes([INPUT_ID]) + echo_of(payload[1:]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=3240)
    args = parser.parse_args(argv)

    stop = threading.Event()

    def on_signal(_signum: int, _frame: FrameType | None) -> None:
        stop.set()

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    dev = usbip.USBDevice(VID, PID, manufacturer="hcard", product="hcard guest echo HID")
    dev.add(EchoHID())
    with dev.plug(via=usbip.USBIP(args.host, args.port)):
        print(
            f"echo-device: serving {VID:04x}:{PID:04x} on {args.host}:{args.port} busid 1-1",
            flush=True,
        )
        while not stop.wait(0.5):
            pass
    print("echo-device: stopped", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
