"""``hcard render``: a card along a finger track to target friction frames (CSV or NPZ), and
with ``--profile`` the actuator commands a device profile gives for them."""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from hcard.atomic import write_atomically
from hcard.card_io import load
from hcard.errors import HcardError
from hcard.render import Frames, Renderer, RenderOptions
from hcard.render.options import (
    DEFAULT_BAND_LIMIT_HZ,
    DEFAULT_DEAD_RECKONING_S,
    DEFAULT_FRAME_RATE_HZ,
)
from hcard.track import FingerTrack, read_track_csv

if TYPE_CHECKING:
    from hcard.physics.actuation import ActuatorCommands

PROGRESS_FRAMES = 2_000_000
"""Show a progress bar when a rendering has more frames than this."""


def finger_state(track: FingerTrack, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The finger's speed (m/s, of the track segment each frame falls in; 0 out of contact)
    and normal force (N, interpolated) at the frame times ``t`` (s)."""
    speed_mm_s = np.zeros(len(track))
    if len(track) > 1:
        dt = np.diff(track.t)
        moving = track.contact[1:] & track.contact[:-1] & (dt > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            speed_mm_s[:-1] = np.where(moving, np.hypot(np.diff(track.x), np.diff(track.y)) / dt,
                                       0.0)
    segment = np.clip(np.searchsorted(track.t, t, side="right") - 1, 0, len(track) - 1)
    touching = track.contact[segment]
    speed = np.where(touching, speed_mm_s[segment] * 1e-3, 0.0)
    force = np.where(touching, np.maximum(np.interp(t, track.t, track.fn), 0.0), 0.0)
    return speed, force


def _columns(frames: Frames, commands: ActuatorCommands | None) -> list[tuple[str, np.ndarray]]:
    columns = [("t_s", frames.t), ("uv", frames.uv), ("ev", frames.ev),
               ("friction", frames.friction), ("contact", frames.contact.astype(int)),
               ("texture", frames.texture.astype(int))]
    if commands is not None:
        columns += [
            ("amplitude_m", commands.amplitude), ("voltage_v", commands.voltage),
            ("rendered_uv", commands.uv), ("rendered_ev", commands.ev),
        ]
    return columns


def frames_to_csv(frames: Frames, commands: ActuatorCommands | None = None) -> bytes:
    """CSV bytes with columns t_s, uv, ev, friction, contact, texture (spec/track-format.md),
    and with ``commands`` amplitude_m, voltage_v, rendered_uv, rendered_ev.

    Floats are written in their shortest round-trip form (rule O1), so reading the CSV back
    gives the rendered numbers exactly.
    """
    columns = _columns(frames, commands)
    cells = [map(str, values.tolist()) if values.dtype.kind == "i" else map(repr, values.tolist())
             for _, values in columns]
    rows = (",".join(row) for row in zip(*cells, strict=True))
    header = ",".join(name for name, _ in columns)
    return (header + "\n" + "\n".join(rows) + "\n").encode()


def frames_to_npz(frames: Frames, commands: ActuatorCommands | None = None) -> bytes:
    """NPZ bytes with arrays t_s, uv, ev, friction (float64), contact (bool), texture (int32),
    and with ``commands`` amplitude_m, voltage_v, rendered_uv, rendered_ev (float64)."""
    arrays = dict(_columns(frames, commands))
    arrays["contact"] = frames.contact.astype(bool)
    arrays["texture"] = frames.texture.astype(np.int32)
    buffer = io.BytesIO()
    np.savez_compressed(buffer, **arrays)
    return buffer.getvalue()


@click.command()
@click.argument("card", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--track", "track_path", required=True,
              type=click.Path(dir_okay=False, path_type=Path),
              help="Finger track CSV (t_s, x_mm, y_mm[, fn_n, contact]; spec/track-format.md).")
@click.option("-o", "--output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Output file: .csv or .npz.")
@click.option("--frame-rate", default=DEFAULT_FRAME_RATE_HZ, show_default=True, type=float,
              help="Output frames per second, Hz.")
@click.option("--band-limit", default=DEFAULT_BAND_LIMIT_HZ, show_default=True, type=float,
              help="Components at or above this temporal frequency are silenced, Hz.")
@click.option("--dead-reckoning", default=DEFAULT_DEAD_RECKONING_S, show_default=True,
              type=float, help="Longest extrapolation past the last touch sample, s.")
@click.option("--mode", type=click.Choice(["hybrid", "position-only"]), default="hybrid",
              show_default=True, help="Hybrid control, or the classic position-only baseline.")
@click.option("--profile", "profile_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Device profile (hcard-device-profile/2): add the actuator commands it gives "
                   "for the targets at the track's speed and force (amplitude_m, voltage_v) and "
                   "the friction it predicts for them (rendered_uv, rendered_ev).")
def render(card: Path, track_path: Path, output: Path, frame_rate: float, band_limit: float,
           dead_reckoning: float, mode: str, profile_path: Path | None) -> None:
    """Render CARD along a finger track into target relative friction per channel.

    With --profile, also the commands a device with that profile would play, the profile's
    effects and limits included (the clipping is summarised).
    """
    from hcard.physics.profile import DeviceProfile

    profile = DeviceProfile.load(profile_path) if profile_path is not None else None
    suffix = output.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise click.BadParameter("the output must end in .csv or .npz", param_hint="--output")
    loaded = load(card)
    track = read_track_csv(track_path)
    try:
        options = RenderOptions(frame_rate_hz=frame_rate, band_limit_hz=band_limit,
                                dead_reckoning_s=dead_reckoning, mode=mode)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    renderer = Renderer(loaded, options)
    total = int(track.duration_s * frame_rate) + 1
    if total > PROGRESS_FRAMES:
        stderr = click.get_text_stream("stderr")
        with click.progressbar(length=total, label="rendering", file=stderr) as bar:
            done = [0]

            def advance(frames_done: int, _total: int) -> None:
                bar.update(frames_done - done[0])
                done[0] = frames_done

            frames = renderer.render(track, progress=advance)
    else:
        frames = renderer.render(track)
    commands = None
    if profile is not None:
        speed, force = finger_state(track, frames.t)
        commands = profile.actuate(frames.uv, frames.ev, speed, force)
    data = (frames_to_npz(frames, commands) if suffix == ".npz"
            else frames_to_csv(frames, commands))
    try:
        write_atomically(output, data)
    except OSError as exc:
        raise HcardError(f"{output}: cannot write ({exc.strerror or exc})") from None
    in_contact = float(np.mean(frames.contact)) if len(frames) else 0.0
    click.echo(
        f"{output}: {len(frames)} frames at {frame_rate:g} Hz over {track.duration_s:.3f} s "
        f"({mode}); finger on a texture {100 * in_contact:.0f}% of the time; friction "
        f"{frames.friction.min():.3f}..{frames.friction.max():.3f}"
    )
    if commands is not None:
        click.echo(f"  profile {profile.name}: amplitude up to {commands.amplitude.max() * 1e6:.3g}"
                   f" um, voltage up to {commands.voltage.max():.4g} V")
        for line in commands.summary().splitlines():
            click.echo(f"  {line}")


COMMANDS = [render]
