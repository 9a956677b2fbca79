"""The population report (spec/calibration.md K25): ``population.md``, ``population.json``
(``"format": "hcard-population-report/1"``, finite numbers or null) and ``forest.png``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hcard.atomic import write_atomically
from hcard.calibration.population.population_fit import PopulationResult
from hcard.calibration.population.random_effects import RandomEffects

FORMAT = "hcard-population-report/1"
METHOD = (
    "two-stage mixed effects: each participant fitted alone (bounded least squares, "
    "uncertainties sigma^2 (J^T J)^-1); per parameter a normal random-effects model "
    "y_i ~ N(theta_i, s_i^2), theta_i ~ N(mu, tau^2), tau^2 by REML, mu its weighted mean; "
    "95 % intervals: Knapp-Hartung for mu (t with k-1 df, q = max(1, Q_w/(k-1))), Q-profile "
    "for tau; shrunken estimates mu + tau^2/(tau^2 + s_i^2) (y_i - mu)"
)


@dataclass(frozen=True)
class PopulationFiles:
    """The files written: ``markdown``, ``json`` and the ``figures`` (none with figures off)."""

    markdown: Path
    json: Path
    figures: tuple[Path, ...]


def _number(value: float | None) -> float | None:
    """A finite float, or None (JSON null) for NaN, infinity or None."""
    return float(value) if value is not None and math.isfinite(value) else None


def _interval(pair: tuple[float, float] | None) -> list[float | None] | None:
    return None if pair is None else [_number(pair[0]), _number(pair[1])]


def _population_dict(pop: RandomEffects, unit: str, excluded: tuple[str, ...]) -> dict[str, Any]:
    return {
        "unit": unit, "k": pop.k, "mu": _number(pop.mu), "mu_se": _number(pop.mu_se),
        "mu_interval": _interval(pop.mu_interval), "tau": _number(pop.tau),
        "tau_interval": _interval(pop.tau_interval),
        "prediction_interval": _interval(pop.prediction_interval),
        "tau_dersimonian_laird": _number(pop.tau_dl), "q": _number(pop.q), "i2": _number(pop.i2),
        "excluded": list(excluded),
    }


def population_document(result: PopulationResult) -> dict[str, Any]:
    """The JSON document of ``result`` (K25)."""
    shrunken: dict[str, dict[str, tuple[float, float]]] = {}
    for name, pop in result.population.items():
        members = [p.label for p in result.fitted if p.label not in result.excluded[name]]
        for label, value, se in zip(members, pop.shrunken, pop.shrunken_se, strict=True):
            shrunken.setdefault(label, {})[name] = (value, se)
    participants = []
    for part in result.participants:
        entry: dict[str, Any] = {
            "label": part.label, "sources": list(part.sources),
            "status": "fitted" if part.fit is not None else "failed", "error": part.error or None,
            "held_out_rmse": _number(part.held_out_rmse),
            "never_seen_rmse": _number(part.never_seen_rmse),
            "flags": dict(part.flags), "parameters": {},
        }
        if part.fit is not None:
            entry["n_train"], entry["n_test"] = part.fit.n_train, part.fit.n_test
            for name in result.parameters:
                value, se = shrunken.get(part.label, {}).get(name, (math.nan, math.nan))
                entry["parameters"][name] = {
                    "estimate": _number(part.fit.params[name]),
                    "se": _number(part.fit.uncertainties.get(name)),
                    "shrunken": _number(value), "shrunken_se": _number(se),
                }
        participants.append(entry)
    return {
        "format": FORMAT, "model": result.model, "by": result.by, "unit": result.unit,
        "method": METHOD, "settings": result.settings,
        "effects": {
            "added": list(result.effects),
            "rule": "lowest summed held-out criterion change, when negative and the effect "
                    "earns its place (K9 a, b) for at least half the participants; a "
                    "participant is flagged where its own decision differs (K24)",
            "trials": [{"effect": t.effect, "round": t.round,
                        "summed_criterion_change": _number(t.summed_change),
                        "earns_place_for": t.own_count, "participants": len(t.own),
                        "added": t.added} for t in result.trials],
            "skipped": dict(result.skipped),
        },
        "population": {name: _population_dict(pop, result.units.get(name, ""),
                                              result.excluded.get(name, ()))
                       for name, pop in result.population.items()},
        "errors": {"held_out_rmse": _number(result.mean_error("held_out_rmse")),
                   "never_seen_rmse": _number(result.mean_error("never_seen_rmse")),
                   "meaning": "root mean square over participants of each participant's "
                              "held-out RMSE: with its own fit, and predicted with the "
                              "population mean of the others (leave one participant out)"},
        "participants": participants,
        "failed": [{"label": p.label, "error": p.error} for p in result.failed],
    }


def _g(value: float | None) -> str:
    return "-" if value is None or not math.isfinite(value) else f"{value:.4g}"


def population_markdown(result: PopulationResult, document: dict[str, Any]) -> str:
    """The Markdown report (K25): the population of each parameter, the errors, the effects,
    then the per-participant table."""
    unit = result.unit
    lines = [f"# Population calibration of {result.model}", "",
             f"{len(result.fitted)} {result.by}s fitted"
             + (f", {len(result.failed)} failed" if result.failed else "")
             + f". Held-out error (RMS over {result.by}s): "
             f"{_g(result.mean_error('held_out_rmse'))} {unit} with each one's own fit, "
             f"{_g(result.mean_error('never_seen_rmse'))} {unit} for a {result.by} never seen "
             "(population mean of the others).", "",
             f"Method: {METHOD}.", "", "## Population", "",
             "| parameter | mu | 95 % interval | tau | 95 % interval | prediction interval | k |",
             "|---|---|---|---|---|---|---|"]
    for name, pop in result.population.items():
        unit_text = result.units.get(name, "")
        pi = pop.prediction_interval
        lines.append(
            f"| {name} ({unit_text or '-'}) | {_g(pop.mu)} | {_g(pop.mu_interval[0])} .. "
            f"{_g(pop.mu_interval[1])} | {_g(pop.tau)} | {_g(pop.tau_interval[0])} .. "
            f"{_g(pop.tau_interval[1])} | "
            + (f"{_g(pi[0])} .. {_g(pi[1])}" if pi else "-") + f" | {pop.k} |")
    lines += ["", "## Effects", "",
              f"Added for the population: {', '.join(result.effects) or 'none'}. "
              + document["effects"]["rule"] + ".", ""]
    if result.trials:
        lines += ["| round | effect | summed change of H | earns its place for | added |",
                  "|---|---|---|---|---|"]
        lines += [f"| {t.round} | {t.effect} | {_g(t.summed_change)} | {t.own_count} of "
                  f"{len(t.own)} | {'yes' if t.added else 'no'} |" for t in result.trials]
    for name, why in result.skipped.items():
        lines.append(f"- {name} not tried: {why}")
    names = list(result.parameters)
    lines += ["", f"## {result.by.capitalize()}s", "",
              "| " + " | ".join([result.by, "held-out RMSE", "never seen RMSE",
                                 *[f"{n} (shrunken)" for n in names], "flags"]) + " |",
              "|" + "---|" * (4 + len(names))]
    for entry in document["participants"]:
        if entry["status"] != "fitted":
            lines.append(f"| {entry['label']} | failed: {entry['error']} |")
            continue
        cells = [f"{_g(p['estimate'])} ± {_g(p['se'])} ({_g(p['shrunken'])})"
                 for p in entry["parameters"].values()]
        flags = "; ".join(f"{why} {effect}" for effect, why in entry["flags"].items())
        lines.append(f"| {entry['label']} | {_g(entry['held_out_rmse'])} | "
                     f"{_g(entry['never_seen_rmse'])} | " + " | ".join(cells)
                     + f" | {flags or '-'} |")
    return "\n".join(lines) + "\n"


def forest_plot(result: PopulationResult, path: Path) -> Path:
    """A forest plot (PNG): per parameter, each participant's estimate with its 95 % interval
    (``1.96 s_i``) and its shrunken estimate, the population mean with its interval and the
    prediction interval as bands."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result.population)
    fitted = result.fitted
    height = max(3.0, 0.18 * len(fitted) + 1.5)
    fig, axes = plt.subplots(1, max(1, len(names)), figsize=(4.2 * max(1, len(names)), height),
                             squeeze=False, sharey=True)
    for ax, name in zip(axes[0], names, strict=False):
        pop = result.population[name]
        members = [p for p in fitted if p.label not in result.excluded[name]]
        rows = list(range(len(members)))
        values = [p.fit.params[name] for p in members if p.fit is not None]
        errors = [1.96 * p.fit.uncertainties[name] for p in members if p.fit is not None]
        ax.errorbar(values, rows, xerr=errors, fmt="o", ms=3, color="0.3", lw=0.8,
                    label="own fit, 95 %")
        ax.plot(pop.shrunken, rows, "x", color="tab:red", ms=4, label="shrunken")
        if pop.prediction_interval is not None:
            ax.axvspan(*pop.prediction_interval, color="tab:blue", alpha=0.08,
                       label="prediction interval")
        ax.axvspan(*pop.mu_interval, color="tab:blue", alpha=0.25, label="mu, 95 %")
        ax.axvline(pop.mu, color="tab:blue", lw=1)
        ax.set_yticks(rows, [p.label for p in members], fontsize=6)
        unit = result.units.get(name, "")
        ax.set_xlabel(f"{name}" + (f" ({unit})" if unit else ""))
        ax.set_title(f"mu {pop.mu:.3g}, tau {pop.tau:.3g}", fontsize=9)
        ax.invert_yaxis()
    axes[0][0].legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_population_report(result: PopulationResult, directory: Path, *,
                            figures: bool = True) -> PopulationFiles:
    """Write ``population.md``, ``population.json`` and (with ``figures``) ``forest.png``
    into ``directory`` (created), each atomically."""
    directory.mkdir(parents=True, exist_ok=True)
    document = population_document(result)
    markdown = directory / "population.md"
    json_path = directory / "population.json"
    write_atomically(json_path, (json.dumps(document, indent=2, allow_nan=False)
                                 + "\n").encode())
    write_atomically(markdown, population_markdown(result, document).encode())
    drawn = (forest_plot(result, directory / "forest.png"),) if figures and result.population \
        else ()
    return PopulationFiles(markdown, json_path, drawn)
