"""The image encoder (hcard_builtins.image): gratings recovered, palette merging, bad input."""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

import hcard
from hcard import limits
from hcard.errors import ImageError, UsageError
from hcard.v1 import card_pb2 as pb
from hcard.validate import errors_of, validate
from hcard_builtins import encoders
from hcard_builtins.image import (
    DEFAULT_FRICTION_RANGE,
    DEFAULT_MAX_PIXELS,
    EncodeOptions,
    ImageEncoder,
    encode_image,
    load_gray,
)
from hcard_builtins.image.palette import (
    Textures,
    build_palette,
    distances_from,
    keyed_distances_from,
)

PITCH_MM = 0.1  # 254 dpi
UV_LOW, UV_HIGH = DEFAULT_FRICTION_RANGE["uv"]

# Tolerances of the encoder's grating recovery, under the limits spec/conformance.md sets a
# renderer's components (section 3.3):
# - period within 2 %: a frequency error |1/0.98 - 1| = 2.04 %, under A3 (e_f <= 0.05);
# - amplitude within 5 % of itself: the amplitude is at most the mean friction, so at most
#   5 % of the mean, under A2 (e_A <= 0.08 of the mean);
# - orientation within 2 deg: the wave vector turned by 2 deg moves by 2 sin(1 deg) = 3.5 % of
#   its length, so the frequency felt along any swipe by at most 3.5 % of f * speed, again
#   under A3's 5 %.
PERIOD_TOL = 0.02
ORIENTATION_TOL_DEG = 2.0
AMPLITUDE_TOL = 0.05
PHASE_TOL = 0.1  # rad, 1/60 of a cycle


# ---------------------------------------------------------------------------------------------
# Helpers


def coordinates(
    width_px: int, height_px: int, pitch_x: float = PITCH_MM, pitch_y: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Surface coordinates (mm) of the pixel centres."""
    pitch_y = pitch_x if pitch_y is None else pitch_y
    y, x = np.mgrid[0:height_px, 0:width_px].astype(np.float64)
    return (x + 0.5) * pitch_x, (y + 0.5) * pitch_y


def wave(
    x: np.ndarray, y: np.ndarray, period_mm: float, orientation_deg: float, phase: float
) -> np.ndarray:
    t = math.radians(orientation_deg)
    return np.cos(2 * np.pi * (math.cos(t) * x + math.sin(t) * y) / period_mm + phase)


def save_gray(gray: np.ndarray, path: Path, *, bits: int = 8, dpi: float | None = None) -> Path:
    """Save gray levels in [0, 1] (0 = black) as a PNG."""
    gray = np.clip(gray, 0.0, 1.0)
    if bits == 16:
        image = Image.fromarray(np.round(gray * 65535).astype(np.uint16))
    else:
        image = Image.fromarray(np.round(gray * 255).astype(np.uint8))
    if dpi is None:
        image.save(path)
    else:
        image.save(path, dpi=(dpi, dpi))
    return path


def grating_gray(
    x: np.ndarray, y: np.ndarray, period: float, orientation: float, phase: float, depth=0.4
) -> np.ndarray:
    """Gray levels whose friction (black = high) is ``mean + A cos(2 pi k.x + phase)``."""
    return 0.5 - depth * wave(x, y, period, orientation, phase)


def friction_amplitude(depth: float, low: float = UV_LOW, high: float = UV_HIGH) -> float:
    return depth * (high - low)


def angle_difference(a: float, b: float) -> float:
    """|a - b| wrapped to [0, pi]."""
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def assert_component(
    component: pb.Component,
    period: float,
    orientation_deg: float,
    amplitude: float,
    phase: float | None = None,
) -> None:
    """``component`` is the grating (period, orientation, amplitude, phase) within the
    tolerances above. Orientations are compared as gratings: (th, phase) and (th + 180 deg, -phase)
    are the same one, which matters next to the canonical range's edge at +-90 deg."""
    assert component.domain == pb.DOMAIN_SPATIAL
    assert -math.pi / 2 < component.orientation <= math.pi / 2
    measured_deg, measured_phase = math.degrees(component.orientation), component.phase
    expected = math.radians(orientation_deg)
    if math.cos(component.orientation - expected) < 0:
        measured_deg, measured_phase = measured_deg + 180.0, -measured_phase
    assert 1.0 / component.frequency == pytest.approx(period, rel=PERIOD_TOL)
    difference = (measured_deg - orientation_deg + 180.0) % 360.0 - 180.0
    assert abs(difference) < ORIENTATION_TOL_DEG
    assert component.amplitude == pytest.approx(amplitude, rel=AMPLITUDE_TOL)
    if phase is not None:
        assert angle_difference(measured_phase, phase) < PHASE_TOL


def png_bytes(width: int, height: int, *, bit_depth: int = 8, colour_type: int = 0) -> bytes:
    """A PNG file written by hand: header declaring ``width`` x ``height``, one empty IDAT."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(b""))
        + chunk(b"IEND", b"")
    )


def render_card(card: pb.Card, width_px: int, height_px: int, pitch_x: float, pitch_y: float):
    """Position-locked friction of ``card`` at the pixel centres (independent reference)."""
    x, y = coordinates(width_px, height_px, pitch_x, pitch_y)
    grid = card.grid
    col = np.minimum((x // grid.taxtel_width_mm).astype(int), grid.cols - 1)
    row = np.minimum((y // grid.taxtel_height_mm).astype(int), grid.rows - 1)
    index = np.asarray(grid.texture_index)[row * grid.cols + col]
    out = np.zeros_like(x)
    for t, texture in enumerate(card.textures):
        value = np.full_like(x, texture.baseline)
        for c in texture.components:
            value += c.amplitude * np.cos(
                2
                * np.pi
                * c.frequency
                * (math.cos(c.orientation) * x + math.sin(c.orientation) * y)
                + c.phase
            )
        out = np.where(index == t, value, out)
    return out


# ---------------------------------------------------------------------------------------------
# Gratings of known period, orientation and phase


@pytest.mark.parametrize(
    ("period", "orientation", "phase"),
    [
        (1.0, 0.0, 0.0),
        (1.7, 30.0, 1.0),
        (2.3, -60.0, -2.0),
        (0.8, 90.0, 2.5),
        (1.3, 120.0, 0.5),  # the card writes it as -60 deg with the phase negated
        (0.45, 10.0, -1.2),
    ],
)
def test_grating_is_recovered(tmp_path: Path, period: float, orientation: float, phase: float):
    x, y = coordinates(300, 300)
    path = save_gray(grating_gray(x, y, period, orientation, phase), tmp_path / "g.png")
    result = encode_image(path, dpi=254)
    card = result.card
    assert (card.grid.cols, card.grid.rows) == (6, 6)
    assert card.surface.width_mm == pytest.approx(30.0)
    assert len(card.textures) == 1
    assert list(card.grid.texture_index) == [0] * 36
    texture = card.textures[0]
    assert len(texture.components) == 1
    assert texture.baseline == pytest.approx(UV_HIGH - 0.5 * (UV_HIGH - UV_LOW), abs=0.01)
    assert_component(texture.components[0], period, orientation, friction_amplitude(0.4), phase)
    assert result.stats["rms_error"] < 0.01


def test_rectangular_pixels_convert_each_axis(tmp_path: Path):
    """30 x 30 mm in 300 x 150 pixels: 0.1 mm wide, 0.2 mm tall pixels."""
    x, y = coordinates(300, 150, 0.1, 0.2)
    path = save_gray(grating_gray(x, y, 1.5, 45.0, 0.7), tmp_path / "r.png")
    card = encode_image(path, width_mm=30.0, height_mm=30.0).card
    assert (card.surface.width_mm, card.surface.height_mm) == (30.0, 30.0)
    assert len(card.textures) == 1
    assert_component(card.textures[0].components[0], 1.5, 45.0, friction_amplitude(0.4), 0.7)


def test_one_size_keeps_the_aspect_ratio(tmp_path: Path):
    x, y = coordinates(300, 200)
    path = save_gray(grating_gray(x, y, 1.2, 0.0, 0.0), tmp_path / "a.png")
    card = encode_image(path, width_mm=60.0).card  # 0.2 mm square pixels
    assert (card.surface.width_mm, card.surface.height_mm) == pytest.approx((60.0, 40.0))
    assert_component(card.textures[0].components[0], 2.4, 0.0, friction_amplitude(0.4))


def test_size_from_dpi_option_embedded_dpi_or_default(tmp_path: Path):
    x, y = coordinates(200, 100)
    gray = grating_gray(x, y, 1.0, 0.0, 0.0)
    plain = save_gray(gray, tmp_path / "plain.png")
    tagged = save_gray(gray, tmp_path / "tagged.png", dpi=127)  # 0.2 mm per pixel
    default = encode_image(plain)
    assert default.card.surface.width_mm == pytest.approx(20.0)
    assert "254 dpi" in default.stats["size_source"]
    embedded = encode_image(tagged)
    assert embedded.card.surface.width_mm == pytest.approx(40.0, rel=1e-3)
    assert "stored in the image" in embedded.stats["size_source"]
    assert_component(embedded.card.textures[0].components[0], 2.0, 0.0, friction_amplitude(0.4))
    option = encode_image(tagged, dpi=508)  # the option wins over the file
    assert option.card.surface.width_mm == pytest.approx(10.0)
    assert option.stats["pixel_pitch_mm"] == pytest.approx((0.05, 0.05))


def test_several_components_in_one_taxtel(tmp_path: Path):
    x, y = coordinates(400, 400)
    gray = (
        0.5
        - 0.25 * wave(x, y, 1.0, 20.0, 0.3)
        - 0.15 * wave(x, y, 0.6, -50.0, -1.0)
        - 0.08 * wave(x, y, 2.0, 80.0, 2.0)
    )
    path = save_gray(gray, tmp_path / "three.png")
    card = encode_image(path).card
    assert len(card.textures) == 1
    parts = sorted(card.textures[0].components, key=lambda c: -c.amplitude)
    assert len(parts) == 3
    assert_component(parts[0], 1.0, 20.0, friction_amplitude(0.25), 0.3)
    assert_component(parts[1], 0.6, -50.0, friction_amplitude(0.15), -1.0)
    assert_component(parts[2], 2.0, 80.0, friction_amplitude(0.08), 2.0)
    limited = encode_image(path, components=2).card
    assert [len(t.components) for t in limited.textures] == [2] * len(limited.textures)


def test_sixteen_bit_image_keeps_its_precision(tmp_path: Path):
    """A grating of 0.6 % of the gray range: under one 8-bit level, but 390 16-bit levels."""
    x, y = coordinates(300, 300)
    gray = grating_gray(x, y, 1.1, -20.0, 0.4, depth=0.003)
    path = save_gray(gray, tmp_path / "g16.png", bits=16)
    assert load_gray(path).pixels.dtype == np.uint16
    card = encode_image(path, min_amplitude=0.001).card
    assert len(card.textures) == 1
    assert_component(card.textures[0].components[0], 1.1, -20.0, friction_amplitude(0.003), 0.4)


# ---------------------------------------------------------------------------------------------
# Palette


def test_checkerboard_of_two_gratings_gives_two_textures_on_the_right_taxtels(tmp_path: Path):
    x, y = coordinates(400, 400)  # 8 x 8 taxtels of 5 mm; checker squares = taxtels
    first = ((x // 5.0) + (y // 5.0)) % 2 == 0
    gray = np.where(
        first, grating_gray(x, y, 1.0, 0.0, 0.5), grating_gray(x, y, 1.5, 60.0, -1.0, depth=0.3)
    )
    card = encode_image(save_gray(gray, tmp_path / "checker.png")).card
    assert len(card.textures) == 2
    index = np.asarray(card.grid.texture_index).reshape(8, 8)
    expected = np.add.outer(np.arange(8), np.arange(8)) % 2 == 0
    a = index[0, 0]
    b = 1 - a
    assert np.array_equal(index == a, expected)
    assert len(card.textures[a].components) == 1
    assert len(card.textures[b].components) == 1
    assert_component(card.textures[a].components[0], 1.0, 0.0, friction_amplitude(0.4), 0.5)
    assert_component(card.textures[b].components[0], 1.5, 60.0, friction_amplitude(0.3), -1.0)


def test_flat_image_gives_one_baseline_texture(tmp_path: Path):
    path = save_gray(np.full((120, 200), 0.25), tmp_path / "flat.png")
    result = encode_image(path)
    card = result.card
    assert len(card.textures) == 1
    assert len(card.textures[0].components) == 0
    gray = round(0.25 * 255) / 255
    assert card.textures[0].baseline == pytest.approx(UV_HIGH - gray * (UV_HIGH - UV_LOW), abs=1e-9)
    assert set(card.grid.texture_index) == {0}
    assert result.stats["components"] == 0
    assert result.stats["rms_error"] < 1e-6


def test_near_uniform_taxtels_become_baseline_only(tmp_path: Path):
    """Noise and a grating weaker than --min-amplitude leave only baselines; a strong grating
    in the right half keeps its component there."""
    rng = np.random.default_rng(3)
    x, y = coordinates(400, 200)
    gray = 0.6 + rng.normal(0.0, 0.002, x.shape) - 0.005 * wave(x, y, 1.0, 0.0, 0.0)
    gray = np.where(x >= 20.0, grating_gray(x, y, 1.25, 30.0, 0.0), gray)
    card = encode_image(save_gray(gray, tmp_path / "quiet.png")).card
    index = np.asarray(card.grid.texture_index).reshape(4, 8)
    left = {card.textures[i].baseline for i in index[:, :4].ravel()}
    assert all(len(card.textures[i].components) == 0 for i in index[:, :4].ravel())
    assert len(left) == 1
    assert all(len(card.textures[i].components) == 1 for i in index[:, 4:].ravel())


def test_grating_longer_than_a_taxtel_becomes_baseline_steps(tmp_path: Path):
    x, y = coordinates(600, 100)  # 60 x 10 mm, 12 x 2 taxtels
    gray = grating_gray(x, y, 40.0, 0.0, 0.0)
    card = encode_image(save_gray(gray, tmp_path / "long.png"), merge_tolerance=0.0).card
    friction = UV_HIGH - (UV_HIGH - UV_LOW) * np.round(np.clip(gray, 0, 1) * 255) / 255
    expected = friction.reshape(2, 50, 12, 50).mean(axis=(1, 3)).ravel()
    baselines = np.array([card.textures[i].baseline for i in card.grid.texture_index])
    assert all(len(t.components) == 0 for t in card.textures)
    assert baselines == pytest.approx(expected, abs=0.005)
    assert np.ptp(baselines) > 0.4  # the long grating is there, as steps


def test_max_textures_merges_the_closest_textures(tmp_path: Path):
    x, y = coordinates(400, 400)
    quadrant = (x >= 20.0).astype(int) + 2 * (y >= 20.0).astype(int)
    gray = np.select(
        [quadrant == 0, quadrant == 1, quadrant == 2],
        [
            grating_gray(x, y, 1.0, 0.0, 0.0),
            grating_gray(x, y, 1.0, 0.0, 0.0, depth=0.36),  # close to quadrant 0
            grating_gray(x, y, 2.0, 90.0, 0.0),
        ],
        np.full_like(x, 0.9),
    )
    path = save_gray(gray, tmp_path / "four.png")
    assert len(encode_image(path, merge_tolerance=0.01).card.textures) == 4
    result = encode_image(path, max_textures=3, merge_tolerance=0.01)
    card = result.card
    assert len(card.textures) == 3
    assert result.stats["distinct_textures"] == 4
    index = np.asarray(card.grid.texture_index).reshape(8, 8)
    assert index[0, 0] == index[0, 7]  # the two close quadrants now share a texture
    assert len({index[0, 0], index[7, 0], index[7, 7]}) == 3
    merged = card.textures[index[0, 0]].components[0]
    assert merged.amplitude == pytest.approx(friction_amplitude(0.38), rel=AMPLITUDE_TOL)
    assert not errors_of(validate(card))


def test_default_merge_tolerance_joins_textures_within_half_a_jnd(tmp_path: Path):
    x, _ = coordinates(400, 200)
    gray = np.where(x < 20.0, 0.50, 0.52)  # 0.014 relative friction apart
    card = encode_image(save_gray(gray, tmp_path / "two.png")).card
    assert len(card.textures) == 1
    apart = encode_image(save_gray(np.where(x < 20.0, 0.3, 0.5), tmp_path / "far.png")).card
    assert len(apart.textures) == 2


def test_texture_distance_is_the_rms_friction_difference():
    def one(baseline: float, parts: list[tuple[float, float, complex]]) -> Textures:
        k = np.array([[[kx, ky] for kx, ky, _ in parts]]).reshape(1, len(parts), 2)
        coef = np.array([[c for _, _, c in parts]], dtype=complex).reshape(1, len(parts))
        return Textures(np.array([baseline]), k, coef, np.ones((1, len(parts)), dtype=bool))

    a = one(0.5, [(1.0, 0.0, 0.2)])
    same_but_mirrored = one(0.5, [(-1.0, 0.0, 0.2)])  # (k, C) and (-k, conj C): same grating
    shifted = one(0.5, [(1.0, 0.0, 0.2 * np.exp(1j * np.pi))])
    other = one(0.6, [(2.0, 0.0, 0.1)])
    # Field differences by brute force on a fine grid, 10 mm (a whole number of periods).
    x = (np.arange(10000) + 0.5) / 1000.0

    def field(t: Textures) -> np.ndarray:
        return t.baseline[0] + sum(
            (c * np.exp(2j * np.pi * k[0] * x)).real for k, c in zip(t.k[0], t.coef[0], strict=True)
        )

    for b in (a, same_but_mirrored, shifted, other):
        brute = np.sqrt(np.mean((field(a) - field(b)) ** 2))
        assert distances_from(a, 0, b, bin_width=0.2)[0] == pytest.approx(brute, abs=1e-6)
    assert distances_from(a, 0, same_but_mirrored, bin_width=0.2)[0] == pytest.approx(0.0, abs=1e-9)


def test_keyed_distance_is_the_rms_difference_over_a_taxtel_for_harmonics_a_bin_apart():
    """Harmonics of a 5 mm taxtel lie 0.2 cycles/mm apart and are orthogonal over it; a texture
    may also hold a grating a fraction of a bin from one of them. The keyed distance is the RMS
    difference over the taxtel (a whole number of periods of each harmonic), and 0 from a
    texture to itself."""
    rng = np.random.default_rng(3)

    def texture(baseline: float, parts: list[tuple[float, float, complex]]) -> Textures:
        k = np.array([[(kx, ky) for kx, ky, _ in parts]], dtype=float)
        coef = np.array([[c for _, _, c in parts]], dtype=complex)
        return Textures(np.array([baseline]), k, coef, np.ones((1, len(parts)), dtype=bool))

    def amplitude() -> complex:
        return complex(*(0.05 * rng.standard_normal(2)))

    a = texture(0.6, [(0.2, 0.0, amplitude()), (0.4, 0.0, amplitude()), (0.2, 0.2, amplitude()),
                      (0.0, 0.4, amplitude())])
    b = texture(0.55, [(0.2, 0.0, amplitude()), (0.6, 0.0, amplitude()), (0.2, 0.2, amplitude())])
    y, x = (np.mgrid[0:500, 0:500] + 0.5) / 100.0  # one 5 mm taxtel, 10 um pixels

    def field(t: Textures) -> np.ndarray:
        return t.baseline[0] + sum((c * np.exp(2j * np.pi * (k[0] * x + k[1] * y))).real
                                   for k, c in zip(t.k[0], t.coef[0], strict=True))

    brute = float(np.sqrt(np.mean((field(a) - field(b)) ** 2)))
    assert keyed_distances_from(a, 0, b, bin_width=0.2)[0] == pytest.approx(brute, rel=1e-6)
    assert keyed_distances_from(a, 0, a, bin_width=0.2)[0] == pytest.approx(0.0, abs=1e-9)
    # two components of one texture 0.004 cycles/mm apart (aligned into one) and the mirror
    # form of a grating are the same field: distance 0 to their sum
    close = texture(0.6, [(0.2, 0.0, 0.03), (0.2 + 0.004, 0.0, 0.02j), (-0.4, 0.0, 0.01)])
    merged = texture(0.6, [(0.202, 0.0, 0.03 + 0.02j), (0.4, 0.0, 0.01)])
    assert keyed_distances_from(close, 0, merged, bin_width=0.2)[0] == pytest.approx(0.0,
                                                                                      abs=2e-3)


def test_ward_merging_spares_large_clusters():
    """Leaders: two clusters of 10 taxtels 0.05 apart, two of 1 taxtel 0.06 apart, one far.
    Closest-pair merging joins the two large clusters (adding 10 * 0.05^2 / 2 of squared error
    per side); Ward's criterion joins the two small ones (1 * 0.06^2 / 2)."""
    from hcard_builtins.image.palette import _agglomerate_ward

    distance = np.full((5, 5), 1.0)
    distance[0, 1] = distance[1, 0] = 0.05
    distance[2, 3] = distance[3, 2] = 0.06
    np.fill_diagonal(distance, np.inf)
    weight = np.array([10.0, 10.0, 1.0, 1.0, 5.0])
    kept = _agglomerate_ward(distance.copy(), weight.copy(), 4)
    assert kept == [0, 1, 2, 4]


def test_per_taxtel_tolerance_keeps_a_tight_taxtel_apart():
    """Four flat taxtels 0.03 apart: with one tolerance of 0.04 they share a texture; a taxtel
    whose tolerance is 0.01 keeps its own."""
    textures = Textures(np.array([0.50, 0.53, 0.50, 0.53]), np.zeros((4, 0, 2)),
                        np.zeros((4, 0), complex), np.zeros((4, 0), bool))
    centres = np.zeros((4, 2))
    common = build_palette(textures, centres, bin_width=0.2, tolerance=0.04, max_textures=8,
                           min_amplitude=0.01)
    assert common.textures.baseline.size == 1
    tight = build_palette(textures, centres, bin_width=0.2,
                          tolerance=np.array([0.04, 0.01, 0.04, 0.04]), max_textures=8,
                          min_amplitude=0.01)
    assert tight.textures.baseline.size == 2
    assert tight.textures.baseline[tight.index[1]] == pytest.approx(0.53)


# ---------------------------------------------------------------------------------------------
# Reconstruction, channels, metadata, tiling


def test_reconstruction_error_matches_an_independent_render(tmp_path: Path):
    x, y = coordinates(370, 230)  # overhanging last column and row
    gray = np.where(x + y < 25.0, grating_gray(x, y, 1.3, 25.0, 0.2), 0.8)
    gray = gray + 0.1 * (x > 30.0)
    path = save_gray(gray, tmp_path / "mix.png")
    result = encode_image(path)
    stored = np.round(np.clip(gray, 0, 1) * 255) / 255
    friction = UV_HIGH - (UV_HIGH - UV_LOW) * stored
    error = render_card(result.card, 370, 230, PITCH_MM, PITCH_MM) - friction
    rms = float(np.sqrt(np.mean(error**2)))
    assert result.stats["rms_error"] == pytest.approx(rms, rel=1e-3, abs=1e-6)
    assert result.stats["max_error"] == pytest.approx(float(np.abs(error).max()), rel=1e-3)
    assert result.stats["rms_error_jnd"] == pytest.approx(
        rms / limits.RELATIVE_FRICTION_JND, rel=1e-3
    )
    assert rms > 0.001  # the sharp edges cannot be represented exactly: a real error is measured
    jnd = limits.RELATIVE_FRICTION_JND
    p95 = float(np.percentile(np.abs(error), 95, method="inverted_cdf"))  # nearest rank
    assert result.stats["p95_error"] == pytest.approx(p95, rel=1e-4)
    assert 0.1 < p95 < result.stats["max_error"]  # the percentile sits inside the distribution
    assert result.stats["p95_error_jnd"] == pytest.approx(result.stats["p95_error"] / jnd)
    assert result.stats["max_error_jnd"] == pytest.approx(result.stats["max_error"] / jnd)
    # per taxtel: each 5 mm taxtel owns the pixels whose centres lie in it (50 x 50 at 0.1 mm;
    # the overhanging last column and row own 20 and 30)
    grid = result.card.grid
    taxtel_rms = np.zeros((grid.rows, grid.cols))
    taxtel_max = np.zeros((grid.rows, grid.cols))
    for row in range(grid.rows):
        for col in range(grid.cols):
            block = error[row * 50:(row + 1) * 50, col * 50:(col + 1) * 50]
            taxtel_rms[row, col] = np.sqrt(np.mean(block**2))
            taxtel_max[row, col] = np.abs(block).max()
    np.testing.assert_allclose(result.maps["error_rms"], taxtel_rms, rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(result.maps["error_max"], taxtel_max, rtol=1e-3, atol=1e-6)
    # 95th percentile per taxtel, nearest rank (numpy's inverted CDF), on the owned pixels only
    taxtel_p95 = np.array([[np.percentile(np.abs(error[r * 50:(r + 1) * 50, c * 50:(c + 1) * 50]),
                                          95, method="inverted_cdf")
                            for c in range(grid.cols)] for r in range(grid.rows)])
    np.testing.assert_allclose(result.maps["error_p95"], taxtel_p95, rtol=1e-3, atol=1e-6)
    worst = np.unravel_index(np.argmax(taxtel_rms), taxtel_rms.shape)
    assert (result.stats["worst_taxtel"]["row"], result.stats["worst_taxtel"]["col"]) == worst
    assert result.stats["taxtels_over_jnd"] == int(np.count_nonzero(taxtel_rms > jnd))


def test_tiles_that_do_not_fit_whole_pixels(tmp_path: Path):
    x, y = coordinates(300, 300)
    path = save_gray(grating_gray(x, y, 0.9, 15.0, 1.0), tmp_path / "g.png")
    result = encode_image(path, taxtel_mm=3.33)  # 33.3 pixels per taxtel
    card = result.card
    assert (card.grid.cols, card.grid.rows) == (10, 10)
    assert not errors_of(validate(card))
    assert_component(card.textures[0].components[0], 0.9, 15.0, friction_amplitude(0.4), 1.0)
    stored = np.round(np.clip(grating_gray(x, y, 0.9, 15.0, 1.0), 0, 1) * 255) / 255
    error = render_card(card, 300, 300, PITCH_MM, PITCH_MM) - (UV_HIGH - 0.7 * stored)
    assert result.stats["rms_error"] == pytest.approx(np.sqrt(np.mean(error**2)), rel=1e-3)
    # a pixel belongs to the taxtel holding its centre: taxtels own 33 or 34 pixels a side, and
    # the tenth column and row (29.97-30 mm) none: their figures are 0
    owner = ((np.arange(300) + 0.5) * PITCH_MM // 3.33).astype(int)
    p95 = np.zeros((10, 10))
    for r in range(9):
        for c in range(9):
            block = np.abs(error[np.ix_(owner == r, owner == c)])
            p95[r, c] = np.percentile(block, 95, method="inverted_cdf")
    np.testing.assert_allclose(result.maps["error_p95"], p95, rtol=1e-3, atol=1e-6)


@pytest.mark.parametrize("taxtel_mm", [4.5, 12.5])
def test_overhanging_taxtels_are_analysed_on_real_pixels(tmp_path: Path, taxtel_mm: float):
    """27 x 27 mm does not divide into 4.5 or 12.5 mm taxtels: the last column and row overhang
    the surface. Their tiles end at the image edge instead of mirroring the grating, so the whole
    surface is one texture (45-pixel tiles are also odd-sized)."""
    x, y = coordinates(270, 270)
    path = save_gray(grating_gray(x, y, 1.3, 33.0, 0.2), tmp_path / "g.png")
    result = encode_image(path, taxtel_mm=taxtel_mm)
    card = result.card
    assert card.grid.cols == math.ceil(27.0 / taxtel_mm)
    assert len(card.textures) == 1
    assert_component(card.textures[0].components[0], 1.3, 33.0, friction_amplitude(0.4), 0.2)
    assert result.stats["rms_error"] < 0.01


def test_taxtels_of_few_pixels_or_no_components_keep_baselines_only(tmp_path: Path):
    x, y = coordinates(200, 200)
    path = save_gray(grating_gray(x, y, 4.0, 0.0, 0.0), tmp_path / "g.png")
    # 3-pixel tiles are too small to analyse; --components 0 asks for baselines only.
    for options in ({"taxtel_mm": 0.3}, {"taxtel_mm": 1.0, "components": 0}):
        result = encode_image(path, merge_tolerance=0.0, max_textures=256, **options)
        card = result.card
        assert result.stats["components"] == 0
        assert not errors_of(validate(card))
        baselines = np.array([card.textures[i].baseline for i in card.grid.texture_index])
        assert np.ptp(baselines) > 0.3  # the 4 mm grating survives as baseline steps


@pytest.mark.parametrize("channel", ["uv", "ev", "bipolar"])
def test_channel_and_default_range_map_black_to_high_friction(tmp_path: Path, channel: str):
    gray = np.zeros((100, 200))
    gray[:, 100:] = 1.0  # black left half, white right half
    card = encode_image(save_gray(gray, tmp_path / "bw.png"), channel=channel).card
    low, high = DEFAULT_FRICTION_RANGE[channel]
    index = np.asarray(card.grid.texture_index).reshape(2, 4)
    assert card.textures[index[0, 0]].baseline == pytest.approx(high)
    assert card.textures[index[0, 3]].baseline == pytest.approx(low)
    expected = {"uv": pb.CHANNEL_UV, "ev": pb.CHANNEL_EV, "bipolar": pb.CHANNEL_BIPOLAR}
    assert {t.channel for t in card.textures} == {expected[channel]}
    assert not errors_of(validate(card))


def test_friction_range_and_locking_options(tmp_path: Path):
    x, y = coordinates(200, 200)
    path = save_gray(grating_gray(x, y, 1.0, 0.0, 0.0), tmp_path / "g.png")
    card = encode_image(path, channel="bipolar", friction_range=(0.6, 1.4), locking="position").card
    texture = card.textures[0]
    assert texture.locking == pb.LOCKING_POSITION
    assert texture.baseline == pytest.approx(1.0, abs=0.01)
    assert texture.components[0].amplitude == pytest.approx(0.4 * 0.8, rel=AMPLITUDE_TOL)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"friction_range": (0.5, 1.2)}, "UV can only lower"),
        ({"channel": "ev", "friction_range": (0.9, 1.5)}, "EV can only raise"),
        ({"friction_range": (1.0, 0.5), "channel": "bipolar"}, "low < high"),
        ({"dpi": 300, "width_mm": 20.0}, "not both"),
        ({"taxtel_mm": 0.0}, "taxtel_mm"),
        ({"components": 17}, "components"),
        ({"max_textures": 0}, "max_textures"),
        ({"min_amplitude": -0.1}, "min_amplitude"),
        ({"channel": "pneumatic"}, "channel"),
        ({"locking": "sometimes"}, "locking"),
        ({"width_mm": float("nan")}, "width_mm"),
        ({"colour": "blue"}, "unknown image encoder option"),
    ],
)
def test_bad_options_raise_value_error(tmp_path: Path, options: dict, message: str):
    path = save_gray(np.full((10, 10), 0.5), tmp_path / "small.png")
    with pytest.raises(ValueError, match=message):
        encode_image(path, **options)


def test_colour_alpha_and_metadata(tmp_path: Path):
    red = tmp_path / "red.png"
    Image.new("RGB", (60, 60), (255, 0, 0)).save(red)
    card = encode_image(red, title="Red", author="Ada", licence="CC0-1.0").card
    luma = 76 / 255  # ITU-R 601: 0.299 * 255 = 76.2 -> 76
    assert card.textures[0].baseline == pytest.approx(UV_HIGH - 0.7 * luma, abs=1e-9)
    assert (card.metadata.title, card.metadata.author, card.metadata.licence) == (
        "Red",
        "Ada",
        "CC0-1.0",
    )
    assert card.metadata.generator == f"hcard {hcard.__version__} image encoder"
    clear = tmp_path / "clear.png"
    Image.new("RGBA", (60, 60), (0, 0, 0, 0)).save(clear)  # transparent black: over white
    see_through = encode_image(clear).card
    assert see_through.textures[0].baseline == pytest.approx(UV_LOW)
    assert see_through.metadata.title == "clear"


def test_exif_orientation_is_applied(tmp_path: Path):
    """A camera JPEG stored 300 x 100 but tagged "rotate 90 degrees" is a 10 x 30 mm surface."""
    path = tmp_path / "portrait.jpg"
    exif = Image.Exif()
    exif[0x0112] = 6
    Image.new("L", (300, 100), 200).save(path, exif=exif, dpi=(254, 254))
    card = encode_image(path).card
    assert (card.surface.width_mm, card.surface.height_mm) == pytest.approx((10.0, 30.0))


def test_card_is_valid_and_round_trips(tmp_path: Path):
    x, y = coordinates(250, 180)
    gray = np.where(y < 9.0, grating_gray(x, y, 0.7, -45.0, 0.0), 0.3)
    card = encode_image(save_gray(gray, tmp_path / "g.png")).card
    assert not errors_of(validate(card))
    for name in ("out.hcard", "out.json"):
        hcard.save(card, tmp_path / name)
        assert hcard.load(tmp_path / name) == card


def test_plugin_hook_returns_the_image_encoder(tmp_path: Path):
    (encoder,) = encoders.hcard_encoders()
    assert isinstance(encoder.load(), ImageEncoder)  # made on first use
    assert encoder.name == "image" and encoder.kind == "encoder" and encoder.description
    path = save_gray(np.full((50, 50), 0.0), tmp_path / "black.png")
    result = encoder.encode(path, taxtel_mm=2.5)
    assert result.card.grid.cols == 2
    assert result.card.textures[0].baseline == pytest.approx(UV_HIGH)


def test_plugin_options_are_checked_with_the_defaults_filled_in(tmp_path: Path):
    """The encoder contract's options(): the checked EncodeOptions fields, which encode() takes
    back (the card is that of encode_image with the same options); bad ones are usage errors
    naming the field, as ``hcard encode`` reports them."""
    (encoder,) = encoders.hcard_encoders()
    plain = encoder.options(taxtel_mm=2.5)
    # defaults of EncodeOptions (8 components, 64 textures, the UV range 0.3-1.0) filled in
    assert (plain["taxtel_mm"], plain["components"], plain["max_textures"]) == (2.5, 8, 64)
    assert plain["friction_range"] == (0.3, 1.0) and plain["channel"] == "uv"
    assert set(plain) == {f.name for f in fields(EncodeOptions)}
    targeted = encoder.options(max_error=1.0)
    assert (targeted["components"], targeted["max_textures"]) == (16, 256)
    path = save_gray(np.full((50, 50), 0.0), tmp_path / "black.png")
    assert encoder.encode(path, **plain).card == encode_image(path, taxtel_mm=2.5).card
    with pytest.raises(UsageError, match="taxtel_mm must be between"):
        encoder.options(taxtel_mm=0.0)
    with pytest.raises(UsageError, match="give either a DPI or a width/height"):
        encoder.options(dpi=300.0, width_mm=20.0)
    with pytest.raises(UsageError, match=r"unknown image encoder option\(s\): colour"):
        encoder.options(colour="red")


def test_options_object_defaults_follow_the_issue():
    opts = EncodeOptions().checked()
    assert (opts.taxtel_mm, opts.components, opts.max_textures) == (5.0, 8, 64)
    assert opts.max_error is None
    # with an error target, the caps are the format's own unless given
    targeted = EncodeOptions(max_error=1.0).checked()
    assert (targeted.components, targeted.max_textures) == (16, 256)
    assert EncodeOptions(max_error=1.0, components=4).checked().components == 4
    assert opts.min_amplitude == 0.01
    assert opts.merge_tolerance == pytest.approx(limits.RELATIVE_FRICTION_JND / 2)
    assert opts.friction_range == DEFAULT_FRICTION_RANGE["uv"] == (0.3, 1.0)
    assert DEFAULT_FRICTION_RANGE["ev"] == (1.0, 1.6)
    assert DEFAULT_FRICTION_RANGE["bipolar"] == (0.5, 1.5)
    assert DEFAULT_MAX_PIXELS == 64_000_000


# ---------------------------------------------------------------------------------------------
# Bad input: every class raises ImageError


def test_not_an_image(tmp_path: Path):
    path = tmp_path / "notes.png"
    path.write_text("these are not pixels\n")
    with pytest.raises(ImageError, match="not an image"):
        encode_image(path)


def test_empty_file(tmp_path: Path):
    path = tmp_path / "empty.png"
    path.write_bytes(b"")
    with pytest.raises(ImageError, match="empty file"):
        encode_image(path)


@pytest.mark.parametrize(("width", "height"), [(0, 0), (0, 10), (10, 0)])
def test_image_of_zero_width_or_height(tmp_path: Path, width: int, height: int):
    path = tmp_path / "zero.png"
    path.write_bytes(png_bytes(width, height))
    with pytest.raises(ImageError, match=rf"empty image \({width} x {height} pixels\)"):
        encode_image(path)


def test_decompression_bomb_is_refused_from_its_header(tmp_path: Path):
    path = tmp_path / "bomb.png"
    path.write_bytes(png_bytes(100_000, 100_000))  # 10 gigapixels declared, 60 bytes on disk
    with pytest.raises(ImageError, match="10000000000 pixels exceed the limit of 64000000"):
        encode_image(path)
    # Raising the limit above the declared size lets the pixel count through; the surface and
    # grid are then checked from the header too (5 mm taxtels: a 2000 x 2000 grid), and with
    # 40 mm taxtels (a 250 x 250 grid) the (absent) pixel data fails as corrupt, without any
    # large allocation.
    with pytest.raises(ImageError, match="needs a 2000 x 2000 grid, over the card limits"):
        encode_image(path, max_pixels=20_000_000_000)
    with pytest.raises(ImageError, match="corrupt or truncated"):
        encode_image(path, max_pixels=20_000_000_000, taxtel_mm=40.0)


def test_pixel_limit_is_an_option(tmp_path: Path):
    path = save_gray(np.full((100, 100), 0.5), tmp_path / "ok.png")
    with pytest.raises(ImageError, match="10000 pixels exceed the limit of 5000"):
        encode_image(path, max_pixels=5000)
    assert len(encode_image(path, max_pixels=10_000).card.textures) == 1


def test_bomb_in_another_format_is_refused_before_decoding(tmp_path: Path):
    """A BMP header declaring 50000 x 50000 pixels (not PNG: checked through Pillow)."""
    path = tmp_path / "bomb.bmp"
    info = struct.pack("<IiiHHIIiiII", 40, 50_000, 50_000, 1, 8, 0, 0, 2835, 2835, 0, 0)
    header = b"BM" + struct.pack("<IHHI", 14 + 40 + 1024, 0, 0, 14 + 40 + 1024)
    path.write_bytes(header + info + bytes(1024))
    with pytest.raises(ImageError, match="pixel"):
        encode_image(path)


def test_truncated_pixel_data(tmp_path: Path):
    good = save_gray(np.linspace(0, 1, 200 * 200).reshape(200, 200), tmp_path / "good.png")
    data = good.read_bytes()
    cut = tmp_path / "cut.png"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageError, match="corrupt or truncated"):
        encode_image(cut)


def test_missing_file_and_directory(tmp_path: Path):
    with pytest.raises(ImageError, match="no such file"):
        encode_image(tmp_path / "nothing.png")
    with pytest.raises(ImageError, match="is a directory"):
        encode_image(tmp_path)


def test_surface_or_grid_over_the_card_limits(tmp_path: Path):
    path = save_gray(np.full((400, 400), 0.5), tmp_path / "g.png")
    with pytest.raises(ImageError, match="over the limit of 10000 mm"):
        encode_image(path, dpi=1.0)  # 400 inches
    with pytest.raises(ImageError, match="over the card limits"):
        encode_image(path, taxtel_mm=0.1)  # 400 x 400 taxtels


@pytest.mark.parametrize(("seed", "noise"), [(0, 0.02), (1, 0.1), (2, 0.3)])
def test_error_percentile_and_taxtel_maps_on_noisy_images(tmp_path: Path, seed: int, noise: float):
    """Gratings of random period and orientation under gray noise: the 95th percentile and the
    per-taxtel RMS and maximum match an independent render of the card, whatever the noise."""
    rng = np.random.default_rng(seed)
    x, y = coordinates(300, 200)
    gray = grating_gray(x, y, float(rng.uniform(0.5, 2.0)), float(rng.uniform(0, 90)), 0.3)
    gray = np.clip(gray + noise * rng.standard_normal(gray.shape), 0.0, 1.0)
    result = encode_image(save_gray(gray, tmp_path / "noisy.png"))
    stored = np.round(gray * 255) / 255
    error = render_card(result.card, 300, 200, PITCH_MM, PITCH_MM) - (
        UV_HIGH - (UV_HIGH - UV_LOW) * stored)
    assert result.stats["p95_error"] == pytest.approx(
        float(np.percentile(np.abs(error), 95, method="inverted_cdf")), rel=1e-4)
    blocks = error.reshape(4, 50, 6, 50).transpose(0, 2, 1, 3)
    np.testing.assert_allclose(result.maps["error_rms"],
                               np.sqrt(np.mean(blocks**2, axis=(2, 3))), rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(result.maps["error_max"], np.abs(blocks).max(axis=(2, 3)),
                               rtol=1e-3, atol=1e-6)
    p95 = np.percentile(np.abs(blocks).reshape(4, 6, -1), 95, axis=2, method="inverted_cdf")
    np.testing.assert_allclose(result.maps["error_p95"], p95, rtol=1e-3, atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Error target (--max-error): met where the format allows, the others listed with their reason


def shapes_gray(seed: int, noise: float, width: int = 300, height: int = 200) -> np.ndarray:
    """Gray levels in [0, 1]: a light background, a grating patch and dark bars and discs at
    random positions (edges inside taxtels), plus gaussian gray noise of std ``noise``."""
    rng = np.random.default_rng(seed)
    x, y = coordinates(width, height)
    gray = np.full(x.shape, 0.85)
    patch = (x > 2.0) & (x < 14.0) & (y > 3.0) & (y < 16.0)
    gray = np.where(patch, grating_gray(x, y, float(rng.uniform(0.7, 2.0)),
                                        float(rng.uniform(0, 180)), 0.0, depth=0.3), gray)
    for _ in range(3):
        x0, y0 = rng.uniform(15.0, 25.0), rng.uniform(2.0, 16.0)
        gray = np.where((np.abs(x - x0) < rng.uniform(0.5, 2.5)) & (y > y0 - 4) & (y < y0 + 4),
                        rng.uniform(0.05, 0.4), gray)
    cx, cy, r = rng.uniform(4.0, 26.0), rng.uniform(4.0, 16.0), rng.uniform(1.5, 3.5)
    gray = np.where((x - cx) ** 2 + (y - cy) ** 2 < r * r, 0.2, gray)
    return np.clip(gray + noise * rng.standard_normal(gray.shape), 0.0, 1.0)


def taxtel_p95(error: np.ndarray, taxtel_px: int = 50) -> np.ndarray:
    """95th percentile (nearest rank) of |error| over each whole taxtel of ``taxtel_px``."""
    rows, cols = error.shape[0] // taxtel_px, error.shape[1] // taxtel_px
    blocks = np.abs(error).reshape(rows, taxtel_px, cols, taxtel_px).transpose(0, 2, 1, 3)
    return np.percentile(blocks.reshape(rows, cols, -1), 95, axis=2, method="inverted_cdf")


@pytest.mark.parametrize(("seed", "noise"), [(0, 0.0), (1, 0.01), (2, 0.03), (3, 0.3)])
def test_max_error_is_met_or_each_taxtel_over_it_is_listed(tmp_path: Path, seed: int,
                                                           noise: float):
    """Against an independent render of the card: every taxtel's 95th percentile error is
    within the target, or the taxtel is listed with that percentile and a reason; without
    noise every taxtel whose own 16 gratings suffice meets it, and heavy noise (0.3 gray, 2.6
    JND) is detail no texture carries."""
    gray = shapes_gray(seed, noise)
    path = save_gray(gray, tmp_path / "shapes.png")
    jnd = limits.RELATIVE_FRICTION_JND
    before = encode_image(path)
    result = encode_image(path, max_error=1.0)
    card = result.card
    assert not errors_of(validate(card))
    assert max(len(t.components) for t in card.textures) <= limits.MAX_COMPONENTS_PER_TEXTURE
    stored = np.round(gray * 255) / 255
    error = render_card(card, 300, 200, PITCH_MM, PITCH_MM) - (
        UV_HIGH - (UV_HIGH - UV_LOW) * stored)
    p95 = taxtel_p95(error)
    np.testing.assert_allclose(result.maps["error_p95"], p95, rtol=1e-3, atol=1e-6)
    target = result.stats["target"]
    listed = {(t["row"], t["col"]): t for t in target["over_target"]}
    assert set(listed) == {(int(r), int(c)) for r, c in zip(*np.nonzero(p95 > jnd), strict=True)}
    for (row, col), entry in listed.items():
        assert entry["p95_jnd"] == pytest.approx(p95[row, col] / jnd, rel=1e-3)
        assert entry["reason"] in ("detail", "components", "palette")
    assert target["taxtels_over"] == len(listed)
    assert sum(target["reasons"].values()) == len(listed)
    # the image's own 95th percentile is bounded by the per-taxtel target where it is met
    assert result.stats["p95_error"] <= max(jnd, float(p95.max())) + 2e-4
    if noise <= 0.03:
        before_p95 = taxtel_p95(render_card(before.card, 300, 200, PITCH_MM, PITCH_MM)
                                - (UV_HIGH - (UV_HIGH - UV_LOW) * stored))
        assert result.stats["rms_error"] < 0.6 * before.stats["rms_error"]
        assert p95.mean() < 0.6 * before_p95.mean()
    else:
        assert target["reasons"]["detail"] == 24  # every taxtel: noise of 2.6 JND


def bars_gray(blur_mm: float) -> np.ndarray:
    """Six dark vertical bars 1.2 mm wide at different offsets in six 5 mm taxtels, two rows
    of taxtels; edges blurred by a gaussian of ``blur_mm`` (0: sharp)."""
    x, _ = coordinates(300, 100)
    gray = np.full(x.shape, 0.9)
    for col, offset in enumerate((0.7, 1.3, 2.1, 2.9, 3.6, 4.2)):
        centre = 5.0 * col + offset
        if blur_mm == 0:
            bar = (np.abs(x - centre) < 0.6).astype(float)
        else:
            edge = np.vectorize(math.erf)
            scale = blur_mm * math.sqrt(2.0)
            bar = 0.5 * (edge((x - centre + 0.6) / scale) - edge((x - centre - 0.6) / scale))
        gray -= 0.8 * bar
    return gray


def test_sharp_edges_are_detail_a_taxtel_cannot_carry(tmp_path: Path):
    """A bar with sharp edges (7 JND steps from one pixel to the next) leaves its Fourier
    ringing over more than 5 % of a 5 mm taxtel's pixels with 16 harmonics; an antialiased one
    (edges blurred by 0.1 mm, as a rendered picture has them) does not."""
    sharp = encode_image(save_gray(bars_gray(0.0), tmp_path / "sharp.png"), max_error=1.0)
    assert sharp.stats["target"]["reasons"]["detail"] >= 2
    assert sharp.stats["target"]["reasons"]["palette"] == 0
    smooth = encode_image(save_gray(bars_gray(0.1), tmp_path / "smooth.png"), max_error=1.0)
    assert smooth.stats["target"]["taxtels_over"] == 0


def test_component_cap_and_palette_are_named_as_reasons(tmp_path: Path):
    """Antialiased bars at different offsets in six taxtels: each needs its own texture of
    several harmonics. With 3 components a texture the cap is the reason (16 would do); with
    room for two textures the palette is."""
    path = save_gray(bars_gray(0.1), tmp_path / "bars.png")
    met = encode_image(path, max_error=1.0)
    assert met.stats["target"]["taxtels_over"] == 0
    assert len(met.card.textures) == 6  # one per bar, each column's two taxtels alike
    capped = encode_image(path, max_error=1.0, components=3).stats["target"]
    assert capped["reasons"] == {"detail": 0, "components": 12, "palette": 0}  # all bars
    full = encode_image(path, max_error=1.0, max_textures=2).stats["target"]
    assert full["palette_full"]
    assert full["reasons"]["palette"] >= 5 and full["reasons"]["components"] == 0


def test_pursuit_takes_the_strongest_tile_harmonics_exactly():
    """A residual made of three tile harmonics and a constant: the pursuit finds them with
    their amplitudes (c = X / N) and leaves nothing, taking no more than the goal needs."""
    from hcard_builtins.image.pursuit import pursue

    nh, nw = 40, 50
    i, j = np.mgrid[0:nh, 0:nw]
    parts = [(3, 0, 0.8 + 0.2j), (1, -2, -0.5j), (0, 5, 0.3)]  # (kx, ky, c)
    residual = np.full((nh, nw), 0.25)
    for kx, ky, c in parts:
        residual += 2 * (c * np.exp(2j * np.pi * (kx * j / nw + ky * i / nh))).real
    residual = residual[None].astype(np.float32)
    mask = np.ones_like(residual)
    found = pursue(residual, mask=mask, free=np.array([8]), limit=np.array([16]),
                   goal_rms=1e-3, target=1e-2)
    assert found.count[0] == 3
    got = {(int(kx), int(ky)): c for kx, ky, c, v in zip(
        found.spectra.fx[0], found.spectra.fy[0], found.spectra.coef[0], found.spectra.valid[0],
        strict=True) if v}
    assert set(got) == {(kx, ky) for kx, ky, _ in parts}
    for kx, ky, c in parts:
        assert got[kx, ky] == pytest.approx(c, abs=1e-5)
    assert found.spectra.mean[0] == pytest.approx(0.25, abs=1e-5)
    assert found.p95[0] < 1e-4 and found.rms_at_limit[0] < 1e-4
    few = pursue(residual, mask=mask, free=np.array([2]), limit=np.array([16]), goal_rms=1e-3,
                 target=1e-2)
    assert few.count[0] == 2 and few.p95[0] > 0.1  # the cap stops it


def test_largest_values_give_an_exact_order_statistic_of_chunked_data():
    """The 95th percentile of values arriving in chunks of any size, ties included, is the
    nearest-rank percentile of them all."""
    from hcard_builtins.image.reconstruct import Largest, percentile_rank

    rng = np.random.default_rng(5)
    values = np.round(np.abs(rng.standard_normal(10_007)), 2).astype(np.float32)  # many ties
    keep = values.size - percentile_rank(values.size) + 1
    expected = np.percentile(values, 95, method="inverted_cdf")
    for chunk in (1, 37, 500, 3_000, 20_000):
        for reorder in (False, True):  # chunks of >= 4 keep values are partitioned in place
            largest, scratch = Largest(keep), values.copy()
            for start in range(0, values.size, chunk):
                largest.add(scratch[start:start + chunk], reorder=reorder)
            assert largest.smallest == expected


@pytest.mark.parametrize(("width", "height", "taxtel_mm", "path"), [
    (1024, 1024, 5.0, "blocks"),  # the last tile moved back inside: two runs per axis
    (1000, 700, 5.0, "view"),  # whole tiles: one run per axis, a view of the image
    (333, 517, 2.25, "take"),  # 23-pixel tiles of 22.5-pixel taxtels overlap: many runs
    (30, 45, 5.0, "view"),  # smaller than a taxtel: one tile of the whole image
])
def test_tiles_are_the_pixels_the_tile_indices_name(
    width: int, height: int, taxtel_mm: float, path: str, monkeypatch: pytest.MonkeyPatch
):
    """``Geometry.gather`` (a view, slices copied block by block, or ``take``) against numpy's
    fancy indexing of the same rows and columns, for whole and partial chunks of taxtel rows;
    ``path``: the way every chunk of the geometry is gathered (``take`` goes through
    ``_along``, and only a view shares the image's memory)."""
    from hcard_builtins.image import geometry as geometry_module
    from hcard_builtins.image.geometry import resolve_geometry

    called = False
    along = geometry_module._along

    def recorded_along(*args: Any, **kwargs: Any) -> np.ndarray:
        nonlocal called
        called = True
        return along(*args, **kwargs)

    monkeypatch.setattr(geometry_module, "_along", recorded_along)
    pixels = np.random.default_rng(width).integers(0, 256, (height, width), dtype=np.uint8)
    geometry = resolve_geometry(width, height, taxtel_mm=taxtel_mm, width_mm=None,
                                height_mm=None, dpi=None, embedded_dpi=None, source=Path("x"))
    columns = geometry.tile_columns()
    chunks = {(0, geometry.rows), (0, 1), (geometry.rows // 2, geometry.rows)}
    for first, stop in sorted(chunks):
        called = False
        expected = pixels[np.ix_(geometry.tile_rows(first, stop), columns)]
        got = geometry.gather(pixels, first, stop, columns)
        assert got.shape == (stop - first, geometry.tile_h, geometry.cols, geometry.tile_w)
        np.testing.assert_array_equal(got.reshape(expected.shape), expected)
        assert called == (path == "take")
        assert np.shares_memory(got, pixels) == (path == "view")


@pytest.mark.parametrize("n", [50, 33, 7])
def test_window_kernel_and_gain_match_the_windowed_sum(n: int):
    """The closed form of the periodic Hann window's DFT kernel against the direct sum over the
    window, at offsets off the integers and at the removable singularities (stepped off by 2e-7
    bin), and its shifted copies ``hann_kernels(u, n, shifts)[j] = H(u + j)``, which the peak
    offsets and the frequency refinement read, against the direct sum at ``u + j``."""
    from hcard_builtins.image.spectral import hann_kernel, hann_kernels

    rng = np.random.default_rng(n)
    u = np.concatenate([rng.uniform(-n / 2, n / 2, 400), [0.0, 1.0, -1.0, 3.0, 0.5, -0.25]])
    window = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)

    def direct(at: np.ndarray) -> np.ndarray:
        return (window * np.exp(2j * np.pi * np.outer(at, np.arange(n)) / n)).sum(axis=1)

    # the 2e-7-bin step off a singularity turns the phase by up to 2e-7 pi at the peak n / 2
    tolerance = 4e-7 * n
    np.testing.assert_allclose(hann_kernel(u, n), direct(u), atol=tolerance)
    shifted = hann_kernels(u, n, (-1, 0, 1))
    for j, kernel in shifted.items():
        np.testing.assert_allclose(kernel, direct(u + j), atol=tolerance)


def test_chunk_size_changes_no_more_than_the_last_bits(tmp_path: Path, monkeypatch):
    """Taxtel rows are analysed and rendered in chunks (memory, cache); a tile's figures may
    differ in the last bits with its place in a batched FFT, nothing more: the same textures,
    indices and components, values within 1e-12, the same error figures."""
    from hcard_builtins.image import analysis

    path = save_gray(shapes_gray(7, 0.02), tmp_path / "shapes.png")
    whole = encode_image(path)
    monkeypatch.setattr(analysis, "CHUNK_PIXELS", 50 * 50 * 6)  # one taxtel row a chunk
    rows = encode_image(path)
    a, b = whole.card, rows.card
    assert list(a.grid.texture_index) == list(b.grid.texture_index)
    assert [len(t.components) for t in a.textures] == [len(t.components) for t in b.textures]
    for ta, tb in zip(a.textures, b.textures, strict=True):
        assert ta.baseline == pytest.approx(tb.baseline, abs=1e-12)
        for ca, cb in zip(ta.components, tb.components, strict=True):
            assert (ca.frequency, ca.amplitude, ca.orientation) == pytest.approx(
                (cb.frequency, cb.amplitude, cb.orientation), abs=1e-12)
            assert angle_difference(ca.phase, cb.phase) < 1e-9
    for key in ("rms_error", "p95_error", "max_error"):
        assert whole.stats[key] == pytest.approx(rows.stats[key], rel=1e-9)
