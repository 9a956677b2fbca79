"""Whether two calibrations of the same recording gave the same answers: what the calibration
benches compare a screened loop against the loop that fits every candidate on every sample by.
"""

from __future__ import annotations

from hcard.calibration.results import CalibrationResult


def differences(baseline: CalibrationResult, screened: CalibrationResult) -> list[str]:
    """What differs between the two answers (empty: nothing): the effects, the verdict, the
    accepted fit, and the runner-up where it may decide the verdict (it or its screened
    counterpart within twice the separation thresholds of the final model)."""
    found = []
    if screened.effects_added != baseline.effects_added:
        found.append(f"effects {baseline.effects_added} / {screened.effects_added}")
    if screened.verdict != baseline.verdict:
        found.append(f"verdict {baseline.verdict!r} / {screened.verdict!r}")
    if screened.after.fit.params != baseline.after.fit.params:
        found.append("accepted fit's parameters")
    if screened.after.test_rmse != baseline.after.test_rmse:
        found.append("accepted fit's held-out RMSE")
    near = [r.comparison is not None and r.after.effects != () and (
        r.comparison.criterion_margin < 2 * r.settings.separation_criterion
        or r.comparison.rmse_margin < 2 * r.settings.separation_rmse)
        for r in (baseline, screened)]
    if any(near) and runner_up(baseline) != runner_up(screened):
        found.append(f"runner-up {runner_up(baseline)} / {runner_up(screened)}")
    return found


def runner_up(result: CalibrationResult) -> tuple[tuple[str, ...], float] | None:
    """The runner-up's effects and its criterion margin to the final model."""
    if result.comparison is None:
        return None
    return result.comparison.runner_up, result.comparison.criterion_margin
