"""The faulty device's data sheet and the physics profile it publishes (through the
``device-profile`` plugin of :mod:`.plugin`, which recognises it from DEVICE_INFO by device
kind and plate frequency).

The device is a UV+EV plate with the coupled stimulator's amplifier and finger models (thesis
chapter 4: the ``coupled`` predictor, Eq. 4.1, with the stratum-corneum charge leakage of
Eqs. 3.19-3.23) on a faster 40 kHz plate, so the default (E-ViTa) device class holds it to
D1 400 Hz and D2 2 ms. Its faults change what it does, never what it publishes: the host
renders, and the conformance suite judges, with this one profile.
"""

from __future__ import annotations

import functools

from hcard.device.frame_device import FrameDeviceInfo
from hcard.device.protocol import DeviceInfo
from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS
from hcard.physics.profile import DeviceProfile

PLATE = FrameDeviceInfo(
    model="hcard faulty plate (simulated)", frame_rate_hz=10_000.0,
    plate_frequency_hz=40_000.0, ev_carrier_hz=COUPLED_STIMULATOR_LIMITS.carrier_frequency,
    max_amplitude_m=COUPLED_STIMULATOR_LIMITS.max_amplitude,
    max_voltage_v=COUPLED_STIMULATOR_LIMITS.max_voltage,
    max_current_a=COUPLED_STIMULATOR_LIMITS.max_current, width_mm=120.0, height_mm=80.0,
    watchdog_s=0.020, device_kind=0, lateral_force=False)
"""The data sheet: 10 kHz frames (the golden renders' rate), a 40 kHz plate to 2.5 um, EV to
2000 V at 440 Hz and 250 uA, the vectors' 120 x 80 mm surface, a 20 ms watchdog, no
lateral-force sensor (rendered friction is judged from the measured amplitude and voltage)."""


def is_faulty_plate(info: DeviceInfo) -> bool:
    """DEVICE_INFO ``info`` names :data:`PLATE`'s device kind and plate frequency (Hz): the
    two fields a ``device-profile`` plugin tells devices apart by."""
    return (int(info.device_kind), int(info.plate_frequency_hz)) == (
        PLATE.device_kind, round(PLATE.plate_frequency_hz))


@functools.cache
def plate_profile() -> DeviceProfile:
    """The profile of :data:`PLATE`: the coupled stimulator's models at its limits, the plate
    frequency its own (built once; a profile is immutable)."""
    from hcard.plugins.registry import get_registry

    leakage = get_registry().get("predictor", "ev-charge-leakage")
    return DeviceProfile.coupled_stimulator(
        leakage=leakage, plate_frequency=PLATE.plate_frequency_hz).replace(
        name="faulty-plate", description=f"{PLATE.model}: coupled UV+EV (thesis Eq. 4.1)")
