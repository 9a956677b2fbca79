"""Tanvas and TPad bitmaps (spec/interchange/bitmaps.md): polarity and channel on hand-made
images whose friction is worked out by hand, alpha, colour, 16-bit and palette pixels, the
options, export against an independent evaluation of the card, losses, and round trips."""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hcard import build
from hcard.errors import UsageError
from hcard.v1 import card_pb2 as pb
from hcard_builtins.formats.bitmaps import (
    TanvasExporter,
    TanvasImporter,
    TPadExporter,
    TPadImporter,
)
from hcard_builtins.image.encoder import encode_image
from tests.interchange.bitmap_helpers import JND, card_friction, pixel_centres, save_png

TANVAS_LEVEL = 0.6 / 255
"""Relative friction of one Tanvas gray level at the default range 1.0 .. 1.6 (IB3)."""
TPAD_LEVEL = 0.7 / 255


def halves(path: Path, left: int, right: int) -> Path:
    """A 100 x 60 pixel 8-bit gray PNG at 254 dpi (10 x 6 mm): ``left`` on the left 50 columns,
    ``right`` on the right 50."""
    pixels = np.full((60, 100), left, dtype=np.uint8)
    pixels[:, 50:] = right
    return save_png(pixels, path, dpi=254.0)


def friction_of_halves(card: pb.Card) -> tuple[float, float]:
    """Mean friction of the card over the left and right halves (mm 0-5 and 5-10)."""
    x, y = np.meshgrid(np.linspace(0.05, 4.95, 50), np.linspace(0.05, 5.95, 60))
    return float(card_friction(card, x, y).mean()), float(card_friction(card, x + 5, y).mean())


def test_tanvas_black_is_natural_friction_and_white_the_most_ev(tmp_path: Path):
    """IB1, IB3: gray 0 = 1.0 and 255 = 1.6 on channel EV, on the two halves of an image."""
    result = TanvasImporter().read(halves(tmp_path / "t.png", 0, 255), taxtel_mm=5.0, dpi=254.0)
    left, right = friction_of_halves(result.card)
    assert left == pytest.approx(1.0, abs=1e-6) and right == pytest.approx(1.6, abs=1e-6)
    assert {t.channel for t in result.card.textures} == {pb.CHANNEL_EV}
    assert (result.card.grid.cols, result.card.grid.rows) == (2, 2)
    assert result.stats["rms_error_jnd"] < 1e-6 and result.stats["embedded_card"] is False


def test_tpad_white_is_slipperiest_uv(tmp_path: Path):
    """IB2, IB3: the reverse polarity: gray 0 = 1.0, 255 = 0.3 on channel UV."""
    result = TPadImporter().read(halves(tmp_path / "t.png", 0, 255), taxtel_mm=5.0)
    left, right = friction_of_halves(result.card)
    assert left == pytest.approx(1.0, abs=1e-6) and right == pytest.approx(0.3, abs=1e-6)
    assert {t.channel for t in result.card.textures} == {pb.CHANNEL_UV}


def test_mid_gray_maps_linearly_in_each_polarity(tmp_path: Path):
    """IB3: gray 128 is 1 + 0.6 * 128/255 = 1.30118 (Tanvas) and 1 - 0.7 * 128/255 = 0.64863
    (TPad); with --friction-range 1 2 Tanvas gray 51 is 1.2."""
    path = halves(tmp_path / "g.png", 128, 51)
    tanvas = friction_of_halves(TanvasImporter().read(path, dpi=254.0).card)
    tpad = friction_of_halves(TPadImporter().read(path).card)
    ranged = friction_of_halves(TanvasImporter().read(path, friction_range=(1.0, 2.0),
                                                      dpi=254.0).card)
    assert tanvas == pytest.approx((1.301176, 1.12), abs=1e-5)
    assert tpad == pytest.approx((0.648627, 0.86), abs=1e-5)
    assert ranged == pytest.approx((1.501961, 1.2), abs=1e-5)


def test_transparent_pixels_are_natural_friction_in_both_formats(tmp_path: Path):
    """IB4: alpha composites over black (gray 0, no drive): white at alpha 0 is 1.0 in both
    formats, opaque white 1.6 (Tanvas) and 0.3 (TPad), white at alpha 102 (40 %) is gray 102:
    Tanvas 1 + 0.6 * 0.4 = 1.24, TPad 1 - 0.7 * 0.4 = 0.72."""
    rgba = np.full((60, 100, 4), 255, dtype=np.uint8)
    rgba[:, :50, 3] = 0
    rgba[:, 50:, 3] = 102
    path = save_png(rgba, tmp_path / "a.png", dpi=254.0)
    assert friction_of_halves(TanvasImporter().read(path, dpi=254.0).card) == pytest.approx(
        (1.0, 1.24), abs=1e-5)
    assert friction_of_halves(TPadImporter().read(path).card) == pytest.approx(
        (1.0, 0.72), abs=1e-5)


def test_colour_is_luma_16_bit_keeps_its_levels_and_palettes_are_read(tmp_path: Path):
    """IB4: RGB is ITU-R 601 luma (pure red 0.299 of white: 1 + 0.6 * 0.299 = 1.1794 within a
    gray level), 16-bit gray keeps 65536 levels (32768 -> 1.300005), a palette PNG its
    colours' luma."""
    rgb = np.zeros((60, 100, 3), dtype=np.uint8)
    rgb[:, :50, 0] = 255
    red = friction_of_halves(TanvasImporter().read(save_png(rgb, tmp_path / "c.png",
                                                            dpi=254.0)).card)[0]
    assert abs(red - (1 + 0.6 * 0.299)) < TANVAS_LEVEL
    deep = np.full((60, 100), 32768, dtype=np.uint16)
    path = tmp_path / "d.png"
    Image.fromarray(deep).save(path, dpi=(254, 254))
    assert friction_of_halves(TanvasImporter().read(path, dpi=254.0).card)[0] == pytest.approx(
        1 + 0.6 * 32768 / 65535, abs=1e-6)
    palette = Image.fromarray(np.where(np.arange(100) < 50, 0, 1).astype(np.uint8)[None, :]
                              .repeat(60, axis=0), mode="P")
    palette.putpalette([0, 0, 0, 255, 255, 255])
    palette.save(tmp_path / "p.png", dpi=(254, 254))
    assert friction_of_halves(TPadImporter().read(tmp_path / "p.png").card) == pytest.approx(
        (1.0, 0.3), abs=1e-6)


def test_size_comes_from_options_then_phys_then_the_format_default(tmp_path: Path):
    """IB5: --dpi, else the Tanvas screen, 149.4 dpi (100 px = 17.00 mm) whatever the pHYs;
    TPad: pHYs, else 254 dpi. (The other tests give Tanvas reads ``dpi=254.0``, their images'
    stated resolution, so that a taxtel holds whole pixels.)"""
    plain = save_png(np.zeros((60, 100), dtype=np.uint8), tmp_path / "n.png")
    tanvas = TanvasImporter().read(plain).stats
    assert tanvas["width_mm"] == pytest.approx(100 * 25.4 / 149.4)
    assert "assumed 149.4 dpi, the Tanvas default" in tanvas["size_source"]
    assert TPadImporter().read(plain).stats["width_mm"] == pytest.approx(10.0)
    stated = halves(tmp_path / "s.png", 0, 0)  # 100 x 60 pixels at a stated 254 dpi
    assert TPadImporter().read(stated).stats["width_mm"] == pytest.approx(10.0)
    screen = TanvasImporter().read(stated).stats
    assert screen["width_mm"] == pytest.approx(100 * 25.4 / 149.4)
    assert "a Tanvas bitmap pixel is a screen pixel" in screen["size_source"]
    assert TanvasImporter().read(stated, dpi=127.0).stats["width_mm"] == pytest.approx(20.0)
    assert TanvasImporter().read(stated, width_mm=50.0).stats["height_mm"] == pytest.approx(30.0)


def test_options_are_checked_and_unknown_ones_named():
    """IB6: unknown options and ranges the channel cannot render are usage errors."""
    with pytest.raises(UsageError, match="length_unit_mm: not an option of the tanvas importer"):
        TanvasImporter().options(length_unit_mm=1.0)
    with pytest.raises(UsageError, match="EV can only raise friction"):
        TanvasImporter().options(friction_range=(0.5, 1.5))
    with pytest.raises(UsageError, match="UV can only lower friction"):
        TPadImporter().options(friction_range=(0.5, 1.5))
    with pytest.raises(UsageError, match="taxtel_mm must be between"):
        TPadImporter().options(taxtel_mm=0.0)
    with pytest.raises(UsageError, match="px_per_mm must be a number above 0"):
        TanvasExporter().options(px_per_mm=0.0)
    with pytest.raises(UsageError, match="dpi: not an option of the tpad exporter"):
        TPadExporter().options(dpi=100.0)
    assert TPadImporter().options()["friction_range"] == (0.3, 1.0)
    assert TanvasExporter().options() == {"px_per_mm": 10.0, "friction_range": None}


def test_recognises_any_png_as_either_and_its_own_export_surely(tmp_path: Path):
    """IB12: 1 for a PNG, 2 for a PNG whose hcard chunk names the format, 0 otherwise."""
    plain = save_png(np.zeros((4, 4), dtype=np.uint8), tmp_path / "p.png").read_bytes()
    exported = TPadExporter().write(uniform_card(0.5, "uv")).files[0][1]
    assert (TanvasImporter().recognises(plain), TPadImporter().recognises(plain)) == (1, 1)
    assert (TanvasImporter().recognises(exported[:4096]),
            TPadImporter().recognises(exported[:4096])) == (1, 2)
    assert TanvasImporter().recognises(b"GIF89a" + bytes(100)) == 0


def uniform_card(baseline: float, channel: str, components: list[pb.Component] | None = None,
                 *, width: float = 20.0, height: float = 10.0, locking: str = "position"
                 ) -> pb.Card:
    """A card of one texture over ``width`` x ``height`` mm in 5 mm taxtels."""
    return build.card(width, height, taxtel_mm=5.0, textures=[
        build.texture(baseline, components or [], channel=channel, locking=locking)],
        title="uniform", author="test", licence="CC0-1.0")


def gray_of(data: bytes) -> np.ndarray:
    """The pixels of PNG bytes."""
    with Image.open(io.BytesIO(data)) as image:
        assert image.mode == "L"
        return np.asarray(image)


def test_export_gray_levels_follow_each_polarity():
    """IB8: Tanvas EV 1.0 -> 0, 1.6 -> 255, 1.3 -> 127.5 rounded to even 128; TPad UV 1.0 ->
    0, 0.3 -> 255, 0.58 -> 153 (0.42 / 0.7 * 255)."""
    for baseline, level in ((1.0, 0), (1.6, 255), (1.24, 102)):
        gray = gray_of(TanvasExporter().write(uniform_card(baseline, "ev")).files[0][1])
        assert gray.shape == (100, 200) and set(np.unique(gray)) == {level}
    for baseline, level in ((1.0, 0), (0.3, 255), (0.58, 153)):
        gray = gray_of(TPadExporter().write(uniform_card(baseline, "uv")).files[0][1])
        assert set(np.unique(gray)) == {level}


def mixed_card() -> pb.Card:
    """Rectangular 4 x 3 mm taxtels over 24 x 15 mm, four textures: EV gratings at angles,
    a bipolar texture, a velocity-locked one, and a plain baseline."""
    textures = [
        build.texture(1.25, [build.spatial(0.4, 0.1, phase=1.0, orientation=0.6),
                             build.spatial(1.1, 0.05, phase=-2.0, orientation=2.0)],
                      channel="ev", locking="position"),
        build.texture(1.2, [build.spatial(0.3, 0.15, orientation=-0.4)], channel="bipolar",
                      locking="position"),
        build.texture(1.3, [build.spatial(0.5, 0.1, phase=0.5)], channel="ev",
                      locking="velocity"),
        build.texture(1.45, [], channel="ev"),
    ]
    index = (np.arange(6 * 5) * 7) % 4
    return build.card(24.0, 15.0, taxtel_mm=(4.0, 3.0), textures=textures,
                      texture_index=index)


def test_export_pixels_match_an_independent_evaluation_of_the_card():
    """IB8: every written pixel is the card's friction at its centre (card_friction, written
    from spec/README.md) within half a gray level; the stated error is that of the pixels."""
    card = mixed_card()
    result = TanvasExporter().write(card, px_per_mm=8.0)
    gray = gray_of(result.files[0][1]).astype(float)
    x, y = pixel_centres(card, 192, 120)
    expected = card_friction(card, x, y)
    drawn = 1.0 + TANVAS_LEVEL * gray
    assert gray.shape == (120, 192)
    assert np.max(np.abs(drawn - np.clip(expected, 1.0, 1.6))) <= TANVAS_LEVEL / 2 + 1e-6
    rms = math.sqrt(np.mean((drawn - expected) ** 2)) / JND
    assert result.stats["rms_error_jnd"] == pytest.approx(rms, rel=1e-4)
    assert result.stats["max_error_jnd"] <= TANVAS_LEVEL / 2 / JND + 1e-6


def test_losses_name_what_a_bitmap_cannot_hold():
    """IB15: the bipolar texture (channel), the velocity-locked one (locking), orientation and
    phase, the friction scale, the taxtel map and metadata, each kept in the chunk; a UV card
    in a Tanvas export clips every pixel to gray 0 and its error is (1 - 0.5) / 0.08 = 6.25
    JND."""
    result = TanvasExporter().write(mixed_card())
    fields = [loss.field for loss in result.losses]
    assert fields == ["channel", "locking", "orientation", "phase", "friction-scale",
                      "taxtel-map", "metadata"]
    assert all(loss.carried == 'PNG chunk iTXt "hcard"' for loss in result.losses)
    assert "BIPOLAR" in result.losses[0].detail and "1 velocity-locked" in result.losses[1].detail
    uv = TanvasExporter().write(uniform_card(0.5, "uv"))
    assert uv.stats["clipped_pixels"] == 200 * 100
    assert uv.stats["max_error_jnd"] == pytest.approx(6.25)
    assert uv.losses[0].field == "channel" and "200 x" not in uv.losses[0].detail


def test_components_a_picture_cannot_hold_are_left_out_and_counted():
    """IB8, IB15: at 2 px/mm (Nyquist 1 cycle/mm) a 1.5 cycles/mm grating and a 50 Hz
    temporal component are not drawn: the picture is the baseline, 1.3 -> gray 128."""
    card = uniform_card(1.3, "ev", [build.spatial(1.5, 0.2), build.temporal(50.0, 0.2)])
    result = TanvasExporter().write(card, px_per_mm=2.0)
    assert set(np.unique(gray_of(result.files[0][1]))) == {128}
    (components,) = [loss for loss in result.losses if loss.field == "components"]
    assert "1 temporal component(s) and 1 grating(s)" in components.detail


def test_the_range_the_card_states_is_the_range_of_its_export(tmp_path: Path):
    """IB9: a card imported with --friction-range 1 2 exports on 1 .. 2: its gray levels come
    back (gray 51 -> 1.2 -> 51)."""
    path = halves(tmp_path / "r.png", 51, 51)
    card = TanvasImporter().read(path, friction_range=(1.0, 2.0)).card
    result = TanvasExporter().write(card)
    assert result.stats["friction_range"] == (1.0, 2.0)
    assert result.stats["range_source"] == "the range the card's description states"
    assert set(np.unique(gray_of(result.files[0][1]))) == {51}
    assert TanvasExporter().write(card, friction_range=(1.0, 1.6)).stats[
        "clipped_pixels"] == 0


def test_an_export_beyond_the_pixel_limit_is_refused():
    """IB10: 10 m x 10 m at 10 px/mm is 10^10 pixels."""
    card = build.card(10_000.0, 10_000.0, taxtel_mm=100.0, textures=[build.texture(1.2)])
    with pytest.raises(UsageError, match=r"px_per_mm: 10000 x 10000 mm at 10 px/mm is "
                                         r"100000 x 100000"):
        TanvasExporter().write(card)


@pytest.mark.parametrize(("exporter", "importer", "channel", "baseline"), [
    (TanvasExporter, TanvasImporter, "ev", 1.25),
    (TPadExporter, TPadImporter, "uv", 0.6),
])
def test_round_trip_with_the_chunk_gives_the_card_back(tmp_path: Path, exporter, importer,
                                                       channel: str, baseline: float):
    """IB13: import(export(card)) == card, with the fidelity of the card to the pixels (their
    quantisation: at most half a level, 0.0147 JND Tanvas, 0.0172 JND TPad)."""
    card = uniform_card(baseline, channel, [build.spatial(0.25, 0.1, orientation=0.3)],
                        locking="auto")
    path = tmp_path / "x.png"
    path.write_bytes(exporter().write(card).files[0][1])
    result = importer().read(path, taxtel_mm=2.0)
    assert result.card == card
    level = TANVAS_LEVEL if channel == "ev" else TPAD_LEVEL
    assert result.stats["embedded_card"] is True
    assert 0 < result.stats["max_error_jnd"] <= level / 2 / JND + 1e-6
    assert any("ignored taxtel_mm" in line for line in result.log)


def without_chunk(data: bytes, path: Path) -> Path:
    """The pixels and resolution of an exported PNG saved again without its hcard chunk."""
    with Image.open(io.BytesIO(data)) as image:
        assert "hcard" in image.info
        image.save(path, dpi=image.info["dpi"])
    with Image.open(path) as check:
        assert "hcard" not in check.info
    return path


ROUND_TRIP_RMS_JND = 0.1
"""IB16: the RMS difference between a card and the re-encoding of its export stripped of the
chunk, at --max-error 0.5 and the export's default 10 px/mm, for gratings the taxtels hold
whole periods of (measured: RMS 0.005 JND Tanvas, 0.004 TPad; largest 0.007 and 0.005)."""
ROUND_TRIP_MAX_JND = 0.25


@pytest.mark.parametrize(("exporter", "importer", "channel", "baseline"), [
    (TanvasExporter, TanvasImporter, "ev", 1.3),
    (TPadExporter, TPadImporter, "uv", 0.65),
])
def test_round_trip_without_the_chunk_is_within_the_stated_tolerance(
        tmp_path: Path, exporter, importer, channel: str, baseline: float):
    """IB16: the card encoded from the stripped export's pixels, against the original card,
    both evaluated independently (card_friction) on a 0.05 mm grid: RMS below
    ROUND_TRIP_RMS_JND, and the importer's own rms_error_jnd tells the truth within 0.05."""
    textures = [
        build.texture(baseline, [build.spatial(0.4, 0.12, phase=0.7)], channel=channel,
                      locking="position"),
        build.texture(baseline + 0.15 if channel == "ev" else baseline - 0.15, [],
                      channel=channel),
    ]
    card = build.card(30.0, 20.0, taxtel_mm=5.0, textures=textures,
                      texture_index=(np.arange(24) // 3) % 2)
    data = exporter().write(card).files[0][1]
    result = importer().read(without_chunk(data, tmp_path / "s.png"), max_error=0.5, dpi=254.0)
    assert result.stats["embedded_card"] is False
    assert (result.card.surface.width_mm, result.card.surface.height_mm) == (30.0, 20.0)
    x, y = np.meshgrid(np.arange(0.025, 30, 0.05), np.arange(0.025, 20, 0.05))
    difference = card_friction(result.card, x, y) - card_friction(card, x, y)
    rms = math.sqrt(np.mean(difference**2)) / JND
    assert rms < ROUND_TRIP_RMS_JND
    assert np.abs(difference).max() / JND < ROUND_TRIP_MAX_JND
    assert abs(rms - result.stats["rms_error_jnd"]) < 0.05


def test_an_edited_export_is_encoded_from_its_pixels(tmp_path: Path):
    """IB13: pixels changed after the export no longer match pixels_sha256: the card is the
    encoding of the pixels (a painted white block reads 1.6), and the log says why."""
    data = TanvasExporter().write(uniform_card(1.0, "ev")).files[0][1]
    with Image.open(io.BytesIO(data)) as image:
        info = image.info
        pixels = np.asarray(image).copy()
    pixels[:, :50] = 255
    path = tmp_path / "edited.png"
    from PIL.PngImagePlugin import PngInfo

    keep = PngInfo()
    keep.add_itxt("hcard", info["hcard"])
    Image.fromarray(pixels).save(path, pnginfo=keep, dpi=info["dpi"])
    result = TanvasImporter().read(path, dpi=254.0)
    assert result.stats["embedded_card"] is False
    assert "the pixels differ from those" in result.log[0]
    assert friction_of_halves(result.card) == pytest.approx((1.6, 1.0), abs=1e-6)


def test_encoder_white_is_high_is_the_inverted_image_and_transparent_black(tmp_path: Path):
    """The image encoder's white_is and transparent options (used by the Tanvas importer):
    white_is="high" encodes exactly what the default encodes of 255 - gray; a transparent
    pixel shows black with transparent="black" and white by default."""
    rng = np.random.default_rng(3)
    gray = rng.integers(0, 256, (40, 40), dtype=np.uint8)
    a = encode_image(save_png(gray, tmp_path / "a.png", dpi=254.0), white_is="high",
                     channel="ev", title="x")
    b = encode_image(save_png(255 - gray, tmp_path / "b.png", dpi=254.0), channel="ev",
                     title="x")
    assert a.card.textures == b.card.textures
    assert "white = relative friction 1.6, black = 1" in a.card.metadata.description
    clear = np.zeros((40, 40, 4), dtype=np.uint8)
    path = save_png(clear, tmp_path / "c.png", dpi=254.0)
    assert encode_image(path, transparent="black").card.textures[0].baseline == pytest.approx(1.0)
    assert encode_image(path).card.textures[0].baseline == pytest.approx(0.3)
    with pytest.raises(ValueError, match="white_is must be one of low, high"):
        encode_image(path, white_is="up")


def test_an_error_target_every_taxtel_meets_at_once_encodes(tmp_path: Path):
    """The image encoder with --max-error on an image whose checked taxtels all meet the
    target before the pursuit (a 2.5 mm grating in 5 mm taxtels beside a flat half): it
    raised a ValueError from a reshape of zero tiles; now the card is within the target
    (95th percentile 0.5 JND)."""
    x = (np.arange(300) + 0.5) / 10
    gray = np.tile(np.round(127 + 50 * np.cos(2 * np.pi * 0.4 * x)).astype(np.uint8), (200, 1))
    gray[:, 150:] = 200
    result = encode_image(save_png(gray, tmp_path / "g.png", dpi=254.0), max_error=0.5)
    assert result.stats["p95_error_jnd"] <= 0.5
    assert result.stats["target"]["taxtels_over"] == 0
