"""Effects on a predictor: what an effect is, and a predictor with effects added.

An :class:`Effect` (plugin kind ``"calibration-effect"``, hook ``hcard_calibration_effects``) is a
physical effect that a base :class:`~hcard.physics.Predictor` may lack: charge leakage through the
stratum corneum, a load index, occlusion, the actuator's rise time, ... It names the regressors
against which its absence leaves structure in a residual (:attr:`Effect.signature`), carries its
own parameters (unit, default, bounds, thesis source), and changes a model by transforming the
model's inputs before the base forward map (:meth:`Effect.transform_inputs`, e.g. the voltage
becomes the effective voltage behind the skin's high-pass), the base model's parameters per
sample (:meth:`Effect.transform_params`, e.g. the dry friction coefficient ``mu0`` drifts with
occlusion and enters the ultrasonic group ``Psi = U / (w f mu0 (1 + nu))`` of Eq. 2.30) and/or its
output after it (:meth:`Effect.transform_output`, e.g. the force is multiplied by a load factor).

:func:`augment` builds from a base predictor and a list of effects a new predictor whose
parameters are the base's plus each effect's (named ``"<effect>.<parameter>"``): calibration
fits it unchanged (:func:`hcard.calibration.fit.fit_predictor`), and a device profile renders
with it (:func:`hcard.physics.profile_effects.with_effects`). Calibration builds on this module,
not the reverse.

Regressor names used in signatures (all 1-D arrays aligned with the samples, SI units; the
calibration's dataset computes them, :mod:`hcard.calibration.dataset`):

- ``normal_force`` (N), ``speed`` (m/s), ``amplitude`` (m), ``voltage`` (V), ``pressure`` (Pa);
- ``time`` (s): time since the recording began (lifts included);
- ``stroke`` (count): the stroke number of each sample;
- ``contact`` (flag, an input rather than a regressor): 1 while the finger touches the
  surface, 0 out of contact (:func:`hcard.calibration.time_series.touchdowns`);
- ``voltage_history`` (s): time since the voltage last changed
  (:func:`hcard.calibration.time_series.time_since_change`);
- ``amplitude_history`` (m): change of the amplitude over the last few time constants
  (:func:`hcard.calibration.time_series.recent_change`), signed.
"""

from __future__ import annotations

import abc
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar

import numpy as np

from hcard.physics.per_sample import ParameterValue, forward_per_sample, samplewise_parameters
from hcard.physics.predictor import Parameter, Predictor, PredictorError, Variable

SEPARATOR = "."
"""Between an effect's name and its parameter's name in an augmented predictor."""


class Effect:
    """Base class of calibration effects.

    Subclasses set the class attributes and override :meth:`transform_inputs`,
    :meth:`transform_params` and/or :meth:`transform_output`; each receives the effect's own
    parameter values by their short names (units of :attr:`parameters`). With an effect's
    parameters at their :attr:`neutral` values the augmented model equals the base exactly (the
    effect bypasses itself there; tests/calibration/test_effect_forms_neutral.py).

    Attributes:
        kind: ``"calibration-effect"``.
        name: unique identifier, e.g. ``"charge-leakage"``.
        description: one line: what the effect is and where the thesis describes it.
        reason: one line: why a model fitted without it leaves a residual.
        signature: regressor names (module docstring) against which its absence leaves
            residual structure, strongest first.
        parameters: the effect's parameters with units, defaults, bounds and sources.
        inputs: input variables the effect needs in addition to the base's (each with a
            default, so that the augmented model runs on the base's inputs alone).
        requires: names of base inputs the effect transforms or reads; :func:`augment` refuses
            a base without them.
        outputs: names of base outputs the effect applies to (e.g. ``("relative_friction",)``
            for an effect on the ultrasonic reduction); empty: any output.
        instantaneous: inputs it needs as instantaneous values rather than a carrier's
            envelope (e.g. ``("voltage",)`` for a high-pass of the voltage).
        neutral: parameter values (short names) that switch the effect off exactly (e.g. a
            time constant at the bound that stands for "no filter"); a fit started there
            starts from the base model.
    """

    kind: ClassVar[str] = "calibration-effect"  # its row of hcard.plugins.kinds.KIND_TABLE
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    reason: ClassVar[str] = ""
    signature: ClassVar[tuple[str, ...]] = ()
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    inputs: ClassVar[tuple[Variable, ...]] = ()
    requires: ClassVar[tuple[str, ...]] = ()
    outputs: ClassVar[tuple[str, ...]] = ()
    neutral: ClassVar[dict[str, float]] = {}
    instantaneous: ClassVar[tuple[str, ...]] = ()
    """Inputs the effect needs as instantaneous values, not as the envelope of a carrier (a
    time-domain filter of the voltage): a model whose voltage is an envelope refuses it."""

    def applies_to(self, base: Predictor) -> str | None:
        """Why the effect cannot augment ``base`` (a missing input, another output), or None."""
        if isinstance(base, EffectHost):
            return base.refuses(self)
        names = {v.name for v in base.inputs}
        missing = sorted(set(self.requires) - names)
        if missing:
            return f"needs input(s) {', '.join(missing)}, which model {base.name} does not have"
        if self.outputs and base.output.name not in self.outputs:
            return (
                f"applies to models whose output is {' or '.join(self.outputs)}; "
                f"{base.name} outputs {base.output.name}"
            )
        return None

    def transform_inputs(
        self, inputs: Mapping[str, np.ndarray], params: Mapping[str, float]
    ) -> dict[str, np.ndarray]:
        """The inputs the base model sees (default: unchanged). SI units in and out."""
        return dict(inputs)

    def transform_params(
        self,
        params: Mapping[str, ParameterValue],
        inputs: Mapping[str, np.ndarray],
        effect_params: Mapping[str, float],
        per_sample: frozenset[str] = frozenset(),
    ) -> dict[str, ParameterValue]:
        """The base model's parameter values the forward map uses (default: unchanged).

        ``params`` are the base's parameters by name (their units), each one number or an
        array aligned with the samples (an earlier effect's output); ``inputs`` are the
        (transformed) inputs; ``effect_params`` the effect's own values by short name;
        ``per_sample`` the base parameters its forward map broadcasts
        (:func:`samplewise_parameters`). A value returned as an array is the parameter's value
        per sample (e.g. ``mu0`` drifting over contact time); :func:`forward_per_sample`
        evaluates the base with it, fast for a name in ``per_sample`` and once per distinct
        value otherwise (an effect may prefer another form there).
        """
        return dict(params)

    def transform_output(
        self, output: np.ndarray, inputs: Mapping[str, np.ndarray], params: Mapping[str, float]
    ) -> np.ndarray:
        """The augmented output from the base output (default: unchanged), output unit."""
        return output

    def transform_output_of(
        self,
        quantity: str,
        output: np.ndarray,
        inputs: Mapping[str, np.ndarray],
        params: Mapping[str, float],
    ) -> np.ndarray:
        """:meth:`transform_output` for a base whose output is ``quantity`` (its
        :class:`~hcard.physics.Variable` name, e.g. ``"electrostatic_force"``): what the hosts
        call. An effect whose form depends on what the output is (a load index acts on the
        reaction force ``Fn + F_e``, which an electrostatic-force output is part of) overrides
        this; the default is :meth:`transform_output`. Hosts that know the reaction force
        pass it in ``inputs`` as ``reaction_force`` (N)."""
        return self.transform_output(output, inputs, params)

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


class EffectHost(Predictor, abc.ABC):
    """A predictor made of parts (the channels of a device profile) that places each effect on
    the part it acts on, instead of wrapping the whole (:func:`augment` defers to it).
    Abstract: a host says which effects it refuses and how it adds the others."""

    @abc.abstractmethod
    def refuses(self, effect: Effect) -> str | None:
        """Why ``effect`` cannot be added, or None."""

    @abc.abstractmethod
    def with_effects(self, effects: Sequence[Effect]) -> Predictor:
        """This model with ``effects`` added (parameters ``"<effect>.<parameter>"``)."""


def _check_effects(base: Predictor, effects: Sequence[Effect]) -> None:
    names = [effect.name for effect in effects]
    if any(not name for name in names):
        raise PredictorError("every effect needs a non-empty name")
    repeated = sorted({name for name in names if names.count(name) > 1})
    if repeated:
        raise PredictorError(f"effects repeat: {', '.join(repeated)}")
    base_inputs = {v.name for v in base.inputs}
    for effect in effects:
        why = effect.applies_to(base)
        if why:
            raise PredictorError(f"effect {effect.name} {why}")
        for var in effect.inputs:
            if var.name not in base_inputs and var.default is None:
                raise PredictorError(
                    f"effect {effect.name}: extra input {var.name} needs a default"
                )


def augment(base: Predictor, effects: Sequence[Effect]) -> Predictor:
    """A predictor: ``base`` with ``effects`` added, parameters and all, ready to fit.

    The new predictor is an instance of a dynamic subclass of :class:`Predictor`:

    - parameters: the base's (same names), then each effect's, named
      ``"<effect name>.<parameter name>"``, at the base's current values and the effects'
      defaults;
    - inputs: the base's, then each effect's extra inputs not already present (all optional);
    - forward: each effect's :meth:`Effect.transform_inputs` in order, then each effect's
      :meth:`Effect.transform_params` in order (starting from the base's values), the base
      forward map on the base's inputs at those parameter values (:func:`forward_per_sample`),
      then each effect's :meth:`Effect.transform_output_of` in order (given the base's output
      name and the transformed inputs);
    - output: the base's; name ``"<base>+<effect>+..."``.

    With no effects the forward map is the base's exactly, and so is the inverse; with effects
    the augmented model has no inverse.

    Raises:
        PredictorError: repeated or empty effect names, a base without an input an effect
            requires, or an extra input without a default.
    """
    effects = tuple(effects)
    _check_effects(base, effects)
    if isinstance(base, EffectHost):
        return base.with_effects(effects)
    base_names = tuple(p.name for p in base.parameters)
    effect_params = tuple(
        Parameter(
            name=f"{effect.name}{SEPARATOR}{p.name}",
            unit=p.unit,
            default=p.default,
            bounds=p.bounds,
            source=p.source,
            description=p.description,
        )
        for effect in effects
        for p in effect.parameters
    )
    extra: list[Variable] = []
    seen = {v.name for v in base.inputs}
    for effect in effects:
        for var in effect.inputs:
            if var.name not in seen:
                extra.append(var)
                seen.add(var.name)
    base_input_names = tuple(v.name for v in base.inputs)
    per_sample = samplewise_parameters(base)
    prototype = base
    quantity = base.output.name

    class Augmented(Predictor):
        kind: ClassVar[str] = prototype.kind
        name: ClassVar[str] = "+".join([prototype.name, *(e.name for e in effects)])
        description: ClassVar[str] = (
            f"{prototype.name} with {', '.join(e.name for e in effects) or 'no effects'}"
        )
        parameters: ClassVar[tuple[Parameter, ...]] = (*prototype.parameters, *effect_params)
        inputs: ClassVar[tuple[Variable, ...]] = (*prototype.inputs, *extra)
        output: ClassVar[Variable] = prototype.output
        inverse_input: ClassVar[str | None] = None if effects else prototype.inverse_input
        base_predictor: ClassVar[Predictor] = prototype
        effect_list: ClassVar[tuple[Effect, ...]] = tuple(effects)

        def __init__(self, **params: float) -> None:
            defaults = {name: prototype[name] for name in base_names}
            super().__init__(**{**defaults, **params})
            self._base = prototype.with_params(**{name: self._values[name] for name in base_names})
            self._effect_values = [
                {p.name: self._values[f"{e.name}{SEPARATOR}{p.name}"] for p in e.parameters}
                for e in effects
            ]

        @property
        def base(self) -> Predictor:
            """The base predictor at this instance's base parameter values."""
            return self._base

        def _forward(self, **inputs: np.ndarray) -> np.ndarray:
            arrays: dict[str, np.ndarray] = dict(inputs)
            for effect, values in zip(effects, self._effect_values, strict=True):
                arrays = effect.transform_inputs(arrays, values)
            base_values: dict[str, ParameterValue] = dict(self._base.params)
            for effect, own in zip(effects, self._effect_values, strict=True):
                base_values = effect.transform_params(base_values, arrays, own, per_sample)
            out = forward_per_sample(
                self._base, base_values, {k: arrays[k] for k in base_input_names}
            )
            for effect, values in zip(effects, self._effect_values, strict=True):
                out = effect.transform_output_of(quantity, out, arrays, values)
            return out

        def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
            return self._base.inverse(target, **inputs)

        def __reduce__(self) -> tuple[Any, ...]:
            # the class is made here, so pickle rebuilds it from what it was made of (a device
            # profile crosses to the served device's card-check worker and back)
            return _augmented_again, (prototype, effects, self.params)

    Augmented.__name__ = Augmented.__qualname__ = f"Augmented_{type(base).__name__}"
    return Augmented()


def _augmented_again(base: Predictor, effects: tuple[Effect, ...],
                     params: dict[str, float]) -> Predictor:
    """:func:`augment` of ``base`` and ``effects`` at ``params`` (SI units): how a pickled
    augmented predictor is made again."""
    return augment(base, effects).with_params(**params)
