"""The hcard reference device: the E-ViTa firmware protocol and the coupled UV+EV stimulator,
simulated with honest physics and presented as a USB-HID device, plus the host drivers."""
