"""State hashing and snapshots.

:func:`state_hash` feeds every entity's components (ascending ids, components by qualified type
name), the resources flagged as state, the random streams and the tick into BLAKE2b.  Floats are fed
as their IEEE bytes, arrays as dtype + shape + bytes, so equal digests mean bit-equal state.  Objects
opt out of fields (or pick them) with ``__hash_state__``; dataclass fields with
``metadata={"hash": False}`` are skipped (caches that are re-derived from state).
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
import struct
import threading
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import BaseModel

if TYPE_CHECKING:
    from engine.world import World


_ACTIVE = threading.local()  # ids of the plain objects on the hashing stack: a cycle is an error, not a RecursionError


def _feed(h: Any, obj: Any) -> None:
    if isinstance(obj, (np.bool_, np.integer, np.floating)):
        # a numpy scalar hashes as the Python number of the same value: a count kept as np.int64 by one code
        # path and as int by another is the same state (float32 widens exactly; longdouble stays itself)
        obj = obj.item()
    if obj is None or isinstance(obj, (bool, str)):
        h.update(f"{type(obj).__name__}:{obj!s}|".encode())
    elif isinstance(obj, Enum):
        h.update(f"enum:{type(obj).__qualname__}.{obj.name}|".encode())
    elif isinstance(obj, int):
        h.update(f"i:{obj}|".encode())
    elif isinstance(obj, float):
        h.update(b"f:" + struct.pack("<d", obj))
    elif isinstance(obj, np.ndarray):
        arr = np.ascontiguousarray(obj)
        h.update(f"nd:{arr.dtype.str}:{arr.shape}|".encode())
        h.update(arr.tobytes() if arr.dtype != object else repr(arr.tolist()).encode())
    elif isinstance(obj, np.generic):
        h.update(f"np:{obj.dtype.str}|".encode() + obj.tobytes())
    elif isinstance(obj, np.random.Generator):
        _feed(h, obj.bit_generator.state)
    elif hasattr(obj, "__hash_state__"):
        h.update(f"o:{type(obj).__qualname__}|".encode())
        try:
            _feed(h, obj.__hash_state__())
        except StateHashError as exc:
            exc.path.append(f" ({type(obj).__name__})")
            raise
    elif isinstance(obj, BaseModel):
        h.update(f"m:{type(obj).__qualname__}|".encode())
        _feed(h, {k: getattr(obj, k) for k in type(obj).model_fields})
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"d:{type(obj).__qualname__}|".encode())
        name = ""
        try:
            for f in dataclasses.fields(obj):
                if f.metadata.get("hash", True):
                    name = f.name
                    h.update(name.encode())
                    _feed(h, getattr(obj, name))
        except StateHashError as exc:
            exc.path.append(f".{name}")
            raise
    elif isinstance(obj, dict):
        h.update(f"{{{len(obj)}|".encode())
        key = None
        try:
            for key in sorted(obj, key=lambda k: (type(k).__name__, repr(k))):
                _feed(h, key)
                _feed(h, obj[key])
        except StateHashError as exc:
            exc.path.append(f".{key}" if isinstance(key, str) and key.isidentifier() else f"[{key!r}]")
            raise
    elif isinstance(obj, (list, tuple)):
        h.update(f"[{len(obj)}|".encode())
        i = 0
        try:
            for i, item in enumerate(obj):
                _feed(h, item)
        except StateHashError as exc:
            exc.path.append(f"[{i}]")
            raise
    elif isinstance(obj, (set, frozenset)):
        _feed(h, sorted(obj, key=lambda k: (type(k).__name__, repr(k))))
    elif hasattr(obj, "__dict__"):
        active = _ACTIVE.__dict__.setdefault("ids", set())  # plain objects being hashed, outermost first
        if id(obj) in active:  # e.g. a script keeping the world, whose resources hold the app, which holds the world
            raise StateHashError(f"{type(obj).__qualname__} (it contains itself)")
        active.add(id(obj))
        try:
            h.update(f"o:{type(obj).__qualname__}|".encode())
            _feed(h, vars(obj))
        finally:
            active.discard(id(obj))
    else:
        raise StateHashError(type(obj).__qualname__)


class StateHashError(TypeError):
    """Something in the simulation state cannot be hashed (a script keeping a generator, a module, the world);
    ``path`` leads to it, e.g. ``entity 3 ('player') Scripts.slots[0] (ScriptSlot)[3] (Player).world``."""

    def __init__(self, what: str) -> None:
        super().__init__(what)
        self.what = what
        self.path: list[str] = []  # innermost last, built while the error unwinds

    def __str__(self) -> str:
        where = "".join(reversed(self.path)).strip()
        return (f"cannot hash state of type {self.what} at {where or 'the top'}: keep objects that are not "
                "simulation state out of components, state resources and scripts (a script may leave attributes "
                "out with __hash_state__; a dataclass field with metadata={'hash': False})")


def digest(obj: Any) -> str:
    """Hex BLAKE2b digest of any hashable-state object."""
    h = hashlib.blake2b(digest_size=16)
    _feed(h, obj)
    return h.hexdigest()


def state_hash(world: World) -> str:
    """A stable digest of all simulation state of ``world``."""
    h = hashlib.blake2b(digest_size=16)
    _feed(h, world.tick)
    _feed(h, world.seed)
    _feed(h, world._next_id)  # the next entity id: it decides the ids, and so the order, of entities to come
    part = None
    try:
        for entity, comps in world.iter_state():
            _feed(h, entity)
            for part in comps:
                h.update(f"c:{type(part).__module__}.{type(part).__qualname__}|".encode())
                _feed(h, part)
        entity = None
        for part in world.state_resources():
            _feed(h, part)
    except StateHashError as exc:
        where = "resource" if entity is None else _entity_label(world, entity)
        exc.path.append(f"{where} {type(part).__name__}")
        raise
    _feed(h, world.random.states())
    return h.hexdigest()


def _entity_label(world: World, entity: int) -> str:
    from engine.script import entity_label

    return entity_label(world, entity)


_SNAPSHOT_FIELDS = ("_next_id", "_entities", "_stores", "_resources", "_state_resources", "tick", "random",
                    "events")


@dataclasses.dataclass
class Snapshot:
    """A deep copy of a world's state; restore it to continue bit-identically."""

    data: dict[str, Any]
    tick: int
    # the cursors of the event readers that the copy does not hold (non-state resources, closures), weakly
    reader_cursors: list[tuple[Any, int]] = dataclasses.field(default_factory=list)


def snapshot(world: World) -> Snapshot:
    """Copy all of ``world``'s state (resources that are not state are shared, not copied; the cursors of the
    event readers among them are kept, see :class:`engine.events.EventReader`)."""
    memo = _shared_memo(world)
    data = {name: copy.deepcopy(getattr(world, name), memo) for name in _SNAPSHOT_FIELDS}
    data["commands_queue"] = copy.deepcopy(world.commands._queue, memo)
    return Snapshot(data, world.tick, world.events.reader_cursors())


def restore(world: World, snap: Snapshot) -> None:
    """Put ``world`` back into the state of ``snap`` (the snapshot stays reusable).

    ``world.events`` stays the same object, its stream replaced by the snapshot's: readers kept outside the
    state (a non-state resource, a closure) keep reading the world's events, from their cursors at the
    snapshot; readers inside the state (script slots, state resources) come back as copies reading it too."""
    memo = _shared_memo(world)
    live = {t: r for t, r in world._resources.items() if t not in world._state_resources}
    stream = copy.deepcopy(snap.data["events"], memo)  # first: an event also held by the state stays one object
    memo[id(snap.data["events"])] = world.events  # copied readers refer to the live events, not to a copy
    data = copy.deepcopy(snap.data, memo)
    for name in _SNAPSHOT_FIELDS:
        if name != "events":
            setattr(world, name, data[name])
    world.events.load(stream, snap.reader_cursors)
    world._resources.update({t: r for t, r in live.items() if t not in world._state_resources})
    world.commands._queue = data["commands_queue"]
    world._query_cache.clear()
    world._cache_by_type.clear()
    world._each_cache.clear()


def _shared_memo(world: World) -> dict[int, Any]:
    """Objects kept by identity in a copy: the world itself and its non-state resources."""
    memo: dict[int, Any] = {id(world): world, id(world.commands): world.commands}
    for rtype, resource in world._resources.items():
        if rtype not in world._state_resources:
            memo[id(resource)] = resource
    return memo
