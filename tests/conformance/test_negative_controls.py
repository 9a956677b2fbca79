"""Negative controls: each deliberately faulty driver fails the check made to catch it, by a
margin, and passes the checks its defect does not touch."""

from __future__ import annotations

import pytest

from hcard_conformance import renderer_level as rl
from hcard_conformance.context import Context
from hcard_conformance.device_checks.dynamics import check_dynamics
from hcard_conformance.device_checks.friction import check_friction
from hcard_conformance.device_checks.latency import check_latency
from hcard_conformance.device_checks.safety import check_safety
from hcard_conformance.device_checks.watchdog import check_watchdog
from hcard_conformance.registry import all_checks
from hcard_conformance.result import FAIL, PASS, CheckResult
from hcard_device.controls import (
    ACTUATOR_GAIN,
    CATCHES,
    CONTROLS,
    FREQUENCY_ERROR,
    open_control,
)

pytestmark = pytest.mark.wall_clock


def _run(name: str, check: object, renders: list[str] | None = None) -> dict[str, CheckResult]:
    ctx = Context.for_driver(name)
    if renders:
        ctx.options["renders"] = renders
    return {r.case: r for r in check(ctx)}  # type: ignore[operator]


def test_controls_are_reachable_by_name() -> None:
    assert set(CONTROLS) == {
        "position-only", "latency-30ms", "no-ev", "over-limit", "swapped-channels",
        "inverted-phase", "frequency-off", "weak-actuator", "ignored-watchdog", "late-limits",
        "no-ownership", "no-attribution", "shared-halts", "blocking-writes", "accepts-bad-crc",
        "drops-reports",
        "reads-any-major",
        "silent-refusals", "unplayed-commit", "profile-raises-limits", "sticky-profile",
        "misdeclared-state", "wrapped-forces", "host-accepts-any-major",
        "host-refuses-newer-minor", "host-crashes-on-short-report", "host-barges-in"}
    assert set(CATCHES) == set(CONTROLS)  # every control names the check it must fail
    with open_control("control:no-ev") as driver:
        assert driver.info().capabilities & 2  # advertises EV, ignores it
    with pytest.raises(ValueError, match="unknown negative control"):
        open_control("faster-than-light")


def test_position_only_fails_dense_and_passes_coarse() -> None:
    results = _run("control:position-only", check_friction)
    dense, coarse = results["dense-grating"], results["coarse-taxtels"]
    assert not dense.passed and dense.value > 0.25  # 4 mm grating held for 20 ms: aliased
    assert coarse.passed and coarse.value < 0.02


def test_added_latency_fails_the_latency_check() -> None:
    result = _run("control:latency-30ms", check_latency)["boundary-move"]
    assert not result.passed
    assert 30.0 <= result.value <= 33.0  # ms: 30 ms added to the reference's ~1 ms


def test_ignoring_ev_fails_bipolar_textures() -> None:
    results = _run("control:no-ev", check_friction)
    assert not results["bipolar"].passed and results["bipolar"].value > 0.1
    assert results["coarse-taxtels"].passed and results["dense-grating"].passed


def test_unenforced_limits_fail_the_safety_check() -> None:
    results = _run("control:over-limit", check_safety)
    host = results["host-limits"]
    assert not host.passed
    assert host.value > 300  # reports over the limit, out of ~450 in the stroke
    assert "largest measured output 2.00" in host.detail  # 2.5 um hardware vs 1.25 um set
    assert results["card-over-limit"].passed  # the hardware limit itself still holds


def test_swapped_channels_fail_the_rendered_friction() -> None:
    """UV targets on the EV actuation (which only raises friction) and EV targets on the plate
    (which only lowers it): nothing is rendered, so every case is off by about its contrast."""
    results = _run("control:swapped-channels", check_friction)
    assert {r.outcome for r in results.values()} == {FAIL}
    # coarse checkerboard of 1.0 and 0.5: half the reports want 0.5 and get 1 -> error 1 there
    assert 0.55 < results["coarse-taxtels"].value < 0.9
    assert results["bipolar"].value > 0.3


def test_inverted_phase_fails_spatial_phase_and_the_rendered_grating() -> None:
    """Half a cycle off on the 40 mm coarse grating is 20 mm, beyond A4's +-50 ms search: the
    metric reports the bound of its search (speed x 50 ms), twice the 2.5 mm threshold."""
    phase = _run("control:inverted-phase", rl.check_spatial_phase,
                 ["coarse-grating@moderate-stroke"])["coarse-grating@moderate-stroke"]
    assert phase.outcome == FAIL
    assert phase.value == pytest.approx(100.0 * 0.050, rel=0.05)  # mm: 100 mm/s x 50 ms
    dense = _run("control:inverted-phase", check_friction)["dense-grating"]
    assert dense.outcome == FAIL and dense.value > 0.3


def test_frequency_off_fails_the_component_frequency() -> None:
    """A3 finds each grating and temporal component FREQUENCY_ERROR - 1 = 15 % high."""
    cases = ["single-grating@moderate-stroke", "temporal@slow-stroke"]
    results = _run("control:frequency-off", rl.check_component_frequency, cases)
    for case in cases:
        assert results[case].outcome == FAIL
        assert results[case].value == pytest.approx(FREQUENCY_ERROR - 1.0, abs=0.01)


def test_weak_actuator_fails_the_rise_time() -> None:
    """35 % of the piezo gain the PI loop was tuned for: the loop's crossover falls by about
    that factor and the 10-90 % rise time goes from ~1.3 ms to beyond the 2 ms JND."""
    results = _run("control:weak-actuator", check_dynamics)
    rise = results["rise-time"]
    assert ACTUATOR_GAIN == 0.35
    assert rise.outcome == FAIL and 2.5 < rise.value < 6.0  # ms


def test_self_fed_watchdog_fails_the_watchdog_check() -> None:
    results = _run("control:ignored-watchdog", check_watchdog)
    assert results["host-silent"].outcome == FAIL
    assert results["host-silent"].value == float("inf")  # the plate never went off
    assert results["fault-reported"].outcome == FAIL and results["fault-reported"].value == 0.0
    # the same device without the defect passes, so the control isolates the defect
    reference = _run("sim://", check_watchdog)
    assert {r.outcome for r in reference.values()} == {PASS}


@pytest.mark.parametrize("name", sorted(CATCHES))
def test_every_control_fails_at_its_named_check(name: str) -> None:
    """Each control, run through the registered check it names (as `hcard conformance
    --driver control:NAME --check CHECK` would), fails the named case."""
    check_name, case = CATCHES[name]
    chosen = {c.name: c for c in all_checks(plugins=False)}[check_name]
    ctx = Context.for_driver(f"control:{name}")
    if check_name.startswith("renderer."):
        ctx.options["renders"] = [case]
    results = {r.case: r for r in chosen.run(ctx)}
    assert case in results, sorted(results)
    assert results[case].outcome == FAIL, results[case].detail
