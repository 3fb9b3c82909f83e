"""The plugin registry: maps TOML names to component models, scripts, systems, render features.

The engine imports no effect module.  Effect plugins are found through the ``ecsfx.plugins`` entry
point group (declared in each distribution's ``pyproject.toml``) and loaded in name order; each one
is an object with a ``name`` and a ``build(registry)`` method.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from importlib import metadata
from typing import TYPE_CHECKING, Any, Protocol

from pydantic import BaseModel

from engine.config import suggest
from engine.schedule import Schedule, Stage, SystemFn

if TYPE_CHECKING:
    from engine.script import Script
    from engine.world import Entity, World

ENTRY_POINT_GROUP = "ecsfx.plugins"


class RegistryError(LookupError):
    """An unknown or duplicate name; the message lists what is available.

    For an unknown name, ``problem`` is the short statement ("unknown script 'spinn'") and ``suggestion``
    the nearest registered name, so config errors can report them in their own fields.
    """

    def __init__(self, message: str, problem: str | None = None, suggestion: str | None = None) -> None:
        super().__init__(message)
        self.problem = problem or message
        self.suggestion = suggestion


@dataclass
class BuildContext:
    """What a component factory may use while a scene is being spawned."""

    world: World
    entity: Entity
    entity_name: str
    file: str
    configs_root: Any  # pathlib.Path

    def rng(self, system: str):
        return self.world.random.stream(system, self.entity)


ComponentFactory = Callable[[Any, BuildContext], Any]


@dataclass
class ComponentSpec:
    """A component that TOML can name: its validated config model and how it becomes runtime state."""

    name: str
    model: type[BaseModel]
    build: ComponentFactory | None = None  # None: the validated model itself is the component
    preset_dir: str | None = None  # presets live in configs/effects/<preset_dir>/
    description: str = ""
    # Hot reload: keys whose change needs the component rebuilt (grid sizes, capacities).  None means
    # "unknown", so any change rebuilds; a tuple (even empty) lets other changes swap the config in place.
    structural: tuple[str, ...] | None = None
    live_update: Callable[[Any, Any, Any, int], None] | None = None  # (old cfg, new cfg, world, entity)

    def instantiate(self, config: BaseModel, ctx: BuildContext) -> list[Any]:
        if self.build is None:
            return [config]
        built = self.build(config, ctx)
        return list(built) if isinstance(built, (list, tuple)) else [built]


class Plugin(Protocol):
    name: str

    def build(self, registry: Registry) -> None: ...


@dataclass
class Registry:
    """Everything the loaded plugins registered."""

    components: dict[str, ComponentSpec] = field(default_factory=dict)
    scripts: dict[str, type[Script]] = field(default_factory=dict)
    schedule: Schedule = field(default_factory=Schedule)
    render_features: list[Callable[..., Any]] = field(default_factory=list)
    render_feature_names: list[str] = field(default_factory=list)
    commands: dict[str, Callable[..., Any]] = field(default_factory=dict)
    world_setup: list[Callable[[World], None]] = field(default_factory=list)
    scene_checks: list[Callable[..., Any]] = field(default_factory=list)
    plugins: list[str] = field(default_factory=list)

    # -- registration
    def add_component(self, name: str, model: type[BaseModel], build: ComponentFactory | None = None, *,
                      preset_dir: str | None = None, description: str = "",
                      structural: tuple[str, ...] | None = None,
                      live_update: Callable[[Any, Any, Any, int], None] | None = None) -> ComponentSpec:
        """Register a TOML-nameable component.

        ``build(cfg, ctx)`` turns the validated config into runtime components (return ``[cfg, state]`` so
        systems can read live parameters from ``cfg``).  For hot reload, ``structural`` names the keys whose
        change rebuilds the component (others swap the config in place, state kept) and ``live_update``
        is called after an in-place swap.
        """
        if name in self.components:
            raise RegistryError(f"component '{name}' is already registered")
        spec = ComponentSpec(name, model, build, preset_dir, description or (model.__doc__ or "").strip(),
                             tuple(structural) if structural is not None else None, live_update)
        self.components[name] = spec
        return spec

    def add_system(self, fn: SystemFn, stage: Stage | str, *, name: str | None = None,
                   before: Iterable[str] = (), after: Iterable[str] = ()) -> None:
        self.schedule.add(fn, stage, name=name, before=before, after=after)

    def add_script(self, cls: type[Script]) -> None:
        name = getattr(cls, "script_name", None)
        if not name:
            raise RegistryError(f"{cls.__qualname__} has no script name: decorate it with @script('name')")
        if name in self.scripts and self.scripts[name] is not cls:
            raise RegistryError(f"script '{name}' is already registered")
        self.scripts[name] = cls

    def add_scripts(self, classes: Sequence[type[Script]]) -> None:
        for cls in classes:
            self.add_script(cls)

    def add_command(self, name: str, fn: Callable[..., Any]) -> None:
        """Publish a command that scripts call by name: ``fn(world, entity, **kwargs)``."""
        if name in self.commands:
            raise RegistryError(f"command '{name}' is already registered")
        self.commands[name] = fn

    def add_render_feature(self, factory: Callable[..., Any], name: str | None = None) -> None:
        """``factory(renderer)`` returns an object with ``extract(world)`` and ``add_passes(graph, frame)``.
        ``name``: the feature's ``name`` (what a Camera's ``hide_features`` lists), for a factory that defers
        importing its class (and GL) until a renderer asks; a class's own ``name`` is used when omitted."""
        self.render_features.append(factory)
        name = name if name is not None else getattr(factory, "name", None)
        if name:
            self.render_feature_names.append(name)

    def add_scene_check(self, fn: Callable[..., Any]) -> None:
        """``fn(plan, text)`` looks across a validated scene (``engine.scene.ScenePlan`` and the scene file's
        text) and returns a list of ``engine.config.Problem`` *warnings*: things that are legal but probably not
        meant, such as a name that refers to no entity of the scene (a script may still spawn it).  They never
        stop a scene from loading; ``validate`` prints them and the app logs them (``App.warnings``)."""
        self.scene_checks.append(fn)

    def on_world(self, fn: Callable[[World], None]) -> None:
        """Run ``fn(world)`` when a world is created (to insert resources)."""
        self.world_setup.append(fn)

    # -- lookup
    def component(self, name: str) -> ComponentSpec:
        try:
            return self.components[name]
        except KeyError:
            raise _unknown("component", name, self.components) from None

    def script(self, name: str) -> type[Script]:
        try:
            return self.scripts[name]
        except KeyError:
            raise _unknown("script", name, self.scripts) from None

    def command(self, name: str) -> Callable[..., Any]:
        try:
            return self.commands[name]
        except KeyError:
            raise _unknown("command", name, self.commands) from None

    def preset_component(self, preset_dir: str) -> ComponentSpec | None:
        for spec in self.components.values():
            if spec.preset_dir == preset_dir:
                return spec
        return None

    def install(self, plugin: Plugin) -> None:
        if plugin.name in self.plugins:
            return
        plugin.build(self)
        self.plugins.append(plugin.name)

    def plugin_error(self, name: str) -> RegistryError | None:
        """Why a plugin a scene names (``[scene] plugins``) is missing from this registry; None when it is
        installed here.  A name no installed package declares is unknown (with the nearest name); a plugin that
        exists but was not installed here is named as such, since the scene's components and scripts from it
        would be unknown."""
        if name in self.plugins:
            return None
        available = available_plugins()
        if name not in available:
            return _unknown("plugin", name, set(available) | set(self.plugins))
        problem = f"plugin '{name}' is not installed in this registry"
        return RegistryError(f"{problem} (installed: {', '.join(self.plugins) or 'none'}); a registry given to App "
                             "must install every plugin the scene names (registry.install), or leave registry= out "
                             "and App builds it from [scene] plugins", problem)


def _unknown(kind: str, name: str, known: Iterable[str]) -> RegistryError:
    close = suggest(name, known)
    hint = f"; did you mean '{close}'?" if close else ""
    problem = f"unknown {kind} '{name}'"
    how = ""
    if kind in ("script", "command") and not close:  # likely one of the game's own, not registered yet
        how = (f"; a {kind} is registered by a plugin's build(registry) (registry.add_{kind}), and a plugin is "
               f"found through the '{ENTRY_POINT_GROUP}' entry points of an installed package, or given with "
               "registry.install(plugin) or the command line's --plugin MODULE (docs/extending.md)")
    return RegistryError(f"{problem}{hint} (registered: {', '.join(sorted(known)) or 'none'}){how}", problem, close)


def available_plugins() -> list[str]:
    """The names of the plugins that installed packages declare (``ecsfx.plugins`` entry points), sorted."""
    return sorted(ep.name for ep in metadata.entry_points(group=ENTRY_POINT_GROUP))


def discover_plugins(names: Iterable[str] | None = None) -> list[Plugin]:
    """Plugins from the ``ecsfx.plugins`` entry points, in name order (only ``names`` if given)."""
    eps = sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda ep: ep.name)
    available = {ep.name: ep for ep in eps}
    if names is None:
        wanted = list(available)
    else:
        wanted = list(names)
        for name in wanted:
            if name not in available:
                raise _unknown("plugin", name, available)
    return [available[n].load() for n in wanted]


def default_registry(plugins: Iterable[str] | None = None) -> Registry:
    """A registry with the engine's core plugin and the discovered (or named) plugins installed."""
    from engine.builtin import CorePlugin

    registry = Registry()
    registry.install(CorePlugin())
    for plugin in discover_plugins(plugins):
        registry.install(plugin)
    return registry
