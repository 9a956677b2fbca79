"""Tests of the host library (hcard.device) and of the reference device (hcard_device): the
protocol, the drivers, the firmware and simulation, the USB/IP server and the QEMU guest tier."""
