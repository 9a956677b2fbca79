"""pytest plugin: the conformance suite as test items of a vendor's own test run.

Enable it with one line, either on the command line::

    pytest -p hcard_conformance.pytest_plugin --hcard-driver=sim://

or in the vendor's top-level ``conftest.py``::

    pytest_plugins = ["hcard_conformance.pytest_plugin"]

and name the implementation with ``--hcard-driver=URI`` (or the ini option ``hcard_driver``).
Without a driver the plugin adds nothing. Options: ``--hcard-level`` (repeatable),
``--hcard-vectors DIR``, ``--hcard-check PREFIX`` (repeatable).

The suite runs once, during collection (its cases, such as the vectors and the device's
faults, are only known by running it); each (check, case) becomes one item named
``check[case]`` that passes or fails with the case's result. A failure reports
``VALUE UNIT > THRESHOLD UNIT (METRIC)`` and the detail; metric, value, threshold and unit are
also recorded as user properties, so ``--junitxml`` carries them.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from hcard.errors import HcardError
from hcard_conformance.result import LEVELS, CheckResult


class ConformanceFailure(HcardError):
    """A conformance case failed (its result is in ``args[0]``)."""


class ConformanceItem(pytest.Item):
    """One (check, case) of the suite, carrying the result it already has."""

    def __init__(self, *, result: CheckResult, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.result = result
        self.user_properties += [("level", result.level), ("metric", result.metric),
                                 ("value", result.value), ("threshold", result.threshold),
                                 ("unit", result.unit)]

    def runtest(self) -> None:
        """Fail when the case failed."""
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
        return str(super().repr_failure(excinfo))

    def reportinfo(self) -> tuple[str, int | None, str]:
        """Location shown by pytest: the check and case."""
        return f"hcard conformance {self.result.level}", None, self.name


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
    """Run the suite and append one item per (check, case)."""
    driver = _driver(config)
    if driver is None:
        return
    from hcard_conformance.context import Context
    from hcard_conformance.runner import run_suite

    vectors = config.getoption("--hcard-vectors")
    ctx = Context.for_driver(driver, vectors_root=Path(vectors) if vectors else None)
    report = run_suite(ctx, config.getoption("--hcard-level") or LEVELS,
                       select=config.getoption("--hcard-check"))
    seen: dict[str, int] = {}
    for result in report.results:
        name = f"{result.check}[{result.case}]"
        seen[name] = seen.get(name, 0) + 1
        if seen[name] > 1:
            name = f"{name}#{seen[name]}"
        items.append(ConformanceItem.from_parent(session, name=name, result=result))
