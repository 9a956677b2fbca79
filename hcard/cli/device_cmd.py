"""``hcard device serve|list|synthesize`` and ``hcard play``: the reference device, its host
drivers, and synthetic tribometer recordings.

The device side lives in :mod:`hcard_device.usb`, the drivers in :mod:`hcard_device.drivers`
(imported when a command runs, so ``hcard`` starts fast without them).
"""

from __future__ import annotations

from pathlib import Path

import click

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
@click.option("--effect", "effect_names", multiple=True, metavar="NAME",
              help="Hide a physical effect in the hardware (repeatable; see --list-effects). "
                   "Nothing the device reports names it.")
@click.option("--effect-param", "assignments", multiple=True, metavar="EFFECT.PARAM=VALUE",
              help="True value of a hidden effect's parameter, units accepted "
                   "(air-layer.air_gap=8um). Repeatable.")
@click.option("--list-effects", is_flag=True, help="List the effects a device can hide and exit.")
def serve(host: str, port: int, variant: str, seed: int, effect_names: tuple[str, ...],
          assignments: tuple[str, ...], list_effects: bool) -> None:
    """Serve a simulated device as USB-HID over USB/IP until Ctrl-C or SIGTERM.

    On any Linux host, `usbip attach -r HOST -b 1-1` turns it into a /dev/hidraw device.
    With --effect the hardware hides a physical effect from its own profile, for a calibration
    to find from recordings alone (sim://...?effect=NAME does the same in process).
    """
    from hcard_device.sim.hidden import HIDDEN_EFFECTS, HiddenEffectError, parse_assignments
    from hcard_device.usb.server import serve as serve_device

    if list_effects:
        for effect in HIDDEN_EFFECTS.values():
            params = ", ".join(f"{p.name}={p.default:g} {p.unit}".rstrip()
                               for p in effect.parameters)
            click.echo(f"{effect.name} ({'/'.join(effect.devices)}; {params}): "
                       f"{effect.description}")
        return
    try:
        effects = parse_assignments(effect_names, assignments)
    except HiddenEffectError as exc:
        raise HcardError(f"--effect: {exc}") from None
    status = serve_device(variant, host, port, seed, effects=effects,
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


class SynthesizeUsageError(HcardError):
    """A bad option of ``hcard device synthesize`` (one line, exit status 1)."""


def _effect_assignment(text: str) -> tuple[str, str, str]:
    """``EFFECT.PARAM=VALUE`` of ``--effect-param`` as its three texts."""
    name, equals, value = text.partition("=")
    effect, dot, parameter = name.strip().rpartition(".")
    if not equals or not dot or not effect or not parameter or not value.strip():
        raise SynthesizeUsageError(f"--effect-param {text!r}: expected EFFECT.PARAM=VALUE "
                                   "(charge-leakage.time_constant=10ms)")
    return effect, parameter, value.strip()


@device.command("synthesize")
@click.option("--device", "variant", type=click.Choice(["uv", "ev", "coupled"]), default="uv",
              show_default=True,
              help="uv: E-ViTa (amplitude); ev: coupled stimulator, plate off (voltage); "
                   "coupled: both.")
@click.option("--effect", "effect_names", multiple=True, metavar="NAME",
              help="Switch on a hidden physical effect (repeatable; see --list-effects).")
@click.option("--effect-param", "assignments", multiple=True, metavar="EFFECT.PARAM=VALUE",
              help="True value of an effect's parameter, units accepted "
                   "(charge-leakage.time_constant=10ms). Repeatable.")
@click.option("--noise", default="2mN", show_default=True,
              help="Standard deviation of the lateral and normal force noise.")
@click.option("--drift", default="0N", show_default=True,
              help="Peak-to-peak drift of the lateral force offset per recording.")
@click.option("--duration", default="60s", show_default=True, help="Length of each recording.")
@click.option("--pressure", "pressures", multiple=True, metavar="PRESSURE",
              help="Ambient pressure, one recording each (repeatable; default 101325 Pa).")
@click.option("--seed", default=0, show_default=True, type=int, help="Seed of every draw.")
@click.option("-o", "--output", type=click.Path(file_okay=False, path_type=Path),
              help="Directory for rec_<i>.csv and their .json sidecars.")
@click.option("--list-effects", is_flag=True, help="List the effect names and exit.")
def synthesize(variant: str, effect_names: tuple[str, ...], assignments: tuple[str, ...],
               noise: str, drift: str, duration: str, pressures: tuple[str, ...], seed: int,
               output: Path | None, list_effects: bool) -> None:
    """Synthesize tribometer recordings of the simulated finger with hidden physical effects.

    Writes one recording per pressure (OUTPUT/rec_<i>.csv plus its sidecar) in the format of
    spec/measurement-format.md; nothing in them names the effects.
    """
    from hcard.calibration.measurement import write_measurement
    from hcard.physics.units import UnitError, parse_quantity
    from hcard_device.sim.tribometer import Protocol, available_effects, effect_parameters
    from hcard_device.sim.tribometer import synthesize as run

    known = available_effects()
    if list_effects:
        for name in known:
            params = ", ".join(f"{p.name}={p.default:g}{p.unit}" for p in effect_parameters(name))
            click.echo(f"{name}  ({params})")
        return
    if output is None:
        raise SynthesizeUsageError("missing option -o/--output (the output directory)")

    def quantity(text: str, unit: str, option: str) -> float:
        try:
            return parse_quantity(text, unit)
        except UnitError as exc:
            raise SynthesizeUsageError(f"{option}: {exc}") from None

    for name in effect_names:
        if name not in known:
            raise SynthesizeUsageError(
                f"--effect: unknown effect {name!r}; known: {', '.join(known)}"
            )
    effects: dict[str, dict[str, float]] = {name: {} for name in effect_names}
    for text in assignments:
        effect, parameter, value = _effect_assignment(text)
        if effect not in effects:
            raise SynthesizeUsageError(f"--effect-param {text!r}: effect {effect!r} is not "
                                       f"switched on (add --effect {effect})")
        units = {p.name: p.unit for p in effect_parameters(effect)}
        if parameter not in units:
            raise SynthesizeUsageError(f"--effect-param {text!r}: effect {effect} has no "
                                       f"parameter {parameter!r}; its parameters: "
                                       f"{', '.join(units)}")
        effects[effect][parameter] = quantity(value, units[parameter], "--effect-param")
    noise_n = quantity(noise, "N", "--noise")
    drift_n = quantity(drift, "N", "--drift")
    protocol_changes: dict[str, object] = {"duration_s": quantity(duration, "s", "--duration")}
    if pressures:
        protocol_changes["pressures_pa"] = tuple(
            quantity(p, "Pa", "--pressure") for p in pressures
        )
    try:
        protocol = Protocol(**protocol_changes)  # type: ignore[arg-type]
        recordings = run(variant, effects, protocol=protocol, lateral_noise_n=noise_n,
                         normal_noise_n=noise_n, drift_n=drift_n, seed=seed)
    except ValueError as exc:
        raise HcardError(str(exc)) from None
    try:
        output.mkdir(parents=True, exist_ok=True)
        for index, recording in enumerate(recordings):
            path = output / f"rec_{index}.csv"
            write_measurement(recording, path)
            click.echo(f"{path}: {len(recording)} samples, {recording.conditions['device']}, "
                       f"{recording.conditions['ambient_pressure_pa']:g} Pa")
    except OSError as exc:
        raise HcardError(f"{output}: cannot write ({exc.strerror or exc})") from None


@click.command("play")
@click.argument("card", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--device", "uri", required=True, metavar="URI",
              help="Device URI: sim://, usbip://HOST:PORT/BUSID, pyusb://..., hid://VID:PID "
                   "or hid:///dev/hidrawN (see `hcard device list`).")
@click.option("--track", "track_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="Finger track CSV (t_s, x_mm, y_mm[, fn_n, contact]).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Recording (.csv, plus its .csv.json sidecar), in the measurement format.")
@click.option("--profile", "profile_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Device profile to render with (hcard-device-profile/2, e.g. the "
                   "profile.json of `hcard calibrate`); default: the device's own.")
@click.option("--timeout", default=1.0, show_default=True, type=click.FloatRange(min=0.001),
              help="Longest wait for any answer from the device, s.")
def play(card: Path, uri: str, track_path: Path, output: Path, profile_path: Path | None,
         timeout: float) -> None:
    """Upload CARD to a device, drive the finger track, record what the device reports.

    The track is played in real time on hardware and USB/IP devices, as fast as possible on
    sim://. The recording is a measurement file (spec/measurement-format.md): one row per
    input report with the device's columns (measured forces, amplitude, voltage, targets,
    faults; SI units) and a sidecar with the conditions the device knows, so `hcard calibrate`
    reads it as it is. The summary ends with the rendered friction error against the card's
    target, from the measured lateral force.
    """
    from hcard.calibration.measurement import write_measurement
    from hcard.physics.profile import DeviceProfile
    from hcard_device.drivers import open_device
    from hcard_device.drivers.play import play as play_track
    from hcard_device.drivers.play import summary
    from hcard_device.drivers.recording import recording

    if output.suffix.lower() != ".csv":
        raise click.BadParameter("the recording must end in .csv", param_hint="--output")
    loaded = load(card)
    track = read_track_csv(track_path)
    profile_bytes = None
    if profile_path is not None:
        profile_bytes = read_profile_bytes(profile_path)
        DeviceProfile.from_json(profile_bytes, source=str(profile_path))  # checked before use
    with open_device(uri, timeout_s=timeout) as driver:
        result = play_track(driver, loaded, track, profile=profile_bytes)
    try:
        write_measurement(recording(result, track_path=str(track_path), card_path=str(card)),
                          output)
    except ValueError as exc:
        raise HcardError(f"{output}: {exc}") from None
    except OSError as exc:
        raise HcardError(f"{output}: cannot write ({exc.strerror or exc})") from None
    click.echo(f"{output}: {len(result.states)} reports from {uri}")
    for line in summary(result):
        click.echo(f"  {line}")


def read_profile_bytes(path: Path) -> bytes:
    """The bytes of a profile file; a missing or unreadable file is a one-line error."""
    from hcard.physics.profile import ProfileError

    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise ProfileError(f"{path}: no such file") from None
    except OSError as exc:
        raise ProfileError(f"{path}: cannot read ({exc.strerror or exc})") from None


COMMANDS = [device, play]
