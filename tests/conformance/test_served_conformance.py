"""The suite against the reference device served in real time by another process, run twice
against the same running server (a vendor's device stays powered between runs).

What holds here is session-relative timing (spec/conformance.md section 5.2;
conformance/README.md, bench runs): boundaries and spatial phase are
judged on this session's echoes (a stale echo of the previous run once dropped 12 of 26
renders and failed 10 of 11 boundaries), the dynamics stream keeps a lead (the queue once ran
dry: 29-67 Hz measured for 400 Hz), the rise time is timed from the reported step (not from
the device's uptime), the safety check leaves the limits as it found them, and no case is
dropped.
"""

from __future__ import annotations

from served_device import served_device

from hcard_conformance.context import Context
from hcard_conformance.runner import run_suite
from hcard_device.drivers import open_device

SESSION_CHECKS = ("renderer.boundary", "renderer.spatial_phase", "device.dynamics",
                  "device.latency", "device.safety", "device.watchdog")


def test_session_relative_checks_pass_twice_against_one_running_server():
    reference = run_suite(Context.for_driver("reference"), ("renderer",),
                          select=("renderer.boundary", "renderer.spatial_phase"))
    expected = {(r.check, r.case) for r in reference.results}
    assert len(expected) >= 10
    with served_device("evita", cli=True) as served:
        with open_device(served.uri) as driver:
            hardware = driver.limits()
        runs = [run_suite(Context.for_driver(served.uri), ("renderer", "device"),
                          select=SESSION_CHECKS) for _ in range(2)]
        with open_device(served.uri) as driver:
            after = driver.limits()
    assert after == hardware  # the safety check restored what it lowered
    for report in runs:
        failed = [(r.check, r.case, r.outcome, r.detail) for r in report.results if not r.passed]
        assert not failed, failed
        cases = {(r.check, r.case) for r in report.results}
        assert expected <= cases  # every renderer case of the reference is judged, none dropped
        device = {(r.check, r.case) for r in report.results if r.level == "device"}
        assert device == {
            ("device.dynamics", "bandwidth"), ("device.dynamics", "rise-time"),
            ("device.latency", "boundary-move"), ("device.safety", "card-over-limit"),
            ("device.safety", "host-limits"), ("device.safety", "stream-extremes"),
            ("device.safety", "limits-while-driven"),
            ("device.watchdog", "host-silent"), ("device.watchdog", "fault-reported"),
        }
