"""An image is checked for what its header declares before any pixel is decoded
(builtin_plugins/hcard_builtins/image/loading.py): its pixel count, the memory decoding it
takes (the bytes a pixel of its mode takes, :func:`decode_bytes`) and the encoder's surface and
grid. On
main a 0.5 MB PNG declaring 8000 x 8000 pixels of 16-bit RGBA was decoded (34 s, 1.0 GB) and a
64,000,000 x 1 PNG was decoded (221 MB) before the surface check refused it. Checked on hostile
PNGs made here and on the real PNG files matplotlib ships (mpl-data/images)."""

from __future__ import annotations

from pathlib import Path

import matplotlib
import pytest
from click.testing import CliRunner
from PIL import Image, ImageFile

from hcard.bounded_read import DECODE_BYTES_PER_ALLOWED_PIXEL, DEFAULT_MAX_PIXELS
from hcard.cli.main import cli
from hcard.errors import ImageError
from hcard_builtins.image import loading
from hcard_builtins.image.loading import ImageHeader, decode_bytes, load_gray
from tests.helpers.hostile_cards import png_declaring

REAL_PNGS = sorted(Path(matplotlib.get_data_path()).glob("images/*.png"))


@pytest.fixture
def no_decoding(monkeypatch: pytest.MonkeyPatch) -> None:
    """Decoding an image fails the test: what is refused must be refused from its header."""

    def refuse(self: Image.Image) -> None:
        raise AssertionError(f"{self.size} pixels of {self.mode} were decoded")

    monkeypatch.setattr(Image.Image, "load", refuse)
    monkeypatch.setattr(ImageFile.ImageFile, "load", refuse)


def test_a_png_declaring_more_memory_than_the_limit_is_refused_before_decoding(
        tmp_path: Path, no_decoding: None) -> None:
    path = tmp_path / "bomb.png"
    path.write_bytes(png_declaring(8000, 8000, bit_depth=16, colour_type=6))
    assert DEFAULT_MAX_PIXELS >= 8000 * 8000  # under the pixel limit: the bytes refuse it
    with pytest.raises(ImageError) as raised:
        load_gray(path)
    # RGBA: the decoded image, a white one and their composite at 4 bytes, the gray at 1
    assert str(raised.value) == (
        f"{path}: 8000 x 8000 pixels of mode RGBA take 832 MB to decode (13 bytes a pixel), "
        f"over the limit of 256 MB ({DECODE_BYTES_PER_ALLOWED_PIXEL} bytes a pixel of the pixel "
        "limit; raise it with --max-pixels if the image is genuine)")


def test_an_image_whose_surface_is_over_the_limit_is_refused_before_decoding(
        tmp_path: Path, no_decoding: None) -> None:
    path = tmp_path / "line.png"
    path.write_bytes(png_declaring(64_000_000, 1))
    result = CliRunner().invoke(cli, ["encode", str(path), "-o", str(tmp_path / "x.hcard")])
    assert result.exit_code == 1
    assert "Traceback" not in result.output
    # 64e6 pixels at the default 254 dpi (0.1 mm a pixel): 6.4 km, over the 10 m of rule G1
    assert result.output.startswith(f"Error: {path}: the surface would be 6.4e+06 x 0.1 mm")
    assert result.output.count("\n") == 1


def test_the_bytes_a_pixel_takes_follow_the_mode() -> None:
    assert [decode_bytes(mode) for mode in ("L", "1", "I;16", "I", "F", "RGB", "P", "RGBA",
                                            "LA")] == [1, 1, 2, 4, 4, 5, 9, 13, 13]


@pytest.mark.parametrize("path", REAL_PNGS, ids=lambda p: p.name)
def test_real_files_are_checked_from_their_header_as_decoding_finds_them(
        path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[ImageHeader] = []
    image = load_gray(path, check_header=seen.append)
    (header,) = seen
    with Image.open(path) as decoded:
        decoded.load()
        assert (header.width, header.height, header.mode) == (decoded.width, decoded.height,
                                                              decoded.mode)
    assert image.pixels.shape == (header.height, header.width)
    need = header.width * header.height * decode_bytes(header.mode)
    # a pixel limit whose budget is short of what the file needs: refused, not decoded
    short = (need - 1) // DECODE_BYTES_PER_ALLOWED_PIXEL
    assert short >= header.width * header.height  # so the pixel count alone passes
    monkeypatch.setattr(Image.Image, "load", _undecodable)
    monkeypatch.setattr(ImageFile.ImageFile, "load", _undecodable)
    with pytest.raises(ImageError, match="to decode"):
        load_gray(path, max_pixels=short)
    assert loading.png_header_size(path.read_bytes()[:64]) == (header.width, header.height)


def _undecodable(self: Image.Image) -> None:
    raise AssertionError("decoded")
