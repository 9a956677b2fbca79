"""The package's hcard plugin (entry point ``acme`` in the group ``hcard.plugins``): the
``acme://`` driver and the TX-1's profile.

The driver is registered as a row (:class:`hcard.plugins.lazy_plugins.LazyDriver`: name,
description, schemes, where the class lives), so ``hcard plugins`` lists it without importing
it or the host library's driver code; it is imported when an ``acme://`` device is opened.
"""

from __future__ import annotations

from typing import Any

from hcard.plugins import hookimpl
from hcard.plugins.lazy_plugins import LazyDriver

ACME_DRIVER = LazyDriver(
    "acme", "Acme TX-1 friction plate (simulated), rendered on the host: acme://tx1",
    ("acme",), "acme_haptics.driver:AcmeDriver")
"""The driver's row; its name, description and schemes are the class's own (a test compares)."""


@hookimpl
def hcard_drivers() -> list[Any]:
    """The ``acme://`` driver."""
    return [ACME_DRIVER]


@hookimpl
def hcard_device_profiles() -> list[Any]:
    """The TX-1's physics profile."""
    from acme_haptics.profile import Tx1Profile

    return [Tx1Profile()]
