"""USB identity of a device speaking the hcard HID protocol: what a host looks for.

The numbers are the reference device's (spec/device-protocol.md section 2): a host driver
recognises an hcard device by its VID:PID and talks to its two interrupt endpoints.
"""

from __future__ import annotations

VID = 0x1209
"""pid.codes vendor ID (open-source hardware)."""
PID = 0x0001
"""pid.codes test PID: for development and testing only."""
IN_ENDPOINT = 0x81
"""Interrupt IN endpoint address (STATE reports)."""
OUT_ENDPOINT = 0x01
"""Interrupt OUT endpoint address (output reports)."""
