"""The names the ``hcard`` package offers (``hcard.__all__``) are the objects of the modules they
come from, whether or not those modules were imported first (most are imported on first use)."""

from __future__ import annotations

import importlib
import subprocess
import sys

import hcard
import hcard.card_io
import hcard.errors
import hcard.v1.card_pb2


def test_every_public_name_is_its_modules_object() -> None:
    validate_module = importlib.import_module("hcard.validate")
    homes = {**dict.fromkeys(("dumps", "load", "parse_card", "save", "to_json"), hcard.card_io),
             **dict.fromkeys(("Card", "Component", "Texture"), hcard.v1.card_pb2),
             "validate": validate_module}
    for name in hcard.__all__:
        if name == "__version__":
            continue
        home = homes.get(name, hcard.errors)
        assert getattr(hcard, name) is getattr(home, name), name
    # the submodule of the same name does not take the function's place
    assert callable(hcard.validate) and hcard.validate is validate_module.validate


def test_an_unknown_name_is_an_attribute_error() -> None:
    try:
        hcard.no_such_name  # type: ignore[attr-defined]  # noqa: B018
    except AttributeError as exc:
        assert "no attribute 'no_such_name'" in str(exc)
    else:
        raise AssertionError("hcard.no_such_name did not raise")


def test_importing_the_package_does_not_load_the_card_reader() -> None:
    code = "import sys, hcard; print('hcard.card_io' in sys.modules, hcard.load.__module__)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True)
    assert done.stdout.split() == ["False", "hcard.card_io"]
