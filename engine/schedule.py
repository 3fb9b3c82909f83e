"""Stages, systems and their order.

Stages run in a fixed order.  Within a stage, systems are ordered by their ``before`` / ``after``
constraints (by name) with a topological sort whose ties are broken by registration order; a cycle
raises :class:`ScheduleError` naming the systems in it.

The game-logic stages (input, script, simulation, post-simulation) run once per fixed tick so that a
recorded input stream replays exactly; render-extract and render run once per displayed frame.  Between them,
frame-update runs once after each batch of ticks (:meth:`engine.app.App.step`, which a frame's ticks are): the
place for state derived from the simulation only to be drawn (a display grid, a mesh), which would otherwise be
re-derived on every tick of a frame and thrown away; nothing the ticks read may come from it.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from engine.world import World


class Stage(str, Enum):
    STARTUP = "startup"
    INPUT = "input"
    SCRIPT = "script"
    SIMULATION = "simulation"
    POST_SIMULATION = "post_simulation"
    FRAME_UPDATE = "frame_update"
    RENDER_EXTRACT = "render_extract"
    RENDER = "render"


STAGE_ORDER: tuple[Stage, ...] = tuple(Stage)
TICK_STAGES = (Stage.INPUT, Stage.SCRIPT, Stage.SIMULATION, Stage.POST_SIMULATION)
FRAME_STAGES = (Stage.RENDER_EXTRACT, Stage.RENDER)

SystemFn = Callable[["World", float], None]


class ScheduleError(Exception):
    """A scheduling problem (cycle, unknown constraint, duplicate name)."""


@dataclass
class System:
    name: str
    fn: SystemFn
    stage: Stage
    before: tuple[str, ...] = ()
    after: tuple[str, ...] = ()
    index: int = 0  # registration order


@dataclass
class Schedule:
    """Systems per stage, sorted lazily and re-sorted when a system is added."""

    systems: list[System] = field(default_factory=list)
    _sorted: dict[Stage, list[System]] | None = None

    def add(self, fn: SystemFn, stage: Stage | str, *, name: str | None = None,
            before: Iterable[str] = (), after: Iterable[str] = ()) -> System:
        stage = Stage(stage)
        name = name or getattr(fn, "__qualname__", repr(fn))
        if any(s.name == name for s in self.systems):
            raise ScheduleError(f"a system named '{name}' is already registered")
        system = System(name, fn, stage, tuple(before), tuple(after), len(self.systems))
        self.systems.append(system)
        self._sorted = None
        return system

    def stage(self, stage: Stage) -> list[System]:
        if self._sorted is None:
            self._sorted = {s: _sort_stage([x for x in self.systems if x.stage is s]) for s in STAGE_ORDER}
        return self._sorted[stage]

    def order(self) -> list[tuple[Stage, list[str]]]:
        """The exact run order, stage by stage."""
        return [(s, [x.name for x in self.stage(s)]) for s in STAGE_ORDER]

    def describe(self, fixed_dt: float) -> str:
        lines = []
        for stage, names in self.order():
            note = " (fixed step %.6g s, per tick)" % fixed_dt if stage in TICK_STAGES else ""
            if stage is Stage.STARTUP:
                note = " (once)"
            elif stage in FRAME_STAGES:
                note = " (per frame)"
            elif stage is Stage.FRAME_UPDATE:
                note = " (once after each batch of ticks)"
            lines.append(f"{stage.value}{note}:")
            lines.extend(f"  {i + 1}. {n}" for i, n in enumerate(names))
        return "\n".join(lines)


def _sort_stage(systems: list[System]) -> list[System]:
    by_name = {s.name: s for s in systems}
    edges: dict[str, set[str]] = {s.name: set() for s in systems}  # a -> b: a runs before b
    for s in systems:
        for other in s.before:
            if other in by_name:
                edges[s.name].add(other)
        for other in s.after:
            if other in by_name:
                edges[other].add(s.name)
    indegree = {n: 0 for n in edges}
    for targets in edges.values():
        for t in targets:
            indegree[t] += 1
    ready = [(by_name[n].index, n) for n, d in indegree.items() if d == 0]
    heapq.heapify(ready)
    result: list[System] = []
    while ready:
        _, name = heapq.heappop(ready)
        result.append(by_name[name])
        for t in sorted(edges[name], key=lambda n: by_name[n].index):
            indegree[t] -= 1
            if indegree[t] == 0:
                heapq.heappush(ready, (by_name[t].index, t))
    if len(result) != len(systems):
        remaining = {n for n, d in indegree.items() if d > 0}
        cycle = _find_cycle(edges, remaining)
        raise ScheduleError("system order has a cycle: " + " -> ".join(cycle))
    return result


def _find_cycle(edges: dict[str, set[str]], nodes: set[str]) -> list[str]:
    """Walk predecessors among the unsorted nodes (each has one) until a node repeats."""
    preds = {n: sorted(a for a in nodes if n in edges[a]) for n in nodes}
    path: list[str] = []
    seen: dict[str, int] = {}
    node = min(nodes)
    while node not in seen:
        seen[node] = len(path)
        path.append(node)
        node = preds[node][0]
    cycle = path[seen[node]:][::-1]
    return cycle + [cycle[0]]


class FixedClock:
    """A fixed-step accumulator decoupled from the frame rate, with a cap on catch-up steps."""

    def __init__(self, dt: float = 1.0 / 60.0, max_steps: int = 5) -> None:
        self.dt = float(dt)
        self.max_steps = int(max_steps)
        self.accumulator = 0.0
        self.dropped_time = 0.0

    def advance(self, real_dt: float) -> int:
        """Add ``real_dt`` seconds; return how many fixed steps to run now (at most ``max_steps``)."""
        self.accumulator += max(0.0, float(real_dt))
        steps = int(self.accumulator // self.dt)
        remainder = self.accumulator - steps * self.dt
        if remainder >= self.dt:  # floor division can land one short in floating point
            steps, remainder = steps + 1, remainder - self.dt
        if steps > self.max_steps:
            self.dropped_time += (steps - self.max_steps) * self.dt
            steps = self.max_steps
        self.accumulator = min(max(remainder, 0.0), self.dt * (1.0 - 1e-12))
        return steps

    @property
    def alpha(self) -> float:
        """How far the render frame sits between the last two ticks (for interpolation)."""
        return self.accumulator / self.dt
