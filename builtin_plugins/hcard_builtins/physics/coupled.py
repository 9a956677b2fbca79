"""The coupled UV + EV model of thesis chapter 4: ``F_t = mu(w) (F_n + F_e)`` (Eq. 4.1).

Ultrasonic vibration lowers the friction coefficient, ``mu(w) = mu0 mu'(w)`` (chapter 2);
electrovibration adds the electrostatic attraction ``F_e`` to the normal force (chapter 3,
Eq. 3.13). Section 4.3 shows the two act independently (no mutual influence in the static
regime; the UV reduction does not depend on the normal load), so the lateral force is the
product of Eq. 4.1 and the relative friction is

    F_t / (mu0 F_n) = mu'(w) * (1 + F_e / F_n).

:class:`Coupled` composes a UV relative-friction predictor (default: the dimensionless group,
``"dimensionless-group"``, Eqs. 2.30-2.33) and an EV force predictor (default: Kaczmarek's law,
``"ev-kaczmarek"``, Eq. 3.12, whose defaults are the section 3.6 film of the chapter-4 stimulator:
A = 1 cm^2, d_sc = 200 um, eps_sc = 1560, d_i = 90 um, eps_i = 3.35), with the plate frequency
of that stimulator (38,220 Hz) as the default ``frequency``. Their parameters appear prefixed
``uv_`` and ``ev_``; :meth:`Coupled.compose` couples other models. The device limits of the
stimulator (2000 V, 440 Hz carrier, 250 uA) belong to its device profile
(:data:`hcard.physics.device_limits.COUPLED_STIMULATOR_LIMITS`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import Any, ClassVar

import numpy as np

from hcard.errors import HcardError
from hcard.physics import Parameter, Predictor, PredictorError, Variable
from hcard.physics.device_limits import COUPLED_STIMULATOR_LIMITS
from hcard_builtins.physics.electrovibration import Kaczmarek
from hcard_builtins.physics.ultrasonic import DimensionlessGroup

CHAPTER_4_PLATE_FREQUENCY = COUPLED_STIMULATOR_LIMITS.plate_frequency
"""Resonance of the aluminium plate of the chapter-4 coupled stimulator, Hz (section 4.2.1);
the default ``frequency`` input of :class:`Coupled`."""

UV_PREFIX = "uv_"
EV_PREFIX = "ev_"

_LEADING_INPUTS = (
    Variable("amplitude", "m", "plate vibration amplitude, peak-to-peak"),
    Variable("voltage", "V", "EV voltage acting on the finger (instantaneous, or carrier RMS)"),
    Variable("speed", "m/s", "finger sliding speed"),
    Variable("normal_force", "N", "normal force Fn applied by the finger (> 0)"),
    Variable("frequency", "Hz", "plate vibration frequency (chapter 4 plate: 38,220 Hz)"),
)
"""Inputs of the coupled model, in order; defaults come from the sub-models."""


def _prefixed(model: type[Predictor], prefix: str, label: str) -> tuple[Parameter, ...]:
    return tuple(
        dataclasses.replace(
            p,
            name=prefix + p.name,
            description=f"{label} ({model.name}): {p.description}".rstrip(": "),
        )
        for p in model.parameters
    )


SHARED_INPUTS = ("speed", "normal_force")
"""Inputs that mean the same for both sub-models (the finger's state). Any other EV input whose
name a UV input already uses (``frequency``: plate vs EV drive) is renamed ``ev_<name>``."""


def _ev_input_names(uv: type[Predictor], ev: type[Predictor]) -> dict[str, str]:
    """Coupled input name -> EV model input name."""
    uv_names = {v.name for v in uv.inputs}
    return {
        (EV_PREFIX + v.name if v.name in uv_names and v.name not in SHARED_INPUTS else v.name):
        v.name
        for v in ev.inputs
    }


def _union_inputs(uv: type[Predictor], ev: type[Predictor]) -> tuple[Variable, ...]:
    """Inputs of both sub-models plus ``normal_force``: those of :data:`_LEADING_INPUTS` first,
    with the coupled model's descriptions and the sub-models' defaults (UV first), then any
    others in sub-model order (EV inputs renamed as by :func:`_ev_input_names`)."""
    union: dict[str, Variable] = {v.name: v for v in uv.inputs}
    ev_variables = {v.name: v for v in ev.inputs}
    for name, ev_name in _ev_input_names(uv, ev).items():
        variable = ev_variables[ev_name]
        if name != ev_name:
            variable = dataclasses.replace(
                variable, name=name, description=f"EV ({ev.name}): {variable.description}"
            )
        union.setdefault(name, variable)
    leading = [
        dataclasses.replace(v, default=union[v.name].default if v.name in union else None)
        for v in _LEADING_INPUTS
        if v.name in union or v.name == "normal_force"  # Eq. 4.1 needs F_n
    ]
    others = [v for name, v in union.items() if name not in {w.name for w in _LEADING_INPUTS}]
    return (*leading, *others)


def _check_components(uv: type[Predictor], ev: type[Predictor]) -> None:
    if "amplitude" not in {v.name for v in uv.inputs} or uv.output.unit != "":
        raise PredictorError(
            f"coupled: the UV model must map amplitude to relative friction; {uv.name!r} maps "
            f"{', '.join(v.name for v in uv.inputs)} to {uv.output.name} [{uv.output.unit}]"
        )
    if "voltage" not in {v.name for v in ev.inputs} or ev.output.unit != "N":
        raise PredictorError(
            f"coupled: the EV model must map voltage to a force in N; {ev.name!r} maps "
            f"{', '.join(v.name for v in ev.inputs)} to {ev.output.name} [{ev.output.unit}]"
        )


def _compose_attributes(cls: type[Coupled]) -> None:
    """Set ``parameters``, ``inputs`` and ``inverse_input`` of ``cls`` from its sub-models."""
    _check_components(cls.uv_model, cls.ev_model)
    cls.parameters = (
        *_prefixed(cls.uv_model, UV_PREFIX, "UV"),
        *_prefixed(cls.ev_model, EV_PREFIX, "EV"),
    )
    cls.inputs = tuple(
        dataclasses.replace(v, default=cls.input_defaults[v.name])
        if v.name in cls.input_defaults
        else v
        for v in _union_inputs(cls.uv_model, cls.ev_model)
    )
    cls.inverse_input = "amplitude" if cls.uv_model.inverse_input == "amplitude" else None
    cls.ev_inputs = _ev_input_names(cls.uv_model, cls.ev_model)


class Coupled(Predictor):
    """Relative friction of a finger under UV and EV together, Eq. 4.1.

    ``F_t / (mu0 F_n) = mu'(w) (1 + F_e(v) / F_n)`` with ``mu'`` from the UV model (inputs
    amplitude, speed, normal_force, frequency) and ``F_e`` (N) from the EV model (input voltage).
    ``voltage`` is the voltage whose force acts: instantaneous, or the RMS value of a carrier for
    the carrier-averaged force (a force going as ``v^2`` averages to ``F(v_rms)``). The inverse
    gives the plate amplitude for a target total at a given voltage.

    Subclass with other ``uv_model`` / ``ev_model`` classes, or call :meth:`compose`.
    """

    name: ClassVar[str] = "coupled"
    calibrated: ClassVar[tuple[str, ...]] = ("uv_mu0", "uv_psi_star", "ev_area")
    description: ClassVar[str] = (
        "UV + EV coupled stimulator, F_t = mu(w)(Fn + Fe) (Eq. 4.1), as F_t / (mu0 Fn)"
    )
    output: ClassVar[Variable] = Variable(
        "relative_friction", "", "F_t / (mu0 Fn): UV factor mu'(w) times EV factor 1 + Fe/Fn"
    )
    uv_model: ClassVar[type[Predictor]] = DimensionlessGroup
    """UV relative-friction model (output mu/mu0, input amplitude)."""
    ev_model: ClassVar[type[Predictor]] = Kaczmarek
    """EV force model (output N, input voltage)."""
    input_defaults: ClassVar[dict[str, float]] = {"frequency": CHAPTER_4_PLATE_FREQUENCY}
    """Input defaults replacing the sub-models' (the chapter-4 plate frequency)."""
    ev_inputs: ClassVar[dict[str, str]] = {}
    """Coupled input name -> EV model input name (set from the sub-models)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        _compose_attributes(cls)

    def __init__(self, **params: float) -> None:
        super().__init__(**params)
        values = self.params
        self.uv: Predictor = self.uv_model(
            **{k[len(UV_PREFIX):]: v for k, v in values.items() if k.startswith(UV_PREFIX)}
        )
        """The UV sub-model with this instance's ``uv_`` parameters."""
        self.ev: Predictor = self.ev_model(
            **{k[len(EV_PREFIX):]: v for k, v in values.items() if k.startswith(EV_PREFIX)}
        )
        """The EV sub-model with this instance's ``ev_`` parameters."""

    @classmethod
    def compose(cls, uv: Predictor | None = None, ev: Predictor | None = None) -> Coupled:
        """A coupled model of the instances ``uv`` and ``ev`` (defaults: the default models),
        keeping their parameter values."""
        uv = uv if uv is not None else cls.uv_model()
        ev = ev if ev is not None else cls.ev_model()
        for part in (uv, ev):
            if type(part)(**part.params).to_profile() != part.to_profile():
                raise PredictorError(
                    f"coupled: {part.name!r} carries settings beyond its parameters (for "
                    "example a curve) that a coupled model cannot keep; use it on its own"
                )
        # (classes are hashable; mypy takes type[Predictor] for an unhashable instance type)
        model = coupled_class(type(uv), type(ev))  # type: ignore[arg-type]
        return model(
            **{UV_PREFIX + k: v for k, v in uv.params.items()},
            **{EV_PREFIX + k: v for k, v in ev.params.items()},
        )

    # -- the model -------------------------------------------------------------------------
    @staticmethod
    def _subset(model: Predictor, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        names = {v.name for v in model.inputs}
        return {k: v for k, v in inputs.items() if k in names}

    def _ev_arguments(self, inputs: Mapping[str, np.ndarray]) -> dict[str, np.ndarray]:
        return {ev_name: inputs[name] for name, ev_name in self.ev_inputs.items()}

    @staticmethod
    def _normal_force(inputs: Mapping[str, np.ndarray]) -> np.ndarray:
        fn = inputs["normal_force"]
        if not np.all(fn > 0) or not np.all(np.isfinite(fn)):
            raise PredictorError(
                "coupled: normal_force must be finite and > 0 N (F_t / (mu0 Fn) needs Fn > 0)"
            )
        return fn

    def factors(self, **inputs: Any) -> tuple[np.ndarray, np.ndarray]:
        """The two factors of Eq. 4.1: ``(mu'(w), 1 + F_e/F_n)`` (UV lowers, EV raises)."""
        arrays = self._inputs(inputs)
        fn = self._normal_force(arrays)
        mu = np.asarray(self.uv.forward(**self._subset(self.uv, arrays)), dtype=np.float64)
        fe = np.asarray(self.ev.forward(**self._ev_arguments(arrays)), dtype=np.float64)
        return mu, 1.0 + fe / fn

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        mu, ev = self.factors(**inputs)
        return mu * ev

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        fn = self._normal_force(inputs)
        fe = np.asarray(self.ev.forward(**self._ev_arguments(inputs)), dtype=np.float64)
        uv_target = target / (1.0 + fe / fn)
        if np.any(~np.isfinite(uv_target)) or np.any(uv_target < 0):
            raise PredictorError("coupled: the target relative friction must be finite and >= 0")
        if np.any(uv_target > 1.0 + 1e-12):
            worst = float(np.max(uv_target))
            raise PredictorError(
                f"coupled: the target needs mu'(w) = {worst:.4g} > 1 at this voltage; UV can "
                "only lower friction (lower the voltage or the target)"
            )
        rest = {k: v for k, v in self._subset(self.uv, inputs).items() if k != "amplitude"}
        return self.uv.inverse(np.minimum(uv_target, 1.0), **rest)

    # -- profiles --------------------------------------------------------------------------
    def to_profile(self) -> dict[str, Any]:
        """The predictor profile plus ``components``: the names of the UV and EV models."""
        profile = super().to_profile()
        profile["components"] = {"uv": self.uv_model.name, "ev": self.ev_model.name}
        return profile

    @classmethod
    def from_profile(cls, profile: Mapping[str, Any], *, source: str = "profile") -> Predictor:
        """An instance from a profile; ``components`` names the UV and EV models (looked up
        among the installed predictors), the default pair when absent."""
        components = profile.get("components", {})
        if not isinstance(components, Mapping):
            raise PredictorError(f"{source}: 'components' must be an object with 'uv' and 'ev'")
        uv_name = components.get("uv", cls.uv_model.name)
        ev_name = components.get("ev", cls.ev_model.name)
        model: type[Coupled] = cls
        if (uv_name, ev_name) != (cls.uv_model.name, cls.ev_model.name):
            from hcard.plugins.registry import get_registry

            registry = get_registry()
            try:
                uv_cls = type(registry.get("predictor", str(uv_name)))
                ev_cls = type(registry.get("predictor", str(ev_name)))
                model = coupled_class(uv_cls, ev_cls)  # type: ignore[arg-type]  # as above
            except HcardError as exc:  # no such plugin, or not a UV / EV pair
                raise PredictorError(f"{source}: components: {exc}") from None
        return super(Coupled, model).from_profile(profile, source=source)


_compose_attributes(Coupled)


@functools.cache
def coupled_class(uv: type[Predictor], ev: type[Predictor]) -> type[Coupled]:
    """The :class:`Coupled` subclass of ``uv`` and ``ev`` (one class per pair)."""
    if (uv, ev) == (Coupled.uv_model, Coupled.ev_model):
        return Coupled
    name = f"Coupled[{uv.name}, {ev.name}]"
    return type(name, (Coupled,), {"uv_model": uv, "ev_model": ev, "__module__": __name__})
