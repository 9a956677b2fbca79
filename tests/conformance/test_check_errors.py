"""A check never crashes the run (spec/conformance.md QP5): whatever a plugin's check raises,
wherever it raises it (its ``applies`` predicate, importing it, building its generator, between
cases, even SystemExit), the run records an ERROR naming the check and the cause (exception
type, message, file:line) and goes on with the other checks."""

from __future__ import annotations

import types
from collections.abc import Iterator
from typing import Any

import pytest

from hcard.plugins import hookimpl
from hcard.plugins.registry import PluginRegistry
from hcard_conformance.context import Context
from hcard_conformance.registry import LazyCheck, all_checks, check
from hcard_conformance.result import ERROR, PASS, UNASSESSED, CannotAssess, CheckResult, measured
from hcard_conformance.runner import run_suite

HERE = __file__.removesuffix("c")  # the .py, not a cached .pyc


def _broken_applies(ctx: Context) -> bool:
    raise ZeroDivisionError("no idea whether it applies")


def _plugin_checks() -> list[Any]:
    found: dict[str, Any] = {}

    @check(name="acme.applies-raises", level="format", applies=_broken_applies, registry=found)
    def applies_raises(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.applies-raises", "format", "never", "x", 0.0, 1.0)

    @check(name="acme.raises-at-once", level="format", registry=found)
    def raises_at_once(ctx: Context) -> Iterator[CheckResult]:  # not a generator: raises now
        raise KeyError("card 7")

    @check(name="acme.exits", level="format", registry=found)
    def exits(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.exits", "format", "first", "x", 0.0, 1.0)
        raise SystemExit(3)

    @check(name="acme.cannot", level="format", registry=found)
    def cannot(ctx: Context) -> Iterator[CheckResult]:
        raise CannotAssess("no fixture plate on this bench")
        yield  # a generator

    @check(name="acme.fine", level="format", registry=found)
    def fine(ctx: Context) -> Iterator[CheckResult]:
        yield measured("acme.fine", "format", "ok", "x", 0.0, 1.0)

    lazy = [LazyCheck("acme.not-importable", "format", "its module is gone",
                      "acme_gone.checks:check_gone"),
            LazyCheck("acme.predicate-not-importable", "format", "its predicate is gone",
                      "hcard_conformance.format_level:check_parse", "acme_gone.checks:applies")]
    return [*found.values(), *lazy]


@pytest.fixture(scope="module")
def results() -> dict[str, list[CheckResult]]:
    plugin = types.ModuleType("acme_conformance")
    plugin.hcard_conformance_checks = hookimpl(_plugin_checks)  # type: ignore[attr-defined]
    registry = PluginRegistry()
    registry.register(plugin, package="acme")
    chosen = [c for c in all_checks(("format",), registry=registry)
              if c.name.startswith("acme.")]
    assert len(chosen) == 7
    report = run_suite(Context.for_driver("reference"), ("format",), checks=chosen)
    out: dict[str, list[CheckResult]] = {}
    for r in report.results:
        out.setdefault(r.check, []).append(r)
    assert set(report.check_durations_s) == set(out)
    return out


def test_a_raising_applies_predicate_is_an_error_of_that_check(
        results: dict[str, list[CheckResult]]) -> None:
    (r,) = results["acme.applies-raises"]
    assert (r.case, r.status) == ("(error)", ERROR)
    assert r.detail.startswith("check acme.applies-raises raised ZeroDivisionError: no idea "
                               f"whether it applies (at {HERE}:")
    assert r.detail.endswith("while deciding whether it applies")


def test_a_check_that_raises_before_its_generator_is_an_error(
        results: dict[str, list[CheckResult]]) -> None:
    (r,) = results["acme.raises-at-once"]
    assert (r.case, r.status) == ("(error)", ERROR)
    assert f"check acme.raises-at-once raised KeyError: 'card 7' (at {HERE}:" in r.detail


def test_system_exit_inside_a_check_is_an_error_after_its_last_case(
        results: dict[str, list[CheckResult]]) -> None:
    first, error = results["acme.exits"]
    assert (first.case, first.status) == ("first", PASS)
    assert (error.case, error.status) == ("(error after first)", ERROR)
    assert "raised SystemExit: 3" in error.detail


def test_cannot_assess_outside_guarded_is_unassessed(
        results: dict[str, list[CheckResult]]) -> None:
    (r,) = results["acme.cannot"]
    assert r.status == UNASSESSED and "no fixture plate on this bench" in r.detail


def test_checks_whose_code_cannot_be_imported_are_errors(
        results: dict[str, list[CheckResult]]) -> None:
    (gone,) = results["acme.not-importable"]
    assert gone.status == ERROR and "ModuleNotFoundError" in gone.detail
    assert "acme_gone" in gone.detail
    (predicate,) = results["acme.predicate-not-importable"]
    assert predicate.status == ERROR and "acme_gone" in predicate.detail
    assert "while deciding whether it applies" in predicate.detail


def test_the_other_checks_still_run(results: dict[str, list[CheckResult]]) -> None:
    (r,) = results["acme.fine"]
    assert r.status == PASS
