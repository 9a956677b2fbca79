"""The simulated device: plate and PI amplitude loop, EV amplifier, sensors, a finger built from
the physics predictors, safety clamps and watchdog (DESIGN.md section 6, thesis chapters 4-5).

Usage (the firmware's view)::

    from hcard_device.sim import DeviceConfig, DeviceSimulation, Faults
    sim = DeviceSimulation(DeviceConfig.evita(), seed=0)
    report = sim.load_card(card)        # ClipReport: what the device cannot render
    sim.use_internal_finger(track)      # or sim.host_finger(t, x, y, fn, contact)
    sim.start()
    block = sim.step(1000)              # 0.1 s of 10 kHz frames: a SimBlock of arrays
"""

from hcard_device.sim.clip import ClipItem, ClipReport
from hcard_device.sim.config import DeviceConfig
from hcard_device.sim.faults import Faults
from hcard_device.sim.simulation import TOUCH_DTYPE, DeviceSimulation, Limits, SimBlock

__all__ = [
    "TOUCH_DTYPE",
    "ClipItem",
    "ClipReport",
    "DeviceConfig",
    "DeviceSimulation",
    "Faults",
    "Limits",
    "SimBlock",
]
