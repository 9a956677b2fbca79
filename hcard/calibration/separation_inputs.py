"""What a separating experiment is designed from (spec/calibration.md K33): the two effects by
name, and the base device model with its noise, either a device class's own profile with the
stated defaults (:class:`~hcard.calibration.separation.Noise`) or a previous calibration's
output folder (``profile.json`` and ``report.json``, K12-K13).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hcard.calibration.separation import Noise, Pair, SeparationError, make_pair
from hcard.json_file import read_json_file
from hcard.physics import Predictor
from hcard.physics.effects import Effect
from hcard.physics.profile import DeviceProfile
from hcard.plugins.registry import get_registry

PROFILE_FILE, REPORT_FILE = "profile.json", "report.json"
DEVICE_CHANNELS = {"uv": ("uv", "finger"), "ev": ("ev", "finger"),
                   "coupled": ("uv", "ev", "finger")}
"""What each device class of the plan can play (spec/calibration.md section 6)."""


def effect_pair(text: str) -> tuple[Effect, Effect]:
    """``"A,B"`` -> the two installed effects.

    Raises:
        SeparationError: not two names, an unknown name (the installed ones listed), or one
            effect twice.
    """
    library = get_registry().calibration_effects
    names = [name.strip() for name in text.split(",")]
    if len(names) != 2 or not all(names):
        raise SeparationError(f"--separate {text!r}: give two effects, A,B")
    unknown = [name for name in names if name not in library]
    if unknown:
        raise SeparationError(f"--separate: unknown effect(s) {', '.join(unknown)}; installed: "
                              f"{', '.join(library) or 'none'}")
    if names[0] == names[1]:
        raise SeparationError(f"--separate {text!r}: one effect twice; name two different "
                              "effects")
    return library[names[0]], library[names[1]]


def default_finger() -> Predictor:
    """The bare finger's friction model a calibration fits by default (K15)."""
    return get_registry().get("predictor", "finger-friction")


def finger_of(profile: DeviceProfile) -> Predictor:
    """The finger model a calibrated profile was fitted with (its observation), else the
    default at its defaults."""
    observed = (profile.observation or {}).get("finger")
    if not isinstance(observed, Mapping):
        return default_finger()
    model = get_registry().get("predictor", str(observed.get("model", "finger-friction")))
    values = {name: float(entry["value"]) for name, entry in
              (observed.get("parameters") or {}).items() if name in model.params}
    return model.with_params(**values)


def _number(document: Mapping[str, Any], *path: str) -> float | None:
    value: Any = document
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    return float(value) if isinstance(value, (int, float)) and math.isfinite(value) else None


def noise_of(report: Mapping[str, Any], source: str, pair_names: tuple[str, str]) -> Noise:
    """The noise, sample rate, held-out share and length of a previous calibration's
    recordings, and, when its runner-up comparison was between the two effects, the squared
    difference of their held-out errors (report.json, K12)."""
    defaults = Noise()
    sigma = _number(report, "structure", "noise", "sigma_n") or _number(
        report, "held_out_rmse_n", "after") or defaults.sigma_n
    rate = _number(report, "data", "sample_rate_hz") or defaults.rate_hz
    samples = _number(report, "data", "samples")
    used = (_number(report, "data", "training_samples") or 0) + (
        _number(report, "data", "held_out_samples") or 0)
    held = _number(report, "data", "held_out_samples")
    observed = None
    runner = report.get("runner_up")
    if isinstance(runner, Mapping) and {tuple(runner.get("chosen") or ()),
                                        tuple(runner.get("runner_up") or ())} == {
            (pair_names[0],), (pair_names[1],)}:
        chosen, rival = _number(runner, "chosen_rmse"), _number(runner, "runner_up_rmse")
        if chosen is not None and rival is not None:
            observed = abs(rival**2 - chosen**2)
    return Noise(
        sigma_n=sigma,
        lag1=_number(report, "residuals", "after", "time", "lag1_autocorrelation") or 0.0,
        rate_hz=rate,
        held_out=held / used if held and used else defaults.held_out,
        recorded_s=samples / rate if samples else defaults.recorded_s,
        source=f"{source} (noise over the lifts, sample rate, held-out share, length)",
        observed_n2=observed,
    )


def from_folder(folder: Path, a: Effect, b: Effect) -> tuple[Pair, Noise]:
    """The pair on a previous calibration's fitted profile, the effect it added the reference
    (at its fitted values; ``a`` when it added neither), and that run's noise.

    Raises:
        SeparationError: the folder holds no profile.json.
    """
    path = folder / PROFILE_FILE
    if not path.is_file():
        raise SeparationError(f"--from {folder}: no {PROFILE_FILE} in this folder (the output "
                              "folder of `hcard calibrate` holds one)")
    profile = DeviceProfile.load(path)
    report_path = folder / REPORT_FILE
    report = read_json_file(report_path, SeparationError, what="a calibration report",
                            named="report.json", label="report") if report_path.is_file() else {}
    if not isinstance(report, Mapping):
        raise SeparationError(f"{report_path}: not a calibration report (a JSON object)")
    added = {fitted.name: dict(fitted.values) for fitted in profile.effects}
    reference, rival = (b, a) if b.name in added and a.name not in added else (a, b)
    pair = make_pair(reference, rival, profile, finger_of(profile), added.get(reference.name))
    source = str(report_path) if report else f"{path} (no report.json: noise defaults)"
    noise = noise_of(report, source, (a.name, b.name)) if report else Noise(source=source)
    return pair, noise


def from_class(device: str, a: Effect, b: Effect) -> tuple[Pair, Noise]:
    """The pair on a device class's own profile (the coupled stimulator's models), ``a`` the
    reference at its defaults, the noise defaults.

    Raises:
        SeparationError: the class cannot play the effects' channel.
    """
    pair = make_pair(a, b, DeviceProfile.coupled_stimulator(), default_finger())
    check_device(device, pair)
    return pair, Noise()


def check_device(device: str, pair: Pair) -> None:
    """:class:`SeparationError` when ``device`` cannot play the pair's channel."""
    if pair.channel not in DEVICE_CHANNELS.get(device, ()):
        raise SeparationError(
            f"device class {device} cannot render the {pair.channel.upper()} channel "
            f"{pair.reference.name} and {pair.rival.name} act on; use a class that plays it "
            f"({', '.join(c for c, ch in DEVICE_CHANNELS.items() if pair.channel in ch)})")
