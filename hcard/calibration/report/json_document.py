"""``report.json``: a calibration report for programs (:mod:`hcard.calibration.report`), format
:data:`FORMAT`, finite numbers only (NaN and infinities become ``null``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict
from typing import Any

import numpy as np

from hcard.calibration.profile import parameter_table, profile_of
from hcard.calibration.residuals import ResidualReport
from hcard.calibration.results import CalibrationResult, ModelFit
from hcard.calibration.screening import SCREEN_TOLERANCE, describe_screening, screening_stride
from hcard.physics.profile import DeviceProfile
from hcard.version import __version__

FORMAT = "hcard-calibration-report/1"
"""Value of the ``format`` key of ``report.json``."""


def _finite(value: Any) -> Any:
    """``value`` with numpy types as Python ones and NaN/inf as None, recursively."""
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_finite(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def _analysis_dict(analysis: ResidualReport) -> dict[str, Any]:
    return {
        "n": analysis.n,
        "rms_n": analysis.rms,
        "regressors": {
            name: {
                "eta2": s.eta2,
                "f_statistic": s.f_statistic,
                "p_value": s.p_value,
                "spearman_rho": s.spearman_rho,
                "spearman_p": s.spearman_p,
                "monotonic": s.monotonic,
                "bin_centres": s.bin_centres,
                "bin_means_n": s.bin_means,
                "bin_counts": s.bin_counts,
            }
            for name, s in analysis.regressors.items()
        },
        "time": asdict(analysis.time),
    }


def _model_dict(step: ModelFit) -> dict[str, Any]:
    fit = step.fit
    return {
        "effects": list(step.effects),
        "held_out_rmse_n": step.test_rmse,
        "train_rmse_n": step.train_rmse,
        "score": step.score,
        "free": list(fit.free),
        "at_bounds": list(fit.at_bounds),
        "held": list(fit.held),
        "condition_number": fit.condition_number,
        "success": fit.success,
        "parameters": parameter_table(fit),
    }


def report_dict(
    result: CalibrationResult,
    figures: Sequence[str] = (),
    *,
    profile: DeviceProfile | None = None,
    rendering: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The content of ``report.json`` (finite numbers only; ``figures``: relative file names)."""
    data = result.data
    content = {
        "format": FORMAT,
        "hcard_version": __version__,
        "model": result.model,
        "verdict": result.verdict,
        "summary": result.summary,
        "held_out_rmse_n": {"before": result.before.test_rmse, "after": result.after.test_rmse},
        "train_rmse_n": {"before": result.before.train_rmse, "after": result.after.train_rmse},
        "relative_change": -result.improvement,
        "effects_added": [
            {
                "name": name,
                "parameters": {
                    short: {"value": v, "uncertainty": s, "unit": u}
                    for short, (v, s, u) in result.effect_parameters(name).items()
                },
            }
            for name in result.after.effects
        ],
        "uncertainty_method": result.uncertainty_method,
        "bootstrap": None
        if result.bootstrap is None
        else {
            "samples": result.bootstrap.samples,
            "requested": result.bootstrap.requested,
            "capped": result.bootstrap.capped,
            "held": list(result.bootstrap.held),
            "seed": result.bootstrap.seed,
            "strokes": result.bootstrap.strokes,
            "uncertainties": result.bootstrap.uncertainties,
            "intervals_95": result.bootstrap.intervals,
            "jacobian_uncertainties": result.after.fit.uncertainties,
        },
        "criterion": result.settings.criterion(),
        "settings": asdict(result.settings),
        "screening": {
            "stride": screening_stride(int(np.count_nonzero(data.train)),
                                       result.settings.screen_samples),
            "tolerance": SCREEN_TOLERANCE,
            "description": describe_screening(int(np.count_nonzero(data.train)),
                                              result.settings.screen_samples),
        },
        "data": {
            "sources": list(data.sources),
            "samples": len(data),
            "training_samples": int(np.count_nonzero(data.train)),
            "held_out_samples": int(np.count_nonzero(data.test)),
            "split": data.split,
            "sample_rate_hz": data.sample_rate_hz,
            "sensor_zero": [
                {"source": source, "lifts": lifts, "drift_n": _finite(drift)}
                for source, (lifts, drift) in zip(data.sources, data.zeroing, strict=False)
            ],
            "regressors": list(data.regressors),
            "contact_threshold_n": list(data.contact_threshold_n),
        },
        "warnings": list(data.warnings),
        "library": list(result.library),
        "candidates": [asdict(c) for c in result.candidates],
        "runner_up": None
        if result.comparison is None
        else {
            **asdict(result.comparison),
            "description": result.comparison.describe(),
            "separation": result.settings.separation().describe(),
        },
        "skipped": dict(result.skipped),
        "structure": {
            "regressors": [
                {"name": n, "eta2": e, "p_value": p} for n, e, p in result.structure.regressors
            ],
            "autocorrelation": result.structure.autocorrelation,
            "in_time": result.structure.in_time,
            "dominant_frequency_hz": result.structure.dominant_frequency_hz,
            "description": result.structure.describe(),
            "small": [
                {"name": n, "eta2": e, "p_value": p} for n, e, p in result.structure.small
            ],
            "small_description": result.structure.describe_small(),
            "time_threshold": result.structure.time_threshold,
            "variance_beyond_noise": result.structure.beyond_noise,
            "noise": None
            if result.structure.noise is None
            else {
                "sigma_n": result.structure.noise.sigma,
                "lag1": result.structure.noise.lag1,
                "samples": result.structure.noise.samples,
                "runs": result.structure.noise.runs,
            },
            "detectable_eta2_at_80_percent_power": dict(result.structure.detectable),
        },
        "residuals": {
            "before": _analysis_dict(result.before.analysis),
            "after": _analysis_dict(result.after.analysis),
        },
        "steps": [_model_dict(step) for step in result.steps],
        "before": _model_dict(result.before),
        "after": _model_dict(result.after),
        "profile": (profile if profile is not None else profile_of(result)).to_dict(),
        "rendering": None if rendering is None else dict(rendering),
        "figures": list(figures),
        "seconds": result.seconds,
    }
    return _finite(content)
