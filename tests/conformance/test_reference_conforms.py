"""CI runs the whole suite, every level, against the reference device through the command a
vendor runs (spec/conformance.md), and the reports it writes are complete."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

from click.testing import CliRunner

from hcard.cli.main import cli
from hcard_conformance.context import Context
from hcard_conformance.plan import plan_suite


def test_reference_device_passes_every_level(tmp_path):
    junit, report = tmp_path / "conformance.xml", tmp_path / "conformance.json"
    result = CliRunner().invoke(
        cli, ["conformance", "--driver", "sim://", "--junit", str(junit), "--json", str(report)]
    )
    assert result.exit_code == 0, result.output
    assert "CONFORMS" in result.output
    suites = ET.parse(junit).getroot().findall("testsuite")
    assert {s.get("name").split(".")[-1] for s in suites} >= {"format", "renderer", "device"}
    cases = sum(int(s.get("tests")) for s in suites)
    failures = sum(int(s.get("failures")) + int(s.get("errors", "0")) for s in suites)
    assert cases >= 100 and failures == 0
    data = json.loads(report.read_text())
    assert json.dumps(data).count('"passed": false') == 0
    assert json.dumps(data).count('"passed": true') >= 100
    # every check declared, before the run, the cases it reported (the pytest plugin's items)
    reported: dict[str, list[str]] = {}
    for result in data["results"]:
        reported.setdefault(result["check"], []).append(result["case"])
    plan = plan_suite(Context.for_driver("sim://"))
    assert {p.name: list(p.cases or ()) for p in plan.checks} == reported
    assert all(p.error is None for p in plan.checks)


def test_position_only_control_fails_through_the_command(tmp_path):
    result = CliRunner().invoke(
        cli, ["conformance", "--driver", "control:position-only", "--level", "renderer"]
    )
    assert result.exit_code == 1, result.output
    assert "FAIL" in result.output
