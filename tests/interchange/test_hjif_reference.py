"""The exporter's .hjif through the MPEG reference software's own reader and writer
(spec/interchange/hjif.md IJ30): ``Encoder -f in.hjif -o out.hjif`` loads the file
(``IOJson::loadFile``: schema, required fields, semantic checks) and writes it back
(``IOJson::writeFile``); an accepted file leaves stderr empty and comes back byte for byte.

The reference is not fetched or built in CI: set ``HCARD_MPEG_REFERENCE`` to the path of its
``Encoder`` executable (scripts/build_mpeg_reference.sh builds it and prints the path)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from tests.interchange.hjif_cards import CARDS, _fixed_date, export

__all__ = ["_fixed_date"]

REFERENCE = os.environ.get("HCARD_MPEG_REFERENCE", "")
pytestmark = pytest.mark.skipif(
    not (REFERENCE and Path(REFERENCE).is_file() and os.access(REFERENCE, os.X_OK)),
    reason="HCARD_MPEG_REFERENCE does not name the MPEG reference software's Encoder "
           "executable (scripts/build_mpeg_reference.sh builds it); CI cannot build it")


def _round_trip(tmp_path: Path, data: bytes) -> tuple[bytes, str]:
    source, target = tmp_path / "in.hjif", tmp_path / "out.hjif"
    source.write_bytes(data)
    run = subprocess.run([REFERENCE, "-f", source, "-o", target], capture_output=True,
                         text=True, timeout=120, check=False)
    return target.read_bytes(), run.stderr


@pytest.mark.parametrize("name", sorted(CARDS))
def test_the_reference_writes_the_export_back_byte_for_byte(tmp_path, name) -> None:
    data = export(CARDS[name]()).files[0][1]
    written, errors = _round_trip(tmp_path, data)
    assert errors == ""
    assert written == data


def test_the_reference_drops_what_the_rules_forbid(tmp_path) -> None:
    """The control: a band limit written 500.0 (IJ25) is dropped without a message, so the
    byte comparison above would see it."""
    data = export(CARDS["plain"]()).files[0][1].replace(
        b'"upper_frequency_limit":0,', b'"upper_frequency_limit":0.0,', 1)
    written, errors = _round_trip(tmp_path, data)
    assert "Missing or invalid upper frequency limit" in errors
    assert b'"band_type":"Curve"' not in written
