"""pytest plugin: the conformance suite as test items of a vendor's own test run.

Enable it with one line, either on the command line::

    pytest -p hcard_conformance.pytest_plugin --hcard-driver=sim://

or in the vendor's top-level ``conftest.py``::

    pytest_plugins = ["hcard_conformance.pytest_plugin"]

and name the implementation with ``--hcard-driver=URI`` (or the ini option ``hcard_driver``).
Without a driver the plugin adds nothing. Options: ``--hcard-level`` (repeatable),
``--hcard-vectors DIR``, ``--hcard-check PREFIX`` (repeatable).

**Collection measures nothing** (spec QP6). Every check that concerns the implementation is a
collector, node ID ``CHECK``, holding one item per case the check declares before it runs
(:func:`hcard_conformance.registry.declared_cases`: the vectors' manifest and golden renders
for the format and renderer levels, fixed names or DEVICE_INFO for the device checks), node
ID ``CHECK::CASE``. So ``--collect-only`` lists every item a run reports, and ``-k``,
``--deselect`` and ``--lf`` choose before anything runs. Collecting with a driver opens the
device to read its DEVICE_INFO and whether it renders on the host (which checks apply, which
cases ``device.friction`` has); a driver that cannot be opened is one error,
``hcard-conformance::setup``, and nothing else is collected.

**Node IDs select again.** A node ID pytest prints, ``CHECK::CASE`` or ``CHECK``, given as an
argument selects that case or check (the plugin takes such arguments, which name a check rather
than a file, out of pytest's file arguments; ``hcard-conformance``, or the setup error's node
ID, names the whole suite)::

    pytest -p hcard_conformance.pytest_plugin --hcard-driver=reference \\
        'renderer.friction_error::single-grating@fast-stroke'

A case its check does not declare is a collection error naming the cases it does.

**Running.** The selected checks run once, in level order, before the first test runs; a
line per check on the terminal says how many cases it measured and how long it took (not with
``-q``). A check measures only the selected cases where it measures its cases one by one (the
format and renderer levels, ``device.friction``, ``device.dynamics``,
``device.upload-integrity``: :meth:`~hcard_conformance.context.Context.wants`); the others
measure all and the plugin reports the selected ones. A case a check reports that it did not
declare (an ``(error)``, the cases of a check that declares none) becomes one more item of its
check, reported next to the others: a case is never dropped (spec QP5). A check that declares
nothing is one item ``CHECK::(cases)`` until it runs, which its cases then replace. A declared
case the run did not report is an error saying so.

**Outcomes.** Each item's duration is its case's own, so ``--junitxml`` gives it
``classname`` CHECK, ``name`` CASE and ``time`` the case's. A case that passed passes; one that
failed fails, reporting ``VALUE UNIT > THRESHOLD UNIT (METRIC)`` and the detail; an UNASSESSED
case is skipped with its reason; an ERROR case is an error. Metric, value, threshold and unit
are also recorded as user properties, so ``--junitxml`` carries them.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

from hcard.errors import HcardError
from hcard_conformance.result import ERROR, LEVELS, UNASSESSED, CheckResult

if TYPE_CHECKING:
    from hcard_conformance.plan import Plan, PlannedCheck

SUITE_NODE = "hcard-conformance"
"""Node ID of the suite as a whole: the parent of the setup error, and, as an argument, every
check."""
UNDECLARED = "(cases)"
"""Name of the one item of a check that declares no cases, until its run names them."""


class ConformanceFailure(HcardError):
    """A conformance case failed (its result is in ``args[0]``)."""


class CaseNotFound(HcardError):
    """A node ID names a case its check does not declare."""


class ConformanceItem(pytest.Item):
    """One (check, case) of the suite; its result comes from the suite's run (or, for an
    ERROR of the plan, with it).

    Attributes:
        check: the check's name.
        level: the check's level.
        result: the case's result; None until the suite has run.
        undeclared: the item stands for all the cases of a check that declares none
            (:data:`UNDECLARED`).
        missing: why the run reported no result for it (set after the run).
    """

    def __init__(self, *, check: str, level: str, result: CheckResult | None = None,
                 undeclared: bool = False, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.check = check
        self.level = level
        self.result: CheckResult | None = None
        self.undeclared = undeclared
        self.missing = ""
        if result is not None:
            self.record(result)

    def record(self, result: CheckResult) -> None:
        """Give the item its case's result (and its metric as user properties)."""
        self.result = result
        self.user_properties += [("level", result.level), ("metric", result.metric),
                                 ("value", result.value), ("threshold", result.threshold),
                                 ("unit", result.unit)]

    def setup(self) -> None:
        """An ERROR case is an error (the check raised), not a failure; so is a case the run
        did not report. The message names the check, level and case, without a traceback."""
        why = (self.missing or f"{self.check} was not run" if self.result is None
               else self.result.detail if self.result.status == ERROR else "")
        if why:
            pytest.fail(f"{self.check} [{self.level}] {self.name}: ERROR {why}", pytrace=False)

    def runtest(self) -> None:
        """Fail when the case failed; skip, with the reason, when it could not be assessed."""
        assert self.result is not None  # setup raised otherwise
        if self.result.status == UNASSESSED:
            pytest.skip(f"UNASSESSED: {self.result.detail}")
        if not self.result.passed:
            raise ConformanceFailure(self.result)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: Any = None) -> str:
        """The failure message and detail of the case (no traceback: nothing to debug here)."""
        if isinstance(excinfo.value, ConformanceFailure) and self.result is not None:
            from hcard_conformance.report import failure_message

            r = self.result
            return f"{r.check} [{r.level}] {r.case}: {failure_message(r)}\n{r.detail}"
        return str(super().repr_failure(excinfo))

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest: the level; and the headline of a failure, the node ID
        and the level (a headline that ends the node ID would have pytest's verbose line
        print it with every ``.`` made ``::``, a node ID that selects nothing)."""
        return f"hcard conformance {self.level}", None, f"{self.nodeid} ({self.level} level)"


class CheckNode(pytest.Collector):
    """One check: the parent of its cases, so that a case's node ID is ``CHECK::CASE`` and its
    JUnit ``classname`` the check."""

    def __init__(self, *, planned: PlannedCheck, wanted: frozenset[str] | None,
                 **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.planned = planned
        self.wanted = wanted

    def collect(self) -> list[ConformanceItem]:
        """An item per declared case (those named by node ID, when some are), the ERROR of a
        check that could not say whether it applies or what its cases are, or one
        :data:`UNDECLARED` item for a check that declares none (or declares an empty list: its
        run reports ``(none)``, which fails, spec Q6).

        Raises:
            CaseNotFound: a node ID names a case the check does not declare.
        """
        planned, level = self.planned, str(self.planned.check.level)
        if planned.error is not None:
            return [ConformanceItem.from_parent(self, name=planned.error.case, check=self.name,
                                                level=level, result=planned.error)]
        if not planned.cases:
            names = sorted(self.wanted) if self.wanted else [UNDECLARED]
            return [ConformanceItem.from_parent(self, name=name, check=self.name, level=level,
                                                undeclared=not self.wanted) for name in names]
        if self.wanted is not None:
            unknown = sorted(self.wanted - set(planned.cases))
            if unknown:
                raise CaseNotFound(
                    f"not found: {self.name}::{unknown[0]} ({self.name} declares "
                    f"{len(planned.cases)} cases: {', '.join(planned.cases)})")
        return [ConformanceItem.from_parent(self, name=case, check=self.name, level=level)
                for case in planned.cases if self.wanted is None or case in self.wanted]

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: Any = None) -> str:
        """A node ID that names no case: the message alone."""
        if isinstance(excinfo.value, CaseNotFound):
            return str(excinfo.value)
        return str(super().repr_failure(excinfo))


class SetupErrorItem(pytest.Item):
    """The run could not start (the driver cannot be opened): one error naming why."""

    def __init__(self, *, reason: str, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.reason = reason

    def setup(self) -> None:
        """Always an error, the reason without a traceback: the suite did not run."""
        pytest.fail(f"hcard conformance could not start: {self.reason}", pytrace=False)

    def runtest(self) -> None:  # never reached: setup fails
        """Nothing: the suite did not run."""

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest."""
        return "hcard conformance", None, self.nodeid


class SetupNode(pytest.Collector):
    """The suite's node when it could not start: the parent of :class:`SetupErrorItem`."""

    def __init__(self, *, reason: str, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.reason = reason

    def collect(self) -> list[SetupErrorItem]:
        """The one error, ``hcard-conformance::setup``."""
        return [SetupErrorItem.from_parent(self, name="setup", reason=self.reason)]


class Suite:
    """The conformance suite of one pytest session: what to collect, and its one run."""

    def __init__(self, config: pytest.Config, driver: str) -> None:
        from hcard_conformance.context import Context

        vectors = config.getoption("--hcard-vectors")
        self.config = config
        self.driver = driver
        self.ctx = Context.for_driver(driver, vectors_root=Path(vectors) if vectors else None)
        self.levels = tuple(config.getoption("--hcard-level") or LEVELS)
        self.prefixes = tuple(config.getoption("--hcard-check"))
        self.named: dict[str, frozenset[str] | None] = {}
        """Checks named by node ID: the cases named, or None for all of them."""
        self.whole = True
        """No node ID named a check: every check of the levels is collected."""
        self.plan: Plan | None = None

    def take_node_ids(self, args: list[str], here: Path, root: Path) -> list[str]:
        """Record the arguments that are node IDs of the suite (``CHECK``, ``CHECK::CASE``,
        ``hcard-conformance``, ``hcard-conformance::setup``: the first part a check's name, or
        the suite's, and no file or directory of that name); the other arguments, which
        pytest collects as usual. pytest prints a node ID relative to the directory it was
        started in (``../CHECK::CASE`` from a folder below the rootdir ``root``), so such a
        path to ``root/CHECK`` names the check too."""
        from hcard_conformance.registry import all_checks

        known = {c.name for c in all_checks(LEVELS)} | {SUITE_NODE}
        kept: list[str] = []
        whole = False
        for arg in args:
            path, _, case = arg.partition("::")
            where = Path(os.path.normpath(here / path))
            head = path if path in known else where.name if where.parent == root else ""
            if head not in known or where.exists():
                kept.append(arg)
            elif head == SUITE_NODE:
                whole = True
            elif not case or self.named.get(head, frozenset()) is None:
                self.named[head] = None
            else:
                self.named[head] = frozenset({case}) | (self.named.get(head) or frozenset())
        if whole:
            self.named = {}
        self.whole = whole or not self.named
        return kept

    def roots(self, session: pytest.Session) -> list[pytest.Collector]:
        """The suite's collectors, children of the session: one per check to run (all, or
        those named by node ID), or the setup error. Plans the run (measuring nothing)."""
        from hcard_conformance.plan import plan_suite
        from hcard_conformance.registry import all_checks

        if self.ctx.open_driver is not None:
            try:
                self.ctx.device_info()
            except (HcardError, OSError, ValueError) as exc:
                reason = f"cannot open driver {self.driver!r}: {exc}"
                return [SetupNode.from_parent(session, name=SUITE_NODE, nodeid=SUITE_NODE,
                                              reason=reason)]
        checks = [c for c in all_checks(self.levels) if self.whole or c.name in self.named]
        self.plan = plan_suite(self.ctx, self.levels, checks=checks, select=self.prefixes)
        return [CheckNode.from_parent(session, name=p.name, nodeid=p.name, planned=p,
                                      wanted=self.named.get(p.name))
                for p in self.plan.checks]

    def run(self, session: pytest.Session) -> None:
        """Run the checks that have a selected item, each on its selected cases where it can,
        give every item its result, and put the cases the checks reported undeclared among
        the items, after their check's last."""
        from hcard_conformance.runner import run_suite

        pending = [i for i in session.items if isinstance(i, ConformanceItem)
                   and i.result is None]
        if self.plan is None or not pending:
            return
        by_check: dict[str, list[ConformanceItem]] = {}
        for item in pending:
            by_check.setdefault(item.check, []).append(item)
        chosen = [p for p in self.plan.checks if p.name in by_check]
        narrowed: dict[str, frozenset[str]] = {}
        for planned in chosen:
            names = frozenset(i.name for i in by_check[planned.name] if not i.undeclared)
            whole = not planned.cases and not names
            if not whole and (not planned.cases or not names >= set(planned.cases)):
                narrowed[planned.name] = names
        self.ctx.selected_cases = narrowed
        report = run_suite(self.ctx, self.plan.levels, checks=[p.check for p in chosen],
                           check_done=self._progress)
        extras = self._assign(report.results, by_check, narrowed)
        self._place(session, extras)

    def _assign(self, results: Iterable[CheckResult], by_check: dict[str, list[ConformanceItem]],
                narrowed: dict[str, frozenset[str]]) -> dict[str, list[ConformanceItem]]:
        """Give each item its result; the results no item waits for become extra items (by
        check), except those of cases not selected: declared ones, or any of a check that
        declares none when node IDs named its cases."""
        assert self.plan is not None
        seen: Counter[tuple[str, str]] = Counter()
        extras: dict[str, list[ConformanceItem]] = {}
        errors: dict[str, list[str]] = {}
        for result in results:
            seen[(result.check, result.case)] += 1
            n = seen[(result.check, result.case)]
            name = result.case if n == 1 else f"{result.case}#{n}"
            if result.status == ERROR:
                errors.setdefault(result.check, []).append(result.detail)
            mine = by_check.get(result.check, [])
            item = next((i for i in mine if i.name == name and not i.undeclared), None)
            if item is not None:
                item.record(result)
                continue
            planned = self.plan.check(result.check)
            declared = planned.cases if planned is not None else None
            if result.check in narrowed and (not declared or name in declared):
                continue  # not selected
            parent = mine[0].parent if mine else None
            if parent is not None:
                extras.setdefault(result.check, []).append(ConformanceItem.from_parent(
                    parent, name=name, check=result.check, level=result.level, result=result))
        for check, items in by_check.items():
            for item in items:
                if item.result is None:
                    why = f"; it raised: {' | '.join(errors[check])}" if check in errors else ""
                    item.missing = f"{check} did not report case {item.name}{why}"
        return extras

    @staticmethod
    def _place(session: pytest.Session, extras: dict[str, list[ConformanceItem]]) -> None:
        """Put each check's extra items after its last item, in place of its
        :data:`UNDECLARED` item (which its reported cases replace)."""
        last = {item.check: k for k, item in enumerate(session.items)
                if isinstance(item, ConformanceItem)}
        placed: list[pytest.Item] = []
        for k, item in enumerate(session.items):
            replaced = (isinstance(item, ConformanceItem) and item.undeclared
                        and bool(extras.get(item.check)))
            if not replaced:
                placed.append(item)
            if isinstance(item, ConformanceItem) and last.get(item.check) == k:
                placed += extras.get(item.check, [])
        session.items[:] = placed
        session.testscollected = len(placed)  # the terminal's progress counts from it

    def _progress(self, chk: Any, results: list[CheckResult], duration_s: float) -> None:
        """One line per check run, on the terminal (not with ``-q``)."""
        reporter = self.config.pluginmanager.get_plugin("terminalreporter")
        if reporter is not None and self.config.getoption("verbose") >= 0:
            n = len(results)
            reporter.write_line(f"hcard conformance: {chk.name}: {n} case{'s' * (n != 1)} in "
                                f"{duration_s:.2f} s")


SUITE_KEY = pytest.StashKey[Suite]()
"""Where a session's :class:`Suite` is kept (``config.stash``)."""


def pytest_addoption(parser: pytest.Parser) -> None:
    """Options of the ``hcard conformance`` group."""
    group = parser.getgroup("hcard-conformance", "hcard conformance suite")
    group.addoption("--hcard-driver", default=None, metavar="URI",
                    help="implementation under test: reference, a device URI (sim://, ...) "
                         "or control:NAME; without it the plugin adds no tests")
    group.addoption("--hcard-level", action="append", default=[], choices=LEVELS,
                    help="conformance level to run (repeatable; default all)")
    group.addoption("--hcard-vectors", default=None, metavar="DIR",
                    help="vectors directory (default: spec/vectors of hcard_conformance)")
    group.addoption("--hcard-check", action="append", default=[], metavar="PREFIX",
                    help="only checks whose name starts with PREFIX (repeatable)")
    parser.addini("hcard_driver", "default --hcard-driver", default="")


def _driver(config: pytest.Config) -> str | None:
    return config.getoption("--hcard-driver") or config.getini("hcard_driver") or None


def pytest_configure(config: pytest.Config) -> None:
    """With a driver: the session's :class:`Suite`, and the arguments that are its node IDs
    taken out of pytest's file arguments (pytest would look for a file of that name)."""
    driver = _driver(config)
    if driver is None:
        return
    suite = Suite(config, driver)
    config.args[:] = suite.take_node_ids(list(config.args), config.invocation_params.dir,
                                         config.rootpath)
    config.stash[SUITE_KEY] = suite


def pytest_report_header(config: pytest.Config) -> str | None:
    """Name the implementation under test in pytest's header."""
    driver = _driver(config)
    return f"hcard conformance: driver {driver}" if driver else None


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector) -> Any:
    """The session's children: pytest's own, then the suite's (:meth:`Suite.roots`)."""
    outcome = yield
    suite = collector.config.stash.get(SUITE_KEY, None)
    if suite is None or not isinstance(collector, pytest.Session):
        return
    report = outcome.get_result()
    if report.passed:
        report.result.extend(suite.roots(collector))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtestloop(session: pytest.Session) -> Any:
    """Run the suite's selected checks before the first test (not when collecting only,
    planning only, or when collection failed: pytest then stops)."""
    suite = session.config.stash.get(SUITE_KEY, None)
    option = session.config.option
    stops = bool(session.testsfailed) and not option.continue_on_collection_errors
    if suite is not None and not (option.collectonly or getattr(option, "setupplan", False)
                                  or stops):
        suite.run(session)
    yield


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """A case's duration is the time the suite spent on it, not the ~0 s of reporting it: on
    the phase that reports it (setup for an ERROR, else the call)."""
    outcome = yield
    if not isinstance(item, ConformanceItem) or item.result is None:
        return
    error = item.result.status == ERROR
    if call.when == ("setup" if error else "call"):
        outcome.get_result().duration = item.result.duration_s
