"""``hcard predict``: evaluate a physics predictor at a point or over a sweep.

    hcard predict                       # list the models, their parameters and inputs
    hcard predict dimensionless-group --input speed=20mm/s --input frequency=27.5kHz \\
        --input normal_force=0.5N --sweep amplitude=0:5um:51 -o out.csv --plot out.png

Values take units (``3.9MN/m``, ``20 mm/s``, ``27.5kHz``); everything is computed and written
in SI units, with the unit in each column header. Bad names, units or values are one-line
errors (:class:`~hcard.errors.HcardError`), never tracebacks.
"""

from __future__ import annotations

import io
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import click
import numpy as np

from hcard.atomic import write_atomically
from hcard.cli.errors import option_values
from hcard.cli.input_files import INPUT_FILE
from hcard.cli.options import plugin_option
from hcard.cli.verbosity import verbosity_options
from hcard.errors import HcardError, UsageError
from hcard.file_errors import writing
from hcard.physics.predictor import Parameter, Predictor, PredictorError, Variable
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_error import ProfileError
from hcard.physics.sweep import Sweep, parse_sweep, quantity, split_assignment
from hcard.plugins.registry import get_registry
from hcard.quantities import display_unit, format_value

if TYPE_CHECKING:
    from matplotlib.figure import Figure

PLOT_FORMATS = (".png", ".pdf", ".svg")
"""File types ``--plot`` writes (by suffix)."""

TITLE_WIDTH = 90
"""Characters per line of the plot title's list of fixed inputs."""

Y_LABEL_DESCRIPTION = 30
"""The output's description joins the y label only when at most this long."""


class PredictUsageError(UsageError):
    """Options of ``hcard predict`` that do not fit together."""


# -- units for people --------------------------------------------------------------------------
def column(name: str, unit: str) -> str:
    """Column header: ``name [unit]``, ``[-]`` for a pure number."""
    return f"{name} [{unit or '-'}]"


# -- the evaluation ----------------------------------------------------------------------------
@dataclass(frozen=True)
class Prediction:
    """A predictor evaluated at fixed inputs, over a sweep or at one point.

    Attributes:
        predictor: the model with its parameters.
        fixed: fixed input values, SI (given and defaulted).
        sweep: the swept input or parameter (None: one point).
        values: the swept values, SI (empty without a sweep).
        output: the output, SI, one per swept value (one value without a sweep).
    """

    predictor: Predictor
    fixed: dict[str, float]
    sweep: Sweep | None
    values: np.ndarray
    output: np.ndarray

    def unit_of(self, name: str) -> str:
        """SI unit of an input or parameter of the predictor."""
        items: tuple[Variable | Parameter, ...] = (*self.predictor.inputs,
                                                   *self.predictor.parameters)
        for item in items:
            if item.name == name:
                return item.unit
        raise PredictorError(f"{self.predictor.name}: no input or parameter {name!r}")

    def columns(self, *, all_inputs: bool, readable: bool = False) -> tuple[list[str], np.ndarray]:
        """Headers and rows: the swept variable (and, with ``all_inputs``, every fixed input),
        then the output; SI units, or with ``readable`` each column in a unit that suits its
        values (um for plate amplitudes, mm/s for speeds), as in the plot."""
        count = self.output.size
        names: list[str] = []
        data: list[np.ndarray] = []
        if self.sweep is not None:
            names.append(column(self.sweep.name, self.unit_of(self.sweep.name)))
            data.append(self.values)
        if all_inputs or self.sweep is None:
            for name, value in self.fixed.items():
                names.append(column(name, self.unit_of(name)))
                data.append(np.full(count, value))
        out = self.predictor.output
        names.append(column(out.name, out.unit))
        data.append(self.output.reshape(count))
        if readable:
            for i, (name, values) in enumerate(zip(names, data, strict=True)):
                label, unit = name.rsplit(" [", 1)
                unit = unit.rstrip("]")
                scale, shown = display_unit("" if unit == "-" else unit, values)
                names[i], data[i] = column(label, shown), values / scale
        return names, np.column_stack(data)

    def description(self) -> str:
        """``"dimensionless: speed = 20 mm/s, frequency = 27.5 kHz"`` (model, fixed inputs)."""
        fixed = ", ".join(
            f"{name} = {format_value(value, self.unit_of(name))}"
            for name, value in self.fixed.items()
        )
        return f"{self.predictor.name}: {fixed}" if fixed else self.predictor.name


def _named(items: Sequence[Parameter | Variable], name: str, model: str, kind: str) -> Any:
    for item in items:
        if item.name == name:
            return item
    known = ", ".join(i.name for i in items) or "none"
    raise PredictorError(f"{model}: unknown {kind} {name!r}; {kind}s: {known}")


def _assignments(texts: Sequence[str], option: str) -> dict[str, str]:
    values: dict[str, str] = {}
    for text in texts:
        name, value = split_assignment(text, option)
        if name in values:
            raise PredictUsageError(f"{option} {name} is given twice")
        values[name] = value
    return values


def evaluate(
    predictor: Predictor,
    params: Mapping[str, str],
    inputs: Mapping[str, str],
    sweep_text: str | None,
) -> Prediction:
    """Evaluate ``predictor`` with parameter and input texts (units allowed) and a sweep text.

    Raises:
        PredictorError: unknown parameter or input, value out of bounds, missing input.
        UnitError: a value's unit is unknown or of another dimension.
        SweepError: a malformed assignment or sweep.
    """
    model = predictor.name
    changes = {}
    for name, text in params.items():
        parameter = _named(predictor.parameters, name, model, "parameter")
        value = quantity(text, parameter.unit, f"--param {name}")
        low, high = parameter.bounds
        if not low <= value <= high:
            unit = f" {parameter.unit}" if parameter.unit else ""
            raise PredictorError(
                f"{model}: --param {name} = {value:g}{unit} is outside its bounds "
                f"[{low:g}, {high:g}]{unit}"
            )
        changes[name] = value
    if changes:
        predictor = predictor.with_params(**changes)

    given: dict[str, float] = {}
    for name, text in inputs.items():
        variable = _named(predictor.inputs, name, model, "input")
        given[name] = quantity(text, variable.unit, f"--input {name}")

    sweep = None
    if sweep_text is not None:
        name, spec = split_assignment(sweep_text, "--sweep")
        input_names = {v.name for v in predictor.inputs}
        if name in input_names:
            unit = _named(predictor.inputs, name, model, "input").unit
        elif name in {p.name for p in predictor.parameters}:
            unit = _named(predictor.parameters, name, model, "parameter").unit
        else:
            known = ", ".join([*input_names, *(p.name for p in predictor.parameters)])
            raise PredictorError(f"{model}: cannot sweep {name!r}; inputs and parameters: {known}")
        if name in given or name in changes:
            raise PredictUsageError(f"{name} is both swept and set; give it once")
        sweep = parse_sweep(name, spec, unit)

    fixed: dict[str, float] = {}
    for variable in predictor.inputs:
        if sweep is not None and variable.name == sweep.name:
            continue
        if variable.name in given:
            fixed[variable.name] = given[variable.name]
        elif variable.default is not None:
            fixed[variable.name] = float(variable.default)
        else:
            raise PredictorError(
                f"{model}: input {variable.name} ({variable.unit or 'no unit'}) is required; "
                f"give --input {variable.name}=VALUE or --sweep {variable.name}=START:STOP:COUNT"
            )

    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        if sweep is None:
            values = np.empty(0)
            output = np.atleast_1d(np.asarray(predictor.forward(**fixed), dtype=np.float64))
        elif sweep.name in {v.name for v in predictor.inputs}:
            values = sweep.values()
            raw = np.asarray(predictor.forward(**fixed, **{sweep.name: values}), np.float64)
            output = np.broadcast_to(raw, values.shape).copy()
        else:
            values = sweep.values()
            output = np.array(
                [
                    float(np.asarray(predictor.with_params(**{sweep.name: v}).forward(**fixed)))
                    for v in values
                ]
            )
    if sweep is None and output.size != 1:
        raise PredictorError(f"{model}: expected one output value, got {output.size}")
    return Prediction(predictor, fixed, sweep, values, output)


# -- tables, CSV, plot ------------------------------------------------------------------------
def format_table(headers: Sequence[str], rows: np.ndarray) -> str:
    """Right-aligned columns, values with 6 significant digits."""
    cells = [list(headers)] + [[f"{v:.6g}" for v in row] for row in rows]
    widths = [max(len(row[i]) for row in cells) for i in range(len(headers))]
    return "\n".join(
        "  ".join(cell.rjust(width) for cell, width in zip(row, widths, strict=True))
        for row in cells
    )


def to_csv(headers: Sequence[str], rows: np.ndarray) -> bytes:
    """CSV bytes: a header row, then values with 12 significant digits (SI units)."""
    buffer = io.StringIO()
    buffer.write(",".join(headers) + "\n")
    for row in rows:
        buffer.write(",".join(f"{v:.12g}" for v in row) + "\n")
    return buffer.getvalue().encode()


def make_figure(prediction: Prediction) -> Figure:
    """The sweep as a line plot: axes labelled with readable units, title with the model and
    the fixed inputs (a matplotlib figure on an Agg canvas, not yet saved)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if prediction.sweep is None:
        raise PredictUsageError("--plot needs --sweep: a single point is not a plot")
    sweep = prediction.sweep
    x_scale, x_unit = display_unit(prediction.unit_of(sweep.name), prediction.values)
    out = prediction.predictor.output
    y_scale, y_unit = display_unit(out.unit, prediction.output)

    figure = Figure(figsize=(7.5, 4.8), dpi=120, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    axes.plot(prediction.values / x_scale, prediction.output / y_scale, lw=2, color="tab:blue")
    if sweep.spacing == "log":
        axes.set_xscale("log")
    axes.set_xlabel(f"{sweep.name.replace('_', ' ')} [{x_unit or '-'}]", fontsize=11)
    y_label = out.name.replace("_", " ")
    if out.description and len(out.description) <= Y_LABEL_DESCRIPTION:
        y_label += f" ({out.description})"
    axes.set_ylabel(f"{y_label} [{y_unit or '-'}]", fontsize=11)
    fixed = prediction.description().partition(": ")[2]
    title = f"{prediction.predictor.name}: {out.name.replace('_', ' ')} vs {sweep.name}"
    if fixed:
        title += "\n" + "\n".join(textwrap.wrap(fixed, TITLE_WIDTH))
    axes.set_title(title, fontsize=11)
    axes.grid(True, alpha=0.3)
    axes.tick_params(labelsize=10)
    return figure


def _write(path: Path, data: bytes) -> None:
    with writing(path, HcardError):
        write_atomically(path, data)


# -- listing -----------------------------------------------------------------------------------
def describe_model(predictor: Predictor) -> str:
    """A model's inputs, output, inverse and parameter table (name, unit, default, bounds,
    source, description)."""
    lines = [f"{predictor.name}: {predictor.description}"]
    lines.append("  inputs:")
    for v in predictor.inputs:
        default = "required" if v.default is None else f"default {v.default:g}"
        lines.append(f"    {v.name} [{v.unit or '-'}] ({default}): {v.description}")
    out = predictor.output
    lines.append(f"  output: {out.name} [{out.unit or '-'}]: {out.description}")
    inverse = predictor.inverse_input or "none"
    lines.append(f"  inverse: {inverse}")
    if not predictor.parameters:
        lines.append("  parameters: none")
        return "\n".join(lines)
    lines.append("  parameters:")
    header = ("NAME", "UNIT", "DEFAULT", "BOUNDS", "SOURCE")
    rows = [header] + [
        (p.name, p.unit or "-", f"{p.default:g}", f"[{p.bounds[0]:g}, {p.bounds[1]:g}]", p.source)
        for p in predictor.parameters
    ]
    widths = [max(len(row[i]) for row in rows) for i in range(len(header) - 1)]
    for row, parameter in zip(rows, (None, *predictor.parameters), strict=True):
        cells = [cell.ljust(width) for cell, width in zip(row[:-1], widths, strict=True)]
        lines.append(("    " + "  ".join([*cells, row[-1]])).rstrip())
        if parameter is not None and parameter.description:
            lines.append(" " * (6 + widths[0]) + parameter.description)
    return "\n".join(lines)


def list_models(predictors: Mapping[str, Predictor]) -> str:
    """Every installed model, described by :func:`describe_model`, sorted by name."""
    if not predictors:
        return "no predictors installed"
    return "\n\n".join(describe_model(predictors[name]) for name in sorted(predictors))


# -- profiles ----------------------------------------------------------------------------------
def predictor_of_profile(path: Path, model: str | None) -> Predictor:
    """The predictor ``model`` with the parameters stored in the device profile file ``path``
    (spec/device-profile.md).

    A profile offers, in this order: the model a calibration fitted (its base with the effects
    it added, as a lateral force when that was observed; only in a calibrated profile), its
    predictor, the UV and EV models of a coupled predictor, and its leakage model. ``model``
    None takes the first.
    """
    from hcard.calibration.profile import fitted_model

    device = DeviceProfile.load(path)
    candidates: list[Predictor] = []
    if device.observation is not None:
        candidates.append(fitted_model(device))
    candidates.append(device.predictor)
    for part in (
        getattr(device.predictor, "uv", None),
        getattr(device.predictor, "ev", None),
        device.leakage,
    ):
        if isinstance(part, Predictor):
            candidates.append(part)
    if model is None:
        return candidates[0]
    for candidate in candidates:
        if candidate.name == model:
            return candidate
    held = ", ".join(c.name for c in candidates)
    raise ProfileError(f"{path}: holds no parameters for model {model!r} (it has: {held})")


# -- the command -------------------------------------------------------------------------------
@click.command("predict")
@verbosity_options
@click.argument("model", required=False)
@click.option(
    "--param",
    "params",
    multiple=True,
    metavar="NAME=VALUE",
    help="Set a model parameter; units accepted (normal_stiffness=3.9MN/m). Repeatable.",
)
@click.option(
    "--input",
    "inputs",
    multiple=True,
    metavar="NAME=VALUE",
    help="Set an input of the forward map; units accepted (speed=20mm/s). Repeatable.",
)
@click.option(
    "--sweep",
    "sweep_text",
    metavar="NAME=START:STOP:COUNT[:log]",
    help="Sweep one input or parameter over COUNT points (amplitude=0:5um:51); an "
    "end without a unit takes the other end's unit.",
)
@click.option(
    "-o",
    "--output",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Write the table as CSV (SI units, every input as a column) to this file.",
)
@click.option(
    "--plot",
    "plot_path",
    type=click.Path(dir_okay=False, path_type=Path),
    help="Plot the sweep to this file (.png, .pdf or .svg); needs --sweep.",
)
@click.option(
    "--profile",
    "profile_path",
    type=INPUT_FILE,
    help="Take the parameters from a device profile (hcard-device-profile/2, e.g. the "
    "profile.json of hcard calibrate); --param overrides them. Without MODEL, use the "
    "profile's fitted model (a calibrated profile) or its predictor.",
)
@click.option(
    "--list",
    "list_only",
    is_flag=True,
    help="List the models (or MODEL) with inputs, output and parameters (name, unit, "
    "default, bounds, source).",
)
def predict(
    model: str | None,
    params: tuple[str, ...],
    inputs: tuple[str, ...],
    sweep_text: str | None,
    output: Path | None,
    plot_path: Path | None,
    profile_path: Path | None,
    list_only: bool,
) -> None:
    """Evaluate a physics predictor MODEL at a point or over a sweep.

    Without MODEL (or with --list), list the installed predictors. Values are SI unless a
    unit is given; the table and CSV are in SI units, the plot in readable units.

    \b
    Examples:
      hcard predict --list
      hcard predict squeeze-film --input amplitude=2um --input normal_force=0.5N
      hcard predict squeeze-film --sweep amplitude=0:5um:51 -o sweep.csv --plot sweep.png
    """
    registry = get_registry()
    chosen = None if model is None else plugin_option("predictor", model, "MODEL")
    if list_only or (model is None and profile_path is None):
        click.echo(describe_model(chosen) if chosen else list_models(registry.predictors))
        return
    if plot_path is not None and plot_path.suffix.lower() not in PLOT_FORMATS:
        raise PredictUsageError(
            f"--plot {plot_path}: the file must end in {', '.join(PLOT_FORMATS)}"
        )
    if plot_path is not None and sweep_text is None:
        raise PredictUsageError("--plot needs --sweep: a single point is not a plot")
    predictor = chosen if profile_path is None else predictor_of_profile(profile_path, model)
    if predictor is None:  # unreachable: without MODEL or --profile the models were listed
        raise PredictUsageError("give a MODEL or --profile")

    with option_values(PredictorError):  # the values given, the names, the bounds
        prediction = evaluate(predictor, _assignments(params, "--param"),
                              _assignments(inputs, "--input"), sweep_text)
    if output is not None:
        headers, rows = prediction.columns(all_inputs=True)
        _write(output, to_csv(headers, rows))
        click.echo(f"{output}: {len(rows)} rows ({prediction.description()})")
    else:
        headers, rows = prediction.columns(all_inputs=False, readable=True)
        if prediction.sweep is not None:
            click.echo(f"# {prediction.description()}")
        click.echo(format_table(headers, rows))
    if plot_path is not None:
        figure = make_figure(prediction)
        buffer = io.BytesIO()
        figure.savefig(buffer, format=plot_path.suffix.lower().lstrip("."))
        _write(plot_path, buffer.getvalue())
        click.echo(f"{plot_path}: plot of {prediction.output.size} points")


COMMANDS = [predict]
