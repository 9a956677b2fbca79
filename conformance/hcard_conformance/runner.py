"""Running checks: every result is kept, every exception becomes a failed result.

:func:`run_suite` runs the checks of the chosen levels on a :class:`Context` and returns a
:class:`SuiteReport`. A check that raises (before its first case or between cases) yields a
failed result carrying the error, and the suite carries on with the next check: the suite
itself never crashes because of the implementation under test.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from hcard_conformance.conditions import run_conditions
from hcard_conformance.context import Context
from hcard_conformance.realtime import host_priority
from hcard_conformance.registry import all_checks, applies_to
from hcard_conformance.result import LEVELS, CheckResult, error_result, level_index
from hcard_conformance.timing import timing_class

Progress = Callable[[Any, CheckResult], None]
"""Called after each result with the check and the result (the CLI prints progress)."""


@dataclass
class SuiteReport:
    """Everything a run produced.

    Attributes:
        driver: the implementation's name (``Context.driver_name``).
        levels: the levels run, in order.
        results: every result, in run order.
        not_applicable: checks of the levels that do not concern this implementation (for
            example the exact-render check A0 for a driver, device checks for ``reference``).
        thresholds: the manifest's tolerances in force (with the run's overrides).
        conditions: device class and timing class of a device-level run, with why
            (:func:`hcard_conformance.conditions.run_conditions`).
        check_durations_s: wall-clock time of each check, s.
        duration_s: wall-clock time of the whole run, s.
    """

    driver: str
    levels: tuple[str, ...]
    results: list[CheckResult] = field(default_factory=list)
    not_applicable: list[str] = field(default_factory=list)
    thresholds: dict[str, float] = field(default_factory=dict)
    conditions: dict[str, str] = field(default_factory=dict)
    check_durations_s: dict[str, float] = field(default_factory=dict)
    duration_s: float = 0.0

    @property
    def passed(self) -> bool:
        """True when there is at least one result and none failed."""
        return bool(self.results) and all(r.passed for r in self.results)

    @property
    def failures(self) -> list[CheckResult]:
        """The failed results."""
        return [r for r in self.results if not r.passed]

    def by_level(self, level: str) -> list[CheckResult]:
        """Results of ``level``."""
        return [r for r in self.results if r.level == level]

    def level_durations_s(self) -> dict[str, float]:
        """Time spent per level, s (sum of its results' durations)."""
        return {level: sum(r.duration_s for r in self.by_level(level)) for level in self.levels}

    @property
    def exit_code(self) -> int:
        """0 when every result passed, 1 otherwise (also when nothing ran)."""
        return 0 if self.passed else 1


def run_check(chk: Any, ctx: Context, progress: Progress | None = None) -> list[CheckResult]:
    """Run one check; each result is timed (time since the previous one) and an exception
    anywhere becomes a failed result for case ``(error)``, or for the case after the last one
    reported."""
    results: list[CheckResult] = []
    last = time.perf_counter()
    try:
        iterator: Iterable[CheckResult] = chk.run(ctx)
        for result in iterator:
            if not isinstance(result, CheckResult):
                raise TypeError(f"check yielded {type(result).__name__}, not a CheckResult")
            now = time.perf_counter()
            if not result.duration_s:
                result.duration_s = now - last
            last = now
            results.append(result)
            if progress is not None:
                progress(chk, result)
    except Exception as exc:
        case = "(error)" if not results else f"(error after {results[-1].case})"
        failed = error_result(chk.name, chk.level, case, exc)
        failed.duration_s = time.perf_counter() - last
        results.append(failed)
        if progress is not None:
            progress(chk, failed)
    if not results:
        empty = CheckResult(chk.name, chk.level, "(none)", False, "cases", 0.0, 1.0,
                            detail="the check produced no results (no vectors?)")
        results.append(empty)
        if progress is not None:
            progress(chk, empty)
    return results


def run_suite(ctx: Context, levels: Sequence[str] = LEVELS, *, checks: Sequence[Any] | None = None,
              select: Sequence[str] = (), progress: Progress | None = None,
              check_done: Callable[[Any, list[CheckResult], float], None] | None = None,
              ) -> SuiteReport:
    """Run the checks of ``levels`` (in level order) on ``ctx``.

    Args:
        ctx: the implementation under test and the vectors.
        levels: levels to run.
        checks: the checks to consider (default: :func:`all_checks` of ``levels``).
        select: when given, only checks whose name starts with one of these strings.
        progress: called after each result.
        check_done: called after each check with the check, its results and its time, s.
    """
    ordered = tuple(sorted(dict.fromkeys(levels), key=level_index))
    candidates = list(checks) if checks is not None else all_checks(ordered)
    chosen = [c for c in candidates if c.level in ordered
              and (not select or any(c.name.startswith(s) for s in select))]
    chosen.sort(key=lambda c: level_index(c.level))
    report = SuiteReport(ctx.driver_name, ordered)
    try:
        report.thresholds = {**ctx.manifest.tolerances, **ctx.options.get("tolerances", {})}
    except Exception as exc:  # no vectors: the checks report it, one failed result each
        report.thresholds = {"error": math.nan}
        report.not_applicable.append(f"(thresholds unavailable: {exc})")
    priority: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
    if any(c.level == "device" for c in chosen):
        report.conditions = run_conditions(ctx, ordered)
        if ctx.open_driver is not None and timing_class(ctx).keeps_real_time:
            priority = host_priority()  # a real-time host asks to be one (spec QT3)
    start = time.perf_counter()
    with priority as granted:
        if granted:
            report.conditions["host_scheduling"] = granted
        _run_chosen(chosen, ctx, report, progress, check_done)
    report.duration_s = time.perf_counter() - start
    return report


def _run_chosen(chosen: Sequence[Any], ctx: Context, report: SuiteReport,
                progress: Progress | None,
                check_done: Callable[[Any, list[CheckResult], float], None] | None) -> None:
    """Run each chosen check on ``ctx`` into ``report`` (not applicable ones listed)."""
    for chk in chosen:
        if not applies_to(chk, ctx):
            report.not_applicable.append(chk.name)
            continue
        began = time.perf_counter()
        results = run_check(chk, ctx, progress)
        report.results += results
        report.check_durations_s[chk.name] = time.perf_counter() - began
        if check_done is not None:
            check_done(chk, results, report.check_durations_s[chk.name])
