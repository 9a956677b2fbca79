"""Results of conformance checks: one :class:`CheckResult` per (check, case).

A check compares one *metric* of the implementation under test with a *threshold* derived in
``spec/conformance.md``; the result records both, so a report says not only that a case failed
but by how much.

>>> r = measured("renderer.friction", "renderer", "single-grating/slow", "max_abs_error",
...              0.02, 0.08, unit="relative friction")
>>> r.passed
True
"""

from __future__ import annotations

import math
import traceback
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from typing import Any

from hcard.errors import HcardError

PASS, FAIL, ERROR, UNASSESSED = "PASS", "FAIL", "ERROR", "UNASSESSED"
OUTCOMES = (PASS, FAIL, ERROR, UNASSESSED)
"""Outcomes of a case; only PASS passes."""


STOPS_THE_RUN: tuple[type[BaseException], ...] = (KeyboardInterrupt, GeneratorExit)
"""Exceptions raised inside a check that stop the run (the user's interrupt, a generator being
closed); any other, even ``SystemExit`` or a test framework's outcome exception (both
BaseException subclasses), is the check's ERROR."""


class CannotAssess(HcardError):
    """Raised by a measurement that cannot assess its case (the reason is the message): the
    case is reported UNASSESSED, never dropped."""


LEVELS: tuple[str, ...] = ("format", "renderer", "device")
"""Conformance levels, in the order they run (spec/conformance.md)."""


def level_index(level: str) -> int:
    """Position of ``level`` in :data:`LEVELS` (raises ValueError naming the levels)."""
    try:
        return LEVELS.index(level)
    except ValueError:
        raise ValueError(f"unknown conformance level {level!r}; levels are: "
                         f"{', '.join(LEVELS)}") from None


@dataclass
class CheckResult:
    """The outcome of one check on one case.

    Attributes:
        check: name of the check, for example ``renderer.friction``.
        level: ``format``, ``renderer`` or ``device``.
        case: what was checked, for example a vector name or ``card/track``.
        passed: True when the metric is within its threshold.
        metric: name of the metric compared (``""`` for pass/fail checks without one).
        value: the metric's value (NaN when there is none).
        threshold: the limit it is held to (NaN when there is none).
        unit: unit of ``value`` and ``threshold``.
        detail: one line for a human: what was found, what was expected, or the error.
        duration_s: wall-clock time spent on this case, s (set by the runner when 0).
        outcome: ``PASS`` or ``FAIL`` (from ``passed``), ``ERROR`` (the check raised: the
            implementation or the suite broke) or ``UNASSESSED`` (the case could not be
            measured, for a reason in ``detail``); neither of the last two passes.
    """

    check: str
    level: str
    case: str
    passed: bool
    metric: str = ""
    value: float = math.nan
    threshold: float = math.nan
    unit: str = ""
    detail: str = ""
    duration_s: float = 0.0
    outcome: str = ""

    def __post_init__(self) -> None:
        level_index(self.level)
        self.value = float(self.value)
        self.threshold = float(self.threshold)
        if not self.outcome:
            self.outcome = PASS if self.passed else FAIL
        if self.outcome not in OUTCOMES:
            raise ValueError(f"unknown outcome {self.outcome!r}; outcomes: {', '.join(OUTCOMES)}")
        self.passed = self.outcome == PASS

    @property
    def status(self) -> str:
        """``PASS``, ``FAIL``, ``ERROR`` or ``UNASSESSED``: ERROR and UNASSESSED as recorded,
        else from :attr:`passed` (which a check may still set after building the result)."""
        if self.outcome in (ERROR, UNASSESSED):
            return self.outcome
        return PASS if self.passed else FAIL

    def to_dict(self) -> dict[str, Any]:
        """A JSON-ready dict (NaN becomes None)."""
        out = asdict(self)
        out["outcome"] = self.status
        for key in ("value", "threshold"):
            if math.isnan(out[key]):
                out[key] = None
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> CheckResult:
        """The inverse of :meth:`to_dict`."""
        fields = dict(data)
        for key in ("value", "threshold"):
            if fields.get(key) is None:
                fields[key] = math.nan
        return cls(**fields)


def measured(check: str, level: str, case: str, metric: str, value: float, threshold: float,
             *, unit: str = "", detail: str = "", higher_is_better: bool = False) -> CheckResult:
    """A result that passes when ``value <= threshold`` (or ``>=`` with ``higher_is_better``).

    A NaN value (nothing could be measured) fails.
    """
    value = float(value)
    if math.isnan(value):
        passed = False
    elif higher_is_better:
        passed = value >= threshold
    else:
        passed = value <= threshold
    if not detail:
        relation = ">=" if higher_is_better else "<="
        detail = f"{metric} {value:.4g} {unit} (must be {relation} {threshold:.4g})".replace(
            "  ", " ")
    return CheckResult(check, level, case, passed, metric, value, threshold, unit, detail)


def error_result(check: str, level: str, case: str, exc: BaseException,
                 during: str = "") -> CheckResult:
    """An ERROR result for a check that raised, naming the check and the cause: the exception
    type, message and where it was raised (file:line); ``during``: what the check was doing,
    when not measuring (``"deciding whether it applies"``)."""
    message = " ".join(str(exc).split())
    text = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    frames = traceback.extract_tb(exc.__traceback__)
    if frames:
        text += f" (at {frames[-1].filename}:{frames[-1].lineno})"
    when = f" while {during}" if during else ""
    return CheckResult(check, level, case, False, "error",
                       detail=f"check {check} raised {text}{when}", outcome=ERROR)


def unassessed(check: str, level: str, case: str, reason: str) -> CheckResult:
    """A case that could not be measured, and why."""
    return CheckResult(check, level, case, False, detail=f"not assessed: {reason}",
                       outcome=UNASSESSED)


def guarded(check: str, level: str, cases: Iterable[str],
            measure: Callable[[], Iterable[CheckResult]]) -> list[CheckResult]:
    """Run ``measure``, which yields the results of ``cases``; when it raises, every case it
    has not yet reported becomes ERROR (UNASSESSED for :class:`CannotAssess`), one result
    each, so a broken measurement never hides its cases."""
    cases = list(cases)
    results: list[CheckResult] = []
    try:
        results.extend(measure())
    except CannotAssess as exc:
        done = {r.case for r in results}
        results += [unassessed(check, level, c, str(exc)) for c in cases if c not in done]
    except STOPS_THE_RUN:
        raise
    except BaseException as exc:  # a measurement never stops the run
        done = {r.case for r in results}
        results += [error_result(check, level, c, exc) for c in cases if c not in done]
    return results
