"""The GrassField systems (no GL): placing fields on the terrain, and the commands scripts call.

Grass does not move, so there is no per-tick update: the random draws of figure 1 are made when the entity
is built (``components.grass_field.build_grass_field``); the placement system turns them into world
positions on the terrain once, at startup, and the level meshes of table 1 are derived with them.  All of it
is a cache of the state (``GrassFieldState.placed``, not hashed).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState
from engine.spatial import Transform
from engine.world import World
from systems.grass_field.geometry import LevelMesh, build_level_meshes, cell_primitives, plant_extent
from systems.grass_field.layout import PlacedField, place_field

__all__ = ["FieldData", "field_data", "place_system", "terrain_height_fn", "set_max_level", "set_debug_levels"]


@dataclass
class FieldData:
    """Everything derived from a field's config and random draws: placement, meshes, bounds, counts."""

    placed: PlacedField
    meshes: list[LevelMesh]  # levels 0..3
    cell_primitives: np.ndarray  # (C, 4) real primitives of each cell at each geometric level
    plant_reach: float  # horizontal reach of a plant from its base (largest scale included)
    plant_height: float  # height of the tallest plant (largest scale included)
    cell_radius: float  # horizontal radius bounding a cell's plants
    lod_points: np.ndarray  # (C, 3) the point of each cell whose distance enters eq. 1
    cell_variant: np.ndarray  # (C,) layout of each cell
    cell_turn: np.ndarray  # (C,) quarter turns of each cell
    cell_sphere: tuple[np.ndarray, np.ndarray]  # (C, 3) centres and (C,) radii of spheres bounding each cell
    plant_sphere: tuple[np.ndarray, float]  # offset (3,) from a plant's base and radius of a sphere bounding it
    bare: np.ndarray  # (C,) bool: cells overlapping a bare area (``bare_areas``), never drawn
    key: str = ""  # digest of everything above: equal keys draw the same (survives snapshot / restore copies)

    @property
    def cell_count(self) -> int:
        return self.placed.cell_count


def terrain_height_fn(world: World):
    """``height(x, z)`` of the first Terrain entity (world space), or None when the world has none."""
    try:
        from engine.builtin import Terrain
    except ImportError:  # pragma: no cover
        return None
    found = world.query(Terrain, Transform)
    if not found:
        found = [(e, (t, Transform())) for e, (t,) in world.query(Terrain)]
    if not found:
        return None
    terrain, transform = found[0][1]

    def height(x: np.ndarray, z: np.ndarray) -> np.ndarray:
        pts = np.column_stack([x, np.zeros_like(x), z])
        local = transform.to_local(pts)
        local[:, 1] = terrain.field.height_at(local[:, 0], local[:, 2])
        return transform.to_world(local)[:, 1]

    return height


def field_data(cfg: GrassFieldConfig, state: GrassFieldState, origin: np.ndarray, height=None) -> FieldData:
    """Place the field and build its level meshes (figure 1, table 1)."""
    placed = place_field(cfg, state, origin, height)
    meshes = build_level_meshes(cfg, state)
    reach, tallest = plant_extent(meshes)
    grow = 1.0 + cfg.scale_jitter
    reach, tallest = reach * grow, tallest * grow
    lowest = min(0.0, min(float(m.vertices[..., 1].min()) for m in meshes) * grow)
    half_diag = cfg.cell_size * np.sqrt(0.5)
    cell_radius = float(half_diag + reach)
    lod_points = placed.cell_centre + np.array([0.0, 0.5 * tallest, 0.0])
    bottom, top = placed.cell_ground[:, 0] + lowest, placed.cell_ground[:, 1] + tallest
    cell_sphere = (np.column_stack([placed.cell_centre[:, 0], 0.5 * (bottom + top), placed.cell_centre[:, 2]]),
                   np.hypot(cell_radius, 0.5 * (top - bottom)))
    plant_sphere = (np.array([0.0, 0.5 * (lowest + tallest), 0.0]), float(np.hypot(reach, 0.5 * (tallest - lowest))))
    key = _digest(cfg, state, placed)
    return FieldData(placed, meshes, cell_primitives(placed.plant_variant, cfg.plants_per_cell, meshes),
                     reach, tallest, cell_radius, lod_points, state.cell_variant.copy(),
                     state.cell_turn.copy(), cell_sphere, plant_sphere, bare_cells(cfg, placed), key)


def bare_cells(cfg: GrassFieldConfig, placed: PlacedField) -> np.ndarray:
    """(C,) bool: the cells whose square overlaps one of ``cfg.bare_areas`` (world x/z rectangles)."""
    bare = np.zeros(placed.cell_count, dtype=bool)
    half = 0.5 * cfg.cell_size
    x, z = placed.cell_centre[:, 0], placed.cell_centre[:, 2]
    for x0, z0, x1, z1 in cfg.bare_areas:  # a few rectangles; each test is over all cells at once
        bare |= (x + half > x0) & (x - half < x1) & (z + half > z0) & (z - half < z1)
    return bare


def _digest(cfg: GrassFieldConfig, state: GrassFieldState, placed: PlacedField) -> str:
    """SHA-256 of the config's canonical JSON, the random draws and the placed plants."""
    h = hashlib.sha256(json.dumps(cfg.model_dump(mode="json", warnings=False), sort_keys=True).encode())
    for arr in (state.variant_branch_count, state.variant_segments, state.variant_base_length, state.variant_tilt,
                state.variant_azimuth, state.layout_offset, state.layout_yaw, state.layout_variant,
                state.layout_scale, state.layout_tint, state.cell_variant, state.cell_turn, placed.plant_position):
        h.update(np.ascontiguousarray(arr).tobytes())
    return h.hexdigest()


def ensure_placed(world: World, transform: Transform, cfg: GrassFieldConfig, state: GrassFieldState) -> FieldData:
    """The field's derived data, computed on first use."""
    if state.placed is None:
        state.placed = field_data(cfg, state, transform.position, terrain_height_fn(world))
        state.revision += 1
    return state.placed


def place_system(world: World, dt: float) -> None:
    """Startup: put every GrassField on the terrain (when there is one) and build its level meshes."""
    for _, (transform, cfg, state) in world.query(Transform, GrassFieldConfig, GrassFieldState):
        ensure_placed(world, transform, cfg, state)


def set_max_level(world: World, entity: int, max_level: int = 5) -> None:
    """Command ``grass_field.set_max_level``: 3, 4 or 5 = the paper's method 1, 2 or 3."""
    if int(max_level) not in (3, 4, 5):
        raise ValueError(f"grass_field.set_max_level: max_level must be 3, 4 or 5, got {max_level!r}")
    world.get(entity, GrassFieldState).max_level = int(max_level)


def set_debug_levels(world: World, entity: int, enabled: bool = True) -> None:
    """Command ``grass_field.set_debug_levels``: colour every cell by its level."""
    world.get(entity, GrassFieldState).debug_levels = bool(enabled)
