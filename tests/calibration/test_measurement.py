"""Measurement files (spec/measurement-format.md) and held-out splits."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hcard.calibration.measurement import (
    Measurement,
    MeasurementError,
    read_measurement,
    sidecar_path,
    write_measurement,
)
from hcard.calibration.splits import (
    split_by_stroke,
    split_by_time_blocks,
    stroke_ids,
    time_blocks,
)
from hcard.errors import HcardError

CONDITIONS = {
    "device": "ref-uv-1",
    "plate_frequency_hz": 27_500.0,
    "surface": "glass",
    "probe": "artificial finger A",
    "ambient_pressure_pa": 101_325.0,
    "temperature_c": 22.5,
    "notes": "test",
}


def write(tmp_path: Path, text: str, conditions: object = CONDITIONS, name: str = "rec.csv"
          ) -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    sidecar = sidecar_path(path)
    sidecar.write_text(conditions if isinstance(conditions, str) else json.dumps(conditions))
    return path


GOOD = """# a comment
t_s,amplitude_um,speed_mm_s,fn_n,fl_n,stroke
0.0,1.5,20,0.5,0.30,0
0.001,2.0,-20,0.5,0.20,0
0.002,2.5,20,0.6,0.25,1
"""


def test_read_converts_units_to_si(tmp_path: Path) -> None:
    m = read_measurement(write(tmp_path, GOOD))
    np.testing.assert_allclose(m.amplitude, [1.5e-6, 2.0e-6, 2.5e-6], rtol=1e-15)
    np.testing.assert_allclose(m.speed, [0.02, -0.02, 0.02], rtol=1e-15)
    np.testing.assert_array_equal(m.t, [0.0, 0.001, 0.002])
    np.testing.assert_array_equal(m.normal_force, [0.5, 0.5, 0.6])
    np.testing.assert_array_equal(m.lateral_force, [0.30, 0.20, 0.25])
    np.testing.assert_array_equal(m.stroke, [0, 0, 1])
    assert m.stroke.dtype == np.int64
    assert m.voltage is None and m.x is None and m.plate_frequency is None
    assert m.conditions == CONDITIONS  # the sidecar as written: nothing added to it
    assert m.source == str(tmp_path / "rec.csv")
    assert list(m.regressors()) == [
        "t", "amplitude", "speed", "normal_force", "lateral_force", "stroke",
    ]


def test_alternative_units(tmp_path: Path) -> None:
    text = ("t_ms,amplitude_m,voltage_kv,x_mm,y_um,speed_m_s,fn_mn,fl_mn,frequency_khz\n"
            "1,2e-6,0.1,10,500,0.03,400,200,27.5\n"
            "2,3e-6,0.2,11,600,0.03,500,250,27.5\n")
    m = read_measurement(write(tmp_path, text))
    np.testing.assert_allclose(m.t, [1e-3, 2e-3], rtol=1e-15)
    np.testing.assert_allclose(m.voltage, [100.0, 200.0], rtol=1e-15)
    np.testing.assert_allclose(m.x, [0.010, 0.011], rtol=1e-15)
    np.testing.assert_allclose(m.y, [5e-4, 6e-4], rtol=1e-15)
    np.testing.assert_allclose(m.normal_force, [0.4, 0.5], rtol=1e-15)
    np.testing.assert_allclose(m.lateral_force, [0.2, 0.25], rtol=1e-15)
    np.testing.assert_allclose(m.plate_frequency, [27_500.0, 27_500.0], rtol=1e-15)


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(3)
    n = 200
    m = Measurement(
        t=np.cumsum(rng.uniform(1e-4, 2e-3, n)),
        normal_force=rng.uniform(0.1, 1.0, n),
        lateral_force=rng.uniform(0.0, 0.5, n),
        amplitude=rng.uniform(0, 3e-6, n),
        voltage=rng.uniform(-200, 200, n),
        x=rng.normal(0, 0.01, n),
        y=rng.normal(0, 0.01, n),
        speed=rng.normal(0, 0.05, n),
        stroke=np.repeat(np.arange(10), 20),
        plate_frequency=np.full(n, 27_512.3),
        conditions=CONDITIONS,
    )
    path = tmp_path / "out.csv"
    write_measurement(m, path)
    back = read_measurement(path)
    for name, value in m.regressors().items():
        np.testing.assert_array_equal(back.regressors()[name], value, err_msg=name)
    assert back.conditions == CONDITIONS
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv", "out.csv.json"]


HEADER = "t_s,voltage_v,fn_n,fl_n\n"


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("t_s,voltage_v,fn_n\n0,1,0.5\n", "rec.csv:1: missing column(s) fl_n"),
        ("fn_n,fl_n,voltage_v\n0.5,0.3,1\n", "missing column(s) t_s"),
        ("t_s,fn_n,fl_n\n0,0.5,0.3\n", "missing column: an actuation column"),
        ("t_s,amplitude_in,fn_n,fl_n\n0,1,0.5,0.3\n", "unknown unit 'in' for amplitude"),
        ("t_s,voltage_V,fn_n,fl_n\n0,1,0.5,0.3\n", "unknown unit 'V' for voltage"),
        ("t_s,speed_mm,voltage_v,fn_n,fl_n\n0,1,1,0.5,0.3\n", "unknown unit 'mm' for speed"),
        ("t_s,pressure_pa,voltage_v,fn_n,fl_n\n0,1,1,0.5,0.3\n",
         "column 'pressure_pa' is not a known quantity"),
        ("t_s,voltage_v,voltage_mv,fn_n,fl_n\n0,1,1,0.5,0.3\n", "duplicates 'voltage_v'"),
        (HEADER + "0,1,0.5,0.3\n0.1,abc,0.5,0.3\n", "rec.csv:3: column voltage_v: 'abc' is "
         "not a number"),
        (HEADER + "0,1,0.5,0.3\n0.1,1,0.5\n", "rec.csv:3: row has 3 fields"),
        (HEADER + "0,1,0.5,0.3\n0.2,1,0.5,0.3\n0.1,1,0.5,0.3\n",
         "rec.csv:4: column t_s: non-monotonic time, 0.1 s follows 0.2 s"),
        (HEADER + "0,1,0.5,0.3\n0,1,0.5,0.3\n", "rec.csv:3: column t_s: non-monotonic time"),
        (HEADER + "0,1,0.5,0.3\n0.1,1,nan,0.3\n0.2,1,0.5,0.3\n",
         "rec.csv:3: column fn_n: NaN sample"),
        (HEADER + "0,1,0.5,0.3\n0.1,1,0.5,\n0.2,1,0.5,0.3\n",
         "rec.csv:3: column fl_n: NaN sample"),
        (HEADER + "0,1,0.5,0.3\n0.1,nan,0.5,0.3\n0.2,NaN,0.5,0.3\n0.3,,0.5,0.3\n",
         "rec.csv:3: column voltage_v: NaN run of 3 samples (lines 3-5)"),
        (HEADER + "0,inf,0.5,0.3\n", "rec.csv:2: column voltage_v: infinite value"),
        ("t_s,voltage_v,fn_n,fl_n,stroke\n0,1,0.5,0.3,1.5\n",
         "rec.csv:2: column stroke: 1.5 is not an integer"),
        (HEADER, "no samples after the header"),
        ("# only a comment\n", "empty file"),
    ],
)
def test_bad_csv_raises(tmp_path: Path, text: str, fragment: str) -> None:
    with pytest.raises(MeasurementError) as info:
        read_measurement(write(tmp_path, text))
    assert fragment in str(info.value)
    assert isinstance(info.value, HcardError)


@pytest.mark.parametrize(
    ("sidecar", "fragment"),
    [
        ('{"device": "a",', "rec.csv.json:1:16: bad sidecar JSON"),
        ("[1, 2]", "bad sidecar JSON (the top level must be an object)"),
        ({"surface": "glass"}, "key 'device' must be a non-empty string"),
        ({"device": "a", "ambient_pressure_pa": "1 atm"},
         "key 'ambient_pressure_pa' must be a finite number"),
        ({"device": "a", "plate_frequency_hz": True}, "key 'plate_frequency_hz'"),
        ({"device": "a", "notes": 3}, "key 'notes' must be a string"),
    ],
)
def test_bad_sidecar_raises(tmp_path: Path, sidecar: object, fragment: str) -> None:
    with pytest.raises(MeasurementError) as info:
        read_measurement(write(tmp_path, HEADER + "0,1,0.5,0.3\n", sidecar))
    assert fragment in str(info.value)


def test_missing_files_raise(tmp_path: Path) -> None:
    with pytest.raises(MeasurementError, match=r"nope\.csv: no such file"):
        read_measurement(tmp_path / "nope.csv")
    path = tmp_path / "alone.csv"
    path.write_text(HEADER + "0,1,0.5,0.3\n")
    with pytest.raises(MeasurementError, match=r"alone\.csv\.json: no such file"):
        read_measurement(path)


def test_write_is_atomic_on_failure(tmp_path: Path) -> None:
    m = read_measurement(write(tmp_path, GOOD))
    target = tmp_path / "keep.csv"
    target.write_text("old")
    m.conditions = {"device": "x", "bad": float("nan")}
    with pytest.raises(ValueError):
        write_measurement(m, target)
    assert target.read_text() == "old"
    assert not sidecar_path(target).exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


def make(n_strokes: int = 12, per: int = 50, *, stroke_column: bool = True) -> Measurement:
    """Strokes of ``per`` samples at 1 kHz separated by 0.1 s lifts (no samples in between)."""
    t = np.concatenate([k * 0.2 + np.arange(per) * 1e-3 for k in range(n_strokes)])
    n = t.size
    return Measurement(
        t=t,
        normal_force=np.full(n, 0.5),
        lateral_force=np.full(n, 0.2),
        voltage=np.full(n, 100.0),
        stroke=np.repeat(np.arange(n_strokes), per) if stroke_column else None,
    )


def test_split_by_stroke_keeps_strokes_whole() -> None:
    m = make()
    train, test = split_by_stroke(m, test_fraction=0.25, seed=1)
    assert np.intersect1d(train, test).size == 0
    assert train.size + test.size == len(m)
    assert test.size == 3 * 50  # round(0.25 * 12) strokes of 50 samples
    train_strokes, test_strokes = set(m.stroke[train]), set(m.stroke[test])
    assert not train_strokes & test_strokes
    assert len(test_strokes) == 3 and len(train_strokes) == 9
    for s in test_strokes:
        assert np.array_equal(np.flatnonzero(m.stroke == s), test[m.stroke[test] == s])
    # Deterministic in the seed, different across seeds.
    again = split_by_stroke(m, test_fraction=0.25, seed=1)
    assert np.array_equal(again[1], test)
    assert any(not np.array_equal(split_by_stroke(m, 0.25, seed=s)[1], test)
               for s in range(2, 6))


def test_split_by_stroke_needs_two_strokes() -> None:
    with pytest.raises(MeasurementError, match="at least 2 strokes, the recording has 1"):
        split_by_stroke(make(n_strokes=1))
    with pytest.raises(MeasurementError, match="test_fraction"):
        split_by_stroke(make(), test_fraction=1.0)


def test_stroke_ids_from_time_gaps() -> None:
    ids = stroke_ids(make(n_strokes=4, per=10, stroke_column=False))
    np.testing.assert_array_equal(ids, np.repeat(np.arange(4), 10))


def test_stroke_ids_from_contact_and_speed_sign() -> None:
    t = np.arange(12) * 1e-3
    fn = np.array([0.5, 0.5, 0.5, 0.0, 0.0, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5, 0.5])
    speed = np.array([1, 1, 1, 0, 0, 1, 1, 0, -1, -1, 1, 1]) * 0.02
    m = Measurement(t=t, normal_force=fn, lateral_force=fn * 0.4, amplitude=np.zeros(12),
                    speed=speed)
    np.testing.assert_array_equal(
        stroke_ids(m), [0, 0, 0, -1, -1, 1, 1, 1, 2, 2, 3, 3]
    )
    train, test = split_by_stroke(m, test_fraction=0.5, seed=0)
    assert 3 not in train and 4 not in train and 3 not in test and 4 not in test
    assert train.size + test.size == 10


def test_split_by_time_blocks_is_contiguous() -> None:
    m = Measurement(t=np.arange(1000) * 1e-3, normal_force=np.ones(1000),
                    lateral_force=np.ones(1000), voltage=np.ones(1000))
    train, test = split_by_time_blocks(m, n_blocks=5, test_blocks=(2,))
    np.testing.assert_array_equal(test, np.arange(400, 600))
    np.testing.assert_array_equal(train, np.r_[0:400, 600:1000])
    assert np.all(np.diff(test) == 1)
    np.testing.assert_array_equal(np.bincount(time_blocks(m, 5)), [200] * 5)
    train, test = split_by_time_blocks(m, n_blocks=4, test_blocks=(-1, 0))
    np.testing.assert_array_equal(test, np.r_[0:250, 750:1000])
    np.testing.assert_array_equal(train, np.arange(250, 750))


def test_split_by_time_blocks_errors() -> None:
    m = make(n_strokes=2, per=5)
    with pytest.raises(MeasurementError, match=r"outside 0\.\.4"):
        split_by_time_blocks(m, 5, (5,))
    with pytest.raises(MeasurementError, match="not all of them"):
        split_by_time_blocks(m, 2, (0, 1))
    with pytest.raises(MeasurementError, match="holds no sample"):
        split_by_time_blocks(m, 5, (0,))


def test_spec_example_reads(tmp_path: Path) -> None:
    """The worked example of spec/measurement-format.md section 5 reads to the stated values."""
    spec = (Path(__file__).parents[2] / "spec" / "measurement-format.md").read_text()
    csv_text = spec.split("```csv\n", 1)[1].split("```", 1)[0]
    json_text = spec.split("```json\n", 1)[1].split("```", 1)[0]
    m = read_measurement(write(tmp_path, csv_text, json_text))
    np.testing.assert_allclose(m.amplitude, [0, 1.5e-6, 3e-6, 0, 1.5e-6], rtol=1e-15)
    np.testing.assert_allclose(m.speed, [0.02, 0.02, 0.02, -0.02, -0.02], rtol=1e-15)
    np.testing.assert_array_equal(m.stroke, [0, 0, 0, 1, 1])
    assert m.conditions["plate_frequency_hz"] == 27500
    np.testing.assert_array_equal(stroke_ids(m), [0, 0, 0, 1, 1])
    m.stroke = None  # derived strokes: the time gap and the speed reversal both split here
    np.testing.assert_array_equal(stroke_ids(m), [0, 0, 0, 1, 1])


# -- device columns (rule MF12) -------------------------------------------------------------
DEVICE_TEXT = """t_s,x_m,y_m,speed_m_s,fn_n,fl_n,amplitude_m,voltage_v,contact,sequence,f_tl_mn,\
f_tr_n,f_bl_n,f_br_n,current_ua,target_uv,target_ev,texture,faults,flags,echo_ms
0.000,0.01,0.02,0.05,0.50,0.24,1e-6,0,1,65534,125,0.125,0.125,0.125,0,0.8,1.0,2,0,15,10
0.001,0.01,0.02,0.05,0.50,0.23,1e-6,0,1,65535,125,0.125,0.125,0.125,0,0.8,1.0,2,1,15,10
0.002,0.01,0.02,0.00,0.00,0.00,0,0,0,0,0,0,0,0,0,1.0,1.0,-1,0,2,20
"""


def test_device_columns_are_read_by_name_in_si_units(tmp_path: Path) -> None:
    m = read_measurement(write(tmp_path, DEVICE_TEXT))
    np.testing.assert_array_equal(m.contact, [True, True, False])
    np.testing.assert_array_equal(m.column("sequence"), [65534, 65535, 0])
    np.testing.assert_allclose(m.column("f_tl"), [0.125, 0.125, 0.0], rtol=1e-15)
    np.testing.assert_allclose(m.column("echo"), [0.010, 0.010, 0.020], rtol=1e-15)
    np.testing.assert_array_equal(m.column("texture"), [2, 2, -1])
    np.testing.assert_array_equal(m.column("target_uv"), [0.8, 0.8, 1.0])
    assert m.column("faults").dtype == np.int64
    assert m.column("fl") is m.lateral_force
    with pytest.raises(KeyError, match="lateral_n"):
        m.column("lateral_n")
    # contact: the device's own sensing, and at least 10 mN (rule MS2)
    np.testing.assert_array_equal(m.in_contact, [True, True, False])
    np.testing.assert_array_equal(stroke_ids(m), [0, 0, -1])


def test_device_columns_round_trip_exactly(tmp_path: Path) -> None:
    m = read_measurement(write(tmp_path, DEVICE_TEXT))
    write_measurement(m, tmp_path / "again.csv")
    back = read_measurement(tmp_path / "again.csv")
    assert set(back.device) == set(m.device)
    for name, values in m.device.items():
        np.testing.assert_array_equal(back.device[name], values, err_msg=name)
    np.testing.assert_array_equal(back.contact, m.contact)
    header = (tmp_path / "again.csv").read_text().splitlines()[0]
    assert header.endswith("contact,sequence,f_tl_n,f_tr_n,f_bl_n,f_br_n,current_a,target_uv,"
                           "target_ev,texture,faults,flags,echo_s")


@pytest.mark.parametrize(
    ("header", "row", "message"),
    [
        ("t_s,fn_n,fl_n,voltage_v,lateral_n", "0,0.5,0.2,0,0.2",
         "rec.csv:1: column 'lateral_n' is not a known quantity"),
        ("t_s,fn_n,fl_n,voltage_v,contact", "0,0.5,0.2,0,2",
         "rec.csv:2: column contact: 2.0 is neither 0 nor 1"),
        ("t_s,fn_n,fl_n,voltage_v,faults", "0,0.5,0.2,0,1.5",
         "rec.csv:2: column faults: 1.5 is not an integer"),
        ("t_s,fn_n,fl_n,voltage_v,current_kv", "0,0.5,0.2,0,1",
         "column 'current_kv': unknown unit 'kv' for current"),
    ],
)
def test_bad_device_columns_are_named(tmp_path: Path, header: str, row: str,
                                      message: str) -> None:
    with pytest.raises(MeasurementError, match=message.replace(".", r"\.")):
        read_measurement(write(tmp_path, f"{header}\n{row}\n"))


@pytest.mark.parametrize(
    ("conditions", "message"),
    [
        ({"device": "d", "voltage_form": "rms"}, "key 'voltage_form' is 'rms'"),
        ({"device": "d", "voltage_form": "envelope"}, "needs 'carrier_frequency_hz'"),
        ({"device": "d", "profile": "default"}, "key 'profile' must be an object"),
        ({"device": "d", "carrier_frequency_hz": "440 Hz"}, "'carrier_frequency_hz' must be"),
    ],
)
def test_bad_device_sidecar_keys(tmp_path: Path, conditions: dict, message: str) -> None:
    with pytest.raises(MeasurementError, match=message):
        read_measurement(write(tmp_path, "t_s,fn_n,fl_n,voltage_v\n0,0.5,0.2,0\n", conditions))


def test_envelope_voltage_is_declared_in_the_sidecar(tmp_path: Path) -> None:
    conditions = {"device": "d", "voltage_form": "envelope", "carrier_frequency_hz": 440}
    m = read_measurement(write(tmp_path, "t_s,fn_n,fl_n,voltage_v\n0,0.5,0.2,0\n", conditions))
    assert m.voltage_form == "envelope"
    assert read_measurement(write(tmp_path, GOOD, name="b.csv")).voltage_form == "instantaneous"
