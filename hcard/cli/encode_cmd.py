"""``hcard encode``: a grayscale friction image to a haptic card (the built-in image encoder)."""

from __future__ import annotations

import json
import os
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

import hcard.channels as channels
import hcard.limits as limits
from hcard.atomic import write_atomically, write_atomically_together
from hcard.bounded_read import DEFAULT_MAX_PIXELS, STDIN
from hcard.card_io import checked_bytes, format_for_path, save, to_bytes
from hcard.cli.executor_options import executor_options, options_of
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.errors import CardError, HcardError, UsageError
from hcard.executor import Executor, ExecutorOptions
from hcard.file_errors import write_reason
from hcard.validate import require_valid

if TYPE_CHECKING:
    from hcard.plugins.kinds import EncodeResult, EncoderPlugin



@click.command()
@verbosity_options
@click.argument("images", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(allow_dash=True, path_type=Path),
    help="Card file to write: a name ending in .json gets the JSON form, any other the binary "
    "form (.hcard); - writes the binary card to standard output (the summary then goes to "
    "standard error).",
)
@click.option(
    "--width-mm",
    type=float,
    help="Physical width of the image in millimetres (alone: square pixels, aspect kept).",
)
@click.option(
    "--height-mm",
    type=float,
    help="Physical height of the image in millimetres (with --width-mm: rectangular pixels "
    "allowed).",
)
@click.option(
    "--dpi",
    type=float,
    help="Resolution in dots per inch (at most 25400), instead of a size. Default: the "
    "resolution the image states in a physical unit (PNG pHYs, JPEG JFIF density, TIFF with "
    "a resolution unit) when it lies in 10-25400 dpi, else 254 (0.1 mm per pixel).",
)
@click.option(
    "--taxtel-mm",
    type=float,
    default=5.0,
    show_default=True,
    help="Side of a square taxtel in millimetres. Gratings longer than half a taxtel become "
    "baseline steps between taxtels.",
)
@click.option(
    "--max-error",
    type=click.FloatRange(min=0.0, min_open=True),
    default=None,
    metavar="JND",
    help="Error target in multiples of the 8% friction JND: in every taxtel, 95% of the "
    "pixels within this of the image (the 95th percentile of the absolute error over the "
    "taxtel's pixels, card evaluated position-locked at the pixel centres; it bounds the "
    "image's 95th percentile too). The encoder adds gratings to the taxtels over it and gives "
    "them textures of their own, up to --components and --max-textures, and lists the taxtels "
    "it cannot bring under it and why. Default: no target (the spectral analysis alone).",
)
@click.option(
    "--components",
    type=click.IntRange(0, limits.MAX_COMPONENTS_PER_TEXTURE),
    default=None,
    help="Most grating components per taxtel texture (strongest first). Default: 8, or "
    f"{limits.MAX_COMPONENTS_PER_TEXTURE} (the format's limit) with --max-error.",
)
@click.option(
    "--max-textures",
    type=click.IntRange(1, limits.MAX_TEXTURES),
    default=None,
    help="Most textures in the card's palette; the closest textures are merged until it fits. "
    f"Default: 64, or {limits.MAX_TEXTURES} (the format's limit) with --max-error.",
)
@click.option(
    "--min-amplitude",
    type=float,
    default=0.01,
    show_default=True,
    help="Smallest component amplitude kept, relative friction; a taxtel whose friction "
    "varies less than this (standard deviation) keeps only its baseline.",
)
@click.option(
    "--merge-tolerance",
    type=float,
    default=limits.RELATIVE_FRICTION_JND / 2,
    show_default=True,
    help="Taxtels whose textures differ by less than this RMS relative friction share one "
    "palette texture (default: half the 8% friction JND).",
)
@click.option(
    "--channel",
    type=click.Choice(list(channels.NAMES)),
    default="uv",
    show_default=True,
    help="Actuator of the textures: uv lowers friction, ev raises it, bipolar does both.",
)
@click.option(
    "--locking",
    type=click.Choice(["auto", "position", "velocity"]),
    default="auto",
    show_default=True,
    help="Phase locking of the textures: position (tied to the surface), velocity (texture "
    "control from the finger speed) or auto (by grating period).",
)
@click.option(
    "--friction-range",
    nargs=2,
    type=float,
    metavar="LO HI",
    default=None,
    help="Relative friction of white (LO) and black (HI). Defaults: uv 0.3 1.0, ev 1.0 1.6, "
    "bipolar 0.5 1.5. UV cannot go above 1 nor EV below 1.",
)
@click.option(
    "--max-pixels",
    type=click.IntRange(min=1),
    default=DEFAULT_MAX_PIXELS,
    show_default=True,
    help="Refuse images with more pixels than this (checked from the header, before "
    "decoding: a guard against decompression bombs).",
)
@click.option("--title", default=None, help="Card title. Default: the image file name stem.")
@click.option("--author", default="", help="Card author (metadata).")
@click.option("--licence", default="", help="Card licence, an SPDX identifier or free text.")
@click.option(
    "--preview",
    type=click.Path(path_type=Path),
    default=None,
    help="Also write a PNG preview of the card to this file: taxtel map, error map in JND, "
    "each texture's friction over one shared length.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of text.")
@executor_options
def encode(
    images: tuple[Path, ...],
    output: Path,
    width_mm: float | None,
    height_mm: float | None,
    dpi: float | None,
    taxtel_mm: float,
    max_error: float | None,
    components: int | None,
    max_textures: int | None,
    min_amplitude: float,
    merge_tolerance: float,
    channel: str,
    locking: str,
    friction_range: tuple[float, float] | None,
    max_pixels: int,
    title: str | None,
    author: str,
    licence: str,
    preview: Path | None,
    as_json: bool,
    scheduler: str | None,
    workers: int | None,
) -> None:
    """Encode a grayscale IMAGE: black is high friction, white low. Several IMAGEs: -o is a
    directory, each card is written there as NAME.hcard, the images encoded as tasks on a
    local Dask cluster (--workers, --scheduler); an image that fails is named, the others
    are written, and the exit status is 1.

    The image is cut into taxtels; each taxtel's friction becomes a baseline plus up to
    --components gratings (frequency, orientation, amplitude, phase), and similar taxtels
    share a palette texture. Prints a summary: grid, textures, components, card size and the
    reconstruction error against the image (relative friction and multiples of the 8% JND):
    RMS, 95th percentile and maximum over the image, and per taxtel. With --max-error, the
    encoder spends components and textures where a taxtel is over the target and says which
    taxtels it cannot bring under it, by how much and why.

    \b
    Examples:
      hcard encode photo.png -o photo.hcard --width-mm 80
      hcard encode button.png -o button.hcard --max-error 1
      hcard encode map.png -o map.hcard.json --taxtel-mm 2 --channel ev --preview map-p.png
      hcard encode photo.png -o - --dpi 300 | hcard info -
      hcard encode a.png b.png c.png -o cards/ --workers 2
    """
    _single_threaded_blas()
    try:
        encoder = _image_encoder()
    except HcardError as exc:
        raise click.ClickException(str(exc)) from None
    try:
        options = encoder.options(
            width_mm=width_mm,
            height_mm=height_mm,
            dpi=dpi,
            taxtel_mm=taxtel_mm,
            max_error=max_error,
            components=components,
            max_textures=max_textures,
            min_amplitude=min_amplitude,
            merge_tolerance=merge_tolerance,
            channel=channel,
            locking=locking,
            friction_range=(friction_range[0], friction_range[1]) if friction_range else None,
            max_pixels=max_pixels,
            title=title,
            author=author,
            licence=licence,
        )
    except UsageError as exc:
        raise click.UsageError(_option_names(str(exc))) from None
    if len(images) > 1:
        _encode_many(images, output, options, preview, options_of(scheduler, workers))
        return
    image = images[0]
    to_stdout = str(output) == STDIN
    if output.suffix.lower() in IMAGE_SUFFIXES:
        raise click.UsageError(
            f"-o {output}: a card is not an image; name it .hcard (binary) or .hcard.json "
            f"(the PNG preview is --preview {output})")
    try:
        if not to_stdout:
            _check_writable(output, "card")
        if preview is not None:
            _check_writable(preview, "preview")
        result = encoder.encode(image, progress=_progress, **options)
        require_valid(result.card, source=image)  # the one check: written unchecked below
        # The preview is rendered before the card is saved: a preview that cannot be made
        # leaves the previous card in place.
        png = _preview_bytes(result, max_error) if preview is not None else None
        if to_stdout:
            card_bytes = to_bytes(result.card)
            if preview is not None and png is not None:
                _write_preview(png, preview)  # before the card goes out: it cannot be taken back
            sys.stdout.flush()  # text already printed goes first
            sys.stdout.buffer.write(card_bytes)
        elif preview is not None and png is not None:
            _write_card_and_preview(checked_bytes(result.card, output, check=False), output,
                                    png, preview)
            card_bytes = b""
        else:
            save(result.card, output, check=False)
            card_bytes = b""
    except HcardError as exc:
        raise click.ClickException(str(exc)) from None
    summary = dict(result.stats)
    summary.update(
        output="<stdout>" if to_stdout else str(output),
        output_format="binary" if to_stdout else format_for_path(output),
        output_bytes=len(card_bytes) if to_stdout else output.stat().st_size,
        preview=str(preview) if preview is not None else None,
    )
    if as_json:
        click.echo(json.dumps(summary, indent=2), err=to_stdout)
    else:
        for line in summary_lines(summary):
            click.echo(line, err=to_stdout)


IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tif", ".tiff", ".webp"})
"""Output names encode refuses for a card: a binary card written to ``card.png`` is a file
that image viewers reject and card readers find only by content."""

_OPTION_FIELDS = (
    "width_mm",
    "height_mm",
    "dpi",
    "taxtel_mm",
    "max_error",
    "components",
    "max_textures",
    "min_amplitude",
    "merge_tolerance",
    "max_pixels",
)


def encode_to_file(job: tuple[str, str, dict[str, Any]]) -> dict[str, Any]:
    """Task: encode image ``job[0]`` with the encoder options ``job[2]`` and write the card
    atomically to ``job[1]``; returns the encoder's statistics. Raises what the encoder, the
    validation or the write raise."""
    image, card, options = job
    _single_threaded_blas()
    result = _image_encoder().encode(Path(image), progress=None, **options)
    require_valid(result.card, source=Path(image))
    save(result.card, Path(card), check=False)
    return dict(result.stats)


def _encode_many(images: tuple[Path, ...], output: Path, options: dict[str, Any],
                 preview: Path | None, where: ExecutorOptions) -> None:
    """Encode every image to ``output``/STEM.hcard on the executor; name each failure and
    exit with status 1 when any failed."""
    if preview is not None:
        raise click.UsageError("--preview takes one image; encode the others alone")
    if str(output) == STDIN or (output.exists() and not output.is_dir()):
        raise click.UsageError(f"-o {output}: with several images, -o is a directory")
    stems = [image.stem for image in images]
    twice = sorted({stem for stem in stems if stems.count(stem) > 1})
    if twice:
        raise click.UsageError(f"several images would make the same card: {', '.join(twice)}")
    output.mkdir(parents=True, exist_ok=True)
    jobs = [(str(image), (str(image), str(output / f"{image.stem}.hcard"), options))
            for image in images]
    failed = 0
    with Executor(where) as executor:
        for outcome in executor.map(encode_to_file, jobs, _progress):
            card = output / f"{Path(outcome.key).stem}.hcard"
            if outcome.ok:
                click.echo(f"{outcome.key} -> {card}")
            else:
                failed += 1
                click.echo(f"error: {outcome.key}: {outcome.error}", err=True)
    if failed:
        click.echo(f"{failed} of {len(images)} image(s) failed", err=True)
        sys.exit(1)


def _single_threaded_blas() -> None:
    """One BLAS thread for this process unless the environment says otherwise, set before
    numpy loads its BLAS. The encoder's BLAS calls are small batched products and solves; a
    pool of BLAS threads only adds its start-up (50-60 ms at numpy's import on a loaded
    2-core machine) and threads competing with the main one (bench/bench_encoder.py)."""
    if "numpy" not in sys.modules:
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


def _image_encoder() -> EncoderPlugin:
    """The encoder plugin ``image`` of the plugin registry (the built-in one; a third party
    cannot take its name), whose options (:meth:`~hcard.plugins.kinds.EncoderPlugin.options`)
    are this command's options, named without the ``--`` and with ``_`` for ``-``."""
    from hcard.plugins.registry import get_registry

    return get_registry().get("encoder", "image")


def _option_names(message: str) -> str:
    """An encoder message with its field names written as the options of this command."""
    for name in _OPTION_FIELDS:
        message = re.sub(rf"\b{name}\b", "--" + name.replace("_", "-"), message)
    return message


def _progress(line: str) -> None:
    if not quiet():
        click.echo(f"hcard encode: {line}", err=True)


def _check_writable(path: Path, what: str) -> None:
    """Fail before the (possibly long) encode when ``path`` obviously cannot be written."""
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise CardError(f"cannot write the {what}: is a directory", source=path)
    if not parent.is_dir():
        raise CardError(f"cannot write the {what}: directory {parent} does not exist", source=path)


def _preview_bytes(result: EncodeResult, max_error: float | None) -> bytes:
    """The PNG preview with the encoder's error map in JND (hcard.preview.picture, imported only
    when asked for: it loads matplotlib). The map shows the statistic the summary counts taxtels
    by: each taxtel's RMS error, or its 95th percentile when ``--max-error`` set that target."""
    from hcard.preview.picture import preview_png

    statistic, label = ("error_p95", "95th-percentile error") if max_error is not None else (
        "error_rms", "RMS error")
    error = result.maps.get(statistic)
    error_map = None if error is None else error / limits.RELATIVE_FRICTION_JND
    return preview_png(result.card, error_map=error_map, error_label=label, check=False)


def _write_card_and_preview(card: bytes, card_path: Path, png: bytes, preview: Path) -> None:
    """Replace the card and its preview together (:func:`hcard.atomic.atomic_outputs`): when
    either cannot be written (a full disk), both previous files stay as they were."""
    try:
        write_atomically_together([(card_path, card), (preview, png)])
    except OSError as exc:
        raise CardError(write_reason(exc, "write the card and its preview"),
                        source=card_path) from None


def _write_preview(png: bytes, path: Path) -> None:
    """Write the rendered preview to ``path``, atomically."""
    try:
        write_atomically(path, png)
    except OSError as exc:
        raise CardError(write_reason(exc, "write the preview"), source=path) from None


def _ends(stats: dict[str, Any], high: float, low: float) -> str:
    """``black = HIGH, white = LOW``, or the reverse for an image whose white is the high end
    (the encoder's ``white_is``, a Tanvas bitmap)."""
    if stats.get("white_is") == "high":
        return f"white = {high:g}, black = {low:g}"
    return f"black = {high:g}, white = {low:g}"


def summary_lines(s: dict[str, Any]) -> list[str]:
    """The text summary of an encode (``s``: the encoder's stats plus the output fields)."""
    pitch_x, pitch_y = s["pixel_pitch_mm"]
    low, high = s["friction_range"]
    raw = s["raw_bitmap_bytes"]
    card_bytes = s["card_bytes"]
    taxtels = s["cols"] * s["rows"]
    merged = (
        f" ({s['distinct_textures']} distinct before merging)"
        if s["distinct_textures"] > s["textures"]
        else ""
    )
    lines = [
        f"image       {s['image']}: {s['image_width_px']} x {s['image_height_px']} pixels, "
        f"mode {s['image_mode']}",
        f"surface     {s['width_mm']:.6g} x {s['height_mm']:.6g} mm, pixel pitch "
        f"{pitch_x:.4g} x {pitch_y:.4g} mm ({s['size_source']})",
        f"grid        {s['cols']} x {s['rows']} taxtels of {s['taxtel_mm']:g} mm "
        f"(tiles of {s['tile_px'][0]} x {s['tile_px'][1]} pixels)",
        f"textures    {s['textures']} in the palette{merged}; {s['textured_taxtels']} of "
        f"{taxtels} taxtels carry gratings",
        f"components  {s['components']} in total",
        f"channel     {s['channel']}: {_ends(s, high, low)} relative friction; "
        f"locking {s['locking']}",
        f"card size   {card_bytes} bytes (binary); raw 8-bit bitmap at 0.1 mm: {raw} bytes "
        f"(card = {100.0 * card_bytes / raw:.3g} % of it)",
        _error_line(s),
        *_taxtel_error_lines(s),
        *_target_lines(s),
        f"wrote       {s['output']} ({s['output_format']}, {s['output_bytes']} bytes)",
    ]
    if s.get("preview"):
        lines.append(f"preview     {s['preview']}")
    return lines


def _error_line(s: dict[str, Any]) -> str:
    """The summary's error line: RMS, 95th percentile (when the encoder gives it) and maximum,
    in relative friction and in multiples of the friction JND."""
    jnd = limits.RELATIVE_FRICTION_JND
    names = ("rms", "p95", "max") if "p95_error" in s else ("rms", "max")
    values = [float(s[f"{name}_error"]) for name in names]
    return (f"error       {', '.join(f'{n} {v:.4f}' for n, v in zip(names, values, strict=True))}"
            f" relative friction = {', '.join(f'{v / jnd:.2f}' for v in values)} x the {jnd:g} "
            "friction JND")


def _taxtel_error_lines(s: dict[str, Any]) -> list[str]:
    """The summary's line on the per-taxtel error, when the encoder gives it."""
    worst = s.get("worst_taxtel")
    if not worst:
        return []
    taxtels = s["cols"] * s["rows"]
    return [f"taxtels     {s['taxtels_over_jnd']} of {taxtels} with an rms error above 1 JND; "
            f"worst: column {worst['col']}, row {worst['row']} (rms {worst['rms_jnd']:.2f}, max "
            f"{worst['max_jnd']:.2f} JND)"]


REASON_TEXT = {
    "detail": "detail finer than {limit} gratings a taxtel can carry (a smaller --taxtel-mm "
    "helps)",
    "components": "the --components cap (up to {limit} would meet it)",
    "palette": "a shared palette texture{full}",
}
"""How the summary words each reason a taxtel misses the target (see
``hcard_builtins.image.shortfall``)."""


def _target_lines(s: dict[str, Any]) -> list[str]:
    """The summary's lines on the error target, when one was given: how many taxtels meet
    it, the worst of the others and how many miss it for each reason."""
    target = s.get("target")
    if not target:
        return []
    taxtels = s["cols"] * s["rows"]
    head = (f"target      95th percentile <= {target['target_jnd']:g} JND in each taxtel: met in "
            f"{taxtels - target['taxtels_over']} of {taxtels}")
    worst = target["worst"]
    if worst is None:
        return [head]
    head += (f"; worst: column {worst['col']}, row {worst['row']} ({worst['p95_jnd']:.2f} JND, "
             f"{worst['p95_jnd'] - target['target_jnd']:.2f} over)")
    full = f" (palette full: {s['textures']} textures)" if target["palette_full"] else ""
    limit = limits.MAX_COMPONENTS_PER_TEXTURE
    reasons = [f"{count} for {REASON_TEXT[name].format(limit=limit, full=full)}"
               for name, count in target["reasons"].items() if count]
    return [head, f"            over it: {'; '.join(reasons)}"]


COMMANDS = [encode]
