"""A view server in a thread of the test's process, on a free port of 127.0.0.1, and JSON
requests to it with plain urllib."""

from __future__ import annotations

import contextlib
import json
import threading
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import Any

from hcard.view.server import ViewServer, ViewState


@contextlib.contextmanager
def view_server(state: ViewState) -> Iterator[str]:
    """Serve ``state`` on port 0 (any free port) while the block runs; yields the base URL."""
    server = ViewServer(state, 0)
    thread = threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True)
    thread.start()
    try:
        yield server.url
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


def request(url: str, body: dict[str, Any] | None = None) -> tuple[int, Any]:
    """``(status, JSON answer)`` of a GET (``body`` None) or a POST of ``body`` as JSON."""
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method="GET" if body is None else "POST",
                                 headers={"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as answer:
            return answer.status, json.load(answer)
    except urllib.error.HTTPError as exc:
        with exc:
            return exc.code, json.load(exc)
