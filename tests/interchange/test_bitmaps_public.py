"""Real Tanvas and TPad bitmaps from public repositories (neither states a licence, so they
are fetched by scripts/fetch_public_samples.py into tests/data/public/fetched/, not kept
here): each imports with the grid its resolution gives, the format's channel, and a fidelity
to its own pixels below a bound a little above what was measured
(spec/interchange/bitmaps.md IB5, IB16)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from hcard.v1 import card_pb2 as pb
from hcard_builtins.formats.bitmaps import TanvasImporter, TPadImporter
from tests.helpers.public_samples import fetched_sample

# repo, path, importer, --dpi (None: the PNG's pHYs), measured rms and p95 in JND at
# --max-error 1 (bounds: 1.25 x measured, rounded up)
SAMPLES = [
    ("CaritaRoti/TanvasProject", "TanvasProject/Assets/HelloTanvas_haptics.png", "tanvas",
     149.4, 0.53, 1.24),
    ("CaritaRoti/TanvasProject", "TanvasProject/Assets/appHapticSprite.png", "tanvas",
     149.4, 0.28, 0.33),
    ("brockel27/DrivingStudy-TanvasTouch", "tanvas_knob/assets/nub/haptics@1.png", "tanvas",
     149.4, 1.17, 2.54),
    ("brockel27/DrivingStudy-TanvasTouch",
     "tanvas_knob/assets/background/rotation_haptics@1.png", "tanvas", 149.4, 0.45, 0.71),
    ("TPadTabletProject/TPadSoftware", "HelloTPadPhone/res/drawable/spacialgrad.png", "tpad",
     None, 0.61, 1.22),
    ("TPadTabletProject/TPadSoftware", "HelloTPadPhone/res/drawable/testdepth.png", "tpad",
     None, 0.25, 0.55),
    ("TPadTabletProject/TPadSoftware", "HelloTPadPhone/res/drawable/testdepthbars.png", "tpad",
     None, 0.27, 0.64),
]
IMPORTERS = {"tanvas": TanvasImporter(), "tpad": TPadImporter()}
CHANNELS = {"tanvas": pb.CHANNEL_EV, "tpad": pb.CHANNEL_UV}
STORED_DPI = {72.009, 96.012, 119.99, 143.993, 95.987}
"""The pHYs the samples carry (authoring tools' defaults, not screen densities)."""


@pytest.mark.parametrize(("repo", "path", "name", "dpi", "rms", "p95"), SAMPLES,
                         ids=[Path(s[1]).name for s in SAMPLES])
def test_public_bitmap_imports(repo: str, path: str, name: str, dpi: float | None, rms: float,
                               p95: float):
    source = fetched_sample(repo, path, "its project states no licence")
    result = IMPORTERS[name].read(source, max_error=1.0, dpi=dpi)
    stats = result.stats
    stored = None
    if dpi is None:
        assert stats["size_source"].startswith("from the DPI stored in the image")
        stored = float(stats["size_source"].split("(")[1].split(" x ")[0])
        assert any(abs(stored - value) < 0.01 for value in STORED_DPI)
    pitch = 25.4 / (dpi or stored)  # type: ignore[operator]
    assert stats["cols"] == math.ceil(stats["image_width_px"] * pitch / 5.0 - 1e-9)
    assert stats["rows"] == math.ceil(stats["image_height_px"] * pitch / 5.0 - 1e-9)
    assert stats["width_mm"] == pytest.approx(stats["image_width_px"] * pitch)
    assert {t.channel for t in result.card.textures} == {CHANNELS[name]}
    assert stats["rms_error_jnd"] <= math.ceil(rms * 1.25 * 100) / 100
    assert stats["p95_error_jnd"] <= math.ceil(p95 * 1.25 * 100) / 100
    assert stats["embedded_card"] is False
