"""Benchmark: PS1 when the host lowers a limit while the plate is driven (spec PS5).

Run from the repository root::

    python bench/bench_limits_while_driven.py [--device evita|coupled] [--late]

The reference device (``sim://``, protocol path: :class:`~hcard_device.sim_driver.SimDriver`
over :class:`~hcard_device.firmware.Firmware`) streams UV 0 (and EV 4 on the coupled device)
while the host's finger slides at 60 mm/s and 0.5 N, so the plate sits at the amplitude limit
``--from-nm`` (set at rest first) and the EV output at its voltage limit. After 80 ms plus
``phase`` frames (0..9: every phase of the 1 kHz report clock) the host SETs LIMITS to
``--to`` times the hardware limits, then sends a FINGER report at once (the marker). Every STATE
report echoing the marker or a later FINGER is *after the change*; the table gives, per phase,
the largest reported amplitude, voltage and current after the change over the new limit, and the
number of such reports above it (PS1 allows none).

``--late`` runs the ``late-limits`` negative control instead (the device before PS5: the lowered
limit is in force at once, the drive is only cut and the plate decays at its own rate).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np

from hcard.device.protocol import State
from hcard.device.uri import parse_uri
from hcard_device.controls import LateLimitsSimulation
from hcard_device.firmware import Firmware
from hcard_device.sim import DeviceConfig, DeviceSimulation
from hcard_device.sim_driver import SimDriver

SET_AT_S = 0.080
"""Device time of the SET before the phase offset, s (the plate has settled at the limit)."""
AFTER_S = 0.040
"""Reports collected after the SET, s."""


@dataclass(frozen=True)
class Outcome:
    """The reports after the change of one run.

    Attributes:
        reports: reports after the change.
        over: reports with an output above its new limit (1 count of quantisation allowed).
        ratios: largest amplitude, voltage and current over its new limit.
        before_nm: plate amplitude of the last report before the SET, nm.
    """

    reports: int
    over: int
    ratios: tuple[float, float, float]
    before_nm: float


def _driver(device: str, late: bool) -> SimDriver:
    config = DeviceConfig.coupled() if device == "coupled" else DeviceConfig.evita()
    sim = LateLimitsSimulation(config) if late else DeviceSimulation(config)
    return SimDriver(parse_uri(f"sim://{device}"), Firmware(sim))


def run(device: str, late: bool, phase: int, from_m: float, to: float) -> Outcome:
    """One run: drive at ``from_m``, lower every limit to ``to`` times the hardware one at
    :data:`SET_AT_S` + ``phase`` frames, and judge the reports after the change."""
    driver = _driver(device, late)
    info = driver.info()
    hw = driver.limits()
    driver.set_limits(from_m, None, None)
    driver.set_touch_source(host=True)
    driver.start()
    rate = info.frame_rate_hz
    ev = 4.0 if device == "coupled" else 1.0
    set_at = SET_AT_S + phase / rate
    states: list[State] = []
    marks: list[int] = []
    t, lowered = 0.0, False
    while t < set_at + AFTER_S:
        host_us = round(driver.clock() * 1e6) + 1
        driver.send_finger(host_us * 1e-6, 20.0 + 60.0 * t, 25.0, 0.5, True)
        if lowered:
            marks.append(host_us)
        driver.stream_frames(np.zeros(100), np.full(100, ev))
        step_end = min(t + 0.010, set_at) if not lowered else t + 0.010
        states += driver.collect_until(step_end)
        t = driver.clock()
        if not lowered and t >= set_at - 1e-12:
            before = states[-1].amplitude_m
            driver.set_limits(hw.max_amplitude_m * to, hw.max_voltage_v * to,
                              hw.max_current_a * to)
            lowered = True
    driver.stop()
    after = [s for s in states if s.host_time_echo_us in set(marks)]
    new = (hw.max_amplitude_m * to, hw.max_voltage_v * to, hw.max_current_a * to)
    quanta = (1e-9, 0.1, 1e-8)
    over = np.zeros(len(after), dtype=bool)
    ratios = []
    for k, name in enumerate(("amplitude_m", "voltage_v", "current_a")):
        values = np.array([getattr(s, name) for s in after])
        over |= values > new[k] + quanta[k]
        ratios.append(float(values.max() / new[k]) if new[k] > 0 and values.size else 0.0)
    return Outcome(len(after), int(over.sum()), (ratios[0], ratios[1], ratios[2]),
                   before * 1e9)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--device", choices=("evita", "coupled"), default="evita")
    parser.add_argument("--late", action="store_true", help="the late-limits control")
    parser.add_argument("--from-nm", type=float, default=2000.0,
                        help="amplitude limit the plate is driven at, nm")
    parser.add_argument("--to", type=float, default=0.5,
                        help="new limits as a fraction of the hardware limits")
    args = parser.parse_args()
    print(f"{args.device}{' (late-limits control)' if args.late else ''}: driven at "
          f"{args.from_nm:.0f} nm, limits lowered to {args.to:g} x hardware")
    print("phase  before_nm  reports  over  max_amp/limit  max_V/limit  max_I/limit")
    worst = 0.0
    for phase in range(10):
        o = run(args.device, args.late, phase, args.from_nm * 1e-9, args.to)
        worst = max(worst, o.ratios[0])
        print(f"{phase:5d}  {o.before_nm:9.0f}  {o.reports:7d}  {o.over:4d}  "
              f"{o.ratios[0]:13.3f}  {o.ratios[1]:11.3f}  {o.ratios[2]:11.3f}")
    print(f"largest amplitude after the change: {worst:.3f} x the new limit")


if __name__ == "__main__":
    main()
