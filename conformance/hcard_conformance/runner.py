"""Running checks: every result is kept, every exception becomes an ERROR result.

:func:`run_suite` runs the checks of the chosen levels on a :class:`Context` and returns a
:class:`SuiteReport`. A check that raises, built-in or a plugin's, wherever it raises (its
``applies`` predicate, importing it, building its generator, before its first case or between
cases), yields an ERROR result naming the check and the cause (exception type, message,
file:line), and the suite carries on with the next check: neither the implementation under
test nor a broken check crashes the run. Only an interrupt (Ctrl-C) stops it.
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
from hcard_conformance.result import (
    LEVELS,
    STOPS_THE_RUN,
    CannotAssess,
    CheckResult,
    error_result,
    level_index,
    unassessed,
)
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
    anywhere becomes an ERROR result for case ``(error)``, or for the case after the last one
    reported (:class:`~hcard_conformance.result.CannotAssess`: UNASSESSED with its reason)."""
    results: list[CheckResult] = []
    last = time.perf_counter()

    def report(result: CheckResult) -> None:
        results.append(result)
        if progress is not None:
            progress(chk, result)

    try:
        iterator: Iterable[CheckResult] = chk.run(ctx)
        for result in iterator:
            if not isinstance(result, CheckResult):
                raise TypeError(f"check yielded {type(result).__name__}, not a CheckResult")
            now = time.perf_counter()
            if not result.duration_s:
                result.duration_s = now - last
            last = now
            report(result)
    except STOPS_THE_RUN:
        raise
    except BaseException as exc:  # a check never stops the run
        case = "(error)" if not results else f"(error after {results[-1].case})"
        if isinstance(exc, CannotAssess):
            failed = unassessed(chk.name, chk.level, case, str(exc))
        else:
            failed = error_result(chk.name, chk.level, case, exc)
        failed.duration_s = time.perf_counter() - last
        report(failed)
    if not results:
        report(CheckResult(chk.name, chk.level, "(none)", False, "cases", 0.0, 1.0,
                           detail="the check produced no results (no vectors?)"))
    return results


def check_applies(chk: Any, ctx: Context) -> bool | CheckResult:
    """:func:`~hcard_conformance.registry.applies_to`, or, when deciding raises (a broken
    ``applies`` predicate, or one that cannot be imported), the ERROR result saying so."""
    try:
        return applies_to(chk, ctx)
    except STOPS_THE_RUN:
        raise
    except BaseException as exc:  # a check never stops the run
        return error_result(chk.name, chk.level, "(error)", exc,
                            "deciding whether it applies")


def choose_checks(levels: Sequence[str], checks: Sequence[Any] | None = None,
                  select: Sequence[str] = ()) -> tuple[tuple[str, ...], list[Any]]:
    """The levels of a run, in level order, and its checks: those of ``checks`` (default
    :func:`all_checks` of the levels) of those levels whose name starts with one of ``select``
    (any, when empty), in level order."""
    ordered = tuple(sorted(dict.fromkeys(levels), key=level_index))
    candidates = list(checks) if checks is not None else all_checks(ordered)
    chosen = [c for c in candidates if c.level in ordered
              and (not select or any(c.name.startswith(s) for s in select))]
    chosen.sort(key=lambda c: level_index(c.level))
    return ordered, chosen


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
    ordered, chosen = choose_checks(levels, checks, select)
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
        began = time.perf_counter()
        applies = check_applies(chk, ctx)
        if applies is False:
            report.not_applicable.append(chk.name)
            continue
        if isinstance(applies, CheckResult):
            applies.duration_s = time.perf_counter() - began
            results = [applies]
            if progress is not None:
                progress(chk, applies)
        else:
            results = run_check(chk, ctx, progress)
        report.results += results
        report.check_durations_s[chk.name] = time.perf_counter() - began
        if check_done is not None:
            check_done(chk, results, report.check_durations_s[chk.name])
