"""``hcard preview``: draw a card as a PNG picture (taxtel map and texture profiles)."""

from __future__ import annotations

from pathlib import Path

import click

from hcard.card_io import load
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.verbosity import verbosity_options
from hcard.errors import HcardError
from hcard.file_errors import writing


@click.command("preview")
@verbosity_options
@click.argument("card", type=INPUT_FILE)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, writable=True, path_type=Path),
    default=None,
    help="PNG file to write [default: CARD with the suffix .preview.png].",
)
@click.option(
    "--dpi",
    type=click.IntRange(20, 1200),
    default=120,
    show_default=True,
    help="Resolution in dots per inch (the picture is 14 inches wide).",
)
def preview(card: Path, output: Path | None, dpi: int) -> None:
    """Draw CARD as a PNG picture of its taxtels and textures.

    The taxtel grid over the surface (mm, origin top-left, y downwards) coloured by texture;
    then each texture's relative friction and its UV and EV drives along its direction over one
    length shared by all textures (mm, its period stated; a temporal part versus time in ms), on
    one friction scale, with a legend above the cells.

    The PNG is written atomically: an existing file is replaced only once the picture is
    complete.

    \b
    Examples:
      hcard preview card.hcard
      hcard preview card.json -o card.png --dpi 200
    """
    from hcard.preview.picture import render_preview  # matplotlib loads only for this command

    out = output if output is not None else card.with_suffix(".preview.png")
    if out.suffix.lower() != ".png":
        raise click.UsageError(f"output must be a .png file, got '{out}'")
    loaded = load(card)
    with writing(out, HcardError):
        render_preview(loaded, out, dpi=dpi, check=False)  # load() validated it
    click.echo(f"wrote {out}")


COMMANDS = [preview]
