"""The known-fault table (spec/conformance.md QN2): every fault of the faulty device, run through
the conformance runner restricted to the check of its row (as ``hcard conformance --driver
faulty://... --level LEVEL --check CHECK`` runs it), has a FAIL case at the row's strength above
the threshold and passes every case of the same run at its strength below; the table in
conformance/README.md is the table's data.

The faulty device runs on its own clock, so a row's figures do not depend on the machine's
load; a case that is not assessed (UNASSESSED) or raised (ERROR) is never taken for a pass or
for the FAIL a row needs.
"""

from __future__ import annotations

import pytest

from hcard_conformance.context import Context
from hcard_conformance.faulty.faults import FAULTS, fault_uri
from hcard_conformance.faulty.known_faults import KNOWN_FAULTS
from hcard_conformance.registry import BUILTIN_CHECKS
from hcard_conformance.result import FAIL, PASS, CheckResult
from hcard_conformance.runner import run_suite
from hcard_device.controls import CATCHES
from tests.helpers.known_fault_table import README, expected_block, readme_block


def run_row(fault: str, strength: float) -> list[CheckResult]:
    """The results of the row of ``fault`` at ``strength``: its check alone, on its renders."""
    row = next(r for r in KNOWN_FAULTS if r.fault == fault)
    ctx = Context.for_driver(row.uri(strength))
    if row.renders:
        ctx.options["renders"] = list(row.renders)
    results = run_suite(ctx, (row.level,), select=(row.check,)).results
    assert {r.check for r in results} == {row.check}, [(r.check, r.case) for r in results]
    if row.renders:
        assert {r.case for r in results} == set(row.renders), [r.case for r in results]
    return results


def _outcomes(results: list[CheckResult]) -> str:
    return "; ".join(f"{r.case} {r.outcome} {r.value:.4g} ({r.detail})" for r in results)


def _rows() -> list[str]:
    """Every row's fault."""
    return [row.fault for row in KNOWN_FAULTS]


@pytest.mark.parametrize("fault", _rows())
def test_above_its_threshold_the_fault_fails_its_check(fault: str) -> None:
    row = next(r for r in KNOWN_FAULTS if r.fault == fault)
    results = run_row(fault, row.fails_at)
    failed = [r for r in results if r.outcome == FAIL]
    assert failed, f"{row.uri(row.fails_at)} did not fail {row.check}: {_outcomes(results)}"


@pytest.mark.parametrize("fault", _rows())
def test_below_its_threshold_the_fault_passes_every_case_of_its_check(fault: str) -> None:
    row = next(r for r in KNOWN_FAULTS if r.fault == fault)
    results = run_row(fault, row.passes_at)
    assert results and all(r.outcome == PASS for r in results), (
        f"{row.uri(row.passes_at)} did not pass {row.check}: {_outcomes(results)}")


def test_every_fault_has_one_row_with_strengths_in_its_range() -> None:
    assert [row.fault for row in KNOWN_FAULTS] == [fault.name for fault in FAULTS]
    for row in KNOWN_FAULTS:
        assert row.check in {c.name for c in BUILTIN_CHECKS}, row.check
        assert 0 < row.passes_at < row.fails_at <= row.info.most, row.fault
        assert row.why and (row.level == "renderer") == bool(row.renders)
        assert row.uri(row.fails_at) == fault_uri(row.fault, row.fails_at)


def test_the_readme_table_is_the_data() -> None:
    """conformance/README.md holds the table made from the rows and the reference device's
    negative controls (``controls.CATCHES``); ``python -m tests.helpers.known_fault_table``
    rewrites it after a change."""
    found = readme_block(README.read_text(encoding="utf-8"))
    assert found is not None, "conformance/README.md has lost the known-fault table's markers"
    assert found == expected_block(), (
        "the known-fault table of conformance/README.md is not the data; run python -m "
        "tests.helpers.known_fault_table")
    assert all(f"`control:{name}`" in found for name in CATCHES)
    assert all(f"`faulty://{row.fault}`" in found for row in KNOWN_FAULTS)
