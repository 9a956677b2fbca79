"""The steps of :func:`hcard.calibration.dataset.prepare`, each on a recording written here."""

from __future__ import annotations

import numpy as np
import pytest

from hcard.calibration.contact import in_contact
from hcard.calibration.dataset import (
    ATMOSPHERE_PA,
    check_recordings,
    contact_time,
    prepare,
    recording_columns,
    sliding,
    split_masks,
)
from hcard.calibration.measurement import Measurement, MeasurementError


def test_contact_time_restarts_at_every_touch_down() -> None:
    t = np.arange(10) * 0.1
    contact = np.array([0, 1, 1, 1, 0, 0, 1, 1, 0, 1], dtype=bool)
    expected = [0.0, 0.0, 0.1, 0.2, 0.0, 0.0, 0.0, 0.1, 0.0, 0.0]
    assert contact_time(t, contact) == pytest.approx(expected, abs=1e-12)
    assert contact_time(t, np.ones(10, dtype=bool)) == pytest.approx(t, abs=1e-12)


def strokes(n: int = 40, frequency_hz: float | None = 31_000.0) -> Measurement:
    """Four strokes of 8 samples at 100 Hz, each after 2 lifted samples, sliding +x then -x at
    20 mm/s; 0.5 N in contact."""
    t = np.arange(n) * 0.01
    lifted = (np.arange(n) % 10) < 2
    direction = np.where((np.arange(n) // 10) % 2 == 0, 1.0, -1.0)
    conditions = {"device": "here"}
    if frequency_hz:
        conditions["plate_frequency_hz"] = frequency_hz
    return Measurement(
        t=t,
        normal_force=np.where(lifted, 0.0, 0.5),
        lateral_force=np.where(lifted, 0.0, 0.2 * direction),
        amplitude=np.full(n, 1e-6),
        speed=np.where(lifted, 0.0, 0.02 * direction),
        x=np.cumsum(0.0002 * direction),
        conditions=conditions,
    )


def test_a_recording_becomes_inputs_regressors_and_the_observed_force() -> None:
    m = strokes()
    ids = np.where(m.normal_force > 0.01, np.arange(40) // 10, -1)
    force = np.abs(m.lateral_force)
    columns = recording_columns(m, 2, ids, in_contact(m, 0.01), force, rest_s=0.5)
    contact = m.normal_force > 0.01
    assert columns["time"] == pytest.approx(m.t - m.t[0])
    assert columns["contact_time"][contact] == pytest.approx(np.tile(np.arange(8) * 0.01, 4))
    # the 32 sample intervals that end in contact (each 10 ms)
    assert columns["occlusion_time"][-1] == pytest.approx(32 * 0.01)
    assert columns["stroke"][contact] == pytest.approx(np.repeat([0, 1, 2, 3], 8))
    assert np.all(columns["pressure"] == ATMOSPHERE_PA)
    assert columns["observed"] is force
    assert np.all(columns["recording"] == 2.0)
    assert np.array_equal(columns["speed"], np.abs(m.speed))
    assert np.array_equal(columns["direction"], np.sign(m.speed))
    assert np.all(columns["plate_frequency"] == 31_000.0)
    assert columns["voltage"] is None and columns["voltage_history"] is None
    # out of contact the normal force input is the floor of 10 mN, in contact the recorded one
    assert np.all(columns["normal_force"][~contact] == pytest.approx(0.01))
    assert columns["normal_force"][contact] == pytest.approx(0.5)


def test_a_time_split_holds_out_the_last_share_in_contact_only() -> None:
    m = strokes()
    keep = m.normal_force > 0.01
    train, test = split_masks(m, "here", "time", 0.25, 0, 0.01, keep)
    assert not (train & test).any() and not ((train | test) & ~keep).any()
    assert np.array_equal(test, keep & (m.t >= 0.75 * m.t[-1]))
    assert np.array_equal(train, keep & (m.t < 0.75 * m.t[-1]))
    with pytest.raises(MeasurementError, match=r"^here: a split by time needs"):
        one = Measurement(t=np.zeros(1), normal_force=np.ones(1), lateral_force=np.ones(1),
                          amplitude=np.ones(1))
        split_masks(one, "here", "time", 0.25, 0, 0.01, np.ones(1, dtype=bool))


def test_recordings_that_cannot_be_calibrated_together_are_refused() -> None:
    with pytest.raises(MeasurementError, match="no recordings"):
        check_recordings([], "stroke", 0.25)
    with pytest.raises(MeasurementError, match="split must be one of"):
        check_recordings([strokes()], "random", 0.25)
    with pytest.raises(MeasurementError, match=r"test_fraction must lie in \(0, 1\)"):
        check_recordings([strokes()], "stroke", 1.0)
    with pytest.raises(MeasurementError, match=r"plate frequency .* some recordings but not all"):
        check_recordings([strokes(), strokes(frequency_hz=None)], "stroke", 0.25)
    check_recordings([strokes(), strokes()], "time", 0.25)


def test_a_finger_at_rest_is_in_no_split_rule_ms5() -> None:
    """The first sample of each contact has no speed estimate (0): its lateral force is static
    friction, here 0 N against 0.2 N sliding, and prepare fits and holds out only the sliding
    samples; it keeps its stroke, and its contact time counts."""
    m = strokes()
    touch_downs = np.arange(40) % 10 == 2
    m.speed[touch_downs] = 0.0
    m.lateral_force[touch_downs] = 0.0
    data = prepare([m])
    assert not np.any(data.used[touch_downs])
    assert np.count_nonzero(data.used) == 28  # 32 in contact, 4 at rest
    assert data.inputs["contact_time"][touch_downs] == pytest.approx(0.0)
    assert data.inputs["contact_time"][np.arange(40) % 10 == 3] == pytest.approx(0.01)
    assert sliding(None, np.ones(3, dtype=bool)) is True


def test_a_recording_that_never_slides_is_fitted_whole() -> None:
    """A press without motion (every speed 0) has no sliding sample to prefer: every contact
    sample is in a split, as without a speed column."""
    m = strokes()
    m.speed[:] = 0.0
    data = prepare([m])
    assert np.count_nonzero(data.used) == 32
