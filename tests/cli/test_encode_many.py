"""``hcard encode a.png b.png c.png -o DIR/``: one card per image on the executor, each the
card a single encode writes; an image that fails is named, the others written, exit 1."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from click.testing import CliRunner
from PIL import Image

from hcard.cli.main import cli


def _image(path: Path, period: int) -> Path:
    x = np.arange(48)
    pixels = (127 + 100 * np.sin(2 * np.pi * x / period))[None, :].repeat(32, 0)
    Image.fromarray(pixels.astype(np.uint8), mode="L").save(path)
    return path


def test_three_images_make_the_three_cards_single_encodes_make(tmp_path: Path) -> None:
    images = [_image(tmp_path / f"{name}.png", period)
              for name, period in (("a", 6), ("b", 9), ("c", 16))]
    runner = CliRunner()
    size = ["--width-mm", "24", "--taxtel-mm", "4"]
    many = runner.invoke(cli, ["encode", *map(str, images), "-o", str(tmp_path / "cards"),
                               *size, "--workers", "1"])
    assert many.exit_code == 0, many.output
    for image in images:
        alone = tmp_path / f"{image.stem}-alone.hcard"
        one = runner.invoke(cli, ["encode", str(image), "-o", str(alone), "--title",
                                  image.stem, *size])
        assert one.exit_code == 0, one.output
        assert (tmp_path / "cards" / f"{image.stem}.hcard").read_bytes() == alone.read_bytes()
        assert f"{image} -> {tmp_path / 'cards' / image.stem}.hcard" in many.stdout


def test_a_bad_image_is_named_and_the_others_are_written(tmp_path: Path) -> None:
    good = [_image(tmp_path / "a.png", 6), _image(tmp_path / "c.png", 16)]
    bad = tmp_path / "b.png"
    bad.write_bytes(b"not a png")
    result = CliRunner().invoke(cli, ["encode", str(good[0]), str(bad), str(good[1]), "-o",
                                      str(tmp_path / "cards"), "--width-mm", "24",
                                      "--workers", "0"])
    assert result.exit_code == 1
    assert f"error: {bad}:" in result.stderr
    assert "1 of 3 image(s) failed" in result.stderr
    assert sorted(p.name for p in (tmp_path / "cards").iterdir()) == ["a.hcard", "c.hcard"]


def test_several_images_need_a_directory(tmp_path: Path) -> None:
    (tmp_path / "x.hcard").write_text("")
    result = CliRunner().invoke(cli, ["encode", "a.png", "b.png", "-o",
                                      str(tmp_path / "x.hcard")])
    assert result.exit_code == 2
    assert "with several images, -o is a directory" in result.output
