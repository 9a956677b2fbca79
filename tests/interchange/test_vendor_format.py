"""A vendor adds its own format without touching hcard (spec/interchange.md IX1-IX3, IX6-IX9):
an installed distribution whose ``hcard.plugins`` entry point returns an importer and an
exporter, driven through ``hcard import``, ``hcard export`` and ``hcard plugins`` in fresh
interpreters, as a user of that vendor's package would."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hcard import build
from hcard.card_io import load, save
from tests.helpers.cli import run_python
from tests.helpers.distributions import install_distribution

ACME_PROFILE = """
import math
from pathlib import Path

from hcard import build
from hcard.errors import AssetError, UsageError
from hcard.plugins import EncodeResult, ExportResult, Loss, hookimpl

MAGIC = b"# acme-profile v1"


class ProfileImporter:
    kind = "importer"
    name = "acme-profile"
    description = "Acme friction profile (CSV of x_mm,friction) to a one-row card"
    suffixes = (".acp",)

    def recognises(self, head):
        return 2 if head.startswith(MAGIC) else 0

    def options(self, **values):
        unknown = sorted(set(values) - {"taxtel_mm"})
        if unknown:
            raise UsageError(f"{unknown[0]} does not apply to an Acme profile")
        return {"taxtel_mm": float(values.get("taxtel_mm", 5.0))}

    def read(self, source, *, progress=None, taxtel_mm=5.0):
        rows = Path(source).read_text().splitlines()[1:]
        samples = []
        for number, row in enumerate(rows, start=2):
            try:
                x_mm, friction = (float(cell) for cell in row.split(","))
            except ValueError:
                raise AssetError("not two numbers", source=source,
                                 field=f"line {number}") from None
            samples.append((x_mm, friction))
        length = samples[-1][0]
        cols = max(1, round(length / taxtel_mm))
        textures, index = [], []
        for col in range(cols):
            inside = [f for x, f in samples if col * taxtel_mm <= x < (col + 1) * taxtel_mm]
            textures.append(build.texture(sum(inside) / len(inside), [], channel="uv"))
            index.append(col)
        card = build.card(cols * taxtel_mm, taxtel_mm, taxtel_mm=taxtel_mm,
                          textures=textures, texture_index=index)
        errors = [abs(f - textures[min(int(x // taxtel_mm), cols - 1)].baseline)
                  for x, f in samples]
        jnd = 0.08
        rms = math.sqrt(sum(e * e for e in errors) / len(errors))
        return EncodeResult(card, stats={"rms_error_jnd": rms / jnd,
                                         "max_error_jnd": max(errors) / jnd,
                                         "format_detail": f"{len(samples)} samples",
                                         "fidelity_basis": "the samples"})


class ProfileExporter:
    kind = "exporter"
    name = "acme-profile"
    description = "Card to an Acme friction profile, with a JSON sidecar"
    suffix = ".acp"

    def options(self, **values):
        return {}

    def write(self, card, *, progress=None):
        taxtel = card.grid.taxtel_width_mm
        lines = [MAGIC.decode()]
        for col in range(card.grid.cols):
            baseline = card.textures[card.grid.texture_index[col]].baseline
            lines.append(f"{(col + 0.5) * taxtel:g},{baseline:g}")
        sidecar = {"title": card.metadata.title}
        losses = [Loss("components", "gratings are not written: baselines only")]
        return ExportResult([("", "\\n".join(lines).encode()),
                             (".json", repr(sidecar).encode())], losses,
                            {"rms_error_jnd": 0.0, "max_error_jnd": 0.0})


@hookimpl
def hcard_importers():
    return [ProfileImporter()]


@hookimpl
def hcard_exporters():
    return [ProfileExporter()]
"""


@pytest.fixture
def acme_site(tmp_path: Path) -> Path:
    """A site directory holding the vendor's distribution ``acme-formats`` 2.1."""
    site = tmp_path / "site"
    site.mkdir()
    install_distribution(site, "acme-formats", "[hcard.plugins]\nacme = acme_formats\n",
                         {"acme_formats": ACME_PROFILE}, "2.1")
    return site


def _hcard(site: Path, *args: str):
    return run_python("-m", "hcard", *args, site=site)


def _profile(site: Path, rows: list[tuple[float, float]]) -> Path:
    path = site / "plate.acp"
    path.write_text("# acme-profile v1\n" + "".join(f"{x},{f}\n" for x, f in rows))
    return path


def test_the_vendor_importer_and_exporter_are_listed_with_their_package(acme_site: Path):
    done = _hcard(acme_site, "plugins", "--json")
    assert done.returncode == 0, done.stderr
    rows = {(p["kind"], p["name"]): p for p in json.loads(done.stdout)["plugins"]}
    assert rows["importer", "acme-profile"]["package"] == "acme-formats"
    assert rows["exporter", "acme-profile"]["version"] == "2.1"
    # the built-in formats are plugins of the same kinds
    assert {("importer", "tanvas"), ("importer", "tpad"), ("importer", "haps"),
            ("importer", "hjif"), ("exporter", "hjif"), ("exporter", "tanvas"),
            ("exporter", "tpad")} <= set(rows)


def test_the_vendor_format_is_recognised_by_content_and_imported(acme_site: Path):
    # 0.9 on the first 5 mm, 0.5 on the next: two taxtels of those baselines, exactly
    source = _profile(acme_site, [(0.5, 0.9), (2.5, 0.9), (4.5, 0.9), (5.5, 0.5), (9.5, 0.5),
                                  (10.0, 0.5)])
    done = _hcard(acme_site, "import", str(source), "-o", "plate.hcard", "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["format"] == "acme-profile" and summary["rms_error_jnd"] == 0.0
    card = load(acme_site / "plate.hcard")
    assert [t.baseline for t in card.textures] == pytest.approx([0.9, 0.5])


def test_the_fidelity_is_the_importers_own_figure(acme_site: Path):
    # one taxtel of 0.9 and 0.7: the baseline 0.8 is 0.1 = 1.25 JND from each
    source = _profile(acme_site, [(1.0, 0.9), (4.9, 0.7)])
    done = _hcard(acme_site, "import", str(source), "-o", "plate.hcard")
    assert done.returncode == 0, done.stderr
    assert "fidelity    rms 1.25, max 1.25 x the 0.08 friction JND" in done.stdout


def test_an_option_that_does_not_apply_is_refused_by_its_option_name(acme_site: Path):
    source = _profile(acme_site, [(1.0, 0.9), (5.0, 0.8)])
    done = _hcard(acme_site, "import", str(source), "-o", "plate.hcard", "--dpi", "96")
    assert done.returncode == 2
    assert "--dpi does not apply to an Acme profile" in done.stderr
    assert not (acme_site / "plate.hcard").exists()


def test_a_bad_line_names_the_file_and_line_and_keeps_the_previous_card(acme_site: Path):
    previous = build.card(10.0, 5.0, taxtel_mm=5.0, textures=[build.texture(0.7, [])])
    save(previous, acme_site / "plate.hcard")
    before = (acme_site / "plate.hcard").read_bytes()
    source = acme_site / "plate.acp"
    source.write_text("# acme-profile v1\n1.0,0.9\n2.0,slippery\n")
    done = _hcard(acme_site, "import", str(source), "-o", "plate.hcard")
    assert done.returncode == 1
    assert done.stderr.strip() == f"Error: {source}: line 3: not two numbers"
    assert (acme_site / "plate.hcard").read_bytes() == before


def test_an_unknown_format_and_an_unknown_importer_are_refused(acme_site: Path):
    other = acme_site / "notes.txt"
    other.write_text("nothing a haptic importer reads\n")
    done = _hcard(acme_site, "import", str(other), "-o", "x.hcard")
    assert done.returncode == 1
    assert "no importer recognises this content" in done.stderr and "--from" in done.stderr
    assert "Traceback" not in done.stderr
    done = _hcard(acme_site, "import", str(other), "-o", "x.hcard", "--from", "acme-wave")
    assert done.returncode == 2
    assert "--from acme-wave: no such importer; installed: acme-profile, haps" in done.stderr


def test_the_export_states_its_losses_and_writes_its_companion(acme_site: Path):
    card = build.card(10.0, 5.0, taxtel_mm=5.0,
                      textures=[build.texture(0.9, [build.spatial(1.0, 0.1)]),
                                build.texture(0.5, [])], texture_index=[0, 1])
    card.metadata.title = "plate"
    save(card, acme_site / "plate.hcard")
    done = _hcard(acme_site, "export", "plate.hcard", "--to", "acme-profile", "-o", "out.acp",
                  "--json")
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["losses"] == [{"field": "components", "carried": "",
                                  "detail": "gratings are not written: baselines only"}]
    assert [Path(f["path"]).name for f in summary["files"]] == ["out.acp", "out.json"]
    assert (acme_site / "out.acp").read_text().splitlines()[1:] == ["2.5,0.9", "7.5,0.5"]
    assert (acme_site / "out.json").read_text() == "{'title': 'plate'}"
    text = _hcard(acme_site, "export", "plate.hcard", "--to", "acme-profile", "-o", "out.acp")
    assert "cannot hold components: gratings are not written: baselines only; not kept" in (
        text.stdout)


def test_an_export_writes_all_its_files_or_none(acme_site: Path):
    save(build.card(10.0, 5.0, taxtel_mm=5.0, textures=[build.texture(0.5, [])]),
         acme_site / "plate.hcard")
    (acme_site / "out.acp").write_text("previous")
    (acme_site / "out.json").mkdir()  # the companion cannot be written
    done = _hcard(acme_site, "export", "plate.hcard", "--to", "acme-profile", "-o", "out.acp")
    assert done.returncode == 1
    assert "out.json" in done.stderr and "Traceback" not in done.stderr
    assert (acme_site / "out.acp").read_text() == "previous"
