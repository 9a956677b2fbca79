"""``hcard render``: a card along a finger track to target friction frames (CSV or NPZ)."""

from __future__ import annotations

import io
from pathlib import Path

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
from hcard.track import read_track_csv

PROGRESS_FRAMES = 2_000_000
"""Show a progress bar when a rendering has more frames than this."""


def frames_to_csv(frames: Frames) -> bytes:
    """CSV bytes with columns t_s, uv, ev, friction, contact, texture (spec/track-format.md).

    Floats are written in their shortest round-trip form (rule O1), so reading the CSV back
    gives the rendered numbers exactly.
    """
    columns = [
        map(repr, frames.t.tolist()),
        map(repr, frames.uv.tolist()),
        map(repr, frames.ev.tolist()),
        map(repr, frames.friction.tolist()),
        map(str, frames.contact.astype(int).tolist()),
        map(str, frames.texture.astype(int).tolist()),
    ]
    rows = (",".join(cells) for cells in zip(*columns, strict=True))
    return ("t_s,uv,ev,friction,contact,texture\n" + "\n".join(rows) + "\n").encode()


def frames_to_npz(frames: Frames) -> bytes:
    """NPZ bytes with arrays t_s, uv, ev, friction (float64), contact (bool), texture (int32)."""
    buffer = io.BytesIO()
    np.savez_compressed(
        buffer,
        t_s=frames.t,
        uv=frames.uv,
        ev=frames.ev,
        friction=frames.friction,
        contact=frames.contact.astype(bool),
        texture=frames.texture.astype(np.int32),
    )
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
def render(card: Path, track_path: Path, output: Path, frame_rate: float, band_limit: float,
           dead_reckoning: float, mode: str) -> None:
    """Render CARD along a finger track into target relative friction per channel."""
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
    data = frames_to_npz(frames) if suffix == ".npz" else frames_to_csv(frames)
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


COMMANDS = [render]
