"""Check ``device.watchdog`` (PS3, PS4): outputs off and fault WATCHDOG reported when the host
goes silent.

The host goes silent while driving the finger; metric: time from the last host report to
outputs off (amplitude <= :data:`~.common.OFF_AMPLITUDE_M`, voltage <= 1 V) with fault WATCHDOG
reported, ms; threshold ``watchdog_ms`` + :data:`WATCHDOG_ALLOWANCE_S`.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np

from hcard import build
from hcard.device.base import Driver
from hcard.device.protocol import FaultBits, Finger, State
from hcard.quantities import MS_PER_S, NM_PER_M, S_PER_MS
from hcard_conformance.check_names import DEVICE_WATCHDOG as CHECK
from hcard_conformance.context import Context
from hcard_conformance.device_checks.common import (
    LEVEL,
    OFF_AMPLITUDE_M,
    READ_CATCH_UP_S,
    STROKE_SPEED_MM_S,
    judged,
)
from hcard_conformance.result import CheckResult, guarded

SEND_READ_BATCH = 10
"""Reports a sending loop reads at a time between two FINGER reports (:func:`_read_briefly`)."""
WATCHDOG_ALLOWANCE_S = 0.050
"""Time allowed after ``watchdog_ms`` for the 10 ms ramp and the plate's decay, s."""


def measure_watchdog(driver: Driver) -> tuple[float, bool, float]:
    """Stroke the host finger over a UV 0.3 card for 0.2 s, then go silent.

    Returns the time (s) from the last host report to outputs off (inf when they never go
    off), whether WATCHDOG was reported, and the plate amplitude before the silence (m). The
    silence is timed by the reports that echo the last FINGER report: by their echo age (the
    device's own account, PI3), or when read on a device without one; a host that reads its
    reports late keeps reading until they cover the silence (:data:`READ_CATCH_UP_S`)."""
    info = driver.info()
    w, h = info.surface_width_10um * 0.01, info.surface_height_10um * 0.01
    card = build.card(w, h, taxtel_mm=(w, h), textures=[build.texture(0.3, channel="uv")])
    driver.upload_card(card)
    driver.set_touch_source(host=True)
    driver.start()
    start = driver.clock()
    read: list[tuple[State, float]] = []  # each report and when it was read
    sent: list[int] = []
    last = start
    while driver.clock() < start + 0.2:
        last = driver.clock()
        driver.send_finger(last, w / 4 + STROKE_SPEED_MM_S * (last - start), h / 2, 0.5, True)
        sent.append(Finger.from_si(last, 0.0, 0.0, 0.0, False).host_time_us)
        read += [(s, driver.clock()) for s in _read_briefly(driver, 0.02)]
    silence_s = info.watchdog_ms * S_PER_MS + 0.2

    def since_last(batch: list[tuple[State, float]]) -> list[tuple[State, float]]:
        """The reports of ``batch`` after the last FINGER report, each with its time since
        it, s."""
        return [(s, s.echo_age_s if s.echo_age_s is not None else t - last)
                for s, t in batch if s.host_time_echo_us == sent[-1]]

    seen = since_last(read)
    covered = max((t for _, t in seen), default=-math.inf)  # silence the reports read cover
    catch_up = driver.clock() + silence_s + READ_CATCH_UP_S
    while driver.clock() < catch_up and covered < silence_s:
        batch = [(s, driver.clock()) for s in driver.collect_until(driver.clock() + 5e-4)]
        read += batch
        new = since_last(batch)
        seen += new
        covered = max([covered, *(t for _, t in new)])
    driver.stop()
    stroke = set(sent[:-1])
    driven_states = [s for s, _ in read if s.host_time_echo_us in stroke][-10:]
    driven = float(np.median([s.amplitude_m for s in driven_states])) if driven_states else 0.0
    watchdog = any(s.faults & FaultBits.WATCHDOG for s, _ in seen)
    on = [t for s, t in seen if s.amplitude_m > OFF_AMPLITUDE_M or s.voltage_v > 1.0]
    off = max(on, default=0.0)
    if not seen or seen[-1][0].amplitude_m > OFF_AMPLITUDE_M or seen[-1][0].voltage_v > 1.0:
        off = math.inf
    return off, watchdog, driven


def _read_briefly(driver: Driver, seconds: float) -> list[State]:
    """The reports read for ``seconds``, in batches of :data:`SEND_READ_BATCH`, so that a
    host with a backlog of reports (software emulation) returns on time to send its next
    FINGER report rather than drain the backlog while the device's watchdog runs out."""
    end = driver.clock() + seconds
    states: list[State] = []
    while (remaining := end - driver.clock()) > 0:
        states += driver.read_inputs(remaining, max_count=SEND_READ_BATCH)
    return states


WATCHDOG_CASES = ("host-silent", "fault-reported")
"""The cases of ``device.watchdog``, in order (both from one silence of the host)."""


def check_watchdog(ctx: Context) -> Iterator[CheckResult]:
    """Fault behaviour on host silence (spec PS3)."""
    if ctx.open_driver is None:
        return
    open_driver = ctx.open_driver

    def measure() -> Iterator[CheckResult]:
        with open_driver() as driver:
            limit = driver.info().watchdog_ms * S_PER_MS + WATCHDOG_ALLOWANCE_S
            off, reported, driven = measure_watchdog(driver)
        yield judged(CHECK, WATCHDOG_CASES[0], "time_to_off", off * MS_PER_S,
                      limit * MS_PER_S, "ms",
                      f"plate at {driven * NM_PER_M:.0f} nm before the host went silent; "
                      f"off means <= {OFF_AMPLITUDE_M * NM_PER_M:.0f} nm and <= 1 V")
        yield CheckResult(CHECK, LEVEL, WATCHDOG_CASES[1], reported,
                          "watchdog_fault", float(reported), 1.0, "bool",
                          "fault WATCHDOG in STATE")

    yield from guarded(CHECK, LEVEL, WATCHDOG_CASES, measure)
