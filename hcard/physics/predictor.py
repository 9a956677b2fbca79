"""The predictor plugin kind: named parameters, a vectorised forward map, an inverse.

A predictor maps actuation and finger state (keyword arrays in SI units, broadcast together)
to one output (for example relative friction mu/mu0, or a force in N). Its parameters carry a
unit, a default, bounds and the thesis source they come from, so that a fitted device profile
can be saved, reloaded and checked.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hcard.errors import HcardError


class PredictorError(HcardError):
    """Bad parameters or inputs for a predictor, or an inverse that does not exist."""


@dataclass(frozen=True)
class Parameter:
    """A model parameter.

    Attributes:
        name: identifier, e.g. ``"normal_stiffness"``.
        unit: SI unit, e.g. ``"N/m"`` (``""`` for a pure number).
        default: default value in ``unit``.
        bounds: inclusive (low, high) range in ``unit``; fits stay inside it.
        source: where the value comes from in the thesis, e.g. ``"Table 2.1"`` or ``"Eq. 2.33"``.
        description: one line.
    """

    name: str
    unit: str
    default: float
    bounds: tuple[float, float]
    source: str
    description: str = ""

    def check(self, value: float) -> float:
        """``value`` as a float, or :class:`PredictorError` if not finite or out of bounds."""
        value = float(value)
        low, high = self.bounds
        if not math.isfinite(value):
            raise PredictorError(f"parameter {self.name}: must be finite, got {value}")
        if not low <= value <= high:
            raise PredictorError(
                f"parameter {self.name} = {value:g} {self.unit} is outside its bounds "
                f"[{low:g}, {high:g}] {self.unit}"
            )
        return value


@dataclass(frozen=True)
class Variable:
    """An input or output of the forward map: name, SI unit, one-line description, default."""

    name: str
    unit: str
    description: str = ""
    default: float | None = None


_INPUT_TABLES: dict[int, tuple[Sequence[Variable], dict[str, Variable]]] = {}
"""``id(inputs)`` -> (inputs, their table) of the predictor classes met so far."""


def _input_table(inputs: Sequence[Variable]) -> dict[str, Variable]:
    """The inputs of a predictor class by name, built once per class (do not modify it)."""
    cached = _INPUT_TABLES.get(id(inputs))
    if cached is not None and cached[0] is inputs:
        return cached[1]
    if len(_INPUT_TABLES) >= 4096:  # classes made on the fly (calibration): start afresh
        _INPUT_TABLES.clear()
    table = {v.name: v for v in inputs}
    _INPUT_TABLES[id(inputs)] = (inputs, table)  # keeps ``inputs`` alive, so its id stays
    return table


class Predictor:
    """Base class of physics predictors.

    Subclasses set the class attributes and implement :meth:`_forward` (and :meth:`_inverse`
    where the map can be inverted). Instances are immutable: :meth:`with_params` returns a
    changed copy.
    """

    kind: ClassVar[str] = "predictor"
    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    parameters: ClassVar[tuple[Parameter, ...]] = ()
    inputs: ClassVar[tuple[Variable, ...]] = ()
    output: ClassVar[Variable] = Variable("relative_friction", "", "mu / mu0")
    inverse_input: ClassVar[str | None] = None
    """Name of the input that :meth:`inverse` solves for (None: no inverse)."""
    calibrated: ClassVar[tuple[str, ...]] = ()
    """Parameters a calibration fits by default (the ones a lab's data identify); empty: all."""

    def __init__(self, **params: float) -> None:
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(params) - set(known))
        if unknown:
            raise PredictorError(
                f"{self.name}: unknown parameter(s) {', '.join(unknown)}; "
                f"known: {', '.join(known) or 'none'}"
            )
        self._values = {
            name: p.check(params.get(name, p.default)) for name, p in known.items()
        }

    @property
    def params(self) -> dict[str, float]:
        """Current parameter values, SI units."""
        return dict(self._values)

    def __getitem__(self, name: str) -> float:
        return self._values[name]

    def with_params(self, **changes: float) -> Predictor:
        """A copy with some parameters changed."""
        return type(self)(**{**self._values, **changes})

    def _inputs(self, given: Mapping[str, Any]) -> dict[str, np.ndarray]:
        names = _input_table(self.inputs)
        if not given.keys() <= names.keys():
            unknown = sorted(set(given) - set(names))
            raise PredictorError(
                f"{self.name}: unknown input(s) {', '.join(unknown)}; inputs: {', '.join(names)}"
            )
        arrays = {}
        for name, var in names.items():
            if name in given:
                value = given[name]
            elif var.default is not None:
                value = var.default
            else:
                raise PredictorError(f"{self.name}: input {name} ({var.unit}) is required")
            arrays[name] = np.asarray(value, dtype=np.float64)
        return arrays

    def _trusted_inputs(self, given: dict[str, Any]) -> Mapping[str, Any]:
        """The inputs of a ``*_trusted`` call: ``given`` itself when it names every input (the
        caller's float64 arrays or floats), else :meth:`_inputs` (defaults filled in)."""
        if given.keys() == _input_table(self.inputs).keys():
            return given
        return self._inputs(given)

    def forward(self, **inputs: Any) -> np.ndarray:
        """The output for inputs broadcast together (SI units); vectorised."""
        return self._forward(**self._inputs(inputs))

    def inverse(self, target: Any, **inputs: Any) -> np.ndarray:
        """The value of :attr:`inverse_input` that makes the output equal ``target``."""
        if self.inverse_input is None:
            raise PredictorError(f"{self.name}: this model has no inverse")
        given = dict(inputs)
        given.setdefault(self.inverse_input, 0.0)
        arrays = self._inputs(given)
        del arrays[self.inverse_input]
        return self._inverse(np.asarray(target, dtype=np.float64), **arrays)

    def forward_trusted(self, **inputs: Any) -> np.ndarray:
        """:meth:`forward` for inputs its caller has already checked: float64 arrays (or
        floats) that broadcast together, finite, and inside the model's domain (every value
        :meth:`forward` accepts). A model whose input checks cost more than its arithmetic
        (on the few frames of a real-time block) skips them here; checks that depend on its
        parameters stay. The result is :meth:`forward`'s, bit for bit. By default this is
        :meth:`forward`, checks included."""
        return self.forward(**inputs)

    def inverse_trusted(self, target: Any, **inputs: Any) -> np.ndarray:
        """:meth:`inverse` for a target and inputs its caller has already checked (as for
        :meth:`forward_trusted`; the target inside the range the inverse accepts). By
        default this is :meth:`inverse`, checks included."""
        return self.inverse(target, **inputs)

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        raise PredictorError(f"{self.name}: no forward map")

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        raise PredictorError(f"{self.name}: this model has no inverse")

    # -- profiles --------------------------------------------------------------------------
    def to_profile(self) -> dict[str, Any]:
        """A JSON-ready description: model name and parameters with units (the ``predictor``
        object of a device profile, spec/device-profile.md)."""
        return {
            "model": self.name,
            "parameters": {
                p.name: {"value": self._values[p.name], "unit": p.unit} for p in self.parameters
            },
        }

    @classmethod
    def from_profile(cls, profile: Mapping[str, Any], *, source: str = "profile") -> Predictor:
        """An instance with the parameters of ``profile`` (see :meth:`to_profile`)."""
        if profile.get("model") != cls.name:
            raise PredictorError(
                f"{source}: profile is for model {profile.get('model')!r}, not {cls.name!r}"
            )
        raw = profile.get("parameters", {})
        if not isinstance(raw, Mapping):
            raise PredictorError(f"{source}: 'parameters' must be an object")
        units = {p.name: p.unit for p in cls.parameters}
        values = {}
        for name, entry in raw.items():
            if isinstance(entry, Mapping):
                if name in units and entry.get("unit", units[name]) != units[name]:
                    raise PredictorError(
                        f"{source}: parameter {name} is in {entry.get('unit')!r}, "
                        f"expected {units[name]!r}"
                    )
                entry = entry.get("value")
            if not isinstance(entry, int | float):
                raise PredictorError(f"{source}: parameter {name} must be a number")
            values[name] = float(entry)
        try:
            return cls(**values)
        except PredictorError as exc:
            raise PredictorError(f"{source}: {exc}") from None

