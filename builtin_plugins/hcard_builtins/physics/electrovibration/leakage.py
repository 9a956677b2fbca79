"""Charge leakage through the stratum corneum: the dynamic electrovibration force (section 3.6).

With the finger in contact, the stratum corneum is a capacitor ``C_sc`` with a leak ``R_sc``
in series with the insulator ``C_i`` (Fig. 3.12, Eqs. 3.5 and 3.20):

``C_i = eps0 eps_i A / d_i``, ``C_sc = eps0 eps_sc A / d_sc``, ``R_sc = rho_sc d_sc / A``.

Charge that crosses the stratum corneum settles on the insulator surface and stops pulling
on the finger (Fig. 3.14), so only the part of the applied voltage ``v`` held by the charge
still bound to the finger acts (Eqs. 3.19, 3.21, 3.22):

``v_e(s) = tau_d s / (1 + tau_d s) v(s)``, ``tau_d = (C_i + C_sc) R_sc``,

a first-order high pass, and the force is Kaczmarek's law with ``v_e`` (Eq. 3.23):

``F_e = eps0 A v_e^2 / (2 (d_sc/eps_sc + d_i/eps_i)(d_sc + d_i))``.

Consequences (tests/builtins/test_electrovibration.py): a DC step gives ``v_e = V exp(-t/tau_d)``
and a force ``~ exp(-2 t/tau_d)`` that decays to zero with time constant ``tau_d / 2``, which is why
electrovibration needs an AC carrier; a sinusoid well above ``1/(2 pi tau_d)`` passes almost fully;
the force response ``|H(f)|^2`` rises then saturates with frequency (Fig. 3.16).

Defaults are those of section 3.6.1 (A = 1 cm^2, d_sc = 200 um, eps_sc = 1560, a 90 um film
of eps_i = 3.35: ``C_i`` = 33 pF, ``C_sc`` = 6.9 nF) and ``tau_d`` = 7.7 ms (section 3.6.3,
computed for the square-wave set-up of Giraud et al. [84], who measured 6 ms). With them
Eq. 3.23 gives 56.6 mN at a steady ``v_e`` = 1000 V (section 3.7: 10-20 % more friction at
0.5 N). The 2.5 mN that section 3.6.3 reports for the trapezium 0-1000 V of Fig. 3.15 is not a
steady value of these layers (it would need A = 4.4 mm^2 and then C_i = 1.5 pF, not the
printed 32 pF): it is the peak of the transient, ``v_e = r tau_d (1 - exp(-t/tau_d))`` on a
rising edge of slope ``r``, which gives 2.5 mN for a 1000 V edge of 36 ms (2-5 mN measured:
25-41 ms; the thesis does not print the rise time). tests/builtins/test_physics_ev_section_3_6_3.py
checks this reading.

Frequency dependence of ``tau_d`` (Figs. 3.13, 3.16). ``tau_d = eps0 eps_sc rho_sc`` follows
the stratum corneum's permittivity and resistivity, both of which fall strongly with frequency
(Yamamoto and Yamamoto [88]); the thesis plots the resulting ``tau_d(f)`` (Fig. 3.13) and says
it "substantially changes the behavior of Eq. 3.19 from a pure first order high pass filter"
(section 3.6.1). By default ``tau_d`` is therefore a power law of the frequency above
:data:`TAU_D_REFERENCE_FREQUENCY`::

    tau_d(f) = tau_d (max(f, 10 Hz) / 10 Hz)^tau_d_exponent,

``tau_d`` = 7.7 ms (the slow, square-wave drive of section 3.6.3) and ``tau_d_exponent`` =
:data:`FIG_3_13_SLOPE` = -0.7. ``tau_d_exponent = 0`` is the constant ``tau_d`` of the
equations, Eq. 3.22 as a pure first-order high pass (with it the force response is already
0.96 at 100 Hz and leakage does nothing to a carrier above ~100 Hz, against Fig. 3.16).

How Fig. 3.16 was read. The thesis prints neither the figure's data nor Fig. 3.13's; what the
text states about Fig. 3.16 (section 3.6.3, and its caption) is: Meyer et al. [86] measured
the force from 100 to 10000 Hz; it "exhibited an increasing and a successive saturation"; the
lines are stratum corneum thicknesses; the simulation uses ``tau_d = (C_i + C_sc) R_sc``.
Read as numbers: the force response ``|H(f)|^2`` (the peak force over the static one at the
same voltage) rises monotonically over 100 Hz - 10 kHz, is at most 0.6 of its plateau at
100 Hz (a rise must be visible across the band) and within 0.1 of it at 10 kHz (saturated at
its top), with ``tau_d`` = 7.7 ms for slow drive. The exponent -0.7 is the round value that
meets these (0.48 at 100 Hz, 0.79 at 1 kHz, 0.94 at 10 kHz); any exponent from about -0.55
to -0.8 does, so it is a reading of the figure's shape, not a digitisation, and calibrating
``tau_d_exponent`` on a device's data is the way to pin it down.

A :class:`ChargeLeakage` may instead carry an explicit curve of ``(frequency, tau_d)`` points
(``tau_d_curve``), interpolated linearly in log-log and held constant beyond its ends; it
replaces the power law. :meth:`ChargeLeakage.frequency_response` and
:meth:`ChargeLeakage.forward` use ``tau_d(f)`` per frequency, and
:meth:`ChargeLeakage.simulate` uses one ``tau_d``, taken at the ``frequency`` argument if
given, else at the waveform's dominant frequency (largest non-DC spectral line), since
Eq. 3.22 is a linear time-invariant filter only at a fixed ``tau_d``; a step (no carrier) gets
``tau_d`` itself. :data:`FIG_3_13_TREND` is the power law as a curve.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from hcard.physics import Parameter, Predictor, PredictorError, Variable

from ._common import (
    EPSILON_0,
    area_parameter,
    check_finite,
    check_non_negative,
    insulator_parameters,
    kaczmarek_coefficient,
    sc_parameters,
    voltage_for_force,
)
from .static import FORCE, Kaczmarek

TAU_D_SECTION_3_6_3 = 7.7e-3
"""``tau_d`` in s computed in section 3.6.3 for the square-wave drive of Giraud et al. [84]."""

FIG_3_13_SLOPE = -0.7
"""Log-log slope of ``tau_d(f)`` above 10 Hz (the default ``tau_d_exponent``; see the module
documentation for how it was read from Figs. 3.13 and 3.16)."""

TAU_D_REFERENCE_FREQUENCY = 10.0
"""Frequency, Hz, at and below which ``tau_d(f)`` equals the ``tau_d`` parameter (slow drive,
the square wave of section 3.6.3)."""

FIG_3_13_TREND: tuple[tuple[float, float], ...] = tuple(
    (f, TAU_D_SECTION_3_6_3 * (f / 10.0) ** FIG_3_13_SLOPE) for f in (10.0, 1e2, 1e3, 1e4)
)
"""The default ``tau_d(f)`` power law as a ``(frequency Hz, tau_d s)`` curve (the same values
from 10 Hz to 10 kHz; a curve is held constant beyond its ends, the power law is not).

The thesis prints the figure but not its values, so this is a trend, not a digitisation:
``tau_d`` falls with frequency as a power law of log-log slope -0.7, anchored at the 7.7 ms of
section 3.6.3 for slow (square-wave, <= 10 Hz) drive: 7.7 ms at 10 Hz, 1.54 ms at 100 Hz,
0.31 ms at 1 kHz, 61 us at 10 kHz. The slope is chosen so that the force response rises over
100 Hz - 10 kHz and then saturates (0.48 at 100 Hz, 0.79 at 1 kHz, 0.94 at 10 kHz), the shape
of the measurements of Meyer et al. compared in Fig. 3.16; with the constant 7.7 ms the
response is already 0.96 at 100 Hz.
"""

VOLTAGE_AMPLITUDE = Variable("voltage", "V", "amplitude of the sinusoidal applied voltage")
FREQUENCY = Variable("frequency", "Hz", "frequency of the sinusoidal applied voltage")


@dataclass(frozen=True)
class LeakageResult:
    """Output of :meth:`ChargeLeakage.simulate`.

    Attributes:
        t: sample times, s.
        voltage: applied voltage ``v(t)``, V.
        effective_voltage: ``v_e(t)`` of Eq. 3.22, V (same shape as ``voltage``).
        force: electrostatic force of Eq. 3.23, N (same shape).
        tau_d: the discharge time constant used, s.
        frequency: the frequency at which ``tau_d(f)`` was read, Hz (None when ``tau_d`` is
            constant).
    """

    t: np.ndarray
    voltage: np.ndarray
    effective_voltage: np.ndarray
    force: np.ndarray
    tau_d: float
    frequency: float | None


def _curve_array(points: Iterable[Iterable[float]]) -> np.ndarray:
    """``points`` as a checked ``(n, 2)`` array of (frequency Hz, tau_d s)."""
    try:
        curve = np.array([[float(f), float(tau)] for f, tau in points], dtype=np.float64)
    except (TypeError, ValueError):
        raise PredictorError(
            "tau_d_curve: expected (frequency Hz, tau_d s) pairs of numbers"
        ) from None
    if curve.shape[0] == 0:
        raise PredictorError("tau_d_curve: needs at least one (frequency, tau_d) point")
    if not np.all(np.isfinite(curve)) or np.any(curve <= 0):
        raise PredictorError("tau_d_curve: frequencies and tau_d must be finite and > 0")
    if np.any(np.diff(curve[:, 0]) <= 0):
        raise PredictorError("tau_d_curve: frequencies must be strictly increasing")
    return curve


class ChargeLeakage(Predictor):
    """Electrovibration force with charge leakage through the stratum corneum, Eqs. 3.19-3.23.

    ``forward(voltage=V, frequency=f)`` is the peak force (N) of a sinusoidal drive of
    amplitude ``V`` (V) at ``f`` (Hz) in steady state: Eq. 3.23 at ``v_e = |H(f)| V``
    (the force ``K v_e^2 sin^2`` oscillates at ``2 f`` between 0 and this peak; its mean is
    half of it). ``inverse`` gives the voltage amplitude for a target peak force at ``f``.
    :meth:`simulate` runs Eqs. 3.22-3.23 on a sampled waveform ``v(t)``.

    Args:
        tau_d_curve: optional ``(frequency Hz, tau_d s)`` points (Fig. 3.13; see the module
            documentation and :data:`FIG_3_13_TREND`); None keeps ``tau_d`` constant.
        **params: parameter values (see :attr:`parameters`).
    """

    name: ClassVar[str] = "ev-charge-leakage"
    calibrated: ClassVar[tuple[str, ...]] = ("area", "tau_d")
    description: ClassVar[str] = (
        "Electrovibration force through the stratum corneum charge-leakage high pass "
        "(Eqs. 3.19-3.23)"
    )
    parameters: ClassVar[tuple[Parameter, ...]] = (
        area_parameter(1e-4, "section 3.6.1 (A = 1 cm^2)"),
        *sc_parameters(200e-6, 1560.0, "section 3.6.1 (d_sc [1], eps_sc [88])"),
        *insulator_parameters(90e-6, 3.35, "section 3.6.1 (plastic film)"),
        Parameter(
            "tau_d",
            "s",
            TAU_D_SECTION_3_6_3,
            (1e-7, 10.0),
            "section 3.6.3 (7.7 ms computed; 6 ms measured in [84]); Eq. 3.19",
            "discharge time constant (C_i + C_sc) R_sc for slow drive (<= 10 Hz)",
        ),
        Parameter(
            "tau_d_exponent",
            "",
            FIG_3_13_SLOPE,
            (-1.0, 0.0),
            "Figs. 3.13, 3.16 (shape read from section 3.6.3; 0: constant tau_d)",
            "log-log slope of tau_d(f) above 10 Hz",
        ),
    )
    inputs: ClassVar[tuple[Variable, ...]] = (VOLTAGE_AMPLITUDE, FREQUENCY)
    output: ClassVar[Variable] = FORCE
    inverse_input: ClassVar[str | None] = "voltage"

    def __init__(
        self, *, tau_d_curve: Iterable[Iterable[float]] | None = None, **params: float
    ) -> None:
        super().__init__(**params)
        self._curve = None if tau_d_curve is None else _curve_array(tau_d_curve)

    # -- circuit quantities (Fig. 3.12) -----------------------------------------------------
    @property
    def insulator_capacitance(self) -> float:
        """``C_i = eps0 eps_i A / d_i`` in F (Eq. 3.5)."""
        return (
            EPSILON_0 * self["insulator_permittivity"] * self["area"] / self["insulator_thickness"]
        )

    @property
    def sc_capacitance(self) -> float:
        """``C_sc = eps0 eps_sc A / d_sc`` in F (Eq. 3.5)."""
        return EPSILON_0 * self["sc_permittivity"] * self["area"] / self["sc_thickness"]

    @property
    def sc_resistance(self) -> float:
        """``R_sc = tau_d / (C_i + C_sc)`` in Ohm (Eq. 3.19) for slow drive (``tau_d``)."""
        return self["tau_d"] / (self.insulator_capacitance + self.sc_capacitance)

    @property
    def sc_resistivity(self) -> float:
        """``rho_sc = R_sc A / d_sc`` in Ohm m (Eq. 3.20)."""
        return self.sc_resistance * self["area"] / self["sc_thickness"]

    @property
    def coefficient(self) -> float:
        """``F_e / v_e^2`` in N/V^2 (Eq. 3.23)."""
        return float(
            kaczmarek_coefficient(
                self["area"],
                self["sc_thickness"] / self["sc_permittivity"]
                + self["insulator_thickness"] / self["insulator_permittivity"],
                self["sc_thickness"] + self["insulator_thickness"],
            )
        )

    def static_model(self) -> Kaczmarek:
        """The static Kaczmarek model (Eq. 3.12) with the same area and layers."""
        return Kaczmarek(**{p.name: self[p.name] for p in Kaczmarek.parameters})

    # -- tau_d(f), Fig. 3.13 ----------------------------------------------------------------
    @property
    def tau_d_curve(self) -> tuple[tuple[float, float], ...] | None:
        """The ``(frequency Hz, tau_d s)`` points, or None for a constant ``tau_d``."""
        if self._curve is None:
            return None
        return tuple((float(f), float(tau)) for f, tau in self._curve)

    @property
    def frequency_dependent(self) -> bool:
        """True when ``tau_d`` depends on the frequency (a curve, or a non-zero exponent)."""
        return self._curve is not None or self["tau_d_exponent"] != 0.0

    def tau_d_at(self, frequency: Any) -> np.ndarray:
        """``tau_d`` in s at each ``frequency`` (Hz, >= 0): the curve interpolated in log-log
        (constant beyond its ends) when there is one, else
        ``tau_d (max(f, 10 Hz) / 10 Hz)^tau_d_exponent``."""
        freq = check_non_negative("frequency", np.asarray(frequency, dtype=np.float64), "Hz")
        if self._curve is None:
            ratio = np.maximum(freq, TAU_D_REFERENCE_FREQUENCY) / TAU_D_REFERENCE_FREQUENCY
            return self["tau_d"] * ratio ** self["tau_d_exponent"]
        log_f = np.log(np.maximum(freq, self._curve[0, 0]))
        return np.exp(np.interp(log_f, np.log(self._curve[:, 0]), np.log(self._curve[:, 1])))

    # -- frequency domain -------------------------------------------------------------------
    def frequency_response(self, frequency: Any) -> np.ndarray:
        """Complex ``H(j 2 pi f) = v_e / v = j w tau_d / (1 + j w tau_d)`` (Eq. 3.22).

        ``frequency`` in Hz (>= 0, any shape); ``tau_d`` per frequency when the model has a
        curve. ``|H|`` rises from 0 at DC to 1 (``|H| = 1/sqrt(2)`` at ``1/(2 pi tau_d)``).
        """
        freq = check_non_negative("frequency", np.asarray(frequency, dtype=np.float64), "Hz")
        jwt = 2j * np.pi * freq * self.tau_d_at(freq)
        return jwt / (1.0 + jwt)

    def force_response(self, frequency: Any) -> np.ndarray:
        """``|H(f)|^2``: steady-state peak force over the static (Eq. 3.12) force at the same
        voltage amplitude, for a sinusoid at ``frequency`` Hz (the shape of Fig. 3.16)."""
        return np.square(np.abs(self.frequency_response(frequency)))

    def _forward(self, **inputs: np.ndarray) -> np.ndarray:
        voltage = check_finite("voltage", inputs["voltage"])
        return self.coefficient * self.force_response(inputs["frequency"]) * np.square(voltage)

    def _inverse(self, target: np.ndarray, **inputs: np.ndarray) -> np.ndarray:
        gain = self.force_response(inputs["frequency"])
        check_finite("target", target)
        if np.any((gain == 0) & (target > 0)):
            raise PredictorError(
                "frequency: at 0 Hz the charge leaks away and no voltage gives a force "
                "(Eq. 3.22); use an AC carrier"
            )
        coefficient = np.where(gain > 0, self.coefficient * gain, 1.0)
        return voltage_for_force(target, coefficient)

    # -- time domain ------------------------------------------------------------------------
    def simulate(self, t: Any, v: Any, *, frequency: float | None = None) -> LeakageResult:
        """Effective voltage (Eq. 3.22) and force (Eq. 3.23) for a sampled waveform ``v(t)``.

        Args:
            t: sample times, s: 1-D, finite, strictly increasing and uniformly spaced.
            v: applied voltage, V: finite, shape ``(..., len(t))`` (several waveforms at once
                along leading axes).
            frequency: Hz, where to read ``tau_d(f)`` (only used when ``tau_d`` depends on
                the frequency; default: the dominant frequency of ``v``).

        The system is uncharged before ``t[0]``, where ``v`` steps from 0 to ``v[0]``.
        Between samples ``v`` is taken as linear, and the high pass is discretised exactly
        for such a waveform (ramp-invariant, first-order-hold coefficients):
        ``v_e[n] = a v_e[n-1] + g (v[n] - v[n-1])`` with ``a = exp(-dt/tau_d)`` and
        ``g = tau_d (1 - a) / dt``, run by :func:`scipy.signal.lfilter` (no Python loop over
        samples). After a step the effective voltage decays exactly as ``exp(-t/tau_d)``;
        for sinusoids the gain matches :meth:`frequency_response` to better than 1e-5 and
        the phase to 2 mrad up to a fifth of the sampling rate.
        """
        times = np.asarray(t, dtype=np.float64)
        volts = np.asarray(v, dtype=np.float64)
        if times.ndim != 1 or times.size < 2:
            raise PredictorError("t: must be a 1-D array of at least 2 sample times")
        check_finite("t", times)
        steps = np.diff(times)
        if np.any(steps <= 0):
            raise PredictorError("t: sample times must be strictly increasing")
        dt = float(times[-1] - times[0]) / (times.size - 1)
        if np.max(np.abs(steps - dt)) > 1e-6 * dt:
            raise PredictorError("t: samples must be uniformly spaced")
        if volts.ndim == 0 or volts.shape[-1] != times.size:
            raise PredictorError(
                f"v: its last axis must have one value per sample time ({times.size}), "
                f"got shape {volts.shape}"
            )
        check_finite("v", volts)

        used_frequency: float | None = None
        if not self.frequency_dependent:
            tau = self["tau_d"]
        else:
            if frequency is None:
                used_frequency = dominant_frequency(volts, dt)
            else:
                used_frequency = float(
                    check_non_negative("frequency", np.asarray(frequency, dtype=float), "Hz")
                )
            tau = float(self.tau_d_at(used_frequency))

        a = math.exp(-dt / tau)
        g = tau * -math.expm1(-dt / tau) / dt
        # State chosen so that v_e[0] = v[0]: the step from 0 at t[0] passes undiminished.
        initial = ((1.0 - g) * volts[..., :1]).astype(np.float64)
        # imported here: a host that only describes a device (a conformance run under TCG)
        # never pays for scipy.signal; a simulated device has it from its plate already
        from scipy.signal import lfilter

        effective, _ = lfilter([g, -g], [1.0, -a], volts, axis=-1, zi=initial)
        force = self.coefficient * np.square(effective)
        return LeakageResult(
            t=times,
            voltage=volts,
            effective_voltage=effective,
            force=force,
            tau_d=tau,
            frequency=used_frequency,
        )

    # -- profiles: the curve travels with the parameters ------------------------------------
    def with_params(self, **changes: float) -> ChargeLeakage:
        """A copy with some parameters changed (the ``tau_d`` curve is kept)."""
        return type(self)(tau_d_curve=self.tau_d_curve, **{**self.params, **changes})

    def with_tau_d_curve(self, tau_d_curve: Iterable[Iterable[float]] | None) -> ChargeLeakage:
        """A copy with another ``tau_d`` curve (None: constant ``tau_d``)."""
        return type(self)(tau_d_curve=tau_d_curve, **self.params)

    def to_profile(self) -> dict[str, Any]:
        """The base profile plus ``"curves": {"tau_d": [[f, tau_d], ...]}`` when set."""
        profile = super().to_profile()
        if self._curve is not None:
            profile["curves"] = {
                "tau_d": {"unit": ["Hz", "s"], "points": self._curve.tolist()}
            }
        return profile

    @classmethod
    def from_profile(cls, profile: Mapping[str, Any], *, source: str = "profile") -> ChargeLeakage:
        """An instance from :meth:`to_profile` output, ``tau_d`` curve included."""
        base = super().from_profile(profile, source=source)
        curves = profile.get("curves", {})
        if not isinstance(curves, Mapping):
            raise PredictorError(f"{source}: 'curves' must be an object")
        entry = curves.get("tau_d")
        if entry is None:
            return cls(tau_d_curve=None, **base.params)
        if not isinstance(entry, Mapping) or not isinstance(entry.get("points"), list):
            raise PredictorError(f"{source}: curves.tau_d must be an object with 'points'")
        if entry.get("unit", ["Hz", "s"]) != ["Hz", "s"]:
            raise PredictorError(f"{source}: curves.tau_d points must be in [Hz, s]")
        try:
            return cls(tau_d_curve=entry["points"], **base.params)
        except PredictorError as exc:
            raise PredictorError(f"{source}: {exc}") from None


def dominant_frequency(v: np.ndarray, dt: float) -> float:
    """The frequency (Hz) of the largest non-DC line of the spectrum of ``v`` (summed over
    leading axes) sampled every ``dt`` s; 0 for a constant waveform (a step at ``t[0]``,
    whose content is at the lowest frequencies)."""
    spectrum = np.abs(np.fft.rfft(v, axis=-1))
    if spectrum.ndim > 1:
        spectrum = np.sqrt(np.sum(np.square(spectrum.reshape(-1, spectrum.shape[-1])), axis=0))
    if spectrum.size < 2 or np.max(spectrum[1:]) <= 1e-9 * np.max(spectrum):
        return 0.0
    index = 1 + int(np.argmax(spectrum[1:]))
    return index / (v.shape[-1] * dt)
