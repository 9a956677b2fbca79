"""The one module of quantities and units (hcard.quantities): conversions, column units."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import scipy.constants as sc

from hcard import quantities as units
from hcard.calibration.measurement import SI_SUFFIX, read_measurement


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("M_PER_MM", sc.milli), ("MM_PER_M", sc.kilo), ("UM_PER_M", 1 / sc.micro),
        ("UM_PER_MM", sc.milli / sc.micro), ("NM_PER_M", 1 / sc.nano),
        ("S_PER_MS", sc.milli), ("MS_PER_S", sc.kilo), ("S_PER_US", sc.micro),
        ("US_PER_S", 1 / sc.micro), ("N_PER_MN", sc.milli), ("MN_PER_N", sc.kilo),
        ("UA_PER_A", 1 / sc.micro),
    ],
)
def test_named_conversions_are_the_si_prefixes(name: str, expected: float) -> None:
    """Each factor is its SI prefix, and exactly the double nearest that power of ten (so a
    factor times its inverse, ``M_PER_MM * MM_PER_M``, is exactly 1)."""
    value = getattr(units, name)
    assert value == pytest.approx(expected, rel=1e-15)
    assert value == float(f"1e{round(math.log10(value))}")


def test_an_atmosphere_is_101325_pa() -> None:
    assert units.ATMOSPHERE_PA == sc.atm == 101_325.0


def test_the_vacuum_permittivity_is_codata_s() -> None:
    """CODATA 2022 (SciPy >= 1.15) or 2018 (SciPy 1.10-1.14, 6.8e-10 higher relative error)."""
    assert pytest.approx(sc.epsilon_0, rel=1e-9) == units.EPSILON_0
    assert units.parse_quantity("1 atm", "Pa") == 101_325.0


@pytest.mark.parametrize(
    ("quantity", "suffix", "scale"),
    [
        ("t", "ms", 1e-3), ("t", "us", 1e-6), ("amplitude", "nm", 1e-9), ("amplitude", "um", 1e-6),
        ("voltage", "kv", 1e3), ("voltage", "mv", 1e-3), ("speed", "mm_s", 1e-3),
        ("speed", "um_s", 1e-6), ("fn", "mn", 1e-3), ("frequency", "khz", 1e3),
        ("current", "ua", 1e-6), ("current", "ma", 1e-3), ("echo", "us", 1e-6),
    ],
)
def test_column_units_scale_to_si(quantity: str, suffix: str, scale: float) -> None:
    assert units.COLUMN_UNITS[quantity][suffix] == scale


SPEC_SI_SUFFIX = {
    # spec/measurement-format.md rule MF3's table (the SI unit of each quantity; MF11 writes it)
    "t": "s", "fn": "n", "fl": "n", "amplitude": "m", "voltage": "v", "x": "m", "y": "m",
    "speed": "m_s", "frequency": "hz",
    # and rule MF12's device columns with a unit
    "f_tl": "n", "f_tr": "n", "f_bl": "n", "f_br": "n", "current": "a", "echo": "s",
}
"""The SI unit suffix of every column quantity with a unit, as spec/measurement-format.md
names them (``stroke`` and MF12's integer columns have none)."""


def test_every_column_quantity_is_written_in_its_si_unit() -> None:
    """Rules MF3, MF12: the quantities and their SI units are the spec's, and each quantity has
    exactly one suffix of scale 1, its SI unit, which the writer uses (MF11)."""
    assert SI_SUFFIX == SPEC_SI_SUFFIX
    for quantity, accepted in units.COLUMN_UNITS.items():
        si = [suffix for suffix, scale in accepted.items() if scale == 1.0]
        assert si == [SPEC_SI_SUFFIX[quantity]], quantity


def test_the_reader_applies_the_column_units(tmp_path) -> None:
    path = tmp_path / "r.csv"
    path.write_text("t_ms,fn_mn,fl_n,amplitude_um,speed_mm_s\n0,500,0.2,1.5,20\n10,400,0.1,2,30\n")
    path.with_name("r.csv.json").write_text('{"device": "tribometer"}')
    m = read_measurement(path)
    assert m.t.tolist() == pytest.approx([0.0, 0.01])
    assert m.normal_force.tolist() == pytest.approx([0.5, 0.4])
    assert m.amplitude.tolist() == pytest.approx([1.5e-6, 2e-6])
    assert m.speed.tolist() == pytest.approx([0.02, 0.03])


def test_si_units_agree_with_the_parser() -> None:
    for name, unit in units.SI_UNITS.items():
        if unit:
            assert units.parse_unit(unit) == (1.0, unit), name


def test_the_quantities_module_loads_without_numpy() -> None:
    """The device's drivers take their conversions from it and never load numpy."""
    code = ("import sys; import hcard.quantities, hcard.channels, hcard.rates; "
            "sys.exit('numpy' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0
