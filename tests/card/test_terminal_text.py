"""Text from a card never reaches the terminal as a command (ESC sequences, C1 controls,
bidirectional overrides): `hcard info` printed metadata and texture names raw."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from hcard import build
from hcard.card_io import to_bytes
from hcard.cli.main import cli
from hcard.terminal_text import printable

HOSTILE = {
    "\x1b]0;pwned\x07": "\\x1b]0;pwned\\x07",  # OSC: set the window title
    "\x1b[2J\x1b[H": "\\x1b[2J\\x1b[H",  # CSI: clear the screen, cursor home
    "a\rb\nc\td": "a\\x0db\\x0ac\\x09d",  # CR, LF, TAB: one line
    "\x9b31m": "\\x9b31m",  # C1 CSI
    "\x7f": "\\x7f",
    "evil\u202etxt.exe": "evil\\u202etxt.exe",  # right-to-left override
    "\u2066x\u2069": "\\u2066x\\u2069",  # isolates
}


@pytest.mark.parametrize(("raw", "shown"), list(HOSTILE.items()))
def test_unsafe_characters_are_shown_as_escapes(raw, shown):
    assert printable(raw) == shown


def test_ordinary_text_is_unchanged():
    text = "Grating 2 mm — 50 % ± 0.1, 触覚, Ελληνικά, emoji 🙂"
    assert printable(text) == text


def hostile_card(tmp_path):
    card = build.card(20.0, 10.0, taxtel_mm=10.0, textures=[
        build.texture(1.0, channel="uv", name="plain\x1b[31mRED"),
        build.texture(0.5, channel="uv", name="slip\u202eevil")],
        texture_index=[0, 1], title="title\x1b]0;pwned\x07")
    path = tmp_path / "hostile.hcard"
    path.write_bytes(to_bytes(card))
    return path


def test_info_and_validate_print_no_control_character(tmp_path):
    path = hostile_card(tmp_path)
    for args in (["info", str(path)], ["validate", str(path)]):
        result = CliRunner().invoke(cli, args)
        out = result.output
        assert "\x1b" not in out and "\x07" not in out and "\u202e" not in out, args
    info = CliRunner().invoke(cli, ["info", str(path)]).output
    assert "title\\x1b]0;pwned\\x07" in info
    assert "plain\\x1b[31mRED" in info and "slip\\u202eevil" in info
