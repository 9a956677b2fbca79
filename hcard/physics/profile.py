"""Device profiles: a fitted predictor plus the limits of one device (DESIGN.md sections 2, 5).

A device profile is to friction what an ICC profile is to colour: it maps the device-independent
target of a card (relative friction per channel, ``Frames.uv`` in [0, 1] and ``Frames.ev`` in
[1, 4]) to the actuator commands of one device, and the commands back to the friction they
render. It bundles

- a predictor with its parameters: the coupled model of Eq. 4.1 (``"coupled"``: UV and EV),
  a UV relative-friction model whose inverse gives the plate amplitude (``inverse_input ==
  "amplitude"``, for example ``"dimensionless-group"``), or an EV force model whose inverse
  gives the voltage (output in N, ``inverse_input == "voltage"``, e.g. ``"ev-kaczmarek"``);
- optionally a charge-leakage model (Eqs. 3.19-3.23) whose gain at the EV carrier frequency
  scales the voltage that acts on the finger;
- the device limits (:class:`DeviceLimits`).

Profiles are JSON files (format ``hcard-device-profile/1``), written atomically; every loading
error names the file and the field. :mod:`hcard.physics.actuation` does the rendering.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from hcard.atomic import write_atomically
from hcard.errors import HcardError
from hcard.physics.predictor import Predictor, PredictorError
from hcard.physics.units import UnitError, parse_quantity, parse_unit

if TYPE_CHECKING:
    from hcard.physics.actuation import ActuatorCommands
    from hcard.plugins.registry import PluginRegistry

PROFILE_FORMAT = "hcard-device-profile/1"
"""Value of the ``format`` field of a device profile file."""

PREDICTOR_PROFILE_FORMAT = "hcard-predictor-profile/1"
"""Format of a bare predictor profile (:meth:`Predictor.to_profile`)."""

EPSILON_0 = 8.8541878128e-12
"""Vacuum permittivity, F/m."""

_LAYER_PARAMETERS = (
    "area", "sc_thickness", "sc_permittivity", "insulator_thickness", "insulator_permittivity"
)
"""Parameters of a layered EV model from which Eq. 3.8 gives the finger capacitance."""

QUADRATIC_TOLERANCE = 1e-6
"""Relative tolerance of the check that an EV force model goes as ``v^2``."""


class ProfileError(PredictorError):
    """A device profile is invalid, or its file cannot be read; the message names file and field."""


@dataclass(frozen=True)
class DeviceLimits:
    """What a device can do, in SI units; commands are clipped to these.

    Attributes:
        max_amplitude: largest peak-to-peak plate vibration amplitude, m (0: no UV channel).
        max_voltage: largest peak EV voltage of the amplifier, V (0: no EV channel).
        max_current: largest peak current the EV amplifier may drive through the user, A
            (250 uA on the coupled stimulator of chapter 4, section 3.6.3).
        carrier_frequency: frequency of the sinusoidal EV carrier, Hz (440 Hz in chapter 4).
        plate_frequency: resonance frequency of the vibrating plate, Hz (38,220 Hz, chapter 4).
        load_capacitance: capacitance the EV amplifier drives through the finger, F; ``None``
            derives it from the EV model's layers, ``C = eps0 A / (d_sc/eps_sc + d_i/eps_i)``
            (Eq. 3.8; 33 pF for the section 3.6 values). A profile whose EV model has no such
            layers must give it.
    """

    max_amplitude: float
    max_voltage: float
    max_current: float
    carrier_frequency: float
    plate_frequency: float
    load_capacitance: float | None = None

    UNITS: ClassVar[dict[str, str]] = {
        "max_amplitude": "m",
        "max_voltage": "V",
        "max_current": "A",
        "carrier_frequency": "Hz",
        "plate_frequency": "Hz",
        "load_capacitance": "F",
    }
    """SI unit of each field."""

    def __post_init__(self) -> None:
        for name in self.UNITS:
            value = getattr(self, name)
            if value is None and name == "load_capacitance":
                continue
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise ProfileError(f"limits.{name}: must be a number, got {value!r}")
            value = float(value)
            object.__setattr__(self, name, value)
            strictly = name not in ("max_amplitude", "max_voltage")
            if not math.isfinite(value) or value < 0 or (strictly and value == 0):
                relation = "> 0" if strictly else ">= 0"
                raise ProfileError(
                    f"limits.{name}: must be a finite number {relation} {self.UNITS[name]}, "
                    f"got {value:g}"
                )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{field: {"value": v, "unit": u}}`` (``None`` stays ``None``)."""
        out: dict[str, Any] = {}
        for name, unit in self.UNITS.items():
            value = getattr(self, name)
            out[name] = None if value is None else {"value": value, "unit": unit}
        return out

    @classmethod
    def from_dict(cls, raw: Any, *, source: str) -> DeviceLimits:
        """Limits from a profile's ``limits`` object.

        Each field is a number in SI units, a ``{"value": v, "unit": u}`` object whose unit
        has the right dimension (``"um"`` for ``max_amplitude``), or a string such as
        ``"2.5 um"``. Errors name ``source`` and the field.
        """
        if not isinstance(raw, Mapping):
            raise ProfileError(f"{source}: 'limits' must be an object")
        unknown = sorted(set(raw) - set(cls.UNITS))
        if unknown:
            raise ProfileError(
                f"{source}: limits.{unknown[0]}: unknown field; fields: {', '.join(cls.UNITS)}"
            )
        values: dict[str, float | None] = {}
        for name, unit in cls.UNITS.items():
            where = f"{source}: limits.{name}"
            if name not in raw:
                if name == "load_capacitance":
                    continue
                raise ProfileError(f"{where}: missing ({unit})")
            values[name] = _si_value(raw[name], unit, where, optional=name == "load_capacitance")
        try:
            return cls(**values)  # type: ignore[arg-type]
        except ProfileError as exc:
            raise ProfileError(f"{source}: {exc}") from None


COUPLED_STIMULATOR_LIMITS = DeviceLimits(
    max_amplitude=2.5e-6,
    max_voltage=2000.0,
    max_current=250e-6,
    carrier_frequency=440.0,
    plate_frequency=38_220.0,
)
"""The coupled UV+EV stimulator of chapter 4 (section 4.2.1): aluminium plate at 38,220 Hz,
EV amplifier to 2000 V modulated at 440 Hz, current limited to 250 uA (section 3.6.3); plate
amplitudes up to 2.5 um peak-to-peak, the range "generally implemented in ultrasonic displays"
(section 2.4)."""


def _si_value(raw: Any, unit: str, where: str, *, optional: bool = False) -> float | None:
    """An SI float from a profile field (number, ``{"value", "unit"}`` or ``"2.5 um"``)."""
    if raw is None and optional:
        return None
    if isinstance(raw, str):
        try:
            return parse_quantity(raw, unit)
        except UnitError as exc:
            raise ProfileError(f"{where}: {exc}") from None
    scale = 1.0
    if isinstance(raw, Mapping):
        given_unit = raw.get("unit", unit)
        if not isinstance(given_unit, str):
            raise ProfileError(f"{where}: 'unit' must be a string")
        try:
            scale, dimension = parse_unit(given_unit)
            expected = parse_unit(unit)[1]
        except UnitError as exc:
            raise ProfileError(f"{where}: {exc}") from None
        if dimension != expected:
            raise ProfileError(f"{where}: unit {given_unit!r} is not a unit of {unit}")
        raw = raw.get("value")
    if isinstance(raw, bool) or not isinstance(raw, int | float):
        raise ProfileError(f"{where}: must be a number ({unit}), got {raw!r}")
    return float(raw) * scale


def _registry(registry: PluginRegistry | None) -> PluginRegistry:
    if registry is not None:
        return registry
    from hcard.plugins.registry import get_registry

    return get_registry()


def predictor_from_profile(
    raw: Any, *, source: str, registry: PluginRegistry | None = None
) -> Predictor:
    """A predictor from a predictor profile object (:meth:`Predictor.to_profile`).

    The model is looked up by name among the installed predictor plugins; its class reads the
    parameters (so a model with its own profile layout, such as ``coupled``, reads its own).
    """
    if not isinstance(raw, Mapping):
        raise ProfileError(f"{source}: must be an object with 'model' and 'parameters'")
    model = raw.get("model")
    if not isinstance(model, str) or not model:
        raise ProfileError(f"{source}.model: missing or not a string")
    try:
        prototype = _registry(registry).get("predictor", model)
    except HcardError as exc:
        raise ProfileError(f"{source}.model: {exc}") from None
    try:
        return type(prototype).from_profile(raw, source=source)
    except ProfileError:
        raise
    except PredictorError as exc:
        raise ProfileError(str(exc)) from None


@dataclass(frozen=True)
class DeviceProfile:
    """A predictor with fitted parameters and the limits of one device.

    Attributes:
        predictor: ``coupled`` (UV and EV), a UV relative-friction model with an amplitude
            inverse, or an EV force model (N) with a voltage inverse.
        limits: the device limits.
        leakage: optional charge-leakage model (Eqs. 3.19-3.23) with a
            ``frequency_response(f)`` method; its gain at the carrier frequency scales the EV
            voltage that acts on the finger.
        name: a short identifier of the device.
        description: one line.
    """

    predictor: Predictor
    limits: DeviceLimits
    leakage: Predictor | None = None
    name: str = "device"
    description: str = ""
    _uv: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _ev: Predictor | None = field(default=None, init=False, repr=False, compare=False)
    _carrier_gain: float = field(default=1.0, init=False, repr=False, compare=False)
    _capacitance: float | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.predictor, Predictor):
            raise ProfileError(f"predictor: expected a Predictor, got {type(self.predictor)}")
        if not isinstance(self.limits, DeviceLimits):
            raise ProfileError(f"limits: expected DeviceLimits, got {type(self.limits)}")
        uv, ev = _channels(self.predictor)
        if uv is None and ev is None:
            raise ProfileError(
                f"predictor: model {self.predictor.name!r} can render neither channel; a profile "
                "needs a UV relative-friction model with an amplitude inverse, an EV force "
                "model (N) with a voltage inverse, or 'coupled'"
            )
        if ev is not None:
            frequency = self.limits.carrier_frequency
            _check_quadratic(ev, frequency)
            if self.leakage is not None and "frequency" in {v.name for v in ev.inputs}:
                raise ProfileError(
                    f"leakage: the EV model {ev.name!r} already depends on the carrier "
                    "frequency; a separate leakage model would count the leak twice"
                )
        if self.leakage is not None and not callable(
            getattr(self.leakage, "frequency_response", None)
        ):
            raise ProfileError(
                f"leakage: model {self.leakage.name!r} has no frequency_response(f) method"
            )
        capacitance = self._derive_capacitance(ev)
        if ev is not None and capacitance is None:
            raise ProfileError(
                f"limits.load_capacitance: missing, and the EV model {ev.name!r} has no "
                "area and layers to derive it from (Eq. 3.8); give it in F so that "
                "max_current can be enforced"
            )
        # Frozen dataclass: the derived values are set once, here.
        object.__setattr__(self, "_uv", uv)
        object.__setattr__(self, "_ev", ev)
        object.__setattr__(self, "_carrier_gain", self._leakage_gain())
        object.__setattr__(self, "_capacitance", capacitance)

    # -- channels --------------------------------------------------------------------------
    @property
    def uv_model(self) -> Predictor | None:
        """The relative-friction model of the UV channel (``None``: no UV channel)."""
        return self._uv

    @property
    def ev_model(self) -> Predictor | None:
        """The electrostatic-force model of the EV channel, N (``None``: no EV channel)."""
        return self._ev

    @property
    def carrier_gain(self) -> float:
        """Voltage gain ``|v_e / v|`` at the carrier frequency (Eq. 3.22); 1 without leakage."""
        return self._carrier_gain

    @property
    def load_capacitance(self) -> float | None:
        """Capacitance the EV amplifier drives, F (given in the limits, or from Eq. 3.8)."""
        return self._capacitance

    @property
    def voltage_limit(self) -> tuple[float, str]:
        """The binding peak-voltage limit, V, and its name (``max_voltage`` or ``max_current``).

        ``max_current`` binds when a sinusoidal carrier of peak ``V`` at ``carrier_frequency``
        into :attr:`load_capacitance` would draw more than ``max_current`` (``I = 2 pi f C V``,
        the envelope taken as slow against the carrier).
        """
        capacitance = self.load_capacitance
        if capacitance is None:  # no EV channel: nothing draws current
            return self.limits.max_voltage, "max_voltage"
        by_current = self.limits.max_current / (
            2.0 * math.pi * self.limits.carrier_frequency * capacitance
        )
        if by_current < self.limits.max_voltage:
            return by_current, "max_current"
        return self.limits.max_voltage, "max_voltage"

    def _leakage_gain(self) -> float:
        if self.leakage is None:
            return 1.0
        frequency = self.limits.carrier_frequency
        try:
            response = np.asarray(self.leakage.frequency_response(np.asarray([frequency])))
        except HcardError as exc:
            raise ProfileError(f"leakage: {exc}") from None
        gain = float(np.abs(response).ravel()[0])
        if not math.isfinite(gain) or gain <= 0:
            raise ProfileError(
                f"leakage: gain at the carrier frequency {frequency:g} Hz is {gain:g}; "
                "the EV channel cannot act"
            )
        return gain

    def _derive_capacitance(self, ev: Predictor | None) -> float | None:
        """The limits' load capacitance, else Eq. 3.8 from the EV model's layer parameters
        (``area``, ``sc_thickness``, ``sc_permittivity``, ``insulator_thickness``,
        ``insulator_permittivity``), else None (the current limit cannot be checked)."""
        if self.limits.load_capacitance is not None:
            return self.limits.load_capacitance
        if ev is None or not set(_LAYER_PARAMETERS) <= set(ev.params):
            return None
        p = ev.params
        electrical_thickness = (
            p["sc_thickness"] / p["sc_permittivity"]
            + p["insulator_thickness"] / p["insulator_permittivity"]
        )
        return EPSILON_0 * p["area"] / electrical_thickness

    # -- forward and rendering -------------------------------------------------------------
    def forward(
        self,
        amplitude: Any,
        voltage: Any,
        speed: Any,
        normal_force: Any,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Relative friction per channel rendered by actuator commands (Eq. 4.1 factors).

        Args:
            amplitude: peak-to-peak plate amplitude, m.
            voltage: peak EV voltage envelope of the sinusoidal carrier, V.
            speed: finger speed, m/s.
            normal_force: finger normal force, N (> 0 where EV acts).

        Returns:
            ``(uv, ev)``: ``uv = mu(w)/mu0`` from the UV model at the plate frequency, and
            ``ev = 1 + <F_e>/F_n`` with ``<F_e>`` the carrier average of the EV force, which for
            a force going as ``v^2`` is ``F_e(g V / sqrt 2)`` (mean of ``sin^2`` = 1/2, ``g``
            the leakage gain at the carrier). ``ev = 1`` where ``F_n = 0``. Their product is
            the total relative friction ``F_t / (mu0 F_n)``.
        """
        amplitude, voltage, speed, normal_force = np.broadcast_arrays(
            *(np.asarray(a, dtype=np.float64) for a in (amplitude, voltage, speed, normal_force))
        )
        uv = np.ones(amplitude.shape)
        if self.uv_model is not None:
            uv = np.broadcast_to(self.uv_for(amplitude, speed, normal_force), uv.shape)
        ev = np.ones(amplitude.shape)
        if self.ev_model is not None:
            force = self.force_for(voltage)
            with np.errstate(divide="ignore", invalid="ignore"):
                ev = np.where(normal_force > 0, 1.0 + force / normal_force, 1.0)
        return np.array(uv, dtype=np.float64), np.array(ev, dtype=np.float64)

    def _uv_inputs(self, speed: np.ndarray, normal_force: np.ndarray) -> dict[str, Any]:
        """Inputs of the UV model: finger state and the plate frequency (those it takes)."""
        names = {v.name for v in self._channel("uv").inputs}
        given: dict[str, Any] = {
            "speed": speed,
            "normal_force": normal_force,
            "frequency": self.limits.plate_frequency,
        }
        return {k: v for k, v in given.items() if k in names}

    def _channel(self, channel: str) -> Predictor:
        model = self._uv if channel == "uv" else self._ev
        if model is None:
            raise ProfileError(f"profile {self.name!r} has no {channel.upper()} channel")
        return model

    def uv_for(self, amplitude: Any, speed: Any, normal_force: Any) -> np.ndarray:
        """UV relative friction ``mu(w)/mu0`` for peak-to-peak amplitude ``w`` (m) at the
        plate frequency, finger speed (m/s) and normal force (N)."""
        model = self._channel("uv")
        return model.forward(amplitude=amplitude, **self._uv_inputs(speed, normal_force))

    def amplitude_for(self, uv: Any, speed: Any, normal_force: Any) -> np.ndarray:
        """Peak-to-peak plate amplitude (m) giving UV relative friction ``uv`` at the finger
        speed (m/s) and normal force (N): the UV model's inverse, not clipped."""
        model = self._channel("uv")
        return model.inverse(uv, **self._uv_inputs(speed, normal_force))

    def _ev_inputs(self) -> dict[str, Any]:
        """Extra inputs of the EV model: the carrier frequency when it takes ``frequency``."""
        names = {v.name for v in self._channel("ev").inputs}
        return {"frequency": self.limits.carrier_frequency} if "frequency" in names else {}

    def force_for(self, voltage: Any) -> np.ndarray:
        """Carrier-averaged EV force, N, for a peak envelope ``voltage`` (V).

        ``<F(g V sin)> = F(g V / sqrt 2)`` for a force going as ``v^2`` (mean of ``sin^2`` is
        1/2; ``g`` the leakage gain at the carrier, Eq. 3.22).
        """
        model = self._channel("ev")
        effective = self.carrier_gain * np.asarray(voltage, dtype=np.float64) / math.sqrt(2.0)
        return np.asarray(model.forward(voltage=effective, **self._ev_inputs()), dtype=np.float64)

    def voltage_for(self, force: Any) -> np.ndarray:
        """Peak envelope voltage, V, whose carrier-averaged EV force is ``force`` (N): the
        inverse of :meth:`force_for`, not clipped."""
        model = self._channel("ev")
        effective = np.asarray(model.inverse(force, **self._ev_inputs()), dtype=np.float64)
        return effective * math.sqrt(2.0) / self.carrier_gain

    def actuate(
        self, uv: Any, ev: Any, speed: Any, normal_force: Any, **options: Any
    ) -> ActuatorCommands:
        """Actuator commands for target relative friction; see
        :func:`hcard.physics.actuation.actuate` (which takes the same arguments)."""
        from hcard.physics.actuation import actuate

        return actuate(self, uv, ev, speed, normal_force, **options)

    # -- files -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The JSON-ready profile (format :data:`PROFILE_FORMAT`)."""
        return {
            "format": PROFILE_FORMAT,
            "name": self.name,
            "description": self.description,
            "predictor": self.predictor.to_profile(),
            "leakage": None if self.leakage is None else self.leakage.to_profile(),
            "limits": self.limits.to_dict(),
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write the profile as JSON, atomically (readers see the old file or the new one)."""
        text = json.dumps(self.to_dict(), indent=2) + "\n"
        try:
            write_atomically(path, text.encode())
        except OSError as exc:
            raise ProfileError(f"{path}: cannot write ({exc.strerror or exc})") from None

    @classmethod
    def from_dict(
        cls,
        raw: Any,
        *,
        source: str = "profile",
        registry: PluginRegistry | None = None,
    ) -> DeviceProfile:
        """A profile from its JSON object; errors name ``source`` and the field."""
        if not isinstance(raw, Mapping):
            raise ProfileError(f"{source}: a device profile must be a JSON object")
        if raw.get("format") != PROFILE_FORMAT:
            raise ProfileError(
                f"{source}: format: expected {PROFILE_FORMAT!r}, got {raw.get('format')!r}"
            )
        known = {"format", "name", "description", "predictor", "leakage", "limits"}
        unknown = sorted(set(raw) - known)
        if unknown:
            raise ProfileError(f"{source}: {unknown[0]}: unknown field")
        for text_field in ("name", "description"):
            if not isinstance(raw.get(text_field, ""), str):
                raise ProfileError(f"{source}: {text_field}: must be a string")
        if "predictor" not in raw:
            raise ProfileError(f"{source}: predictor: missing")
        if "limits" not in raw:
            raise ProfileError(f"{source}: limits: missing")
        predictor = predictor_from_profile(
            raw["predictor"], source=f"{source}: predictor", registry=registry
        )
        leakage = None
        if raw.get("leakage") is not None:
            leakage = predictor_from_profile(
                raw["leakage"], source=f"{source}: leakage", registry=registry
            )
        limits = DeviceLimits.from_dict(raw["limits"], source=source)
        try:
            return cls(
                predictor=predictor,
                limits=limits,
                leakage=leakage,
                name=raw.get("name", "device"),
                description=raw.get("description", ""),
            )
        except ProfileError as exc:
            raise ProfileError(f"{source}: {exc}") from None

    @classmethod
    def load(
        cls, path: str | os.PathLike[str], *, registry: PluginRegistry | None = None
    ) -> DeviceProfile:
        """Read a profile file written by :meth:`save` (or by hand)."""
        file = Path(path)
        return cls.from_dict(read_json(file), source=str(file), registry=registry)

    @classmethod
    def coupled_stimulator(
        cls,
        *,
        leakage: Predictor | None = None,
        registry: PluginRegistry | None = None,
        **changes: float,
    ) -> DeviceProfile:
        """The chapter-4 coupled stimulator (:data:`COUPLED_STIMULATOR_LIMITS`) with the
        default ``coupled`` predictor; ``changes`` replace limits (for example
        ``max_amplitude=5e-6``)."""
        try:
            predictor = _registry(registry).get("predictor", "coupled")
        except HcardError as exc:
            raise ProfileError(f"coupled stimulator: {exc}") from None
        values = {f.name: getattr(COUPLED_STIMULATOR_LIMITS, f.name) for f in fields(DeviceLimits)}
        unknown = sorted(set(changes) - set(values))
        if unknown:
            raise ProfileError(f"limits.{unknown[0]}: unknown field")
        return cls(
            predictor=predictor,
            limits=DeviceLimits(**{**values, **changes}),
            leakage=leakage,
            name="coupled-stimulator",
            description="UV+EV coupled stimulator of thesis chapter 4",
        )


def read_json(file: Path) -> Any:
    """The JSON content of ``file``; :class:`ProfileError` naming the file otherwise."""
    try:
        return json.loads(file.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ProfileError(f"{file}: no such file") from None
    except IsADirectoryError:
        raise ProfileError(f"{file}: is a directory, not a profile") from None
    except UnicodeDecodeError:
        raise ProfileError(f"{file}: not a text (UTF-8) file") from None
    except json.JSONDecodeError as exc:
        raise ProfileError(f"{file}: not valid JSON ({exc.msg}, line {exc.lineno})") from None
    except OSError as exc:
        raise ProfileError(f"{file}: cannot read ({exc.strerror or exc})") from None


def _channels(predictor: Predictor) -> tuple[Predictor | None, Predictor | None]:
    """(UV relative-friction model, EV force model) rendered by ``predictor``."""
    uv = getattr(predictor, "uv", None)
    ev = getattr(predictor, "ev", None)
    if isinstance(uv, Predictor) and isinstance(ev, Predictor):
        return (
            uv if uv.inverse_input == "amplitude" else None,
            ev if ev.inverse_input == "voltage" else None,
        )
    if predictor.inverse_input == "amplitude" and predictor.output.unit == "":
        return predictor, None
    if predictor.inverse_input == "voltage" and predictor.output.unit == "N":
        return None, predictor
    return None, None


def _check_quadratic(ev: Predictor, carrier_frequency: float) -> None:
    """:class:`ProfileError` unless ``F(2 v) = 4 F(v)``: the carrier average (mean of sin^2 =
    1/2) and its inverse assume the ``v^2`` law of Eqs. 3.3, 3.12, 3.17, 3.18 and 3.23."""
    extra = {"frequency": carrier_frequency} if "frequency" in {v.name for v in ev.inputs} else {}
    try:
        low, high = ev.forward(voltage=np.asarray([500.0, 1000.0]), **extra)
    except HcardError as exc:
        raise ProfileError(f"predictor: EV model {ev.name!r} cannot be used alone: {exc}") from None
    if not (low > 0 and abs(high / low - 4.0) <= 4.0 * QUADRATIC_TOLERANCE):
        raise ProfileError(
            f"predictor: EV model {ev.name!r} does not go as v^2 "
            f"(F(1000 V) / F(500 V) = {high / low if low else math.nan:g}, expected 4)"
        )
