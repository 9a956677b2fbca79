"""Validation findings (spec/README.md 5.1): every problem cites its rule, the report is bounded
(100 listed, the rest counted by rule), and ``hcard validate`` checks several files, reads ``-``
from standard input and prints JSON for a card that does not even parse."""

from __future__ import annotations

import json
from pathlib import Path

from click.testing import CliRunner

from hcard import build, card_io
from hcard.cli.main import cli
from hcard.v1 import card_pb2 as pb
from hcard.validate import MAX_LISTED_PROBLEMS, validate


def small_card() -> pb.Card:
    return build.card(20.0, 10.0, taxtel_mm=10.0,
                      textures=[build.texture(0.5, channel="uv", name="a")])


def test_each_problem_cites_the_rule_it_breaks() -> None:
    card = small_card()
    card.surface.width_mm = 0.0
    card.grid.texture_index[1] = 7
    card.textures[0].channel = pb.CHANNEL_UNSPECIFIED
    card.textures[0].components.add(domain=pb.DOMAIN_TEMPORAL, frequency=30_000.0,
                                    amplitude=0.1)
    card.textures[0].components.add(domain=pb.DOMAIN_SPATIAL, frequency=1.0, amplitude=0.2,
                                    phase=float("nan"))
    found = {(p.path, p.rule) for p in validate(card)}
    assert found == {
        ("surface.width_mm", "G1"),
        ("grid.texture_index[1]", "G6"),
        ("textures[0].channel", "T4"),
        ("textures[0].components[0].frequency", "C2"),
        ("textures[0].components[1].phase", "C4"),
    }
    uv = small_card()
    uv.textures[0].baseline = 0.9
    uv.textures[0].components.add(domain=pb.DOMAIN_SPATIAL, frequency=1.0, amplitude=0.2)
    (warning,) = validate(uv)
    assert (warning.rule, warning.severity) == ("W1", "warning")


def test_the_report_lists_a_bounded_number_and_counts_the_rest_by_rule() -> None:
    card = small_card()
    del card.textures[:]
    for _ in range(300):
        card.textures.add(baseline=9.0, channel=pb.CHANNEL_UV, locking=pb.LOCKING_AUTO)
    problems = validate(card)
    listed = [p for p in problems if p.path]
    assert len(listed) == MAX_LISTED_PROBLEMS
    assert listed[0].rule == "T1" and "300 textures exceed the limit of 256" in listed[0].reason
    # 256 textures examined (those past the T1 limit are not), each a T3 error
    (summary,) = [p for p in problems if not p.path]
    assert summary.rule == "T3"
    unlisted = 256 - (MAX_LISTED_PROBLEMS - 1)
    assert summary.reason == f"{unlisted} more problems of rule T3 not listed"


def test_validate_checks_several_files_and_standard_input(tmp_path: Path) -> None:
    good, bad = tmp_path / "good.hcard", tmp_path / "bad.json"
    card_io.save(small_card(), good)
    broken = small_card()
    broken.grid.texture_index[0] = 4
    bad.write_text(card_io.to_json(broken))
    runner = CliRunner()
    both = runner.invoke(cli, ["validate", str(good), str(bad)])
    assert both.exit_code == 1
    assert f"{good}: valid hcard 1.0 card" in both.output
    assert f"{bad}: error G6: grid.texture_index[0]: texture 4 is outside" in both.output
    piped = runner.invoke(cli, ["validate", "-"], input=good.read_bytes())
    assert piped.exit_code == 0 and "<stdin>: valid hcard 1.0 card (binary" in piped.output
    reports = json.loads(runner.invoke(cli, ["validate", "--json", str(good), str(bad)]).stdout)
    assert [(r["file"], r["valid"]) for r in reports] == [(str(good), True), (str(bad), False)]
    assert reports[1]["problems"][0]["rule"] == "G6"


def test_json_output_describes_a_card_that_does_not_parse(tmp_path: Path) -> None:
    corrupt = tmp_path / "corrupt.hcard"
    corrupt.write_bytes(b"\x0a\xff\x01")
    result = CliRunner().invoke(cli, ["validate", "--json", str(corrupt)])
    assert result.exit_code == 1
    report = json.loads(result.stdout)
    assert report["file"] == str(corrupt) and report["valid"] is False
    (problem,) = report["problems"]
    assert problem["rule"] == "F7" and "corrupt or truncated" in problem["reason"]
    missing = json.loads(CliRunner().invoke(cli, ["validate", "--json",
                                                  str(tmp_path / "none.hcard")]).stdout)
    assert missing["problems"][0]["reason"] == "no such file"


def test_info_describes_an_invalid_card_too_and_speaks_json(tmp_path: Path) -> None:
    good, bad = tmp_path / "good.hcard", tmp_path / "bad.hcard"
    card_io.save(small_card(), good)
    broken = small_card()
    broken.grid.texture_index[1] = 9
    bad.write_bytes(card_io.to_bytes(broken))
    runner = CliRunner()
    described = runner.invoke(cli, ["info", str(bad)])
    assert described.exit_code == 1
    assert "grid: 2 x 1 taxtels of 10 x 10 mm" in described.stdout
    assert "[0] 'a': baseline 0.5, UV, auto locking, 0 component(s), on 1 taxtel(s)" in (
        described.stdout)
    assert f"{bad}: invalid: 1 error(s) (hcard validate {bad} lists them)" in described.stderr
    summaries = json.loads(runner.invoke(cli, ["info", "--json", str(good), str(bad)]).stdout)
    assert [(s["file"], s["valid"], s["errors"]) for s in summaries] == [
        (str(good), True, 0), (str(bad), False, 1)]
    first = summaries[0]
    assert first["surface_mm"] == [20.0, 10.0] and first["grid"]["cols"] == 2
    assert first["textures"] == [{"index": 0, "name": "a", "baseline": 0.5, "channel": "UV",
                                  "locking": "auto", "components": 0, "taxtels": 2}]
    piped = runner.invoke(cli, ["info", "--json", "-"], input=good.read_bytes())
    assert json.loads(piped.stdout)["file"] == "<stdin>"
