"""Calibration effects: physical effects a fitted model may lack (spec/calibration.md).

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
parameters are the base's plus each effect's (named ``"<effect>.<parameter>"``), so that
:func:`hcard.calibration.fit.fit_predictor` fits it unchanged.

Regressor names used in signatures (all 1-D arrays aligned with the samples, SI units):

- ``normal_force`` (N), ``speed`` (m/s), ``amplitude`` (m), ``voltage`` (V), ``pressure`` (Pa);
- ``time`` (s): time since the recording began (lifts included);
- ``stroke`` (count): the stroke number of each sample;
- ``contact`` (flag, an input rather than a regressor): 1 while the finger touches the
  surface, 0 out of contact (:func:`touchdowns`);
- ``voltage_history`` (s): time since the voltage last changed (:func:`time_since_change`);
- ``amplitude_history`` (m): change of the amplitude over the last few time constants
  (:func:`recent_change`), signed.
"""

from __future__ import annotations

import abc
import copy
import itertools
import math
from collections.abc import Mapping, Sequence
from typing import Any, ClassVar, TypeAlias

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable

KIND = "calibration-effect"
"""Plugin kind of calibration effects."""

SEPARATOR = "."
"""Between an effect's name and its parameter's name in an augmented predictor."""

ParameterValue: TypeAlias = float | np.ndarray
"""A base parameter's value as :meth:`Effect.transform_params` passes it: one number, or an
array aligned with the samples (a value per sample)."""

SAMPLEWISE_PARAMETERS: dict[str, frozenset[str]] = {
    "dimensionless-group": frozenset(
        {"mu0", "poisson_ratio", "psi_star", "psi_star_normal_force_slope"}
    ),
    "spring-slider": frozenset(
        {"normal_stiffness", "lateral_stiffness", "mu0", "lateral_recovery_speed"}
    ),
    "ev-air-layer": frozenset(
        {
            "area",
            "sc_thickness",
            "sc_permittivity",
            "insulator_thickness",
            "insulator_permittivity",
            "air_permittivity",
        }
    ),
    "finger-friction": frozenset(
        {
            "friction_initial",
            "friction_occluded",
            "occlusion_time",
            "load_index",
            "peak_speed",
            "speed_sensitivity",
        }
    ),
}
"""Built-in predictors (by name) whose forward map reads these parameters at call time and
broadcasts them with the inputs, so that a value per sample gives each sample's output exactly
(tests/calibration/test_effect_forms_params.py checks each against one evaluation per sample).
A vendor predictor declares the same with a class attribute ``samplewise_parameters``. Any other
parameter given per sample is evaluated once per distinct value (:func:`forward_per_sample`):
exact, and slower by the number of distinct values."""


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

    kind: ClassVar[str] = KIND
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

    Augmented.__name__ = Augmented.__qualname__ = f"Augmented_{type(base).__name__}"
    return Augmented()


# -- the base model with parameters per sample -----------------------------------------------
def samplewise_parameters(base: Predictor) -> frozenset[str]:
    """The parameters of ``base`` its forward map broadcasts per sample: the class attribute
    ``samplewise_parameters`` when it sets one, else :data:`SAMPLEWISE_PARAMETERS` by name."""
    declared = getattr(type(base), "samplewise_parameters", None)
    if declared is not None:
        return frozenset(declared)
    return SAMPLEWISE_PARAMETERS.get(base.name, frozenset())


def _checked_values(
    base: Predictor, changed: Mapping[str, ParameterValue]
) -> dict[str, np.ndarray]:
    """The changed parameters as float arrays, or :class:`PredictorError` naming the parameter
    when a value is not finite or below the parameter's lower bound (its physical domain, e.g.
    a positive ``mu0``; the upper bound only limits a fit's search, and a drift may pass it)."""
    lows = {p.name: p.bounds[0] for p in base.parameters}
    out = {}
    for name, value in changed.items():
        array = np.asarray(value, dtype=np.float64)
        bad = ~np.isfinite(array)
        if bad.any():
            raise PredictorError(
                f"{base.name}: parameter {name} per sample must be finite, got "
                f"{array[bad].flat[0]}"
            )
        if np.any(array < lows[name]):
            raise PredictorError(
                f"{base.name}: parameter {name} per sample must be >= {lows[name]:g}, got "
                f"{float(np.min(array)):g}"
            )
        out[name] = array
    return out


def forward_per_sample(
    base: Predictor, params: Mapping[str, ParameterValue], inputs: Mapping[str, Any]
) -> np.ndarray:
    """``base``'s output at parameter values that may differ from sample to sample.

    ``params`` maps base parameter names to one number or an array aligned with the samples
    (broadcast with the inputs); names not given keep ``base``'s values. Where every value is
    ``base``'s own, this is ``base.forward(**inputs)`` exactly; where every changed value is one
    number, the base at those values (bounds checked). Parameters the base broadcasts
    (:func:`samplewise_parameters`) are handed to its forward map as arrays; otherwise the base
    is evaluated once per distinct combination of the per-sample values (exact, slower).

    Per-sample values are checked for being finite and above the parameters' lower bounds, not
    against the upper bounds (a drifting ``mu0`` may leave the range a fit searches).

    Raises:
        PredictorError: an unknown parameter, a non-finite value or one below its lower bound,
            or values whose shape does not broadcast with the inputs.
    """
    known = {p.name for p in base.parameters}
    unknown = sorted(set(params) - known)
    if unknown:
        raise PredictorError(f"{base.name}: unknown parameter(s) {', '.join(unknown)}")
    changed = {
        name: value
        for name, value in params.items()
        if not (np.ndim(value) == 0 and float(value) == base[name])
    }
    if not changed:
        return base.forward(**inputs)
    if all(np.ndim(value) == 0 for value in changed.values()):
        return base.with_params(**{k: float(v) for k, v in changed.items()}).forward(**inputs)
    arrays = _checked_values(base, changed)
    if set(arrays) <= samplewise_parameters(base):
        view = copy.copy(base)
        # Samplewise parameters: arrays where the attribute is typed for floats.
        view._values = {**base.params, **arrays}  # type: ignore[dict-item]
        return view.forward(**inputs)
    return _forward_by_distinct_values(base, arrays, inputs)


def _forward_by_distinct_values(
    base: Predictor, arrays: Mapping[str, np.ndarray], inputs: Mapping[str, Any]
) -> np.ndarray:
    """:func:`forward_per_sample` for a base that does not broadcast its parameters: one
    evaluation per distinct combination of parameter values, on the samples that have it."""
    given = {k: np.asarray(v, dtype=np.float64) for k, v in inputs.items()}
    names = list(arrays)
    try:
        shaped = np.broadcast_arrays(*arrays.values(), *given.values())
    except ValueError:
        shapes = ", ".join(f"{k} {np.shape(v)}" for k, v in {**arrays, **given}.items())
        raise PredictorError(
            f"{base.name}: parameters per sample do not broadcast with the inputs: {shapes}"
        ) from None
    values = np.stack([a.ravel() for a in shaped[: len(names)]], axis=1)
    flat_inputs = {k: a.ravel() for k, a in zip(given, shaped[len(names) :], strict=True)}
    combos, which = np.unique(values, axis=0, return_inverse=True)
    which = which.ravel()
    out = np.empty(values.shape[0])
    for index, combo in enumerate(combos):
        rows = which == index
        model = base.with_params(**{n: float(v) for n, v in zip(names, combo, strict=True)})
        out[rows] = model.forward(**{k: v[rows] for k, v in flat_inputs.items()})
    return out.reshape(shaped[0].shape)


# -- helpers for effects and regressors -----------------------------------------------------
def _series(x: Any, t: Any) -> tuple[np.ndarray, np.ndarray] | None:
    """``(x, t)`` as 1-D arrays of one length, or None when ``t`` gives no time axis
    (a scalar or constant time: the steady state).

    Time must increase strictly, except that a decrease starts a new recording (several
    recordings concatenated, each with its own time origin)."""
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(t, float))
    if x_arr.ndim == 0 or t_arr.size < 2 or np.ptp(t_arr) == 0:
        return None
    if x_arr.ndim != 1:
        raise PredictorError(f"a time series must be 1-D, got shape {x_arr.shape}")
    if np.any(np.diff(t_arr) == 0):
        raise PredictorError("time must increase strictly from sample to sample (repeated time)")
    return x_arr, t_arr


def _segments(t: np.ndarray, restart: np.ndarray | None = None) -> list[slice]:
    """The runs of increasing time in ``t`` (one per concatenated recording), split again at
    every sample where ``restart`` (boolean, aligned with ``t``) is true."""
    cuts = np.diff(t) < 0
    if restart is not None:
        cuts = cuts | restart[1:]
    starts = [0, *(np.flatnonzero(cuts) + 1).tolist(), t.size]
    return [slice(a, b) for a, b in itertools.pairwise(starts)]


def _restart_mask(restart: Any, size: int) -> np.ndarray | None:
    """``restart`` as a boolean array of ``size`` samples (None: no restarts)."""
    if restart is None:
        return None
    mask = np.asarray(restart)
    if mask.ndim == 0:
        return None
    if mask.shape != (size,):
        raise PredictorError(
            f"restart must be one flag per sample ({size}), got shape {mask.shape}"
        )
    return mask.astype(bool)


def touchdowns(contact: Any, t: Any = None) -> np.ndarray | None:
    """Where the finger touches down: a boolean array, true at the first sample of every
    contact, from the ``contact`` input (1 while the finger touches the surface, 0 out of
    contact). A contact starts where ``contact`` turns on after a sample off, at the first
    sample if it is on, and where time ``t`` (s) decreases (a new recording). A new stroke
    without a lift between (a reversal, the finger still on the surface) is no touch-down.
    None when ``contact`` is one number (no contact column: one contact throughout)."""
    on = np.asarray(contact, dtype=np.float64)
    if on.ndim == 0:
        return None
    if on.ndim != 1:
        raise PredictorError(f"contact must be one flag per sample (1-D), got shape {on.shape}")
    if np.any(np.isnan(on)):
        raise PredictorError("contact must not be NaN (1 in contact, 0 out of contact)")
    touching = on > 0.5
    start = np.zeros(on.size, dtype=bool)
    if on.size:
        start[0] = touching[0]
        start[1:] = touching[1:] & ~touching[:-1]
    if t is not None and np.ndim(t) == 1 and np.size(t) == on.size:
        start[1:] |= touching[1:] & (np.diff(np.asarray(t, dtype=np.float64)) < 0)
    return start


def high_pass(
    x: Any, t: Any, tau: float, step_offset: float = 0.5, restart: Any = None
) -> np.ndarray:
    """First-order high-pass of ``x`` sampled at times ``t`` (s), time constant ``tau`` (s).

    ``e_k = a_k e_{k-1} + a_k^theta (x_k - x_{k-1})`` with ``a_k = exp(-(t_k - t_{k-1})/tau)``
    and ``theta = step_offset``: exact for an input that changes in steps a fraction ``theta``
    of the sample interval before the sample that first shows the new value. The default 1/2
    (midway) suits a measured input, of which a recording only says that it changed between
    two samples; 0 suits a command logged at the instant it changes (the response is then zero
    at that sample). The recording starts from rest, the drive switched on the same ``theta``
    of the first interval before the first sample (``e_0 = a_1^theta x_0``). The discrete form
    of ``tau s / (1 + tau s)`` (Eq. 3.22); as ``tau -> inf`` it passes ``x`` unchanged, and as
    ``tau -> 0`` it vanishes when ``theta > 0``; ``tau = inf`` passes ``x`` unchanged exactly.
    Without a time axis (scalar or constant ``t``) the input is returned unchanged. Where time
    decreases a new recording starts, from rest; so does every sample where ``restart`` (one
    boolean per sample, e.g. :func:`touchdowns`) is true: the filter restarts from rest there,
    the drive switched on ``theta`` of the interval before that sample.
    """
    if not (tau > 0) or math.isnan(tau):
        raise PredictorError(f"time constant must be positive, got {tau}")
    if not 0.0 <= step_offset <= 1.0:
        raise PredictorError(f"step offset must lie in [0, 1], got {step_offset}")
    series = _series(x, t)
    if series is None or math.isinf(tau):
        return np.array(np.asarray(x, dtype=np.float64))
    x_arr, t_arr = series
    parts = _segments(t_arr, _restart_mask(restart, t_arr.size))
    return np.concatenate(
        [_high_pass(x_arr[p], t_arr[p], tau, step_offset, _lead(t_arr, p)) for p in parts]
    )


def _lead(t_arr: np.ndarray, part: slice) -> float | None:
    """The interval before a segment's first sample (s) when the segment restarts within a
    run of increasing time, else None (a recording's first sample: no interval before it)."""
    a = part.start
    if a == 0 or t_arr[a] < t_arr[a - 1]:
        return None
    return float(t_arr[a] - t_arr[a - 1])


def _high_pass(
    x_arr: np.ndarray, t_arr: np.ndarray, tau: float, theta: float, lead: float | None = None
) -> np.ndarray:
    """:func:`high_pass` of one recording (time increasing strictly), step offset ``theta``;
    ``lead`` (s): the interval before the first sample, in which the drive switched on (None:
    the first interval of the recording stands in for it).

    Vectorised by runs of equal sample interval (one IIR filter per run, its state carried
    over), so that a recording with gaps (a training split without its held-out strokes)
    costs a filter call per gap, not a Python step per sample.
    """
    out = np.empty_like(x_arr)
    if x_arr.size == 0:
        return out
    dt = np.diff(t_arr)
    decay = np.exp(-dt / tau)
    # The drive is switched on theta of the interval before the first sample.
    if lead is not None:
        out[0] = x_arr[0] * math.exp(-lead / tau) ** theta
    else:
        out[0] = x_arr[0] * (decay[0] ** theta if dt.size else 1.0)
    if x_arr.size == 1:
        return out
    drive = np.power(decay, theta) * np.diff(x_arr)
    # Runs of (nearly) equal intervals: a new run where the interval changes.
    change = np.flatnonzero(np.abs(np.diff(dt)) > 1e-9 * dt[1:]) + 1
    starts = [0, *change.tolist()]
    ends = [*change.tolist(), dt.size]
    from scipy.signal import lfilter  # here: scipy.signal costs ~0.6 s to import, and listing
    # the effects (`hcard plugins`) must not pay it

    previous = out[0]
    for a, b in zip(starts, ends, strict=True):
        factor = decay[a]
        run, _ = lfilter([1.0], [1.0, -factor], drive[a:b], zi=[factor * previous])
        out[a + 1 : b + 1] = run
        previous = run[-1]
    return out


def low_pass(
    x: Any, t: Any, tau: float, step_offset: float = 0.5, restart: Any = None
) -> np.ndarray:
    """First-order low-pass of ``x`` at times ``t`` (s), time constant ``tau`` (s):
    ``x - high_pass(x, t, tau, step_offset, restart)``, starting from rest (``y_0 = 0``) at
    the first sample and at every sample where ``restart`` is true. With ``step_offset = 0``
    (steps at the sample instants) this is ``y_k = a_k y_{k-1} + (1 - a_k) x_{k-1}``.
    ``tau = 0`` passes ``x`` unchanged exactly, and so does a missing time axis (the steady
    state)."""
    if tau == 0:
        return np.array(np.asarray(x, dtype=np.float64))
    series = _series(x, t)
    if series is None:
        return np.asarray(x, dtype=np.float64)
    x_arr, t_arr = series
    return x_arr - high_pass(x_arr, t_arr, tau, step_offset, restart)


def time_since_change(x: Any, t: Any) -> np.ndarray:
    """Time (s) since ``x`` last changed value, per sample (since ``t_0`` before any change).

    The ``voltage_history`` regressor (of the voltage) in the module docstring.
    """
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, float), np.asarray(t, float))
    changed = np.ones(x_arr.size, dtype=bool)
    changed[1:] = x_arr[1:] != x_arr[:-1]
    last = np.maximum.accumulate(np.where(changed, np.arange(x_arr.size), 0))
    return t_arr - t_arr[last]


def recent_change(x: Any, t: Any, window: float) -> np.ndarray:
    """``x(t) - x(t - window)`` per sample (unit of ``x``), with ``x`` before ``t_0`` taken as
    zero; ``window`` in s. The ``amplitude_history`` regressor (of the amplitude)."""
    x_arr, t_arr = np.broadcast_arrays(np.asarray(x, float), np.asarray(t, float))
    index = np.searchsorted(t_arr, t_arr - window, side="right") - 1
    earlier = np.where(index >= 0, x_arr[np.maximum(index, 0)], 0.0)
    return x_arr - earlier
