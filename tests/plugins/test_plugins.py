"""The plugin registry and ``hcard plugins``, against real distributions on ``sys.path``.

Third-party plugins are real installed-looking distributions (``*.dist-info`` with METADATA and
entry_points.txt) written into a temporary directory, found by ``importlib.metadata`` exactly as
a pip-installed vendor package would be.
"""

from __future__ import annotations

import importlib
import json
import sys
import types
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest
from click.testing import CliRunner

import hcard
from hcard.errors import PluginError
from hcard.plugins import (
    KINDS,
    HcardPluginWarning,
    PluginRegistry,
    get_registry,
    hookimpl,
)
from tests.helpers.cli import run_python
from tests.helpers.distributions import install_distribution

MODULE_PREFIX = "hcardtest_"

BROKEN_IMPORT = """
raise ImportError("vendor SDK missing")
"""

RAISING_HOOK = """
from hcard.plugins import hookimpl


class Driver:
    kind = "driver"
    name = "raising-vendor-bus"
    description = "a driver that works although its encoder hook does not"


@hookimpl
def hcard_encoders():
    raise RuntimeError("calibration table missing")


@hookimpl
def hcard_drivers():
    return [Driver()]
"""

BAD_OBJECTS = """
from hcard.plugins import hookimpl


class Twin:
    kind = "encoder"
    description = "two encoders of one name"

    def __init__(self, note):
        self.name = "twin"
        self.note = note


@hookimpl
def hcard_encoders():
    return [object(), Twin("first"), Twin("second")]
"""

BAD_SIGNATURE = """
from hcard.plugins import hookimpl


@hookimpl
def hcard_encoders(config):
    return []
"""

GOOD_VENDOR = """
from hcard import build
from hcard.plugins import Encoder, EncodeResult, hookimpl


class BumpEncoder(Encoder):
    name = "acme-bumps"
    description = "Acme bump encoder"

    def encode(self, source, **options):
        texture = build.texture(1.2, [build.spatial(0.5, 0.1)], channel="ev")
        return EncodeResult(build.card(10.0, 10.0, taxtel_mm=5.0, textures=[texture]))


@hookimpl
def hcard_encoders():
    return [BumpEncoder()]
"""


def make_distribution(
    root: Path, name: str, version: str, entry_point: str, module: str, source: str
) -> None:
    """Write an installed distribution ``name`` whose ``hcard.plugins`` entry point
    ``entry_point`` names the module ``module`` with the given ``source``."""
    install_distribution(root, name, f"[hcard.plugins]\n{entry_point} = {module}\n",
                         {module: source}, version)


def _forget_test_modules() -> None:
    for module in [m for m in sys.modules if m.startswith(MODULE_PREFIX)]:
        del sys.modules[module]


@pytest.fixture
def restore_registry() -> Iterator[None]:
    """Rebuild the default registry after the test, once its ``sys.path`` changes are undone."""
    yield
    _forget_test_modules()
    importlib.invalidate_caches()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)
        get_registry(refresh=True)


@pytest.fixture
def site_dir(restore_registry: None, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A directory on ``sys.path`` where tests install distributions."""
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    importlib.invalidate_caches()
    return site


@pytest.fixture
def broken_site(site_dir: Path) -> Path:
    """Four broken third-party plugins, each broken in a different way."""
    make_distribution(site_dir, "broken-vendor", "1.2", "bad", "hcardtest_broken", BROKEN_IMPORT)
    make_distribution(site_dir, "raising-vendor", "0.3", "boom", "hcardtest_raising", RAISING_HOOK)
    make_distribution(site_dir, "odd-vendor", "2.0", "odd", "hcardtest_odd", BAD_OBJECTS)
    make_distribution(site_dir, "sig-vendor", "0.1", "sig", "hcardtest_sig", BAD_SIGNATURE)
    importlib.invalidate_caches()
    return site_dir


def _run_cli(args: list[str]):
    from hcard.cli.main import cli

    return CliRunner().invoke(cli, args)


def _table_rows(output: str) -> dict[str, list[str]]:
    """Rows of the ``hcard plugins`` table by plugin name (cells split on runs of spaces)."""
    lines = output.strip().splitlines()
    assert lines[0].split() == ["NAME", "KIND", "VERSION", "PACKAGE", "DESCRIPTION"]
    return {line.split()[0]: line.split(None, 4) for line in lines[1:]}


# --------------------------------------------------------------------------- built-ins


def test_builtin_image_encoder_is_found_through_the_entry_point(restore_registry: None) -> None:
    registry = get_registry(refresh=True)
    info = registry.info("encoder", "image")
    assert info.kind == "encoder"
    assert info.package == "hcard"
    assert info.version == hcard.__version__
    assert info.entry_point == "builtin-encoders"
    assert registry.encoders["image"] is info.obj
    assert callable(info.obj.encode)
    assert type(info.obj.load()).__module__.startswith("hcard_builtins.")
    assert [b for b in registry.broken if "package 'hcard'" in b.reason] == []


def test_get_unknown_plugin_lists_available_names(restore_registry: None) -> None:
    registry = get_registry(refresh=True)
    with pytest.raises(PluginError, match=r"no encoder plugin named 'nope'; available: .*image"):
        registry.get("encoder", "nope")
    with pytest.raises(PluginError, match="unknown plugin kind 'encoders'"):
        registry.get("encoders", "image")


def test_default_registry_is_cached_until_refreshed(restore_registry: None) -> None:
    first = get_registry(refresh=True)
    assert get_registry() is first
    assert get_registry(refresh=True) is not first


# ----------------------------------------------------------------- broken third parties


def test_broken_plugins_warn_and_the_rest_still_loads(broken_site: Path) -> None:
    with pytest.warns(HcardPluginWarning) as record:
        registry = get_registry(refresh=True)
        registry.collect()  # hooks are called when their kind is first asked for
    messages = [str(w.message) for w in record if issubclass(w.category, HcardPluginWarning)]

    def one(*needles: str) -> str:
        found = [m for m in messages if all(n in m for n in needles)]
        assert len(found) == 1, (needles, messages)
        return found[0]

    one("plugin 'bad'", "package 'broken-vendor'", "1.2", "ImportError", "vendor SDK missing")
    one("plugin 'boom'", "package 'raising-vendor'", "hcard_encoders()", "RuntimeError")
    one("plugin 'odd'", "package 'odd-vendor'", "of type 'object' without a string 'name'")
    one("plugin 'odd'", "encoder 'twin', a name already taken", "package 'odd-vendor'")
    one("plugin 'sig'", "package 'sig-vendor'", "could not be registered")
    assert sorted(b.entry_point for b in registry.broken if "-vendor'" in b.reason) == [
        "bad",
        "boom",
        "odd",
        "odd",
        "sig",
    ]

    # The built-in and every valid object of a partly broken plugin survive.
    assert "image" in registry.encoders
    assert registry.drivers["raising-vendor-bus"].name == "raising-vendor-bus"
    assert registry.info("driver", "raising-vendor-bus").package == "raising-vendor"
    assert registry.encoders["twin"].note == "first"


def test_cli_plugins_reports_broken_plugins_and_exits_0(broken_site: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)
        get_registry(refresh=True)
    result = _run_cli(["plugins"])
    assert result.exit_code == 0, result.output
    warning_lines = [line for line in result.stderr.splitlines() if line.startswith("warning: ")]
    assert any(
        line.startswith("warning: plugin 'bad' from package 'broken-vendor' (version 1.2)")
        for line in warning_lines
    ), result.stderr
    assert len(warning_lines) == 5
    assert "Traceback" not in result.stderr
    rows = _table_rows(result.stdout)
    assert rows["image"][:4] == ["image", "encoder", hcard.__version__, "hcard"]
    bus = rows["raising-vendor-bus"]
    assert bus[:4] == ["raising-vendor-bus", "driver", "0.3", "raising-vendor"]

    as_json = _run_cli(["plugins", "--json"])
    assert as_json.exit_code == 0
    document = json.loads(as_json.stdout)
    assert {p["name"] for p in document["plugins"]} >= {"image", "twin", "raising-vendor-bus"}
    assert {b["entry_point"] for b in document["broken"]} >= {"bad", "boom", "odd", "sig"}


def test_cli_plugins_subprocess_with_broken_plugin(broken_site: Path) -> None:
    done = run_python("-m", "hcard", "plugins", site=broken_site)
    assert done.returncode == 0, done.stderr
    assert "warning: plugin 'bad' from package 'broken-vendor' (version 1.2)" in done.stderr
    assert "Traceback" not in done.stderr
    assert "HcardPluginWarning" not in done.stderr  # reported once, as a warning line
    assert _table_rows(done.stdout)["image"][1] == "encoder"


# ------------------------------------------------------------------ a good third party


def test_good_vendor_plugin_is_listed_with_its_package_and_version(site_dir: Path) -> None:
    make_distribution(site_dir, "good-vendor", "1.2", "acme", "hcardtest_good", GOOD_VENDOR)
    importlib.invalidate_caches()
    registry = get_registry(refresh=True)
    assert [b for b in registry.broken if "vendor" in b.reason] == []

    result = _run_cli(["plugins"])
    assert result.exit_code == 0, result.output
    row = _table_rows(result.stdout)["acme-bumps"]
    assert row == ["acme-bumps", "encoder", "1.2", "good-vendor", "Acme bump encoder"]

    encoded = registry.get("encoder", "acme-bumps").encode(site_dir / "any.png")
    assert hcard.validate(encoded.card) == []
    assert encoded.card.textures[0].baseline == pytest.approx(1.2)


# ------------------------------------------------------------- programmatic registration


def _module(name: str, **hooks: object) -> types.ModuleType:
    module = types.ModuleType(name)
    for hook_name, function in hooks.items():
        setattr(module, hook_name, hookimpl(function))
    return module


class _Plugin:
    def __init__(self, kind: str, name: str, description: str = "") -> None:
        self.kind, self.name, self.description = kind, name, description


def test_register_in_code_orders_all_by_kind_then_name() -> None:
    registry = PluginRegistry()
    module = _module(
        "acme_plugin",
        hcard_encoders=lambda: [_Plugin("encoder", "b"), _Plugin("encoder", "a")],
        hcard_drivers=lambda: [_Plugin("driver", "z", "bus")],
        hcard_predictors=lambda: [_Plugin("predictor", "p")],
        hcard_conformance_checks=lambda: [_Plugin("conformance-check", "c")],
    )
    infos = registry.register(module, package="acme", version="9.9")
    assert len(infos) == 5
    assert [(i.kind, i.name) for i in registry.all()] == [
        ("encoder", "a"),
        ("encoder", "b"),
        ("predictor", "p"),
        ("driver", "z"),
        ("conformance-check", "c"),
    ]
    assert [i.kind for i in registry.all()] == sorted(
        (i.kind for i in registry.all()), key=KINDS.index
    )
    info = registry.info("driver", "z")
    assert (info.package, info.version, info.entry_point, info.description) == (
        "acme",
        "9.9",
        "acme_plugin",
        "bus",
    )
    assert registry.calibration_effects == {}
    assert set(registry.conformance_checks) == {"c"}


def test_register_in_code_is_strict_and_leaves_registry_unchanged() -> None:
    registry = PluginRegistry()
    registry.register(_module("first", hcard_encoders=lambda: [_Plugin("encoder", "a")]))

    def explode() -> list[object]:
        raise ValueError("no licence file")

    broken = _module(
        "second", hcard_encoders=explode, hcard_drivers=lambda: [_Plugin("driver", "d")]
    )
    with pytest.raises(PluginError, match=r"hcard_encoders\(\) raised ValueError: no licence"):
        registry.register(broken)
    clash = _module("third", hcard_encoders=lambda: [_Plugin("encoder", "a")])
    with pytest.raises(PluginError, match="encoder 'a', a name already taken by plugin 'first'"):
        registry.register(clash)
    wrong_kind = _module("fourth", hcard_encoders=lambda: [_Plugin("driver", "x")])
    with pytest.raises(PluginError, match="'x' of kind 'driver', expected 'encoder'"):
        registry.register(wrong_kind)
    with pytest.raises(PluginError, match="defines no hcard hook implementations"):
        registry.register(types.ModuleType("empty"))

    with pytest.raises(PluginError, match="already registered"):
        registry.register(registry.plugin_manager.get_plugin("first:first"))

    assert [(i.kind, i.name) for i in registry.all()] == [("encoder", "a")]
    assert registry.broken == []
    # A failed module can be fixed and registered again.
    registry.register(_module("second", hcard_drivers=lambda: [_Plugin("driver", "d")]))
    assert set(registry.drivers) == {"d"}
