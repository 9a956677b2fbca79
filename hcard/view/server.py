"""The view server: the page and its JSON API on 127.0.0.1, standard library only.

Routes (JSON in and out; an error is ``{"error": MESSAGE}`` with status 400, 404 or 409):

- ``GET /``, ``GET /static/NAME``: the page (``hcard/view/static/``).
- ``GET /api/cards``: every card (:func:`hcard.view.model.card_json`) and what the server
  offers: ``error_map`` (a source image was given), ``device`` (the URI to play on, or null)
  and ``play_disabled_reason``.
- ``GET /api/texture?card=I&texture=J&length_mm=L``: the texture's spatial profile over ``L``
  mm (default 20) and its spectrum (:func:`hcard.view.model.texture_profile`).
- ``POST /api/render``: ``{"card": I, "path": [[x, y], ...], "speed_mm_s": V}`` (or
  ``points``/``track_csv``, optional ``frame_rate_hz``): the core renderer's frames along the
  stroke (:func:`hcard.view.model.render_json`).
- ``GET /api/diff?a=I&b=J``: the per-taxtel difference ``b - a``
  (:func:`hcard.view.model.card_difference`).
- ``GET /api/error-map``: the first card's error against the source image, in JND (404
  without ``--source``).
- ``POST /api/play``: the stroke of a render request played on the ``--device`` (409 without
  one): the device's summary and its reports.

The server listens on 127.0.0.1 only and loads nothing from the network.
"""

from __future__ import annotations

import json
import threading
from collections.abc import Sequence
from dataclasses import dataclass, field
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import numpy as np

from hcard.errors import HcardError
from hcard.v1 import card_pb2 as pb
from hcard.view import model

HOST = "127.0.0.1"
MAX_BODY_BYTES = 8 << 20
"""Largest request body, bytes (a drawn stroke is a few kB; a track file up to this)."""
STATIC_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                ".css": "text/css; charset=utf-8"}
NO_DEVICE_REASON = ("no device: start hcard view with --device URI (for example "
                    "--device sim://coupled) to play strokes on one")


@dataclass
class ViewState:
    """What the server serves.

    Attributes:
        cards: the cards, in command-line order.
        names: their file names.
        source: the first card's source image, or None.
        device_uri: the device to play on, or None.
    """

    cards: Sequence[pb.Card]
    names: Sequence[str]
    source: model.SourceImage | None = None
    device_uri: str | None = None
    play_lock: threading.Lock = field(default_factory=threading.Lock)

    def cards_json(self) -> dict[str, Any]:
        return {"cards": [model.card_json(c, n) for c, n in zip(self.cards, self.names,
                                                                 strict=True)],
                "error_map": self.source is not None,
                "device": self.device_uri,
                "play_disabled_reason": None if self.device_uri else NO_DEVICE_REASON}

    def card(self, value: object) -> pb.Card:
        return self.cards[model.card_index(value, self.cards)]

    def texture(self, query: dict[str, str]) -> dict[str, Any]:
        card = self.card(query.get("card", 0))
        texture = card.textures[model.texture_index(query.get("texture", 0), card)]
        return model.texture_profile(texture, float(query.get("length_mm",
                                                              model.DEFAULT_PROFILE_MM)))

    def diff(self, query: dict[str, str]) -> dict[str, Any]:
        if len(self.cards) < 2:
            raise model.ViewRequestError("a difference needs two cards on the command line")
        a, b = self.card(query.get("a", 0)), self.card(query.get("b", 1))
        return model.card_difference(a, b)

    def error_map(self) -> dict[str, Any]:
        if self.source is None:
            raise NotFound("no error map: start hcard view with --source IMAGE, the image the "
                           "first card was encoded from")
        return model.error_map(self.cards[0], self.source)

    def render(self, body: dict[str, Any]) -> dict[str, Any]:
        return model.render_json(self.card(body.get("card", 0)), body)

    def play(self, body: dict[str, Any]) -> dict[str, Any]:
        if self.device_uri is None:
            raise Conflict(NO_DEVICE_REASON)
        card = self.card(body.get("card", 0))
        track = model.request_track(body)
        if not self.play_lock.acquire(blocking=False):
            raise Conflict("the device is playing another stroke")
        try:
            return play_on_device(self.device_uri, card, track)
        finally:
            self.play_lock.release()


class NotFound(model.ViewRequestError):
    """Answered with status 404."""


class Conflict(model.ViewRequestError):
    """Answered with status 409."""


def play_on_device(uri: str, card: pb.Card, track: Any) -> dict[str, Any]:
    """Play ``card`` along ``track`` on the device at ``uri`` through the host library (as
    ``hcard play`` does, without writing a recording): its summary lines and, per STATE
    report, the time since the first (s), the target UV and EV it rendered and the lateral
    force it measured (mN)."""
    import contextlib

    from hcard.device.open import open_device
    from hcard.device.play import play
    from hcard.device.play_summary import summary
    from hcard.device.priority import real_time_host

    with open_device(uri) as driver, \
            real_time_host() if driver.realtime else contextlib.nullcontext():
        result = play(driver, card, track, whole_session=True)
    states = result.states
    stamps = states.field("timestamp_us").astype(np.int64)
    t = np.concatenate(([0], np.cumsum(np.diff(stamps) % (1 << 32)))) * 1e-6 if len(
        states) else np.zeros(0)
    uv = states.field("target_uv_x1e4") / 1e4
    ev = states.field("target_ev_x1e4") / 1e4
    return {"device": uri, "summary": summary(result),
            "reports": {"t_s": t.tolist(), "uv": uv.tolist(), "ev": ev.tolist(),
                        "friction": (uv * ev).tolist(),
                        "lateral_force_mn": states.field("lateral_force_mn").tolist()}}


def static_file(name: str) -> bytes | None:
    """The bytes of the page's file ``name`` (package data of ``hcard.view``), or None."""
    if "/" in name or name.startswith(".") or Path(name).suffix not in STATIC_TYPES:
        return None
    resource = resources.files("hcard.view").joinpath("static").joinpath(name)
    return resource.read_bytes() if resource.is_file() else None


class ViewHandler(BaseHTTPRequestHandler):
    """Routes of the module docstring."""

    server: ViewServer
    server_version = "hcard-view"

    def log_message(self, format: str, *args: Any) -> None:
        if self.server.log_requests:
            super().log_message(format, *args)

    def do_GET(self) -> None:
        url = urlsplit(self.path)
        query = {k: v[-1] for k, v in parse_qs(url.query).items()}
        state = self.server.state
        if url.path in ("/", "/index.html"):
            self._static("index.html")
        elif url.path.startswith("/static/"):
            self._static(url.path.removeprefix("/static/"))
        elif url.path == "/api/cards":
            self._answer(state.cards_json)
        elif url.path == "/api/texture":
            self._answer(lambda: state.texture(query))
        elif url.path == "/api/diff":
            self._answer(lambda: state.diff(query))
        elif url.path == "/api/error-map":
            self._answer(state.error_map)
        else:
            self._json({"error": f"no such page: {url.path}"}, HTTPStatus.NOT_FOUND)

    def do_POST(self) -> None:
        path = urlsplit(self.path).path
        routes = {"/api/render": self.server.state.render, "/api/play": self.server.state.play}
        route = routes.get(path)
        if route is None:
            self._json({"error": f"no such page: {path}"}, HTTPStatus.NOT_FOUND)
            return
        try:
            body = self._body()
        except model.ViewRequestError as exc:
            self._json({"error": str(exc)}, HTTPStatus.BAD_REQUEST)
            return
        self._answer(lambda: route(body))

    def _body(self) -> dict[str, Any]:
        try:
            length = int(self.headers.get("Content-Length", "0"))
        except ValueError:
            raise model.ViewRequestError("bad Content-Length") from None
        if not 0 < length <= MAX_BODY_BYTES:
            raise model.ViewRequestError(f"the request body must be 1..{MAX_BODY_BYTES} bytes "
                                         "of JSON")
        try:
            body = json.loads(self.rfile.read(length))
        except (UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise model.ViewRequestError(f"the request body is not JSON ({exc})") from None
        if not isinstance(body, dict):
            raise model.ViewRequestError("the request body must be a JSON object")
        return body

    def _answer(self, compute: Any) -> None:
        """Send what ``compute()`` returns, or its error: 404/409/400 for a request error, 400
        for another hcard error (a device that refuses a card), 500 for a bug."""
        try:
            value = compute()
        except NotFound as exc:
            self._json({"error": str(exc)}, HTTPStatus.NOT_FOUND)
        except Conflict as exc:
            self._json({"error": str(exc)}, HTTPStatus.CONFLICT)
        except HcardError as exc:
            self._json({"error": str(exc)}, HTTPStatus.BAD_REQUEST)
        except Exception as exc:  # a bug: the page shows it, the server goes on
            self.log_error("internal error: %r", exc)
            self._json({"error": f"internal error ({type(exc).__name__}: {exc}): this is a "
                                 "bug in hcard"}, HTTPStatus.INTERNAL_SERVER_ERROR)
        else:
            self._json(value, HTTPStatus.OK)

    def _json(self, value: Any, status: HTTPStatus) -> None:
        data = json.dumps(value, allow_nan=False).encode()
        self._send(data, "application/json", status)

    def _static(self, name: str) -> None:
        data = static_file(name)
        if data is None:
            self._json({"error": f"no such file: {name}"}, HTTPStatus.NOT_FOUND)
        else:
            self._send(data, STATIC_TYPES[Path(name).suffix], HTTPStatus.OK)

    def _send(self, data: bytes, content_type: str, status: HTTPStatus) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(data)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(data)


class ViewServer(ThreadingHTTPServer):
    """The view's HTTP server on 127.0.0.1 (port 0: any free port)."""

    daemon_threads = True
    allow_reuse_address = False  # a port in use is an error, not a second server on it

    def __init__(self, state: ViewState, port: int = 0, *, log_requests: bool = False) -> None:
        self.state = state
        self.log_requests = log_requests
        super().__init__((HOST, port), ViewHandler)

    @property
    def url(self) -> str:
        return f"http://{HOST}:{self.server_address[1]}/"
