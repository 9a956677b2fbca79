"""The examples printed in the normative text are valid: the spec cannot drift from the code."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import hcard
from hcard.card_io import parse_card
from hcard.track import parse_track_csv
from tests.helpers.repository import REPO

SPEC = REPO / "spec"


def blocks(path: Path, language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", path.read_text(), flags=re.S)


def test_json_card_examples_in_the_spec_validate():
    examples = [b for b in blocks(SPEC / "README.md", "json") if '"version"' in b]
    assert examples, "spec/README.md lost its JSON card example"
    for text in examples:
        card = parse_card(text.encode())
        assert [p for p in hcard.validate(card) if p.severity == "error"] == []
        assert card.version.major == 1 and len(card.textures) >= 2


@pytest.mark.parametrize("language", ["csv"])
def test_track_examples_in_the_track_format_parse(language):
    examples = [b for b in blocks(SPEC / "track-format.md", language) if "x_mm" in b]
    assert examples, "spec/track-format.md lost its track example"
    for text in examples:
        track = parse_track_csv(text)
        assert len(track) >= 2


def test_render_output_example_is_what_hcard_render_writes():
    """spec/track-format.md shows the first frames of the README's example card on its example
    track; the reference renderer must write exactly those lines."""
    from hcard.cli.render_cmd import frames_to_csv
    from hcard.render import render

    card_text = next(b for b in blocks(SPEC / "README.md", "json") if '"version"' in b)
    csv_blocks = blocks(SPEC / "track-format.md", "csv")
    track = parse_track_csv(next(b for b in csv_blocks if "x_mm" in b))
    example = next(b for b in csv_blocks if b.startswith("t_s,uv,ev"))
    written = frames_to_csv(render(parse_card(card_text.encode()), track)).decode()
    expected = example.strip().splitlines()
    assert written.splitlines()[: len(expected)] == expected


def test_device_profile_example_loads_and_renders():
    from hcard.physics.profile import DeviceProfile

    (text,) = blocks(SPEC / "device-profile.md", "json")
    profile = DeviceProfile.from_json(text.encode(), source="device-profile.md")
    assert [(f.name, f.channel) for f in profile.effects] == [("air-layer", "ev")]
    # the air layer lowers the EV force at 0.5 N against the profile's own contact law
    plain = profile.replace(effects=())
    assert 0.3 < profile.force_for(1000.0, 0.5) / plain.force_for(1000.0, 0.5) < 0.9
