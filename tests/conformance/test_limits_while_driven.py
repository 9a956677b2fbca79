"""device.safety case ``limits-while-driven`` (spec/conformance.md 4.4 S1; protocol PS1, PS5):
the reference device passes it in process and served in real time over USB/IP (twice against one
running server); the ``late-limits`` control (a plate left to decay to a lowered limit) and the
``over-limit`` control (a lowered limit never applied) fail it, and ``late-limits`` still passes
the limits set at rest."""

from __future__ import annotations

import re

import pytest

from hcard.device import open_device
from hcard_conformance.context import Context
from hcard_conformance.device_checks import safety
from hcard_conformance.result import CheckResult
from hcard_conformance.runner import run_suite
from hcard_device.controls import CONTROLS
from tests.helpers.realtime import assert_conforms
from tests.helpers.served_device import served_device

pytestmark = pytest.mark.wall_clock

CASE = "limits-while-driven"


def _safety(name: str) -> dict[str, CheckResult]:
    return {r.case: r for r in safety.check_safety(Context.for_driver(name))}


def _reports_after(result: CheckResult) -> tuple[int, int, float]:
    """(reports over, reports after the change, largest output / new limit) from the detail."""
    match = re.search(r"(\d+) of (\d+) reports after the SET.*largest output ([\d.]+) x",
                      result.detail)
    assert match, result.detail
    return int(match[1]), int(match[2]), float(match[3])


def test_the_case_is_part_of_the_safety_check() -> None:
    assert safety.SAFETY_CASES[-1] == CASE and "late-limits" in CONTROLS


@pytest.mark.parametrize("uri", ["sim://", "sim://coupled"])
def test_the_reference_device_keeps_every_report_after_the_change_under_the_new_limits(
        uri: str) -> None:
    result = _safety(uri)[CASE]
    assert result.passed and result.value == 0.0, result.detail
    over, after, ratio = _reports_after(result)
    assert over == 0 and after >= 45  # 50 ms of reports after the change
    assert 0.99 <= ratio <= 1.0 + 1e-3  # the plate is held at the new limit, not under it
    assert "read back the same" in result.detail and "plate at 2500 nm before" in result.detail


def test_late_limits_fails_the_case_and_passes_the_limits_set_at_rest() -> None:
    results = _safety("control:late-limits")
    late = results[CASE]
    assert not late.passed
    over, after, ratio = _reports_after(late)
    # 2.5 um left to decay to 625 nm: tau ln 4 = 2.2 ms, the first two reports after the SET.
    assert late.value == over == 2 and after >= 45
    assert ratio == pytest.approx(2.155, abs=0.01)  # 1347 nm against 625 nm
    assert results["host-limits"].passed and results["host-limits"].value == 0.0
    assert results["card-over-limit"].passed and results["stream-extremes"].passed


def test_over_limit_fails_the_case_at_every_report() -> None:
    result = _safety("control:over-limit")[CASE]
    over, after, ratio = _reports_after(result)
    assert not result.passed and result.value == over == after >= 45
    assert ratio == pytest.approx(4.0, abs=0.01)  # the plate stays at the 2.5 um hardware limit


def test_served_device_passes_the_case_twice_against_one_running_server() -> None:
    with served_device("evita") as served:
        with open_device(served.uri) as driver:
            hardware = driver.limits()
        runs = [run_suite(Context.for_driver(served.uri), ("device",), select=("device.safety",))
                for _ in range(2)]
        with open_device(served.uri) as driver:
            after = driver.limits()
    assert after == hardware  # the case restored the limits it lowered
    for report in runs:
        results = {r.case: r for r in report.results}
        assert set(results) == set(safety.SAFETY_CASES)
        assert_conforms(report.results)  # the machine's lateness fails saying so
        over, reports, ratio = _reports_after(results[CASE])
        assert over == 0 and reports >= 30 and ratio <= 1.0 + 1e-3
