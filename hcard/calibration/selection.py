"""The runner-up of a model selection, the margin, and the measurement that would separate them.

The loop (:mod:`hcard.calibration.loop`) ends on one set of effects. :func:`compare` sets it
against the best other set of the same size it fitted (the runner-up) and states the margin:
the difference of the held-out criterion ``H`` and of the held-out RMSE. When the margin is
below :class:`Separation`'s thresholds the data cannot tell the two apart; the measurement that
would is read from where the two models' predictions differ most: the regressor whose bins
explain the largest share of the prediction difference (its ``eta^2``), named as a protocol
change by :data:`MEASUREMENTS`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from hcard.calibration.residuals import bin_labels

MEASUREMENTS: dict[str, str] = {
    "stroke": "rests of a few seconds between runs of strokes (the stroke count since a rest "
              "restarts while the time runs on)",
    "time": "a longer recording with long rests out of contact (time runs on through a rest "
            "while the stroke count restarts)",
    "contact_time": "strokes of several durations",
    "occlusion_time": "long rests out of contact between runs of strokes (the occlusion time "
                      "stops in a rest while the time runs on)",
    "normal_force": "strokes at several normal forces, over a wider range",
    "speed": "strokes at several speeds, over a wider range",
    "amplitude": "strokes at several vibration amplitudes",
    "voltage": "strokes at several voltages",
    "pressure": "recordings at several ambient pressures",
    "plate_frequency": "recordings at several plate frequencies",
    "amplitude_history": "amplitude steps held for several durations",
    "voltage_history": "voltage steps held for several durations",
    "direction": "strokes in both directions at each speed and force",
    "x": "strokes over other parts of the surface",
    "y": "strokes over other parts of the surface",
    "recording": "more recordings under each condition",
}
"""A regressor -> the measurement that spreads it (what to record to separate two models whose
predictions differ most along it)."""


@dataclass(frozen=True)
class Separation:
    """Thresholds below which two models are not separated by the data.

    Attributes:
        min_criterion: smallest difference of the held-out criterion ``H`` (a likelihood ratio
            of ``exp(min_criterion / 2)`` at the effective sample count).
        min_rmse: smallest relative difference of the held-out RMSE.
    """

    min_criterion: float = 10.0
    min_rmse: float = 0.01

    def describe(self) -> str:
        """The thresholds in words."""
        return (
            f"two models are separated when the runner-up's held-out criterion is at least "
            f"{self.min_criterion:g} higher and its held-out RMSE at least "
            f"{self.min_rmse:.0%} higher"
        )


@dataclass(frozen=True)
class Comparison:
    """The final model against its runner-up.

    Attributes:
        chosen: effects of the final model.
        runner_up: effects of the best other model of the same size.
        criterion_margin: ``H`` of the runner-up minus that of the final model (positive: the
            final model is better).
        rmse_margin: relative held-out RMSE difference, ``RMSE_runner-up / RMSE_final - 1``.
        chosen_rmse: held-out RMSE of the final model (output unit).
        runner_up_rmse: held-out RMSE of the runner-up (output unit).
        ambiguous: whether the margin is below the :class:`Separation` thresholds.
        separating_regressor: the regressor along which the two models' predictions differ
            most (None when they do not differ).
        separating_eta2: share of the prediction difference its bins explain.
        largest_difference: the largest binned relative prediction difference along it
            (final minus runner-up, over the final model's prediction).
        at_value: the regressor's value (median of that bin, its unit).
        measurement: the measurement that would separate them.
    """

    chosen: tuple[str, ...]
    runner_up: tuple[str, ...]
    criterion_margin: float
    rmse_margin: float
    chosen_rmse: float
    runner_up_rmse: float
    ambiguous: bool
    separating_regressor: str | None
    separating_eta2: float
    largest_difference: float
    at_value: float
    measurement: str

    def names(self) -> tuple[str, str]:
        """The two models as text (``a + b``; ``base model`` for no effect)."""
        return model_name(self.chosen), model_name(self.runner_up)

    def describe(self) -> str:
        """The comparison in one sentence."""
        chosen, runner = self.names()
        text = (
            f"runner-up {runner}: held-out criterion {self.criterion_margin:+.1f}, held-out "
            f"RMSE {100 * self.rmse_margin:+.1f} % against {chosen}"
        )
        if self.ambiguous:
            text = f"ambiguous between {chosen} and {runner} ({text})"
            if self.separating_regressor is not None:
                text += (
                    f"; their predictions differ most against {self.separating_regressor} "
                    f"(eta2 {self.separating_eta2:.3f}); to separate them, record "
                    f"{self.measurement}"
                )
        return text


def model_name(effects: Sequence[str]) -> str:
    """A set of effects as text: ``a + b``, or ``base model``."""
    return " + ".join(effects) if effects else "base model"


def separating_regressor(
    difference: np.ndarray, regressors: Mapping[str, np.ndarray], bins: int = 10
) -> tuple[str | None, float, float, float]:
    """Where two models' predictions differ most: ``(regressor, eta2, largest binned mean
    difference, regressor value there)``.

    ``difference`` is prediction A minus prediction B per sample (any unit; :func:`compare`
    passes it relative to prediction A, the effects being factors on it); each regressor
    is cut into ``bins`` quantile bins (or its distinct values), and the one whose bin means
    explain the largest share of the difference's variance around zero (``eta^2`` of the
    binned mean difference) wins: a constant offset (which ``force_offset`` absorbs) counts for
    nothing. Returns ``(None, 0, 0, nan)`` when the predictions do not differ.
    """
    d = np.asarray(difference, dtype=np.float64)
    centred = d - d.mean()
    total = float(np.sum(centred**2))
    if total <= 0:
        return None, 0.0, 0.0, float("nan")
    best: tuple[str | None, float, float, float] = (None, 0.0, 0.0, float("nan"))
    for name, values in regressors.items():
        x = np.asarray(values, dtype=np.float64)
        if x.shape != d.shape or np.ptp(x) == 0:
            continue
        labels = bin_labels(x, bins)
        present = np.unique(labels)
        means = np.array([centred[labels == k].mean() for k in present])
        counts = np.array([np.count_nonzero(labels == k) for k in present])
        eta2 = float(np.sum(counts * means**2) / total)
        if eta2 > best[1]:
            k = int(np.argmax(np.abs(means)))
            at = float(np.median(x[labels == present[k]]))
            best = (name, eta2, float(means[k]), at)
    return best


def compare(
    chosen: tuple[str, ...],
    chosen_score: float,
    chosen_rmse: float,
    chosen_prediction: np.ndarray,
    runner_up: tuple[str, ...],
    runner_up_score: float,
    runner_up_rmse: float,
    runner_up_prediction: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    separation: Separation,
    bins: int = 10,
    *,
    decides: bool = True,
) -> Comparison:
    """Compare the final model with its runner-up (module docstring). Scores are the held-out
    criterion ``H`` at one effective sample count; predictions are over the fitted samples,
    aligned with ``regressors``. ``decides``: whether an ambiguity is a verdict (False when
    the final model is the base model, whose runner-up is the best effect not added: the
    margin is reported, the base model is not "ambiguous")."""
    margin = float(runner_up_score - chosen_score)
    rmse_margin = float(runner_up_rmse / chosen_rmse - 1.0) if chosen_rmse > 0 else float("inf")
    ambiguous = decides and (
        margin < separation.min_criterion or rmse_margin < separation.min_rmse
    )
    a = np.asarray(chosen_prediction, dtype=np.float64)
    b = np.asarray(runner_up_prediction, dtype=np.float64)
    scale = np.abs(a)
    kept = scale > 0.01 * float(np.median(scale)) if scale.size else scale > 0
    name, eta2, largest, at = separating_regressor(
        (a[kept] - b[kept]) / scale[kept],
        {k: np.asarray(v)[kept] for k, v in regressors.items()},
        bins,
    )
    return Comparison(
        chosen=chosen,
        runner_up=runner_up,
        criterion_margin=margin,
        rmse_margin=rmse_margin,
        chosen_rmse=float(chosen_rmse),
        runner_up_rmse=float(runner_up_rmse),
        ambiguous=ambiguous,
        separating_regressor=name,
        separating_eta2=eta2,
        largest_difference=largest,
        at_value=at,
        measurement=MEASUREMENTS.get(name or "", f"a wider range of {name}"),
    )
