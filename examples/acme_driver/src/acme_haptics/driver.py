"""``acme://`` — the hcard driver of the Acme TX-1: hcard renders the card on the host and the
plate plays the frames (:class:`hcard.device.frame_driver.FrameDriver`).

URI: ``acme://tx1`` with options ``seed`` (measurement noise, default 0) and ``tau_ms``
(the simulated plate's envelope time constant, ms, default 0.25), e.g.
``acme://tx1?seed=3&tau_ms=0.3``.
"""

from __future__ import annotations

import math
from dataclasses import replace

from hcard.device.errors import UriError
from hcard.device.frame_device import FrameDevice
from hcard.device.frame_driver import FrameDriver
from hcard.device.uri import DeviceUri

from acme_haptics.plate import AcmePlate, PlatePhysics

MODELS = ("tx1",)
"""Models this driver opens (the URI's host part)."""


def _option(uri: DeviceUri, name: str, default: float, low: float, high: float) -> float:
    """A numeric URI option within [low, high]; UriError naming it otherwise."""
    text = uri.options.get(name)
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and low <= value <= high):
        raise UriError(f"bad device URI {uri.text!r}: option {name}={text!r} must be a number "
                       f"in [{low:g}, {high:g}] (expected e.g. acme://tx1?seed=3&tau_ms=0.25)")
    return value


class AcmeDriver(FrameDriver):
    """The TX-1, simulated in this process."""

    name = "acme"
    description = "Acme TX-1 friction plate (simulated), rendered on the host: acme://tx1"
    schemes = ("acme",)

    def open_frame_device(self, uri: DeviceUri) -> FrameDevice:
        """The plate the URI names."""
        model = uri.host or "tx1"
        if model not in MODELS:
            raise UriError(f"bad device URI {uri.text!r}: unknown model {model!r} (known: "
                           f"{', '.join(MODELS)})")
        unknown = sorted(set(uri.options) - {"seed", "tau_ms"})
        if unknown:
            raise UriError(f"bad device URI {uri.text!r}: unknown option {unknown[0]!r} "
                           "(known: seed, tau_ms)")
        seed = _option(uri, "seed", 0, 0, 2**32 - 1)
        if seed != int(seed):
            raise UriError(f"bad device URI {uri.text!r}: option seed must be an integer")
        tau_s = _option(uri, "tau_ms", 0.25, 0.01, 100.0) * 1e-3
        return AcmePlate(physics=replace(PlatePhysics(), tau_s=tau_s), seed=int(seed))
