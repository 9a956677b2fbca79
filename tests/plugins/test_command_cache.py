"""``hcard --help`` reuses the contributed commands an earlier run found, and the plugin
registry the entry points, until a distribution is installed or removed or a plugin module
changes; a plugin with a problem is warned about on every run."""

from __future__ import annotations

import importlib
import json
import os
import shutil
import subprocess
import sys
import time
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

from hcard.plugins import HcardPluginWarning, command_cache
from hcard.plugins.registry import PluginRegistry
from tests.helpers.cli import run_python
from tests.helpers.distributions import install_distribution

LIST_COMMANDS = (
    "import sys\nfrom hcard.cli.main import cli\n"
    "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
    "print(sorted(m for m in ('pluggy', 'importlib.metadata') if m in sys.modules))\n"
)
"""Prints ``hcard --help``, then which of the discovery machinery's modules it imported."""

GREETER = '''
from hcard.plugins import LazyCommand, hookimpl


@hookimpl
def hcard_commands():
    return [LazyCommand("greet", "hcardtest_greet_cmd:greet", "Greet the user.")]
'''

GREET_COMMAND = '''
import click


@click.command("greet")
def greet():
    """Greet the user."""
    click.echo("hello")
'''


def test_help_reuses_the_commands_until_a_distribution_is_installed(tmp_path: Path) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    first = run_python("-c", LIST_COMMANDS, site=site, cache=cache)
    assert first.returncode == 0, first.stderr
    assert first.stdout.splitlines()[-1] == "['importlib.metadata', 'pluggy']"  # discovered
    remembered = json.loads((cache / "hcard" / "commands.json").read_text(encoding="utf-8"))
    assert {c["name"] for c in remembered["commands"]} >= {"device", "play", "conformance"}

    second = run_python("-c", LIST_COMMANDS, site=site, cache=cache)
    assert second.stdout.splitlines()[-1] == "[]"  # no entry-point scan, no pluggy
    assert second.stdout.splitlines()[:-1] == first.stdout.splitlines()[:-1]  # same listing

    install_distribution(site, "greeter", "[hcard.commands]\ngreet = hcardtest_greeter\n",
             {"hcardtest_greeter": GREETER, "hcardtest_greet_cmd": GREET_COMMAND})
    third = run_python("-c", LIST_COMMANDS, site=site, cache=cache)
    assert third.stdout.splitlines()[-1] == "['importlib.metadata', 'pluggy']"  # found again
    assert "  greet        Greet the user." in third.stdout
    ran = run_python("-m", "hcard", "greet", site=site, cache=cache)
    assert (ran.returncode, ran.stdout) == (0, "hello\n"), ran.stderr


def test_a_remembered_command_that_no_longer_loads_is_warned_and_forgotten(
    tmp_path: Path,
) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    install_distribution(site, "greeter", "[hcard.commands]\ngreet = hcardtest_greeter\n",
             {"hcardtest_greeter": GREETER, "hcardtest_greet_cmd": GREET_COMMAND})
    assert run_python("-m", "hcard", "greet", site=site, cache=cache).stdout == "hello\n"
    (site / "hcardtest_greet_cmd.py").unlink()  # the command's module is gone, the plugin not
    gone = run_python("-m", "hcard", "greet", site=site, cache=cache)
    assert gone.returncode == 2
    assert ("warning: command 'greet' cannot be loaded: ModuleNotFoundError: No module named "
            "'hcardtest_greet_cmd'") in gone.stderr
    assert "Traceback" not in gone.stderr
    # both findings the commands come from are dropped: the commands and their group's entry
    # points (either one left would bring the stale command back without a warning)
    assert not (cache / "hcard" / "commands.json").exists()
    assert not (cache / "hcard" / "entry-points-hcard.commands.json").exists()


FIND_ENCODERS = (
    "import sys\nfrom hcard.plugins.registry import get_registry\n"
    "print(sorted(get_registry().encoders))\n"
    "print(sorted(m for m in ('importlib.metadata', 'hcard_conformance.registry', "
    "'hcard_device.plugins', 'hcard_builtins.predictors') if m in sys.modules))\n"
)
"""Prints the encoders of the registry, then which modules that only discovery needs (the
entry-point scan, the plugin modules of other kinds) it imported."""

VENDOR_ENCODER = '''
from hcard import build
from hcard.plugins import EncodeResult, Encoder, LazyCommand, hookimpl


class VendorEncoder(Encoder):
    name = "{name}"
    description = "{description}"

    def encode(self, source, **options):
        # every source: a 10 mm square card of one flat texture (2 x 2 taxtels)
        textures = [build.texture(1.0)]
        return EncodeResult(build.card(10.0, 10.0, taxtel_mm=5.0, textures=textures))


@hookimpl
def hcard_encoders():
    return [VendorEncoder()]
'''
"""A vendor's plugin module: ``name`` and ``description`` of its encoder to format in."""


def vendor_encoder(name: str, description: str = "a vendor's encoder") -> str:
    return VENDOR_ENCODER.format(name=name, description=description)


def _install_vendor(site: Path, module: str = "hcardtest_vendor_encoder") -> None:
    """Install distribution ``vendor`` in ``site``: entry point ``vendor`` naming ``module``,
    whose encoder is ``vendor-bumps``."""
    install_distribution(site, "vendor", f"[hcard.plugins]\nvendor = {module}\n",
             {module: vendor_encoder("vendor-bumps")})


ENTRY_POINT_CACHE = Path("hcard", "entry-points-hcard.plugins.json")


def test_the_registry_reuses_the_entry_points_until_a_plugin_module_changes(
    tmp_path: Path,
) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    _install_vendor(site)
    first = run_python("-c", FIND_ENCODERS, site=site, cache=cache)
    assert first.stdout.splitlines() == [
        "['image', 'vendor-bumps']",
        "['hcard_builtins.predictors', 'hcard_conformance.registry', "
        "'hcard_device.plugins', 'importlib.metadata']",  # discovered: all imported
    ], first.stderr
    assert (cache / ENTRY_POINT_CACHE).exists()

    second = run_python("-c", FIND_ENCODERS, site=site, cache=cache)
    assert second.stdout.splitlines() == ["['image', 'vendor-bumps']", "[]"], second.stderr

    module = site / "hcardtest_vendor_encoder.py"
    module.write_text(vendor_encoder("vendor-ridges"), encoding="utf-8")
    os.utime(module, ns=(module.stat().st_atime_ns, module.stat().st_mtime_ns + 10**9))
    third = run_python("-c", FIND_ENCODERS, site=site, cache=cache)
    assert third.stdout.splitlines()[0] == "['image', 'vendor-ridges']", third.stderr
    assert "importlib.metadata" in third.stdout.splitlines()[1]  # found again


def test_a_remembered_plugin_that_no_longer_imports_is_warned_on_every_run(
    tmp_path: Path,
) -> None:
    cache, site = tmp_path / "cache", tmp_path / "site"
    site.mkdir()
    _install_vendor(site)
    assert run_python("-c", FIND_ENCODERS, site=site, cache=cache).returncode == 0
    assert (cache / ENTRY_POINT_CACHE).exists()
    # What the module imports breaks while the module itself keeps its modification time.
    module = site / "hcardtest_vendor_encoder.py"
    mtime = module.stat().st_mtime_ns
    module.write_text('raise ImportError("vendor toolkit missing")\n', encoding="utf-8")
    os.utime(module, ns=(mtime, mtime))
    warning = ("plugin 'vendor' from package 'vendor' (version 1.0) failed to import "
               "'hcardtest_vendor_encoder': ImportError: vendor toolkit missing")
    for _ in range(2):  # the first run reads the cache, the second discovers
        run = run_python("-c", FIND_ENCODERS, site=site, cache=cache)
        assert run.stdout.splitlines()[0] == "['image']", run.stderr
        assert warning in run.stderr
        assert not (cache / ENTRY_POINT_CACHE).exists()  # a plugin with a problem: nothing kept


COMMAND_HOOK = '''

@hookimpl
def hcard_commands():
    return [LazyCommand("clash-cmd", "hcardtest_nowhere:command", "Clash.")]
'''


@pytest.fixture
def own_site(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """A directory on ``sys.path`` for distributions, and a cache directory of this test."""
    site = tmp_path / "site"
    site.mkdir()
    monkeypatch.syspath_prepend(str(site))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    importlib.invalidate_caches()
    yield site
    for module in [m for m in sys.modules if m.startswith("hcardtest_clash")]:
        del sys.modules[module]


def test_remembered_plugins_imported_late_keep_the_discovery_order(own_site: Path) -> None:
    """'a-vendor' is discovered before 'b-vendor', so its encoder keeps the name both give,
    even when b's module is imported first (for the command hook, which a's lacks)."""
    install_distribution(own_site, "a-vendor", "[hcard.plugins]\na = hcardtest_clash_a\n",
             {"hcardtest_clash_a": vendor_encoder("clash", "from a")})
    install_distribution(own_site, "b-vendor", "[hcard.plugins]\nb = hcardtest_clash_b\n",
             {"hcardtest_clash_b": vendor_encoder("clash", "from b") + COMMAND_HOOK})
    for remembered in (False, True):  # discovered, then from the cache
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            registry = PluginRegistry.discover()
            assert "clash-cmd" in registry.commands
            assert ("hcardtest_clash_a" in sys.modules) is not remembered
            encoder = registry.get("encoder", "clash")
            assert encoder.description == "from a"
            card = encoder.encode(own_site / "any.png").card  # the remembered module runs
            assert len(card.grid.texture_index) == 4  # 10 mm square in 5 mm taxtels
        assert [str(w.message) for w in caught if w.category is HcardPluginWarning] == [
            "plugin 'b' from package 'b-vendor' (version 1.0): hcard_encoders() returned "
            "encoder 'clash', a name already taken by plugin 'a' from package 'a-vendor'; "
            "it is ignored"
        ]
        for module in ("hcardtest_clash_a", "hcardtest_clash_b"):
            sys.modules.pop(module, None)


def test_a_current_directory_that_no_longer_exists_is_no_internal_error(tmp_path) -> None:
    # a relative sys.path entry ('' for `python -c`) cannot be made absolute once the current
    # directory is gone: the cache's validity check must not fail the command for that
    script = "\n".join([
        "import os, sys, tempfile",
        "gone = tempfile.mkdtemp()",
        "os.chdir(gone)",
        "os.rmdir(gone)",
        "sys.path.insert(0, '')",
        "from hcard.cli.main import cli",
        "try:",
        "    cli(['--help'], standalone_mode=False)",
        "except SystemExit as exc:",
        "    sys.exit(exc.code)",
    ])
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    for _run in range(2):  # the first run writes the cache, the second reads it
        done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                              env=env, timeout=60, check=False)
        assert done.returncode == 0, done.stderr
        assert "conformance" in done.stdout and "encode" in done.stdout


def _remember_vendor_encoder(site: Path) -> list[Path]:
    """Install a vendor encoder in ``site`` and a distribution without hcard entry points, age
    ``site`` beyond the clock's resolution, and remember the discovered entry points; the
    metadata directories (vendor's, other's)."""
    _install_vendor(site, "hcardtest_clash_vendor")
    install_distribution(site, "other", "[console_scripts]\nother = other:main\n", {})
    hour_ago = time.time_ns() - 3600 * 10**9
    os.utime(site, ns=(hour_ago, hour_ago))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HcardPluginWarning)
        PluginRegistry.discover()
    assert command_cache.load_entry_points("hcard.plugins") is not None  # remembered
    return [site / "vendor-1.0.dist-info", site / "other-1.0.dist-info"]


def test_a_distribution_changed_in_place_invalidates_the_remembered_entry_points(
    own_site: Path,
) -> None:
    vendor, _ = _remember_vendor_encoder(own_site)
    mtime = own_site.stat().st_mtime_ns
    (vendor / "direct_url.json").write_text("{}", encoding="utf-8")  # its directory changes
    assert own_site.stat().st_mtime_ns == mtime  # not the directory holding it
    assert command_cache.load_entry_points("hcard.plugins") is None


def test_files_that_are_no_distribution_keep_the_remembered_entry_points(
    own_site: Path,
) -> None:
    _remember_vendor_encoder(own_site)
    (own_site / "encoded.card").write_bytes(b"")  # e.g. output written to the current directory
    assert own_site.stat().st_mtime_ns > time.time_ns() - 3600 * 10**9  # the directory changed
    assert command_cache.load_entry_points("hcard.plugins") is not None


@pytest.mark.parametrize("change", ["install", "remove", "reinstall"])
def test_installing_or_removing_a_distribution_invalidates_the_remembered_entry_points(
    own_site: Path, change: str,
) -> None:
    vendor, other = _remember_vendor_encoder(own_site)
    if change == "install":
        install_distribution(own_site, "third", "[console_scripts]\nthird = third:main\n", {})
    elif change == "remove":
        shutil.rmtree(other)
    else:  # the same version again, as `pip install -e .` does: a new metadata directory
        shutil.rmtree(vendor)
        install_distribution(own_site, "vendor",
                             "[hcard.plugins]\nvendor = hcardtest_clash_vendor\n", {})
        later = vendor.stat().st_mtime_ns + 10**9  # whatever the file system clock's resolution
        os.utime(vendor, ns=(later, later))
    assert command_cache.load_entry_points("hcard.plugins") is None
