"""The plan of a run, made before anything is measured: which checks of the chosen levels
concern the implementation, and the cases each declares
(:func:`~hcard_conformance.registry.declared_cases`).

The pytest plugin collects one item per planned case from it, so that ``--collect-only`` lists
what a run reports, ``-k`` chooses before anything runs and a case's node ID selects it again.
Making the plan measures nothing: it reads the vectors' manifest and golden renders, and, for a
driver, asks the device whether the wire-protocol checks concern it and reads its DEVICE_INFO
(device-dependent cases, such as ``device.friction``'s ``bipolar`` on a device with EV).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from hcard_conformance.context import Context
from hcard_conformance.registry import declared_cases
from hcard_conformance.result import LEVELS, STOPS_THE_RUN, CheckResult, error_result
from hcard_conformance.runner import check_applies, choose_checks


@dataclass
class PlannedCheck:
    """One check a run would run.

    Attributes:
        check: the check (:class:`~hcard_conformance.registry.Check`, a
            :class:`~hcard_conformance.registry.LazyCheck` row or a plugin's object).
        cases: the cases it declares, in order; None when it declares none (they are known
            only by running it) or could not say.
        error: the ERROR result, case ``(error)``, when deciding whether it applies or reading
            its declaration raised (spec QP5: a check that raises before it names its cases);
            such a check is not run.
    """

    check: Any
    cases: tuple[str, ...] | None
    error: CheckResult | None = None

    @property
    def name(self) -> str:
        """The check's name."""
        return str(self.check.name)


@dataclass
class Plan:
    """The checks of a run, in level order, and those that do not concern the implementation.

    Attributes:
        levels: the levels, in order.
        checks: the checks to run, each with its declared cases.
        not_applicable: names of the checks of the levels that do not apply (not run).
    """

    levels: tuple[str, ...]
    checks: list[PlannedCheck] = field(default_factory=list)
    not_applicable: list[str] = field(default_factory=list)

    def check(self, name: str) -> PlannedCheck | None:
        """The planned check ``name``, or None."""
        return next((p for p in self.checks if p.name == name), None)


def plan_suite(ctx: Context, levels: Sequence[str] = LEVELS, *,
               checks: Sequence[Any] | None = None, select: Sequence[str] = ()) -> Plan:
    """The plan of :func:`~hcard_conformance.runner.run_suite` with the same arguments: the
    same checks, each applicable one with its declared cases. A check whose ``applies``
    predicate or case declaration raises is planned with its ERROR (named as the runner names
    it, ``while deciding whether it applies`` / ``while declaring its cases``); only an
    interrupt stops planning."""
    ordered, chosen = choose_checks(levels, checks, select)
    plan = Plan(ordered)
    for chk in chosen:
        applies = check_applies(chk, ctx)
        if applies is False:
            plan.not_applicable.append(chk.name)
            continue
        if isinstance(applies, CheckResult):
            plan.checks.append(PlannedCheck(chk, None, applies))
            continue
        try:
            cases = declared_cases(chk, ctx)
        except STOPS_THE_RUN:
            raise
        except BaseException as exc:  # a check never stops the run
            plan.checks.append(PlannedCheck(chk, None, error_result(
                chk.name, chk.level, "(error)", exc, "declaring its cases")))
            continue
        plan.checks.append(PlannedCheck(chk, cases))
    return plan
