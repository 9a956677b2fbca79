"""The simulated device: plate and PI amplitude loop, EV amplifier, sensors, a finger built from
the physics predictors, safety clamps and watchdog (spec/device-protocol.md, thesis chapters 4-5).

Usage (the firmware's view)::

    from hcard_device.sim import DeviceConfig, DeviceSimulation
    sim = DeviceSimulation(DeviceConfig.evita(), seed=0)
    report = sim.load_card(card)        # ClipReport: what the device cannot render
    sim.use_internal_finger(track)      # or sim.host_finger(t, x, y, normal_force_n, contact)
    sim.start()
    block = sim.step(1000)              # 0.1 s of 10 kHz frames: a SimBlock of arrays
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "ClipItem": "hcard.physics.card_clipping",
    "ClipReport": "hcard.physics.card_clipping",
    "DeviceConfig": "hcard_device.sim.config",
    "TOUCH_DTYPE": "hcard_device.sim.simulation",
    "DeviceSimulation": "hcard_device.sim.simulation",
    "Limits": "hcard_device.sim.simulation",
    "SimBlock": "hcard_device.sim.simulation",
}
"""Where each exported name lives. Resolved on first use (PEP 562), so a host that needs only
the configuration (``hcard_device.sim.config``, the conformance suite's device classes) does not
import the simulation, its plate filters and scipy.signal (over a minute under TCG)."""


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_EXPORTS[name]), name)
    globals()[name] = value
    return value


__all__ = [
    "TOUCH_DTYPE",
    "ClipItem",
    "ClipReport",
    "DeviceConfig",
    "DeviceSimulation",
    "Limits",
    "SimBlock",
]
