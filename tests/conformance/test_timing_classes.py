"""Timing classes (spec/conformance.md section 5.2) and the run conditions every report states."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from hcard.cli.conformance_cmd import TIMING_NAMES
from hcard.cli.main import cli
from hcard_conformance.context import Context
from hcard_conformance.result import CannotAssess
from hcard_conformance.runner import run_suite
from hcard_conformance.streaming import STARVED_FRACTION, require_fed
from hcard_conformance.timing import REAL_TIME, TIMING_CLASSES


def test_cli_timing_names_are_the_timing_classes_default_first() -> None:
    assert tuple(TIMING_CLASSES) == TIMING_NAMES
    assert TIMING_NAMES[0] == REAL_TIME.name


def test_software_emulation_declares_host_timed_checks_not_applicable_and_loosens_d3() -> None:
    ctx = Context.for_driver("sim://")
    ctx.options["timing"] = "software-emulation"
    report = run_suite(ctx, ("device",), select=("device.latency", "device.friction",
                                                  "device.dynamics"))
    assert set(report.not_applicable) == {"device.friction", "device.dynamics"}
    (latency,) = report.results
    assert latency.threshold == 250.0 and latency.passed  # ms; the sim's latency is ~1 ms
    assert report.conditions["timing_class"] == "software-emulation"
    assert report.conditions["device_class"] == "e-vita"
    assert "DEVICE_INFO" in report.conditions["device_class_why"]


def test_the_report_states_the_conditions_and_rejects_an_unknown_class(tmp_path) -> None:
    out = tmp_path / "r.json"
    runner = CliRunner()
    result = runner.invoke(cli, ["conformance", "--driver", "sim://", "--level", "device",
                                 "--check", "device.latency", "-q", "--json", str(out)])
    assert result.exit_code == 0, result.output
    assert "timing class: real-time" in result.output
    report = json.loads(out.read_text())
    assert report["conditions"]["timing_class"] == "real-time"
    assert report["results"][0]["threshold"] == 10.0  # ms, D3 of a real-time host
    bad = runner.invoke(cli, ["conformance", "--driver", "sim://", "--option", "timing=warp"])
    assert bad.exit_code == 2 and "unknown timing class 'warp'" in bad.output


def test_a_starved_stream_is_not_assessed_only_beyond_the_fraction() -> None:
    reports = 700
    require_fed(int(STARVED_FRACTION * reports), reports, "at the bound")  # 35 of 700: judged
    with pytest.raises(CannotAssess, match="36 of 700 reports"):
        require_fed(int(STARVED_FRACTION * reports) + 1, reports, "one more")
