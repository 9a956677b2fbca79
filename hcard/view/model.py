"""The numbers of the view page: cards as JSON, texture profiles and spectra, strokes rendered
by the core renderer, the difference of two cards and a card's error against its source image.

Every function takes checked cards (:func:`hcard.card_io.load` validated them) and raises
:class:`ViewRequestError` for a request the page should not have made (an index out of range,
a stroke without samples): the server answers it with status 400 and the message.
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hcard.channels import LABEL_OF_VALUE
from hcard.errors import HcardError, ImageError, UsageError
from hcard.limits import RELATIVE_FRICTION_JND
from hcard.rates import TOUCH_RATE_HZ
from hcard.render import Frames, Renderer, RenderOptions
from hcard.track import FingerTrack, make_track, parse_track_csv
from hcard.v1 import card_pb2 as pb

DEFAULT_PROFILE_MM = 20.0
"""Length of a texture's spatial profile unless the page asks for another, mm."""
MAX_PROFILE_MM = 1000.0
"""Longest profile the page may ask for, mm."""
PROFILE_SAMPLES_PER_CYCLE = 16
"""Samples per cycle of the finest spatial component along a profile."""
PROFILE_SAMPLES = (256, 8192)
"""Fewest and most samples of a profile."""
MAX_VIEW_FRAMES = 200_000
"""Most frames one rendering for the page may have (20 s at 10 kHz): the page receives every
frame as JSON, about 100 bytes each."""
DIFF_LATTICE = 8
"""Points per taxtel side at which two cards are compared (sub-cell centres)."""
LOCKING_LABELS = {pb.LOCKING_POSITION: "POSITION", pb.LOCKING_VELOCITY: "VELOCITY",
                  pb.LOCKING_AUTO: "AUTO"}
DOMAIN_LABELS = {pb.DOMAIN_SPATIAL: "SPATIAL", pb.DOMAIN_TEMPORAL: "TEMPORAL"}


class ViewRequestError(UsageError):
    """A request the server answers with status 400 and this message."""


def _index(value: object, count: int, what: str) -> int:
    """``value`` as an index below ``count``; :class:`ViewRequestError` otherwise."""
    try:
        index = int(str(value))
    except ValueError:
        raise ViewRequestError(f"{what} must be an integer, got {value!r}") from None
    if not 0 <= index < count:
        raise ViewRequestError(f"{what} {index} is out of range (0..{count - 1})")
    return index


def card_index(value: object, cards: Sequence[pb.Card]) -> int:
    """The card ``value`` names (its position on the command line, from 0)."""
    return _index(value, len(cards), "card")


def texture_index(value: object, card: pb.Card) -> int:
    """The palette texture ``value`` names."""
    return _index(value, len(card.textures), "texture")


def _number(value: object, what: str, low: float, high: float) -> float:
    """``value`` as a finite number in [low, high]; :class:`ViewRequestError` otherwise."""
    try:
        number = float(str(value)) if not isinstance(value, (int, float)) else float(value)
    except ValueError:
        raise ViewRequestError(f"{what} must be a number, got {value!r}") from None
    if not (math.isfinite(number) and low <= number <= high):
        raise ViewRequestError(f"{what} must be a number in [{low:g}, {high:g}], got {value!r}")
    return number


# --- cards -------------------------------------------------------------------------------


def component_json(component: pb.Component, texture: pb.Texture) -> dict[str, Any]:
    """One component: its triplet, domain, orientation and channel (the texture's when it
    leaves its own unspecified), in the spec's wire units."""
    channel = component.channel or texture.channel
    return {"domain": DOMAIN_LABELS.get(component.domain, str(component.domain)),
            "frequency": component.frequency,
            "unit": "cycles/mm" if component.domain == pb.DOMAIN_SPATIAL else "Hz",
            "amplitude": component.amplitude, "phase_rad": component.phase,
            "orientation_rad": component.orientation,
            "channel": LABEL_OF_VALUE.get(channel, str(channel))}


def card_json(card: pb.Card, name: str) -> dict[str, Any]:
    """What the page draws of a card: surface, grid, per-taxtel texture index (row-major),
    and every texture with its components."""
    grid = card.grid
    return {
        "name": name, "title": card.metadata.title, "description": card.metadata.description,
        "surface": {"width_mm": card.surface.width_mm, "height_mm": card.surface.height_mm},
        "grid": {"cols": grid.cols, "rows": grid.rows,
                 "taxtel_width_mm": grid.taxtel_width_mm,
                 "taxtel_height_mm": grid.taxtel_height_mm,
                 "texture_index": list(grid.texture_index)},
        "textures": [{"index": i, "name": t.name, "baseline": t.baseline,
                      "channel": LABEL_OF_VALUE.get(t.channel, str(t.channel)),
                      "locking": LOCKING_LABELS.get(t.locking, str(t.locking)),
                      "components": [component_json(c, t) for c in t.components]}
                     for i, t in enumerate(card.textures)],
    }


# --- one texture ---------------------------------------------------------------------------


def main_direction(texture: pb.Texture) -> float:
    """Direction of the texture's strongest spatial component (the first of the largest
    amplitude), radians from +x towards +y; 0 without spatial components. The direction of
    ``hcard preview``'s period strips."""
    spatial = [c for c in texture.components if c.domain == pb.DOMAIN_SPATIAL]
    return max(spatial, key=lambda c: c.amplitude).orientation if spatial else 0.0


def texture_profile(texture: pb.Texture, length_mm: float) -> dict[str, Any]:
    """The spatial profile of ``texture`` over ``length_mm`` from the surface origin along its
    main direction ``u`` (:func:`main_direction`), and its spectrum.

    The profile is the texture's target relative friction, position-locked, its temporal
    components left out::

        friction(s) = baseline + sum_c A_c cos(2 pi k_c (u_c . u) s + phase_c)

    (before the channel split of spec rule R11, as ``hcard preview`` draws it). The spectrum
    lists each spatial component at its frequency along ``u``, ``|k_c (u_c . u)|`` cycles/mm,
    and at its own ``k_c``, with its amplitude; temporal components are listed in Hz.
    """
    length = _number(length_mm, "length_mm", 1e-3, MAX_PROFILE_MM)
    theta = main_direction(texture)
    spatial = [c for c in texture.components if c.domain == pb.DOMAIN_SPATIAL]
    along = [c.frequency * math.cos(c.orientation - theta) for c in spatial]
    finest = max((abs(k) for k in along), default=0.0)
    low, high = PROFILE_SAMPLES
    n = int(min(high, max(low, math.ceil(length * finest * PROFILE_SAMPLES_PER_CYCLE) + 1)))
    s_mm = np.linspace(0.0, length, n)
    friction = np.full(n, float(texture.baseline))
    for component, k in zip(spatial, along, strict=True):
        friction += component.amplitude * np.cos(2.0 * np.pi * k * s_mm + component.phase)
    return {
        "length_mm": length, "direction_rad": theta, "s_mm": s_mm.tolist(),
        "friction": friction.tolist(), "baseline": texture.baseline,
        "spectrum": [{"frequency_along": abs(k), "frequency": c.frequency,
                      "amplitude": c.amplitude, "orientation_rad": c.orientation,
                      "channel": component_json(c, texture)["channel"]}
                     for c, k in zip(spatial, along, strict=True)],
        "temporal": [{"frequency_hz": c.frequency, "amplitude": c.amplitude}
                     for c in texture.components if c.domain == pb.DOMAIN_TEMPORAL],
    }


# --- position-locked friction at points ----------------------------------------------------


def texture_at(card: pb.Card, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """The palette index of the taxtel under each point, -1 off the grid."""
    grid = card.grid
    col = np.floor(x_mm / grid.taxtel_width_mm).astype(np.int64)
    row = np.floor(y_mm / grid.taxtel_height_mm).astype(np.int64)
    inside = (col >= 0) & (col < grid.cols) & (row >= 0) & (row < grid.rows)
    index = np.asarray(grid.texture_index, dtype=np.int64)
    return np.where(inside, index[np.where(inside, row * grid.cols + col, 0)], -1)


def friction_at(card: pb.Card, x_mm: np.ndarray, y_mm: np.ndarray) -> np.ndarray:
    """The card's target relative friction at each point, every spatial component
    position-locked (absolute surface coordinates), temporal components left out, before the
    channel split: the card as the image encoder measures its reconstruction error. NaN off
    the grid."""
    which = texture_at(card, x_mm, y_mm)
    out = np.full(np.shape(x_mm), np.nan)
    for i, texture in enumerate(card.textures):
        mask = which == i
        if not mask.any():
            continue
        x, y = x_mm[mask], y_mm[mask]
        value = np.full(x.shape, float(texture.baseline))
        for c in texture.components:
            if c.domain == pb.DOMAIN_SPATIAL:
                kx = c.frequency * math.cos(c.orientation)
                ky = c.frequency * math.sin(c.orientation)
                value += c.amplitude * np.cos(2.0 * np.pi * (kx * x + ky * y) + c.phase)
        out[mask] = value
    return out


def taxtel_lattice(grid: pb.TaxtelGrid, row: int, n: int = DIFF_LATTICE
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(x, y)`` of ``n x n`` sub-cell centres of every taxtel of grid row ``row``, each of
    shape ``(cols, n * n)``, mm."""
    u = (np.arange(n) + 0.5) / n
    cx = (np.arange(grid.cols)[:, None] + u[None, :]) * grid.taxtel_width_mm  # (cols, n)
    y = (row + u) * grid.taxtel_height_mm
    x = np.repeat(cx, n, axis=1)  # x varies slowest within a taxtel
    return x, np.broadcast_to(np.tile(y, n), x.shape)


def card_difference(a: pb.Card, b: pb.Card) -> dict[str, Any]:
    """The difference ``b - a`` on ``a``'s taxtel grid: per taxtel the RMS and the mean of
    ``friction_b - friction_a`` (:func:`friction_at`) over :data:`DIFF_LATTICE` x
    :data:`DIFF_LATTICE` sub-cell centres of the taxtel (relative friction; NaN where ``b``
    has no taxtel at one of them), and whether both cards play textures equal in every field
    there."""
    grid = a.grid
    rms = np.empty((grid.rows, grid.cols))
    mean = np.empty((grid.rows, grid.cols))
    same = np.zeros((grid.rows, grid.cols), dtype=bool)
    for row in range(grid.rows):
        x, y = taxtel_lattice(grid, row)
        delta = friction_at(b, x, y) - friction_at(a, x, y)
        rms[row] = np.sqrt(np.mean(delta**2, axis=1))
        mean[row] = np.mean(delta, axis=1)
        ta, tb = texture_at(a, x, y), texture_at(b, x, y)
        for col in range(grid.cols):
            if np.all(tb[col] == tb[col, 0]) and tb[col, 0] >= 0:
                same[row, col] = a.textures[int(ta[col, 0])] == b.textures[int(tb[col, 0])]
    return {"rows": grid.rows, "cols": grid.cols, "taxtel_width_mm": grid.taxtel_width_mm,
            "taxtel_height_mm": grid.taxtel_height_mm, "lattice": DIFF_LATTICE,
            "rms": _nan_to_none(rms), "mean": _nan_to_none(mean),
            "same_texture": same.tolist(), "jnd": RELATIVE_FRICTION_JND,
            "largest_rms": _finite_max(rms)}


def _nan_to_none(values: np.ndarray) -> list[list[float | None]]:
    """Rows of ``values`` with NaN as None (JSON has no NaN)."""
    return [[None if math.isnan(v) else float(v) for v in row] for row in values]


def _finite_max(values: np.ndarray) -> float | None:
    finite = values[np.isfinite(values)]
    return float(finite.max()) if finite.size else None


# --- the error map ------------------------------------------------------------------------

_STATED_RANGE = re.compile(
    r"\b(black|white) = relative friction ([0-9.eE+-]+), (white|black) = ([0-9.eE+-]+)")
"""The gray-to-friction range the image encoder writes in a card's description
(``black = relative friction 1, white = 0.3, channel uv``)."""


@dataclass(frozen=True)
class SourceImage:
    """A card's source image as relative friction.

    Attributes:
        path: the image file.
        friction: ``(height_px, width_px)`` relative friction of each pixel.
        black, white: relative friction of gray 0 and of white.
    """

    path: Path
    friction: np.ndarray
    black: float
    white: float


def stated_range(card: pb.Card) -> tuple[float, float]:
    """``(black, white)``: the relative friction of black and of white the card says its
    image was encoded with (the image encoder's description).

    Raises:
        UsageError: the description states no range.
    """
    match = _STATED_RANGE.search(card.metadata.description)
    if match is None:
        raise UsageError("--source: the card's description does not state the friction of "
                         "black and white its image was encoded with (the image encoder writes "
                         "'black = relative friction H, white = L'): no error map")
    ends = {match[1]: float(match[2]), match[3]: float(match[4])}
    return ends["black"], ends["white"]


def load_source(path: Path, card: pb.Card) -> SourceImage:
    """The image ``path`` as relative friction in the range ``card`` states
    (:func:`stated_range`): 8-bit gray (colour converted, transparency on white), 16-bit gray
    at full scale 65535.

    Raises:
        ImageError: the file cannot be read or decoded, or is larger than the pixel limit.
        UsageError: the card states no range.
    """
    from PIL import Image, ImageOps, UnidentifiedImageError

    from hcard.bounded_read import DEFAULT_MAX_PIXELS

    black, white = stated_range(card)
    try:
        with Image.open(path) as opened:
            if opened.width * opened.height > DEFAULT_MAX_PIXELS:
                raise ImageError(f"{path}: {opened.width} x {opened.height} pixels exceed the "
                                 f"limit of {DEFAULT_MAX_PIXELS}")
            image = ImageOps.exif_transpose(opened) or opened
            if image.mode in ("I;16", "I;16B", "I;16L", "I"):
                gray = np.clip(np.asarray(image, dtype=np.float64), 0, 65535) / 65535.0
            else:
                if image.mode in ("RGBA", "LA", "PA") or "transparency" in image.info:
                    rgba = image.convert("RGBA")
                    white_back = Image.new("RGBA", rgba.size, (255, 255, 255, 255))
                    image = Image.alpha_composite(white_back, rgba)
                gray = np.asarray(image.convert("L"), dtype=np.float64) / 255.0
    except (OSError, UnidentifiedImageError, Image.DecompressionBombError) as exc:
        raise ImageError(f"{path}: cannot read the source image ({exc})") from None
    return SourceImage(path, black + (white - black) * gray, black, white)


def error_map(card: pb.Card, source: SourceImage) -> dict[str, Any]:
    """Each taxtel's RMS error of the card against its source image, in JND: the card at the
    pixel centres (:func:`friction_at`, position-locked, as the image encoder evaluates its
    reconstruction) minus the pixel's friction, over the pixels whose centres lie in the
    taxtel; the image spans the card's surface. NaN (None in JSON) for a taxtel that owns no
    pixel. The encoder's ``error_rms`` map divided by the JND for a card it made of this
    image."""
    height_px, width_px = source.friction.shape
    grid = card.grid
    x = (np.arange(width_px) + 0.5) * card.surface.width_mm / width_px
    col = np.minimum(np.floor(x / grid.taxtel_width_mm).astype(np.int64), grid.cols - 1)
    squares = np.zeros((grid.rows, grid.cols))
    counts = np.zeros((grid.rows, grid.cols))
    for top in range(0, height_px, max(1, 1_000_000 // width_px)):
        rows = slice(top, min(height_px, top + max(1, 1_000_000 // width_px)))
        y = (np.arange(rows.start, rows.stop) + 0.5) * card.surface.height_mm / height_px
        yy, xx = np.meshgrid(y, x, indexing="ij")
        error = friction_at(card, xx, yy) - source.friction[rows]
        row = np.minimum(np.floor(y / grid.taxtel_height_mm).astype(np.int64), grid.rows - 1)
        cell = (row[:, None] * grid.cols + col[None, :]).ravel()
        squares += np.bincount(cell, weights=(error**2).ravel(),
                               minlength=grid.rows * grid.cols).reshape(squares.shape)
        counts += np.bincount(cell, minlength=grid.rows * grid.cols).reshape(counts.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        jnd = np.sqrt(squares / counts) / RELATIVE_FRICTION_JND
    return {"rows": grid.rows, "cols": grid.cols, "taxtel_width_mm": grid.taxtel_width_mm,
            "taxtel_height_mm": grid.taxtel_height_mm, "source": source.path.name,
            "width_px": width_px, "height_px": height_px, "black": source.black,
            "white": source.white, "jnd": RELATIVE_FRICTION_JND, "label": "RMS error",
            "error_jnd": _nan_to_none(jnd), "largest_jnd": _finite_max(jnd),
            "above_1_jnd": int(np.count_nonzero(jnd > 1.0))}


# --- strokes -------------------------------------------------------------------------------


def _float_rows(value: object, width: int, what: str) -> np.ndarray:
    """``value`` as an ``(n, width)`` array of finite numbers; :class:`ViewRequestError`."""
    try:
        rows = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ViewRequestError(f"{what} must be a list of [{width} numbers] rows") from None
    if rows.ndim != 2 or rows.shape[1] != width or rows.shape[0] < 2:
        raise ViewRequestError(f"{what} must be a list of at least 2 rows of {width} numbers")
    if not np.all(np.isfinite(rows)):
        raise ViewRequestError(f"{what} holds a value that is not a finite number")
    return rows


def path_track(path_mm: np.ndarray, speed_mm_s: float,
               rate_hz: float = TOUCH_RATE_HZ) -> FingerTrack:
    """A finger moving along the polyline ``path_mm`` (``(n, 2)``, mm) at a constant
    ``speed_mm_s``, sampled at ``rate_hz`` (a capacitive touch screen's 50 Hz) from its start,
    with one more sample at its end: the stroke the page draws, timed by its speed control.

    Raises:
        ViewRequestError: the path has no length.
    """
    step = np.hypot(*np.diff(path_mm, axis=0).T)
    distance = np.concatenate(([0.0], np.cumsum(step)))
    length = float(distance[-1])
    if not length > 0:
        raise ViewRequestError("the stroke has no length: draw a line, not a point")
    duration = length / speed_mm_s
    t = np.arange(math.floor(duration * rate_hz + 1e-9) + 1) / rate_hz
    if duration - t[-1] > 1e-6 / rate_hz:
        t = np.append(t, duration)
    else:
        t[-1] = duration
    keep = np.concatenate(([True], step > 0))  # np.interp needs increasing distances
    s = t * speed_mm_s
    x = np.interp(s, distance[keep], path_mm[keep, 0])
    y = np.interp(s, distance[keep], path_mm[keep, 1])
    return make_track(t, x, y, source="stroke")


def retimed(track: FingerTrack, speed_mm_s: float, rate_hz: float = TOUCH_RATE_HZ
            ) -> FingerTrack:
    """``track``'s positions as a path at ``speed_mm_s`` (:func:`path_track`)."""
    return path_track(np.column_stack((track.x, track.y)), speed_mm_s, rate_hz)


def request_track(body: dict[str, Any]) -> FingerTrack:
    """The finger track a render or play request describes: ``path`` (``[[x_mm, y_mm],
    ...]``) with ``speed_mm_s``; or ``points`` (``[[t_s, x_mm, y_mm], ...]``) or
    ``track_csv`` (the text of a track file, spec/track-format.md) at their own times, or
    re-timed along their positions at ``speed_mm_s`` when it is given."""
    return _request_track(body)[0]


def _request_track(body: dict[str, Any]) -> tuple[FingerTrack, float | None]:
    """:func:`request_track` and the speed it was timed at (None: the samples' own times)."""
    speed = body.get("speed_mm_s")
    speed_value = None if speed is None else _number(speed, "speed_mm_s", 1e-3, 1e5)
    rate = _number(body.get("touch_rate_hz", TOUCH_RATE_HZ), "touch_rate_hz", 1.0, 10_000.0)
    given = [key for key in ("path", "points", "track_csv") if key in body]
    if len(given) != 1:
        raise ViewRequestError("give the stroke as exactly one of path (with speed_mm_s), "
                               f"points or track_csv (got {', '.join(given) or 'none'})")
    try:
        if given[0] == "path":
            if speed_value is None:
                raise ViewRequestError("a path needs speed_mm_s")
            path = _float_rows(body["path"], 2, "path")
            return path_track(path, speed_value, rate), speed_value
        if given[0] == "points":
            rows = _float_rows(body["points"], 3, "points")
            track = make_track(rows[:, 0], rows[:, 1], rows[:, 2], source="points")
        else:
            text = body["track_csv"]
            if not isinstance(text, str):
                raise ViewRequestError("track_csv must be the text of a track file")
            track = parse_track_csv(text, source="track_csv")
    except ViewRequestError:
        raise
    except HcardError as exc:  # the track format's own message (TrackError)
        raise ViewRequestError(str(exc)) from None
    if speed_value is None:
        return track, None
    return retimed(track, speed_value, rate), speed_value


def render_options(body: dict[str, Any]) -> RenderOptions:
    """The renderer's options of a request: ``frame_rate_hz`` (default the renderer's)."""
    rate = body.get("frame_rate_hz")
    if rate is None:
        return RenderOptions()
    try:
        return RenderOptions(frame_rate_hz=_number(rate, "frame_rate_hz", 100.0, 1e6))
    except ValueError as exc:
        raise ViewRequestError(str(exc)) from None


def render_frames(card: pb.Card, track: FingerTrack, options: RenderOptions) -> Frames:
    """The frames of ``card`` along ``track``: :class:`hcard.render.Renderer`'s batch
    rendering, block by block as ``hcard render`` writes it, joined.

    Raises:
        ViewRequestError: more than :data:`MAX_VIEW_FRAMES` frames.
    """
    renderer = Renderer(card, options, check=False)  # load() validated it
    frames = track.duration_s * options.frame_rate_hz
    if frames >= MAX_VIEW_FRAMES:
        raise ViewRequestError(
            f"the stroke lasts {track.duration_s:.3g} s: {frames:.3g} frames at "
            f"{options.frame_rate_hz:g} Hz, more than the page takes ({MAX_VIEW_FRAMES}); "
            "raise the speed, lower the frame rate or use hcard render")
    return Frames.concatenate(list(renderer.blocks(track)))


def stroke_distance(track: FingerTrack, t: np.ndarray, speed_mm_s: float | None = None
                    ) -> np.ndarray:
    """Distance along the stroke at the times ``t``, mm: ``speed_mm_s`` times the time since
    the first sample for a stroke timed at that speed (its path's length at its end); else
    along the straight lines between the track's samples (held after the last)."""
    if speed_mm_s is not None:
        return np.clip(speed_mm_s * (t - track.t[0]), 0.0, speed_mm_s * track.duration_s)
    distance = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(track.x), np.diff(track.y)))))
    return np.interp(t, track.t, distance)


def render_json(card: pb.Card, body: dict[str, Any]) -> dict[str, Any]:
    """The answer to a render request: the track, and every frame's time, distance along the
    stroke, UV and EV targets, friction (``uv * ev``, thesis Eq. 4.1) and texture."""
    track, speed = _request_track(body)
    options = render_options(body)
    frames = render_frames(card, track, options)
    distance = stroke_distance(track, frames.t, speed)
    friction = frames.friction
    return {
        "frame_rate_hz": options.frame_rate_hz,
        "track": {"t_s": track.t.tolist(), "x_mm": track.x.tolist(), "y_mm": track.y.tolist()},
        "frames": {"t_s": frames.t.tolist(), "distance_mm": distance.tolist(),
                   "uv": frames.uv.tolist(), "ev": frames.ev.tolist(),
                   "friction": friction.tolist(), "texture": frames.texture.tolist()},
        "summary": {"frames": len(frames), "duration_s": track.duration_s,
                    "length_mm": float(distance[-1]) if len(frames) else 0.0,
                    "friction_min": float(friction.min()) if len(frames) else None,
                    "friction_max": float(friction.max()) if len(frames) else None},
    }
