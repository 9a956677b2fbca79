"""Reports of a suite run: a readable table, JUnit XML for CI and JSON for tools.

JUnit XML has one ``<testsuite>`` per level (``name`` = the level) and one
``<testcase>`` per (check, case): ``classname`` is the check, ``name`` the case. A failed case
has a ``<failure>`` whose ``message`` gives metric, value and threshold; every case carries
them as ``<properties>`` too; an UNASSESSED case is ``<skipped>`` with its reason, an ERROR an
``<error>``. A last ``<testsuite name="verdict">`` holds one case, ``hcard-conformance.conforms``,
that fails when the run does not conform: a run whose cases are all skipped never reads green
on a dashboard (spec/conformance.md section 7). A run that could not start (an unreachable
device, unreadable vectors) is one ``<error>`` case (:func:`junit_setup_error`).

JSON (:data:`JSON_FORMAT`, spec QP4) holds the run, the thresholds and every result
(:meth:`CheckResult.to_dict`); non-finite numbers are written as the strings ``"inf"``,
``"-inf"``, ``"nan"``.
"""

from __future__ import annotations

import json
import math
import platform
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

from hcard import __version__
from hcard.atomic import write_atomically
from hcard_conformance.result import ERROR, FAIL, OUTCOMES, PASS, UNASSESSED, CheckResult
from hcard_conformance.runner import SuiteReport

JSON_FORMAT = "hcard-conformance-report/1"
"""The ``format`` field of JSON reports."""


def _number(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.4g}"


def failure_message(result: CheckResult) -> str:
    """``VALUE UNIT > THRESHOLD UNIT (METRIC)`` (spec QP3), or the detail when there is no
    measured value (a check that raised)."""
    if result.metric and not math.isnan(result.value):
        unit = f" {result.unit}" if result.unit else ""
        relation = ">" if math.isnan(result.threshold) or result.value > result.threshold else "<"
        return (f"{_number(result.value)}{unit} {relation} {_number(result.threshold)}{unit} "
                f"({result.metric})")
    return result.detail or result.metric or "failed"


def table(report: SuiteReport, *, verbose: bool = False) -> str:
    """A readable table: one row per (check, case) (failed ones only unless ``verbose``, plus
    a per-check summary), then totals and timings per level."""
    lines = [f"hcard conformance {__version__}: driver {report.driver}, "
             f"levels {', '.join(report.levels)}"]
    for kind in ("device_class", "timing_class"):
        if kind in report.conditions:
            lines.append(f"{kind.replace('_', ' ')}: {report.conditions[kind]} "
                         f"({report.conditions[kind + '_why']})")
    if report.not_applicable:
        lines.append(f"not applicable here: {', '.join(report.not_applicable)}")
    header = f"{'status':6}  {'check':34} {'case':44} {'metric':26} {'value':>10} {'limit':>10}"
    lines += ["", header, "-" * len(header)]
    by_check: dict[str, list[CheckResult]] = {}
    for r in report.results:
        by_check.setdefault(r.check, []).append(r)
    for name, results in by_check.items():
        failed = [r for r in results if not r.passed]
        shown = results if verbose else failed
        for r in shown:
            lines.append(f"{r.status:6}  {r.check[:34]:34} {r.case[:44]:44} {r.metric[:26]:26} "
                         f"{_number(r.value):>10} {_number(r.threshold):>10}")
            if not r.passed and r.detail:
                lines.append(f"{'':8}{r.detail}")
        if not verbose:
            status = "PASS" if not failed else "FAIL"
            worst = _worst(results)
            lines.append(f"{status:6}  {name[:34]:34} {len(results) - len(failed)}/{len(results)}"
                         f" cases pass{worst}")
    lines.append("")
    for level, seconds in report.level_durations_s().items():
        counts = outcome_counts(report.by_level(level))
        lines.append(f"level {level:9} {counts[PASS]:4} passed {counts[FAIL]:4} failed "
                     f"{counts[ERROR]:4} errors {counts[UNASSESSED]:4} unassessed "
                     f"in {seconds:7.2f} s")
    lines.append(f"{verdict_line(report)} ({report.duration_s:.2f} s)")
    return "\n".join(lines) + "\n"


def outcome_counts(results: list[CheckResult]) -> dict[str, int]:
    """How many results have each outcome (every outcome present, 0 when none)."""
    counts = dict.fromkeys(OUTCOMES, 0)
    for r in results:
        counts[r.status] += 1
    return counts


def _shortfall(r: CheckResult) -> float:
    """How close ``r`` is to (or how far past) its threshold: > 1 means failed. The direction
    is inferred from the outcome (a passed value below its threshold is lower-is-better)."""
    if r.metric == "error":
        return math.inf
    lower_is_better = (r.value <= r.threshold) == r.passed
    if lower_is_better:
        return abs(r.value / r.threshold)
    return abs(r.threshold / r.value) if r.value else math.inf


def _worst(results: list[CheckResult]) -> str:
    """``; worst metric value/threshold`` over the results that have a metric."""
    measured = [r for r in results if r.metric and not math.isnan(r.value)
                and not math.isnan(r.threshold) and r.threshold != 0]
    if not measured:
        return ""
    worst = max(measured, key=_shortfall)
    return (f"; worst {worst.metric} {_number(worst.value)} {worst.unit} "
            f"(limit {_number(worst.threshold)}) on {worst.case}").replace("  ", " ")


VERDICT_CLASS = "hcard-conformance"
"""``classname`` of the cases about the run itself (its verdict, a run that could not start)."""


def verdict_line(report: SuiteReport) -> str:
    """One line: CONFORMS or DOES NOT CONFORM, with the counts of each outcome."""
    counts = outcome_counts(report.results)
    head = "CONFORMS" if report.passed else "DOES NOT CONFORM"
    return (f"{head}: {counts[PASS]} of {len(report.results)} cases pass, {counts[FAIL]} fail, "
            f"{counts[ERROR]} errors, {counts[UNASSESSED]} not assessed")


def junit_xml(report: SuiteReport) -> bytes:
    """JUnit XML bytes (see the module docstring)."""
    totals = outcome_counts(report.results)
    verdict_failed = 0 if report.passed else 1
    root = ET.Element("testsuites", name=f"hcard-conformance {report.driver}",
                      tests=str(len(report.results) + 1),
                      failures=str(totals[FAIL] + verdict_failed),
                      errors=str(totals[ERROR]), skipped=str(totals[UNASSESSED]),
                      time=f"{report.duration_s:.3f}")
    for level in report.levels:
        results = report.by_level(level)
        counts = outcome_counts(results)
        suite = ET.SubElement(
            root, "testsuite", name=level, tests=str(len(results)),
            failures=str(counts[FAIL]), errors=str(counts[ERROR]),
            skipped=str(counts[UNASSESSED]),
            time=f"{sum(r.duration_s for r in results):.3f}")
        props = ET.SubElement(suite, "properties")
        ET.SubElement(props, "property", name="driver", value=report.driver)
        ET.SubElement(props, "property", name="hcard_version", value=__version__)
        if level == "device":
            for key, value in report.conditions.items():
                ET.SubElement(props, "property", name=key, value=value)
        for r in results:
            case = ET.SubElement(suite, "testcase", classname=r.check, name=r.case,
                                 time=f"{r.duration_s:.6f}")
            case_props = ET.SubElement(case, "properties")
            for key in ("metric", "value", "threshold", "unit"):
                value = getattr(r, key)
                text = _number(value) if isinstance(value, float) else str(value)
                ET.SubElement(case_props, "property", name=key, value=text)
            if r.status == ERROR:
                error = ET.SubElement(case, "error", message=r.detail, type="error")
                error.text = r.detail
            elif r.status == UNASSESSED:
                ET.SubElement(case, "skipped", message=r.detail)
            elif not r.passed:
                failure = ET.SubElement(case, "failure", message=failure_message(r),
                                        type=r.metric or "failure")
                failure.text = r.detail
    verdict = ET.SubElement(root, "testsuite", name="verdict", tests="1",
                            failures=str(verdict_failed), errors="0", skipped="0",
                            time=f"{report.duration_s:.3f}")
    case = ET.SubElement(verdict, "testcase", classname=VERDICT_CLASS, name="conforms",
                         time=f"{report.duration_s:.6f}")
    if verdict_failed:
        failure = ET.SubElement(case, "failure", message=verdict_line(report),
                                type="does-not-conform")
        failure.text = verdict_line(report)
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def junit_setup_error(driver: str, message: str) -> bytes:
    """JUnit XML of a run that could not start: one ``<error>`` case naming why."""
    root = ET.Element("testsuites", name=f"hcard-conformance {driver}", tests="1",
                      failures="0", errors="1", skipped="0", time="0.000")
    suite = ET.SubElement(root, "testsuite", name="setup", tests="1", failures="0",
                          errors="1", skipped="0", time="0.000")
    case = ET.SubElement(suite, "testcase", classname=VERDICT_CLASS, name="setup",
                         time="0.000000")
    error = ET.SubElement(case, "error", message=message, type="setup")
    error.text = message
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


def to_json(report: SuiteReport) -> dict[str, Any]:
    """The JSON document of a run."""
    return {
        "format": JSON_FORMAT,
        "hcard_version": __version__,
        "python": platform.python_version(),
        "driver": report.driver,
        "levels": list(report.levels),
        "passed": report.passed,
        "totals": {"cases": len(report.results), "failed": len(report.failures),
                   **{k.lower(): v for k, v in outcome_counts(report.results).items()}},
        "duration_s": report.duration_s,
        "thresholds": {k: _finite(v) for k, v in report.thresholds.items()},
        "conditions": dict(report.conditions),
        "not_applicable": list(report.not_applicable),
        "level_durations_s": report.level_durations_s(),
        "check_durations_s": report.check_durations_s,
        "results": [{k: _finite(v) for k, v in r.to_dict().items()}
                    for r in report.results],
    }


def _finite(value: Any) -> Any:
    """``value``, with non-finite floats (and None from :meth:`CheckResult.to_dict`) as the
    strings of spec QP4."""
    if value is None:
        return "nan"
    if isinstance(value, float) and not math.isfinite(value):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")
    return value


def json_bytes(report: SuiteReport) -> bytes:
    """:func:`to_json` as UTF-8 bytes (indented, strict JSON: no NaN)."""
    return (json.dumps(to_json(report), indent=2, allow_nan=False) + "\n").encode()


def write_junit(report: SuiteReport, path: Path) -> None:
    """Write JUnit XML to ``path`` atomically."""
    write_atomically(Path(path), junit_xml(report))


def write_json(report: SuiteReport, path: Path) -> None:
    """Write the JSON report to ``path`` atomically."""
    write_atomically(Path(path), json_bytes(report))
