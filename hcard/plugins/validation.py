"""What a plugin gives the registry, checked: its hook implementations, the objects they return
and the commands it contributes.

A registered plugin must implement known hooks (:data:`~hcard.plugins.hookspecs.ALL_HOOKS`),
none of them as a hook wrapper; each implementation is called on its own (one that raises
hides nothing else) and must return a list. Each object returned must have a non-empty string
``name``, a string ``description`` and, when it says, the ``kind`` of its hook
(:data:`~hcard.plugins.kinds.KIND_OF_HOOK`), under a name not taken; each command must be a
:class:`~hcard.plugins.kinds.CommandPlugin` under a name not taken. What fails is not kept: it
is a problem, a line appended to the caller's ``problems`` naming the plugin
(:meth:`~hcard.plugins.records.PluginSource.label`), which the registry warns or raises.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

import pluggy

from hcard.plugins.hookspecs import ALL_HOOKS, COMMAND_HOOK
from hcard.plugins.kinds import KIND_OF_HOOK, CommandPlugin
from hcard.plugins.records import PluginInfo, PluginSource, describe_exception


def hook_problems(plugin_manager: pluggy.PluginManager, plugin: Any,
                  source: PluginSource) -> list[str]:
    """Problems of ``plugin``'s hook implementations found without calling them: hooks without a
    specification, or no hook at all."""
    problems = []
    callers = plugin_manager.get_hookcallers(plugin) or []
    unknown = sorted(c.name for c in callers if not c.has_spec())
    if unknown:
        problems.append(
            f"{source.label()} implements unknown hook(s) {', '.join(unknown)} "
            f"(known: {', '.join(ALL_HOOKS)}); they are ignored"
        )
    if not callers:
        problems.append(
            f"{source.label()} defines no hcard hook implementations "
            "(are its hooks decorated with hcard.plugins.hookimpl?)"
        )
    return problems


def answers(plugin_manager: pluggy.PluginManager, plugin: Any, source: PluginSource,
            hook_name: str, problems: list[str]) -> Iterable[Any]:
    """What each implementation of ``hook_name`` by ``plugin`` returns, called on its own."""
    for impl in getattr(plugin_manager.hook, hook_name).get_hookimpls():
        if impl.plugin is not plugin:
            continue
        if impl.hookwrapper or impl.wrapper:
            problems.append(f"{source.label()}: {hook_name} must not be a hook wrapper")
            continue
        try:
            result = impl.function()
        except (Exception, SystemExit) as exc:
            problems.append(f"{source.label()}: {hook_name}() raised {describe_exception(exc)}")
            continue
        yield from _objects_of(result, hook_name, source, problems)


def _objects_of(result: Any, hook_name: str, source: PluginSource,
                problems: list[str]) -> Iterable[Any]:
    if isinstance(result, list | tuple):
        return result
    problems.append(
        f"{source.label()}: {hook_name}() returned {type(result).__name__}, "
        "expected a list of plugin objects"
    )
    return ()


def plugins_of(plugin_manager: pluggy.PluginManager, plugin: Any, source: PluginSource,
               hook_name: str, taken: Mapping[str, PluginInfo],
               problems: list[str]) -> list[PluginInfo]:
    """The valid plugin objects ``plugin``'s ``hook_name`` returns, none of them named as one
    of ``taken`` (the registry's plugins of that hook's kind, by name) or as an earlier one."""
    kind = KIND_OF_HOOK[hook_name].name
    infos: list[PluginInfo] = []
    staged: dict[str, PluginInfo] = {}
    for obj in answers(plugin_manager, plugin, source, hook_name, problems):
        info = _plugin_info(obj, kind, hook_name, source, staged, taken, problems)
        if info is not None:
            staged[info.name] = info
            infos.append(info)
    return infos


def _plugin_info(
    obj: Any,
    kind: str,
    hook_name: str,
    source: PluginSource,
    staged: Mapping[str, PluginInfo],
    taken: Mapping[str, PluginInfo],
    problems: list[str],
) -> PluginInfo | None:
    """A :class:`PluginInfo` for ``obj`` when it is a valid ``kind`` plugin, else None."""
    where = f"{source.label()}: {hook_name}() returned"
    name = getattr(obj, "name", None)
    if not isinstance(name, str) or not name.strip():
        problems.append(
            f"{where} an object of type '{type(obj).__name__}' without a string 'name'"
        )
        return None
    description = getattr(obj, "description", "")
    if not isinstance(description, str):
        problems.append(f"{where} '{name}' whose 'description' is not a string")
        return None
    declared = getattr(obj, "kind", kind)
    if declared != kind:
        problems.append(f"{where} '{name}' of kind '{declared}', expected '{kind}'")
        return None
    other = staged.get(name) or taken.get(name)
    if other is not None:
        problems.append(
            f"{where} {kind} '{name}', a name already taken by plugin "
            f"'{other.entry_point}' from package '{other.package}'; it is ignored"
        )
        return None
    return PluginInfo(
        name=name,
        kind=kind,
        version=source.version,
        package=source.package,
        entry_point=source.entry_point,
        obj=obj,
    )


def commands_of(plugin_manager: pluggy.PluginManager, plugin: Any, source: PluginSource,
                taken: Mapping[str, CommandPlugin],
                problems: list[str]) -> dict[str, CommandPlugin]:
    """The subcommands ``plugin`` contributes through :data:`COMMAND_HOOK`, by name, none of
    them named as one of ``taken`` (the registry's commands) or as an earlier one."""
    found: dict[str, CommandPlugin] = {}
    where = f"{source.label()}: {COMMAND_HOOK}() returned"
    for command in answers(plugin_manager, plugin, source, COMMAND_HOOK, problems):
        name = getattr(command, "name", None)
        if not isinstance(command, CommandPlugin) or not isinstance(name, str) or not (
            name.strip() and isinstance(command.summary, str)
        ):
            problems.append(
                f"{where} an object of type '{type(command).__name__}' that is not a "
                "command (a string 'name' and 'summary', and load())"
            )
            continue
        if name in found or name in taken:
            problems.append(f"{where} command '{name}', a name already taken; it is ignored")
            continue
        found[name] = command
    return found
