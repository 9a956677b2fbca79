"""The catalogue of hidden effects: names, parameters and their checks (:data:`HIDDEN_EFFECTS`).

What each effect does physically is in the package documentation (:mod:`hcard_device.sim.hidden`)
and in the module that runs it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from hcard.errors import InputError
from hcard.physics import Parameter, PredictorError
from hcard_builtins.physics.finger import FingerFriction

FINGER_LOAD_INDEX = next(p.default for p in FingerFriction.parameters if p.name == "load_index")
"""The load index of the device's own finger (:class:`FingerFriction`'s default)."""
NO_LEAKAGE_S = 10.0
"""``charge-leakage`` time constant that stands for no leakage at all, s."""
DEVICE_TAU_D_S = 7.7e-3
"""The leakage time constant at 10 Hz of the device's own profile (section 3.6.3), s: the
``charge-leakage`` value that leaves the device as it is."""
NO_LOAD_DAMPING_N = 1e6
"""``plate-load-damping`` force that stands for no local damping (the effect off exactly), N."""
IDEAL_SENSOR_HZ = 1e5
"""``force-sensor-resonance`` natural frequency that stands for an ideal sensor (off), Hz."""


class HiddenEffectError(InputError, ValueError):
    """An unknown hidden effect or parameter, a bad value, or an effect the device cannot have."""


@dataclass(frozen=True)
class HiddenEffect:
    """An effect the simulated hardware can hide.

    Attributes:
        name: its name (the calibration library's name for the same physics).
        description: one line: what it is, with its thesis source.
        devices: the device variants (``evita``, ``coupled``) that can have it.
        parameters: its parameters; the defaults are the hidden truth when none is given.
        neutral: parameter values at which the device is the un-hidden one exactly.
    """

    name: str
    description: str
    devices: tuple[str, ...]
    parameters: tuple[Parameter, ...]
    neutral: dict[str, float]


def _p(name: str, unit: str, default: float, bounds: tuple[float, float], source: str,
       description: str) -> Parameter:
    return Parameter(name, unit, default, bounds, source, description)


UV, EV, BOTH = ("evita", "coupled"), ("coupled",), ("evita", "coupled")

HIDDEN_EFFECTS: dict[str, HiddenEffect] = {e.name: e for e in (
    HiddenEffect(
        "load-index",
        "the finger's friction F = k Fn^n with another load index n (Eqs. 1.7, 2.35)",
        BOTH,
        (_p("load_index", "", 0.75, (0.3, 1.5),
            "Eqs. 1.7, 2.35 (theory 2/3 <= n <= 1); value chosen",
            f"frictional load index n of the finger (the device's own: {FINGER_LOAD_INDEX:g})"),),
        {"load_index": FINGER_LOAD_INDEX},
    ),
    HiddenEffect(
        "occlusion-drift",
        "dry friction rising with the accumulated contact time t, lifts excluded: "
        "mu0 (1 + g (1 - exp(-t/tau))) (Fig. 1.11)",
        BOTH,
        (_p("gain", "", 0.5, (0.0, 10.0), "Fig. 1.11, section 1.4.2.2; value chosen",
            "relative friction rise g at full occlusion"),
         _p("time_constant", "s", 30.0, (1e-2, 1e4), "Fig. 1.11b (~20 s); value chosen",
            "time constant tau of the rise")),
        {"gain": 0.0},
    ),
    HiddenEffect(
        "actuator-bandwidth",
        "the vibration under the finger follows the sensed amplitude through a first-order lag "
        "tau_a (section 4.3.2, Fig. 4.5)",
        BOTH,
        (_p("time_constant", "s", 1.5e-3, (0.0, 1.0),
            "section 4.3.2 (fast plate ~1.5 ms, [86]'s ~15 ms)",
            "time constant tau_a of the lag (0: none)"),),
        {"time_constant": 0.0},
    ),
    HiddenEffect(
        "charge-leakage",
        "bound charge leaking through the stratum corneum of a finger whose tau_d differs from "
        "the profile's: the carrier reaches the skin with the gain of Eq. 3.22 at tau_d(f_c) "
        "(Eqs. 3.19-3.23, Fig. 3.13)",
        EV,
        (_p("time_constant", "s", 3e-3, (1e-5, NO_LEAKAGE_S),
            "Eq. 3.22, section 3.6.3 (7.7 ms at 10 Hz, the device profile's), Fig. 3.13 "
            "(tau_d falls as f^-0.7); value chosen: a more conductive skin",
            "the finger's leakage time constant tau_d at 10 Hz"),),
        {"time_constant": DEVICE_TAU_D_S},
    ),
    HiddenEffect(
        "ultrasonic-speed",
        "the ultrasonic friction reduction scales with sliding speed: (1 - mu') (U/U_ref)^a "
        "(Fig. 2.21e)",
        BOTH,
        (_p("speed_exponent", "", -0.5, (-3.0, 3.0),
            "Fig. 2.21e (the reduction falls with speed: a < 0); value chosen",
            "exponent a of U/U_ref on the reduction"),
         _p("reference_speed", "m/s", 0.025, (1e-3, 0.5),
            "Figs. 2.21, 2.24 (20-40 mm/s); value chosen",
            "speed U_ref at which the device's own reduction holds")),
        {"speed_exponent": 0.0},
    ),
    HiddenEffect(
        "air-layer",
        "air between the fingerprint ridges and the insulator: EV force of AirLayer (Eq. 3.17) "
        "with the gap d_a1 (1 N / Fn)",
        EV,
        (_p("air_gap", "m", 10e-6, (0.0, 1e-3), "Eq. 3.17, Fig. 3.7; value chosen",
            "air gap d_a1 at a normal force of 1 N"),),
        {"air_gap": 0.0},
    ),
    HiddenEffect(
        "skin-recovery",
        "friction deficit D exp(-k/k_r) over the strokes k since the finger last rested "
        "(Figs. 2.25-2.26)",
        BOTH,
        (_p("depth", "", 0.2, (0.0, 0.95), "Figs. 2.25-2.26 (mechanism); value chosen",
            "relative friction deficit D of the first stroke after a rest"),
         _p("strokes", "", 2.0, (0.05, 1e3), "Figs. 2.25-2.26 (mechanism); value chosen",
            "strokes k_r over which the deficit decays by 1/e")),
        {"depth": 0.0},
    ),
    HiddenEffect(
        "squeeze-film-share",
        "the ultrasonic reduction scales with the ambient pressure p: gamma = 1 - s (1 - p/p0) "
        "(Eq. 2.10)",
        BOTH,
        (_p("share", "", 0.5, (0.0, 1.0), "Eq. 2.10, Fig. 2.12; value chosen",
            "share s of the reduction carried by the squeeze film"),),
        {"share": 0.0},
    ),
    HiddenEffect(
        "finger-geometry",
        "EV force of the curved ridged pad (Eq. 3.18, Table 3.2) flattened to the depth "
        "h_1 (Fn/1 N)^m, relative to the device's own force at 1 N",
        EV,
        (_p("area_index", "", 2.0 / 3.0, (0.0, 2.0), "Eqs. 1.4-1.5 (Hertz: m = 2/3)",
            "areal load index m of the flattened depth (0: the device's own law)"),),
        {"area_index": 0.0},
    ),
    HiddenEffect(
        "plate-load-damping",
        "the finger damps the mode under it: it feels A_sensed / (1 + Fn/F_d) while the "
        "sensing piezos report A_sensed (section 4.4: the finger damps the plate's vibration)",
        BOTH,
        (_p("damping_force", "N", 2.0, (1e-2, NO_LOAD_DAMPING_N),
            f"section 4.4 (the finger damps the vibration); value chosen; {NO_LOAD_DAMPING_N:g} "
            "N: none", "normal force F_d at which the amplitude under the finger is halved"),),
        {"damping_force": NO_LOAD_DAMPING_N},
    ),
    HiddenEffect(
        "force-sensor-resonance",
        "the lateral force sensor is a second-order system (f0, zeta) the true force passes "
        "through (the floating-table tribometer of section 2.2.2.1, Fig. 2.5a)",
        BOTH,
        (_p("natural_frequency", "Hz", 150.0, (1.0, IDEAL_SENSOR_HZ),
            "Fig. 2.5a; value chosen (the tribometer of section 4.3.2: 1 kHz); "
            f"{IDEAL_SENSOR_HZ:g} Hz: an ideal sensor",
            "natural frequency f0 of the sensor"),
         _p("damping_ratio", "", 0.1, (1e-3, 10.0), "value chosen",
            "damping ratio zeta of the sensor")),
        {"natural_frequency": IDEAL_SENSOR_HZ},
    ),
)}
"""The effects a simulated device can hide, by name."""


def resolve(variant: str, effects: Mapping[str, Mapping[str, float]] | None
            ) -> dict[str, dict[str, float]]:
    """``effects`` checked for device ``variant`` and completed with the defaults.

    Raises:
        HiddenEffectError: an unknown effect or parameter (listing the known ones), one the
            device cannot have, or a value outside the parameter's bounds.
    """
    out: dict[str, dict[str, float]] = {}
    for name, values in (effects or {}).items():
        effect = HIDDEN_EFFECTS.get(name)
        if effect is None:
            raise HiddenEffectError(
                f"unknown hidden effect {name!r}; known: {', '.join(HIDDEN_EFFECTS)}")
        if variant not in effect.devices:
            raise HiddenEffectError(
                f"effect {name} needs the {' or '.join(effect.devices)} device, not {variant}")
        known = {p.name: p for p in effect.parameters}
        unknown = sorted(set(values) - set(known))
        if unknown:
            raise HiddenEffectError(
                f"effect {name} has no parameter(s) {', '.join(unknown)}; its parameters: "
                f"{', '.join(known)}")
        checked = {}
        for parameter in effect.parameters:
            try:
                checked[parameter.name] = parameter.check(values.get(parameter.name,
                                                                     parameter.default))
            except PredictorError as exc:
                raise HiddenEffectError(f"effect {name}: {exc}") from None
        out[name] = checked
    return out


def parse_assignments(names: Iterable[str], assignments: Iterable[str]
                      ) -> dict[str, dict[str, float]]:
    """Effects from ``--effect NAME`` and ``--effect-param NAME.PARAM=VALUE`` texts (units
    accepted; an assignment switches its effect on).

    Raises:
        HiddenEffectError: a malformed assignment, an unknown effect or parameter, a bad value.
    """
    from hcard.quantities import UnitError, parse_quantity

    chosen: dict[str, dict[str, float]] = {name: {} for name in names}
    for text in assignments:
        key, equals, value = text.partition("=")
        effect, dot, parameter = key.strip().rpartition(".")
        if not equals or not dot or not effect or not parameter or not value.strip():
            raise HiddenEffectError(
                f"{text!r}: expected EFFECT.PARAM=VALUE (air-layer.air_gap=8um)")
        known = HIDDEN_EFFECTS.get(effect)
        if known is None:
            raise HiddenEffectError(
                f"{text!r}: unknown hidden effect {effect!r}; known: {', '.join(HIDDEN_EFFECTS)}")
        units = {p.name: p.unit for p in known.parameters}
        if parameter not in units:
            raise HiddenEffectError(
                f"{text!r}: effect {effect} has no parameter {parameter!r}; its parameters: "
                f"{', '.join(units)}")
        try:
            chosen.setdefault(effect, {})[parameter] = parse_quantity(value.strip(),
                                                                      units[parameter])
        except UnitError as exc:
            raise HiddenEffectError(f"{text!r}: {exc}") from None
    return chosen
