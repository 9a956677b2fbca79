"""The view server's JSON API against the numbers computed here: the renderer called directly
on the same track, the texture's cosines, the per-taxtel difference and the encoder's own error
map; and its answers to requests it cannot serve."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hcard.limits import RELATIVE_FRICTION_JND
from hcard.render import Renderer, RenderOptions
from hcard.track import make_track, track_to_csv
from hcard.view.model import DIFF_LATTICE, load_source
from hcard.view.server import ViewState
from tests.helpers.repository import REPO
from tests.view.cards import GRATING, card_a, card_b
from tests.view.served import request, view_server

RTOL = 1e-9


@pytest.fixture(scope="module")
def url() -> str:
    with view_server(ViewState([card_a(), card_b()], ["a.hcard", "b.hcard"])) as base:
        yield base


def test_cards_give_surface_grid_and_textures(url: str) -> None:
    status, answer = request(url + "api/cards")
    assert status == 200
    first = answer["cards"][0]
    assert first["surface"] == {"width_mm": 40.0, "height_mm": 30.0}
    assert (first["grid"]["cols"], first["grid"]["rows"]) == (8, 6)
    assert first["grid"]["texture_index"] == list(card_a().grid.texture_index)
    grating = first["textures"][0]
    assert (grating["channel"], grating["locking"], grating["baseline"]) == ("UV", "VELOCITY",
                                                                           0.7)
    k, a, phase, theta = GRATING
    assert grating["components"][0] == {
        "domain": "SPATIAL", "frequency": k, "unit": "cycles/mm", "amplitude": a,
        "phase_rad": phase, "orientation_rad": theta, "channel": "UV"}
    assert answer["device"] is None and "--device" in answer["play_disabled_reason"]
    assert answer["error_map"] is False


def test_profile_is_the_cosine_of_the_triplet(url: str) -> None:
    status, p = request(url + "api/texture?card=0&texture=0")
    assert status == 200
    s = np.array(p["s_mm"])
    k, a, phase, theta = GRATING
    assert p["length_mm"] == 20.0 and s[0] == 0.0 and s[-1] == 20.0
    assert p["direction_rad"] == theta  # along its one grating: the full frequency
    np.testing.assert_allclose(p["friction"], 0.7 + a * np.cos(2 * np.pi * k * s + phase),
                               rtol=RTOL, atol=1e-12)
    assert len(s) >= 16 * 20 * k  # 16 samples a cycle at least
    assert p["spectrum"] == [{"frequency_along": k, "frequency": k, "amplitude": a,
                              "orientation_rad": theta, "channel": "UV"}]


def test_profile_of_two_components_over_a_stated_length(url: str) -> None:
    status, p = request(url + "api/texture?card=1&texture=1&length_mm=7.5")
    assert status == 200
    s = np.array(p["s_mm"])
    assert s[-1] == 7.5
    expected = 1.5 + 0.2 * np.cos(2 * np.pi * 0.5 * s) + 0.1 * np.cos(2 * np.pi * 2.0 * s + 1.0)
    np.testing.assert_allclose(p["friction"], expected, rtol=RTOL, atol=1e-12)
    assert [c["frequency_along"] for c in p["spectrum"]] == [0.5, 2.0]
    assert [c["amplitude"] for c in p["spectrum"]] == [0.2, 0.1]


def _renderer_frames(track, frame_rate_hz: float = 10_000.0):
    return Renderer(card_a(), RenderOptions(frame_rate_hz=frame_rate_hz)).render(track)


def _assert_frames_equal(answer: dict, frames) -> None:
    got = answer["frames"]
    assert len(got["t_s"]) == len(frames) > 100
    for name, values in (("t_s", frames.t), ("uv", frames.uv), ("ev", frames.ev),
                         ("friction", frames.friction)):
        np.testing.assert_allclose(got[name], values, rtol=RTOL, atol=0)
    assert got["texture"] == frames.texture.tolist()


def test_render_of_points_is_the_renderers(url: str) -> None:
    t = np.arange(16) / 50.0
    x, y = 3.0 + 90.0 * t, 4.0 + 40.0 * t**2
    points = np.column_stack((t, x, y)).tolist()
    status, answer = request(url + "api/render", {"card": 0, "points": points})
    assert status == 200
    frames = _renderer_frames(make_track(t, x, y))
    _assert_frames_equal(answer, frames)
    # the same track as a track file gives the same frames
    status, from_csv = request(url + "api/render",
                               {"card": 0, "track_csv": track_to_csv(make_track(t, x, y))})
    assert status == 200 and from_csv["frames"] == answer["frames"]


def test_render_of_a_path_at_a_speed_is_the_renderers_on_the_retimed_track(url: str) -> None:
    """A drawn path at 80 mm/s: the finger at 80 mm/s along it, sampled at 50 Hz from its
    start, with one more sample at its end."""
    path = np.array([[2.0, 3.0], [20.0, 3.0], [20.0, 27.0]])
    speed = 80.0
    status, answer = request(url + "api/render", {"card": 0, "path": path.tolist(),
                                                  "speed_mm_s": speed, "frame_rate_hz": 5000})
    assert status == 200
    length = 18.0 + 24.0
    t = np.append(np.arange(math.floor(length / speed * 50) + 1) / 50.0, length / speed)
    s = t * speed
    x = np.where(s <= 18.0, 2.0 + s, 20.0)
    y = np.where(s <= 18.0, 3.0, 3.0 + (s - 18.0))
    frames = _renderer_frames(make_track(t, x, y), 5000.0)
    _assert_frames_equal(answer, frames)
    np.testing.assert_allclose(answer["track"]["x_mm"], x, rtol=RTOL)
    np.testing.assert_allclose(answer["frames"]["distance_mm"], speed * (frames.t - t[0]),
                               rtol=RTOL, atol=1e-9)
    assert answer["summary"]["frames"] == len(frames)


def _lattice_friction(card, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The card position-locked at points, written out here (spatial components only)."""
    g = card.grid
    which = np.array(g.texture_index)[(y // g.taxtel_height_mm).astype(int) * g.cols
                                      + (x // g.taxtel_width_mm).astype(int)]
    out = np.empty(x.shape)
    for i, texture in enumerate(card.textures):
        here = which == i
        value = np.full(here.sum(), texture.baseline)
        for c in texture.components:
            value += c.amplitude * np.cos(2 * np.pi * c.frequency * (
                math.cos(c.orientation) * x[here] + math.sin(c.orientation) * y[here]) + c.phase)
        out[here] = value
    return out


def test_diff_is_the_per_taxtel_difference(url: str) -> None:
    status, d = request(url + "api/diff?a=0&b=1")
    assert status == 200
    a, b = card_a(), card_b()
    u = (np.arange(DIFF_LATTICE) + 0.5) / DIFF_LATTICE * 5.0
    for row in range(6):
        for col in range(8):
            x, y = np.meshgrid(col * 5.0 + u, row * 5.0 + u)
            delta = _lattice_friction(b, x.ravel(), y.ravel()) - _lattice_friction(
                a, x.ravel(), y.ravel())
            assert d["rms"][row][col] == pytest.approx(np.sqrt(np.mean(delta**2)), rel=1e-9,
                                                       abs=1e-12)
            assert d["mean"][row][col] == pytest.approx(np.mean(delta), rel=1e-9, abs=1e-12)
    assert d["rms"][0][7] == pytest.approx(0.2)  # the EV baseline raised by 0.2
    assert d["rms"][5][0] == 0.0
    same = np.array(d["same_texture"])
    assert not same[0, 0] and not same[:, 4:].any() and same[1:, :4].all()


def test_error_map_is_the_encoders(tmp_path: Path) -> None:
    """Card of examples/gratings.png by the image encoder: the page's map is the encoder's
    ``error_rms`` map in JND."""
    from hcard_builtins.image.encoder import EncodeOptions, encode_image

    image = REPO / "examples" / "gratings.png"
    result = encode_image(image, EncodeOptions())
    state = ViewState([result.card], ["gratings.hcard"], load_source(image, result.card))
    with view_server(state) as base:
        status, cards = request(base + "api/cards")
        assert status == 200 and cards["error_map"] is True
        status, e = request(base + "api/error-map")
    assert status == 200
    expected = result.maps["error_rms"] / RELATIVE_FRICTION_JND
    np.testing.assert_allclose(np.array(e["error_jnd"], dtype=float), expected, rtol=1e-4,
                               atol=1e-6)  # the encoder works in single precision
    assert (e["black"], e["white"]) == (1.0, 0.3)


@pytest.mark.parametrize(("path", "body", "code", "words"), [
    ("api/texture?card=2&texture=0", None, 400, "card 2 is out of range (0..1)"),
    ("api/texture?card=x", None, 400, "card must be an integer"),
    ("api/texture?card=0&texture=9", None, 400, "texture 9 is out of range (0..1)"),
    ("api/texture?card=0&texture=0&length_mm=-1", None, 400, "length_mm must be a number"),
    ("api/diff?a=0&b=5", None, 400, "card 5 is out of range"),
    ("api/error-map", None, 404, "--source IMAGE"),
    ("api/nothing", None, 404, "no such page"),
    ("static/../server.py", None, 404, "no such"),
    ("api/render", {"card": 3, "path": [[0, 0], [1, 1]], "speed_mm_s": 10}, 400,
     "card 3 is out of range"),
    ("api/render", {"card": 0}, 400, "exactly one of path"),
    ("api/render", {"card": 0, "path": [[0, 0], [1, 1]]}, 400, "a path needs speed_mm_s"),
    ("api/render", {"card": 0, "path": [[1, 1], [1, 1]], "speed_mm_s": 10}, 400, "no length"),
    ("api/render", {"card": 0, "path": [[0, 0], [30, 0]], "speed_mm_s": 1e-3}, 400,
     "more than the page takes"),
    ("api/render", {"card": 0, "points": [[0, 0, 0], [0, 1, 1]]}, 400,
     "time must increase strictly"),
    ("api/render", {"card": 0, "track_csv": "t_s,x_mm\n0,1\n"}, 400, "lacks column(s) y_mm"),
    ("api/play", {"card": 0, "path": [[0, 0], [1, 1]], "speed_mm_s": 10}, 409, "--device"),
])
def test_requests_it_cannot_serve_get_a_json_error(url: str, path: str, body: dict | None,
                                                   code: int, words: str) -> None:
    status, answer = request(url + path, body)
    assert status == code
    assert words in answer["error"]


def test_a_body_that_is_not_json_is_refused(url: str) -> None:
    import urllib.error
    import urllib.request

    req = urllib.request.Request(url + "api/render", data=b"{nope", method="POST")
    with pytest.raises(urllib.error.HTTPError) as caught:
        urllib.request.urlopen(req, timeout=10)
    assert caught.value.code == 400
    assert b"not JSON" in caught.value.read()
    caught.value.close()


def test_the_page_and_its_files_are_served(url: str) -> None:
    import urllib.request

    with urllib.request.urlopen(url, timeout=10) as page:
        html = page.read().decode()
        assert page.headers["Content-Type"].startswith("text/html")
    assert '<script src="/static/view.js">' in html and "http" not in html.replace(
        "hcard", "")  # nothing from the network
    with urllib.request.urlopen(url + "static/view.js", timeout=10) as script:
        assert b"/api/render" in script.read()


def test_a_diff_needs_two_cards() -> None:
    with view_server(ViewState([card_a()], ["a.hcard"])) as base:
        status, answer = request(base + "api/diff")
    assert status == 400 and "two cards" in answer["error"]


def test_play_sends_the_stroke_to_the_device() -> None:
    """``--device sim://coupled``: the page's play goes through the host library."""
    state = ViewState([card_a()], ["a.hcard"], device_uri="sim://coupled")
    with view_server(state) as base:
        status, cards = request(base + "api/cards")
        assert cards["device"] == "sim://coupled" and cards["play_disabled_reason"] is None
        status, played = request(base + "api/play", {"card": 0, "path": [[2, 15], [38, 15]],
                                                     "speed_mm_s": 120})
    assert status == 200, played
    assert played["summary"][0].startswith("played ")
    reports = played["reports"]
    assert len(reports["t_s"]) > 200  # 0.3 s of STATE reports at 1 kHz
    uv = np.array(reports["uv"])
    assert uv.min() < 0.6 and np.array(reports["ev"]).max() > 1.1  # both halves were played
