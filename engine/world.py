"""The ECS world: entities, component storage, cached queries, resources, events and deferred commands.

A world is a plain object: nothing lives at module level, so two worlds coexist in one process.

Storage is one ``dict[entity, component]`` per component type (esper-style).  Queries are cached per
``(types, exclude)`` key and invalidated when a structural change touches one of their types; a
cached query yields ``(entity, (c1, c2, ...))`` in ascending entity id order.
"""

from __future__ import annotations

from bisect import bisect_left
from collections.abc import Callable, Iterator
from operator import itemgetter
from typing import Any, TypeVar

from engine.commands import Commands
from engine.events import Events
from engine.rng import RandomStreams

T = TypeVar("T")
Entity = int


class EntityError(KeyError):
    """Raised for an operation on an entity that does not exist or lacks a component."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0]) if self.args else ""


class World:
    """Entities, their components, resources, events and commands."""

    def __init__(self, seed: int = 0) -> None:
        self._next_id: Entity = 1
        self._entities: dict[Entity, dict[type, Any]] = {}
        self._stores: dict[type, dict[Entity, Any]] = {}
        self._query_cache: dict[tuple, list[tuple[Entity, tuple]]] = {}
        self._each_cache: dict[type, list[tuple[Entity, Any]]] = {}
        self._cache_by_type: dict[type, set[tuple]] = {}
        self._resources: dict[type, Any] = {}
        self._state_resources: set[type] = set()
        self.seed = int(seed)
        self.tick = 0
        self.random = RandomStreams(self.seed)
        self.events = Events()
        self.commands = Commands(self)
        self.despawn_hooks: list[Callable[[World, Entity], None]] = []

    # ------------------------------------------------------------------ entities
    def reserve(self) -> Entity:
        """Allocate a fresh entity id (ids are never reused within a world)."""
        entity = self._next_id
        self._next_id += 1
        return entity

    def spawn(self, *components: Any, entity: Entity | None = None) -> Entity:
        """Create an entity with ``components``; ``entity`` may be an id from :meth:`reserve`."""
        if entity is None:
            entity = self.reserve()
        elif entity in self._entities or entity >= self._next_id:
            raise EntityError(f"entity {entity} was not reserved or is already alive")
        self._entities[entity] = {}
        for component in components:
            self.add(entity, component)
        return entity

    def despawn(self, entity: Entity) -> None:
        """Remove an entity and all its components; despawn hooks run first."""
        self._require(entity)
        for hook in list(self.despawn_hooks):
            hook(self, entity)
        for ctype in list(self._entities[entity]):
            self._detach(entity, ctype)
        del self._entities[entity]

    def alive(self, entity: Entity) -> bool:
        return entity in self._entities

    @property
    def entities(self) -> list[Entity]:
        """Live entity ids in ascending order."""
        return sorted(self._entities)

    def __len__(self) -> int:
        return len(self._entities)

    # ---------------------------------------------------------------- components
    def add(self, entity: Entity, component: Any) -> None:
        """Attach ``component`` (replacing one of the same type)."""
        comps = self._require(entity)
        ctype = type(component)
        comps[ctype] = component
        self._stores.setdefault(ctype, {})[entity] = component
        self._refresh(entity, ctype)

    insert = add

    def remove(self, entity: Entity, ctype: type) -> Any:
        """Detach and return the component of type ``ctype``."""
        comps = self._require(entity)
        if ctype not in comps:
            raise EntityError(f"entity {entity} has no {ctype.__name__}")
        return self._detach(entity, ctype)

    def get(self, entity: Entity, ctype: type[T]) -> T:
        try:
            return self._stores[ctype][entity]
        except KeyError:
            self._require(entity)
            raise EntityError(f"entity {entity} has no {ctype.__name__}") from None

    def try_get(self, entity: Entity, ctype: type[T]) -> T | None:
        store = self._stores.get(ctype)
        return None if store is None else store.get(entity)

    def has(self, entity: Entity, *ctypes: type) -> bool:
        comps = self._entities.get(entity)
        return comps is not None and all(c in comps for c in ctypes)

    def components_of(self, entity: Entity) -> dict[type, Any]:
        """A copy of the entity's ``{type: component}`` mapping."""
        return dict(self._require(entity))

    # ------------------------------------------------------------------- queries
    def query(self, *ctypes: type, exclude: tuple[type, ...] = ()) -> list[tuple[Entity, tuple]]:
        """Entities having every type in ``ctypes`` and none in ``exclude``, ascending by id.

        Returns the cached list: iterate it, do not mutate it.  Structural changes made while
        iterating must go through :attr:`commands` (they invalidate the cache when applied).
        """
        key = (ctypes, exclude if type(exclude) is tuple else tuple(exclude))
        cached = self._query_cache.get(key)
        if cached is not None:
            return cached
        stores = [self._stores.get(c, {}) for c in ctypes]
        if not stores:
            matched = set(self._entities)
        else:
            smallest = min(stores, key=len)
            matched = set(smallest).intersection(*(s for s in stores if s is not smallest))
        for c in exclude:
            store = self._stores.get(c)
            if store:
                matched.difference_update(store)
        entities = sorted(matched)
        columns = [list(map(s.__getitem__, entities)) for s in stores]  # C-level gathers, no per-entity Python
        result = list(zip(entities, zip(*columns))) if columns else [(e, ()) for e in entities]
        self._query_cache[key] = result
        for c in (*ctypes, *exclude):
            self._cache_by_type.setdefault(c, set()).add(key)
        return result

    def each(self, ctype: type[T]) -> list[tuple[Entity, T]]:
        """``(entity, component)`` for every entity with ``ctype``, ascending by id (cached like :meth:`query`,
        without the one-element tuple: the cheapest way to walk a single component type)."""
        rows = self._each_cache.get(ctype)
        if rows is None:
            store = self._stores.get(ctype, {})
            rows = sorted(store.items(), key=_entity_of)
            self._each_cache[ctype] = rows
        return rows

    def query_one(self, *ctypes: type) -> tuple[Entity, tuple] | None:
        """The first (lowest id) match of :meth:`query`, or ``None``."""
        found = self.query(*ctypes)
        return found[0] if found else None

    def single(self, ctype: type[T]) -> T | None:
        """The component of the lowest-id entity that has ``ctype``, or ``None``."""
        found = self.query(ctype)
        return found[0][1][0] if found else None

    # ----------------------------------------------------------------- resources
    def insert_resource(self, resource: Any, *, state: bool = False) -> None:
        """Store one resource per type; ``state=True`` makes it part of hashes and snapshots."""
        rtype = type(resource)
        self._resources[rtype] = resource
        if state:
            self._state_resources.add(rtype)
        else:
            self._state_resources.discard(rtype)

    def resource(self, rtype: type[T]) -> T:
        try:
            return self._resources[rtype]
        except KeyError:
            raise EntityError(f"no resource of type {rtype.__name__} in this world") from None

    def try_resource(self, rtype: type[T]) -> T | None:
        return self._resources.get(rtype)

    def has_resource(self, rtype: type) -> bool:
        return rtype in self._resources

    def remove_resource(self, rtype: type) -> Any:
        self._state_resources.discard(rtype)
        return self._resources.pop(rtype)

    def state_resources(self) -> list[Any]:
        """Resources flagged as simulation state, in a stable (qualified type name) order."""
        types = sorted(self._state_resources, key=_qualname)
        return [self._resources[t] for t in types]

    # ------------------------------------------------------------------- helpers
    def _require(self, entity: Entity) -> dict[type, Any]:
        comps = self._entities.get(entity)
        if comps is None:
            raise EntityError(f"entity {entity} does not exist (despawned or never spawned)")
        return comps

    def _detach(self, entity: Entity, ctype: type) -> Any:
        component = self._entities[entity].pop(ctype)
        store = self._stores[ctype]
        del store[entity]
        self._refresh(entity, ctype)
        return component

    def _refresh(self, entity: Entity, ctype: type) -> None:
        """Keep every cached query that involves ``ctype`` exact after ``entity`` changed.

        Each cached list stays sorted by entity id: the entity's row is inserted, replaced or removed
        in place (a binary search, then one C-level list operation), so spawning and despawning do not
        force whole queries to be rebuilt.
        """
        comps = self._entities.get(entity, {})
        rows = self._each_cache.get(ctype)
        if rows is not None:
            i = bisect_left(rows, entity, key=_entity_of)
            present = i < len(rows) and rows[i][0] == entity
            if ctype in comps:
                if present:
                    rows[i] = (entity, comps[ctype])
                else:
                    rows.insert(i, (entity, comps[ctype]))
            elif present:
                del rows[i]
        keys = self._cache_by_type.get(ctype)
        if not keys:
            return
        for key in list(keys):
            rows = self._query_cache.get(key)
            if rows is None:
                keys.discard(key)
                continue
            ctypes, exclude = key
            i = bisect_left(rows, entity, key=_entity_of)
            present = i < len(rows) and rows[i][0] == entity
            matches = all(c in comps for c in ctypes) and not any(c in comps for c in exclude)
            if matches:
                row = (entity, tuple(comps[c] for c in ctypes))
                if present:
                    rows[i] = row
                else:
                    rows.insert(i, row)
            elif present:
                del rows[i]

    def iter_state(self) -> Iterator[tuple[Entity, list[Any]]]:
        """Entities ascending with their components sorted by qualified type name (for hashing)."""
        for entity in sorted(self._entities):
            comps = self._entities[entity]
            yield entity, [comps[t] for t in sorted(comps, key=_qualname)]


_entity_of = itemgetter(0)


def _qualname(t: type) -> str:
    return f"{t.__module__}.{t.__qualname__}"
