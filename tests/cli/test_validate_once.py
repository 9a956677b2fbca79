"""Each command validates a card once on the host (:func:`hcard.validate.require_valid` where
the card enters it; what it hands the card to afterwards is told ``check=False``); a device's
check of the card it is sent is the device's own and is counted apart."""

from __future__ import annotations

import functools
import sys
import traceback
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from PIL import Image

import hcard
from hcard import build
from hcard.cli.main import cli
from hcard.errors import CardValidationError
from hcard.physics.profile import DeviceProfile
from hcard.track import straight_stroke, track_to_csv
from hcard.v1 import card_pb2 as pb
from hcard.validate import card_errors, require_valid

DEVICE_CHECK = ("hcard_device", "card_check.py")
"""The reference device's check of an uploaded card (its firmware's, not the host's)."""


class Validations:
    """Every call of the validator, host or device, with the card validated."""

    def __init__(self) -> None:
        self.host: list[bytes] = []
        self.device = 0

    def record(self, card: pb.Card) -> None:
        stack = traceback.extract_stack()
        if any(Path(frame.filename).parts[-2:] == DEVICE_CHECK for frame in stack):
            self.device += 1
        else:
            self.host.append(card.SerializeToString(deterministic=True))


def _validate_attributes(original) -> list[tuple[object, object]]:
    """Every module attribute ``validate`` that is the validator or a counting wrapper of it
    (a module imported while a test ran bound the wrapper of that test)."""
    return [(module, value) for module in list(sys.modules.values())
            if (value := getattr(module, "validate", None)) is not None
            and getattr(value, "__wrapped__", value) is original]


@pytest.fixture()
def validations() -> Iterator[Validations]:
    """Counts the validator's calls, through every name it is imported under; every name is
    given the validator back afterwards."""
    original = sys.modules["hcard.validate"].validate
    seen = Validations()

    @functools.wraps(original)
    def counting(card: pb.Card):
        seen.record(card)
        return original(card)

    for module, _ in _validate_attributes(original):
        module.validate = counting
    try:
        yield seen
    finally:
        for module, _ in _validate_attributes(original):
            module.validate = original


@pytest.fixture()
def files(tmp_path) -> dict[str, Path]:
    card = tmp_path / "card.hcard"
    texture = build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv")
    hcard.save(build.card(40.0, 10.0, taxtel_mm=5.0, textures=[texture],
                          texture_index=[0] * 16), card)
    track = tmp_path / "stroke.csv"
    track.write_text(track_to_csv(straight_stroke((1.0, 5.0), (35.0, 0.0), 0.2)))
    profile = tmp_path / "device.json"
    DeviceProfile.coupled_stimulator().save(profile)
    image = tmp_path / "image.png"
    pixels = (np.indices((40, 40)).sum(axis=0) % 8 < 4).astype(np.uint8) * 200
    Image.fromarray(pixels).save(image)
    return {"card": card, "track": track, "profile": profile, "image": image, "dir": tmp_path}


COMMANDS = {
    "validate": ["validate", "{card}"],
    "info": ["info", "{card}"],
    "render": ["render", "{card}", "--track", "{track}", "-o", "{dir}/frames.csv"],
    "render --profile": ["render", "{card}", "--track", "{track}", "-o", "{dir}/frames.npz",
                         "--profile", "{profile}"],
    "preview": ["preview", "{card}", "-o", "{dir}/card.png"],
    "encode": ["encode", "{image}", "-o", "{dir}/encoded.hcard", "--width-mm", "40"],
    "encode --preview": ["encode", "{image}", "-o", "{dir}/encoded.hcard.json", "--width-mm",
                         "40", "--preview", "{dir}/encoded.png"],
    "encode -o -": ["encode", "{image}", "-o", "-", "--width-mm", "40", "--preview",
                    "{dir}/encoded.png"],
    "play sim://": ["play", "{card}", "--device", "sim://evita?seed=3", "--track", "{track}",
                    "-o", "{dir}/recording.csv"],
}


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_command_validates_its_card_once_on_the_host(command, files, validations):
    names = {k: str(v) for k, v in files.items()}
    args = ["-q", *(a.format(**names) for a in COMMANDS[command])]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    assert len(validations.host) == 1, f"{command}: {len(validations.host)} validations"
    assert validations.device == (1 if command == "play sim://" else 0)  # the device's own


def test_the_conformance_suite_validates_each_card_once(validations):
    """The render entries that share a card share its one validation (the format level's
    validations are its checks: each file of the vectors once)."""
    from hcard_conformance.context import DEFAULT_VECTORS
    from hcard_conformance.vectors import load_manifest

    result = CliRunner().invoke(cli, ["-q", "conformance", "--driver", "reference",
                                      "--level", "renderer"])
    assert result.exit_code == 0, result.output
    assert len(validations.host) == len(set(validations.host))
    manifest = load_manifest(DEFAULT_VECTORS)
    assert len(validations.host) == len({entry.card for entry in manifest.renders})


def test_require_valid_returns_the_card_or_raises_with_the_findings():
    texture = build.texture(0.7, [build.spatial(1.0, 0.2)], channel="uv")
    card = build.card(10.0, 10.0, taxtel_mm=5.0, textures=[texture], texture_index=[0] * 4)
    assert require_valid(card) is card and card_errors(card) == []
    card.grid.texture_index[3] = 3  # outside the palette of one texture
    where = r"^made\.hcard: grid\.texture_index\[3\]: texture 3"
    with pytest.raises(CardValidationError, match=where) as info:
        require_valid(card, source="made.hcard")
    assert info.value.problems == card_errors(card) != []
