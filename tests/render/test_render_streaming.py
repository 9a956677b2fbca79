"""``hcard render`` writes block by block (hcard.render.output): the files equal those of the
whole rendering, memory stays bounded whatever the track's length, and a rendering past the
frame limit is refused before any work (spec/README.md section 4)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hcard import build, card_io
from hcard.cli.main import cli
from hcard.cli.render_cmd import frames_to_csv
from hcard.render import MAX_RENDER_FRAMES, Renderer, RenderOptions, RenderTooLong
from hcard.render.renderer import BATCH_CHUNK_FRAMES
from hcard.track import make_track, track_to_csv
from tests.card.test_bounded_resources import run_measured

CARD = build.card(40.0, 20.0, taxtel_mm=10.0, textures=[
    build.texture(0.6, [build.spatial(1.0, 0.3), build.temporal(120.0, 0.1)], channel="uv"),
    build.texture(1.5, [build.spatial(0.5, 0.4)], channel="ev")],
    texture_index=[0, 1, 1, 0, 1, 0, 0, 1])


def stroke(seconds: float, rate_hz: float = 100.0) -> object:
    """Back and forth across the card at 40 mm/s, sampled at ``rate_hz``."""
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    x = 20.0 + 15.0 * np.sin(2 * np.pi * t / (30.0 / 40.0 * np.pi))
    return make_track(t, x, np.full(t.size, 10.0), 0.5, True)


@pytest.fixture
def files(tmp_path: Path) -> tuple[Path, Path]:
    card, track = tmp_path / "card.hcard", tmp_path / "track.csv"
    card_io.save(CARD, card)
    track.write_text(track_to_csv(stroke(8.0)))
    return card, track


def test_the_streamed_csv_is_the_whole_renderings_csv(files: tuple[Path, Path],
                                                      tmp_path: Path) -> None:
    card, track_path = files
    out = tmp_path / "frames.csv"
    result = CliRunner().invoke(cli, ["render", str(card), "--track", str(track_path), "-o",
                                      str(out)])
    assert result.exit_code == 0, result.output
    frames = Renderer(CARD).render(stroke(8.0))
    assert len(frames) > 2 * BATCH_CHUNK_FRAMES  # several blocks
    assert out.read_bytes() == frames_to_csv(frames)


def test_the_streamed_npz_holds_the_whole_renderings_arrays(files: tuple[Path, Path],
                                                            tmp_path: Path) -> None:
    card, track_path = files
    out = tmp_path / "frames.npz"
    result = CliRunner().invoke(cli, ["render", str(card), "--track", str(track_path), "-o",
                                      str(out)])
    assert result.exit_code == 0, result.output
    frames = Renderer(CARD).render(stroke(8.0))
    with np.load(out) as archive:
        assert sorted(archive.files) == sorted(["t_s", "uv", "ev", "friction", "contact",
                                                "texture"])
        np.testing.assert_array_equal(archive["t_s"], frames.t)
        np.testing.assert_array_equal(archive["uv"], frames.uv)
        np.testing.assert_array_equal(archive["friction"], frames.friction)
        assert archive["contact"].dtype == bool and archive["texture"].dtype == np.int32
        np.testing.assert_array_equal(archive["texture"], frames.texture)
    assert not list(tmp_path.glob(".frames.npz.*"))  # the spilled columns are gone


@pytest.mark.parametrize(("times", "rate"), [
    ([0.0, 0.01, 100_000.0], "10000"),  # a 100,000 s gap in the track
    ([0.0, 0.01, 0.02], "1e12"),  # an absurd frame rate
])
def test_a_rendering_past_the_frame_limit_is_refused_before_any_work(
        files: tuple[Path, Path], tmp_path: Path, times: list[float], rate: str) -> None:
    card, _ = files
    track = tmp_path / "long.csv"
    track.write_text("t_s,x_mm,y_mm\n" + "".join(f"{t},5,5\n" for t in times))
    out = tmp_path / "out.csv"
    out.write_text("previous\n")
    started = time.perf_counter()
    result = CliRunner().invoke(cli, ["render", str(card), "--track", str(track), "-o", str(out),
                                      "--frame-rate", rate, "--band-limit", "1000"])
    assert time.perf_counter() - started < 5.0
    assert result.exit_code == 1
    assert f"over the limit of {MAX_RENDER_FRAMES:.0e}" in result.output
    assert "Traceback" not in result.output
    assert out.read_text() == "previous\n"
    options = RenderOptions(frame_rate_hz=float(rate), band_limit_hz=1000.0)
    with pytest.raises(RenderTooLong):
        Renderer(CARD, options).frame_count(make_track(times, [5.0] * 3, [5.0] * 3, 0.5, True))


def test_memory_does_not_grow_with_the_length_of_the_rendering(files: tuple[Path, Path],
                                                               tmp_path: Path) -> None:
    """Peak memory of the command for a 20 s and a 120 s track (0.2 and 1.2 M frames): the
    whole rendering in memory would grow it by ~0.5 GB; written block by block, by little."""
    card, _ = files
    peaks = []
    for seconds in (20.0, 120.0):
        track = tmp_path / f"t{seconds:g}.csv"
        track.write_text(track_to_csv(stroke(seconds)))
        measured, stderr = run_measured("render", str(card), "--track", str(track), "-o",
                                        str(tmp_path / f"out{seconds:g}.csv"))
        assert measured["code"] == 0, stderr
        peaks.append(measured["peak_kb"] / 1024)
    assert peaks[1] - peaks[0] < 60.0, peaks  # MB
