"""The calibration report: what the loop found, for people (Markdown, PNG) and programs (JSON).

:func:`write_report` writes into a directory:

- ``report.md``: leads with the held-out error before and after and the verdict, then the
  effects added with their fitted parameters, the selection criterion, the data, every
  candidate of every round, the effects skipped, the structure left, the residual analysis
  before and after, the base and final parameters, the figures and the wall time;
- ``report.json``: the same content, format :data:`FORMAT`, finite numbers only (NaN and
  infinities become ``null``), with the fitted profile;
- ``profile.json``: the fitted device profile (:mod:`hcard.calibration.profile`);
- ``residuals.png``: one panel per regressor: the binned mean residual (mN) before (base
  model) and after (final model) over a light scatter of the residual before;
- ``fit.png``: observed and predicted lateral force over a stretch of held-out samples, and
  predicted against observed (held-out samples), before and after.

Figures are drawn on matplotlib's Agg canvas directly (no pyplot). Every file is written
atomically (:func:`hcard.atomic.write_atomically`).
"""

from __future__ import annotations

import io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator, ScalarFormatter
from matplotlib.transforms import ScaledTranslation

from hcard import __version__
from hcard.atomic import write_atomically
from hcard.calibration.profile import parameter_table, profile_of
from hcard.calibration.residuals import ResidualReport
from hcard.calibration.results import CalibrationResult, ModelFit
from hcard.calibration.screening import SCREEN_TOLERANCE, describe_screening, screening_stride
from hcard.physics import PredictorError
from hcard.physics.profile import DeviceProfile
from hcard.preview_text import PathLabels
from hcard.quantities import MN_PER_N, N_PER_MN, SI_UNITS, display_unit

FORMAT = "hcard-calibration-report/1"
"""Value of the ``format`` key of ``report.json``."""

MARKDOWN = "report.md"
JSON = "report.json"
PROFILE = "profile.json"
RESIDUALS_PNG = "residuals.png"
FIT_PNG = "fit.png"

DPI = 100
"""Resolution of the figures, dots per inch."""
PANEL_INCHES = (3.2, 2.5)
"""Size of one regressor panel of ``residuals.png`` (width, height), inches."""
PANEL_COLUMNS = 3
"""Regressor panels per row."""
FIT_INCHES = (12.0, 4.0)
"""Size of ``fit.png``, inches."""
TICKS = MaxNLocator(nbins=5, steps=[1, 2, 2.5, 5, 10])
"""Where the figures' ticks go (:func:`_fixed_ticks`): at most 5 intervals (matplotlib's own
choice for the panels' axes is 5-8); each tick is a handful of artists to make and draw."""
PNG_COMPRESSION = 1
"""zlib level of the PNG figures: 1 encodes residuals.png in 23 ms instead of 39 ms (level 6,
PIL's default), for a file 15 % larger."""
MARGINS_INCHES = (0.62, 0.12, 0.5, 0.3)
"""Space around each panel's axes (left, right, bottom, top), inches: tick labels and the axis
label at left and below, the title above. The figures place their axes at these fixed margins
instead of running matplotlib's constrained layout, which drew every figure twice (with it,
residuals.png of 9-11 regressors took 0.56-0.79 s, without it and with fixed ticks 0.21-0.36 s;
bench/bench_calibration.py); tests/calibration/test_report.py checks that no panel's labels
leave its cell."""
MAX_SCATTER = 3000
"""Most points of a scatter."""
MAX_STRETCH_S = 2.0
"""Longest stretch of held-out samples drawn over time, s."""

REGRESSOR_UNITS = {
    **SI_UNITS,
    "occlusion_time": "s",
    "amplitude_history": "m",
    "voltage_history": "s",
    "recording": "",
}
"""SI unit of each regressor (:mod:`hcard.calibration.effects`, :mod:`.dataset`)."""

BEFORE_COLOUR = "tab:orange"
AFTER_COLOUR = "tab:blue"


@dataclass(frozen=True)
class ReportFiles:
    """The files :func:`write_report` wrote.

    Attributes:
        markdown: ``report.md``.
        json: ``report.json``.
        profile: ``profile.json``.
        figures: the PNG figures (empty with ``figures=False``).
    """

    markdown: Path
    json: Path
    profile: Path
    figures: list[Path] = field(default_factory=list)


# -- numbers for people -------------------------------------------------------------------------
def _mn(value: float | None) -> str:
    """A force in N as mN, the way :func:`~hcard.calibration.loop.calibrate` writes it."""
    if value is None or not math.isfinite(value):
        return "n/a"
    return f"{value * MN_PER_N:.4g}"


def _g(value: float | None, spec: str = ".3g") -> str:
    if value is None or not math.isfinite(value):
        return "n/a" if value is None or math.isnan(value) else ("inf" if value > 0 else "-inf")
    return format(value, spec)


def _with_unit(value: float, uncertainty: float | None, unit: str) -> str:
    """``"12.3 ± 0.4 ms"``: value (and uncertainty) in a readable unit."""
    scale, shown = display_unit(unit, [value])
    text = f"{value / scale:.4g}"
    if uncertainty is not None:
        text += " ± " + (
            f"{uncertainty / scale:.2g}" if math.isfinite(uncertainty) else "not identified"
        )
    return f"{text} {shown}" if shown else text


def _cell(text: Any) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    lines = [
        "| " + " | ".join(headers) + " |",
        "|" + "|".join("---" for _ in headers) + "|",
    ]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


# -- JSON ---------------------------------------------------------------------------------------
def _finite(value: Any) -> Any:
    """``value`` with numpy types as Python ones and NaN/inf as None, recursively."""
    if isinstance(value, Mapping):
        return {str(k): _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    if isinstance(value, np.ndarray):
        return [_finite(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        value = float(value)
        return value if math.isfinite(value) else None
    return value


def _analysis_dict(analysis: ResidualReport) -> dict[str, Any]:
    return {
        "n": analysis.n,
        "rms_n": analysis.rms,
        "regressors": {
            name: {
                "eta2": s.eta2,
                "f_statistic": s.f_statistic,
                "p_value": s.p_value,
                "spearman_rho": s.spearman_rho,
                "spearman_p": s.spearman_p,
                "monotonic": s.monotonic,
                "bin_centres": s.bin_centres,
                "bin_means_n": s.bin_means,
                "bin_counts": s.bin_counts,
            }
            for name, s in analysis.regressors.items()
        },
        "time": asdict(analysis.time),
    }


def _model_dict(step: ModelFit) -> dict[str, Any]:
    fit = step.fit
    return {
        "effects": list(step.effects),
        "held_out_rmse_n": step.test_rmse,
        "train_rmse_n": step.train_rmse,
        "score": step.score,
        "free": list(fit.free),
        "at_bounds": list(fit.at_bounds),
        "held": list(fit.held),
        "condition_number": fit.condition_number,
        "success": fit.success,
        "parameters": parameter_table(fit),
    }


def report_dict(
    result: CalibrationResult,
    figures: Sequence[str] = (),
    *,
    profile: DeviceProfile | None = None,
    rendering: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """The content of ``report.json`` (finite numbers only; ``figures``: relative file names)."""
    data = result.data
    content = {
        "format": FORMAT,
        "hcard_version": __version__,
        "model": result.model,
        "verdict": result.verdict,
        "summary": result.summary,
        "held_out_rmse_n": {"before": result.before.test_rmse, "after": result.after.test_rmse},
        "train_rmse_n": {"before": result.before.train_rmse, "after": result.after.train_rmse},
        "relative_change": -result.improvement,
        "effects_added": [
            {
                "name": name,
                "parameters": {
                    short: {"value": v, "uncertainty": s, "unit": u}
                    for short, (v, s, u) in result.effect_parameters(name).items()
                },
            }
            for name in result.after.effects
        ],
        "uncertainty_method": result.uncertainty_method,
        "bootstrap": None
        if result.bootstrap is None
        else {
            "samples": result.bootstrap.samples,
            "requested": result.bootstrap.requested,
            "capped": result.bootstrap.capped,
            "held": list(result.bootstrap.held),
            "seed": result.bootstrap.seed,
            "strokes": result.bootstrap.strokes,
            "uncertainties": result.bootstrap.uncertainties,
            "intervals_95": result.bootstrap.intervals,
            "jacobian_uncertainties": result.after.fit.uncertainties,
        },
        "criterion": result.settings.criterion(),
        "settings": asdict(result.settings),
        "screening": {
            "stride": screening_stride(int(np.count_nonzero(data.train)),
                                       result.settings.screen_samples),
            "tolerance": SCREEN_TOLERANCE,
            "description": describe_screening(int(np.count_nonzero(data.train)),
                                              result.settings.screen_samples),
        },
        "data": {
            "sources": list(data.sources),
            "samples": len(data),
            "training_samples": int(np.count_nonzero(data.train)),
            "held_out_samples": int(np.count_nonzero(data.test)),
            "split": data.split,
            "sample_rate_hz": data.sample_rate_hz,
            "sensor_zero": [
                {"source": source, "lifts": lifts, "drift_n": _finite(drift)}
                for source, (lifts, drift) in zip(data.sources, data.zeroing, strict=False)
            ],
            "regressors": list(data.regressors),
            "contact_threshold_n": list(data.contact_threshold_n),
        },
        "warnings": list(data.warnings),
        "library": list(result.library),
        "candidates": [asdict(c) for c in result.candidates],
        "runner_up": None
        if result.comparison is None
        else {
            **asdict(result.comparison),
            "description": result.comparison.describe(),
            "separation": result.settings.separation().describe(),
        },
        "skipped": dict(result.skipped),
        "structure": {
            "regressors": [
                {"name": n, "eta2": e, "p_value": p} for n, e, p in result.structure.regressors
            ],
            "autocorrelation": result.structure.autocorrelation,
            "in_time": result.structure.in_time,
            "dominant_frequency_hz": result.structure.dominant_frequency_hz,
            "description": result.structure.describe(),
            "small": [
                {"name": n, "eta2": e, "p_value": p} for n, e, p in result.structure.small
            ],
            "small_description": result.structure.describe_small(),
            "time_threshold": result.structure.time_threshold,
            "noise": None
            if result.structure.noise is None
            else {
                "sigma_n": result.structure.noise.sigma,
                "lag1": result.structure.noise.lag1,
                "samples": result.structure.noise.samples,
                "runs": result.structure.noise.runs,
            },
            "detectable_eta2_at_80_percent_power": dict(result.structure.detectable),
        },
        "residuals": {
            "before": _analysis_dict(result.before.analysis),
            "after": _analysis_dict(result.after.analysis),
        },
        "steps": [_model_dict(step) for step in result.steps],
        "before": _model_dict(result.before),
        "after": _model_dict(result.after),
        "profile": (profile if profile is not None else profile_of(result)).to_dict(),
        "rendering": None if rendering is None else dict(rendering),
        "figures": list(figures),
        "seconds": result.seconds,
    }
    return _finite(content)


# -- Markdown -----------------------------------------------------------------------------------
def _parameter_rows(table: Mapping[str, dict[str, Any]]) -> list[list[str]]:
    rows = []
    for name, entry in table.items():
        uncertainty = entry["uncertainty"]
        if entry["fitted"] and uncertainty is None:
            uncertainty = math.inf
        rows.append(
            [
                name,
                _with_unit(entry["value"], uncertainty if entry["fitted"] else None, entry["unit"]),
                "yes" if entry["fitted"] else "no",
            ]
        )
    return rows


def _residual_rows(analysis: ResidualReport) -> list[list[str]]:
    return [
        [name, f"{s.eta2:.3f}", _g(s.p_value, ".2g"), f"{s.spearman_rho:+.3f}"]
        for name, s in analysis.regressors.items()
    ]


def report_markdown(
    result: CalibrationResult,
    figures: Sequence[str] = (),
    *,
    rendering: Mapping[str, Any] | None = None,
) -> str:
    """The text of ``report.md`` (``figures``: relative file names to embed; ``rendering``: the
    verification on a device, :func:`hcard.calibration.verify.verification_dict`)."""
    before, after, data = result.before, result.after, result.data
    change = -100.0 * result.improvement
    lines = [
        f"# Calibration report: {result.model}",
        "",
        f"**Held-out RMSE: {_mn(before.test_rmse)} mN before, {_mn(after.test_rmse)} mN after "
        f"({change:+.1f} %).**",
        "",
    ]
    if rendering is not None:
        lines += [f"**Rendered friction error on the device: {rendering['text']}.**", ""]
    lines += [
        f"**Verdict: {result.verdict}.**",
        "",
    ]
    if after.effects:
        for name in after.effects:
            params = result.effect_parameters(name)
            shown = ", ".join(
                f"{short} = {_with_unit(v, s, u)}" for short, (v, s, u) in params.items()
            )
            lines.append(f"- Added **{name}**: {shown or 'no parameters'}")
    else:
        lines.append("- No effect added.")
    lines += ["", result.summary, ""]
    if data.warnings:
        lines += ["## Warnings", ""]
        lines += [f"- {text}" for text in data.warnings]
        lines.append("")

    lines += ["## Selection criterion", "", result.settings.criterion() + ".", ""]
    s = result.settings
    lines += [
        f"Thresholds: minimum held-out improvement {s.min_improvement:.0%}, alpha {s.alpha:g}, "
        f"structure eta² ≥ {s.min_eta2:g}, signature eta² ≥ {s.signature_eta2:g}, "
        f"time structure at lag-1 autocorrelation ≥ {s.min_autocorrelation:g}, at most "
        f"{s.max_effects} effects, {s.bins} bins.",
        "",
    ]
    screening = describe_screening(int(np.count_nonzero(data.train)), s.screen_samples)
    if screening:
        lines += [screening, ""]

    lines += ["## Data", ""]
    lines += [f"- Source: {source}" for source in data.sources]
    lines += [
        f"- Samples: {len(data)}, {int(np.count_nonzero(data.used))} in contact "
        f"({int(np.count_nonzero(data.train))} training, "
        f"{int(np.count_nonzero(data.test))} held out)",
        f"- Split: {data.split}",
        *(
            f"- Lateral-force zero of {source}: "
            + (
                f"measured at {lifts} lifts, drift {drift * MN_PER_N:.3g} mN peak to peak, removed"
                if lifts
                else "no lift to measure it (a constant offset is fitted)"
            )
            for source, (lifts, drift) in zip(data.sources, data.zeroing, strict=False)
        ),
        *(
            f"- Contact of {source}: normal force ≥ {threshold * MN_PER_N:.3g} mN (the larger of "
            "10 mN and 5 standard deviations of the lifted normal-force noise, unless given)"
            for source, threshold in zip(data.sources, data.contact_threshold_n, strict=False)
        ),
        f"- Sample rate: {data.sample_rate_hz:.4g} Hz",
        f"- Regressors: {', '.join(data.regressors) or 'none'}",
        "",
    ]

    lines += ["## Candidates", ""]
    if result.candidates:
        lines += _table(
            [
                "round",
                "effect",
                "held-out RMSE (mN)",
                "change",
                "ΔH",
                "signature eta²",
                "added",
                "note",
            ],
            [
                [
                    c.round,
                    c.effect,
                    _mn(c.test_rmse),
                    "n/a" if c.improvement is None else f"{-100 * c.improvement:+.1f} %",
                    _g(c.score_change, ".1f"),
                    f"{c.signature_eta2:.3f}",
                    "yes" if c.accepted else "no",
                    f"{c.note} (screened)" if c.screened else c.note,
                ]
                for c in result.candidates
            ],
        )
    else:
        lines.append("No effect could be tried.")
    lines.append("")

    lines += ["## Runner-up", ""]
    comparison = result.comparison
    if comparison is None:
        lines.append("No other model of as many effects was fitted.")
    else:
        chosen, runner = comparison.names()
        lines += _table(
            ["model", "held-out RMSE (mN)", "held-out criterion H margin"],
            [
                [chosen + " (final)", _mn(comparison.chosen_rmse), "0"],
                [runner + " (runner-up)", _mn(comparison.runner_up_rmse),
                 f"{comparison.criterion_margin:+.1f}"],
            ],
        )
        lines += [
            "",
            f"Margin: held-out RMSE {100 * comparison.rmse_margin:+.1f} %, criterion "
            f"{comparison.criterion_margin:+.1f}; {result.settings.separation().describe()}: "
            + ("**not separated**." if comparison.ambiguous else "separated."),
        ]
        if comparison.separating_regressor is not None:
            lines.append(
                f"Their predictions differ most against {comparison.separating_regressor} "
                f"(eta² {comparison.separating_eta2:.3f}, up to "
                f"{100 * comparison.largest_difference:+.2g} % near "
                f"{comparison.at_value:.3g}); to separate them, record "
                f"{comparison.measurement}."
            )
    lines.append("")

    lines += ["## Effects skipped", ""]
    if result.skipped:
        lines += [f"- {name}: {why}" for name, why in result.skipped.items()]
    else:
        lines.append("None.")
    lines += [
        "",
        "## Structure left",
        "",
        f"Structure in the final residual: {result.structure.describe()}.",
        "",
    ]
    structure = result.structure
    if structure.small:
        lines += [f"Also {structure.describe_small()}.", ""]
    lines += [
        "Noise model: "
        + (structure.noise.describe() if structure.noise is not None
           else "no lift long enough to measure the sensor noise")
        + f"; the residual counts as structured in time at a lag-1 autocorrelation of "
        f"{structure.time_threshold:.2f} or more (at least {s.min_autocorrelation:g}, and "
        "less than half of the noise's own decorrelation left).",
        "",
        f"Power: with {after.analysis.effective_samples:.0f} effectively independent samples "
        f"the F-tests detect, with 80 % probability at alpha {s.alpha:g}, structure explaining "
        "eta² of at least: "
        + ", ".join(f"{name} {eta2:.3g}" for name, eta2 in structure.detectable)
        + ".",
        "",
    ]

    headers = ["regressor", "eta²", "p", "Spearman rho"]
    lines += ["## Residual analysis", "", f"### Before: {result.model}", ""]
    lines += _table(headers, _residual_rows(before.analysis))
    t = before.analysis.time
    lines += ["", f"Lag-1 autocorrelation {t.lag1_autocorrelation:.3f}.", ""]
    lines += [f"### After: {'+'.join([result.model, *after.effects])}", ""]
    if after is before:
        lines.append("Nothing was added: the final model is the base model above.")
    else:
        lines += _table(headers, _residual_rows(after.analysis))
        t = after.analysis.time
        lines += ["", f"Lag-1 autocorrelation {t.lag1_autocorrelation:.3f}."]
    lines.append("")

    lines += ["## Parameters", "", f"Uncertainties: {result.uncertainty_method}.", ""]
    if result.bootstrap is not None:
        boot = result.bootstrap
        lines += _table(
            ["parameter", "value", "bootstrap σ", "95 % interval", "Jacobian σ"],
            [
                [name, _g(after.fit.params[name], ".4g"), _g(boot.uncertainties[name], ".2g"),
                 f"{_g(low, '.4g')} to {_g(high, '.4g')}",
                 _g(after.fit.uncertainties.get(name), ".2g")]
                for name, (low, high) in boot.intervals.items()
            ],
        )
        lines += ["", "The tables below give the fit's own (Jacobian) uncertainties.", ""]
    lines += ["### Base model fit", ""]
    lines += _table(["parameter", "value", "fitted"], _parameter_rows(parameter_table(before.fit)))
    lines += ["", "### Final model fit", ""]
    lines += _table(["parameter", "value", "fitted"], _parameter_rows(parameter_table(after.fit)))
    if after.fit.at_bounds:
        lines += ["", f"At a bound (uncertainty not meaningful): {', '.join(after.fit.at_bounds)}"]
    if after.fit.held:
        lines += ["", "Held at their start values (no training sample moves when they do, so "
                  f"these recordings say nothing about them): {', '.join(after.fit.held)}"]
    lines += ["", f"The fitted profile is in [{PROFILE}]({PROFILE}).", ""]

    if figures:
        lines += ["## Figures", ""]
        captions = {
            RESIDUALS_PNG: "Residual against each regressor, binned means before and after",
            FIT_PNG: "Observed and predicted lateral force, held-out samples",
        }
        for name in figures:
            lines += [f"![{captions.get(name, name)}]({name})", ""]

    lines += [
        "## Wall time",
        "",
        f"Calibration loop: {result.seconds:.1f} s ({len(result.candidates)} candidate fits).",
        "",
    ]
    return "\n".join(lines)


# -- figures ------------------------------------------------------------------------------------
def _png(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI, metadata={"Software": f"hcard {__version__}"},
                pil_kwargs={"compress_level": PNG_COMPRESSION})
    return buffer.getvalue()


def _subsample(indices: np.ndarray, most: int) -> np.ndarray:
    if indices.size <= most:
        return indices
    pick = np.random.default_rng(0).choice(indices.size, size=most, replace=False)
    return indices[np.sort(pick)]


def residuals_grid(n_regressors: int) -> tuple[int, int]:
    """(rows, columns) of the panels of ``residuals.png`` for ``n_regressors``."""
    columns = max(1, min(PANEL_COLUMNS, n_regressors))
    return max(1, math.ceil(n_regressors / columns)), columns


def _panel(fig: Figure, row: int, column: int, rows: int, cell_inches: tuple[float, float],
           span: int = 1) -> Axes:
    """Axes in the cell (``row``, ``column``) of a ``rows``-row grid of cells of
    ``cell_inches`` (``span`` cells wide), inside :data:`MARGINS_INCHES`."""
    width, height = fig.get_size_inches()
    left, right, bottom, top = MARGINS_INCHES
    x0 = column * cell_inches[0] + left
    y0 = (rows - 1 - row) * cell_inches[1] + bottom
    return fig.add_axes((x0 / width, y0 / height,
                         (span * cell_inches[0] - left - right) / width,
                         (cell_inches[1] - bottom - top) / height))


def _fixed_ticks(ax: Axes) -> None:
    """Fix ``ax``'s ticks for its current limits at :data:`TICKS` (steps of 1, 2, 2.5 or 5
    times a power of ten, as matplotlib's automatic locator): the automatic locator runs
    again at every stage of a draw, and took about half of the drawing of a panel."""
    for axis, limits in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
        low, high = sorted(limits)
        ticks = np.asarray(TICKS.tick_values(low, high))
        slack = 1e-9 * (high - low)
        axis.set_ticks(ticks[(ticks >= low - slack) & (ticks <= high + slack)])


TICK_LABEL_PT = 7.0
"""Font size of the residual panels' tick labels, points."""
TICK_GAP_PT = 7.0
"""From the axes' edge to its tick labels, points (matplotlib's tick length plus its pad)."""
LABEL_GAP_PT = 4.0
"""From the tick labels to the axis label, points (matplotlib's label pad)."""


def _tick_texts(ticks: np.ndarray) -> list[str]:
    """The tick labels matplotlib would write for ``ticks``, without an offset or a power of
    ten taken out (the panels have no room for the offset text)."""
    formatter = ScalarFormatter(useOffset=False)
    formatter.set_scientific(False)
    formatter.set_locs(ticks)  # type: ignore[arg-type]  # stubs say list; any sequence works
    return [formatter(value) for value in ticks]


def _outlined_tick_labels(ax: Axes, *, left: bool) -> None:
    """Label ``ax``'s fixed ticks with glyph outlines, one collection per axis
    (:class:`hcard.preview_text.PathLabels`), below the x axis and, if ``left``, left of the y
    axis, and place its axis labels beyond them. matplotlib's ``Text`` costs about 1 ms per
    label to lay out and draw: the ~100 tick labels of a figure of 11 panels took a third of
    it."""
    fig = ax.get_figure()
    assert isinstance(fig, Figure)  # the residual panels' axes sit on the figure itself
    inches = fig.dpi_scale_trans
    gap = TICK_GAP_PT / 72.0
    ax.tick_params(labelbottom=False, labelleft=False)
    box = ax.get_position()
    width_in, height_in = fig.get_size_inches()
    axes_width_in, axes_height_in = box.width * width_in, box.height * height_in
    x_ticks = ax.get_xticks()
    below = ax.get_xaxis_transform() + ScaledTranslation(0.0, -gap, inches)
    x_labels = PathLabels(_tick_texts(x_ticks), np.column_stack(
        [x_ticks, np.zeros_like(x_ticks)]), size_pt=TICK_LABEL_PT, inches=inches,
        offset_transform=below, ha="center", va="top", clip_on=False)
    ax.add_collection(x_labels, autolim=False)
    # from the top of the capitals down to the lowest control point (the outlines' control
    # points bound their curves; Path.get_extents solves for the curves' extrema and took a
    # third of the figure's time)
    label_height_in = max((-float(np.asarray(path.vertices)[:, 1].min())
                           for path in x_labels.get_paths() if len(np.asarray(path.vertices))),
                          default=0.0)
    ax.xaxis.set_label_coords(
        0.5, -(gap + label_height_in + LABEL_GAP_PT / 72.0) / axes_height_in)
    if not left:
        return
    y_ticks = ax.get_yticks()
    texts = _tick_texts(y_ticks)
    beside = ax.get_yaxis_transform() + ScaledTranslation(-gap, 0.0, inches)
    labels = PathLabels(texts, np.column_stack([np.zeros_like(y_ticks), y_ticks]),
                        size_pt=TICK_LABEL_PT, inches=inches, offset_transform=beside,
                        ha="right", va="center", clip_on=False)
    ax.add_collection(labels, autolim=False)
    widest_in = max((float(np.ptp(np.asarray(path.vertices)[:, 0])) for path in labels.get_paths()
                     if len(np.asarray(path.vertices))), default=0.0)
    ax.yaxis.set_label_coords(
        -(gap + widest_in + LABEL_GAP_PT / 72.0) / axes_width_in, 0.5)


def residuals_figure(result: CalibrationResult) -> Figure:
    """``residuals.png`` as a figure (Agg canvas attached)."""
    names = list(result.data.regressors)
    rows, columns = residuals_grid(len(names))
    fig = Figure(figsize=(PANEL_INCHES[0] * columns, PANEL_INCHES[1] * rows), dpi=DPI)
    FigureCanvasAgg(fig)
    before = result.before.fit.residuals
    pick = _subsample(np.flatnonzero(result.data.used), MAX_SCATTER)
    low, high = np.percentile(before[pick], [1.0, 99.0]) if pick.size else (0.0, 0.0)
    if not names:
        ax = fig.add_subplot(1, 1, 1)
        ax.text(0.5, 0.5, "no regressor varies in these data", ha="center", va="center")
        ax.set_axis_off()
        return fig
    # one residual scale for every panel: the binned means of all regressors compare at a
    # glance, and only the first column needs its tick labels
    means = np.concatenate([
        np.concatenate([result.before.analysis.regressors[name].bin_means,
                        result.after.analysis.regressors[name].bin_means])
        for name in names])
    span_low = min(float(low), float(np.nanmin(means, initial=low)))
    span_high = max(float(high), float(np.nanmax(means, initial=high)))
    # in mN for the usual residuals, N or kN should a fit be far off: tick labels of at most
    # four digits, which the panel's margin holds
    force_scale, force_unit = (N_PER_MN, "mN") if max(-span_low, span_high) < 1.0 else display_unit(
        "N", [span_low, span_high])
    before = before / force_scale
    span_low, span_high = span_low / force_scale, span_high / force_scale
    pad = 0.05 * (span_high - span_low) or 1.0
    for k, name in enumerate(names):
        ax = _panel(fig, k // columns, k % columns, rows, PANEL_INCHES)
        x = result.data.regressors[name]
        scale, unit = display_unit(REGRESSOR_UNITS.get(name, ""), x)
        ax.scatter(
            x[pick] / scale, before[pick], s=2, c="0.75", alpha=0.5, linewidths=0
        )
        stats_b = result.before.analysis.regressors[name]
        stats_a = result.after.analysis.regressors[name]
        ax.plot(
            stats_b.bin_centres / scale,
            stats_b.bin_means / force_scale,
            "o-",
            color=BEFORE_COLOUR,
            ms=3,
            lw=1.2,
            label="before",
        )
        ax.plot(
            stats_a.bin_centres / scale,
            stats_a.bin_means / force_scale,
            "s-",
            color=AFTER_COLOUR,
            ms=3,
            lw=1.2,
            label="after",
        )
        ax.axhline(0.0, color="0.4", lw=0.6)
        ax.set_ylim(span_low - pad, span_high + pad)
        ax.set_title(f"{name}: eta² {stats_b.eta2:.2f} → {stats_a.eta2:.2f}", fontsize=9, y=1.0)
        ax.set_xlabel(f"{name} [{unit or '-'}]", fontsize=8)
        _fixed_ticks(ax)
        first_column = k % columns == 0
        if first_column:
            ax.set_ylabel(f"residual [{force_unit}]", fontsize=8)
        _outlined_tick_labels(ax, left=first_column)
        if k == 0:
            ax.legend(fontsize=7, loc="upper right")
    return fig


def _held_out_stretch(result: CalibrationResult) -> np.ndarray:
    """Indices of the window of at most :data:`MAX_STRETCH_S` (within one recording) holding
    the most held-out samples, starting at a held-out sample."""
    data = result.data
    test = data.test
    if not test.any():
        return np.zeros(0, dtype=np.intp)
    width = max(1, round(MAX_STRETCH_S * data.sample_rate_hz))
    counts = np.concatenate([[0], np.cumsum(test)])
    starts = np.flatnonzero(test)
    ends = np.minimum(starts + width, test.size)
    ends = np.minimum(ends, np.searchsorted(data.recording, data.recording[starts], "right"))
    best = int(np.argmax(counts[ends] - counts[starts]))
    return np.arange(starts[best], ends[best])


def fit_figure(result: CalibrationResult) -> Figure:
    """``fit.png`` as a figure (Agg canvas attached)."""
    data = result.data
    observed = data.observed * MN_PER_N
    before = observed - result.before.fit.residuals * MN_PER_N
    after = observed - result.after.fit.residuals * MN_PER_N
    fig = Figure(figsize=FIT_INCHES, dpi=DPI)
    FigureCanvasAgg(fig)
    cell = (FIT_INCHES[0] / 3, FIT_INCHES[1])
    ax = _panel(fig, 0, 0, 1, cell, span=2)
    window = _held_out_stretch(result)
    timed = data.time_ordered and "time" in data.inputs
    if window.size:
        t = data.inputs["time"][window] if timed else window.astype(np.float64)
        held = data.test[window]

        def masked(values: np.ndarray) -> np.ndarray:
            return np.where(held, values[window], np.nan)

        ax.plot(t, masked(observed), color="black", lw=0.8, label="observed")
        ax.plot(
            t,
            masked(before),
            color=BEFORE_COLOUR,
            lw=1.0,
            label=f"before ({_mn(result.before.test_rmse)} mN)",
        )
        ax.plot(
            t,
            masked(after),
            color=AFTER_COLOUR,
            lw=1.0,
            label=f"after ({_mn(result.after.test_rmse)} mN)",
        )
        ax.legend(fontsize=8, loc="best")
    ax.set_xlabel("time [s]" if timed else "sample")
    quantity = "lateral force" if result.observation == "lateral_force" else "force"
    ax.set_ylabel(f"{quantity} [mN]")
    ax.set_title("(a) held-out strokes (gaps: training samples)", fontsize=10, y=1.0)
    _fixed_ticks(ax)

    ax = _panel(fig, 0, 2, 1, cell)
    pick = _subsample(np.flatnonzero(data.test), MAX_SCATTER)
    for predicted, colour, label in (
        (before, BEFORE_COLOUR, "before"),
        (after, AFTER_COLOUR, "after"),
    ):
        ax.scatter(
            observed[pick],
            predicted[pick],
            s=3,
            c=colour,
            alpha=0.4,
            linewidths=0,
            label=label,
            rasterized=True,
        )
    if pick.size:
        values = np.concatenate([observed[pick], before[pick], after[pick]])
        low, high = float(values.min()), float(values.max())
        ax.plot([low, high], [low, high], color="0.3", lw=0.8, ls="--", label="identity")
    ax.set_xlabel("observed [mN]")
    ax.set_ylabel("predicted [mN]")
    ax.set_title("(b) held-out: predicted vs observed", fontsize=10, y=1.0)
    _fixed_ticks(ax)
    ax.legend(fontsize=8, loc="best", markerscale=3)
    return fig


# -- the report ---------------------------------------------------------------------------------
def write_report(
    result: CalibrationResult,
    directory: str | os.PathLike[str],
    *,
    figures: bool = True,
    profile: DeviceProfile | None = None,
    rendering: Mapping[str, Any] | None = None,
) -> ReportFiles:
    """Write the report of ``result`` into ``directory`` (created if needed; module docstring).

    ``profile``: the fitted device profile (default: :func:`~hcard.calibration.profile.
    profile_of` the result, for a bare predictor); ``rendering``: the rendering errors measured
    on a device without and with it, when they were.

    Raises:
        PredictorError: ``directory`` exists but is not a directory, or cannot be created.
    """
    folder = Path(directory)
    if folder.exists() and not folder.is_dir():
        raise PredictorError(f"{folder}: exists and is not a directory; cannot write a report")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise PredictorError(f"{folder}: cannot create the report directory ({exc})") from None
    profile = profile if profile is not None else profile_of(result)

    written: list[Path] = []
    if figures:
        for name, draw in ((RESIDUALS_PNG, residuals_figure), (FIT_PNG, fit_figure)):
            path = folder / name
            write_atomically(path, _png(draw(result)))
            written.append(path)
    names = [p.name for p in written]
    profile_path = folder / PROFILE
    write_atomically(profile_path, profile.to_json())
    content = report_dict(result, names, profile=profile, rendering=rendering)
    text = json.dumps(content, indent=2, allow_nan=False, ensure_ascii=False)
    report_json = folder / JSON
    write_atomically(report_json, (text + "\n").encode("utf-8"))
    markdown = folder / MARKDOWN
    write_atomically(markdown, report_markdown(result, names, rendering=rendering).encode("utf-8"))
    return ReportFiles(markdown=markdown, json=report_json, profile=profile_path,
                       figures=written)
