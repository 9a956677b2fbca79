"""The ``haps`` importer (spec/interchange/haps.md): known answers on hand-written .haps files,
and the public samples of Interhaptics/Unity_CoreSDK against an evaluation of their keyframes
written here, apart from the importer (its own interpolation, phase sum and card equation).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hcard.errors import AssetError, UsageError
from hcard.v1 import card_pb2 as pb
from hcard.validate import require_valid
from hcard_builtins.formats.haps import DEFAULT_LENGTH_UNIT_MM, HapsImporter
from tests.helpers.public_samples import fetched_sample

"""Where scripts/fetch_public_samples.py puts the Unity_CoreSDK samples (their EULA keeps them
out of the repository)."""
JND = 0.08


# --- hand-written files ---------------------------------------------------------------------

def keyframes(pairs: list[tuple[float, float]]) -> dict[str, Any]:
    return {"m_extrapolationStrategy": 0,
            "m_keyframes": [{"m_time": t, "m_value": v} for t, v in pairs]}


def note(amplitude: list[tuple[float, float]], frequency: list[tuple[float, float]], *,
         start: float = 0.0, length: float = 1.0, gain: float = 1.0) -> dict[str, Any]:
    """A note as Haptic Composer writes one (Texture.haps's layout)."""
    return {"m_gain": gain, "m_length": length, "m_priority": 1, "m_startingPoint": start,
            "m_hapticEffect": {"m_amplitudeModulation": keyframes(amplitude),
                               "m_frequencyModulation": keyframes(frequency)}}


def haps(melodies: list[list[dict[str, Any]]], *, gain: float = 1.0,
         texture_gain: float = 1.0, melody_gains: list[float] | None = None,
         muted: tuple[int, ...] = ()) -> dict[str, Any]:
    """A v5 .haps document whose texture perception holds ``melodies`` of notes."""
    gains = melody_gains or [1.0] * len(melodies)
    empty = {"m_gain": 1.0, "m_loop": 0, "m_maximum": 1.0, "m_melodies": [],
             "m_signalEvaluationMethod": 3}
    return {
        "m_HDFlag": 0, "m_description": "", "m_gain": gain, "m_length_unit": 7,
        "m_stiffness": empty, "m_time_unit": 0, "m_version": "5", "m_vibration": empty,
        "m_texture": {"m_gain": texture_gain, "m_loop": 0, "m_signalEvaluationMethod": 3,
                      "m_melodies": [{"m_gain": g, "m_mute": int(i in muted), "m_notes": notes}
                                     for i, (g, notes) in enumerate(zip(gains, melodies,
                                                                        strict=True))]},
    }


def write(tmp_path: Path, document: Any, name: str = "t.haps") -> Path:
    path = tmp_path / name
    path.write_text(json.dumps(document), encoding="utf-8")
    return path


def read(path: Path, **options: Any) -> Any:
    importer = HapsImporter()
    result = importer.read(path, **importer.options(**options))
    require_valid(result.card)
    return result


# --- an evaluation written here: the source from its keyframes, the card from its equation ---

def lerp(ts: list[float], vs: list[float], w: np.ndarray) -> np.ndarray:
    """Piecewise-linear through (ts, vs), ends held: a loop over segments, not np.interp."""
    out = np.full_like(w, vs[0], dtype=float)
    for i in range(len(ts) - 1):
        t0, v0, t1, v1 = ts[i], vs[i], ts[i + 1], vs[i + 1]
        inside = (w >= t0) & (w <= t1)
        if t1 > t0:
            out[inside] = v0 + (v1 - v0) * (w[inside] - t0) / (t1 - t0)
    out[w > ts[-1]] = vs[-1]
    return out


def oracle_friction(document: dict[str, Any], x_mm: np.ndarray, unit_mm: float,
                    low: float = 0.3, high: float = 1.0) -> np.ndarray:
    """spec/interchange/haps.md IH4, IH5, IH8 and IH9 for a UV range, by a midpoint phase sum
    on a 1 um grid."""
    texture = document["m_texture"]
    top = document.get("m_gain", 1.0) * texture.get("m_gain", 1.0)
    envelope = np.zeros_like(x_mm)
    signal = np.zeros_like(x_mm)
    for melody in texture["m_melodies"]:
        if melody.get("m_mute"):
            continue
        for n in melody["m_notes"]:
            effect = n["m_hapticEffect"]
            amp = effect["m_amplitudeModulation"]["m_keyframes"]
            freq = effect["m_frequencyModulation"]["m_keyframes"]
            gain = top * melody.get("m_gain", 1.0) * n.get("m_gain", 1.0)
            step = 0.001 / unit_mm
            fine = np.arange(0.0, n["m_length"] + step, step)
            f = lerp([k["m_time"] for k in freq], [k["m_value"] for k in freq], fine + step / 2)
            cycles = np.concatenate(([0.0], np.cumsum(f * step)))[:-1]
            w = x_mm / unit_mm - n["m_startingPoint"]
            inside = (w >= 0) & (w <= n["m_length"])
            a = np.where(inside, lerp([k["m_time"] for k in amp], [k["m_value"] for k in amp],
                                      w), 0.0)
            phase = 2 * np.pi * np.interp(w, fine, cycles)
            envelope += gain * a
            signal += gain * a * np.sin(phase)
    half = (high - low) / 2
    scale = 1 / max(1.0, float(envelope.max()))
    return high - half * scale * envelope + half * scale * signal


def card_at(card: pb.Card, x_mm: np.ndarray) -> np.ndarray:
    """The card's position-locked friction at (x, height / 2) by spec/README.md's component
    equation ``b + sum a cos(2 pi f (x cos o + y sin o) + p)``, taxtel by taxtel."""
    grid = card.grid
    y = card.surface.height_mm / 2
    col = np.minimum((x_mm / grid.taxtel_width_mm).astype(int), grid.cols - 1)
    out = np.empty_like(x_mm)
    for k in range(grid.cols):
        texture = card.textures[grid.texture_index[k]]
        sel = col == k
        value = np.full(int(sel.sum()), texture.baseline)
        for c in texture.components:
            value += c.amplitude * np.cos(2 * np.pi * c.frequency * (
                x_mm[sel] * math.cos(c.orientation) + y * math.sin(c.orientation)) + c.phase)
        out[sel] = value
    return out


# --- known answers --------------------------------------------------------------------------

def test_a_constant_note_is_one_grating_of_wavelength_one_over_f_units(tmp_path: Path) -> None:
    """IH5, IH9, IH10: amplitude 0.6 at 2 cycles per unit, 10 mm per unit: every taxtel plays
    one position-locked UV grating of 0.2 cycles/mm (5 mm wavelength), amplitude 0.35 x 0.6,
    phase -pi/2 (sin at the note's start), on a baseline of 1 - 0.21."""
    path = write(tmp_path, haps([[note([(0, 0.6), (1, 0.6)], [(0, 2.0), (1, 2.0)])]]))
    result = read(path, length_unit_mm=10.0)
    card = result.card
    assert card.surface.width_mm == pytest.approx(10.0)
    assert len(card.textures) == 1
    texture = card.textures[0]
    assert texture.channel == pb.CHANNEL_UV and texture.locking == pb.LOCKING_POSITION
    assert texture.baseline == pytest.approx(1.0 - 0.21)
    (component,) = texture.components
    assert component.frequency == pytest.approx(0.2)
    assert component.amplitude == pytest.approx(0.21)
    assert component.phase == pytest.approx(-math.pi / 2, abs=1e-9)
    assert result.stats["max_error_jnd"] < 1e-3


def test_an_amplitude_ramp_gives_each_taxtel_its_mean_amplitude(tmp_path: Path) -> None:
    """IH10: amplitude 0 -> 1 over one unit of 10 mm in 2.5 mm taxtels: 0.125, 0.375, 0.625,
    0.875 of the full-scale 0.35, the baseline lowered as much."""
    path = write(tmp_path, haps([[note([(0, 0.0), (1, 1.0)], [(0, 5.0), (1, 5.0)])]]))
    card = read(path, length_unit_mm=10.0, taxtel_mm=2.5).card
    assert card.grid.cols == 4
    amplitudes = [card.textures[i].components[0].amplitude for i in card.grid.texture_index]
    assert amplitudes == pytest.approx([0.35 * a for a in (0.125, 0.375, 0.625, 0.875)])
    baselines = [card.textures[i].baseline for i in card.grid.texture_index]
    assert baselines == pytest.approx([1.0 - a for a in amplitudes])


def test_gains_multiply_and_a_muted_melody_is_silent(tmp_path: Path) -> None:
    """IH4: 0.5 (file) x 0.8 (perception) x 0.5 (melody) x 0.5 (note) = 0.1 of full scale."""
    loud = note([(0, 1.0), (1, 1.0)], [(0, 4.0), (1, 4.0)], gain=0.5)
    document = haps([[loud], [note([(0, 1.0), (1, 1.0)], [(0, 9.0), (1, 9.0)])]], gain=0.5,
                    texture_gain=0.8, melody_gains=[0.5, 1.0], muted=(1,))
    result = read(write(tmp_path, document), length_unit_mm=10.0)
    (component,) = result.card.textures[0].components
    assert component.amplitude == pytest.approx(0.35 * 0.1)
    assert component.frequency == pytest.approx(0.4)
    assert any("melody muted" in line for line in result.log)


def test_overlapping_notes_are_scaled_to_the_range(tmp_path: Path) -> None:
    """IH8: two full-scale notes at once peak at 2; every gain is halved, each grating 0.175."""
    a = note([(0, 1.0), (1, 1.0)], [(0, 2.0), (1, 2.0)])
    b = note([(0, 1.0), (1, 1.0)], [(0, 3.0), (1, 3.0)])
    result = read(write(tmp_path, haps([[a], [b]])), length_unit_mm=10.0)
    texture = result.card.textures[0]
    assert sorted(c.amplitude for c in texture.components) == pytest.approx([0.175, 0.175])
    assert texture.baseline == pytest.approx(1.0 - 0.35)
    assert any("peaks at 2" in line for line in result.log)
    assert result.stats["max_error_jnd"] < 1e-3


def test_an_ev_range_raises_friction_from_its_low_end(tmp_path: Path) -> None:
    """IH9: friction range 1.0-1.6 is EV: the silent texture rests at 1.0 and a note raises it."""
    path = write(tmp_path, haps([[note([(0, 1.0), (1, 1.0)], [(0, 2.0), (1, 2.0)])]]))
    result = read(path, length_unit_mm=10.0, friction_range=(1.0, 1.6))
    texture = result.card.textures[0]
    assert texture.channel == pb.CHANNEL_EV
    assert texture.baseline == pytest.approx(1.3)
    assert texture.components[0].amplitude == pytest.approx(0.3)
    assert result.stats["channel"] == "ev"


def test_the_default_length_unit_and_the_width_option(tmp_path: Path) -> None:
    """IH3, IH7: a 0.5-unit texture is 50 mm at the default 100 mm per unit; width_mm cuts it."""
    path = write(tmp_path, haps([[note([(0, 1.0), (0.5, 1.0)], [(0, 20.0), (0.5, 20.0)],
                                       length=0.5)]]))
    assert DEFAULT_LENGTH_UNIT_MM == 100.0
    result = read(path)
    assert result.card.surface.width_mm == pytest.approx(50.0)
    assert result.card.textures[0].components[0].frequency == pytest.approx(0.2)
    cut = read(path, width_mm=20.0, height_mm=8.0)
    assert cut.card.surface.width_mm == 20.0 and cut.card.surface.height_mm == 8.0
    assert any("cut at the card's width" in line for line in cut.log)


def test_a_chirp_and_pulses_match_an_independent_evaluation(tmp_path: Path) -> None:
    """IH13: a chirp (3 -> 9 cycles per unit) under a pulsed amplitude and a second note that
    starts half-way: the importer's reported error equals the one computed here (the source by
    a midpoint phase sum, the card by its equation), within 0.05 JND, and is small."""
    chirp = note([(0, 0.0), (0.1, 1.0), (0.4, 1.0), (0.5, 0.2), (1.0, 0.2)],
                 [(0, 3.0), (1, 9.0)])
    late = note([(0, 0.5), (0.5, 0.5)], [(0, 6.0), (0.5, 6.0)], start=0.5, length=0.5)
    document = haps([[chirp], [late]])
    result = read(write(tmp_path, document), length_unit_mm=40.0, taxtel_mm=0.5)
    x = np.arange(0.0, 40.0, 0.05)
    error = card_at(result.card, x) - oracle_friction(document, x, 40.0)
    rms = float(np.sqrt(np.mean(error**2))) / JND
    assert result.stats["rms_error_jnd"] == pytest.approx(rms, abs=0.05)
    assert result.stats["max_error_jnd"] == pytest.approx(float(np.abs(error).max()) / JND,
                                                          abs=0.1)
    assert rms < 0.5


def test_a_frequency_past_the_card_limit_names_the_field(tmp_path: Path) -> None:
    """IH11: 1000 cycles per unit at 10 mm per unit is 100 cycles/mm, over the card's 50."""
    path = write(tmp_path, haps([[note([(0, 1.0), (1, 1.0)], [(0, 1000.0), (1, 1000.0)])]]))
    with pytest.raises(AssetError) as caught:
        read(path, length_unit_mm=10.0)
    message = str(caught.value)
    assert str(path) in message
    assert "m_texture.m_melodies[0].m_notes[0].m_hapticEffect.m_frequencyModulation" in message
    assert "100 cycles/mm" in message and "length_unit_mm" in message


@pytest.mark.parametrize(("options", "fragment"), [
    ({"dpi": 160.0}, "dpi does not apply"),
    ({"max_error": 1.0}, "max_error does not apply"),
    ({"length_unit_mm": -1.0}, "length_unit_mm must be a finite number > 0"),
    ({"taxtel_mm": 0.01}, "taxtel_mm 0.01 is below"),
    ({"friction_range": (1.0, 0.3)}, "friction_range 1 0.3 must satisfy"),
    ({"width_mm": 20_000.0}, "width_mm 20000 is above"),
])
def test_bad_options_are_usage_errors_naming_them(options: dict[str, Any],
                                                  fragment: str) -> None:
    """IH14."""
    with pytest.raises(UsageError, match=fragment):
        HapsImporter().options(**options)


def test_recognises_haps_keys_only() -> None:
    """IH1: 2 for a JSON object with a .haps key in its head, else 0."""
    importer = HapsImporter()
    assert importer.recognises(b'\xef\xbb\xbf {\n "m_HDFlag": 0, "m_texture": {}}') == 2
    assert importer.recognises(b'{"m_version": "5", "m_vibration": {}}') == 2
    assert importer.recognises(b'{"version": 1, "perceptions": []}') == 0
    assert importer.recognises(b'["m_texture"]') == 0
    assert importer.recognises(b"\x89PNG\r\n\x1a\n") == 0


# --- the public samples (Interhaptics/Unity_CoreSDK, fetched: their EULA keeps them out) ------

def fetched(name: str) -> Path:
    return fetched_sample("Interhaptics/Unity_CoreSDK", f"Assets/HapticEffects/{name}",
                          "its EULA keeps it out of the repository")


def test_public_texture_sample_within_its_bounds() -> None:
    """Texture.haps (one note: 181.8 -> 180.4 cycles per unit under ten on/off pulses) at the
    default 100 mm per unit: a 101.7 mm card of 256 taxtels whose rendered friction is within
    0.55 JND rms and 7 JND at worst (at the pulses' edges, each inside a 0.4 mm taxtel) of the
    keyframes; this file's own evaluation agrees with the reported figures."""
    path = fetched("Texture.haps")
    result = read(path)
    card = result.card
    assert card.surface.width_mm == pytest.approx(101.7322)
    assert card.grid.cols == 256
    assert result.stats["rms_error_jnd"] < 0.55
    assert result.stats["max_error_jnd"] < 7.0
    document = json.loads(path.read_text(encoding="utf-8"))
    x = np.arange(0.0, 101.7322, 0.05)
    error = card_at(card, x) - oracle_friction(document, x, 100.0)
    assert float(np.sqrt(np.mean(error**2))) / JND == pytest.approx(
        result.stats["rms_error_jnd"], abs=0.05)
    assert any("m_vibration: 1 notes not imported" in line for line in result.log)


def test_public_texture_sample_at_one_centimetre_per_unit() -> None:
    """--length-unit-mm 10: 10.2 mm, a carrier of 18.1 cycles/mm in 0.05 mm taxtels."""
    result = read(fetched("Texture.haps"), length_unit_mm=10.0)
    assert result.card.surface.width_mm == pytest.approx(10.17322)
    assert result.card.textures[0].components[0].frequency == pytest.approx(18.18, abs=0.01)
    assert result.stats["rms_error_jnd"] < 1.5


@pytest.mark.parametrize(("name", "held"), [
    ("Stiffness.haps", "m_stiffness holds 1 notes"),
    ("Swipe_Freq10.haps", "m_vibration holds 1 notes"),
    ("Swipe_Amplitude10.haps", "m_vibration holds 1 notes"),
])
def test_public_samples_without_texture_are_refused_naming_m_texture(name: str,
                                                                     held: str) -> None:
    """IH2: the stiffness and vibration samples have an empty texture perception."""
    path = fetched(name)
    with pytest.raises(AssetError) as caught:
        read(path)
    assert str(caught.value) == (f"{path}: m_texture: no texture notes to import (0 melodies, "
                                 f"0 notes; {held}, not imported)")
