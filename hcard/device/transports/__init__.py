"""The transports of the hcard HID protocol, each a leaf driver of :class:`hcard.device.Driver`:
USB/IP (:mod:`.usbip_client`, over :mod:`.usbip_link`), pyusb through an in-process USB/IP
backend (:mod:`.pyusb_driver`, :mod:`.pyusb_backend`) and hidapi (:mod:`.hidapi_driver`)."""
