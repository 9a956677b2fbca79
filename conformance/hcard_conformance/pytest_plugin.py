"""pytest plugin: the conformance suite as test items of a vendor's own test run.

Enable it with one line, either on the command line::

    pytest -p hcard_conformance.pytest_plugin --hcard-driver=sim://

or in the vendor's top-level ``conftest.py``::

    pytest_plugins = ["hcard_conformance.pytest_plugin"]

and name the implementation with ``--hcard-driver=URI`` (or the ini option ``hcard_driver``).
Without a driver the plugin adds nothing. Options: ``--hcard-level`` (repeatable),
``--hcard-vectors DIR``, ``--hcard-check PREFIX`` (repeatable).

The suite runs once, during collection (its cases, such as the vectors and the device's
faults, are only known by running it); each (check, case) becomes one item, node ID
``CHECK::CASE``, so ``--junitxml`` gives it ``classname`` CHECK and ``name`` CASE, and its
duration is the case's own. A case that passed passes; one that failed fails, reporting
``VALUE UNIT > THRESHOLD UNIT (METRIC)`` and the detail; an UNASSESSED case is skipped with its
reason; an ERROR case is an error. Metric, value, threshold and unit are also recorded as user
properties, so ``--junitxml`` carries them. A driver that cannot be opened is one error,
``hcard-conformance::setup``, not a run. ``--collect-only`` runs nothing: it lists one item per
check, ``CHECK::cases``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from hcard.errors import HcardError
from hcard_conformance.result import ERROR, LEVELS, UNASSESSED, CheckResult


class ConformanceFailure(HcardError):
    """A conformance case failed (its result is in ``args[0]``)."""


class ConformanceError(HcardError):
    """A conformance case could not be run: the check raised, or the run could not start."""


class CheckNode(pytest.Collector):
    """One check (or the run itself): the parent of its cases, so that a case's node ID is
    ``CHECK::CASE`` and its JUnit ``classname`` the check."""

    def collect(self) -> list[pytest.Item]:
        """Nothing more to collect: the cases are made with the results."""
        return []


class ConformanceItem(pytest.Item):
    """One (check, case) of the suite, carrying the result it already has."""

    def __init__(self, *, result: CheckResult, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.result = result
        self.user_properties += [("level", result.level), ("metric", result.metric),
                                 ("value", result.value), ("threshold", result.threshold),
                                 ("unit", result.unit)]

    def setup(self) -> None:
        """An ERROR case is an error (the check raised), not a failure."""
        if self.result.status == ERROR:
            raise ConformanceError(self.result.detail)

    def runtest(self) -> None:
        """Fail when the case failed; skip, with the reason, when it could not be assessed."""
        if self.result.status == UNASSESSED:
            pytest.skip(f"UNASSESSED: {self.result.detail}")
        if not self.result.passed:
            raise ConformanceFailure(self.result)

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: Any = None) -> str:
        """The failure message and detail of the case (no traceback: nothing to debug here)."""
        if isinstance(excinfo.value, ConformanceFailure):
            from hcard_conformance.report import failure_message

            r = self.result
            return (f"{r.check} [{r.level}] {r.case}: {failure_message(r)}\n"
                    f"{r.detail}")
        if isinstance(excinfo.value, ConformanceError):
            return f"{self.result.check} [{self.result.level}] {self.result.case}: ERROR " \
                   f"{excinfo.value}"
        return str(super().repr_failure(excinfo))

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest: the check and case."""
        return f"hcard conformance {self.result.level}", None, self.nodeid


class SetupErrorItem(pytest.Item):
    """The run could not start (the driver cannot be opened): one error naming why."""

    def __init__(self, *, reason: str, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.reason = reason

    def setup(self) -> None:
        """Always an error: the suite did not run."""
        raise ConformanceError(self.reason)

    def runtest(self) -> None:  # never reached: setup raises
        """Nothing: the suite did not run."""

    def repr_failure(self, excinfo: pytest.ExceptionInfo[BaseException],
                     style: Any = None) -> str:
        """The reason, without a traceback."""
        return f"hcard conformance could not start: {excinfo.value}"

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest."""
        return "hcard conformance", None, self.nodeid


class PendingCheckItem(pytest.Item):
    """A check listed by ``--collect-only``: its cases are known only by running it."""

    def runtest(self) -> None:  # collect-only never runs it
        """Nothing: collection only lists the check."""

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest."""
        return "hcard conformance", None, self.nodeid


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


def pytest_report_header(config: pytest.Config) -> str | None:
    """Name the implementation under test in pytest's header."""
    driver = _driver(config)
    return f"hcard conformance: driver {driver}" if driver else None


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config,
                                  items: list[pytest.Item]) -> None:
    """Run the suite and append one item per (check, case); with ``--collect-only`` list the
    checks without running them."""
    driver = _driver(config)
    if driver is None:
        return
    from hcard_conformance.context import Context
    from hcard_conformance.registry import all_checks
    from hcard_conformance.runner import run_suite

    vectors = config.getoption("--hcard-vectors")
    levels = config.getoption("--hcard-level") or LEVELS
    prefixes = tuple(config.getoption("--hcard-check"))
    nodes: dict[str, CheckNode] = {}

    def node(name: str) -> CheckNode:
        if name not in nodes:
            nodes[name] = CheckNode.from_parent(session, name=name, nodeid=name)
        return nodes[name]

    if config.option.collectonly:
        for chk in all_checks(levels):
            if not prefixes or chk.name.startswith(prefixes):
                items.append(PendingCheckItem.from_parent(node(chk.name), name="cases"))
        _count_collected(session, items)
        return
    ctx = Context.for_driver(driver, vectors_root=Path(vectors) if vectors else None)
    if ctx.open_driver is not None:
        try:
            ctx.open_driver().close()
        except (HcardError, OSError, ValueError) as exc:
            items.append(SetupErrorItem.from_parent(
                node("hcard-conformance"), name="setup",
                reason=f"cannot open driver {driver!r}: {exc}"))
            _count_collected(session, items)
            return
    report = run_suite(ctx, levels, select=list(prefixes))
    seen: dict[str, int] = {}
    for result in report.results:
        name = f"{result.check}::{result.case}"
        seen[name] = seen.get(name, 0) + 1
        case = result.case if seen[name] == 1 else f"{result.case}#{seen[name]}"
        items.append(ConformanceItem.from_parent(node(result.check), name=case, result=result))
    _count_collected(session, items)


def _count_collected(session: pytest.Session, items: list[pytest.Item]) -> None:
    """Count the items this plugin added: pytest counted the collected tests before
    ``pytest_collection_modifyitems`` (its session total, and the terminal's "N tests
    collected", which has no public setter: set where the reporter keeps it, when it does)."""
    session.testscollected = len(items)
    reporter = session.config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None and hasattr(reporter, "_numcollected"):
        reporter._numcollected = len(items)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]) -> Any:
    """A case's duration is the time the suite spent on it, not the ~0 s of reporting it."""
    outcome = yield
    if isinstance(item, ConformanceItem) and call.when == "call":
        outcome.get_result().duration = item.result.duration_s
