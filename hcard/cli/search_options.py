"""The options of the effect search that ``hcard calibrate run`` and ``hcard calibrate
population`` share (spec/calibration.md K2, K9): one place for their names and defaults."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import click

from hcard.calibration.splits import SPLITS

F = TypeVar("F", bound=Callable[..., Any])


def search_options(what: str) -> Callable[[F], F]:
    """``--split``, ``--test-fraction``, ``--seed``, ``--min-improvement`` and
    ``--max-effects``; ``what`` is what an effect is added to (``"the model"``, ``"the
    population"``), for the help."""

    def decorate(command: F) -> F:
        for option in reversed((
            click.option("--split", type=click.Choice(SPLITS), default="stroke",
                         show_default=True,
                         help="Hold out whole strokes, or the last time block of each "
                              "recording."),
            click.option("--test-fraction", default="25%", show_default=True,
                         help="Share of strokes (or time) held out."),
            click.option("--seed", default=0, show_default=True,
                         help="Seed of the stroke draw."),
            click.option("--min-improvement", default="5%", show_default=True,
                         help="Held-out RMSE fall an added effect must bring."),
            click.option("--max-effects", default=4, show_default=True,
                         type=click.IntRange(min=0), help=f"Most effects added to {what}."),
        )):
            command = option(command)
        return command

    return decorate
