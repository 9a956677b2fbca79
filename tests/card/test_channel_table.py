"""Every channel table is the one of hcard.channels (spec/README.md rules T4, C5, R11)."""

from __future__ import annotations

import numpy as np
import pytest

from hcard import build, channels
from hcard.cli.encode_cmd import encode
from hcard.describe import CHANNEL_NAMES
from hcard.device.play_summary import clip_text
from hcard.device.protocol import ClipReport
from hcard.preview.periods import channel_label
from hcard.render.compiled import compile_texture
from hcard.render.options import RenderOptions
from hcard.v1 import card_pb2 as pb
from hcard.validate import validate
from hcard_builtins.image.encoder import CHANNELS as ENCODER_CHANNELS
from hcard_builtins.image.encoder import DEFAULT_FRICTION_RANGE


def test_the_table_is_the_card_enum() -> None:
    """Each channel's value and label are the card schema's enum value and name (spec/README.md
    enum Channel), its name the label in lower case; groups are 0, 1, 2."""
    assert {c.value for c in channels.CHANNELS} == set(pb.Channel.values()) - {0}
    for c in channels.CHANNELS:
        assert pb.Channel.Name(c.value) == "CHANNEL_" + c.label
        assert c.name == c.label.lower()
    assert [c.group for c in channels.CHANNELS] == [0, 1, 2]


def test_the_command_line_and_the_encoder_offer_the_table() -> None:
    option = next(p for p in encode.params if p.name == "channel")
    assert list(option.type.choices) == ["uv", "ev", "bipolar"]
    assert tuple(ENCODER_CHANNELS) == tuple(DEFAULT_FRICTION_RANGE) == ("uv", "ev", "bipolar")


@pytest.mark.parametrize(("name", "label"), [("uv", "UV"), ("ev", "EV"), ("bipolar", "BIPOLAR")])
def test_names_and_labels_agree_everywhere(name: str, label: str) -> None:
    value = build.channel_value(name)
    assert value == getattr(pb, "CHANNEL_" + label)
    assert channel_label(value) == CHANNEL_NAMES[value] == label


def test_unknown_and_unspecified_labels() -> None:
    assert channel_label(7) == "?(7)"
    assert CHANNEL_NAMES[pb.CHANNEL_UNSPECIFIED] == "texture"


@pytest.mark.parametrize(("channel", "column"), [(pb.CHANNEL_UV, 0), (pb.CHANNEL_EV, 1),
                                                 (pb.CHANNEL_BIPOLAR, 2)])
def test_the_renderer_sums_each_channel_in_its_group(channel: int, column: int) -> None:
    """Rule R11: a texture's baseline - 1 goes to its channel's column, and a component of
    UNSPECIFIED channel to its texture's."""
    texture = pb.Texture(baseline=1.25 if channel != pb.CHANNEL_UV else 0.75, channel=channel)
    texture.components.add(domain=pb.DOMAIN_TEMPORAL, frequency=10.0, amplitude=0.1)
    compiled = compile_texture(texture, RenderOptions())
    expected = np.zeros(3)
    expected[column] = texture.baseline - 1.0
    np.testing.assert_allclose(compiled.baseline_deviation, expected)
    assert compiled.group_matrix[0].tolist() == [1.0 if k == column else 0.0 for k in range(3)]


def test_validation_accepts_exactly_the_table() -> None:
    for value in (*pb.Channel.values(), 9):
        card = build.card(64.0, 64.0, taxtel_mm=64.0, textures=[build.texture(channel=value)])
        rules = {p.rule for p in validate(card) if p.severity == "error"}
        assert ("T4" in rules) == (value not in channels.VALUES), value


def test_the_clip_report_names_the_channel() -> None:
    clip = ClipReport(item_count=1, clipped_textures=1, item_index=0, texture=0, channel=2,
                      reason=0, target_x1e4=20000, achievable_x1e4=15000, card_generation=1,
                      flags=0, reference_speed_mm_s=120, reference_force_mn=500)
    assert " EV asks 2.000, gets 1.500" in clip_text(clip)
