"""The package's hcard plugin (entry point ``acme`` in the group ``hcard.plugins``): the
``acme://`` driver and the TX-1's profile."""

from __future__ import annotations

from typing import Any

from hcard.plugins import hookimpl


@hookimpl
def hcard_drivers() -> list[Any]:
    """The ``acme://`` driver."""
    from acme_haptics.driver import AcmeDriver

    return [AcmeDriver]


@hookimpl
def hcard_device_profiles() -> list[Any]:
    """The TX-1's physics profile."""
    from acme_haptics.profile import Tx1Profile

    return [Tx1Profile()]
