"""``--plugin MODULE[:ATTR]``: plugins of a game that is not an installed package, named on the command line.

``python -m engine run|validate|graph`` find plugins through the ``ecsfx.plugins`` entry points of installed
packages (:mod:`engine.registry`).  A game kept in its own folder names its plugin instead:

* ``--plugin mygame:MyPlugin`` imports ``mygame`` (from the current directory too, as ``python -m`` does) and
  takes its attribute ``MyPlugin`` (dotted names reach further: ``mygame:plugins.main``);
* ``--plugin mygame`` takes the module's attribute ``plugin`` when it has one, else the one plugin the module
  itself defines (an object, or a class, of the module; an object is preferred to its own class).  Several, or
  none, is an error that says how to name one.

A class is instantiated with no arguments.  A plugin is anything with a ``name`` (a string) and a
``build(registry)`` method (:class:`engine.registry.Plugin`).  Plugins named so are installed after the engine's
core and the entry-point plugins (the scene's ``[scene] plugins`` list, when it has one, still decides which of
those); an entry-point plugin of the same name gives way to it.  A scene may list their names in
``[scene] plugins``.
"""

from __future__ import annotations

import importlib
import os
import sys
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from engine.registry import Plugin, Registry, available_plugins, default_registry

DEFAULT_ATTR = "plugin"


class PluginOptionError(ValueError):
    """A ``--plugin`` value that names no usable plugin; the message names the option and the value."""

    def __init__(self, spec: str, reason: str) -> None:
        super().__init__(f"--plugin {spec!r}: {reason}")
        self.spec = spec
        self.reason = reason


@dataclass(frozen=True)
class NamedPlugin:
    """A plugin and the ``--plugin`` value that named it (for error messages)."""

    spec: str
    plugin: Plugin


def is_plugin(obj: Any) -> bool:
    """Whether ``obj`` (an object, or a class) has a non-empty string ``name`` and a callable ``build``."""
    name = getattr(obj, "name", None)
    return isinstance(name, str) and bool(name) and callable(getattr(obj, "build", None))


def load_plugin(spec: str) -> Plugin:
    """The plugin ``MODULE[:ATTR]`` names (see the module's docstring); raises :class:`PluginOptionError`."""
    module_name, _, attr = spec.partition(":")
    if not module_name or not all(part.isidentifier() for part in module_name.split(".")):
        raise PluginOptionError(spec, "expected MODULE or MODULE:ATTR, a Python module name such as 'mygame' or "
                                      "'mygame.plugin' (run from the folder that holds it)")
    if ":" in spec and not (attr and all(part.isidentifier() for part in attr.split("."))):
        raise PluginOptionError(spec, f"expected an attribute name after ':', got {attr!r}")
    module = _import(spec, module_name)
    if attr:
        obj = _attribute(spec, module, attr)
    elif hasattr(module, DEFAULT_ATTR):
        attr, obj = DEFAULT_ATTR, getattr(module, DEFAULT_ATTR)
    else:
        attr, obj = _the_one_plugin(spec, module)
    if isinstance(obj, type):
        if not is_plugin(obj):
            raise _not_a_plugin(spec, module_name, attr, obj)
        try:
            obj = obj()
        except Exception as exc:  # noqa: BLE001 - the plugin's own code: report it in one line
            raise PluginOptionError(spec, f"cannot instantiate class {module_name}:{attr}: {type(exc).__name__}: "
                                          f"{exc}") from exc
    if not is_plugin(obj):
        raise _not_a_plugin(spec, module_name, attr, obj)
    return obj


def load_plugins(specs: Iterable[str] | None) -> list[NamedPlugin]:
    """Every ``--plugin`` value loaded, in order; the same plugin named twice counts once, two plugins of one name
    are an error."""
    loaded: list[NamedPlugin] = []
    for spec in specs or ():
        plugin = load_plugin(spec)
        same = [p for p in loaded if p.plugin.name == plugin.name]
        if same and same[0].plugin is not plugin:
            raise PluginOptionError(spec, f"its plugin is named {plugin.name!r}, as is the one --plugin "
                                          f"{same[0].spec!r} gives")
        if not same:
            loaded.append(NamedPlugin(spec, plugin))
    return loaded


def registry_with(plugins: Sequence[NamedPlugin], names: Iterable[str] | None = None) -> Registry:
    """The engine's core, the entry-point plugins (only ``names`` if given: a scene's ``[scene] plugins``) and
    then ``plugins``.  A name in ``names`` that is one of ``plugins`` is theirs; an unknown one raises
    :class:`engine.registry.RegistryError` with the nearest name."""
    own = {p.plugin.name for p in plugins}
    wanted = [name for name in (available_plugins() if names is None else names) if name not in own]
    registry = default_registry(wanted)
    for named in plugins:
        if named.plugin.name in registry.plugins:  # the core's name: install() would skip it without a word
            raise PluginOptionError(named.spec, f"its plugin is named {named.plugin.name!r}, the name of a plugin "
                                                "the engine always installs; rename it")
        try:
            registry.install(named.plugin)
        except Exception as exc:  # noqa: BLE001 - the plugin's own code: report it in one line
            raise PluginOptionError(named.spec, f"its build(registry) raised {type(exc).__name__}: {exc}") from exc
    return registry


def scene_registry(scene: str | Path, plugins: Sequence[NamedPlugin]) -> Registry | None:
    """The registry ``App(scene, registry=...)`` runs with ``--plugin`` (None without one: App builds its own from
    the scene's plugins, as always).  Names of ``[scene] plugins`` that no package declares are left out here and
    reported by the scene's validation, with the file and the line, as App does."""
    if not plugins:
        return None
    from engine.config import ConfigError
    from engine.scene import read_scene

    try:
        names = read_scene(scene)[0].scene.plugins
    except (ConfigError, OSError):
        names = None  # App reads the scene again and reports every problem of it
    if names is not None:
        known = set(available_plugins())
        names = [name for name in names if name in known]
    return registry_with(plugins, names)


def _import(spec: str, module_name: str):
    cwd = os.getcwd()
    if cwd not in sys.path and "" not in sys.path:  # as `python -m` does: the game's folder is usually the cwd
        sys.path.insert(0, cwd)
    importlib.invalidate_caches()  # a module written since the last import (by a tool, a test) is found
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and (module_name == exc.name or module_name.startswith(exc.name + ".")):
            raise PluginOptionError(spec, f"no module named {exc.name!r} in the current directory ({cwd}) or on "
                                          "sys.path") from exc
        raise PluginOptionError(spec, f"importing {module_name!r} failed: {exc}") from exc
    except Exception as exc:  # noqa: BLE001 - a syntax error or an exception in the module's own code
        where = ""
        if isinstance(exc, SyntaxError) and exc.filename:
            where = f" ({exc.filename}:{exc.lineno})"
        raise PluginOptionError(spec, f"importing {module_name!r} raised {type(exc).__name__}: {exc}{where}") from exc


def _attribute(spec: str, module, attr: str):
    obj = module
    for part in attr.split("."):
        try:
            obj = getattr(obj, part)
        except AttributeError:
            raise PluginOptionError(spec, f"module {module.__name__!r} has no attribute {attr!r}") from None
    return obj


def _the_one_plugin(spec: str, module) -> tuple[str, Any]:
    """The one plugin object or class defined in ``module`` (an object wins over its own class)."""
    mine = module.__name__
    found = {}
    for name, obj in vars(module).items():
        defined_here = (obj.__module__ if isinstance(obj, type) else type(obj).__module__) == mine
        if defined_here and is_plugin(obj):
            found[name] = obj
    instances = [type(obj) for obj in found.values() if not isinstance(obj, type)]
    candidates = {name: obj for name, obj in found.items() if not (isinstance(obj, type) and obj in instances)}
    if len(candidates) == 1:
        return next(iter(candidates.items()))
    if not candidates:
        raise PluginOptionError(spec, f"module {mine!r} has no attribute {DEFAULT_ATTR!r} and defines no plugin (an "
                                      "object or class with a string 'name' and a 'build(registry)' method); name "
                                      f"one with --plugin {mine}:ATTR")
    names = ", ".join(sorted(candidates))
    raise PluginOptionError(spec, f"module {mine!r} defines several plugins ({names}); name one, e.g. --plugin "
                                  f"{mine}:{sorted(candidates)[0]}")


def _not_a_plugin(spec: str, module_name: str, attr: str, obj: Any) -> PluginOptionError:
    what = f"class {obj.__qualname__}" if isinstance(obj, type) else f"a {type(obj).__name__}"
    return PluginOptionError(spec, f"{module_name}:{attr} is {what}, not a plugin: a plugin has a string 'name' and "
                                   "a 'build(registry)' method (docs/extending.md)")
