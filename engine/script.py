"""The scripting API: game logic written in Python, attached to entities by registered name.

A script is a class derived from :class:`Script`, named with ``@script("name")`` and registered by a
plugin.  TOML attaches scripts by that name only, with parameters validated by the script's
``Params`` model: a config file can never name a Python module, class or callable.

Scripts run in the script stage of every fixed tick, entities in ascending id order, each entity's
scripts in the order attached.  An exception inside a script is logged with the entity, the script
and the traceback, and that script is disabled; the game goes on.  In strict mode (tests) it is
re-raised as :class:`ScriptError`.
"""

from __future__ import annotations

import logging
import traceback
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

from engine.config import ConfigModel
from engine.events import EventReader
from engine.input import InputState

if TYPE_CHECKING:
    from engine.registry import Registry
    from engine.world import Entity, World

log = logging.getLogger("engine.script")
S = TypeVar("S", bound=type)
T = TypeVar("T")


class NoParams(ConfigModel):
    """A script without parameters."""


def script(name: str):
    """Class decorator: give a :class:`Script` subclass its registered name."""

    def mark(cls: S) -> S:
        cls.script_name = name
        return cls

    return mark


class ScriptError(RuntimeError):
    """A script raised (re-raised in strict mode)."""


class ScriptContext:
    """What a script may touch: its entity, queries, commands, input, events, randomness, plugin commands."""

    def __init__(self, world: World, entity: Entity, script_name: str) -> None:
        self.world = world
        self.entity = entity
        self.script_name = script_name

    # components: this entity's, or another's (``entity``: an id from find, query or spawn)
    def get(self, ctype: type[T], entity: Entity | None = None) -> T:
        return self.world.get(self.entity if entity is None else entity, ctype)

    def try_get(self, ctype: type[T], entity: Entity | None = None) -> T | None:
        return self.world.try_get(self.entity if entity is None else entity, ctype)

    def alive(self, entity: Entity) -> bool:
        return self.world.alive(entity)

    def query(self, *ctypes: type, exclude: tuple[type, ...] = ()):
        return self.world.query(*ctypes, exclude=exclude)

    def find(self, name: str) -> Entity | None:
        """The lowest-id live entity the scene (or a prefab) named ``name``; None when there is none."""
        from engine.builtin import find_named

        return find_named(self.world, name)

    def ground_height(self, x: float, z: float) -> float | None:
        """World height of the scene's terrain under world (x, z); None without a terrain."""
        from engine.builtin import ground_height

        return ground_height(self.world, x, z)

    @property
    def commands(self):
        return self.world.commands

    def spawn(self, *components: Any) -> Entity:
        return self.world.commands.spawn(*components)

    def spawn_prefab(self, name: str, position=None, extra: tuple = ()) -> Entity:
        """Spawn ``configs/prefabs/<name>.toml`` (validated like a scene) at ``position``; deferred."""
        from engine.app import App
        from engine.prefab import PrefabLibrary

        return PrefabLibrary.of(self.world.resource(App)).spawn(self.world, name, position, extra)

    def despawn(self, entity: Entity | None = None) -> None:
        self.world.commands.despawn(self.entity if entity is None else entity)

    @property
    def input(self) -> InputState:
        return self.world.resource(InputState)

    def send(self, event: Any) -> None:
        self.world.events.send(event)

    def resource(self, rtype: type[T]) -> T:
        return self.world.resource(rtype)

    def try_resource(self, rtype: type[T]) -> T | None:
        return self.world.try_resource(rtype)

    def insert_resource(self, resource: Any, *, state: bool = True) -> None:
        """Share ``resource`` (one per type) with every script; as game state (``state=True``, the default) it is
        part of state hashes and snapshots, so a restart, a replay or a determinism test sees it."""
        self.world.insert_resource(resource, state=state)

    @property
    def rng(self):
        """This entity's own random stream for this script."""
        return self.world.random.stream(f"script:{self.script_name}", self.entity)

    @property
    def tick(self) -> int:
        return self.world.tick

    @property
    def paused(self) -> bool:
        """True while the game is paused (``engine.pause``): the simulation stages are skipped, scripts still run
        (menus, the pause key). A script that advances game time (a countdown, an animation, a spawner) should
        wait while this is set, as the simulation does."""
        from engine.app import is_paused

        return is_paused(self.world)

    @property
    def window_size(self) -> tuple[int, int]:
        """The window's (or the headless target's) size in pixels, as the renderer draws it; the scene's
        ``[render]`` size when nothing renders.  Mouse positions are pixels of it, origin bottom-left."""
        from engine.render.components import window_size  # no GL: the size only

        return window_size(self.world)

    def call(self, command: str, **kwargs: Any) -> Any:
        """Run a command a plugin published (for example ``"energy_wave.fire"``)."""
        registry = self.world.resource(ScriptRuntime).registry
        fn = registry.command(command)
        try:
            return fn(self.world, self.entity, **kwargs)
        except TypeError:
            import inspect

            signature = inspect.signature(fn)
            try:
                signature.bind(self.world, self.entity, **kwargs)
            except TypeError as exc:  # the call's arguments, not the command's own bug: say what it takes
                takes = ", ".join(str(p) for p in list(signature.parameters.values())[2:])
                raise TypeError(f"command '{command}': {exc}; it takes ({takes})") from None
            raise


class Script:
    """Base class of game scripts; override the hooks you need."""

    script_name: ClassVar[str] = ""
    Params: ClassVar[type[ConfigModel]] = NoParams
    events: ClassVar[tuple[type, ...]] = ()  # event types delivered to on_event

    def __init__(self, ctx: ScriptContext, params: ConfigModel) -> None:
        self.ctx = ctx
        self.params = params

    def on_start(self) -> None: ...

    def on_update(self, dt: float) -> None: ...

    def on_event(self, event: Any) -> None: ...

    def on_destroy(self) -> None: ...

    def __hash_state__(self) -> dict[str, Any]:
        return {k: v for k, v in vars(self).items() if k != "ctx"}


@dataclass
class ScriptSlot:
    name: str
    script: Script
    enabled: bool = True
    started: bool = False
    readers: list[EventReader] = field(default_factory=list)
    source: str = ""  # where the slot was declared ("scenes/x.toml: entities[2].scripts[0]"), for error messages

    def __hash_state__(self) -> tuple:
        return (self.name, self.enabled, self.started, self.script, [r.cursor for r in self.readers])


@dataclass
class Scripts:
    """The component holding an entity's script instances."""

    slots: list[ScriptSlot] = field(default_factory=list)


@dataclass
class ScriptFailure:
    """Event sent when a script raised and was disabled."""

    entity: int
    script: str
    hook: str
    error: str
    traceback: str


class ScriptRuntime:
    """World resource: the registry for commands, strict mode, and the failures so far."""

    def __init__(self, registry: Registry, strict: bool = False) -> None:
        self.registry = registry
        self.strict = strict
        self.failures: list[ScriptFailure] = []


def make_slot(world: World, entity: Entity, cls: type[Script], params: ConfigModel, source: str = "") -> ScriptSlot:
    """A script instance for ``entity``; ``source`` (file and key of its declaration) goes into its errors."""
    ctx = ScriptContext(world, entity, cls.script_name)
    instance = cls(ctx, params)
    readers = [world.events.reader(t) for t in cls.events]
    return ScriptSlot(cls.script_name, instance, readers=readers, source=source)


def entity_label(world: World, entity: Entity) -> str:
    """``entity 3 ('crate')``: the id, and the scene's name for it when it has one."""
    from engine.builtin import Name

    name = world.try_get(entity, Name)
    return f"entity {entity} ('{name.value}')" if name is not None and name.value else f"entity {entity}"


def _invoke(world: World, entity: Entity, slot: ScriptSlot, hook: str, *args: Any) -> None:
    try:
        getattr(slot.script, hook)(*args)
    except Exception as exc:  # a script must never take the game down
        runtime = world.resource(ScriptRuntime)
        slot.enabled = False
        tb = traceback.format_exc()
        failure = ScriptFailure(entity, slot.name, hook, f"{type(exc).__name__}: {exc}", tb)
        runtime.failures.append(failure)
        world.events.send(failure)
        where = f"script '{slot.name}' on {entity_label(world, entity)}"
        if slot.source:
            where = f"{slot.source}: {where}"
        if runtime.strict:
            raise ScriptError(f"{where} raised in {hook}: {exc}") from exc
        log.error("%s raised in %s and was disabled:\n%s", where, hook, tb)


def run_scripts(world: World, dt: float) -> None:
    """The script stage: start, deliver events, update; entities ascending, slots in order."""
    for entity, (scripts,) in list(world.query(Scripts)):
        for slot in scripts.slots:
            if slot.enabled and not slot.started:
                slot.started = True
                _invoke(world, entity, slot, "on_start")
            for reader in slot.readers:
                for event in reader.read():
                    if slot.enabled:
                        _invoke(world, entity, slot, "on_event", event)
            if slot.enabled:
                _invoke(world, entity, slot, "on_update", dt)


def destroy_scripts(world: World, entity: Entity) -> None:
    """Despawn hook: call ``on_destroy`` of the entity's started scripts."""
    scripts = world.try_get(entity, Scripts)
    if scripts is None:
        return
    for slot in scripts.slots:
        if slot.enabled and slot.started:
            _invoke(world, entity, slot, "on_destroy")
