"""The rules the calibration loop decides by (spec/calibration.md), each a function of figures
already computed.

Whether a calibration's arguments are usable (:func:`check_arguments`, :func:`default_free`),
which effects of the library can be tried (:func:`usable_effects`) and what the models can act
on (:func:`claimed_regressors`); the criterion a candidate must pass (:func:`criterion_failure`,
:func:`judge_round`, :func:`earns_place`, with the structure against its signature measured by
:func:`beyond_foreign_structure`); the structure left in a residual (:func:`residual_structure`)
and the verdict (:func:`verdict_of`). The loop that applies them is :mod:`hcard.calibration.loop`;
the verdicts they return and the criterion's wording are in :mod:`hcard.calibration.results`.

**Criterion** (stated in every report as :data:`~hcard.calibration.results.CRITERION`). Each
model ``m`` with ``k_m`` free parameters gets a held-out information criterion

    ``H_m = n_eff ln(MSE_test,m) + 2 k_m``

where ``MSE_test`` is the mean squared error on the held-out samples (which the fit never saw)
and ``n_eff = n_test (1 - rho) / (1 + rho)`` is the number of effectively independent held-out
samples given the lag-1 autocorrelation ``rho`` of the current model's held-out residual
(samples of one stroke are not independent; clipped to [1, n_test]). The candidate with the
lowest ``H`` is accepted when (a) ``H`` falls (the error gain pays for the added parameters),
(b) its held-out RMSE falls by at least ``min_improvement`` (default 5 %: a practically
significant gain, not a fit to noise or drift), and (c) the current residual shows structure
against the effect's signature (F-test p < ``alpha`` with ``eta^2 >= signature_eta2``, against
one of its regressors or, chance-adjusted, against the joint cells of all of them): an effect
is never credited for an error it does not explain where it says it would. When the residual
holds structure against a *foreign* regressor, one no model input or effect signature covers
(the sliding direction, the position, the recording), and that structure is at least
:data:`FOREIGN_DOMINANCE` times the signature's, (c) is judged with it taken out
(:func:`beyond_foreign_structure`).

**Verdicts.** When no candidate passes, the residual of the final model is analysed once more.
Structure left against a regressor (p < ``alpha`` and ``eta^2 >= min_eta2``) or in time
(lag-1 autocorrelation ``>= min_autocorrelation``) gives ``NOT_EXPLAINED``, naming where the
structure is; none gives ``NO_EFFECT`` (nothing added), ``AMBIGUOUS`` (effects added, and a
runner-up within the margin) or ``EXPLAINED`` (effects added): the constants of
:mod:`hcard.calibration.results`.
"""

from __future__ import annotations

import math
from collections.abc import Container, Mapping, Sequence
from dataclasses import replace

import numpy as np

from hcard.calibration.dataset import CalibrationData
from hcard.calibration.fit import FitResult
from hcard.calibration.model_pool import held_out_criterion
from hcard.calibration.noise import (
    EXCESS_MIN_LAG1,
    EXCESS_MIN_SHARE,
    NoiseModel,
    beyond_noise,
    detectable_eta2,
    time_structure_threshold,
)
from hcard.calibration.residuals import (
    MIN_BIN_COUNT,
    ResidualReport,
    analyse_residuals,
    bin_labels,
    effective_samples,
    interactions,
    joint_structure,
    linear_share,
    mostly_one_value,
)
from hcard.calibration.results import (
    AMBIGUOUS,
    EXPLAINED,
    NO_EFFECT,
    NOT_EXPLAINED,
    OBSERVATIONS,
    Candidate,
    LoopSettings,
    Structure,
    fitted_figure,
)
from hcard.calibration.selection import Comparison
from hcard.physics import Predictor, PredictorError
from hcard.physics.effects import Effect

FOREIGN_DOMINANCE = 2.0
"""How many times the signature's eta2 a foreign regressor's must be before the signature test
is judged with the foreign structure taken out (:func:`beyond_foreign_structure`)."""


def default_free(base: Predictor) -> tuple[str, ...]:
    """The base parameters a calibration fits by default: the predictor's ``calibrated``
    attribute when it sets one, else all of its parameters."""
    chosen = tuple(getattr(base, "calibrated", ()) or ())
    return chosen or tuple(p.name for p in base.parameters)


def check_arguments(
    data: CalibrationData, base: Predictor, free: Sequence[str] | None, observation: str
) -> tuple[str, ...]:
    """The base parameters a calibration of ``base`` on ``data`` fits (``free``, default
    :func:`default_free`), once the arguments are checked.

    Raises:
        PredictorError: ``observation`` not one of :data:`OBSERVATIONS`, ``data`` without
            held-out samples, a name in ``free`` that is not a parameter of ``base``, or an
            input of ``base`` without a default that ``data`` do not provide.
    """
    if observation not in OBSERVATIONS:
        raise PredictorError(
            f"observation must be one of {', '.join(OBSERVATIONS)}, got {observation!r}"
        )
    if not data.test.any():
        raise PredictorError("the data have no held-out samples; the loop needs a split")
    base_free = tuple(free) if free is not None else default_free(base)
    unknown = sorted(set(base_free) - {p.name for p in base.parameters})
    if unknown:
        raise PredictorError(
            f"{base.name}: unknown parameter(s) {', '.join(unknown)} to fit; parameters: "
            f"{', '.join(p.name for p in base.parameters)}"
        )
    given = data.inputs_for(base)
    missing = sorted(v.name for v in base.inputs if v.default is None and v.name not in given)
    if missing:
        raise PredictorError(
            f"model {base.name} needs input(s) {', '.join(missing)}, which these recordings "
            f"do not provide (they give {', '.join(sorted(data.inputs))})"
        )
    return base_free


def usable_effects(
    library: Sequence[Effect], base: Predictor, varying: Container[str]
) -> tuple[list[Effect], dict[str, str]]:
    """The effects of ``library`` the loop can try on ``base``, in library order, and why
    each other one cannot be tried (effect name -> reason): it does not apply to ``base``
    (:meth:`~hcard.physics.effects.Effect.applies_to`), or none of its signature
    regressors is in ``varying`` (the regressors that vary in the data), so that it cannot be
    identified."""
    skipped: dict[str, str] = {}
    usable: list[Effect] = []
    for effect in library:
        why = effect.applies_to(base)
        if why is None and not any(name in varying for name in effect.signature):
            why = (
                f"its signature ({', '.join(effect.signature)}) does not vary in these data, "
                "so it cannot be identified"
            )
        if why:
            skipped[effect.name] = why
        else:
            usable.append(effect)
    return usable, skipped


def claimed_regressors(base: Predictor, usable: Sequence[Effect]) -> frozenset[str]:
    """What the models can act on: the inputs of ``base`` and every input and signature
    regressor of the ``usable`` effects. Structure against any other regressor (the sliding
    direction, the position, the recording) is *foreign* (:func:`beyond_foreign_structure`)."""
    return frozenset(
        {v.name for v in base.inputs}
        | {name for effect in usable for name in effect.signature}
        | {v.name for effect in usable for v in effect.inputs}
    )


def _signature_eta2(effect: Effect, analysis: ResidualReport, residual: np.ndarray,
                    regressors: Mapping[str, np.ndarray], alpha: float) -> float:
    """How much of ``residual`` (the current model's, on the samples in use) lies where
    ``effect`` says its error would: the largest significant (p < ``alpha``) eta2 of a single
    signature regressor, or, for a signature of several regressors, the chance-adjusted eta2
    of their joint cells (:func:`~hcard.calibration.residuals.joint_structure`). An effect on
    the electrostatic force shows only where there is voltage: on the load alone its residual
    read eta2 0.009, jointly on load and voltage 0.09. A regressor that holds one value on at
    least half of the samples (the amplitude's change over 10 ms, 0 on 87 % of them) also
    counts by the share of its linear trend (:func:`~hcard.calibration.residuals.
    linear_share`): its quantile bins merge into a few wide ones, and an actuator's lag that cut
    the held-out RMSE 18 % read eta2 0.006 over them, 0.035 linear. Any other regressor does
    not: a linear trend picks up what other regressors confound with it (speed at three
    levels, cycled with time, on a residual of occlusion)."""
    values = [
        analysis.regressors[name].eta2
        for name in effect.signature
        if name in analysis.regressors and analysis.regressors[name].p_value < alpha
    ]
    present = [name for name in effect.signature if name in regressors]
    for name in present:
        if not mostly_one_value(regressors[name]):
            continue  # its bins resolve it: the ANOVA's eta2 above stands
        share, p_value = linear_share(residual, regressors[name], analysis.effective_samples)
        if p_value < alpha:
            values.append(share)
    if len(present) >= 2:
        joint = joint_structure(residual, {name: regressors[name] for name in present},
                                analysis.effective_samples)
        if joint.p_value < alpha:
            values.append(joint.adjusted_eta2)
    return max(values, default=0.0)


def beyond_foreign_structure(
    effect: Effect,
    analysis: ResidualReport,
    residual: np.ndarray,
    regressors: Mapping[str, np.ndarray],
    claimed: frozenset[str],
    settings: LoopSettings,
) -> tuple[float, str | None]:
    """:func:`_signature_eta2` of the residual with its structure against the strongest
    *foreign* regressor taken out: one that is neither an input of the models nor in a usable
    effect's signature (``claimed``: the sliding direction, the position and the recording are
    foreign) and that holds significant structure
    (p < ``alpha``, ``eta^2 >= min_eta2``). Its bin means are subtracted, and the residual
    analysed again on the effect's signature. Returns that eta2 and the foreign regressor
    (None, and the plain eta2, when there is none).

    Only a foreign regressor that explains :data:`FOREIGN_DOMINANCE` times the signature's
    share is taken out: it is then the likelier cause. One that merely matches it is the
    effect's own structure seen through the design (a recording per ambient pressure: the
    recording holds the pressure's structure exactly), and taking it out would hide the effect.
    An effect is credited only for structure that is not the foreign regressor's seen through
    a correlated design: with friction 20 % higher sliding towards -x and back-and-forth
    strokes that start every session in the same direction, the stroke count after a rest
    carries the direction, and skin-recovery (signature: stroke) cut the held-out error by
    more than 5 % without any recovery in the data."""
    plain = _signature_eta2(effect, analysis, residual, regressors, settings.alpha)
    foreign = [
        stats for name, stats in analysis.regressors.items()
        if name not in claimed and name in regressors and stats.p_value < settings.alpha
        and stats.eta2 >= max(settings.min_eta2, FOREIGN_DOMINANCE * plain)
    ]
    if not foreign:
        return plain, None
    strongest = max(foreign, key=lambda stats: stats.eta2)
    labels = bin_labels(np.asarray(regressors[strongest.name], dtype=np.float64),
                        settings.bins)
    means = np.bincount(labels, weights=residual) / np.maximum(np.bincount(labels), 1)
    controlled = residual - means[labels]
    own = {name: regressors[name] for name in effect.signature if name in regressors}
    again = analyse_residuals(controlled, own, bins=settings.bins)
    return min(plain, _signature_eta2(effect, again, controlled, own, settings.alpha)), \
        strongest.name


def residual_structure(
    analysis: ResidualReport,
    settings: LoopSettings,
    time_ordered: bool,
    noise: NoiseModel | None = None,
    residual: np.ndarray | None = None,
    regressors: Mapping[str, np.ndarray] | None = None,
) -> Structure:
    """Where the residual analysed in ``analysis`` is still structured (:class:`Structure`):
    regressors with p < ``alpha`` and ``eta^2 >= min_eta2`` (those below it as ``small``), the
    detectable ``eta^2`` of each regressor's F-test, and structure in time when
    ``time_ordered`` and the lag-1 autocorrelation reaches the threshold set by the sensor
    ``noise`` (:func:`~hcard.calibration.noise.time_structure_threshold`) and, without a
    ``noise`` model (no lifts or rests to measure it on), the residual's block means vary more
    than an AR(1) noise fitted to the residual gives (p < ``alpha``,
    :func:`~hcard.calibration.noise.ar1_block_test`, K29); given the ``residual`` analysed
    and its ``regressors`` (aligned, regressor SI units), every pair of regressors whose
    interaction explains ``min_eta2`` beyond their main effects at ``alpha`` over the number
    of pairs (:func:`~hcard.calibration.residuals.interactions`, K28)."""
    rho = analysis.time.lag1_autocorrelation
    threshold = time_structure_threshold(settings.min_autocorrelation, noise)
    significant = analysis.structured(settings.alpha, 0.0)
    detectable = tuple(
        (
            name,
            detectable_eta2(
                analysis.effective_samples,
                int(np.count_nonzero(s.bin_counts >= MIN_BIN_COUNT)),
                settings.alpha,
            ),
        )
        for name, s in analysis.regressors.items()
    )
    block = analysis.time.beyond_noise
    # K29: without a measured noise model, a correlated residual is structured in time only
    # when it holds more slow variance than an AR(1) noise fitted to it
    beyond = noise is not None or block is None or block.p_value < settings.alpha
    # K37: with a measured noise model, the variance beyond the sensor noise, when it is a
    # large share of the residual and correlated in time, is structure in time whatever
    # the lag-1 of the whole residual (a sensor resonance dilutes it with white noise)
    share, excess_lag1, p_excess = beyond_noise(analysis.rms, rho, analysis.effective_samples,
                                                noise)
    excess = (share >= EXCESS_MIN_SHARE and excess_lag1 >= EXCESS_MIN_LAG1
              and p_excess < settings.alpha)
    return Structure(
        regressors=tuple(item for item in significant if item[1] >= settings.min_eta2),
        autocorrelation=rho,
        in_time=time_ordered and beyond and (rho >= threshold or excess),
        dominant_frequency_hz=analysis.time.dominant_frequency_hz,
        small=tuple(item for item in significant if item[1] < settings.min_eta2),
        time_threshold=threshold,
        noise=noise,
        beyond_noise=share,
        min_eta2=settings.min_eta2,
        detectable=detectable,
        interactions=() if residual is None or regressors is None else tuple(
            (" x ".join(found.names), found.eta2, found.p_value)
            for found in interactions(residual, regressors, analysis.effective_samples,
                                      settings.alpha, settings.min_eta2)),
    )


EXCESS_TO_EXPLAIN = 0.5
"""Share of the base model's held-out MSE beyond the sensor noise an effect must remove where
that is less than K9 (b)'s cut of the RMSE (:func:`noise_aware`, spec/calibration.md K38)."""


def noise_aware(settings: LoopSettings, held_out: np.ndarray, noise: NoiseModel | None
                ) -> tuple[LoopSettings, str | None]:
    """``settings`` with K9 (b)'s ``min_improvement`` lowered where the sensor noise is most of
    the base model's held-out error (K38): an effect passes (b) when it cuts the held-out RMSE
    by ``min_improvement`` or removes :data:`EXCESS_TO_EXPLAIN` of the held-out MSE beyond the
    noise, ``1 - sqrt(1 - 0.5 s)`` for an excess share ``s`` -- when the excess is significant
    (:func:`~hcard.calibration.noise.beyond_noise` at ``alpha``). With the air layer hidden in
    the device, 91 % of the base's held-out MSE was the sensor's noise: the air layer removed
    all the rest (held-out RMSE -4.6 %, ``H`` -690, the rendering error cut 2.8x) and was
    refused at 5 %. ``held_out``: the base model's held-out residual (output unit). Returns the
    settings and a line saying what was changed (None: nothing)."""
    if noise is None or held_out.size < 2:
        return settings, None
    rms = float(np.sqrt(np.mean(held_out * held_out)))
    share, _, p_value = beyond_noise(rms, 0.0, effective_samples(held_out), noise)
    needed = 1.0 - math.sqrt(1.0 - EXCESS_TO_EXPLAIN * share)
    if p_value >= settings.alpha or needed >= settings.min_improvement:
        return settings, None
    return replace(settings, min_improvement=needed), (
        f"{1.0 - share:.0%} of the base model's held-out MSE is the sensor noise: an effect "
        f"earns its place by cutting the held-out RMSE {needed:.1%} (half of the rest), not "
        f"{settings.min_improvement:.0%} (K38)")


def criterion_failure(candidate: Candidate, settings: LoopSettings) -> str:
    """Why a fitted ``candidate`` cannot be added (empty: it passes every check of the
    criterion, module docstring): (a) its ``score_change`` of ``H`` must be negative, (b) its
    ``improvement`` (relative fall of the held-out RMSE) at least ``min_improvement``, (c) its
    ``signature_eta2`` at least ``signature_eta2``; the first check it fails is named."""
    assert candidate.score_change is not None and candidate.improvement is not None
    if candidate.score_change >= 0:
        return "does not lower the held-out criterion"
    if candidate.improvement < settings.min_improvement:
        return (
            f"cuts the held-out RMSE by {candidate.improvement:.1%}, less than "
            f"{settings.min_improvement:.0%}"
        )
    if candidate.signature_eta2 < settings.signature_eta2:
        return "the residual shows no structure against its signature"
    return ""


def judge_round(
    tried: Sequence[tuple[Candidate, bool]], settings: LoopSettings
) -> tuple[str | None, list[Candidate]]:
    """The decision of one round on its candidates ``tried`` (each with whether it was fitted):
    the name of the effect added, the passing candidate (:func:`criterion_failure`) of lowest
    ``score_change``, or None; and every candidate again, in order, marked ``accepted`` or not
    with its ``note`` saying why (a candidate not fitted keeps its own note)."""
    fitted = [cand for cand, ok in tried if ok]
    passing = [cand for cand in fitted if not criterion_failure(cand, settings)]
    best = min(fitted, key=lambda cand: fitted_figure(cand.score_change), default=None)
    chosen = min(passing, key=lambda cand: fitted_figure(cand.score_change), default=None)
    accepted = chosen.effect if chosen is not None else None
    reason = criterion_failure(best, settings) if best is not None else ""
    rows = []
    for cand, _ok in tried:
        if cand.effect == accepted:
            note = (
                "added: best held-out criterion"
                if best is not None and cand is best
                else "added: best held-out criterion of the candidates that pass every check"
            )
        elif cand.test_rmse is None:
            note = cand.note
        elif accepted is None and best is not None and cand is best:
            note = f"best of the round, not added: {reason}"
        elif criterion_failure(cand, settings):
            note = f"not added: {criterion_failure(cand, settings)}"
        else:
            note = "a better candidate in this round"
        rows.append(replace(cand, accepted=cand.effect == accepted, note=note))
    return accepted, rows


def earns_place(with_it: FitResult, without: FitResult, n_eff: float,
                min_improvement: float) -> str:
    """Why the effect that makes the fit ``without`` into ``with_it`` does not earn its place
    (empty: it does): it must lower ``H`` at ``n_eff`` (:func:`held_out_criterion`) and cut the
    held-out RMSE by ``min_improvement`` (a fraction)."""
    if held_out_criterion(with_it, n_eff) >= held_out_criterion(without, n_eff):
        return "does not lower the held-out criterion"
    gain = 1.0 - float(with_it.test_rmse or math.nan) / float(without.test_rmse or math.nan)
    if not gain >= min_improvement:
        return f"cuts the held-out RMSE by {gain:.1%}, less than {min_improvement:.0%}"
    return ""


def verdict_of(structure: Structure, added: Sequence[str], comparison: Comparison | None) -> str:
    """The loop's verdict (module docstring): :data:`NOT_EXPLAINED` while ``structure`` is
    left, else :data:`AMBIGUOUS` when effects were ``added`` and the ``comparison`` with the
    runner-up is ambiguous, :data:`EXPLAINED` when effects were added, :data:`NO_EFFECT`
    when none was."""
    if structure.any:
        return NOT_EXPLAINED
    if added and comparison is not None and comparison.ambiguous:
        return AMBIGUOUS
    return EXPLAINED if added else NO_EFFECT
