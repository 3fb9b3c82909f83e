"""Shared geometry for the water plugin: the grid frame, bodies as arrays, bilinear sampling, convex polygons.

Grid units: a world point (x, z) has grid coordinates (u, v) = ((x − x0)/h, (z − z0)/h), so vertex P[i, j] sits at
(u, v) = (i, j) and ``heights[j, i]`` is its height. Polygons are counter-clockwise in (u, v) and padded to a
common vertex count V; ``counts[b]`` says how many of body b's vertices are real.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from engine import exact

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

BOX, SPHERE = 0, 1

# Reductions as ufunc methods: ndarray.all() / .sum() and np.any() / np.cumsum() pass through Python wrappers that
# cost more than the work itself on the small arrays of a step. Whole-array reductions need axis=None.
all_of, any_of = np.logical_and.reduce, np.logical_or.reduce
sum_of, min_of, max_of = np.add.reduce, np.minimum.reduce, np.maximum.reduce
EPS_LINE = 1e-7  # grid units: closer than this to a grid line counts as "on" it
NUDGE = 1e-4  # grid units: how far a point on a grid line is moved inwards (figure 2.3)


@dataclass(frozen=True)
class Grid:
    """Where a water grid lies in the world: nx × nz vertices, spacing h, P[0, 0] at (x0, z0), rest level y0."""

    nx: int
    nz: int
    h: float
    x0: float
    z0: float
    y0: float

    def to_uv(self, xz: F64) -> F64:
        """World (x, z) (..., 2) → grid units (u, v)."""
        return (xz - np.array([self.x0, self.z0])) / self.h

    def to_xz(self, uv: F64) -> F64:
        """Grid units (u, v) (..., 2) → world (x, z)."""
        return uv * self.h + np.array([self.x0, self.z0])

    def inside(self, uv: F64) -> NDArray[np.bool_]:
        """True where (u, v) lies on the grid's footprint [0, nx − 1] × [0, nz − 1] (borders included)."""
        return ((uv[..., 0] >= 0.0) & (uv[..., 0] <= self.nx - 1)
                & (uv[..., 1] >= 0.0) & (uv[..., 1] <= self.nz - 1))


@dataclass
class Bodies:
    """Bodies at one instant as arrays over B: entity ids, shape codes, world sizes, positions and rotations."""

    entities: I64  # (B,)
    shapes: NDArray[np.int8]  # (B,) BOX or SPHERE
    half: F64  # (B, 3) box half extents in world units (local half extents × |scale|)
    radius: F64  # (B,) sphere radius in world units
    position: F64  # (B, 3)
    rotation: F64  # (B, 3, 3) rotation matrices (column vectors: world = R @ local)
    _extent: F64 | None = field(default=None, repr=False, compare=False)

    def __len__(self) -> int:
        return len(self.entities)

    def take(self, index) -> Bodies:
        index = np.asarray(index)
        if index.dtype == bool:
            index = index.nonzero()[0]
        extent = None if self._extent is None else self._extent.take(index, axis=0)
        return Bodies(self.entities.take(index), self.shapes.take(index), self.half.take(index, axis=0),
                      self.radius.take(index), self.position.take(index, axis=0),
                      self.rotation.take(index, axis=0), extent)

    def extent(self) -> F64:
        """(B, 3) half size of each body's axis-aligned bounding box in x, y, z (computed once)."""
        if self._extent is None:
            box = np.einsum("bij,bj->bi", np.abs(self.rotation), self.half)
            self._extent = np.where((self.shapes == SPHERE)[:, None], self.radius[:, None], box)
        return self._extent

    def horizontal_half(self) -> F64:
        """(B, 2) half size of each body's axis-aligned footprint in x and z."""
        return self.extent()[:, ::2]

    def vertical_half(self) -> F64:
        """(B,) half height of each body's vertical extent."""
        return self.extent()[:, 1]


def empty_bodies() -> Bodies:
    return Bodies(np.zeros(0, np.int64), np.zeros(0, np.int8), np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3)),
                  np.zeros((0, 3, 3)))


def bilinear(field: F64, uv: F64) -> F64:
    """Bilinear height of ``field[j, i]`` at (u, v) (..., 2), clamped to the grid (eq. 2.2; on a grid edge it is the
    linear interpolation of eq. 2.3 / 2.4)."""
    return bilinear_fields((field,), uv)[0]


def bilinear_fields(fields: tuple, uv: F64) -> list:
    """:func:`bilinear` of several fields of the same shape at the same points (M, 2), sharing the lookups."""
    nz, nx = fields[0].shape
    c = np.minimum(np.maximum(uv, 0.0), (nx - 1, nz - 1))
    ij = np.minimum(c.astype(np.int64), (nx - 2, nz - 2))
    t = c - ij
    flat = ij[..., 0] + ij[..., 1] * nx
    corners = flat[..., None] + (0, 1, nx, nx + 1)  # z00, z10, z01, z11
    tu, tv = t[..., 0:1], t[..., 1]
    out = []
    for f in fields:
        q = f.ravel()[corners]
        edge = q[..., 0::2] + tu * (q[..., 1::2] - q[..., 0::2])  # bottom (v = j), top (v = j + 1)
        out.append(edge[..., 0] + tv * (edge[..., 1] - edge[..., 0]))
    return out


def bilinear_with_slope(field: F64, uv: F64) -> tuple[F64, F64, F64]:
    """Bilinear value and its derivatives ∂/∂u, ∂/∂v (per grid unit) at (u, v), clamped to the grid."""
    nz, nx = field.shape
    u = np.clip(uv[..., 0], 0.0, nx - 1)
    v = np.clip(uv[..., 1], 0.0, nz - 1)
    i = np.minimum(u.astype(np.int64), nx - 2)
    j = np.minimum(v.astype(np.int64), nz - 2)
    tu, tv = u - i, v - j
    z00, z10 = field[j, i], field[j, i + 1]
    z01, z11 = field[j + 1, i], field[j + 1, i + 1]
    bottom = z00 + tu * (z10 - z00)
    top = z01 + tu * (z11 - z01)
    du = (1.0 - tv) * (z10 - z00) + tv * (z11 - z01)
    return bottom + tv * (top - bottom), du, top - bottom


def bilinear_slope_pair(field: F64, other: F64, u: F64, v: F64) -> tuple[F64, F64, F64, F64]:
    """:func:`bilinear_with_slope` of ``field`` and the bilinear value of ``other`` (same shape) at the points
    (``u``, ``v``) given one coordinate per array (any shape), sharing the lookups."""
    nz, nx = field.shape
    u = np.minimum(np.maximum(u, 0.0), nx - 1)
    v = np.minimum(np.maximum(v, 0.0), nz - 1)
    i = np.minimum(u.astype(np.int64), nx - 2)
    j = np.minimum(v.astype(np.int64), nz - 2)
    tu, tv = u - i, v - j
    flat = j * nx + i
    f, o = field.ravel(), other.ravel()
    z00, z10, z01, z11 = f[flat], f[flat + 1], f[flat + nx], f[flat + (nx + 1)]
    bottom = z00 + tu * (z10 - z00)
    top = z01 + tu * (z11 - z01)
    du = (1.0 - tv) * (z10 - z00) + tv * (z11 - z01)
    o00, o10, o01, o11 = o[flat], o[flat + 1], o[flat + nx], o[flat + (nx + 1)]
    o_bottom = o00 + tu * (o10 - o00)
    o_top = o01 + tu * (o11 - o01)
    return bottom + tv * (top - bottom), du, top - bottom, o_bottom + tv * (o_top - o_bottom)


def polygon_edges(polygons: F64, counts: I64) -> tuple[F64, F64, NDArray[np.bool_]]:
    """Start and end points (B, V, 2) of every polygon edge k → k + 1 (cyclic) and which edges are real."""
    B, V = polygons.shape[:2]
    k = np.arange(V)
    valid = k[None, :] < counts[:, None]
    nxt = np.where(k[None, :] + 1 < counts[:, None], k[None, :] + 1, 0)
    end = np.take_along_axis(polygons, nxt[:, :, None], axis=1)
    return polygons, end, valid


def inside_polygons(points: F64, polygons: F64, counts: I64, margin: float = 1e-9) -> NDArray[np.bool_]:
    """Whether ``points[p]`` (P, 2) lies inside the convex CCW polygon ``polygons[p]`` (P, V, 2).

    Inside means left of every edge by more than ``margin`` (grid units): (b − a) × (p − a) / |b − a| > margin.
    A positive margin excludes the outline itself, a negative one includes it. Polygons with fewer than 3
    vertices contain nothing.
    """
    if len(points) == 0:
        return np.zeros(0, bool)
    a, b, valid = polygon_edges(polygons, counts)
    e = b - a
    r = points[:, None, :] - a
    cross = e[..., 0] * r[..., 1] - e[..., 1] * r[..., 0]
    length = exact.hypot(e[..., 0], e[..., 1])
    return np.all((cross > margin * length) | ~valid, axis=1) & (counts >= 3)


def polygon_area(polygons: F64, counts: I64) -> F64:
    """Signed area (B,) of each padded polygon (positive when counter-clockwise), shoelace formula."""
    a, b, valid = polygon_edges(polygons, counts)
    cross = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return 0.5 * np.sum(np.where(valid, cross, 0.0), axis=1)


def ranges(lo: I64, count: I64) -> tuple[I64, I64]:
    """For runs r with ``count[r]`` members starting at ``lo[r]``: (run index, value) of every member, flattened."""
    ends = np.add.accumulate(count)
    total = int(ends[-1]) if len(ends) else 0
    run = np.arange(len(count)).repeat(count)
    return run, (lo - ends + count).repeat(count) + np.arange(total)
