"""The plugin kinds are one table (hcard.plugins.kinds.KIND_TABLE): the hooks pluggy knows, the
kind each hook's objects must declare, the registry's property for each kind and the order
``hcard plugins`` lists them in all come from it, so they cannot disagree."""

from __future__ import annotations

import types
from typing import Any

import pluggy
import pytest

from hcard.errors import PluginError
from hcard.plugins import hookimpl, hookspecs
from hcard.plugins.kinds import KIND_TABLE, KINDS, PROTOCOL_OF_KIND
from hcard.plugins.registry import PluginRegistry


class _Named:
    """A plugin object of ``kind`` (the members every kind shares)."""

    def __init__(self, kind: str, name: str) -> None:
        self.kind, self.name, self.description = kind, name, f"a {kind} named {name}"


def _one_of_each_kind() -> types.ModuleType:
    """A plugin module implementing every kind's hook, each returning one object of its kind."""
    plugin = types.ModuleType("one_of_each_kind")
    for row in KIND_TABLE:
        setattr(plugin, row.hook, hookimpl(lambda kind=row.name: [_Named(kind, f"the-{kind}")]))
    return plugin


def test_the_table_gives_the_kinds_their_order_and_protocols() -> None:
    # The eight kinds of ARCHITECTURE.md's table, in the order `hcard plugins` lists them.
    assert KINDS == ("encoder", "predictor", "driver", "device-profile", "calibration-effect",
                     "conformance-check", "importer", "exporter")
    assert {row.name: row.protocol for row in KIND_TABLE} == PROTOCOL_OF_KIND
    assert len({row.hook for row in KIND_TABLE}) == len({row.attribute for row in KIND_TABLE}) == 8


def test_pluggy_knows_one_hook_per_kind_and_the_command_hook() -> None:
    manager = pluggy.PluginManager(hookspecs.PROJECT)
    manager.add_hookspecs(hookspecs)
    specified = {name for name in dir(manager.hook) if name.startswith("hcard_")}
    assert specified == {row.hook for row in KIND_TABLE} | {"hcard_commands"}
    assert set(hookspecs.ALL_HOOKS) == specified
    for row in KIND_TABLE:
        spec = getattr(hookspecs, row.hook)
        assert spec.__name__ == row.hook
        assert row.protocol.__name__ in spec.__doc__  # the hook's doc names its Protocol


def test_each_kind_is_a_registry_property_of_its_objects() -> None:
    registry = PluginRegistry()
    registry.register(_one_of_each_kind(), package="vendor", version="1")
    for row in KIND_TABLE:
        objects = getattr(registry, row.attribute)
        assert list(objects) == [f"the-{row.name}"]
        assert objects == registry.of_kind(row.name)
        assert objects[f"the-{row.name}"].kind == row.name
    assert [info.kind for info in registry.all()] == list(KINDS)


def test_the_registry_has_a_property_for_each_kind_and_no_other() -> None:
    properties = {name for name, member in vars(PluginRegistry).items()
                  if type(member).__name__ == "_PluginsOfKind"}
    assert properties == {row.attribute for row in KIND_TABLE}


def test_a_registry_property_no_kind_names_is_refused() -> None:
    kinds_property = type(vars(PluginRegistry)["encoders"])
    # Python 3.12 raises the error of __set_name__ itself, 3.10 and 3.11 a RuntimeError for it.
    with pytest.raises((TypeError, RuntimeError)) as raised:
        type("Misnamed", (), {"encoder": kinds_property()})  # "encoders" is the property
    text = str(raised.value) + str(raised.value.__cause__)
    assert "Misnamed.encoder: no plugin kind has this attribute" in text


@pytest.mark.parametrize("row", KIND_TABLE, ids=[row.name for row in KIND_TABLE])
def test_an_object_of_another_kind_is_refused_by_each_hook(row: Any) -> None:
    other = next(r.name for r in KIND_TABLE if r.name != row.name)
    plugin = types.ModuleType("wrong_kind")
    setattr(plugin, row.hook, hookimpl(lambda: [_Named(other, "stray")]))
    with pytest.raises(PluginError, match=rf"{row.hook}\(\) returned 'stray' of kind "
                                          rf"'{other}', expected '{row.name}'"):
        PluginRegistry().register(plugin, package="vendor", version="1")
