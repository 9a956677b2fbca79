"""``hcard view`` on the command line: the URL it prints, Ctrl-C, and one-line errors for a
card, a source image, a device URI or a port it cannot use."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

import hcard
from hcard import build
from tests.helpers.cli import assert_one_line_error, run_hcard
from tests.view.cards import card_a


@pytest.fixture
def card(tmp_path: Path) -> Path:
    path = tmp_path / "a.hcard"
    hcard.save(card_a(), path)
    return path


def test_help_has_an_example() -> None:
    result = run_hcard("view", "--help")
    assert result.exit_code == 0
    assert "hcard view gratings.hcard --source examples/gratings.png" in result.output
    assert "--port" in result.output and "--device" in result.output


def test_it_prints_the_url_serves_and_stops_on_ctrl_c(card: Path) -> None:
    process = subprocess.Popen(
        [sys.executable, "-c", "from hcard.cli.main import main; main()", "view", str(card)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = process.stdout.readline() if process.stdout else ""
        assert line.startswith("hcard view: http://127.0.0.1:"), line
        url = line.split()[2]
        with urllib.request.urlopen(url + "api/cards", timeout=10) as answer:
            assert json.load(answer)["cards"][0]["name"] == "a.hcard"
        process.send_signal(signal.SIGINT)
        assert process.wait(10) == 0
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        for stream in (process.stdout, process.stderr):
            if stream:
                stream.close()


def test_a_missing_card_is_one_line(tmp_path: Path) -> None:
    assert_one_line_error(run_hcard("view", tmp_path / "none.hcard"), "none.hcard")


def test_an_invalid_card_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "bad.hcard"
    bad.write_bytes(b"\x08\x01junk")
    assert_one_line_error(run_hcard("view", bad), "bad.hcard")


def test_a_port_in_use_is_a_usage_error(card: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        line = assert_one_line_error(run_hcard("view", card, "--port", port), status=2)
    assert f"--port {port}: the port is in use" in line


def test_a_missing_source_is_a_usage_error(card: Path, tmp_path: Path) -> None:
    assert_one_line_error(run_hcard("view", card, "--source", tmp_path / "no.png"),
                          "--source", "no such file", status=2)


def test_a_source_that_is_not_an_image_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "encoded.hcard"
    card = build.card(10.0, 10.0, taxtel_mm=5.0, textures=[build.texture(0.8, channel="uv")],
                      description="Encoded from x.png: black = relative friction 1, white = "
                                  "0.3, channel uv.")
    hcard.save(card, path)
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    assert_one_line_error(run_hcard("view", path, "--source", text), "notes.png",
                          "cannot read the source image")


def test_a_card_that_states_no_range_has_no_error_map(card: Path) -> None:
    from tests.helpers.repository import REPO

    assert_one_line_error(run_hcard("view", card, "--source", REPO / "examples" / "gratings.png"),
                          "--source", "does not state the friction", status=2)


def test_a_bad_device_uri_is_a_usage_error(card: Path) -> None:
    assert_one_line_error(run_hcard("view", card, "--device", "nope://x"), "--device",
                          status=2)
