"""One frame of a field for one camera, decided on the CPU (no GL): culling, levels, the plants to draw at
levels 0-3, level-4 orientations, the level-5 band and the primitive counts of table 4.  The renderer only
uploads and draws this plan.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.exact import asin, atan2
from components.grass_field import GrassFieldConfig
from systems.grass_field import kernels
from systems.grass_field.culling import cull_cells, frustum_planes, visible_plants
from systems.grass_field.lod import (_BAND_NORMALS, N_BAND_SIDES, CameraInput, ImpostorOrientation,
                                     _horizontal_half_angle, band_distance, nearest_views, select_levels,
                                     visible_band_sides, wrap_angle)
from systems.grass_field.simulate import FieldData

__all__ = ["FramePlan", "plan_frame", "cell_levels", "band_sector_content", "band_apothem"]

NEAR_SORTED_LEVELS = 3


@dataclass
class FramePlan:
    """What to draw this frame."""

    levels: np.ndarray  # (C,) level per cell, CULLED (-1) when culled
    cells: list[np.ndarray]  # cells at geometric levels 0..3, each list nearest first
    plants: list[np.ndarray]  # per geometric level: the plants of those cells the frustum can see, in draw order
    impostor_cells: np.ndarray  # (n4,) cells at level 4, nearest first
    impostor_face: np.ndarray  # (n4,) azimuth each rectangle faces
    impostor_views: np.ndarray  # (n4, 2) cached view indices (second used when blending)
    impostor_blend: np.ndarray  # (n4,) weight of the second view (0 with the paper's swap rule)
    viewer_cell: int
    band_cell: int | None  # the cell whose band images are shown (None: no band this frame)
    band_sides: np.ndarray = field(default_factory=lambda: np.zeros(N_BAND_SIDES, dtype=bool))
    primitives: dict[int, int] = field(default_factory=dict)  # per level, real primitives
    plant_list: np.ndarray | None = None  # int32: ``plants`` one after the other (what the renderer uploads)
    band_apothem: float = 0.0  # the band's distance from the viewer's cell in this view (band_apothem)

    @property
    def total_primitives(self) -> int:
        return int(sum(self.primitives.values()))

    def level_counts(self) -> np.ndarray:
        """Cells per level: index 0 = culled, 1..6 = levels 0..5."""
        return np.bincount(self.levels + 1, minlength=7)


def band_apothem(cfg: GrassFieldConfig, data: FieldData, camera: CameraInput) -> float:
    """The band's apothem in this view.  Level 5 replaces only cells that eq. 1 already puts at level 4 (section
    6: the merged images stand beyond the 3→4 distance), and that distance, D₃₄ = W·L / (2·tan θ·P₃₄), grows with
    the view's width W.  The band lies at ``merge_distance`` unless D₃₄ plus the band's slack (the eye anywhere in
    the viewer's cell and a cell's eq.-1 point anywhere in its cell: two cell radii) reaches past it; then it
    lies there, rounded up to whole cells so that resizing a window re-bakes the band only when it moves a cell.
    Without this, a wide window put cells that eq. 1 wants as geometry into the band's blurry images."""
    if camera.ortho_pixels_per_unit is not None:
        return float(cfg.merge_distance)
    d34 = camera.width * cfg.length_of_interest / (2.0 * camera.tan_half_fov * min(cfg.level_thresholds))
    need = d34 + 2.0 * float(data.cell_radius)
    if need <= cfg.merge_distance:
        return float(cfg.merge_distance)
    return float(np.ceil(need / cfg.cell_size) * cfg.cell_size)


def band_sector_content(data: FieldData, centre_cell: int, apothem: float) -> np.ndarray:
    """(12,) bool: which band sides have far cells behind them (empty sides are not drawn)."""
    centres = data.placed.cell_centre[:, [0, 2]]
    origin = centres[centre_cell]
    far = (band_distance(centres, origin) >= apothem) & ~data.bare
    if not far.any():
        return np.zeros(N_BAND_SIDES, dtype=bool)
    rel = centres[far] - origin
    dist = np.linalg.norm(rel, axis=1)
    az = atan2(rel[:, 1], rel[:, 0])
    margin = np.pi / N_BAND_SIDES + asin(np.clip(data.cell_radius / dist, 0.0, 1.0))
    sides = np.arange(N_BAND_SIDES) * (2.0 * np.pi / N_BAND_SIDES)
    return (np.abs(wrap_angle(az[None, :] - sides[:, None])) <= margin[None, :]).any(axis=1)


def _near_first(levels: np.ndarray, centres: np.ndarray, eye: np.ndarray) -> list[np.ndarray]:
    """The cells at each geometric level 0-3, nearest first (early depth rejection of what is behind them)."""
    geometric = np.flatnonzero((levels >= 0) & (levels <= 3))
    rel = centres[geometric] - eye
    order = np.lexsort((np.einsum("ij,ij->i", rel, rel), levels[geometric]))  # by level, then by distance
    ordered = geometric[order]
    bounds = np.searchsorted(levels[ordered], np.arange(5))
    return [ordered[bounds[k]:bounds[k + 1]] for k in range(4)]


def _plants_to_draw(data: FieldData, cells: list[np.ndarray], camera: CameraInput) -> list[np.ndarray]:
    """Per geometric level, the plants of its cells that the view frustum can see (see
    :func:`~systems.grass_field.culling.visible_plants`), in the cells' order; at the near levels (the
    largest plants on screen) nearest plant first."""
    placed = data.placed
    everything = np.concatenate(cells)
    plants, counts = visible_plants(everything, placed.plants_per_cell, placed.plant_position, data.cell_sphere,
                                    data.plant_sphere, frustum_planes(camera))
    plant_ends = np.concatenate([[0], np.cumsum(counts)])[np.cumsum([len(c) for c in cells])]
    out = np.split(plants, plant_ends[:-1])
    for k in range(NEAR_SORTED_LEVELS):
        if len(out[k]) > 1:
            rel = placed.plant_position[out[k]] - camera.position
            out[k] = out[k][np.argsort(np.einsum("ij,ij->i", rel, rel), kind="stable")]
    return out


def plan_frame(cfg: GrassFieldConfig, data: FieldData, camera: CameraInput, orientation: ImpostorOrientation,
               *, max_level: int | None = None, band_content=None, compiled: bool = True) -> FramePlan:
    """Cull cells, pick their levels (eq. 1, table 2, level 5 past the band) and update level-4 rectangles.

    ``band_content(cell) -> (12,) bool`` may supply cached per-side content flags (see
    :func:`band_sector_content`); ``max_level`` overrides ``cfg.max_level`` (commands change it at run time).
    Orthographic views (a top-view minimap) use geometry only: the 12 cached views are side views.
    Perspective views are planned by the compiled kernels of :mod:`~systems.grass_field.kernels` (the same
    results); ``compiled=False`` plans with the numpy functions they are tested against.
    """
    placed = data.placed
    max_level = cfg.max_level if max_level is None else int(max_level)
    if camera.ortho_pixels_per_unit is not None:
        max_level = 3  # cached side views and the band are meaningless seen from above (a minimap)
    viewer = int(placed.cell_of(camera.position[[0, 2]]))
    fwd = camera.forward[[0, 2]]
    if compiled and camera.ortho_pixels_per_unit is None and fwd @ fwd >= 1e-12:
        return _plan_compiled(cfg, data, camera, orientation, max_level, band_content, viewer)
    apothem = band_apothem(cfg, data, camera)
    keep = cull_cells(placed.cell_centre, camera, cell_radius=data.cell_radius,
                      near_distance=cfg.near_cull_cells * cfg.cell_size, viewer_cell=viewer) & ~data.bare
    levels = select_levels(data.lod_points, camera, length=cfg.length_of_interest,
                           thresholds=cfg.level_thresholds, max_level=max_level,
                           merge_distance=apothem, viewer_cell_centre=placed.cell_centre[viewer],
                           keep=keep)
    cells = _near_first(levels, placed.cell_centre, camera.position)
    plants = _plants_to_draw(data, cells, camera)
    variant = placed.plant_variant
    prims = {k: int(data.meshes[k].real_primitives[variant[plants[k]]].sum()) for k in range(4)}

    active = levels == 4
    rel = placed.cell_centre[:, [0, 2]] - camera.position[[0, 2]]
    to_eye = atan2(-rel[:, 1], -rel[:, 0])
    if camera.ortho_pixels_per_unit is not None:
        to_eye = np.full(len(rel), atan2(-camera.forward[2], -camera.forward[0]))
    orientation.update(to_eye, active, np.radians(cfg.face_turn_deg), np.radians(cfg.image_switch_deg))
    impostors = np.flatnonzero(active)
    rel_eye = placed.cell_centre[impostors] - camera.position
    impostors = impostors[np.argsort(np.einsum("ij,ij->i", rel_eye, rel_eye), kind="stable")]  # nearest first
    if cfg.blend_views:
        a, b, w = nearest_views(to_eye[impostors])
        turn = data.cell_turn[impostors]
        views = np.stack([np.mod(a - 3 * turn, 12), np.mod(b - 3 * turn, 12)], axis=1)
        blend = w
    else:
        view = orientation.local_view(data.cell_turn)[impostors]
        views = np.stack([view, view], axis=1)
        blend = np.zeros(len(impostors))
    prims[4] = 2 * len(impostors)

    band_cell, sides = _band(data, camera, levels, max_level, band_content, viewer, apothem)
    prims[5] = 2 * int(sides.sum())
    return FramePlan(levels, cells, plants, impostors, orientation.face[impostors].copy(), views.astype(np.int64),
                     blend, viewer, band_cell, sides, prims, band_apothem=apothem)


def _band(data: FieldData, camera: CameraInput, levels: np.ndarray, max_level: int, band_content, viewer: int,
          apothem: float) -> tuple[int | None, np.ndarray]:
    """The cell whose band is shown (None: no band) and its sides to draw (visible, with far cells behind).
    ``band_content(cell, apothem)``: a cache of :func:`band_sector_content` (the renderer's)."""
    if max_level < 5 or not np.any(levels == 5):
        return None, np.zeros(N_BAND_SIDES, dtype=bool)
    content = band_content(viewer, apothem) if band_content is not None else band_sector_content(
        data, viewer, apothem)
    centre = data.placed.cell_centre[viewer, [0, 2]]
    return viewer, visible_band_sides(camera, centre, apothem) & content


def cell_levels(cfg: GrassFieldConfig, data: FieldData, camera: CameraInput, max_level: int,
                viewer: int, apothem: float | None = None) -> np.ndarray:
    """(C,) level of every cell of a perspective view, -1 where culled: culling (section 3), eq. 1 with table 2
    and level 5 past the band, compiled (:func:`~systems.grass_field.kernels.cell_levels`; the same levels as
    :func:`~systems.grass_field.culling.cull_cells` + :func:`~systems.grass_field.lod.select_levels`)."""
    return kernels.cell_levels(
        data.placed.cell_centre, data.lod_points, camera.position, camera.forward[[0, 2]],
        _horizontal_half_angle(camera), float(data.cell_radius), float(cfg.near_cull_cells * cfg.cell_size),
        viewer, (float(camera.width) * cfg.length_of_interest, camera.tan_half_fov),
        np.asarray(cfg.level_thresholds, dtype=np.float64), min(max_level, 4), _BAND_NORMALS,
        band_apothem(cfg, data, camera) if apothem is None else float(apothem), max_level >= 5)


def _plan_compiled(cfg: GrassFieldConfig, data: FieldData, camera: CameraInput, orientation: ImpostorOrientation,
                   max_level: int, band_content, viewer: int) -> FramePlan:
    """:func:`plan_frame` of a perspective view with the compiled kernels (three calls instead of ~150 numpy
    calls on arrays of a few hundred elements)."""
    placed = data.placed
    eye = camera.position
    apothem = band_apothem(cfg, data, camera)
    levels = cell_levels(cfg, data, camera, max_level, viewer, apothem)
    if data.bare.any():
        levels[data.bare] = -1  # bare areas: culled like cells out of view
    ordered, cell_counts, plant_list, counts, level_prims = kernels.plants_to_draw(
        levels, placed.cell_centre, eye, placed.plants_per_cell, placed.plant_position, data.cell_sphere[0],
        data.cell_sphere[1], data.plant_sphere[0], float(data.plant_sphere[1]), frustum_planes(camera), True,
        NEAR_SORTED_LEVELS, placed.plant_variant, _real_primitives(data))
    ends = np.cumsum(counts)
    plants = [plant_list[ends[k] - counts[k]:ends[k]] for k in range(4)]
    cell_ends = np.cumsum(cell_counts)
    cells = [ordered[cell_ends[k] - cell_counts[k]:cell_ends[k]] for k in range(4)]
    prims = {k: int(level_prims[k]) for k in range(4)}

    impostors, face, view, turns, swaps = kernels.orient_impostors(
        levels, placed.cell_centre, eye, orientation.face, orientation.image, np.radians(cfg.face_turn_deg),
        np.radians(cfg.image_switch_deg), data.cell_turn)
    orientation.turns += turns
    orientation.swaps += swaps
    if cfg.blend_views:
        rel = placed.cell_centre[impostors][:, [0, 2]] - eye[[0, 2]]
        a, b, blend = nearest_views(atan2(-rel[:, 1], -rel[:, 0]))
        turn = data.cell_turn[impostors]
        views = np.stack([np.mod(a - 3 * turn, 12), np.mod(b - 3 * turn, 12)], axis=1)
    else:
        views = np.stack([view, view], axis=1)
        blend = np.zeros(len(impostors))
    prims[4] = 2 * len(impostors)
    band_cell, sides = _band(data, camera, levels, max_level, band_content, viewer, apothem)
    prims[5] = 2 * int(sides.sum())
    return FramePlan(levels, cells, plants, impostors, face, views, blend, viewer, band_cell, sides, prims,
                     plant_list=plant_list, band_apothem=apothem)


def _real_primitives(data: FieldData) -> np.ndarray:
    """(4, V) real primitives of each geometric level's plant variants (cached on the field's data)."""
    found = getattr(data, "_real_primitives", None)
    if found is None:
        found = np.stack([m.real_primitives for m in data.meshes]).astype(np.int64)
        data._real_primitives = found
    return found

