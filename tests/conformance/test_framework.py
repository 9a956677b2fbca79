"""The conformance framework: results, registry, runner, reports, CLI and pytest plugin."""

from __future__ import annotations

import ast
import importlib
import inspect
import json
import math
import shutil
import subprocess
import sys
import types
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

from hcard.cli.main import cli
from hcard.plugins import hookimpl
from hcard.plugins.registry import PluginRegistry
from hcard_conformance.context import Context
from hcard_conformance.plan import plan_suite
from hcard_conformance.registry import (
    BUILTIN_CHECKS,
    Check,
    all_checks,
    builtin_checks,
    check,
    declared_cases,
)
from hcard_conformance.report import failure_message, json_bytes, junit_xml, table
from hcard_conformance.result import CheckResult, measured
from hcard_conformance.runner import SuiteReport, run_suite
from hcard_conformance.vectors import load_manifest

MANIFEST = load_manifest()


def test_measured_compares_value_with_threshold() -> None:
    assert measured("c", "renderer", "x", "A1", 0.05, 0.08).passed
    assert not measured("c", "renderer", "x", "A1", 0.081, 0.08).passed
    assert measured("c", "device", "x", "D1", 450.0, 400.0, higher_is_better=True).passed
    assert not measured("c", "device", "x", "D1", 350.0, 400.0, higher_is_better=True).passed
    assert not measured("c", "renderer", "x", "A1", math.nan, 0.08).passed
    with pytest.raises(ValueError, match="unknown conformance level"):
        CheckResult("c", "firmware", "x", True)


def test_check_decorator_registers_and_refuses_duplicates() -> None:
    mine: dict[str, Check] = {}

    @check(name="vendor.one", level="device", registry=mine)
    def one(ctx: Context) -> Iterator[CheckResult]:
        """First line is the description."""
        yield CheckResult("vendor.one", "device", "a", True)

    assert mine == {"vendor.one": one}
    assert one.description == "First line is the description."
    with pytest.raises(ValueError, match="already registered"):
        check(name="vendor.one", level="device", registry=mine)(lambda ctx: iter(()))
    with pytest.raises(ValueError, match="unknown conformance level"):
        check(name="vendor.two", level="wire", registry=mine)


def test_builtin_checks_are_ordered_by_level() -> None:
    checks = builtin_checks()
    names = [c.name for c in checks]
    for name in ("format.parse", "format.round_trip", "format.reject", "renderer.exact",
                 "renderer.friction_error", "renderer.boundary"):
        assert name in names
    levels = [c.level for c in checks]
    assert levels == sorted(levels, key=("format", "renderer", "device").index)
    assert levels.count("format") == 4
    assert [c.name for c in all_checks(("format",), plugins=False)] == [
        "format.parse", "format.round_trip", "format.reject", "format.compat"]


def test_every_row_of_the_builtin_table_names_a_check_function_of_its_level() -> None:
    """The table is the only place a built-in check's name is written: each row's function
    (and predicate) imports, and every public ``check_*`` function of the check modules is a
    row (a function left out of the table would never run)."""
    targets = {row.target for row in BUILTIN_CHECKS}
    assert len({row.name for row in BUILTIN_CHECKS}) == len(BUILTIN_CHECKS) == 23
    modules = {target.split(":")[0] for target in targets}
    for row in BUILTIN_CHECKS:
        assert callable(row.func) and row.name.split(".")[0] == row.level, row
        assert row.applies_target is None or callable(row.applies), row
    for module in modules:
        found = {f"{module}:{name}" for name, value in vars(importlib.import_module(module)).items()
                 if name.startswith("check_") and inspect.isfunction(value)
                 and value.__module__ == module}
        assert found <= targets, found - targets


def test_each_builtin_check_name_is_spelled_once() -> None:
    """A built-in check's name is a string in ``check_names.py`` only: the registry's rows, the
    checks' results and the negative controls refer to its constant (a name typed twice could
    drift apart, and a verdict would then name a check the registry does not list)."""
    from hcard_conformance import check_names

    names = {row.name for row in BUILTIN_CHECKS}
    assert names == {value for key, value in vars(check_names).items() if key.isupper()}
    conformance = Path(check_names.__file__).parent
    reference = Path(importlib.import_module("hcard_device").__file__ or "").parent
    spelled = []
    for path in [*conformance.rglob("*.py"), *reference.rglob("*.py")]:
        if path.name == "check_names.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and node.value in names:
                spelled.append(f"{path.name}:{node.lineno} {node.value}")
    assert spelled == []


def test_listing_the_plugins_imports_no_check_module_and_no_driver() -> None:
    """``hcard plugins`` lists 23 checks and hcard's 6 drivers from their tables (rows, not
    modules), whatever other drivers are installed; of the faulty device it imports the entry
    point's module, which holds the rows, and nothing of its driver."""
    code = ("import sys, warnings\n"
            "from hcard.plugins.registry import get_registry\n"
            "warnings.simplefilter('ignore')\n"
            "registry = get_registry(); registry.collect()\n"
            "print(len(registry.infos('conformance-check')),"
            " len([i for i in registry.infos('driver') if i.package == 'hcard']))\n"
            "print(sorted(m for m in sys.modules if m.startswith(('hcard_conformance.',"
            " 'hcard.device.base', 'hcard.device.protocol', 'hcard.device.transports',"
            " 'hcard_device.sim_driver', 'hcard_device.controls', 'hcard_device.usb',"
            " 'hcard_device.firmware'))))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    counts, imported = done.stdout.splitlines()
    assert counts.split() == ["23", "6"]  # usbip, pyusb, hid; sim, control; faulty
    assert ast.literal_eval(imported) == [
        "hcard_conformance.check_names", "hcard_conformance.faulty",
        "hcard_conformance.faulty.plugin", "hcard_conformance.registry",
        "hcard_conformance.result"]


def test_plugin_checks_join_the_suite() -> None:
    @check(name="acme.always", level="format", registry={})
    def always(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.always", "format", "one", "acme", 1.0, 2.0)

    plugin = types.ModuleType("acme_conformance")
    plugin.hcard_conformance_checks = hookimpl(lambda: [always])
    registry = PluginRegistry()
    registry.register(plugin, package="acme")
    chosen = all_checks(("format",), registry=registry)
    assert [c.name for c in chosen][-1] == "acme.always"
    report = run_suite(Context.for_driver("reference"), ("format",), checks=chosen)
    assert report.passed
    assert [r.case for r in report.results if r.check == "acme.always"] == ["one"]


def test_a_check_declares_its_cases_as_names_or_a_function_of_the_context() -> None:
    ctx = Context.for_driver("reference")

    def made(cases: object) -> Check:
        return check(name="acme.x", level="format", cases=cases)(lambda c: iter(()))

    assert declared_cases(made(("a", "b")), ctx) == ("a", "b")
    assert declared_cases(made(lambda c: [f"v{k}" for k in range(3)]), ctx) == ("v0", "v1", "v2")
    assert declared_cases(made(None), ctx) is None
    assert declared_cases(types.SimpleNamespace(name="acme.y", level="format"), ctx) is None
    for bad, why in (((("a", "a")), "declares case 'a' twice"), (("a", ""), "not a non-empty"),
                     ((3,), "declares a case 3")):
        with pytest.raises(ValueError, match=why):
            declared_cases(made(bad), ctx)


def test_every_builtin_check_declares_its_cases() -> None:
    """The pytest plugin lists a check's cases before it runs (spec QP3): every built-in row
    names a declaration, a tuple of names or a function, that resolves."""
    for row in BUILTIN_CHECKS:
        assert row.cases_target is not None, row.name
        assert callable(row.cases) or all(isinstance(c, str) for c in row.cases), row.name


def test_the_plan_names_the_cases_and_the_checks_that_cannot_say() -> None:
    """A check whose declaration raises is planned as one ERROR ``(error)`` saying so (QP5)
    and not run; one that does not apply is listed as such."""
    found: dict[str, Check] = {}

    def unreadable(ctx: Context) -> list[str]:
        raise OSError("vectors gone")

    @check(name="acme.fine", level="format", cases=("one",), registry=found)
    def fine(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.fine", "format", "one", "x", 0.0, 1.0)

    @check(name="acme.cannot-say", level="format", cases=unreadable, registry=found)
    def cannot_say(ctx: Context) -> Iterator[CheckResult]:
        raise AssertionError("a check whose cases are unknown is not run by the plan")

    @check(name="acme.device", level="device", cases=("d",), registry=found)
    def device(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.device", "device", "d", "x", 0.0, 1.0)

    plan = plan_suite(Context.for_driver("reference"), checks=list(found.values()))
    assert [(p.name, p.cases) for p in plan.checks] == [("acme.fine", ("one",)),
                                                        ("acme.cannot-say", None)]
    error = plan.checks[1].error
    assert error is not None and (error.case, error.status) == ("(error)", "ERROR")
    assert "raised OSError: vectors gone" in error.detail
    assert error.detail.endswith("while declaring its cases")
    assert plan.not_applicable == ["acme.device"]  # no driver: device checks do not apply


def test_a_context_wants_every_case_of_a_check_it_does_not_narrow() -> None:
    ctx = Context.for_driver("reference")
    assert ctx.wants("renderer.boundary", "edge@reversal")
    ctx.selected_cases = {"renderer.boundary": frozenset({"edge@slow-stroke"})}
    assert ctx.wants("renderer.boundary", "edge@slow-stroke")
    assert not ctx.wants("renderer.boundary", "edge@reversal")
    assert ctx.wants("renderer.friction_error", "edge@reversal")
    report = run_suite(ctx, ("renderer",), select=["renderer.boundary"])
    assert [r.case for r in report.results] == ["edge@slow-stroke"]


def test_cli_lists_the_cases_of_a_run_without_measuring() -> None:
    """``hcard conformance --list``: the plan's node IDs, in the order a run reports them
    (format level: both files of every card, then every card, then every invalid vector, then
    every compatibility file and the JSON writer)."""
    result = CliRunner().invoke(cli, ["conformance", "--driver", "reference", "--level",
                                      "format", "--list"])
    assert result.exit_code == 0, result.output
    assert result.stdout.splitlines() == [
        *(f"format.parse::{c.name}.{form}" for c in MANIFEST.cards for form in ("binary",
                                                                                  "json")),
        *(f"format.round_trip::{c.name}" for c in MANIFEST.cards),
        *(f"format.reject::{v.name}" for v in MANIFEST.invalid),
        *(f"format.compat::{c.case}" for c in MANIFEST.compat), "format.compat::json-writer"]


def _crashing_checks() -> list[Check]:
    checks: dict[str, Check] = {}

    @check(name="t.crash", level="format", registry=checks)
    def crash(ctx: Context) -> Iterator[CheckResult]:
        yield CheckResult("t.crash", "format", "first", True)
        raise RuntimeError("boom")

    @check(name="t.empty", level="format", registry=checks)
    def empty(ctx: Context) -> Iterator[CheckResult]:
        return iter(())

    @check(name="t.bad-type", level="renderer", registry=checks)
    def bad_type(ctx: Context) -> Iterator[CheckResult]:
        yield 42  # type: ignore[misc]

    @check(name="t.fine", level="renderer", registry=checks)
    def fine(ctx: Context) -> Iterator[CheckResult]:
        yield measured("t.fine", "renderer", "case", "A1", 0.01, 0.08, unit="relative friction")

    @check(name="t.device", level="device", registry=checks)
    def device(ctx: Context) -> Iterator[CheckResult]:
        raise AssertionError("device checks must not run without a driver")

    return list(checks.values())


def test_crashing_checks_become_failed_results() -> None:
    report = run_suite(Context.for_driver("reference"), checks=_crashing_checks())
    cases = [(r.check, r.case, r.passed) for r in report.results]
    assert cases == [
        ("t.crash", "first", True),
        ("t.crash", "(error after first)", False),
        ("t.empty", "(none)", False),
        ("t.bad-type", "(error)", False),
        ("t.fine", "case", True),
    ]
    crash = report.results[1]
    assert crash.metric == "error" and "RuntimeError: boom" in crash.detail
    assert "TypeError" in report.results[3].detail
    assert report.not_applicable == ["t.device"]
    assert report.exit_code == 1 and len(report.failures) == 3
    assert all(r.duration_s >= 0 for r in report.results)
    assert set(report.check_durations_s) == {"t.crash", "t.empty", "t.bad-type", "t.fine"}


def _sample_report() -> SuiteReport:
    report = SuiteReport("demo", ("format", "renderer"))
    report.results = [
        CheckResult("format.parse", "format", "a.binary", True, "Q2", 0.0, 0.0, "errors"),
        CheckResult("format.parse", "format", "a.json", True, "Q2", 0.0, 0.0, "errors"),
        measured("renderer.friction_error", "renderer", "g@slow", "A1", 0.12, 0.08,
                 unit="relative friction", detail="lag 1.0 ms"),
        measured("renderer.exact", "renderer", "g@fast", "A0", math.inf, 1e-5,
                 unit="relative friction", detail="frame counts differ"),
        measured("renderer.friction_error", "renderer", "g@fast", "A1", 0.01, 0.08,
                 unit="relative friction"),
    ]
    report.thresholds = {"friction_rel_jnd": 0.08}
    report.duration_s = 1.5
    return report


def test_junit_xml_has_one_suite_per_level_with_failures() -> None:
    root = ET.fromstring(junit_xml(_sample_report()))
    assert root.tag == "testsuites"
    assert (root.get("tests"), root.get("failures")) == ("6", "3")  # and the verdict's case
    suites = {s.get("name"): s for s in root.findall("testsuite")}
    assert set(suites) == {"format", "renderer", "verdict"}
    assert (suites["format"].get("tests"), suites["format"].get("failures")) == ("2", "0")
    assert (suites["renderer"].get("tests"), suites["renderer"].get("failures")) == ("3", "2")
    cases = suites["renderer"].findall("testcase")
    assert [(c.get("classname"), c.get("name")) for c in cases] == [
        ("renderer.friction_error", "g@slow"), ("renderer.exact", "g@fast"),
        ("renderer.friction_error", "g@fast")]
    failure = cases[0].find("failure")
    assert failure is not None
    assert failure.get("message") == "0.12 relative friction > 0.08 relative friction (A1)"
    assert failure.text == "lag 1.0 ms"
    props = {p.get("name"): p.get("value") for p in cases[0].find("properties")}
    assert props == {"metric": "A1", "value": "0.12", "threshold": "0.08",
                     "unit": "relative friction"}
    assert cases[2].find("failure") is None


def test_json_report_holds_every_result_with_non_finite_as_strings() -> None:
    data = json.loads(json_bytes(_sample_report()))
    assert data["format"] == "hcard-conformance-report/1"
    assert data["passed"] is False
    assert data["totals"] == {"cases": 5, "failed": 2, "pass": 3, "fail": 2, "error": 0,
                              "unassessed": 0}
    assert data["thresholds"] == {"friction_rel_jnd": 0.08}
    assert len(data["results"]) == 5
    assert data["results"][3]["value"] == "inf"
    assert data["results"][2] | {"duration_s": 0} == {
        "check": "renderer.friction_error", "level": "renderer", "case": "g@slow",
        "passed": False, "metric": "A1", "value": 0.12, "threshold": 0.08,
        "unit": "relative friction", "detail": "lag 1.0 ms", "duration_s": 0,
        "outcome": "FAIL"}


def test_table_lists_failures_and_verdict() -> None:
    text = table(_sample_report())
    assert "DOES NOT CONFORM: 3 of 5 cases pass, 2 fail" in text
    assert "FAIL    renderer.friction_error" in text and "lag 1.0 ms" in text
    assert "PASS    format.parse" in text
    assert failure_message(_sample_report().results[3]).startswith("inf relative friction >")


@pytest.fixture
def broken_vectors(tmp_path: Path) -> Path:
    """spec/vectors with one invalid vector replaced by a valid card."""
    target = tmp_path / "vectors"
    shutil.copytree(MANIFEST.root, target)
    manifest = load_manifest(target)
    manifest.invalid[0].file.write_bytes(manifest.cards[0].binary.read_bytes())
    return target


def test_cli_writes_reports_and_exits_zero_for_the_reference(tmp_path: Path) -> None:
    junit, report = tmp_path / "out.xml", tmp_path / "out.json"
    result = CliRunner().invoke(cli, ["conformance", "--driver", "reference", "--level",
                                      "format", "--junit", str(junit), "--json", str(report)])
    assert result.exit_code == 0, result.output
    assert "CONFORMS" in result.output
    data = json.loads(report.read_text())
    cases = 2 * len(MANIFEST.cards) + len(MANIFEST.cards) + len(MANIFEST.invalid) \
        + len(MANIFEST.compat) + 1
    assert data["totals"] == {"cases": cases, "failed": 0, "pass": cases, "fail": 0, "error": 0,
                              "unassessed": 0}
    assert ET.parse(junit).getroot().get("tests") == str(cases + 1)  # and the verdict


def test_cli_exits_one_on_a_failure(broken_vectors: Path, tmp_path: Path) -> None:
    junit = tmp_path / "out.xml"
    result = CliRunner().invoke(cli, ["conformance", "--driver", "reference", "--level",
                                      "format", "--vectors", str(broken_vectors),
                                      "--junit", str(junit)])
    assert result.exit_code == 1, result.output
    assert "DOES NOT CONFORM" in result.output
    assert ET.parse(junit).getroot().get("failures") == "2"  # the case and the verdict


@pytest.mark.parametrize("args", [["--driver", "nope://x"],
                                  ["--driver", "control:nothing"],
                                  ["--driver", "reference", "--vectors", "/nonexistent"],
                                  ["--driver", "reference", "--level", "device"]])
def test_cli_usage_errors_exit_two(args: list[str]) -> None:
    result = CliRunner().invoke(cli, ["conformance", *args])
    assert result.exit_code == 2, result.output
    assert "Error:" in result.output


def test_pytest_plugin_makes_one_item_per_case(broken_vectors: Path, tmp_path: Path) -> None:
    junit = tmp_path / "plugin.xml"
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-p", "hcard_conformance.pytest_plugin",
         "--hcard-driver=reference", "--hcard-level=format", f"--hcard-vectors={broken_vectors}",
         "-p", "no:cacheprovider", "-q", f"--junitxml={junit}", str(tmp_path)],
        capture_output=True, text=True, cwd=tmp_path, timeout=300)
    cases = 3 * len(MANIFEST.cards) + len(MANIFEST.invalid) + len(MANIFEST.compat) + 1
    assert run.returncode == 1, run.stdout + run.stderr
    assert f"1 failed, {cases - 1} passed" in run.stdout
    victim = MANIFEST.invalid[0].name
    assert f"format.reject::{victim}" in run.stdout
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("tests") == str(cases)
    failed = [c for c in suite.iter("testcase") if c.find("failure") is not None]
    assert [(c.get("classname"), c.get("name")) for c in failed] == [("format.reject", victim)]


def _vanishing_device(after_writes: int):
    """The simulated E-ViTa whose link breaks after ``after_writes`` output reports (a device
    unplugged in the middle of a check): every later write raises DeviceError."""
    from hcard.device import open_device
    from hcard.device.errors import DeviceError

    driver = open_device("sim://evita")
    write = driver._write_output
    count = {"n": 0}

    def failing_write(report):
        count["n"] += 1
        if count["n"] > after_writes:
            raise DeviceError("sim://evita: the device vanished (test)")
        return write(report)

    driver._write_output = failing_write
    return driver


def test_a_check_that_raises_is_an_error_per_case_in_table_json_and_junit() -> None:
    from hcard_conformance.device_checks.safety import SAFETY_CASES

    ctx = Context("vanishing", lambda: _vanishing_device(after_writes=5))
    report = run_suite(ctx, ("device",), select=("device.safety", "device.dynamics"))
    outcomes = {(r.check, r.case): r.outcome for r in report.results}
    assert outcomes == {
        **{("device.safety", case): "ERROR" for case in SAFETY_CASES},
        ("device.dynamics", "bandwidth"): "ERROR",
        ("device.dynamics", "rise-time"): "ERROR",
    }
    assert all("DeviceError" in r.detail and "vanished" in r.detail for r in report.results)
    n = len(SAFETY_CASES) + 2
    root = ET.fromstring(junit_xml(report))
    assert (root.get("errors"), root.get("failures"), root.get("tests")) == \
        (str(n), "1", str(n + 1))  # the verdict fails
    assert len(root.findall(".//testcase/error")) == n
    data = json.loads(json_bytes(report))
    assert data["totals"]["error"] == n and data["passed"] is False
    assert f"0 of {n} cases pass, 0 fail, {n} errors" in table(report)


def test_a_case_that_cannot_be_assessed_is_reported_not_dropped() -> None:
    from hcard_conformance.result import CannotAssess, guarded

    def measure() -> Iterator[CheckResult]:
        yield measured("t.part", "device", "first", "m", 1.0, 2.0)
        raise CannotAssess("the device reported no target")

    results = guarded("t.part", "device", ["first", "second", "third"], measure)
    assert [(r.case, r.outcome) for r in results] == [
        ("first", "PASS"), ("second", "UNASSESSED"), ("third", "UNASSESSED")]
    assert "not assessed: the device reported no target" in results[1].detail
    report = SuiteReport("demo", ("device",), results=results)
    assert not report.passed
    root = ET.fromstring(junit_xml(report))
    assert (root.get("skipped"), root.get("errors"), root.get("failures")) == ("2", "0", "1")


def test_a_result_failed_after_it_was_built_is_counted_as_failed() -> None:
    result = measured("t.late", "renderer", "case", "A5", 1.0, 2.5)
    assert result.status == "PASS"
    result.passed = False  # as a check does when the metric is infinite
    report = SuiteReport("demo", ("renderer",), results=[result])
    assert result.status == "FAIL" and result.to_dict()["outcome"] == "FAIL"
    assert "0 of 1 cases pass, 1 fail" in table(report)
    assert ET.fromstring(junit_xml(report)).get("failures") == "2"  # and the verdict
