"""Placement (figure 1, "配置"): random plant shapes, cell layouts, and world positions on the terrain.

Pure numpy, no GL.  Angles in the xz plane are azimuths: ``dir(a) = (cos a, 0, sin a)``, and a rotation by
``φ`` maps ``(x, z)`` to ``(x cos φ - z sin φ, x sin φ + z cos φ)`` (azimuth ``a`` becomes ``a + φ``).  The
GLSL side (``shaders/common.glsl``) uses the same convention.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from components.grass_field import GrassFieldConfig, GrassFieldState

__all__ = ["PlacedField", "draw_field", "place_field", "rotate_xz", "cell_centres_local"]

HeightFn = Callable[[np.ndarray, np.ndarray], np.ndarray]


def rotate_xz(xz: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotate (..., 2) points (x, z) by azimuth ``angle`` (radians, float64): a → a + angle."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    x, z = xz[..., 0], xz[..., 1]
    return np.stack([x * c - z * s, x * s + z * c], axis=-1)


def draw_field(cfg: GrassFieldConfig, rng: np.random.Generator) -> GrassFieldState:
    """All random draws of figure 1 from one seeded stream, in a fixed order.

    Per plant variant: T_NUM, T_LONG, T_BASIS (± jitter), per branch T_GRADI (± jitter) and the branch's
    azimuth (spread over TE_ROTAT plus the small per-branch y rotation).  Per cell layout: each plant's
    position in the cell and y rotation (uniform), its variant, scale and tint.  Per cell: its layout and
    a quarter turn.
    """
    v = cfg.plant_variants
    b_max = cfg.branch_count + cfg.branch_count_jitter
    n_branch = np.clip(cfg.branch_count + rng.integers(-cfg.branch_count_jitter, cfg.branch_count_jitter + 1, v),
                       1, b_max)
    n_seg = np.clip(cfg.branch_segments
                    + rng.integers(-cfg.branch_segments_jitter, cfg.branch_segments_jitter + 1, v), 1, None)
    base = cfg.base_length * (1.0 + rng.uniform(-cfg.base_length_jitter, cfg.base_length_jitter, v))
    tilt_deg = cfg.branch_tilt_deg + rng.uniform(-cfg.branch_tilt_jitter_deg, cfg.branch_tilt_jitter_deg, (v, b_max))
    tilt = np.radians(np.clip(tilt_deg, 0.0, 89.0))
    start = rng.uniform(0.0, 2.0 * np.pi, v)
    twist = np.radians(rng.uniform(-cfg.branch_twist_deg, cfg.branch_twist_deg, (v, b_max)))
    b = np.arange(b_max)[None, :].astype(np.float64)
    n = n_branch[:, None].astype(np.float64)
    spread = np.radians(cfg.branch_spread_deg)
    if cfg.branch_spread_deg >= 360.0:
        fraction = b / n  # evenly all around
    else:
        fraction = np.where(n > 1, b / np.maximum(n - 1, 1) - 0.5, 0.0)
    azimuth = np.where(b < n, start[:, None] + spread * fraction + twist, 0.0)

    k, m = cfg.cell_variants, cfg.plants_per_cell
    half = 0.5 * cfg.cell_size
    offset = rng.uniform(-half, half, (k, m, 2))
    yaw = rng.uniform(0.0, 2.0 * np.pi, (k, m))
    variant = rng.integers(0, v, (k, m))
    scale = 1.0 + rng.uniform(-cfg.scale_jitter, cfg.scale_jitter, (k, m))
    tint = rng.uniform(-cfg.color_jitter, cfg.color_jitter, (k, m))
    cells = cfg.cell_count
    cell_variant = rng.integers(0, k, cells)
    cell_turn = rng.integers(0, 4, cells)
    return GrassFieldState(
        variant_branch_count=n_branch.astype(np.int64), variant_segments=n_seg.astype(np.int64),
        variant_base_length=base, variant_tilt=tilt, variant_azimuth=azimuth,
        layout_offset=offset, layout_yaw=yaw, layout_variant=variant.astype(np.int64), layout_scale=scale,
        layout_tint=tint, cell_variant=cell_variant.astype(np.int64), cell_turn=cell_turn.astype(np.int64),
        max_level=cfg.max_level, debug_levels=cfg.debug_levels)


def cell_centres_local(cfg: GrassFieldConfig) -> np.ndarray:
    """(C, 2) cell centres (x, z) relative to the field's centre; cell c = column c % grid_x, row c // grid_x."""
    col = np.arange(cfg.cell_count) % cfg.grid_x
    row = np.arange(cfg.cell_count) // cfg.grid_x
    x = (col + 0.5 - 0.5 * cfg.grid_x) * cfg.cell_size
    z = (row + 0.5 - 0.5 * cfg.grid_z) * cfg.cell_size
    return np.stack([x, z], axis=-1).astype(np.float64)


@dataclass
class PlacedField:
    """World-space placement of every cell and plant (plants of cell c are rows c*n .. c*n + n - 1)."""

    origin: np.ndarray  # (3,) field centre in world space
    cell_size: float
    grid_x: int
    grid_z: int
    plants_per_cell: int
    cell_centre: np.ndarray  # (C, 3): x, ground height at the centre, z
    cell_ground: np.ndarray  # (C, 2): lowest and highest plant base in the cell
    plant_position: np.ndarray  # (N, 3)
    plant_yaw: np.ndarray  # (N,)
    plant_variant: np.ndarray  # (N,) int
    plant_scale: np.ndarray  # (N,)
    plant_tint: np.ndarray  # (N,)

    @property
    def cell_count(self) -> int:
        return len(self.cell_centre)

    def cell_of(self, xz: np.ndarray) -> np.ndarray:
        """Index of the cell holding each (x, z) point (..., 2), clamped to the grid."""
        rel = (np.asarray(xz, dtype=np.float64) - self.origin[[0, 2]]) / self.cell_size
        col = np.clip(np.floor(rel[..., 0] + 0.5 * self.grid_x), 0, self.grid_x - 1).astype(np.int64)
        row = np.clip(np.floor(rel[..., 1] + 0.5 * self.grid_z), 0, self.grid_z - 1).astype(np.int64)
        return row * self.grid_x + col


def place_field(cfg: GrassFieldConfig, state: GrassFieldState, origin: np.ndarray,
                height: HeightFn | None = None) -> PlacedField:
    """World positions: cell layouts turned and moved to their cells, bases dropped onto ``height(x, z)``."""
    origin = np.asarray(origin, dtype=np.float64)
    centres_xz = cell_centres_local(cfg) + origin[[0, 2]]
    turn = state.cell_turn.astype(np.float64) * (0.5 * np.pi)
    offsets = state.layout_offset[state.cell_variant]  # (C, n, 2)
    plant_xz = centres_xz[:, None, :] + rotate_xz(offsets, turn[:, None])
    plant_xz = plant_xz.reshape(-1, 2)
    yaw = (state.layout_yaw[state.cell_variant] + turn[:, None]).reshape(-1)
    if height is None:
        plant_y = np.full(len(plant_xz), origin[1])
        centre_y = np.full(len(centres_xz), origin[1])
    else:
        plant_y = np.asarray(height(plant_xz[:, 0], plant_xz[:, 1]), dtype=np.float64)
        centre_y = np.asarray(height(centres_xz[:, 0], centres_xz[:, 1]), dtype=np.float64)
    per_cell_y = plant_y.reshape(cfg.cell_count, cfg.plants_per_cell)
    return PlacedField(
        origin=origin, cell_size=cfg.cell_size, grid_x=cfg.grid_x, grid_z=cfg.grid_z,
        plants_per_cell=cfg.plants_per_cell,
        cell_centre=np.column_stack([centres_xz[:, 0], centre_y, centres_xz[:, 1]]),
        cell_ground=np.column_stack([per_cell_y.min(axis=1), per_cell_y.max(axis=1)]),
        plant_position=np.column_stack([plant_xz[:, 0], plant_y, plant_xz[:, 1]]),
        plant_yaw=yaw, plant_variant=state.layout_variant[state.cell_variant].reshape(-1),
        plant_scale=state.layout_scale[state.cell_variant].reshape(-1),
        plant_tint=state.layout_tint[state.cell_variant].reshape(-1))
