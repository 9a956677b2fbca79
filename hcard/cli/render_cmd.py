"""``hcard render``: a card along a finger track to target friction frames (CSV or NPZ), and
with ``--profile`` the actuator commands a device profile gives for them."""

from __future__ import annotations

import contextlib
import math
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import click
import numpy as np

from hcard.card_io import load
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.csv_rows import format_rows
from hcard.errors import HcardError
from hcard.file_errors import write_failure
from hcard.physics.actuation import (
    ChannelClipping,
    UVModelRange,
    actuate,
    combined_clipping,
    combined_range,
)
from hcard.quantities import M_PER_MM, UM_PER_M
from hcard.render import Frames, Renderer, RenderOptions, RenderTooLong
from hcard.render.finger_speed import TouchSamples, predicted_speed
from hcard.render.options import (
    DEFAULT_BAND_LIMIT_HZ,
    DEFAULT_DEAD_RECKONING_S,
    DEFAULT_FRAME_RATE_HZ,
    RenderMode,
)
from hcard.render.output import frame_writer
from hcard.track import FingerTrack, read_track_csv

if TYPE_CHECKING:
    from hcard.physics.actuation import ActuatorCommands

PROGRESS_FRAMES = 2_000_000
"""Show a progress bar when a rendering has more frames than this."""


def finger_state(track: FingerTrack, t: np.ndarray, horizon_s: float, *,
                 samples: TouchSamples | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The finger's speed (m/s) and normal force (N, interpolated) at the frame times ``t``
    (s), 0 out of contact. The speed is the one a device whose touch samples are the track's
    would compensate for: :func:`~hcard.render.finger_speed.predicted_speed` over at most
    ``horizon_s`` (s, the renderer's dead-reckoning horizon) from the samples up to each frame.
    ``samples``: the track's :class:`~hcard.render.finger_speed.TouchSamples`, made once for
    the blocks of a rendering (their speeds are worked out once)."""
    samples = samples if samples is not None else TouchSamples.of_track(track)
    speed = predicted_speed(samples, t, horizon_s) * M_PER_MM
    segment = np.clip(np.searchsorted(track.t, t, side="right") - 1, 0, len(track) - 1)
    touching = track.contact[segment]
    force = np.where(touching, np.maximum(np.interp(t, track.t, track.normal_force), 0.0), 0.0)
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
    and with ``commands`` amplitude_m, voltage_v, rendered_uv, rendered_ev, in one piece (the
    command writes block by block, :mod:`hcard.render.output`)."""
    columns = _columns(frames, commands)
    return (",".join(name for name, _ in columns) + "\n" + format_rows(columns)).encode()


@click.command()
@verbosity_options
@click.argument("card", type=INPUT_FILE)
@click.option("--track", "track_path", required=True, type=INPUT_FILE,
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
@click.option("--profile", "profile_path", type=INPUT_FILE,
              help="Device profile (hcard-device-profile/2): add the actuator commands it gives "
                   "for the targets at the track's force and the finger speed a device predicts "
                   "from its samples (amplitude_m, voltage_v) and "
                   "the friction it predicts for them (rendered_uv, rendered_ev).")
def render(card: Path, track_path: Path, output: Path, frame_rate: float, band_limit: float,
           dead_reckoning: float, mode: str, profile_path: Path | None) -> None:
    """Render CARD along a finger track into target friction.

    With --profile, also the commands a device with that profile would play, the profile's
    effects and limits included (the clipping is summarised). Frames are written block by
    block (any length in bounded memory), at most 1e8 of them.

    \b
    Examples:
      hcard render card.hcard --track stroke.csv -o frames.csv
      hcard render card.hcard --track stroke.csv -o frames.npz --frame-rate 20000
      hcard render card.hcard --track stroke.csv -o cmds.csv --profile evita.profile.json
    """
    from hcard.physics.profile import DeviceProfile

    profile = DeviceProfile.load(profile_path) if profile_path is not None else None
    suffix = output.suffix.lower()
    if suffix not in (".csv", ".npz"):
        raise click.BadParameter("the output must end in .csv or .npz", param_hint="--output")
    try:  # before the files are read: a bad option costs no reading
        options = RenderOptions(frame_rate_hz=frame_rate, band_limit_hz=band_limit,
                                dead_reckoning_s=dead_reckoning, mode=RenderMode(mode))
    except ValueError as exc:
        raise click.UsageError(str(exc)) from None
    loaded = load(card)
    track = read_track_csv(track_path)
    renderer = Renderer(loaded, options, check=False)  # load() validated it
    try:
        total = renderer.frame_count(track)  # the frame limit, before any work
    except RenderTooLong as exc:  # too large an input, as play says (README: exit status 1)
        raise HcardError(f"{track_path}: t_s: {exc}") from None
    summary = _RenderSummary()
    samples = TouchSamples.of_track(track)
    try:
        with frame_writer(output) as writer, _progress(total) as advance:
            for frames in renderer.blocks(track):
                commands = None
                if profile is not None:
                    speed, force = finger_state(track, frames.t, options.dead_reckoning_s,
                                                samples=samples)
                    commands = actuate(profile, frames.uv, frames.ev, speed, force)
                writer.write(_output_columns(frames, commands, npz=suffix == ".npz"))
                summary.add(frames, commands)
                advance(len(frames))
    except OSError as exc:
        raise HcardError(write_failure(output, exc)) from None
    click.echo(
        f"{output}: {summary.frames} frames at {frame_rate:g} Hz over {track.duration_s:.3f} s "
        f"({mode}); finger on a texture {100 * summary.contact_fraction:.0f}% of the time; "
        f"friction {summary.friction_min:.3f}..{summary.friction_max:.3f}"
    )
    if profile is not None:
        click.echo(f"  profile {profile.name}: amplitude up to "
                   f"{summary.amplitude_max * UM_PER_M:.3g} um, "
                   f"voltage up to {summary.voltage_max:.4g} V")
        for line in summary.profile_lines():
            click.echo(f"  {line}")


def _output_columns(frames: Frames, commands: ActuatorCommands | None,
                    npz: bool) -> list[tuple[str, np.ndarray]]:
    """The columns of one block: integers in the CSV, bool and int32 in the NPZ."""
    columns = _columns(frames, commands)
    if npz:
        kinds = {"contact": frames.contact.astype(bool),
                 "texture": frames.texture.astype(np.int32)}
        columns = [(name, kinds.get(name, values)) for name, values in columns]
    return columns


@contextlib.contextmanager
def _progress(total: int) -> Iterator[Callable[[int], None]]:
    """A progress bar on stderr for renderings of more than :data:`PROGRESS_FRAMES` frames;
    yields the function that advances it by a number of frames."""
    if total <= PROGRESS_FRAMES or quiet():
        yield lambda _frames: None
        return
    with click.progressbar(length=total, label="rendering", file=sys.stderr) as bar:
        yield bar.update


class _RenderSummary:
    """What the command prints about a rendering, gathered block by block."""

    def __init__(self) -> None:
        self.frames = 0
        self.in_contact = 0
        self.friction_min = math.inf
        self.friction_max = -math.inf
        self.amplitude_max = 0.0
        self.voltage_max = 0.0
        self._uv: list[ChannelClipping] = []
        self._ev: list[ChannelClipping] = []
        self._range: list[UVModelRange] = []

    def add(self, frames: Frames, commands: ActuatorCommands | None) -> None:
        if not len(frames):
            return
        friction = frames.friction
        self.frames += len(frames)
        self.in_contact += int(np.count_nonzero(frames.contact))
        self.friction_min = min(self.friction_min, float(friction.min()))
        self.friction_max = max(self.friction_max, float(friction.max()))
        if commands is not None:
            self.amplitude_max = max(self.amplitude_max, float(commands.amplitude.max()))
            self.voltage_max = max(self.voltage_max, float(commands.voltage.max()))
            self._uv.append(commands.uv_clipping)
            self._ev.append(commands.ev_clipping)
            self._range.append(commands.uv_range)

    @property
    def contact_fraction(self) -> float:
        return self.in_contact / self.frames if self.frames else 0.0

    def profile_lines(self) -> list[str]:
        """The profile's clipping and range report over the whole rendering."""
        if not self._uv:
            return []
        return [str(combined_clipping(self._uv)), str(combined_clipping(self._ev)),
                *combined_range(self._range).warnings]


COMMANDS = [render]
