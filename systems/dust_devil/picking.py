"""Mouse picking for the top-view drag (section 4, seeds/004), pure numpy.

A screen point in a camera's viewport becomes a world ray through the inverse of ``proj @ view``; the ray hits
the terrain (the engine's height-field ray cast) or, without terrain, a horizontal ground plane.  The helpers
take the view and projection matrices themselves (the renderer's ``View.view`` / ``View.proj``), so they work
for any camera; :func:`camera_matrices` rebuilds them from a Camera component for the simulation side.

Screen coordinates are pixels of the window with the origin at the bottom-left (pyglet's convention, and that
of ``CameraConfig.viewport``).
"""

from __future__ import annotations


import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.exact import inverse, matmul, matvec

__all__ = ["viewport_pixels", "screen_to_ndc", "screen_ray", "intersect_plane", "pick_ground",
           "camera_matrices"]

F64 = NDArray[np.float64]


def viewport_pixels(viewport: ArrayLike, window: tuple[int, int]) -> F64:
    """(x, y, width, height) in whole pixels of a viewport given as fractions of the window (origin bottom-left),
    rounded as the renderer rounds its view rectangles."""
    vx, vy, vw, vh = (float(a) for a in viewport)
    w, h = window
    return np.array([round(vx * w), round(vy * h), max(1, round(vw * w)), max(1, round(vh * h))], dtype=np.float64)


def screen_to_ndc(points: ArrayLike, viewport_px: ArrayLike) -> tuple[F64, NDArray[np.bool_]]:
    """Pixel points (N, 2) to normalised device coordinates of the viewport, and which lie inside it."""
    p = np.atleast_2d(np.asarray(points, dtype=np.float64))
    x0, y0, w, h = (float(a) for a in viewport_px)
    ndc = np.stack([(p[:, 0] - x0) / w * 2.0 - 1.0, (p[:, 1] - y0) / h * 2.0 - 1.0], axis=-1)
    inside = np.all(np.abs(ndc) <= 1.0, axis=-1)
    return ndc, inside


def screen_ray(view: ArrayLike, proj: ArrayLike, ndc: ArrayLike) -> tuple[F64, F64]:
    """World rays (origins (N, 3) on the near plane, unit directions (N, 3)) through NDC points (N, 2).

    Unprojects (x, y, -1) and (x, y, 1) with (proj · view)⁻¹; works for perspective and orthographic cameras.
    """
    inv = inverse(matmul(proj, view))
    ndc = np.atleast_2d(np.asarray(ndc, dtype=np.float64))
    n = len(ndc)
    near = matvec(inv, np.column_stack([ndc, -np.ones(n), np.ones(n)]))
    far = matvec(inv, np.column_stack([ndc, np.ones(n), np.ones(n)]))
    near = near[:, :3] / near[:, 3:]
    far = far[:, :3] / far[:, 3:]
    d = far - near
    return near, d / np.linalg.norm(d, axis=-1, keepdims=True)


def intersect_plane(origins: F64, dirs: F64, height: float) -> tuple[NDArray[np.bool_], F64]:
    """Hits (N,) and points (N, 3) of rays with the horizontal plane y = ``height`` (in front of the origin)."""
    dy = dirs[:, 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (height - origins[:, 1]) / dy
    hit = (dy != 0.0) & (t >= 0.0)
    t = np.where(hit, t, 0.0)
    return hit, origins + t[:, None] * dirs


def pick_ground(view: ArrayLike, proj: ArrayLike, viewport_px: ArrayLike, points: ArrayLike,
                terrain=None, plane_height: float = 0.0) -> tuple[NDArray[np.bool_], F64]:
    """World ground points (N, 3) under pixel ``points`` (N, 2) seen through a camera, and which hit.

    ``terrain`` is ``(Collider, Transform)`` of a height-field terrain or ``None``; rays that miss the terrain
    (or all rays without one) hit the plane y = ``plane_height``.  Points outside the viewport do not hit.
    """
    ndc, inside = screen_to_ndc(points, viewport_px)
    origins, dirs = screen_ray(view, proj, ndc)
    hit, ground = intersect_plane(origins, dirs, plane_height)
    if terrain is not None:
        collider, transform = terrain
        t_hit, t, _ = collider.ray_cast(origins, dirs, transform)
        ground = np.where(t_hit[:, None], origins + np.where(t_hit, t, 0.0)[:, None] * dirs, ground)
        hit = hit | t_hit
    return hit & inside, ground


def camera_matrices(camera, transform, window: tuple[int, int]) -> tuple[F64, F64, F64]:
    """(view, proj, viewport_px) of a Camera component placed by its Transform in a window of ``window`` pixels,
    exactly as the renderer builds them (engine.render.components.camera_matrices)."""
    from engine.render.components import camera_matrices as engine_camera_matrices

    view, proj, rect = engine_camera_matrices(camera, transform, window)
    return view, proj, np.asarray(rect, dtype=np.float64)
