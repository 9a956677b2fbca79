"""acme_haptics: an hcard driver for a device that does not speak the hcard protocol.

The Acme TX-1 (simulated in :mod:`.plate`) takes actuator frames; hcard renders the card on
the host (:class:`hcard.device.frame_driver.FrameDriver`). The package registers the
``acme://`` driver and the TX-1's physics profile through one entry point (:mod:`.plugin`).
"""

__version__ = "0.1.0"
