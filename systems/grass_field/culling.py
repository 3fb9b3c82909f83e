"""Per-cell view-frustum culling (section 3 of seeds/001), and the plants of kept cells that the frustum
cannot see.  Pure numpy.

The paper culls whole grid cells by the view angle.  Because a cell is large, testing its centre errs, most
for near cells, so: near cells are kept up to twice the view angle, and the cell holding the viewer is never
culled.  Far cells are kept while their centre is within the view angle widened by the cell's own angular
radius (the per-cell error), so a cell straddling the frustum edge never disappears.

The cells and levels stay the paper's.  When drawing a kept cell's geometry (levels 0-3) the renderer then
skips the plants whose bounding sphere lies wholly outside the view frustum (:func:`visible_plants`): they
cannot put a pixel on the screen, so the image is the same, but half of the plants of the near cells kept by
the "twice the view angle" rule are off screen and cost vertex work for nothing.
"""

from __future__ import annotations

import numpy as np

from engine.exact import asin
from systems.grass_field.lod import CameraInput, _azimuth, _horizontal_half_angle, wrap_angle

__all__ = ["cull_cells", "frustum_planes", "spheres_inside", "visible_plants"]


def cull_cells(centres: np.ndarray, camera: CameraInput, *, cell_radius: float, near_distance: float,
               viewer_cell: int | None = None) -> np.ndarray:
    """Mask (C,) of the cells to draw.

    ``centres`` (C, 3) cell centres; ``cell_radius`` the horizontal radius bounding a cell's plants (half
    diagonal plus the plants' reach); ``near_distance`` the horizontal distance under which the paper's
    "twice the view angle" rule applies; ``viewer_cell`` the index of the cell holding the camera.
    """
    centres = np.asarray(centres, dtype=np.float64)
    keep = np.ones(len(centres), dtype=bool)
    if camera.ortho_pixels_per_unit is not None:
        return keep
    fwd = camera.forward[[0, 2]]
    if fwd @ fwd < 1e-12:  # looking straight up or down: the horizontal test says nothing
        return keep
    theta = _horizontal_half_angle(camera)
    rel = centres[:, [0, 2]] - camera.position[[0, 2]]
    dist = np.sqrt(np.einsum("ij,ij->i", rel, rel))
    angle = np.abs(wrap_angle(_azimuth(rel) - _azimuth(fwd)))
    angular_radius = asin(np.clip(cell_radius / np.maximum(dist, 1e-9), 0.0, 1.0))
    keep = angle <= theta + angular_radius
    keep |= (dist <= near_distance) & (angle <= 2.0 * theta)
    if viewer_cell is not None and 0 <= viewer_cell < len(keep):
        keep[viewer_cell] = True
    return keep


def frustum_planes(camera: CameraInput) -> np.ndarray | None:
    """(4, 4) inward side planes (unit normal n, offset d: inside where n·p + d ≥ 0) of a perspective camera,
    or None for an orthographic one.  The near and far planes are left out (they cull next to nothing here)."""
    if camera.ortho_pixels_per_unit is not None:
        return None
    f = camera.forward
    right, cam_up = camera.basis()
    tx = np.tan(0.5 * camera.fov_x)
    ty = np.tan(0.5 * (camera.fov_y if camera.fov_y is not None else camera.fov_x))
    normals = np.stack([tx * f + right, tx * f - right, ty * f + cam_up, ty * f - cam_up])
    normals /= np.sqrt(np.einsum("ij,ij->i", normals, normals))[:, None]
    return np.column_stack([normals, -normals @ camera.position])


def spheres_inside(centres: np.ndarray, radius: np.ndarray | float, planes: np.ndarray) -> tuple[np.ndarray,
                                                                                                   np.ndarray]:
    """(touching, wholly inside) masks of spheres against the frustum ``planes`` (see :func:`frustum_planes`)."""
    distance = centres @ planes[:, :3].T + planes[:, 3]
    radius = np.asarray(radius, dtype=np.float64)
    r = radius[:, None] if radius.ndim else radius
    return (distance >= -r).all(axis=1), (distance >= r).all(axis=1)


def visible_plants(cells: np.ndarray, plants_per_cell: int, plant_position: np.ndarray,
                   cell_sphere: tuple[np.ndarray, np.ndarray], plant_sphere: tuple[np.ndarray, float],
                   planes: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    """The plants of ``cells`` (in the cells' order) whose bounding sphere touches the frustum, and how many
    of each cell's plants that is.

    ``cell_sphere`` = (centres (C, 3), radii (C,)) bounds each cell's plants; ``plant_sphere`` = (offset (3,)
    from a plant's base to its sphere's centre, radius) bounds any plant.  Only the plants of cells that
    straddle a frustum side are tested one by one; ``planes`` None (orthographic views) keeps them all.
    """
    n = plants_per_cell
    cells = np.asarray(cells, dtype=np.int64)
    plants = (cells[:, None] * n + np.arange(n)).reshape(-1)
    everything = np.full(len(cells), n, dtype=np.int64)
    if planes is None or len(cells) == 0:
        return plants, everything
    _, inside = spheres_inside(cell_sphere[0][cells], cell_sphere[1][cells], planes)
    if inside.all():
        return plants, everything
    keep = np.ones((len(cells), n), dtype=bool)
    partial = np.flatnonzero(~inside)
    candidates = plants.reshape(-1, n)[partial].reshape(-1)
    touching, _ = spheres_inside(plant_position[candidates] + plant_sphere[0], plant_sphere[1], planes)
    keep[partial] = touching.reshape(-1, n)
    return plants[keep.reshape(-1)], keep.sum(axis=1)
