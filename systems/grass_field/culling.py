"""Per-cell view-frustum culling (section 3 of seeds/001).  Pure numpy.

The paper culls whole grid cells by the view angle.  Because a cell is large, testing its centre errs, most
for near cells, so: near cells are kept up to twice the view angle, and the cell holding the viewer is never
culled.  Far cells are kept while their centre is within the view angle widened by the cell's own angular
radius (the per-cell error), so a cell straddling the frustum edge never disappears.
"""

from __future__ import annotations

import numpy as np

from systems.grass_field.lod import CameraInput, _azimuth, _horizontal_half_angle, wrap_angle

__all__ = ["cull_cells"]


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
    if np.linalg.norm(fwd) < 1e-6:  # looking straight up or down: the horizontal test says nothing
        return keep
    theta = _horizontal_half_angle(camera)
    rel = centres[:, [0, 2]] - camera.position[[0, 2]]
    dist = np.linalg.norm(rel, axis=1)
    angle = np.abs(wrap_angle(_azimuth(rel) - _azimuth(fwd)))
    angular_radius = np.arcsin(np.clip(cell_radius / np.maximum(dist, 1e-9), 0.0, 1.0))
    keep = angle <= theta + angular_radius
    keep |= (dist <= near_distance) & (angle <= 2.0 * theta)
    if viewer_cell is not None and 0 <= viewer_cell < len(keep):
        keep[viewer_cell] = True
    return keep
