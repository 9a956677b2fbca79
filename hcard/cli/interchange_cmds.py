"""``hcard import`` and ``hcard export``: other tools' assets to cards and back, through the
importer and exporter plugins (spec/interchange.md)."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click

import hcard.limits as limits
from hcard.atomic import write_atomically_together
from hcard.card_io import load, save
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.verbosity import quiet, verbosity_options
from hcard.errors import AssetError, CardError, HcardError, UsageError
from hcard.file_errors import read_reason, write_reason
from hcard.validate import require_valid

if TYPE_CHECKING:
    from hcard.plugins.kinds import EncodeResult, ExporterPlugin, ExportResult, ImporterPlugin

_IMPORT_OPTIONS = ("width_mm", "height_mm", "dpi", "taxtel_mm", "friction_range", "max_error",
                   "length_unit_mm", "title", "author", "licence")
"""Options of ``hcard import`` handed to the importer (by these names; the ones left unset
are not handed, and an importer refuses one that does not apply to its format)."""
_EXPORT_OPTIONS = ("px_per_mm",)
"""Options of ``hcard export`` handed to the exporter."""


@click.command("import")
@verbosity_options
@click.argument("source", type=INPUT_FILE)
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path),
              help="Card file to write: .json gets the JSON form, any other name the binary "
              "form (.hcard).")
@click.option("--from", "from_format", default=None, metavar="FORMAT",
              help="The source's format (an importer's name, see `hcard plugins`): tanvas, "
              "tpad, haps, hjif. Default: recognised from the file's content.")
@click.option("--width-mm", type=float, default=None,
              help="Physical width of the surface, mm. Bitmaps: default from the image's "
              "stated resolution, else the format's screen (spec/interchange/bitmaps.md); "
              ".haps/.hjif: the texture's length.")
@click.option("--height-mm", type=float, default=None,
              help="Physical height of the surface, mm (bitmaps: default keeps the aspect).")
@click.option("--dpi", type=float, default=None,
              help="Bitmaps: the screen's resolution, dots per inch (Tanvas and TPad sample "
              "one bitmap pixel per screen pixel), instead of a size.")
@click.option("--taxtel-mm", type=float, default=None,
              help="Side of a taxtel, mm (default: the importer's, 5 mm for bitmaps).")
@click.option("--friction-range", nargs=2, type=float, metavar="LO HI", default=None,
              help="The device's friction range, relative friction of the format's least and "
              "most friction. Defaults: tanvas (EV) 1.0 1.6, tpad (UV) 0.3 1.0, haps and hjif "
              "by channel.")
@click.option("--max-error", type=click.FloatRange(min=0.0, min_open=True), default=None,
              metavar="JND", help="Bitmaps: the image encoder's error target in JND.")
@click.option("--length-unit-mm", type=float, default=None,
              help=".haps: millimetres per unit of the texture's position axis (the format "
              "does not document its length unit). Default: the importer's, see "
              "spec/interchange.md.")
@click.option("--title", default=None, help="Card title. Default: the source's own, else its "
              "file name.")
@click.option("--author", default=None, help="Card author (metadata).")
@click.option("--licence", default=None, help="Card licence (metadata).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def import_(source: Path, output: Path, from_format: str | None, as_json: bool,
            **values: Any) -> None:
    """Import SOURCE, another tool's haptic asset, into a card.

    SOURCE is a Tanvas or TPad bitmap, an Interhaptics .haps texture or an MPEG-I haptics
    .hjif.
    The format is recognised from the content (--from names it). Bitmaps go through the image
    encoder in the format's polarity and channel (Tanvas: electroadhesion, white = most
    friction; TPad: ultrasonic, white = slipperiest). Prints the card's fidelity to the source
    in multiples of the 8% friction JND, as `hcard encode` does. spec/interchange.md gives
    every mapping.

    \b
    Examples:
      hcard import HelloTanvas_haptics.png -o hello.hcard --dpi 160
      hcard import testdepth.png --from tpad -o depth.hcard --width-mm 60
      hcard import Texture.haps -o texture.hcard
      hcard import friction.hjif -o friction.hcard --json
    """
    given = {name: value for name, value in values.items()
             if name in _IMPORT_OPTIONS and value is not None}
    if "friction_range" in given:
        given["friction_range"] = tuple(given["friction_range"])
    try:
        importer = _importer_for(source, from_format)
        try:
            options = importer.options(**given)
        except UsageError as exc:
            raise click.UsageError(_as_options(str(exc))) from None
        _check_writable(output, "card")
        result = importer.read(source, progress=_progress("import"), **options)
        require_valid(result.card, source=f"{source} (imported)")
        save(result.card, output, check=False)
    except HcardError as exc:
        raise click.ClickException(str(exc)) from None
    summary: dict[str, Any] = {"source": str(source), "format": importer.name,
                               **result.stats, "output": str(output),
                               "output_bytes": output.stat().st_size}
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=_json_default))
        return
    for line in import_summary_lines(summary, result):
        click.echo(line)


@click.command("export")
@verbosity_options
@click.argument("card", type=INPUT_FILE)
@click.option("--to", "to_format", required=True, metavar="FORMAT",
              help="The target format (an exporter's name, see `hcard plugins`): hjif, "
              "tanvas, tpad.")
@click.option("-o", "--output", required=True, type=click.Path(path_type=Path),
              help="File to write; companions (the .hjif's glTF material) are written beside "
              "it with their own suffix.")
@click.option("--px-per-mm", type=click.FloatRange(min=0.0, min_open=True), default=None,
              help="Bitmaps: pixels per millimetre of the surface (default 10: 0.1 mm "
              "pixels).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def export(card: Path, to_format: str, output: Path, as_json: bool, **values: Any) -> None:
    """Export CARD to another tool's format: .hjif, Tanvas, TPad.

    States what the target format cannot hold of this card (channel, locking, orientation,
    relative-friction scale, phase convention, the taxtel map) and where the export keeps it
    anyway (a documented extension), so that `hcard import` of the export gives the card back
    within the tolerance spec/interchange.md states.

    \b
    Examples:
      hcard export button.hcard --to hjif -o button.hjif
      hcard export map.hcard --to tanvas -o map_haptics.png --px-per-mm 6.3
    """
    given = {name: value for name, value in values.items()
             if name in _EXPORT_OPTIONS and value is not None}
    try:
        exporter = _exporter_named(to_format)
        try:
            options = exporter.options(**given)
        except UsageError as exc:
            raise click.UsageError(_as_options(str(exc))) from None
        the_card = load(card)
        _check_writable(output, "export")
        result = exporter.write(the_card, progress=_progress("export"), **options)
        paths = [output, *companions(output, [suffix for suffix, _ in result.files[1:]])]
        for path in paths[1:]:
            _check_writable(path, f"{exporter.name} export's companion")
        try:
            write_atomically_together([(path, data) for path, (_, data)
                                       in zip(paths, result.files, strict=True)])
        except OSError as exc:
            raise CardError(write_reason(exc, f"write the {exporter.name} export"),
                            source=output) from None
    except HcardError as exc:
        raise click.ClickException(str(exc)) from None
    summary = export_summary(card, exporter, result, paths)
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=_json_default))
        return
    for line in export_summary_lines(summary):
        click.echo(line)


def companions(output: Path, suffixes: list[str]) -> list[Path]:
    """The companion files of an export to ``output``: its name with each suffix instead."""
    return [output.with_suffix(suffix) for suffix in suffixes]


def export_summary(card: Path, exporter: ExporterPlugin, result: ExportResult,
                   paths: list[Path]) -> dict[str, Any]:
    """The JSON summary of an export: files written, what the format lost, figures."""
    return {
        "card": str(card),
        "format": exporter.name,
        "files": [{"path": str(path), "bytes": len(data)}
                  for path, (_, data) in zip(paths, result.files, strict=True)],
        "losses": [loss.as_json() for loss in result.losses],
        **result.stats,
    }


def export_summary_lines(summary: dict[str, Any]) -> list[str]:
    """The text summary of an export."""
    lines = [f"export      {summary['card']} to {summary['format']}"]
    lines += [f"wrote       {file['path']} ({file['bytes']} bytes)" for file in summary["files"]]
    for loss in summary["losses"]:
        kept = f"; kept in {loss['carried']}" if loss["carried"] else "; not kept"
        lines.append(f"cannot hold {loss['field']}: {loss['detail']}{kept}")
    if not summary["losses"]:
        lines.append("cannot hold nothing: the format holds the whole card")
    fidelity = summary.get("rms_error_jnd")
    if fidelity is not None:
        lines.append(f"fidelity    the format's own content against the card: rms "
                     f"{fidelity:.2f}, max {summary['max_error_jnd']:.2f} x the "
                     f"{limits.RELATIVE_FRICTION_JND:g} friction JND")
    return lines


def import_summary_lines(summary: dict[str, Any], result: EncodeResult) -> list[str]:
    """The text summary of an import: the encoder's summary for a bitmap (the same figures as
    ``hcard encode``), else the source, the card and its fidelity."""
    if "image_width_px" in summary:
        from hcard.cli.encode_cmd import summary_lines

        lines = [f"format      {summary['format']}: {summary.get('format_detail', '')}"]
        lines += summary_lines({**summary, "output_format": _card_form(summary["output"]),
                                "preview": None})
        return lines
    lines = [f"source      {summary['source']} ({summary['format']}: "
             f"{summary.get('format_detail', '')})"]
    lines += [f"note        {line}" for line in result.log]
    card = result.card
    lines.append(f"card        {card.grid.cols} x {card.grid.rows} taxtels, "
                 f"{len(card.textures)} textures, "
                 f"{sum(len(t.components) for t in card.textures)} components")
    jnd = limits.RELATIVE_FRICTION_JND
    lines.append(f"fidelity    rms {summary['rms_error_jnd']:.2f}, max "
                 f"{summary['max_error_jnd']:.2f} x the {jnd:g} friction JND (the card against "
                 f"the source's own friction, {summary.get('fidelity_basis', 'sampled')})")
    lines.append(f"wrote       {summary['output']} ({summary['output_bytes']} bytes)")
    return lines


def _card_form(output: str) -> str:
    from hcard.card_io import format_for_path

    return format_for_path(Path(output))


def _importer_for(source: Path, name: str | None) -> ImporterPlugin:
    """The importer named ``name``, or the one that recognises ``source``'s content."""
    from hcard.plugins.kinds import SNIFF_BYTES
    from hcard.plugins.registry import get_registry

    importers = get_registry().importers
    if name is not None:
        if name not in importers:
            raise click.UsageError(f"--from {name}: no such importer; installed: "
                                   f"{', '.join(sorted(importers)) or 'none'}")
        return importers[name]
    try:
        with source.open("rb") as file:
            head = file.read(SNIFF_BYTES)
    except OSError as exc:
        raise AssetError(read_reason(exc, "a file to import"), source=source) from None
    scores = {importer_name: importer.recognises(head)
              for importer_name, importer in sorted(importers.items())}
    best = max(scores.values(), default=0)
    chosen = [importer_name for importer_name, score in scores.items() if score == best]
    if best == 0:
        raise AssetError(f"no importer recognises this content (installed: "
                         f"{', '.join(scores) or 'none'}); name one with --from",
                         source=source)
    if len(chosen) > 1:
        raise AssetError(
            f"the content fits {' and '.join(chosen)} alike (a bitmap does not say whose "
            f"polarity it has: Tanvas white = most friction, TPad white = slipperiest); "
            f"name one with --from", source=source)
    return importers[chosen[0]]


def _exporter_named(name: str) -> ExporterPlugin:
    from hcard.plugins.registry import get_registry

    exporters = get_registry().exporters
    if name not in exporters:
        raise click.UsageError(f"--to {name}: no such exporter; installed: "
                               f"{', '.join(sorted(exporters)) or 'none'}")
    return exporters[name]


def _as_options(message: str) -> str:
    """A plugin's message with its option names written as this command's options."""
    for name in (*_IMPORT_OPTIONS, *_EXPORT_OPTIONS):
        message = re.sub(rf"\b{name}\b", "--" + name.replace("_", "-"), message)
    return message


def _progress(command: str) -> Any:
    def say(line: str) -> None:
        if not quiet():
            click.echo(f"hcard {command}: {line}", err=True)

    return say


def _check_writable(path: Path, what: str) -> None:
    """Fail before the work when ``path`` obviously cannot be written."""
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise CardError(f"cannot write the {what}: is a directory", source=path)
    if not parent.is_dir():
        raise CardError(f"cannot write the {what}: directory {parent} does not exist",
                        source=path)


def _json_default(value: Any) -> Any:
    """numpy scalars and tuples in the figures, as JSON numbers and lists."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"not JSON: {type(value).__name__}")


COMMANDS = [import_, export]
