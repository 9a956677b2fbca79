"""Negative controls: each deliberately faulty driver fails the check made to catch it, by a
margin, and passes the checks its defect does not touch."""

from __future__ import annotations

import pytest

from hcard_conformance import device_level as dl
from hcard_conformance.context import Context
from hcard_conformance.controls import CONTROLS, open_control
from hcard_conformance.result import CheckResult


def _run(name: str, check: object) -> dict[str, CheckResult]:
    return {r.case: r for r in check(Context.for_driver(name))}  # type: ignore[operator]


def test_controls_are_reachable_by_name() -> None:
    assert set(CONTROLS) == {"position-only", "latency-30ms", "no-ev", "over-limit"}
    with open_control("control:no-ev") as driver:
        assert driver.info().capabilities & 2  # advertises EV, ignores it
    with pytest.raises(ValueError, match="unknown negative control"):
        open_control("faster-than-light")


def test_position_only_fails_dense_and_passes_coarse() -> None:
    results = _run("control:position-only", dl.check_friction)
    dense, coarse = results["dense-grating"], results["coarse-taxtels"]
    assert not dense.passed and dense.value > 0.25  # 4 mm grating held for 20 ms: aliased
    assert coarse.passed and coarse.value < 0.02


def test_added_latency_fails_the_latency_check() -> None:
    result = _run("control:latency-30ms", dl.check_latency)["boundary-move"]
    assert not result.passed
    assert 30.0 <= result.value <= 33.0  # ms: 30 ms added to the reference's ~1 ms


def test_ignoring_ev_fails_bipolar_textures() -> None:
    results = _run("control:no-ev", dl.check_friction)
    assert not results["bipolar"].passed and results["bipolar"].value > 0.1
    assert results["coarse-taxtels"].passed and results["dense-grating"].passed


def test_unenforced_limits_fail_the_safety_check() -> None:
    results = _run("control:over-limit", dl.check_safety)
    host = results["host-limits"]
    assert not host.passed
    assert host.value > 300  # reports over the limit, out of ~450 in the stroke
    assert "largest measured output 2.00" in host.detail  # 2.5 um hardware vs 1.25 um set
    assert results["card-over-limit"].passed  # the hardware limit itself still holds
