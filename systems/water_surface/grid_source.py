"""The older wave source the paper compares against (seeds/003, section 3.1, refs. [9] [11]; figure 3.4).

The body displaces the grid vertices under it: each vertex column's submerged body depth b (the length of the
vertical line through the vertex that lies inside the body and below the water plane S') is tracked, and the
water height of the column changes by α·(b(t) − b(t−1)), as in Müller's height-field coupling. Waves therefore
start from the grid vertices under the body rather than at its outline. b is averaged over 6 × 6 samples of the
vertex's own square so that it changes smoothly as a body glides over the grid.
"""

from __future__ import annotations

import numpy as np

from systems.water_surface.geometry import BOX, F64, I64, Bodies, Grid, ranges

__all__ = ["column_depths"]

_SAMPLES = 6


def column_depths(bodies: Bodies, plane_y: F64, grid: Grid) -> tuple[I64, F64]:
    """(flat vertex index, mean submerged depth b in metres) for the vertices under the bodies."""
    if len(bodies) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    centre = grid.to_uv(bodies.position[:, [0, 2]])
    half = bodies.horizontal_half() / grid.h + 0.5
    lo = np.maximum(np.ceil(centre - half), 0).astype(np.int64)
    hi = np.minimum(np.floor(centre + half), [grid.nx - 1, grid.nz - 1]).astype(np.int64)
    width = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    height = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    body, offset = ranges(np.zeros(len(bodies), np.int64), width * height)
    if len(body) == 0:
        return np.zeros(0, np.int64), np.zeros(0)
    dv, du = np.divmod(offset, width[body])
    vertex = np.stack([lo[body, 0] + du, lo[body, 1] + dv], axis=-1)
    sub = (np.arange(_SAMPLES) + 0.5) / _SAMPLES - 0.5
    su, sv = np.meshgrid(sub, sub)
    uv = vertex[:, None, :] + np.stack([su.ravel(), sv.ravel()], axis=-1)[None, :, :]
    xz = grid.to_xz(uv)
    b = body[:, None]
    is_box = (bodies.shapes == BOX)[b]
    depth = np.where(is_box, _box_depth(bodies, b, xz, plane_y), _sphere_depth(bodies, b, xz, plane_y))
    flat = vertex[:, 1] * grid.nx + vertex[:, 0]
    touched, inverse = np.unique(flat, return_inverse=True)
    return touched, np.bincount(inverse, depth.mean(axis=1), len(touched))


def _box_depth(bodies: Bodies, b: I64, xz: F64, plane_y: F64) -> F64:
    """Length of the vertical line at (x, z) inside the box and below y = plane_y (slab method)."""
    origin = np.stack([xz[..., 0], np.broadcast_to(plane_y[b], xz.shape[:-1]), xz[..., 1]], axis=-1)
    rot = bodies.rotation[b[:, 0]]
    o = np.einsum("bji,bsj->bsi", rot, origin - bodies.position[b[:, 0]][:, None, :])
    d = rot[:, 1, :][:, None, :]  # Rᵀ·(0, 1, 0)
    h = bodies.half[b[:, 0]][:, None, :]
    parallel = np.abs(d) < 1e-12
    safe = np.where(parallel, 1.0, d)
    t1, t2 = (-h - o) / safe, (h - o) / safe
    inside_slab = np.abs(o) <= h
    lo = np.where(parallel, np.where(inside_slab, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=-1)
    hi = np.where(parallel, np.where(inside_slab, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=-1)
    return np.maximum(np.minimum(hi, 0.0) - lo, 0.0)


def _sphere_depth(bodies: Bodies, b: I64, xz: F64, plane_y: F64) -> F64:
    c = bodies.position[b[:, 0]]
    q = (xz[..., 0] - c[:, None, 0]) ** 2 + (xz[..., 1] - c[:, None, 2]) ** 2
    r2 = bodies.radius[b[:, 0]][:, None] ** 2
    chord = np.sqrt(np.maximum(r2 - q, 0.0))
    top = np.minimum(c[:, None, 1] + chord, plane_y[b])
    return np.where(q < r2, np.maximum(top - (c[:, None, 1] - chord), 0.0), 0.0)
