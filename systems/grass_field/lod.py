"""Per-cell level selection (eq. 1, table 2), the level-4 turn/swap rules and the level-5 band.  Pure numpy.

The camera comes in as plain numbers (:class:`CameraInput`) so all of this is testable without GL; the render
feature builds one from the engine's ``View`` with :func:`camera_from_view`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.exact import atan2
from engine.spatial import cross

__all__ = ["CameraInput", "camera_from_view", "pseudo_pixels", "level_from_pixels", "switch_distances",
           "band_distance", "band_normals", "select_levels", "ImpostorOrientation", "wrap_angle",
           "view_angles", "nearest_views", "visible_band_sides", "N_VIEWS", "N_BAND_SIDES", "CULLED"]

N_VIEWS = 12  # cached images per cell, every 30°
N_BAND_SIDES = 12  # the band around the viewer's cell is a 12-gon
CULLED = -1


@dataclass
class CameraInput:
    """What level selection and culling need from a camera.

    ``fov_x`` is the full horizontal field of view 2θ (radians) and ``width`` the viewport width W in pixels
    (eq. 1).  ``ortho_pixels_per_unit`` is set for orthographic views (then P = L · pixels-per-unit).
    """

    position: np.ndarray  # (3,)
    forward: np.ndarray  # (3,) unit
    fov_x: float
    width: int
    up: np.ndarray | None = None  # (3,) camera up; None: derived from world +y
    fov_y: float | None = None  # full vertical field of view; None: same as fov_x
    ortho_pixels_per_unit: float | None = None

    def __post_init__(self) -> None:
        self.position = np.asarray(self.position, dtype=np.float64)
        f = np.asarray(self.forward, dtype=np.float64)
        self.forward = f / max(float(np.linalg.norm(f)), 1e-12)
        if self.up is not None:
            self.up = np.asarray(self.up, dtype=np.float64)
        self._basis: tuple[np.ndarray, np.ndarray] | None = None  # derived once (a camera is not changed)
        self._half_angle: float | None = None

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """(right, camera up): unit vectors completing ``forward`` (right = forward × up)."""
        if self._basis is None:
            f = self.forward
            up = self.up if self.up is not None else np.array([0.0, 1.0, 0.0])
            right = cross(f, up)
            length = float(np.sqrt(right @ right))
            right = right / length if length >= 1e-9 else np.array([1.0, 0.0, 0.0])
            self._basis = (right, cross(right, f))
        return self._basis

    @property
    def tan_half_fov(self) -> float:
        """tan θ of eq. 1 (θ = half the horizontal field of view)."""
        return float(np.tan(0.5 * self.fov_x))

    def corner_rays(self) -> np.ndarray:
        """The four frustum corner directions (4, 3) in world space."""
        f = self.forward
        right, cam_up = self.basis()
        tx = np.tan(0.5 * self.fov_x)
        ty = np.tan(0.5 * (self.fov_y if self.fov_y is not None else self.fov_x))
        sx = np.array([-1.0, 1.0, -1.0, 1.0])[:, None]
        sy = np.array([-1.0, -1.0, 1.0, 1.0])[:, None]
        return f[None, :] + sx * tx * right[None, :] + sy * ty * cam_up[None, :]


def camera_from_view(view) -> CameraInput:
    """A :class:`CameraInput` from an ``engine.render.feature.View`` (uses its projection for the fov)."""
    proj = np.asarray(view.proj, dtype=np.float64)
    rows = np.asarray(view.view, dtype=np.float64)[:3, :3]
    up = rows[1]
    if view.ortho or view.fov_y <= 0.0:
        return CameraInput(view.camera_pos, view.camera_forward, np.pi / 2, int(view.width), up=up,
                           ortho_pixels_per_unit=0.5 * view.width * proj[0, 0])
    fov_x = 2.0 * np.arctan(1.0 / proj[0, 0])
    fov_y = 2.0 * np.arctan(1.0 / proj[1, 1])
    return CameraInput(view.camera_pos, view.camera_forward, float(fov_x), int(view.width), up=up,
                       fov_y=float(fov_y))


# ------------------------------------------------------------------------------------- eq. 1, table 2
def pseudo_pixels(distance: np.ndarray, width: float, length: float, tan_half_fov: float) -> np.ndarray:
    """Eq. 1 (seeds/001): the pseudo-pixel count P = W L / (2 D tan θ) of a length L at distance D."""
    d = np.maximum(np.asarray(distance, dtype=np.float64), 1e-9)
    return width * length / (2.0 * d * tan_half_fov)


def level_from_pixels(pixels: np.ndarray, thresholds) -> np.ndarray:
    """Table 2: level 0 for P ≥ t₀, 1 for t₁ ≤ P < t₀, 2 for t₂ ≤ P < t₁, 3 for t₃ ≤ P < t₂, else 4.

    A pure function of P (no hysteresis): the same P always gives the same level.
    """
    t = np.asarray(thresholds, dtype=np.float64)
    return np.searchsorted(-t, -np.asarray(pixels, dtype=np.float64), side="left").astype(np.int64)


def switch_distances(width: float, length: float, tan_half_fov: float, thresholds) -> np.ndarray:
    """The distances where P equals each threshold of table 2 (eq. 1 solved for D)."""
    return width * length / (2.0 * tan_half_fov * np.asarray(thresholds, dtype=np.float64))


# ------------------------------------------------------------------------------------------- level 5
def band_normals() -> np.ndarray:
    """Outward unit normals (12, 2) in (x, z) of the band's sides: side k faces azimuth k · 30°."""
    return _BAND_NORMALS.copy()


_BAND_ANGLES = np.arange(N_BAND_SIDES) * (2.0 * np.pi / N_BAND_SIDES)
_BAND_NORMALS = np.stack([np.cos(_BAND_ANGLES), np.sin(_BAND_ANGLES)], axis=-1)
_BAND_NORMALS.setflags(write=False)


def band_distance(points_xz: np.ndarray, centre_xz: np.ndarray) -> np.ndarray:
    """Distance in the 12-gon's metric: max over sides of the offset along the side's normal.

    A point is outside the band of apothem R around ``centre_xz`` exactly when this is ≥ R.
    """
    rel = np.asarray(points_xz, dtype=np.float64) - np.asarray(centre_xz, dtype=np.float64)
    return (rel @ _BAND_NORMALS.T).max(axis=-1)


def visible_band_sides(camera: CameraInput, centre_xz: np.ndarray, apothem: float) -> np.ndarray:
    """Which of the 12 band sides the camera can see (horizontal angle test); the others are not drawn."""
    if camera.ortho_pixels_per_unit is not None:
        return np.ones(N_BAND_SIDES, dtype=bool)
    n = _BAND_NORMALS
    half = apothem * np.tan(np.pi / N_BAND_SIDES)
    tangent = np.stack([-n[:, 1], n[:, 0]], axis=-1)
    mid = np.asarray(centre_xz, dtype=np.float64) + apothem * n
    eye = camera.position[[0, 2]]
    a0 = _azimuth(mid - half * tangent - eye)
    a1 = _azimuth(mid + half * tangent - eye)
    span = wrap_angle(a1 - a0)
    centre = a0 + 0.5 * span
    fwd = camera.forward[[0, 2]]
    if np.linalg.norm(fwd) < 1e-6:
        return np.ones(N_BAND_SIDES, dtype=bool)
    return np.abs(wrap_angle(centre - _azimuth(fwd))) <= 0.5 * np.abs(span) + _horizontal_half_angle(camera)


# ---------------------------------------------------------------------------------------- selection
def _azimuth(xz: np.ndarray) -> np.ndarray:
    xz = np.asarray(xz, dtype=np.float64)
    return atan2(xz[..., 1], xz[..., 0])


def wrap_angle(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into [-π, π)."""
    return (np.asarray(a, dtype=np.float64) + np.pi) % (2.0 * np.pi) - np.pi


def _horizontal_half_angle(camera: CameraInput) -> float:
    """Largest azimuth between the forward direction and a frustum corner ray (θ for a level camera)."""
    if camera._half_angle is None:
        fwd = camera.forward[[0, 2]]
        rays = camera.corner_rays()[:, [0, 2]]
        ok = np.einsum("ij,ij->i", rays, rays) > 1e-18
        if not ok.any():
            camera._half_angle = float(np.pi)
        else:
            camera._half_angle = float(np.abs(wrap_angle(_azimuth(rays[ok]) - _azimuth(fwd))).max())
    return camera._half_angle


def select_levels(centres: np.ndarray, camera: CameraInput, *, length: float, thresholds, max_level: int,
                  merge_distance: float, viewer_cell_centre: np.ndarray | None = None,
                  keep: np.ndarray | None = None) -> np.ndarray:
    """The level of every cell: eq. 1 with table 2 (0-4), level 5 outside the band, ``CULLED`` where culled.

    ``centres`` (C, 3) are the points whose distance D to the eye enters eq. 1; ``max_level`` 3, 4 or 5 is the
    paper's method 1, 2 or 3; ``keep`` is the culling mask (see :mod:`culling`).
    """
    centres = np.asarray(centres, dtype=np.float64)
    if camera.ortho_pixels_per_unit is not None:
        pixels = np.full(len(centres), length * camera.ortho_pixels_per_unit)
    else:
        rel = centres - camera.position
        distance = np.sqrt(np.einsum("ij,ij->i", rel, rel))
        pixels = pseudo_pixels(distance, camera.width, length, camera.tan_half_fov)
    level = np.minimum(level_from_pixels(pixels, thresholds), min(max_level, 4))
    if max_level >= 5 and viewer_cell_centre is not None:
        far = band_distance(centres[:, [0, 2]], np.asarray(viewer_cell_centre)[[0, 2]]) >= merge_distance
        level = np.where(far, 5, level)
    if keep is not None:
        level = np.where(keep, level, CULLED)
    return level.astype(np.int64)


# ------------------------------------------------------------------------------ level 4: turn and swap
def view_angles() -> np.ndarray:
    """Azimuths of the 12 cached views (the direction from the cell towards the camera)."""
    return np.arange(N_VIEWS) * (2.0 * np.pi / N_VIEWS)


def nearest_views(angle: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The two cached views around ``angle`` and the weight of the second (for the blending option)."""
    step = 2.0 * np.pi / N_VIEWS
    x = np.mod(np.asarray(angle, dtype=np.float64), 2.0 * np.pi) / step
    lo = np.floor(x)
    return lo.astype(np.int64) % N_VIEWS, (lo.astype(np.int64) + 1) % N_VIEWS, x - lo


class ImpostorOrientation:
    """Per-cell state of the level-4 rectangles (the paper's 15° / 30° rules, section 5).

    ``face`` is the azimuth the rectangle faces, ``image`` the azimuth of the displayed image (a multiple of
    30°); NaN where the cell is not at level 4.  A rectangle turns to face the viewer when the view azimuth
    has moved ``face_step`` or more from ``face``; its image is swapped for the nearest of the 12 when the view
    azimuth is ``image_step`` or more away from the image's.
    """

    def __init__(self, cells: int) -> None:
        self.face = np.full(cells, np.nan)
        self.image = np.full(cells, np.nan)
        self.turns = 0  # rectangle turns so far (statistics)
        self.swaps = 0  # image swaps so far

    def update(self, angle: np.ndarray, active: np.ndarray, face_step: float, image_step: float) -> None:
        """Apply the rules for this frame; ``angle`` (C,) is the azimuth from each cell to the eye."""
        angle = np.mod(np.asarray(angle, dtype=np.float64), 2.0 * np.pi)
        step = 2.0 * np.pi / N_VIEWS
        nearest = np.mod(np.round(angle / step), N_VIEWS) * step
        fresh = active & np.isnan(self.face)
        turn = active & ~fresh & (np.abs(wrap_angle(angle - self.face)) >= face_step - 1e-12)
        swap = active & ~fresh & (np.abs(wrap_angle(angle - self.image)) >= image_step - 1e-12)
        self.face = np.where(fresh | turn, angle, self.face)
        self.image = np.where(fresh | swap, nearest, self.image)
        self.face[~active] = np.nan
        self.image[~active] = np.nan
        self.turns += int(turn.sum())
        self.swaps += int(swap.sum())

    def local_view(self, turn_quarters: np.ndarray) -> np.ndarray:
        """The cached view index of each cell's layout: world image azimuth minus the cell's quarter turns."""
        step = 2.0 * np.pi / N_VIEWS
        k = np.round(np.nan_to_num(self.image) / step).astype(np.int64)
        return np.mod(k - 3 * np.asarray(turn_quarters, dtype=np.int64), N_VIEWS)
