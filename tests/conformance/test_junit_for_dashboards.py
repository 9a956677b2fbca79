"""The JUnit XML reads right on a CI dashboard: a case is red when it has a <failure> or an
<error> child, skipped when it has <skipped>, green otherwise, and the run is green only when no
case is red (how Jenkins, GitLab and GitHub's test reporters count)."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

from click.testing import CliRunner

from hcard.cli.main import cli
from hcard_conformance.report import junit_xml
from hcard_conformance.result import PASS, UNASSESSED, CheckResult
from hcard_conformance.runner import SuiteReport
from tests.helpers.conformance_pytest import collected, dashboard, pytest_run


def report_of(outcomes: list[str]) -> SuiteReport:
    report = SuiteReport("usbip://bench:3240/1-1", ("device",))
    report.results = [CheckResult("device.latency", "device", f"case-{k}", outcome == PASS,
                                  detail="the device flagged REALTIME_LAG", outcome=outcome)
                      for k, outcome in enumerate(outcomes)]
    return report


def test_a_run_of_only_unassessed_cases_is_not_green() -> None:
    colours = dashboard(junit_xml(report_of([UNASSESSED] * 9)))
    assert len(colours["skipped"]) == 9
    assert colours["red"] == ["hcard-conformance.conforms"]


def test_a_conforming_run_is_green_with_its_verdict_case() -> None:
    colours = dashboard(junit_xml(report_of([PASS] * 3)))
    assert colours["red"] == [] and colours["skipped"] == []
    assert "hcard-conformance.conforms" in colours["green"] and len(colours["green"]) == 4


def test_an_unreachable_device_still_writes_one_error(tmp_path: Path) -> None:
    junit = tmp_path / "out.xml"
    result = CliRunner().invoke(cli, ["conformance", "--driver", "usbip://127.0.0.1:9/1-1",
                                      "--junit", str(junit)])
    assert result.exit_code == 2
    xml = junit.read_bytes()
    assert dashboard(xml)["red"] == ["hcard-conformance.setup"]
    error = ET.fromstring(xml).find(".//error")
    assert error is not None and "cannot open driver 'usbip://127.0.0.1:9/1-1'" in error.get(
        "message", "")


def test_the_pytest_plugin_skips_unassessed_cases_with_their_reason(tmp_path: Path) -> None:
    run, xml = pytest_run(tmp_path, "--hcard-driver=control:drops-reports",
                          "--hcard-check=renderer.boundary")
    colours = dashboard(xml)
    assert colours["red"] == [] and colours["green"] == [], run.stdout[-2000:]
    assert len(colours["skipped"]) == 11
    assert all(name.startswith("renderer.boundary.") for name in colours["skipped"])
    reasons = [s.get("message", "") for s in ET.fromstring(xml).iter("skipped")]
    assert all("UNASSESSED" in reason and "lost" in reason for reason in reasons), reasons[0]
    times = [float(c.get("time", "0")) for c in ET.fromstring(xml).iter("testcase")]
    assert sum(times) > 0.1                        # the cases' own durations, not 0.000


def test_the_pytest_plugin_makes_an_unreachable_device_one_error(tmp_path: Path) -> None:
    run, xml = pytest_run(tmp_path, "--hcard-driver=usbip://127.0.0.1:9/1-1")
    assert run.returncode == 1 and "1 error" in run.stdout, run.stdout[-2000:]
    assert dashboard(xml)["red"] == ["hcard-conformance.setup"]


def test_the_pytest_plugin_collects_without_running(tmp_path: Path) -> None:
    """Every case, the device's included, is listed before anything runs: the wire-protocol
    checks apply to the control device (it speaks the protocol), device.friction lists the
    cases of its DEVICE_INFO."""
    from hcard_conformance.device_checks.safety import SAFETY_CASES

    run, _ = pytest_run(tmp_path, "--hcard-driver=control:drops-reports", "--collect-only")
    assert run.returncode == 0, run.stdout[-2000:]
    ids = collected(run.stdout)
    assert f"{len(ids)} tests collected" in run.stdout and "passed" not in run.stdout
    assert [i for i in ids if i.startswith("device.safety::")] == [
        f"device.safety::{case}" for case in SAFETY_CASES]
    assert {i.split("::")[0] for i in ids if i.startswith("device.")} == {
        "device.friction", "device.dynamics", "device.latency", "device.safety",
        "device.watchdog", "device.upload-integrity", "device.report-loss",
        "device.refusals", "device.descriptor", "device.session-ownership", "device.profile-upload",
        "device.host-driver", "device.saturation"}
    assert "device.friction::dense-grating" in ids
    assert not any(i.startswith("renderer.exact::") for i in ids)  # A0: the reference only
