"""The calibration report (Markdown, JSON, PNG) and the fitted device profile."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import matplotlib
import numpy as np
import pytest
from matplotlib.image import imread

from hcard.calibration.dataset import prepare
from hcard.calibration.loop import calibrate
from hcard.calibration.measurement import Measurement
from hcard.calibration.profile import fitted_model, profile_of
from hcard.calibration.report.figures import (
    DPI,
    FIT_INCHES,
    PANEL_INCHES,
    TICK_GAP_PT,
    TICK_LABEL_PT,
    fit_figure,
    residuals_figure,
    residuals_grid,
)
from hcard.calibration.report.json_document import FORMAT
from hcard.calibration.report.writer import write_report
from hcard.physics import PredictorError
from hcard.physics.profile import DeviceProfile
from hcard.physics.profile_format import PROFILE_FORMAT
from hcard.plugins.registry import get_registry

pytest.importorskip("hcard_builtins")
from hcard_builtins.physics.ultrasonic import DimensionlessGroup


def _recording(n: int = 6000, fs: float = 1000.0, seed: int = 0) -> Measurement:
    """Strokes of random speed and load over random UV amplitudes; the friction reduction
    falls with speed (a hidden ultrasonic-speed effect, exponent -0.6)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    stroke = np.arange(n) // 300
    speed = np.repeat(rng.uniform(0.02, 0.15, stroke.max() + 1), 300)[:n]
    speed = speed * np.where(stroke % 2 == 0, 1.0, -1.0)
    fn = np.repeat(rng.uniform(0.2, 1.5, stroke.max() + 1), 300)[:n]
    amp = np.repeat(rng.uniform(0.0, 3e-6, n // 30 + 1), 30)[:n]
    mu = DimensionlessGroup(psi_star=1.7).forward(
        amplitude=amp, speed=np.abs(speed), normal_force=fn, frequency=27500.0
    )
    mu = 1.0 - (1.0 - mu) * (np.abs(speed) / 0.02) ** -0.6
    force = 0.5 * fn * mu + rng.normal(0.0, 0.002, n)
    return Measurement(
        t=t,
        normal_force=fn,
        lateral_force=force * np.sign(speed),
        amplitude=amp,
        speed=speed,
        conditions={"device": "test", "plate_frequency_hz": 27500},
    )


@pytest.fixture(scope="module")
def result():
    data = prepare([_recording()])
    library = list(get_registry().calibration_effects.values())
    return calibrate(data, DimensionlessGroup(), library)


@pytest.fixture(scope="module")
def report(result, tmp_path_factory):
    return write_report(result, tmp_path_factory.mktemp("report") / "new" / "dir")


def test_result_finds_the_speed_effect(result):
    assert "ultrasonic-speed" in result.after.effects


def test_markdown_leads_with_errors_verdict_and_effect(result, report):
    head = "\n".join(report.markdown.read_text(encoding="utf-8").splitlines()[:10])
    assert f"{result.before.test_rmse * 1e3:.4g} mN" in head
    assert f"{result.after.test_rmse * 1e3:.4g} mN" in head
    assert result.verdict in head
    assert "ultrasonic-speed" in head
    value = result.effect_parameters("ultrasonic-speed")["speed_exponent"][0]
    assert f"speed_exponent = {value:.4g}" in head


def test_markdown_sections_and_figure_links(result, report):
    text = report.markdown.read_text(encoding="utf-8")
    for section in (
        "## Selection criterion",
        "## Data",
        "## Candidates",
        "## Effects skipped",
        "## Structure left",
        "## Residual analysis",
        "## Parameters",
        "## Figures",
        "## Wall time",
    ):
        assert section in text
    assert result.settings.criterion() in text
    assert result.data.split in text
    assert "](residuals.png)" in text and "](fit.png)" in text
    for name in result.skipped:
        assert f"- {name}:" in text


def test_json_content(result, report):
    content = json.loads(report.json.read_text(encoding="utf-8"))
    assert content["format"] == FORMAT
    assert content["held_out_rmse_n"]["before"] == result.before.test_rmse
    assert content["held_out_rmse_n"]["after"] == result.after.test_rmse
    assert content["verdict"] == result.verdict
    assert len(content["candidates"]) == len(result.candidates)
    assert content["profile"]["format"] == PROFILE_FORMAT
    assert content["figures"] == ["residuals.png", "fit.png"]

    def finite(value):
        if isinstance(value, dict):
            return all(finite(v) for v in value.values())
        if isinstance(value, list):
            return all(finite(v) for v in value)
        return not isinstance(value, float) or math.isfinite(value)

    assert finite(content)


def test_figures_are_pngs_of_the_expected_size(result, report):
    assert [p.name for p in report.figures] == ["residuals.png", "fit.png"]
    rows, columns = residuals_grid(len(result.data.regressors))
    expected = {
        "residuals.png": (
            round(PANEL_INCHES[1] * rows * DPI),
            round(PANEL_INCHES[0] * columns * DPI),
        ),
        "fit.png": (round(FIT_INCHES[1] * DPI), round(FIT_INCHES[0] * DPI)),
    }
    for path in report.figures:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert imread(path).shape[:2] == expected[path.name]


def _cells_hold_their_panels(fig, cells):
    """Every panel's drawn extent (axes, tick labels, axis labels, title, offset text) lies
    inside its own cell, given in pixels as (x0, y0, x1, y1) from the lower left."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    assert len(fig.axes) == len(cells)
    for ax, (x0, y0, x1, y1) in zip(fig.axes, cells, strict=True):
        box = ax.get_tightbbox(renderer)
        assert box.x0 >= x0 - 0.5 and box.x1 <= x1 + 0.5, (ax.get_title(), box, (x0, x1))
        assert box.y0 >= y0 - 0.5 and box.y1 <= y1 + 0.5, (ax.get_title(), box, (y0, y1))


def test_figure_panels_keep_their_labels_inside_their_cells(result):
    # the figures place their axes at fixed margins (no layout engine): wide tick labels, a
    # long regressor name or an offset must still not spill into the next panel; here the
    # residual is scaled up to four-digit millinewton tick labels as well
    wide = replace(result, before=replace(result.before, fit=replace(
        result.before.fit, residuals=result.before.fit.residuals * 3e4)))
    for case in (result, wide):
        names = list(case.data.regressors)
        rows, columns = residuals_grid(len(names))
        width, height = PANEL_INCHES[0] * DPI, PANEL_INCHES[1] * DPI
        cells = [((k % columns) * width, (rows - 1 - k // columns) * height,
                  (k % columns + 1) * width, (rows - k // columns) * height)
                 for k in range(len(names))]
        _cells_hold_their_panels(residuals_figure(case), cells)
    third = FIT_INCHES[0] * DPI / 3
    _cells_hold_their_panels(fit_figure(result), [(0, 0, 2 * third, FIT_INCHES[1] * DPI),
                                                  (2 * third, 0, 3 * third, FIT_INCHES[1] * DPI)])


def _ink_columns(image: np.ndarray, row: int, left: int, right: int, half: int = 2) -> int:
    """How many pixel columns of ``image`` (RGBA, top row first) between ``left`` and ``right``
    hold dark ink within ``half`` pixels of ``row``."""
    band = image[max(row - half, 0) : row + half + 1, left:right, :3].mean(axis=2)
    return int(np.count_nonzero((band < 0.5).any(axis=0)))


def test_residual_panels_draw_their_tick_labels(result):
    # the tick labels are glyph outlines drawn outside the axes: they must not be clipped
    # away, and the residual axis is labelled in the first column only (all panels share it)
    fig = residuals_figure(result)
    fig.canvas.draw()
    image = np.asarray(fig.canvas.buffer_rgba(), dtype=float) / 255.0
    height = image.shape[0]
    columns = residuals_grid(len(result.data.regressors))[1]
    limits = {ax.get_ylim() for ax in fig.axes}
    assert len(limits) == 1
    # where the labels are looked for, in pixels (a point is DPI / 72 of them): beyond the
    # tick marks (matplotlib's 3.5 pt, 4.9 px) and from before the labels' near edge,
    # TICK_GAP_PT (9.7 px) out; 8-30 px left of the axes for the residual axis (two font sizes
    # of TICK_LABEL_PT, 9.7 px, past the gap: the first digits of its labels), 6-18 px below
    # them for the regressor's (a label's height, about 0.7 of a font size, past the gap)
    tick_px = max(matplotlib.rcParams[f"{axis}tick.major.size"] for axis in "xy") * DPI / 72.0
    gap_px, font_px = TICK_GAP_PT * DPI / 72.0, TICK_LABEL_PT * DPI / 72.0
    assert tick_px < 6 < 8 < gap_px < gap_px + 0.7 * font_px < 18
    assert gap_px + 2.0 * font_px < 30
    for k, ax in enumerate(fig.axes):
        box = ax.get_window_extent()
        ticks = [t for t in ax.get_yticks() if ax.get_ylim()[0] < t < ax.get_ylim()[1]]
        assert len(ticks) >= 3
        for tick in ticks:
            row = height - round(float(ax.transData.transform((0.0, tick))[1]))
            inked = _ink_columns(image, row, int(box.x0) - 30, int(box.x0) - 8)
            if k % columns == 0:
                assert inked >= 4, (ax.get_title(), tick)
            else:
                assert inked == 0, (ax.get_title(), tick)
        x_row = height - int(box.y0) + 12
        for tick in ax.get_xticks():
            column = round(float(ax.transData.transform((tick, 0.0))[0]))
            if box.x0 < column < box.x1:
                inked = _ink_columns(image.transpose(1, 0, 2), column, x_row - 6, x_row + 6, half=6)
                assert inked >= 4, (ax.get_title(), tick)


def test_no_figures(result, tmp_path):
    files = write_report(result, tmp_path, figures=False)
    assert files.figures == []
    assert not (tmp_path / "residuals.png").exists()
    assert "## Figures" not in files.markdown.read_text(encoding="utf-8")


def test_refuses_a_file_as_directory(result, tmp_path):
    target = tmp_path / "report"
    target.write_text("not a directory")
    with pytest.raises(PredictorError, match="not a directory"):
        write_report(result, target, figures=False)


def _forward(predictor, data):
    names = {v.name for v in predictor.inputs}
    return predictor.forward(**{k: v for k, v in data.inputs.items() if k in names})


def test_profile_round_trip(result, report):
    profile = json.loads(report.profile.read_text(encoding="utf-8"))
    expected_profile = profile_of(result).to_dict()
    for raw in (profile, expected_profile):
        raw["calibration"].pop("created")
    assert profile == json.loads(json.dumps(expected_profile))
    assert profile["format"] == "hcard-device-profile/2"
    assert [e["name"] for e in profile["effects"]] == list(result.after.effects)
    speed = profile["effects"][0]["parameters"]["speed_exponent"]
    assert speed["uncertainty"] == pytest.approx(
        result.after.fit.uncertainties["ultrasonic-speed.speed_exponent"])
    assert profile["calibration"]["parameters"]["poisson_ratio"]["uncertainty"] is None
    assert profile["calibration"]["parameters"]["psi_star"]["fitted"] is True
    assert profile["calibration"]["held_out_rmse_after"] == pytest.approx(result.after.test_rmse)
    loaded = fitted_model(DeviceProfile.load(report.profile))
    expected = _forward(result.after.fit.predictor, result.data)
    np.testing.assert_allclose(_forward(loaded, result.data), expected, rtol=0, atol=1e-12)


def _broken(tmp_path, result, change):
    path = tmp_path / "broken-profile.json"
    profile_of(result).save(path)
    raw = json.loads(path.read_text(encoding="utf-8"))
    change(raw)
    path.write_text(json.dumps(raw), encoding="utf-8")
    return path


def _set(raw, key, value):
    raw[key] = value


@pytest.mark.parametrize(
    ("change", "field"),
    [
        (lambda raw: _set(raw["predictor"], "model", "no-such-model"), "predictor.model"),
        (lambda raw: _set(raw["effects"][0], "name", "no-such-effect"), "effects[0].name"),
        (
            lambda raw: _set(raw["effects"][0]["parameters"], "bogus",
                             {"value": 1.0, "unit": ""}),
            "bogus",
        ),
        (
            lambda raw: _set(raw["effects"][0]["parameters"]["speed_exponent"], "unit", "mN"),
            "speed_exponent.unit",
        ),
        (lambda raw: _set(raw["predictor"]["parameters"], "psi_star", {"value": "x"}),
         "psi_star"),
        (lambda raw: _set(raw["observation"], "output", "force"), "observation.output"),
        (lambda raw: _set(raw, "format", "other/1"), "format"),
    ],
)
def test_profile_errors_name_file_and_field(result, tmp_path, change, field):
    path = _broken(tmp_path, result, change)
    with pytest.raises(PredictorError) as info:
        DeviceProfile.load(path)
    assert path.name in str(info.value)
    assert field in str(info.value)


def test_profile_missing_file_and_bad_json(tmp_path):
    missing = tmp_path / "missing-profile.json"
    with pytest.raises(PredictorError, match=r"missing-profile\.json"):
        DeviceProfile.load(missing)
    bad = tmp_path / "bad-profile.json"
    bad.write_text("{not json", encoding="utf-8")
    with pytest.raises(PredictorError, match=r"bad-profile\.json"):
        DeviceProfile.load(bad)


def test_report_states_the_runner_up_noise_model_power_and_uncertainty(result, report):
    text = report.markdown.read_text(encoding="utf-8")
    content = json.loads(report.json.read_text(encoding="utf-8"))
    comparison = result.comparison
    assert comparison is not None
    _chosen, runner = comparison.names()
    assert "## Runner-up" in text and f"{runner} (runner-up)" in text
    assert f"{100 * comparison.rmse_margin:+.1f} %" in text
    # the margin is the two models' held-out RMSEs, recomputed here from the table's numbers
    assert content["runner_up"]["rmse_margin"] == pytest.approx(
        content["runner_up"]["runner_up_rmse"] / result.after.test_rmse - 1.0
    )
    # the noise model is measured (the recording is in contact throughout: none) and stated
    assert "Noise model: no lift long enough" in text
    assert content["structure"]["noise"] is None
    assert "Power: with" in text and "80 % probability" in text
    detectable = content["structure"]["detectable_eta2_at_80_percent_power"]
    assert set(detectable) == set(result.after.analysis.regressors)
    # without a bootstrap the report says the uncertainties are the Jacobian's, and why
    assert "Uncertainties: sigma^2 (J^T J)^-1 of the fit" in text
    assert content["bootstrap"] is None


def test_report_with_a_bootstrap_states_it(result, tmp_path):
    from hcard.calibration.loop import with_bootstrap

    lines: list[str] = []
    booted = with_bootstrap(result, 4, seed=3, progress=lines.append)
    assert lines[-1].startswith("bootstrap 4/4")
    files = write_report(booted, tmp_path / "boot", figures=False)
    text = files.markdown.read_text(encoding="utf-8")
    assert "Uncertainties: stroke-block bootstrap" in text and "4 times (seed 3)" in text
    content = json.loads(files.json.read_text(encoding="utf-8"))
    name = "ultrasonic-speed.speed_exponent"
    values = booted.bootstrap.values[name]
    assert content["bootstrap"]["uncertainties"][name] == pytest.approx(np.std(values, ddof=1))
    _value, sigma, _ = booted.effect_parameters("ultrasonic-speed")["speed_exponent"]
    assert sigma == pytest.approx(np.std(values, ddof=1))
