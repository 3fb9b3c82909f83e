"""Deferred structural changes, safe to issue while iterating a query.

Commands are applied in the order issued at the scheduler's sync points: after every system of the
startup, input, script and post-simulation stages, and after every system of each fixed simulation
step.  ``spawn`` reserves the entity id at once, so the caller can refer to the new entity in the
same tick (it becomes visible to queries at the next sync point).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from engine.world import Entity, World


class Commands:
    """A queue of spawn / despawn / insert / remove operations on one world."""

    def __init__(self, world: World) -> None:
        self._world = world
        self._queue: list[tuple[str, Any, Any]] = []

    def spawn(self, *components: Any) -> Entity:
        entity = self._world.reserve()
        self._queue.append(("spawn", entity, components))
        return entity

    def spawn_reserved(self, entity: Entity, components) -> None:
        """Queue the spawn of an id taken earlier with ``world.reserve()`` (prefabs build with it)."""
        self._queue.append(("spawn", entity, tuple(components)))

    def despawn(self, entity: Entity) -> None:
        self._queue.append(("despawn", entity, None))

    def insert(self, entity: Entity, component: Any) -> None:
        self._queue.append(("insert", entity, component))

    def remove(self, entity: Entity, ctype: type) -> None:
        self._queue.append(("remove", entity, ctype))

    def __len__(self) -> int:
        return len(self._queue)

    def pending(self) -> tuple[list[tuple[Entity, tuple]], set[Entity]]:
        """What the queue will do when applied: the spawns ``(entity, components)`` and the despawned ids."""
        spawns = [(entity, payload) for op, entity, payload in self._queue if op == "spawn"]
        return spawns, {entity for op, entity, _ in self._queue if op == "despawn"}

    def apply(self) -> int:
        """Apply queued commands in order; returns how many ran.

        Operations on an entity that is gone by then (despawned twice, or despawned before an insert)
        are skipped: the later command lost a race inside one tick, which is not an error.
        """
        world = self._world
        count = 0
        while self._queue:
            queue, self._queue = self._queue, []
            for op, entity, arg in queue:
                count += 1
                if op == "spawn":
                    world.spawn(*arg, entity=entity)
                elif not world.alive(entity):
                    continue
                elif op == "despawn":
                    world.despawn(entity)
                elif op == "insert":
                    world.add(entity, arg)
                elif op == "remove" and world.has(entity, arg):
                    world.remove(entity, arg)
        return count
