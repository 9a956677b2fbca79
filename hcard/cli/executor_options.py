"""``--scheduler`` and ``--workers``: where a command's many tasks run (hcard/executor.py,
spec/calibration.md K26)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import click

from hcard.executor import DEFAULT_MEMORY_PER_WORKER, DEFAULT_RETRIES, ExecutorOptions

F = TypeVar("F", bound=Callable[..., Any])


def executor_options(function: F) -> F:
    """Add ``--scheduler ADDRESS`` and ``--workers N`` to a command (its function takes
    ``scheduler`` and ``workers``; :func:`options_of` makes the executor's options)."""
    function = click.option(
        "--workers", type=click.IntRange(min=0), default=None, metavar="N",
        help="Local Dask cluster of N worker processes (default min(4, CPUs), "
             f"{DEFAULT_MEMORY_PER_WORKER} each); 0: run in this process.")(function)
    return click.option(
        "--scheduler", metavar="ADDRESS", default=None,
        help="Run the tasks on the Dask cluster whose scheduler is at ADDRESS "
             "(tcp://host:8786); 'none': in this process. A task that fails is run "
             f"again up to {DEFAULT_RETRIES} times.")(function)


def options_of(scheduler: str | None, workers: int | None) -> ExecutorOptions:
    """The executor's options from the two command-line options."""
    return ExecutorOptions(scheduler=scheduler, workers=workers)
