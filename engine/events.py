"""Typed events, buffered per tick, read through cursors.

Events sent during tick *t* stay readable during ticks *t* and *t + 1* (a double buffer, as in
Bevy), so a reader that runs before the sender in the schedule still sees every event exactly once.
:meth:`Events.update` runs once per tick, at the end of the fixed step.

A world keeps one :class:`Events` object for its whole life: :func:`engine.state.restore` loads the snapshot's
stream into it in place, so a reader made once (kept in a resource or a closure) reads the restored stream.
"""

from __future__ import annotations

import copy
import weakref
from typing import Any, Generic, TypeVar

E = TypeVar("E")


class _Channel:
    __slots__ = ("events", "first_seq")

    def __init__(self) -> None:
        self.events: list[tuple[int, int, Any]] = []  # (sequence, tick sent, event)
        self.first_seq = 0


class Events:
    """All event channels of a world, one per event type."""

    def __init__(self) -> None:
        self._channels: dict[type, _Channel] = {}
        self._seq = 0
        self._tick = 0
        # every reader handed out by reader(), so that restore() can put their cursors back; weak: a reader
        # dropped by its owner goes away (only cursors are set from it, so its order decides nothing)
        self._readers: weakref.WeakSet[EventReader] = weakref.WeakSet()

    def send(self, event: Any) -> None:
        """Queue ``event`` on the channel of its type."""
        channel = self._channels.setdefault(type(event), _Channel())
        channel.events.append((self._seq, self._tick, event))
        self._seq += 1

    def reader(self, etype: type[E], *, from_start: bool = False) -> EventReader[E]:
        """A cursor over events of ``etype`` sent after now (or all buffered with ``from_start``).  Make it once
        and keep it (see :class:`EventReader` for where)."""
        reader = EventReader(self, etype, 0 if from_start else self._seq)
        self._readers.add(reader)
        return reader

    def update(self) -> None:
        """Advance one tick: drop events older than the previous tick."""
        self._tick += 1
        for channel in self._channels.values():
            channel.events = [item for item in channel.events if item[1] >= self._tick - 1]

    def pending(self, etype: type) -> list[Any]:
        """Every buffered event of ``etype`` (for inspection and tests)."""
        channel = self._channels.get(etype)
        return [] if channel is None else [ev for _, _, ev in channel.events]

    # ------------------------------------------------------------------ snapshots (engine/state.py)
    def __deepcopy__(self, memo: dict[int, Any]) -> Events:
        """The buffered stream (channels, sequence, tick); the copy has handed out no readers yet (readers copied
        with the state refer to it through ``memo``)."""
        copied = Events.__new__(Events)
        memo[id(self)] = copied
        copied._channels = copy.deepcopy(self._channels, memo)
        copied._seq, copied._tick = self._seq, self._tick
        copied._readers = weakref.WeakSet()
        return copied

    def reader_cursors(self) -> list[tuple[weakref.ref, int]]:
        """Where each live reader made by :meth:`reader` stands (weakly held): what a snapshot keeps for the
        readers it does not copy, those in non-state resources and closures."""
        return [(weakref.ref(reader), reader.cursor) for reader in self._readers]

    def load(self, stream: Events, cursors: list[tuple[weakref.ref, int]]) -> None:
        """Restore in place: take ``stream``'s buffered events, sequence and tick, keeping this object (and so
        every reader of it) the world's.  Each reader in ``cursors`` still alive goes back to its cursor; a reader
        made after those were taken (after the snapshot) reads from the restored stream's present on, as if made
        at the snapshot."""
        self._channels, self._seq, self._tick = stream._channels, stream._seq, stream._tick
        for reader in self._readers:
            reader.cursor = min(reader.cursor, self._seq)
        for ref, cursor in cursors:
            reader = ref()
            if reader is not None and reader._events is self:
                reader.cursor = cursor

    def _after(self, etype: type, cursor: int) -> list[tuple[int, int, Any]]:
        channel = self._channels.get(etype)
        if channel is None:
            return []
        return [item for item in channel.events if item[0] >= cursor]


class EventReader(Generic[E]):
    """Reads each event of one type once, in the order sent.

    Make a reader once and keep it; reading it every tick delivers each event exactly once::

        @dataclass
        class DamageReader:                      # a resource of the world
            reader: EventReader[Damage]

        def apply_damage(world, dt):
            found = world.try_resource(DamageReader)
            if found is None:                    # the first tick: start reading from now on
                found = DamageReader(world.events.reader(Damage))
                world.insert_resource(found, state=True)
            for event in found.reader.read():
                ...

    Where to keep it:

    * a *state* resource (``insert_resource(..., state=True)``, as above) or a component: the reader is game
      state. Its cursor and event type name are in the state hash (:meth:`__hash_state__`), a snapshot copies
      it and ``App.restore`` puts that copy back, reading the restored world's events.
    * a resource that is not state, or a closure over one world: the reader is shared by snapshots, not
      copied, and still reads that world's events after ``App.restore`` (the world's :class:`Events` is
      restored in place) from the cursor it had when the snapshot was taken, so a run with a snapshot and
      restore reads the same events as one without.  A reader made after the snapshot reads from the
      restored present on.
    * not a module global or a closure shared by several worlds (``App.restart`` builds a new world with new
      events): a reader belongs to the world whose ``world.events`` made it.

    A script's ``events`` attribute does all this for it (``on_event``).
    """

    def __init__(self, events: Events, etype: type[E], cursor: int) -> None:
        self._events = events
        self.etype = etype
        self.cursor = cursor

    def read(self) -> list[E]:
        items = self._events._after(self.etype, self.cursor)
        if items:
            self.cursor = items[-1][0] + 1
        return [ev for _, _, ev in items]

    def __iter__(self):
        return iter(self.read())

    def __hash_state__(self) -> tuple[str, int]:
        """The reader's state: the event type's qualified name and the cursor (not the stream it reads: the
        events are the world's, and the type object itself cannot be hashed)."""
        return f"{self.etype.__module__}.{self.etype.__qualname__}", self.cursor

    def __repr__(self) -> str:
        return f"EventReader({self.etype.__qualname__}, cursor={self.cursor})"
