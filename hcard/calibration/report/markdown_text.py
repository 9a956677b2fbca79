"""``report.md``: a calibration report for people (:mod:`hcard.calibration.report`). It leads
with the held-out error before and after and the verdict, then the effects added with their
fitted parameters, the selection criterion, the data, every candidate of every round, the
runner-up, the effects skipped, the structure left, the residual analysis before and after, the
base and final parameters, the figures and the wall time."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from hcard.calibration.profile import parameter_table
from hcard.calibration.report.files import FIT_PNG, PROFILE, RESIDUALS_PNG
from hcard.calibration.report.number_text import force_in_mn, number, value_with_unit
from hcard.calibration.residuals import ResidualReport
from hcard.calibration.results import CalibrationResult
from hcard.calibration.screening import describe_screening
from hcard.quantities import MN_PER_N


def _cell(text: Any) -> str:
    """``text`` as one cell of a Markdown table: ``|`` escaped, on one line."""
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """The lines of a Markdown table of ``rows`` under ``headers``."""
    lines = [
        "| " + " | ".join(headers) + " |",
        "|" + "|".join("---" for _ in headers) + "|",
    ]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return lines


def _parameter_rows(table: Mapping[str, dict[str, Any]]) -> list[list[str]]:
    rows = []
    for name, entry in table.items():
        uncertainty = entry["uncertainty"]
        if entry["fitted"] and uncertainty is None:
            uncertainty = math.inf
        rows.append(
            [
                name,
                value_with_unit(entry["value"], uncertainty if entry["fitted"] else None,
                                entry["unit"]),
                "yes" if entry["fitted"] else "no",
            ]
        )
    return rows


def _residual_rows(analysis: ResidualReport) -> list[list[str]]:
    return [
        [name, f"{s.eta2:.3f}", number(s.p_value, ".2g"), f"{s.spearman_rho:+.3f}"]
        for name, s in analysis.regressors.items()
    ]


def report_markdown(
    result: CalibrationResult,
    figures: Sequence[str] = (),
    *,
    rendering: Mapping[str, Any] | None = None,
) -> str:
    """The text of ``report.md`` (``figures``: relative file names to embed; ``rendering``: the
    rendering errors measured on a device without and with the fitted profile, as
    ``hcard calibrate --verify`` gives them: ``Verification.to_dict()`` of
    :mod:`hcard.device.verify`, whose ``text`` leads the report)."""
    before, after, data = result.before, result.after, result.data
    change = -100.0 * result.improvement
    lines = [
        f"# Calibration report: {result.model}",
        "",
        f"**Held-out RMSE: {force_in_mn(before.test_rmse)} mN before, "
        f"{force_in_mn(after.test_rmse)} mN after ({change:+.1f} %).**",
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
                f"{short} = {value_with_unit(v, s, u)}" for short, (v, s, u) in params.items()
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
                    force_in_mn(c.test_rmse),
                    "n/a" if c.improvement is None else f"{-100 * c.improvement:+.1f} %",
                    number(c.score_change, ".1f"),
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
                [chosen + " (final)", force_in_mn(comparison.chosen_rmse), "0"],
                [runner + " (runner-up)", force_in_mn(comparison.runner_up_rmse),
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
                [name, number(after.fit.params[name], ".4g"),
                 number(boot.uncertainties[name], ".2g"),
                 f"{number(low, '.4g')} to {number(high, '.4g')}",
                 number(after.fit.uncertainties.get(name), ".2g")]
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
