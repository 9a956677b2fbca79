"""``hcard device serve|list`` and ``hcard play``: the reference device and its host drivers.

The device side lives in :mod:`hcard_device.usb`, the drivers in :mod:`hcard_device.drivers`
(imported when a command runs, so ``hcard`` starts fast without them).
"""

from __future__ import annotations

from pathlib import Path

import click

from hcard.atomic import write_atomically
from hcard.card_io import load
from hcard.errors import HcardError
from hcard.track import read_track_csv

DEFAULT_LIST_HOST = "127.0.0.1:3240"


def _host_port(text: str) -> tuple[str, int]:
    """``HOST[:PORT]`` or ``[IPV6][:PORT]`` (port 3240 by default) for ``device list --host``."""
    if text.startswith("["):
        host, _, rest = text[1:].partition("]")
        port = rest.removeprefix(":")
    elif text.count(":") == 1:
        host, _, port = text.partition(":")
    else:  # a name, an IPv4 address or a bare IPv6 address
        host, port = text, ""
    if port and (not port.isdigit() or not 0 < int(port) < 65536):
        raise click.BadParameter(f"{text!r}: the port must be a number in 1..65535",
                                 param_hint="--host")
    return host or "127.0.0.1", int(port) if port else 3240


@click.group("device")
def device() -> None:
    """Serve the reference device over USB/IP, or list the devices that are reachable."""


@device.command("serve")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on (loopback keeps the device off the network).")
@click.option("--port", default=3240, show_default=True, type=click.IntRange(0, 65535),
              help="TCP port of the USB/IP server (0: any free port).")
@click.option("--device", "variant", type=click.Choice(["evita", "coupled"]), default="evita",
              show_default=True, help="E-ViTa (UV) or the coupled UV+EV stimulator.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the simulation's noise.")
def serve(host: str, port: int, variant: str, seed: int) -> None:
    """Serve a simulated device as USB-HID over USB/IP until Ctrl-C or SIGTERM.

    On any Linux host, `usbip attach -r HOST -b 1-1` turns it into a /dev/hidraw device.
    """
    from hcard_device.usb.server import serve as serve_device

    status = serve_device(variant, host, port, seed,
                          echo=lambda message, error: click.echo(message, err=error))
    if status:
        raise SystemExit(status)


@device.command("list")
@click.option("--host", "hosts", multiple=True, metavar="HOST[:PORT]",
              help=f"USB/IP server to ask (repeatable; default {DEFAULT_LIST_HOST}).")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.01),
              help="Longest wait for each server, s.")
def list_devices(hosts: tuple[str, ...], timeout: float) -> None:
    """List reachable devices: hidapi devices with the hcard VID:PID, hcard devices exported
    by USB/IP servers, and the in-process sim:// devices."""
    from hcard_device.drivers import list_devices as find_devices

    servers = [_host_port(text) for text in (hosts or (DEFAULT_LIST_HOST,))]
    listings = find_devices(servers, timeout_s=timeout)
    width = max(len(listing.uri) for listing in listings)
    for listing in listings:
        click.echo(f"{listing.uri.ljust(width)}  {listing.driver:6s} {listing.description}")


@click.command("play")
@click.argument("card", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--device", "uri", required=True, metavar="URI",
              help="Device URI: sim://, usbip://HOST:PORT/BUSID, pyusb://..., hid://VID:PID "
                   "or hid:///dev/hidrawN (see `hcard device list`).")
@click.option("--track", "track_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="Finger track CSV (t_s, x_mm, y_mm[, fn_n, contact]).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording of the device's input reports (.csv).")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.001),
              help="Longest wait for any answer from the device, s.")
def play(card: Path, uri: str, track_path: Path, output: Path, timeout: float) -> None:
    """Upload CARD to a device, drive the finger track, record what the device reports.

    The track is played in real time on hardware and USB/IP devices, as fast as possible on
    sim://. The recording has one row per input report (columns: t_s, sequence, contact, x_mm,
    y_mm, fn_n, f_tl_n, f_tr_n, f_bl_n, f_br_n, lateral_n, amplitude_m, voltage_v, current_a,
    target_uv, target_ev, texture, faults, flags, echo_s; SI units, relative friction).
    """
    from hcard_device.drivers import open_device
    from hcard_device.drivers.play import play as play_track
    from hcard_device.drivers.play import recording_csv, summary

    if output.suffix.lower() != ".csv":
        raise click.BadParameter("the recording must end in .csv", param_hint="--output")
    loaded = load(card)
    track = read_track_csv(track_path)
    with open_device(uri, timeout_s=timeout) as driver:
        result = play_track(driver, loaded, track)
    try:
        write_atomically(output, recording_csv(result.states))
    except OSError as exc:
        raise HcardError(f"{output}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"{output}: {len(result.states)} reports from {uri}")
    for line in summary(result):
        click.echo(f"  {line}")


COMMANDS = [device, play]
