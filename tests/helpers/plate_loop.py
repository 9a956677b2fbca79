"""The E-ViTa plate loop's frequency response computed from its difference equations, the
independent reference of the D1 bandwidth tests (spec/conformance.md 4.1)."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from hcard_conformance.device_checks.dynamics import BANDWIDTH_REFERENCE_HZ
from hcard_device.sim import DeviceConfig
from hcard_device.sim.plate import PIGains, PlateModel

STREAM_FORCE_N = 0.5
"""The host finger's force while D1 streams, N (spec/conformance.md 4.1)."""


def plate_loop_response(frequency_hz: float, config: DeviceConfig,
                        normal_force_n: float = STREAM_FORCE_N) -> complex:
    """Closed-loop response amplitude/reference of the PI plate loop at ``frequency_hz``,
    from its difference equations in z: plant ``A[k+1] = a A[k] + (1 - a) G u[k]``, controller
    ``u = Kp e + I``, ``I[k+1] = I[k] + Ki T e[k]``, times the zero-order hold of one stream
    frame on the reference."""
    plate = PlateModel(config.limits.plate_frequency, config.plate_quality_factor,
                       config.finger_damping_per_n, config.full_drive_amplitude_m)
    gains = PIGains.ziegler_nichols(plate, config.pi_dead_time_s, config.pi_tuning_force_n)
    period = 1.0 / config.loop_rate_hz
    a = math.exp(-plate.decay_rate(normal_force_n) * period)
    z = complex(math.cos(2 * math.pi * frequency_hz * period),
                math.sin(2 * math.pi * frequency_hz * period))
    plant = (1 - a) * plate.full_drive_amplitude(normal_force_n) / (z - a)
    controller = gains.kp + gains.ki * period / (z - 1)
    loop = plant * controller
    return loop / (1 + loop) * float(np.sinc(frequency_hz / config.frame_rate_hz))


def plate_loop_db(frequency_hz: float, config: DeviceConfig) -> float:
    """The loop's gain at ``frequency_hz`` relative to the D1 reference frequency, dB."""
    return 20 * math.log10(abs(plate_loop_response(frequency_hz, config))
                           / abs(plate_loop_response(BANDWIDTH_REFERENCE_HZ, config)))


def plate_loop_bandwidth_hz(config: DeviceConfig) -> float:
    """The frequency where :func:`plate_loop_db` crosses -3 dB, Hz (searched in 100-490 Hz)."""
    return float(brentq(lambda f: plate_loop_db(f, config) + 3.0, 100.0, 490.0))
