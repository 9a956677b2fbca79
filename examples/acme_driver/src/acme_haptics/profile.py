"""The TX-1's physics profile, published to hcard (plugin kind ``device-profile``): the file
``acme-tx1.profile.json`` shipped in this package (spec/device-profile.md)."""

from __future__ import annotations

from importlib.resources import files
from typing import Any

PROFILE_FILE = "acme-tx1.profile.json"


class Tx1Profile:
    """Recognises a TX-1 from DEVICE_INFO (device kind 0, its plate frequency) and gives its
    profile."""

    kind = "device-profile"
    name = "acme-tx1"
    description = "Acme TX-1: UV, dimensionless group (thesis Eq. 2.33)"

    def matches(self, info: Any) -> bool:
        """``info`` (DEVICE_INFO) describes a TX-1."""
        from acme_haptics.plate import TX1  # on use: listing the plugins imports no device

        return (int(info.device_kind) == TX1.device_kind
                and int(info.plate_frequency_hz) == round(TX1.plate_frequency_hz))

    def profile(self) -> Any:
        """The profile (:class:`hcard.physics.profile.DeviceProfile`) from the shipped file."""
        from hcard.physics.profile import DeviceProfile

        data = files("acme_haptics").joinpath(PROFILE_FILE).read_bytes()
        return DeviceProfile.from_json(data, source=PROFILE_FILE)
