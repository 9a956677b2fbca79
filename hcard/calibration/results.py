"""What the calibration loop is set by and what it finds (spec/calibration.md).

The thresholds (:class:`LoopSettings`, and the criterion in words, :data:`CRITERION`), each
fitted model (:class:`ModelFit`), each candidate tried (:class:`Candidate`), the structure left
in the final residual (:class:`Structure`), the verdicts (:data:`NO_EFFECT`, :data:`EXPLAINED`,
:data:`NOT_EXPLAINED`, :data:`AMBIGUOUS`), the whole answer (:class:`CalibrationResult`) and an
error written for people (:func:`format_error`). The loop that fills them is
:mod:`hcard.calibration.loop`; the rules it decides by, :mod:`hcard.calibration.judges`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from hcard.calibration.bootstrap import BootstrapResult
from hcard.calibration.dataset import CalibrationData
from hcard.calibration.fit import FitResult
from hcard.calibration.noise import NoiseModel
from hcard.calibration.residuals import ResidualReport
from hcard.calibration.screening import SCREEN_SAMPLES
from hcard.calibration.selection import Comparison, Separation
from hcard.quantities import MN_PER_N

# the verdicts (:func:`hcard.calibration.judges.verdict_of`)
NO_EFFECT = "no effect needed"
EXPLAINED = "explained by added effects"
NOT_EXPLAINED = "structured residual not explained by any known effect"
AMBIGUOUS = "ambiguous: the data cannot separate the final model from its runner-up"

CRITERION = (
    "held-out information criterion H = n_eff ln(MSE_held-out) + 2k (k free parameters, n_eff "
    "the held-out sample count corrected for lag-1 autocorrelation); an effect is added when "
    "it lowers H, cuts the held-out RMSE by at least {min_improvement:.0%}, and the residual "
    "shows structure against its signature (one regressor, or all of them jointly)"
)


@dataclass(frozen=True)
class LoopSettings:
    """Thresholds of the loop (:mod:`hcard.calibration.judges`).

    Attributes:
        min_improvement: relative fall of the held-out RMSE an added effect must bring.
        alpha: significance level of the residual F-tests.
        min_eta2: share of residual variance a regressor must explain for the final residual to
            count as structured (10 %: samples of one stroke share its speed and force, so a
            slow sensor drift left per stroke already explains a few percent by chance).
        signature_eta2: share of the current residual an effect's signature must explain
            (one of its regressors, or their joint cells chance-adjusted) for the effect to be
            credited.
        min_autocorrelation: lag-1 autocorrelation of the final residual above which it counts
            as structured in time.
        max_effects: most effects added.
        bins: quantile bins of the residual analysis.
        separation_criterion: smallest difference of ``H`` between the final model and its
            runner-up for the data to separate them.
        separation_rmse: smallest relative difference of their held-out RMSE for the same.
        screen_samples: training samples a candidate is first fitted on (every ``k``-th,
            :mod:`hcard.calibration.screening`); candidates whose screened figures come near a
            decision are fitted on every training sample before it is made. 0: every candidate
            is fitted on every training sample.
    """

    min_improvement: float = 0.05
    alpha: float = 0.01
    min_eta2: float = 0.10
    signature_eta2: float = 0.01
    min_autocorrelation: float = 0.5
    max_effects: int = 4
    bins: int = 10
    separation_criterion: float = 10.0
    separation_rmse: float = 0.01
    screen_samples: int = SCREEN_SAMPLES

    def separation(self) -> Separation:
        """The thresholds below which the final model and its runner-up are not separated."""
        return Separation(self.separation_criterion, self.separation_rmse)

    def criterion(self) -> str:
        """The selection criterion in words, with this instance's thresholds."""
        return CRITERION.format(min_improvement=self.min_improvement)


@dataclass(frozen=True)
class ModelFit:
    """One fitted model of the loop.

    Attributes:
        effects: names of the effects in the model, in the order added.
        fit: the fit (its predictor outputs the lateral force, N).
        analysis: the residual analysis of all samples under this model.
        score: held-out criterion ``H`` at the ``n_eff`` of the round that produced it.
    """

    effects: tuple[str, ...]
    fit: FitResult
    analysis: ResidualReport
    score: float

    @property
    def test_rmse(self) -> float:
        """Held-out RMSE, N."""
        return float(self.fit.test_rmse) if self.fit.test_rmse is not None else math.nan

    @property
    def train_rmse(self) -> float:
        """Training RMSE, N."""
        return self.fit.train_rmse


@dataclass(frozen=True)
class Candidate:
    """One effect tried in one round.

    Attributes:
        round: 1-based round number.
        effect: effect name.
        test_rmse: held-out RMSE with the effect added, N (None when not fitted).
        improvement: relative fall of the held-out RMSE against the round's current model.
        score_change: change of ``H`` against the current model (negative is better).
        added_parameters: number of parameters the effect adds.
        signature_eta2: the largest significant eta^2 of the current residual against the
            effect's signature: a single regressor, or their joint cells chance-adjusted.
        accepted: whether the effect was added.
        note: why it was (not) added, or why it was not fitted.
        seconds: wall time of its fit, s.
        screened: whether its figures are those of a fit on the screening samples only
            (:mod:`hcard.calibration.screening`; the held-out RMSE scaled by its start
            model's full over screened one): far enough from every threshold that a full fit
            could not change the decision.
    """

    round: int
    effect: str
    test_rmse: float | None
    improvement: float | None
    score_change: float | None
    added_parameters: int
    signature_eta2: float
    accepted: bool
    note: str
    seconds: float = 0.0
    screened: bool = False


def fitted_figure(figure: float | None) -> float:
    """A :class:`Candidate` figure that its fit has set (every fitted candidate has them)."""
    assert figure is not None
    return figure


@dataclass(frozen=True)
class Structure:
    """Where the residual of the final model is still structured.

    Attributes:
        regressors: ``(name, eta2, p)`` of each structured regressor, strongest first.
        autocorrelation: lag-1 autocorrelation of the residual in time order.
        in_time: whether it counts as structured in time.
        dominant_frequency_hz: largest non-DC spectral peak of the residual, Hz (or None).
        small: ``(name, eta2, p)`` of each regressor with significant structure (p < alpha)
            below the practical threshold ``min_eta2``: reported, not acted on.
        time_threshold: lag-1 autocorrelation above which the residual counts as structured
            in time (from the noise model, :func:`~hcard.calibration.noise.
            time_structure_threshold`).
        noise: the sensor noise measured out of contact, or None.
        min_eta2: the practical threshold of ``eta^2``.
        detectable: ``(name, eta2)``: the smallest ``eta^2`` each regressor's F-test detects
            with 80 % power at the residual's effective sample count.
        interactions: ``("a x b", eta2, p)`` of each pair of regressors whose interaction
            explains at least ``min_eta2`` beyond their main effects (spec/calibration.md K28).
        beyond_noise: share of the residual's variance beyond the sensor noise (0 without a
            noise model; :func:`~hcard.calibration.noise.beyond_noise`, K37).
    """

    regressors: tuple[tuple[str, float, float], ...]
    autocorrelation: float
    in_time: bool
    dominant_frequency_hz: float | None
    small: tuple[tuple[str, float, float], ...] = ()
    time_threshold: float = 0.5
    noise: NoiseModel | None = None
    min_eta2: float = 0.10
    detectable: tuple[tuple[str, float], ...] = ()
    interactions: tuple[tuple[str, float, float], ...] = ()
    beyond_noise: float = 0.0

    @property
    def any(self) -> bool:
        """Whether any structure is left."""
        return bool(self.regressors) or self.in_time or bool(self.interactions)

    def describe(self) -> str:
        """Where the structure is, in words."""
        parts = [f"{name} (eta2 {eta2:.2f})" for name, eta2, _ in self.regressors]
        parts += [f"the interaction {name} (eta2 {eta2:.2f} beyond each alone)"
                  for name, eta2, _ in self.interactions]
        timed = ""
        if self.in_time:
            where = f"in time (lag-1 autocorrelation {self.autocorrelation:.2f}"
            if self.noise is not None and self.noise.lag1 > 0:
                where += f" against {self.noise.lag1:.2f} of the sensor noise"
            if self.beyond_noise > 0:
                where += f"; {self.beyond_noise:.0%} of its variance beyond the sensor noise"
            if self.dominant_frequency_hz is not None:
                where += f", dominant frequency {self.dominant_frequency_hz:.3g} Hz"
            timed = where + ")"
        if not parts:
            return timed or "none"
        return "against " + ", ".join(parts) + (f", and {timed}" if timed else "")

    def describe_small(self) -> str:
        """The small but significant structure, in words (empty when there is none)."""
        if not self.small:
            return ""
        shown = ", ".join(
            f"{name}: eta2 {eta2:.3f}, p {_p_text(p)}" for name, eta2, p in self.small
        )
        return f"small structure against {shown}, below the practical threshold of " \
            f"eta2 {self.min_eta2:g}"


def _p_text(p: float) -> str:
    """A p-value for people: ``< 1e-6`` below that, else ``= 0.0012``."""
    return "< 1e-6" if p < 1e-6 else f"= {p:.2g}"


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`~hcard.calibration.loop.calibrate` found.

    Attributes:
        model: name of the base predictor.
        verdict: :data:`NO_EFFECT`, :data:`EXPLAINED`, :data:`NOT_EXPLAINED` or :data:`AMBIGUOUS`.
        summary: one paragraph: the error before and after and what was added or left.
        before: the base model's fit.
        after: the final model's fit (``before`` when nothing was added).
        steps: every accepted model, the base first.
        candidates: every effect tried, round by round.
        structure: structure left in the final residual.
        library: names of the effects in the library.
        skipped: effect name -> why it could not be tried on this model or these data.
        data: the data fitted.
        settings: the thresholds.
        seconds: wall time of the loop, s.
        effects_added: names of the effects added, in order.
        unit: unit of the observed quantity and of the errors (``"N"`` for a lateral force).
        observation: what the data's observed values are (:data:`OBSERVATIONS`).
        comparison: the final model against the best other model of as many effects (one
            effect when none was added), or None when no other was fitted.
        bootstrap: the final model's parameter uncertainties from a stroke-block bootstrap
            (:func:`~hcard.calibration.loop.with_bootstrap`), or None: the uncertainties are
            then the fit's ``sigma^2 (J^T J)^-1``.
    """

    model: str
    verdict: str
    summary: str
    before: ModelFit
    after: ModelFit
    steps: tuple[ModelFit, ...]
    candidates: tuple[Candidate, ...]
    structure: Structure
    library: tuple[str, ...]
    skipped: dict[str, str]
    data: CalibrationData
    settings: LoopSettings
    seconds: float = 0.0
    effects_added: tuple[str, ...] = field(default=())
    unit: str = "N"
    observation: str = "lateral_force"
    comparison: Comparison | None = None
    bootstrap: BootstrapResult | None = None

    @property
    def uncertainty_method(self) -> str:
        """Which uncertainty the parameters carry and how it was computed."""
        if self.bootstrap is not None:
            return self.bootstrap.method()
        return (
            "sigma^2 (J^T J)^-1 of the fit, which takes every training sample as independent "
            "white noise: an under-estimate when the residual is correlated (a stroke-block "
            "bootstrap was not run)"
        )

    @property
    def improvement(self) -> float:
        """Relative fall of the held-out RMSE from before to after."""
        return 1.0 - self.after.test_rmse / self.before.test_rmse

    def effect_parameters(self, name: str) -> dict[str, tuple[float, float, str]]:
        """An added effect's fitted parameters: short name -> (value, uncertainty, unit); the
        uncertainty is the bootstrap's when one was run (:attr:`uncertainty_method`)."""
        prefix = f"{name}."
        units = {p.name: p.unit for p in self.after.fit.predictor.parameters}
        sigma = (
            self.after.fit.uncertainties if self.bootstrap is None
            else self.bootstrap.uncertainties
        )
        return {
            key[len(prefix) :]: (
                value,
                sigma.get(key, math.nan),
                units.get(key, ""),
            )
            for key, value in self.after.fit.params.items()
            if key.startswith(prefix)
        }


OBSERVATIONS = ("lateral_force", "output")
"""What the data's ``observed`` array is: the lateral force a tribometer measures (the model is
wrapped by :func:`~hcard.calibration.observation.lateral_force_model`), or the model's own output
(e.g. an electrostatic force measured on a scale)."""


def format_error(value: float, unit: str) -> str:
    """An error for people: forces in mN, other units as they are."""
    if unit == "N":
        return f"{value * MN_PER_N:.4g} mN"
    return f"{value:.4g} {unit}".rstrip()
