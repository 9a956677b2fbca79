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


def dashboard(xml: bytes) -> dict[str, list[str]]:
    """Each case's colour as a dashboard shows it, by ``classname.name``."""
    colours: dict[str, list[str]] = {"red": [], "skipped": [], "green": []}
    for case in ET.fromstring(xml).iter("testcase"):
        name = f"{case.get('classname')}.{case.get('name')}"
        if case.find("failure") is not None or case.find("error") is not None:
            colours["red"].append(name)
        elif case.find("skipped") is not None:
            colours["skipped"].append(name)
        else:
            colours["green"].append(name)
    return colours


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
