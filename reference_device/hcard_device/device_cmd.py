"""``hcard device serve|list|synthesize`` and ``hcard play``: the reference device, its host
drivers, and synthetic tribometer recordings.

The device side lives in :mod:`hcard_device.usb`, the drivers in :mod:`hcard.device`
(imported when a command runs). :mod:`hcard_device.commands` contributes the commands to
``hcard``, which imports this module only when one of them runs.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import click

from hcard.card_io import load
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.verbosity import verbosity_options
from hcard.errors import HcardError, UsageError
from hcard.file_errors import write_failure
from hcard.terminal_text import printable
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


def hidden_effect_options(where: str) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """``--effect``, ``--effect-param`` and ``--list-effects``: effects hidden ``where``."""
    def decorate(command: Callable[..., None]) -> Callable[..., None]:
        for option in reversed((
            click.option("--effect", "effect_names", multiple=True, metavar="NAME",
                         help=f"Hide a physical effect {where} (repeatable; see "
                              "--list-effects)."),
            click.option("--effect-param", "assignments", multiple=True,
                         metavar="EFFECT.PARAM=VALUE",
                         help="True value of a hidden effect's parameter, units accepted "
                              "(air-layer.air_gap=8um). Repeatable."),
            click.option("--list-effects", is_flag=True,
                         help="List the effects a device can hide and exit."),
        )):
            command = option(command)
        return command
    return decorate


def pressure_option(text: str | None) -> float | None:
    """``--ambient-pressure`` in Pa (None when not given), or a usage error naming it."""
    if text is None:
        return None
    from hcard.device.uri import ambient_pressure

    try:
        return ambient_pressure(text)
    except ValueError as exc:
        raise click.BadParameter(str(exc), param_hint="--ambient-pressure") from None


def echo_hidden_effects() -> None:
    """One line per effect a simulated device can hide: devices, parameters, what it is."""
    from hcard_device.sim.hidden import HIDDEN_EFFECTS

    for effect in HIDDEN_EFFECTS.values():
        params = ", ".join(f"{p.name}={p.default:g} {p.unit}".rstrip() for p in effect.parameters)
        click.echo(f"{effect.name} ({'/'.join(effect.devices)}; {params}): {effect.description}")


def hidden_effects(names: tuple[str, ...], assignments: tuple[str, ...],
                   variant: str | None = None) -> dict[str, dict[str, float]]:
    """The effects of ``--effect`` and ``--effect-param`` (checked for device ``variant``
    when given); a one-line usage error (exit status 2) when malformed or unknown."""
    from hcard_device.sim.hidden import HiddenEffectError, parse_assignments, resolve

    try:
        effects = parse_assignments(names, assignments)
        if variant is not None:
            resolve(variant, effects)
    except HiddenEffectError as exc:
        raise UsageError(f"--effect: {exc}") from None
    return effects


@click.group("device")
@verbosity_options
def device() -> None:
    """Serve the reference device over USB/IP, or list devices.

    \b
    Examples:
      hcard device serve --device evita --port 3240
      hcard device serve --device coupled --effect air-layer
      hcard device list
    """


@device.command("serve")
@verbosity_options
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to listen on (loopback keeps the device off the network).")
@click.option("--port", default=3240, show_default=True, type=click.IntRange(0, 65535),
              help="TCP port of the USB/IP server (0: any free port).")
@click.option("--device", "variant", type=click.Choice(["evita", "coupled"]), default="evita",
              show_default=True, help="E-ViTa (UV) or the coupled UV+EV stimulator.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the simulation's noise.")
@click.option("--ambient-pressure", "ambient_pressure", default=None, metavar="PRESSURE",
              help="Air pressure around the plate, units accepted (50kPa; default one "
                   "atmosphere); acts only through a hidden squeeze-film-share.")
@hidden_effect_options("in the hardware; nothing the device reports names it")
def serve(host: str, port: int, variant: str, seed: int, ambient_pressure: str | None,
          effect_names: tuple[str, ...], assignments: tuple[str, ...],
          list_effects: bool) -> None:
    """Serve a simulated device as USB-HID over USB/IP until Ctrl-C or SIGTERM.

    On any Linux host, `usbip attach -r HOST -b 1-1` turns it into a /dev/hidraw device.
    With --effect the hardware hides a physical effect from its own profile, for a calibration
    to find from recordings alone (sim://...?effect=NAME does the same in process); several
    --effect options hide several at once. --list-effects lists them with their devices and
    true (default) parameters: the calibration library's effects (load-index,
    occlusion-drift, actuator-bandwidth, charge-leakage, ultrasonic-speed, air-layer,
    skin-recovery, squeeze-film-share, finger-geometry) and two that no library effect
    explains (plate-load-damping, force-sensor-resonance).

    \b
    Examples:
      hcard device serve
      hcard device serve --device coupled --port 0
      hcard device serve --device coupled --effect air-layer --effect-param air-layer.air_gap=8um
      hcard device serve --effect force-sensor-resonance --effect plate-load-damping
      hcard device serve --effect squeeze-film-share --ambient-pressure 50kPa
    """
    from hcard_device.usb.server import serve as serve_device

    if list_effects:
        echo_hidden_effects()
        return
    effects = hidden_effects(effect_names, assignments, variant)
    pressure = pressure_option(ambient_pressure)
    status = serve_device(variant, host, port, seed, effects=effects,
                          echo=lambda message, error: click.echo(message, err=error),
                          ambient_pressure_pa=pressure)
    if status:
        raise SystemExit(status)


@device.command("list")
@verbosity_options
@click.option("--host", "hosts", multiple=True, metavar="HOST[:PORT]",
              help=f"USB/IP server to ask (repeatable; default {DEFAULT_LIST_HOST}).")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.01),
              help="Longest wait for each server, s.")
def list_devices(hosts: tuple[str, ...], timeout: float) -> None:
    """List reachable devices: hidapi devices with the hcard VID:PID, hcard devices exported
    by USB/IP servers, and the in-process sim:// devices.

    \b
    Examples:
      hcard device list
      hcard device list --host 192.168.1.20 --host lab-pc:3241 --timeout 3
    """
    from hcard.device import list_devices as find_devices

    servers = [_host_port(text) for text in (hosts or (DEFAULT_LIST_HOST,))]
    listings = find_devices(servers, timeout_s=timeout)
    width = max(len(listing.uri) for listing in listings)
    for listing in listings:
        click.echo(f"{listing.uri.ljust(width)}  {listing.driver:6s} {listing.description}")


class SynthesizeUsageError(UsageError):
    """A bad option of ``hcard device synthesize`` (one line, exit status 2)."""


VARIANT_OF_CLASS = {"uv": "evita", "ev": "coupled", "coupled": "coupled"}
"""The reference device that plays each device class's protocol."""
RECORDING = "recording.csv"
"""File name of the recording ``hcard device synthesize`` writes."""


@device.command("synthesize")
@verbosity_options
@click.option("--device", "device_class", type=click.Choice(["uv", "ev", "coupled"]),
              default="uv", show_default=True,
              help="uv: E-ViTa (amplitude); ev: coupled stimulator, plate off (voltage); "
                   "coupled: both.")
@click.option("--uri", metavar="URI",
              help="Device to play on (default: sim://evita or sim://coupled in this process, "
                   "with the hidden effects); any device URI, e.g. a served device.")
@hidden_effect_options("in the simulated hardware of sim:// (a served device hides its own)")
@click.option("--duration", default="60s", show_default=True, help="Length of the protocol.")
@click.option("--seed", default=0, show_default=True, type=int,
              help="Seed of the protocol's order and of the simulation's noise.")
@click.option("-o", "--output", type=click.Path(file_okay=False, path_type=Path),
              help="Directory for the plan and recording.csv (with its .json sidecar).")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.001),
              help="Longest wait for any answer from the device, s.")
def synthesize(device_class: str, uri: str | None, effect_names: tuple[str, ...],
               assignments: tuple[str, ...], duration: str, seed: int, output: Path | None,
               timeout: float, list_effects: bool) -> None:
    """Record the calibration protocol played on a device: synthetic calibration data that
    went through the firmware, the plate loop, the amplifier and the protocol.

    Writes the plan of `hcard calibrate plan` (protocol and verification cards and tracks)
    and OUTPUT/recording.csv with its sidecar, in the measurement format. Nothing in them
    names the hidden effects.

    \b
    Examples:
      hcard device synthesize --device uv -o synth/
      hcard device synthesize --device ev --effect air-layer --duration 30s -o synth/
      hcard device synthesize --device coupled --uri usbip://127.0.0.1:3240/1-1 -o synth/
    """
    from urllib.parse import urlencode

    from hcard.calibration.measurement import write_measurement
    from hcard.calibration.plan import protocol, verification
    from hcard.cli.calibrate_cmd import write_plan
    from hcard.cli.options import quantity_option
    from hcard.device import open_device
    from hcard.device.play import play as play_track
    from hcard.device.play_summary import summary
    from hcard.device.recording import recording
    from hcard.device.uri import parse_uri

    if list_effects:
        echo_hidden_effects()
        return
    if output is None:
        raise SynthesizeUsageError("missing option -o/--output (the output directory)")
    effects = hidden_effects(effect_names, assignments)
    if uri is not None and effects:
        raise SynthesizeUsageError(
            "--effect hides an effect in the simulated device of sim://; to hide one in a "
            "served device, start it with `hcard device serve --effect NAME`")
    if uri is None:
        query = {"seed": str(seed)}
        if effects:
            query["effect"] = ",".join(effects)
            query.update({f"{name}.{key}": repr(value) for name, values in effects.items()
                          for key, value in values.items()})
        uri = f"sim://{VARIANT_OF_CLASS[device_class]}?{urlencode(query)}"
    parse_uri(uri)  # a bad URI or an effect the device cannot have: before anything is written
    seconds = quantity_option(duration, "s", "--duration")
    plan = protocol(device_class, duration_s=seconds, seed=seed)
    check = verification(device_class, seed=seed + 1)
    write_plan(output, device_class, plan, check)
    click.echo(f"playing the {device_class} protocol ({plan.track.t[-1]:.1f} s, "
               f"{len(plan.sessions)} sessions) on {uri}")
    with open_device(uri, timeout_s=timeout) as driver:
        result = play_track(driver, plan.card, plan.track, whole_session=True)
    path = output / RECORDING
    try:
        write_measurement(recording(result, track_path=str(output / "protocol.csv"),
                                    card_path=str(output / "protocol.hcard")), path)
    except OSError as exc:
        raise HcardError(write_failure(path, exc)) from None
    click.echo(f"{path}: {len(result.states)} reports")
    for line in summary(result):
        click.echo(printable(f"  {line}"))


@click.command("play")
@verbosity_options
@click.argument("card", type=INPUT_FILE)
@click.option("--device", "uri", required=True, metavar="URI",
              help="Device URI: sim://, usbip://HOST:PORT/BUSID, pyusb://..., hid://VID:PID "
                   "or hid:///dev/hidrawN (see `hcard device list`).")
@click.option("--track", "track_path", required=True, type=INPUT_FILE,
              help="Finger track CSV (t_s, x_mm, y_mm[, fn_n, contact]).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording (.csv, plus its .csv.json sidecar), in the measurement format.")
@click.option("--profile", "profile_path", type=INPUT_FILE,
              help="Device profile to render with (hcard-device-profile/2, e.g. the "
                   "profile.json of `hcard calibrate`); default: the device's own.")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.001),
              help="Longest wait for any answer from the device, s.")
@click.option("--ambient-pressure", "ambient_pressure", default=None, metavar="PRESSURE",
              help="The air pressure around the plate as measured during the play, e.g. "
                   "101.3kPa or 0.5atm: kept in the recording's sidecar (ambient_pressure_pa), "
                   "where a calibration reads it (squeeze-film share, Eq. 2.10).")
def play(card: Path, uri: str, track_path: Path, output: Path, profile_path: Path | None,
         timeout: float, ambient_pressure: str | None) -> None:
    """Play CARD on a device along a finger track and record it.

    The track is played in real time on hardware and USB/IP devices, as fast as possible on
    sim://. The recording is a measurement file (spec/measurement-format.md): one row per
    input report with the device's columns (measured forces, amplitude, voltage, targets,
    faults; SI units) and a sidecar with the conditions the device knows, so `hcard calibrate`
    reads it as it is. The summary ends with the rendered friction error against the card's
    target, from the measured lateral force.

    A recording is written only for a complete session: when another host's session is live
    (device busy), when this session is lost to another host (taken over, or the card
    replaced; protocol 1.2, spec section 14) or when the device's reports stop, play exits
    with status 1 and the reason, and writes nothing (an earlier file at OUTPUT is kept).

    \b
    Examples:
      hcard play card.hcard --device sim://evita --track stroke.csv -o rec.csv
      hcard play card.hcard --device usbip://127.0.0.1:3240/1-1 --track stroke.csv -o rec.csv
    """
    from hcard.device import PlayTooLong
    from hcard.device.play import check_play_length
    from hcard.device.play_summary import summary
    from hcard.device.record_play import play_and_record
    from hcard.physics.profile import DeviceProfile
    from hcard.physics.profile_format import read_profile_bytes

    if output.suffix.lower() != ".csv":
        raise click.BadParameter("the recording must end in .csv", param_hint="--output")
    folder = output.parent if str(output.parent) else Path(".")
    if not folder.is_dir():  # checked before the device plays: the session is not lost
        raise HcardError(f"{output}: cannot write (no directory {folder})")
    pressure_pa = pressure_option(ambient_pressure)
    loaded = load(card)
    track = read_track_csv(track_path)
    try:
        check_play_length(track)
    except PlayTooLong as exc:
        raise HcardError(f"{track_path}: {exc}") from None
    profile_bytes = None
    if profile_path is not None:
        profile_bytes = read_profile_bytes(profile_path)
        DeviceProfile.from_json(profile_bytes, source=str(profile_path))  # checked before use
    result = play_and_record(uri, loaded, track, output, card_path=str(card),
                             track_path=str(track_path), timeout_s=timeout,
                             profile=profile_bytes, ambient_pressure_pa=pressure_pa)
    click.echo(f"{output}: {len(result.states)} reports from {uri}")
    for line in summary(result):
        click.echo(printable(f"  {line}"))


COMMANDS = [device, play]
