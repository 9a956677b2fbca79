"""``hcard view``: see and try cards on a local page (:mod:`hcard.view`)."""

from __future__ import annotations

import contextlib
import errno
import signal
from collections.abc import Iterator
from pathlib import Path

import click

from hcard.card_io import load
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.errors import HcardError, UsageError
from hcard.file_errors import os_reason


@click.command("view")
@verbosity_options
@click.argument("cards", nargs=-1, required=True, type=INPUT_FILE)
@click.option("--port", type=click.IntRange(0, 65535), default=0, show_default=True,
              help="Port on 127.0.0.1; 0 takes any free port.")
@click.option("--source", "source", type=INPUT_FILE, default=None,
              help="The image the first CARD was encoded from: show its error map (JND per "
                   "taxtel).")
@click.option("--device", "device_uri", metavar="URI", default=None,
              help="Let the page play strokes on this device (sim://coupled, "
                   "usbip://HOST:PORT/BUSID, hid://...); without it the play button is off.")
@click.option("--open", "open_browser", is_flag=True,
              help="Open the page in the default web browser.")
def view(cards: tuple[Path, ...], port: int, source: Path | None, device_uri: str | None,
         open_browser: bool) -> None:
    """Show each CARD on a local page; draw strokes and render them.

    The page is served on 127.0.0.1 (any free port unless --port says which). It draws each
    card's taxtel map to scale, a texture's spatial profile over a length you set (mm) and
    its spectrum (cycles/mm), and renders a stroke you draw on the surface (or a track CSV
    you load) with hcard's renderer, at the speed you set: the friction a finger would feel
    along it, with the UV and EV drives. Two cards are shown side by side
    with their difference; --source adds the encoder's error map; --device lets the page play
    the stroke on a device. Nothing is loaded from the network. Stop with Ctrl-C.

    \b
    Examples:
      hcard view gratings.hcard
      hcard view gratings.hcard --source examples/gratings.png --open
      hcard view old.hcard new.hcard --port 8765
      hcard view gratings.hcard --device sim://coupled
    """
    from hcard.view.model import load_source
    from hcard.view.server import ViewServer, ViewState

    loaded = [load(path) for path in cards]
    source_image = None
    if source is not None:
        if not source.is_file():
            raise UsageError(f"--source: {source}: no such file")
        source_image = load_source(source, loaded[0])
    if device_uri is not None:
        from hcard.device.open import driver_classes
        from hcard.device.uri import SCHEMES, parse_uri

        try:  # the schemes open_device takes: the host library's and every driver plugin's
            parse_uri(device_uri, schemes=tuple(dict.fromkeys((*SCHEMES, *driver_classes()))))
        except HcardError as exc:
            raise UsageError(f"--device: {exc}") from None
    state = ViewState(loaded, [path.name for path in cards], source_image, device_uri)
    try:
        server = ViewServer(state, port, log_requests=not quiet())
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            raise UsageError(f"--port {port}: the port is in use on 127.0.0.1 (another "
                             "program listens on it); give another, or 0 for any free one"
                             ) from None
        raise HcardError(f"cannot listen on 127.0.0.1:{port}: {os_reason(exc)}") from None
    click.echo(f"hcard view: {server.url} (Ctrl-C stops)")
    if open_browser:
        import webbrowser

        webbrowser.open(server.url)
    try:
        with _stopped_by_signals():
            server.serve_forever()
    except KeyboardInterrupt:
        click.echo("hcard view: stopped", err=True)
    finally:
        server.server_close()


@contextlib.contextmanager
def _stopped_by_signals() -> Iterator[None]:
    """Ctrl-C (SIGINT) and SIGTERM stop the server, whatever disposition the process
    inherited: a command started in the background by a non-interactive shell (a CI script)
    inherits SIGINT ignored, and Python then never raises KeyboardInterrupt; the previous
    handlers are given back on exit."""
    def interrupt(_signum: int, _frame: object) -> None:
        raise KeyboardInterrupt

    previous = {sig: signal.signal(sig, interrupt) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


COMMANDS = [view]
