"""Contact from the normal force, and a warning when a stroke column disagrees.

The recordings are written by hand (:mod:`test_selection_recordings`): a stroke column that
carries the stroke number through the lifts puts samples with ``fn ~ 0`` "in contact".
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from hcard.calibration.contact import default_contact_threshold, normal_force_noise
from hcard.calibration.dataset import prepare
from hcard.calibration.measurement import MeasurementError, write_measurement
from hcard.cli.main import cli
from tests.calibration.test_selection_recordings import Hidden, uv_recording


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_stroke_column_carried_through_lifts_warns_and_the_forces_decide(seed: int) -> None:
    carried = uv_recording(Hidden(), seed=seed, duration_s=12.0, stroke_column="carried")
    proper = uv_recording(Hidden(), seed=seed, duration_s=12.0, stroke_column="lifts")
    data = prepare([carried])
    reference = prepare([proper])
    # the forces decide: the same samples are fitted as with a column that is -1 in the lifts
    assert np.array_equal(data.used, reference.used)
    pressed = carried.normal_force >= 0.01
    assert np.array_equal(data.used, pressed)
    assert data.zeroing[0][0] >= 10  # the zero is measured at every lift
    (warning,) = data.warnings
    lifted = int(np.count_nonzero(carried.normal_force < data.contact_threshold_n[0]))
    assert f"puts {lifted} of its {len(carried)} stroke samples in contact" in warning
    assert reference.warnings == ()


@pytest.mark.parametrize(("sigma", "seed"), [(1e-3, 1), (4e-3, 2), (8e-3, 3)])
def test_the_default_threshold_follows_the_normal_force_noise(sigma: float, seed: int) -> None:
    m = uv_recording(Hidden(), seed=seed, duration_s=12.0, lift_noise_n=sigma)
    lifted = m.normal_force[m.amplitude >= 0][m.speed == 0]
    # independent: the sample standard deviation of the lifts (the MAD estimate sees only the
    # samples below 10 mN, so it is within ~15 % of it for sigma up to 8 mN)
    assert normal_force_noise(m.normal_force) == pytest.approx(float(np.std(lifted)), rel=0.2)
    threshold = default_contact_threshold(m.normal_force)
    assert threshold == pytest.approx(max(0.01, 5 * float(np.std(lifted))), rel=0.2)
    data = prepare([m])
    assert data.contact_threshold_n == (pytest.approx(threshold),)
    # no lift sample is taken for a touch at the default threshold
    assert not np.any(data.used & (m.speed == 0))


def test_a_given_threshold_is_checked_and_used() -> None:
    m = uv_recording(Hidden(), seed=4, duration_s=6.0)
    with pytest.raises(MeasurementError, match="contact_threshold_n must be a positive force"):
        prepare([m], contact_threshold_n=-0.01)
    high = prepare([m], contact_threshold_n=0.5)
    assert np.array_equal(high.used, m.normal_force >= 0.5)
    assert high.contact_threshold_n == (0.5,)


def test_the_cli_warns_on_stderr_and_in_the_report(tmp_path: Path) -> None:
    m = uv_recording(Hidden(), seed=5, duration_s=10.0, stroke_column="carried")
    write_measurement(m, tmp_path / "rec.csv")
    out = tmp_path / "report"
    result = CliRunner().invoke(
        cli,
        ["calibrate", str(tmp_path / "rec.csv"), "--model", "dimensionless-group",
         "--max-effects", "0", "--bootstrap", "0", "--no-figures", "-q", "-o", str(out)],
    )
    assert result.exit_code == 0, result.output
    assert "warning: " in result.stderr and "stroke column puts" in result.stderr
    text = (out / "report.md").read_text()
    assert "## Warnings" in text and "contact is taken from the normal force" in text
    assert "Contact of " in text and "normal force ≥ 10 mN" in text
