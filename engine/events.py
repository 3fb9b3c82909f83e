"""Typed events, buffered per tick, read through cursors.

Events sent during tick *t* stay readable during ticks *t* and *t + 1* (a double buffer, as in
Bevy), so a reader that runs before the sender in the schedule still sees every event exactly once.
:meth:`Events.update` runs once per tick, at the end of the fixed step.
"""

from __future__ import annotations

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

    def send(self, event: Any) -> None:
        """Queue ``event`` on the channel of its type."""
        channel = self._channels.setdefault(type(event), _Channel())
        channel.events.append((self._seq, self._tick, event))
        self._seq += 1

    def reader(self, etype: type[E], *, from_start: bool = False) -> EventReader[E]:
        """A cursor over events of ``etype`` sent after now (or all buffered with ``from_start``)."""
        return EventReader(self, etype, 0 if from_start else self._seq)

    def update(self) -> None:
        """Advance one tick: drop events older than the previous tick."""
        self._tick += 1
        for channel in self._channels.values():
            channel.events = [item for item in channel.events if item[1] >= self._tick - 1]

    def pending(self, etype: type) -> list[Any]:
        """Every buffered event of ``etype`` (for inspection and tests)."""
        channel = self._channels.get(etype)
        return [] if channel is None else [ev for _, _, ev in channel.events]

    def _after(self, etype: type, cursor: int) -> list[tuple[int, int, Any]]:
        channel = self._channels.get(etype)
        if channel is None:
            return []
        return [item for item in channel.events if item[0] >= cursor]


class EventReader(Generic[E]):
    """Reads each event of one type once, in the order sent."""

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
