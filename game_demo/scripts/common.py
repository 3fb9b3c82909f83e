"""Small shared helpers for the demo's scripts (lookups through the public world API)."""

from __future__ import annotations

from dataclasses import dataclass, field

from engine.builtin import Terrain

PATTERNS = "ABCDEFGH"


@dataclass
class GameState:
    """World state resource shared by the demo's scripts."""

    phase: str = "playing"  # playing, won, lost
    time_left: float = 0.0
    targets_total: int = 0
    targets_left: int = 0
    pattern: str = "A"
    top_view: str = "minimap"  # minimap or split
    paused: bool = False
    message: str = ""
    destroyed: list[int] = field(default_factory=list)


@dataclass
class Target:
    """Marks a target; ``hp`` falls as energy-wave impacts arrive."""

    hp: float
    max_hp: float


@dataclass(frozen=True)
class TargetDestroyed:
    entity: int
    position: tuple[float, float, float]


def game_state(ctx) -> GameState:
    state = ctx.try_resource(GameState)
    if state is None:
        state = GameState()
        ctx.insert_resource(state)
    return state


def find_named(ctx, name: str) -> int | None:
    return ctx.find(name)


def ground_height(ctx, x: float, z: float) -> float:
    """Terrain height under (x, z) in world space (0 without terrain)."""
    height = ctx.ground_height(x, z)
    return 0.0 if height is None else height


def terrain_extent(ctx, without_terrain: float) -> float:
    """Half the terrain's side length in metres (the playable area), or ``without_terrain``."""
    for _, (terrain,) in ctx.query(Terrain):
        return float(min(terrain.field.size)) / 2.0
    return without_terrain

