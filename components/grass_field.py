"""GrassField: clumped (cespitose) grass on a grid of cells drawn with several representations.

Paper: Hashizume, Yoshida, Kitajima, "A Study on Multi-Representation of Cespitose Plants for Real-Time
Display" (seeds/001).  The field is split into ``grid_x × grid_z`` square cells holding ``plants_per_cell``
plants each; every cell is drawn at one level chosen from its pseudo-pixel count (eq. 1):

    level 0..3  procedural geometry (cylinder / square prism / line / dotted line stems, table 1)
    level 4     one textured rectangle per cell, from 12 cached images (the LOD cache)
    level 5     far cells merged into a 12-sided band of images around the viewer's cell

This module holds the config a modder writes (:class:`GrassFieldConfig`) and the runtime state
(:class:`GrassFieldState`: the seeded random draws of figure 1, and caches derived from them).  No GL here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from pydantic import Field, field_validator, model_validator

from engine.config import Color3, ConfigModel, CrossFieldError, Vec4

__all__ = ["GrassFieldConfig", "GrassFieldState", "build_grass_field", "MAX_PLANTS"]

MAX_PLANTS = 1 << 20  # grid_x * grid_z * plants_per_cell: sizes the per-plant GPU texture
MAX_PLANT_DETAIL = 20_000  # the level-0 triangle estimate of one plant (the paper's: 1,280, the meadow's 2,080)
MAX_DOTS_PER_LINE = 2048  # level-3 dots along one stem or branch (sizes the level-3 mesh)


class GrassFieldConfig(ConfigModel):
    """A field of clumped grass with per-cell levels of detail and a cache of rendered cell images."""

    # -- placement (figure 1: "配置数", no randomness) -------------------------------------------------
    grid_x: int = Field(10, ge=1, le=256, description="Grid count along x (paper: grid 数 x).")
    grid_z: int = Field(10, ge=1, le=256, description="Grid count along z (paper: grid 数 y).")
    cell_size: float = Field(100.0, gt=0.0, le=10000.0,
                             description="Side of a square cell in world units (paper: 100 × 100).")
    plants_per_cell: int = Field(10, ge=1, le=256, description="Plants per cell (paper: plant 数, 10/20/40).")
    cell_variants: int = Field(8, ge=1, le=64,
                               description="Distinct plant layouts; each cell takes one with a random quarter "
                                           "turn (so neighbours differ) and the LOD cache bakes 12 views of each.")
    plant_variants: int = Field(8, ge=1, le=64,
                                description="Distinct plant shapes drawn with the jitter below; each plant "
                                            "also gets its own position, rotation, scale and tint.")
    scale_jitter: float = Field(0.15, ge=0.0, le=0.9, description="Per-plant uniform scale jitter (± fraction).")

    # -- plant shape, jittered (figure 1) -------------------------------------------------------------
    branch_count: int = Field(8, ge=1, le=32, description="T_NUM: branches (leaf-bearing culms) per plant.")
    branch_count_jitter: int = Field(2, ge=0, le=16, description="Random ± added to T_NUM per plant variant.")
    branch_segments: int = Field(7, ge=1, le=24,
                                 description="T_LONG: branch length in base lengths; the bend angle changes "
                                             "once per base length, giving the curve.")
    branch_segments_jitter: int = Field(1, ge=0, le=8, description="Random ± added to T_LONG per plant variant.")
    branch_tilt_deg: float = Field(20.0, ge=0.0, le=90.0,
                                   description="T_GRADI: initial tilt of a branch from the vertical, degrees.")
    branch_tilt_jitter_deg: float = Field(10.0, ge=0.0, le=90.0,
                                          description="Random ± added to T_GRADI per branch, degrees.")
    base_length: float = Field(3.0, gt=0.0, le=1000.0,
                               description="T_BASIS: base length; the stem is a chain of these (world units).")
    base_length_jitter: float = Field(0.15, ge=0.0, le=0.9, description="Random ± fraction of T_BASIS per variant.")
    branch_twist_deg: float = Field(12.0, ge=0.0, le=180.0,
                                    description="Small per-branch y rotation (± degrees) so branches look "
                                                "radial from above.")

    # -- plant shape, fixed -----------------------------------------------------------------------------
    stem_diameter: float = Field(0.5, gt=0.0, le=100.0, description="Stem diameter at the base (paper: 0.5).")
    stem_shortening: float = Field(0.1, ge=0.0, le=0.9,
                                   description="TK_SHORT: each stem segment is this fraction shorter than the "
                                               "one below.")
    stem_thinning: float = Field(0.12, ge=0.0, le=0.9,
                                 description="TK_VOLUM: each stem segment is this fraction thinner than the one "
                                             "below.")
    branch_length_ratio: float = Field(0.9, ge=0.1, le=10.0,
                                       description="TE_DIFFE: branch segment length / stem segment length.")
    branch_shortening: float = Field(0.08, ge=0.0, le=0.9,
                                     description="TE_SHORT: each branch segment is this fraction shorter than "
                                                 "the previous one (towards the tip).")
    branch_bend_deg: float = Field(9.0, ge=-45.0, le=45.0,
                                   description="TE_ANGLE: bend added to a branch's tilt per base length, degrees.")
    branch_spread_deg: float = Field(360.0, ge=0.0, le=360.0,
                                     description="TE_ROTAT: the largest rotation in the xz plane over which the "
                                                 "branches of a plant are spread, degrees.")
    branch_thinning: float = Field(0.15, ge=0.0, le=0.9,
                                   description="TE_VOLUM: branch thinning rate per segment (the first segment "
                                               "is also this fraction thinner than the stem).")
    leaf_width: float = Field(1.2, gt=0.0, le=100.0, description="TR_WIDTH: largest leaf width (world units).")
    leaf_narrowing: float = Field(0.12, ge=0.0, le=0.9,
                                  description="TR_SHORT: leaf narrowing rate per base length towards the tip.")
    leaf_root: float = Field(0.15, ge=0.0, le=0.95,
                             description="TR_ROOT: fraction of the branch length where the leaf blade starts "
                                         "(below it the branch is drawn like the stem).")

    # -- levels (tables 1 and 2, eq. 1) -----------------------------------------------------------------
    stem_sides: int = Field(8, ge=5, le=32, description="Sides of the level-0 cylinder (level 1 is a square prism).")
    stem_length_fractions: Vec4 = Field((1.0, 0.8, 0.6, 0.4),
                                        description="Table 1: stem length kept at levels 0-3 (100/80/60/40 %).")
    leaf_subdivisions: Vec4 = Field((4.0, 2.0, 1.0, 0.5),
                                    description="Table 1: leaf quads per base length at levels 0-3 (many → few).")
    dot_spacing_pixels: float = Field(2.0, ge=1.0, le=16.0,
                                      description="Level 3 dotted line: dot spacing in pixels at the 2→3 switch "
                                                  "(fakes the faintness of a 1-pixel line).")
    length_of_interest: float = Field(0.5, gt=0.0, le=100.0,
                                      description="L of eq. 1: the stem diameter or leaf width, in world units "
                                                  "(paper: 0.5, the stem diameter).")
    level_thresholds: Vec4 = Field((4.0, 1.5, 1.0, 0.75),
                                   description="Table 2: pseudo-pixel counts P at the switches 0⇄1, 1⇄2, 2⇄3, 3⇄4.")
    merge_distance: float = Field(800.0, gt=0.0, le=1.0e6,
                                  description="Level 5: cells past this distance (apothem of the 12-sided band "
                                              "around the viewer's cell) are merged into the band (paper: 800).")
    max_level: int = Field(5, ge=3, le=5,
                           description="Highest level used: 3 = paper's method 1 (geometry only), 4 = method 2 "
                                       "(+ cached rectangles), 5 = method 3 (+ merged band).")
    near_cull_cells: float = Field(1.5, ge=0.0, le=16.0,
                                   description="Culling: cells nearer than this many cell sizes are kept up to "
                                               "twice the view angle (the viewer's cell is never culled).")
    bare_areas: list[Vec4] = Field(default_factory=list, max_length=64,
                                   description="World-space rectangles [x_min, z_min, x_max, z_max] (metres) where "
                                               "no grass grows, e.g. a pond or a road: every cell that overlaps "
                                               "one is left empty at every level (geometry, cached images and the "
                                               "band). Not in the paper; its fields are uniform.")
    face_turn_deg: float = Field(15.0, ge=1.0, le=90.0,
                                 description="Level 4: a rectangle turns to face the viewer once the view angle "
                                             "changed by this much (paper: 15°).")
    image_switch_deg: float = Field(30.0, ge=1.0, le=180.0,
                                    description="Level 4: the image is swapped for the nearest of the 12 once the "
                                                "view angle differs from the image's by this much (paper: 30°).")
    blend_views: bool = Field(False, description="Level 4 option: cross-fade the two nearest of the 12 images "
                                                 "(off = the paper's swap rule).")
    impostor_elevation_deg: float = Field(5.0, ge=0.0, le=60.0,
                                          description="Elevation of the 12 cached views (the paper uses one "
                                                      "plane; about ±30° around it looks right).")
    impostor_resolution_scale: float = Field(1.0, ge=0.25, le=4.0,
                                             description="Texels per pixel of the cached images at the 3→4 "
                                                         "distance (1 = the paper's screen-size capture).")
    impostor_max_size: int = Field(512, ge=16, le=2048, description="Largest cached image side in texels.")
    band_resolution_scale: float = Field(1.0, ge=0.25, le=4.0,
                                         description="Level 5: band texels per screen pixel when baked.")
    band_cache_cells: int = Field(9, ge=1, le=64,
                                  description="Level 5: viewer cells whose 12 band images are kept (LRU); the "
                                              "neighbours of the viewer's cell are baked ahead.")
    disk_cache: bool = Field(False, description="Store the baked level-4 images on disk, keyed by a hash of "
                                                "this config, so a restart skips baking.")
    cache_dir: str = Field(".cache/grass_field", min_length=1, max_length=512,
                           description="Folder of the on-disk cache (relative to the working directory).")
    debug_levels: bool = Field(False, description="Debug view: colour every cell by its level.")

    # -- colours (linear RGB) ---------------------------------------------------------------------------
    stem_color: Color3 = Field((0.20, 0.30, 0.07), description="Stem colour.")
    leaf_base_color: Color3 = Field((0.07, 0.22, 0.03), description="Leaf colour at the blade's root.")
    leaf_tip_color: Color3 = Field((0.40, 0.50, 0.12), description="Leaf colour at the tip.")
    color_jitter: float = Field(0.12, ge=0.0, le=0.5, description="Per-plant brightness jitter (± fraction).")

    @field_validator("level_thresholds")
    @classmethod
    def _decreasing(cls, t: tuple[float, ...]) -> tuple[float, ...]:
        if not (t[0] > t[1] > t[2] > t[3] > 0.0):
            raise ValueError("expected positive, strictly decreasing pseudo-pixel counts (P at 0⇄1 > 1⇄2 > 2⇄3 "
                             "> 3⇄4)")
        return t

    @field_validator("stem_length_fractions")
    @classmethod
    def _fractions(cls, f: tuple[float, ...]) -> tuple[float, ...]:
        if not all(0.0 < x <= 1.0 for x in f):
            raise ValueError("expected four fractions in (0, 1]")
        return f

    @field_validator("leaf_subdivisions")
    @classmethod
    def _subdivisions(cls, s: tuple[float, ...]) -> tuple[float, ...]:
        if not all(0.1 <= x <= 8.0 for x in s):
            raise ValueError("expected four subdivision counts in [0.1, 8]")
        return s

    @field_validator("bare_areas")
    @classmethod
    def _bare_areas_ordered(cls, areas: list) -> list:
        for i, (x0, z0, x1, z1) in enumerate(areas):
            if not (x0 < x1 and z0 < z1):
                raise ValueError(f"bare_areas[{i}] = [{x0}, {z0}, {x1}, {z1}] must be [x_min, z_min, x_max, z_max] "
                                 "with x_min < x_max and z_min < z_max")
        return areas

    def scene_budgets(self, fixed_dt: float) -> list[tuple[str, float, float]]:
        """(what, cost, limit) that every entity of a scene shares (engine.scene: the sum of each is capped)."""
        return [("plants (grid_x * grid_z * plants_per_cell)", self._plants(), MAX_PLANTS)]

    def _plants(self) -> int:
        return self.grid_x * self.grid_z * self.plants_per_cell

    @model_validator(mode="after")
    def _plant_budget(self) -> GrassFieldConfig:
        plants = self._plants()
        if plants > MAX_PLANTS:
            raise CrossFieldError(("plants_per_cell", "grid_x", "grid_z"),
                                 f"grid_x * grid_z * plants_per_cell = {plants} plants exceeds {MAX_PLANTS}; "
                             "lower grid_x, grid_z or plants_per_cell")
        return self

    def level0_triangles(self) -> int:
        """The most triangles one level-0 plant may have, about (estimate used by the limits and warnings)."""
        branches = self.branch_count + self.branch_count_jitter
        segments = self.branch_segments + self.branch_segments_jitter
        return branches * segments * (self.stem_sides + 2 * math.ceil(self.leaf_subdivisions[0]))

    @model_validator(mode="after")
    def _plant_detail(self) -> GrassFieldConfig:
        """A level-0 plant has about (branches) · (segments) · (stem_sides + 2 · leaf subdivisions) triangles (the
        paper's plant: about 1,000). Every shape bound at its maximum made 70,000 a plant, drawn for each near
        plant every frame."""
        estimate = self.level0_triangles()
        if estimate > MAX_PLANT_DETAIL:
            raise CrossFieldError(("branch_count", "branch_count_jitter", "branch_segments", "branch_segments_jitter",
                                  "stem_sides", "leaf_subdivisions"),
                                 f"(branch_count + jitter) * (branch_segments + jitter) * (stem_sides + 2 * "
                             f"leaf_subdivisions[0]) = {estimate} exceeds {MAX_PLANT_DETAIL} (about the triangles "
                             "of one level-0 plant); lower branch_count, branch_segments, stem_sides or "
                             "leaf_subdivisions")
        return self

    @model_validator(mode="after")
    def _dot_budget(self) -> GrassFieldConfig:
        """Level 3 draws one dot every dot_spacing_pixels · L / P₂₃ along the stem (table 1): a tiny L or a huge
        P₂₃ would ask for millions of dots per stem, so the count per polyline is capped."""
        spacing = self.dot_spacing_pixels * self.length_of_interest / self.level_thresholds[2]
        segments = self.branch_segments + self.branch_segments_jitter
        longest = self.base_length * (1.0 + self.base_length_jitter) * segments * max(1.0, self.branch_length_ratio)
        if longest / spacing > MAX_DOTS_PER_LINE:
            raise CrossFieldError(("dot_spacing_pixels", "length_of_interest", "level_thresholds", "base_length",
                                  "base_length_jitter", "branch_segments", "branch_segments_jitter",
                                  "branch_length_ratio"),
                                 f"level-3 dots every dot_spacing_pixels · length_of_interest / level_thresholds[2] = "
                             f"{spacing:.3g} world units along stems up to {longest:.3g} long make "
                             f"{longest / spacing:.0f} dots per stem, more than {MAX_DOTS_PER_LINE}; raise "
                             "length_of_interest or dot_spacing_pixels, or lower level_thresholds[2], or make the "
                             "stems shorter (base_length, base_length_jitter, branch_segments, "
                             "branch_segments_jitter, branch_length_ratio)")
        return self

    @property
    def cell_count(self) -> int:
        return self.grid_x * self.grid_z


@dataclass
class GrassFieldState:
    """Runtime state of one field: the random draws (hashed) and caches derived from them (not hashed).

    Cell ``c`` is column ``c % grid_x`` (x) and row ``c // grid_x`` (z); its plants are the plants of layout
    ``cell_variant[c]`` turned by ``cell_turn[c]`` quarter turns, stored contiguously in the plant arrays.
    """

    # figure 1, per plant variant: the jittered shape parameters
    variant_branch_count: np.ndarray  # (V,) int
    variant_segments: np.ndarray  # (V,) int
    variant_base_length: np.ndarray  # (V,) float64
    variant_tilt: np.ndarray  # (V, B_max) float64, radians
    variant_azimuth: np.ndarray  # (V, B_max) float64, radians
    # figure 1, per plant of each cell layout: position in the cell, rotation, shape, scale, tint
    layout_offset: np.ndarray  # (K, n, 2) float64, (x, z) within [-size/2, size/2]
    layout_yaw: np.ndarray  # (K, n) float64, radians
    layout_variant: np.ndarray  # (K, n) int
    layout_scale: np.ndarray  # (K, n) float64
    layout_tint: np.ndarray  # (K, n) float64
    # per cell: which layout and how many quarter turns
    cell_variant: np.ndarray  # (C,) int
    cell_turn: np.ndarray  # (C,) int in 0..3
    # runtime switches (commands may change them)
    max_level: int = 5
    debug_levels: bool = False
    # derived by the placement system (world positions on the terrain): not state
    placed: Any = field(default=None, metadata={"hash": False})
    revision: int = field(default=0, metadata={"hash": False})


def build_grass_field(cfg: GrassFieldConfig, ctx) -> list:
    """Component factory: draw the random parameters of figure 1 from the entity's seeded stream."""
    from systems.grass_field.layout import draw_field

    rng = ctx.rng("grass_field")
    return [cfg, draw_field(cfg, rng)]
