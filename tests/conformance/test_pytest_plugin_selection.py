"""The pytest plugin chooses before it runs (spec/conformance.md QP3, QP5): ``--collect-only``
lists every item a run reports and runs nothing, ``-k`` and ``--deselect`` choose which checks
and cases run, a node ID pytest prints selects its case again, and the cases a check did not
declare are reported all the same. pytest runs as a vendor's CI runs it (a subprocess) and the
JUnit XML is read as dashboards read it."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from hcard_conformance.context import Context
from hcard_conformance.runner import run_suite
from hcard_conformance.vectors import load_manifest
from tests.helpers.conformance_pytest import (
    checks_run,
    collected,
    dashboard,
    junit_cases,
    pytest_run,
)

MANIFEST = load_manifest()
REFERENCE = "--hcard-driver=reference"


def test_collect_only_lists_the_items_a_run_reports_and_runs_nothing(tmp_path: Path) -> None:
    listed, _ = pytest_run(tmp_path, REFERENCE, "--collect-only")
    assert listed.returncode == 0, listed.stdout[-2000:]
    assert checks_run(listed.stdout) == []
    ids = collected(listed.stdout)
    assert f"{len(ids)} tests collected" in listed.stdout

    def of(check: str) -> int:
        return sum(i.startswith(f"{check}::") for i in ids)

    # what the levels cover, from the manifest (spec Q2-Q4; A0 and A1 on every golden render)
    assert of("format.parse") == 2 * len(MANIFEST.cards)
    assert of("format.round_trip") == len(MANIFEST.cards)
    assert of("format.reject") == len(MANIFEST.invalid)
    assert of("renderer.exact") == of("renderer.friction_error") == len(MANIFEST.renders)
    run, xml = pytest_run(tmp_path, REFERENCE, quiet=False)
    assert run.returncode == 0, run.stdout[-2000:]
    assert junit_cases(xml) == ids
    assert checks_run(run.stdout) == [
        (check, of(check)) for check in dict.fromkeys(i.split("::")[0] for i in ids)]


def test_k_runs_only_the_one_renderer_case_it_selects(tmp_path: Path) -> None:
    run, xml = pytest_run(tmp_path, REFERENCE, "-k",
                          "friction_error and single-grating and fast-stroke", quiet=False)
    assert run.returncode == 0, run.stdout[-2000:]
    assert junit_cases(xml) == ["renderer.friction_error::single-grating@fast-stroke"]
    assert dashboard(xml)["green"] == ["renderer.friction_error.single-grating@fast-stroke"]
    assert checks_run(run.stdout) == [("renderer.friction_error", 1)]  # one render, one check


def test_deselect_leaves_its_case_unrendered(tmp_path: Path) -> None:
    report = run_suite(Context.for_driver("reference"), ("renderer",),
                       select=["renderer.boundary"])
    cases = [r.case for r in report.results]  # what a whole run of the check reports
    left_out = "renderer.boundary::edge@reversal"
    run, xml = pytest_run(tmp_path, REFERENCE, "--hcard-check=renderer.boundary",
                          f"--deselect={left_out}", quiet=False)
    assert run.returncode == 0, run.stdout[-2000:]
    assert junit_cases(xml) == [f"renderer.boundary::{c}" for c in cases
                                if f"renderer.boundary::{c}" != left_out]
    assert checks_run(run.stdout) == [("renderer.boundary", len(cases) - 1)]


def test_the_node_id_of_a_failure_selects_it_again(tmp_path: Path) -> None:
    """A vector that should be refused is a valid card: format.reject fails on it; the node ID
    in pytest's summary, pasted back as the only argument, runs that case alone."""
    vectors = tmp_path / "vectors"
    shutil.copytree(MANIFEST.root, vectors)
    victim = load_manifest(vectors).invalid[0]
    victim.file.write_bytes(MANIFEST.cards[0].binary.read_bytes())
    options = (REFERENCE, "--hcard-level=format", f"--hcard-vectors={vectors}")
    run, _ = pytest_run(tmp_path, *options)
    assert run.returncode == 1, run.stdout[-2000:]
    (node_id,) = re.findall(r"^FAILED (\S+)", run.stdout, re.M)
    assert node_id == f"format.reject::{victim.name}"
    again, xml = pytest_run(tmp_path, *options, "-v", node_id, quiet=False, in_folder=False)
    assert again.returncode == 1, again.stdout[-2000:]
    assert junit_cases(xml) == [node_id] and dashboard(xml)["red"] == [node_id.replace("::", ".")]
    assert checks_run(again.stdout) == [("format.reject", 1)]
    assert re.search(rf"^{re.escape(node_id)} FAILED", again.stdout, re.M)  # pasteable as is


def test_a_device_check_case_runs_alone_by_its_node_id(tmp_path: Path) -> None:
    run, xml = pytest_run(tmp_path, "--hcard-driver=sim://", "device.friction::dense-grating",
                          quiet=False, in_folder=False)
    assert run.returncode == 0, run.stdout[-2000:]
    assert junit_cases(xml) == ["device.friction::dense-grating"]
    assert dashboard(xml)["green"] == ["device.friction.dense-grating"]
    assert checks_run(run.stdout) == [("device.friction", 1)]  # one play, not coarse-taxtels


def test_a_node_id_of_no_declared_case_is_a_collection_error(tmp_path: Path) -> None:
    run, _ = pytest_run(tmp_path, REFERENCE, "renderer.boundary::no-such-vector",
                          quiet=False, in_folder=False)
    assert run.returncode == 2, run.stdout[-2000:]  # pytest: interrupted by collection errors
    assert "not found: renderer.boundary::no-such-vector (renderer.boundary declares" in \
        run.stdout
    assert checks_run(run.stdout) == [] and "Traceback" not in run.stdout


def test_the_setup_error_is_listed_and_its_node_id_runs_the_suite_again(tmp_path: Path) -> None:
    unreachable = "--hcard-driver=usbip://127.0.0.1:9/1-1"
    listed, _ = pytest_run(tmp_path, unreachable, "--collect-only")
    assert collected(listed.stdout) == ["hcard-conformance::setup"]
    run, xml = pytest_run(tmp_path, unreachable, "hcard-conformance::setup", in_folder=False)
    assert run.returncode == 1, run.stdout[-2000:]
    assert dashboard(xml)["red"] == ["hcard-conformance.setup"]
    assert "cannot open driver 'usbip://127.0.0.1:9/1-1'" in run.stdout


VENDOR_CHECKS = '''
import types
from pathlib import Path

from hcard.plugins import get_registry, hookimpl
from hcard_conformance.registry import check
from hcard_conformance.result import CheckResult


def ran(name):
    with open(Path(__file__).parent / "ran.txt", "a") as out:
        out.write(name + "\\n")


@check(name="acme.undeclared", level="format")
def undeclared(ctx):
    ran("acme.undeclared")
    yield CheckResult("acme.undeclared", "format", "one", True)
    yield CheckResult("acme.undeclared", "format", "two", False, detail="two is off")


@check(name="acme.partly", level="format", cases=("a",))
def partly(ctx):
    ran("acme.partly")
    yield CheckResult("acme.partly", "format", "a", True)
    yield CheckResult("acme.partly", "format", "b", True)


@check(name="acme.short", level="format", cases=("x", "y"))
def short(ctx):
    ran("acme.short")
    yield CheckResult("acme.short", "format", "x", True)


@check(name="acme.nothing", level="format", cases=())
def nothing(ctx):
    ran("acme.nothing")
    return iter(())


plugin = types.ModuleType("acme_checks")
plugin.hcard_conformance_checks = hookimpl(lambda: [undeclared, partly, short, nothing])
get_registry().register(plugin, package="acme")
'''
"""A vendor's conftest.py adding four checks: one declaring no cases, one reporting a case it
did not declare, one not reporting a case it declared, one declaring and reporting none (which
fails, spec Q6); each notes in ran.txt that it ran."""


def test_cases_a_check_did_not_declare_are_reported_and_none_is_dropped(tmp_path: Path) -> None:
    (tmp_path / "conftest.py").write_text(VENDOR_CHECKS)
    ran = tmp_path / "ran.txt"
    listed, _ = pytest_run(tmp_path, REFERENCE, "--hcard-check=acme", "--collect-only")
    assert collected(listed.stdout) == ["acme.nothing::(cases)", "acme.partly::a",
                                        "acme.short::x", "acme.short::y",
                                        "acme.undeclared::(cases)"], listed.stdout[-2000:]
    assert not ran.exists()
    run, xml = pytest_run(tmp_path, REFERENCE, "--hcard-check=acme")
    assert junit_cases(xml) == ["acme.nothing::(none)", "acme.partly::a", "acme.partly::b",
                                "acme.short::x", "acme.short::y", "acme.undeclared::one",
                                "acme.undeclared::two"]
    assert dashboard(xml)["red"] == ["acme.nothing.(none)", "acme.short.y",
                                     "acme.undeclared.two"]
    assert "acme.short [format] y: ERROR acme.short did not report case y" in run.stdout
    assert ran.read_text().split() == ["acme.nothing", "acme.partly", "acme.short",
                                       "acme.undeclared"]
    ran.unlink()
    again, xml = pytest_run(tmp_path, REFERENCE, "acme.undeclared::two", in_folder=False)
    assert junit_cases(xml) == ["acme.undeclared::two"], again.stdout[-2000:]
    assert ran.read_text().split() == ["acme.undeclared"]
