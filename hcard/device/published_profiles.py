"""The physics profile a device publishes, found through the plugin registry.

A device renders with its own profile until a host uploads another (protocol 1.1). A kind of
device publishes its own as a ``device-profile`` plugin
(:class:`~hcard.plugins.kinds.DeviceProfilePlugin`; the reference device registers the
E-ViTa's and the coupled stimulator's), recognised from DEVICE_INFO.
"""

from __future__ import annotations

import warnings
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hcard.device.protocol import DeviceInfo
    from hcard.physics.profile import DeviceProfile


def published_profile(info: DeviceInfo) -> DeviceProfile | None:
    """The profile of the first installed ``device-profile`` plugin that recognises the device
    ``info`` describes, or None when none does."""
    from hcard.plugins.registry import get_registry

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # `hcard plugins` reports broken plugins
        plugins = get_registry().device_profiles
    for plugin in plugins.values():
        if plugin.matches(info):
            return plugin.profile()
    return None
