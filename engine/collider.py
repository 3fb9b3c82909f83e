"""Collision shapes and their vectorized queries: signed distance, penetration, ray casts.

A ``Collider`` is defined in its entity's local frame and placed by the entity's ``Transform``: rotation and
translation always apply; scale applies to the box (half extents × |scale|) and the sphere (radius × max
|scale|); planes and height fields ignore scale (bake it into ``offset`` or the heights and spacing). Every query
takes N points or rays at once and returns world-space results. Signed distances are negative inside.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal, get_args

import numpy as np
from numpy.typing import ArrayLike, NDArray

from engine.exact import dot, hypot, hypot_scalar
from engine.exact import length as exact_length
from engine.heightfield import HeightField
from engine.jit import kernel, maximum, minimum
from engine.spatial import Transform, quat_conjugate, quat_is_identity, quat_rotate

__all__ = ["Collider", "ColliderShape", "RayHits"]

F64 = NDArray[np.float64]
ColliderShape = Literal["box", "sphere", "plane", "heightfield"]
RayHits = tuple[NDArray[np.bool_], F64, F64]

_SHAPES = get_args(ColliderShape)
_UP = np.array([0.0, 1.0, 0.0])
_HEIGHTFIELD_BISECTIONS = 40  # most refinement iterations (each at least halves the bracket every other step)
_HEIGHTFIELD_TOLERANCE = 1e-10  # bracket width (in units of t) at which refinement stops
_HEIGHTFIELD_MARCH_CHUNK = 64


def _points(points: ArrayLike, name: str) -> F64:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {array.shape}")
    return array


def _first_max(a: F64, b: F64, c: F64) -> NDArray[np.int64]:
    """``np.argmax`` over the three columns (the first of equal maxima; no NaNs here), without a reduction over
    a trailing axis of 3."""
    axis = (b > a).astype(np.int64)
    axis[c > np.maximum(a, b)] = 2
    return axis


def _unit(v: F64, fallback: F64) -> F64:
    """Normalize rows of v; rows of zero length become ``fallback``."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    safe = np.where(norm > 0.0, norm, 1.0)
    return np.where(norm > 0.0, v / safe, fallback)


@dataclass
class Collider:
    """A collision shape in local space.

    box: centred cube with ``half_extents``; sphere: ``radius`` about the origin; plane: the half-space below
    ``dot(normal, p) = offset`` (the plane passes through the origin when offset = 0; normal default +Y);
    heightfield: the column below ``heightfield``'s surface over its footprint, a finite solid as in Bullet and
    PhysX (distance measured vertically over the footprint; beside it a point is outside, however low: see
    :meth:`HeightField.solid_distance`). ``layer`` names the collision layer, ``is_trigger`` marks a volume that
    reports overlaps without being solid.
    """

    shape: ColliderShape = "box"
    half_extents: F64 = field(default_factory=lambda: np.full(3, 0.5))
    radius: float = 0.5
    normal: F64 = field(default_factory=lambda: _UP.copy())
    offset: float = 0.0
    heightfield: HeightField | None = None
    layer: str = "default"
    is_trigger: bool = False

    def __post_init__(self) -> None:
        if self.shape not in _SHAPES:
            raise ValueError(f"unknown collider shape {self.shape!r}; expected one of {', '.join(_SHAPES)}")
        self.half_extents = np.array(self.half_extents, dtype=np.float64)
        if self.half_extents.shape != (3,) or np.any(self.half_extents < 0.0):
            raise ValueError(f"Collider.half_extents must be 3 non-negative numbers, got {self.half_extents.tolist()}")
        self.radius = float(self.radius)
        if self.radius < 0.0:
            raise ValueError(f"Collider.radius must be >= 0, got {self.radius}")
        normal = np.array(self.normal, dtype=np.float64)
        length = float(exact_length(normal)) if normal.shape == (3,) else 0.0
        if length == 0.0:
            raise ValueError(f"Collider.normal must be a non-zero 3-vector, got {normal.tolist()}")
        self.normal = normal / length
        self.offset = float(self.offset)
        if self.shape == "heightfield" and self.heightfield is None:
            raise ValueError("Collider shape 'heightfield' needs a HeightField in Collider.heightfield")

    # ----------------------------------------------------------------------------------------------- queries

    def signed_distance(self, points: ArrayLike, transform: Transform) -> F64:
        """Signed distance (N,) from world points to the surface, negative inside (vertical over a height field's
        footprint, to the column's border beside it)."""
        if self.shape == "box":
            return self._box_kernel_query(_points(points, "points"), transform)[0]
        return self._local_signed_distance(self._to_local(_points(points, "points"), transform), transform)

    def query(self, points: ArrayLike, transform: Transform) -> tuple[F64, F64]:
        """Penetration depth z = max(0, -signed distance) (N,) and outward unit surface normal (N, 3), world space.

        The normal is that of the nearest surface point (box, sphere, plane) or of the height field at the
        point's (x, z) over its footprint (beside it, from the column's point straight across the border to the
        point, as a box's outside normal); it is returned for every point, penetrating or not.
        """
        if self.shape == "box":
            _, depth, normal = self._box_kernel_query(_points(points, "points"), transform)
            return depth, normal
        return self._query_numpy(_points(points, "points"), transform)

    def _query_numpy(self, points: F64, transform: Transform) -> tuple[F64, F64]:
        """:meth:`query` in numpy, every shape (the reference of the box kernel)."""
        distance, normal = self._local_distance(self._to_local(_points(points, "points"), transform), transform)
        return np.maximum(0.0, -distance), quat_rotate(transform.rotation, normal)

    def ray_cast(
        self, origins: ArrayLike, dirs: ArrayLike, transform: Transform, max_t: float = np.inf
    ) -> RayHits:
        """First hit of rays o + t·d, 0 <= t <= max_t: (hit (N,) bool, t (N,), world normal (N, 3)).

        ``t`` is in units of ``dirs`` (distance when they are unit). Misses have t = inf and normal 0. A ray that
        starts inside (signed distance < 0) hits at t = 0 with the nearest surface's normal. Box: slab method
        (Kay & Kajiya 1986); sphere: the quadratic |o + t·d|² = r²; plane: o·n + t·d·n = offset; height field:
        march then bisect (see ``_ray_heightfield``).
        """
        origins, dirs = _points(origins, "origins"), _points(dirs, "dirs")
        if origins.shape != dirs.shape:
            raise ValueError(f"origins {origins.shape} and dirs {dirs.shape} must have the same shape")
        if self.shape == "box":
            return _box_ray_cast_kernel(
                np.ascontiguousarray(origins), np.ascontiguousarray(dirs), *self._box_frame(transform), float(max_t))
        if self.shape == "heightfield":  # a ray with a NaN or infinite coordinate misses, as it does the others
            finite = np.isfinite(origins).all(axis=1) & np.isfinite(dirs).all(axis=1)
            if not finite.all():
                return self._ray_cast_rows(origins, dirs, transform, max_t, np.flatnonzero(finite))
        return self._ray_cast_numpy(origins, dirs, transform, max_t)

    def _ray_cast_rows(self, origins: F64, dirs: F64, transform: Transform, max_t: float,
                       rows: NDArray[np.int64]) -> RayHits:
        """:meth:`ray_cast` of the given rows; the others miss (hit False, t = inf, normal 0)."""
        n = len(origins)
        hit, t, normal = np.zeros(n, dtype=bool), np.full(n, np.inf), np.zeros((n, 3))
        if rows.size:
            hit[rows], t[rows], normal[rows] = self._ray_cast_numpy(origins[rows], dirs[rows], transform, max_t)
        return hit, t, normal

    def _ray_cast_numpy(self, origins: F64, dirs: F64, transform: Transform, max_t: float = np.inf) -> RayHits:
        """:meth:`ray_cast` in numpy, every shape (the reference of the box kernel).

        An unrotated collider skips the rotations (a rotation by the identity returns its input, up to the sign of
        zeros), and the inside test's normals are computed only for the rays that start inside (usually none):
        for a height field they cost four more surface lookups per ray."""
        rotated = not quat_is_identity(transform.rotation)
        o = origins - transform.position
        d = dirs
        if rotated:
            inverse = quat_conjugate(transform.rotation)
            o, d = quat_rotate(inverse, o), quat_rotate(inverse, dirs)
        cast = {
            "box": self._ray_box,
            "sphere": self._ray_sphere,
            "plane": self._ray_plane,
            "heightfield": self._ray_heightfield,
        }[self.shape]
        hit, t, normal = cast(o, d, transform, float(max_t))
        inside = self._local_signed_distance(o, transform) < 0.0
        hit = hit | inside
        t = np.where(inside, 0.0, np.where(hit, t, np.inf))
        normal = np.where(hit[:, None], normal, 0.0)
        starts_inside = np.flatnonzero(inside)
        if starts_inside.size:
            normal[starts_inside] = self._local_normal(o[starts_inside], transform)
        return hit, t, quat_rotate(transform.rotation, normal) if rotated else normal

    # ------------------------------------------------------------------------------------------ local frame

    @staticmethod
    def _to_local(points: F64, transform: Transform) -> F64:
        """World → collider frame with rotation and translation only (scale is handled per shape)."""
        return quat_rotate(quat_conjugate(transform.rotation), points - transform.position)

    def _box_half_extents(self, transform: Transform) -> F64:
        return self.half_extents * np.abs(transform.scale)

    def _box_frame(self, transform: Transform) -> tuple[F64, F64, F64, F64]:
        """The box kernels' frame arguments: position, rotation q, its conjugate and the half extents."""
        q = np.ascontiguousarray(transform.rotation, dtype=np.float64)
        return (np.ascontiguousarray(transform.position, dtype=np.float64), q, quat_conjugate(q),
                self._box_half_extents(transform))

    def _box_kernel_query(self, points: F64, transform: Transform) -> tuple[F64, F64, F64]:
        """Box signed distance, penetration depth and world normal (the compiled :meth:`query`)."""
        return _box_query_kernel(np.ascontiguousarray(points), *self._box_frame(transform))

    def _sphere_radius(self, transform: Transform) -> float:
        return self.radius * float(np.max(np.abs(transform.scale)))

    def _local_distance(self, p: F64, transform: Transform) -> tuple[F64, F64]:
        """Signed distance (N,) and outward unit normal (N, 3), both in the collider frame."""
        if self.shape == "box":
            return self._box_distance(p, self._box_half_extents(transform))
        return self._local_signed_distance(p, transform), self._local_normal(p, transform)

    def _local_signed_distance(self, p: F64, transform: Transform) -> F64:
        """The distance of :meth:`_local_distance` alone."""
        if self.shape == "box":
            return self._box_distance(p, self._box_half_extents(transform))[0]
        if self.shape == "sphere":
            return np.linalg.norm(p, axis=-1) - self._sphere_radius(transform)
        if self.shape == "plane":
            return dot(p, self.normal) - self.offset
        return self._heightfield_distance(p)

    def _heightfield_distance(self, p: F64) -> F64:
        """HeightField.solid_distance of local points p (y − h(x, z) over the footprint, positive beside it):
        compiled (:func:`_heightfield_distance_kernel`, the same bits) for float64 heights without NaN x or z;
        otherwise by HeightField.solid_distance, the numpy reference (its indexing fails on NaN)."""
        field_ = self.heightfield
        if field_.heights.dtype == np.float64:
            distance, done = _heightfield_distance_kernel(
                np.ascontiguousarray(p), np.ascontiguousarray(field_.heights), float(field_.origin[0]),
                float(field_.origin[1]), float(field_.spacing))
            if done:
                return distance
        return field_.solid_distance(p[:, 0], p[:, 1], p[:, 2])

    def _local_normal(self, p: F64, transform: Transform) -> F64:
        """The normal of :meth:`_local_distance` alone."""
        if self.shape == "box":
            return self._box_distance(p, self._box_half_extents(transform))[1]
        if self.shape == "sphere":
            return _unit(p, _UP)
        if self.shape == "plane":
            return np.broadcast_to(self.normal, p.shape).copy()
        return self._heightfield_normal(p)

    def _heightfield_normal(self, p: F64) -> F64:
        """The surface normal at (x, z) over the footprint; beside it the unit vector from the column's point
        straight across the border (clip(x), min(y, h), clip(z)) to p, that of :meth:`HeightField.solid_distance`."""
        field_ = self.heightfield
        normal = field_.normal_at(p[:, 0], p[:, 2])
        (x_lo, x_hi), (z_lo, z_hi) = field_.bounds()
        beside = np.flatnonzero((p[:, 0] < x_lo) | (p[:, 0] > x_hi) | (p[:, 2] < z_lo) | (p[:, 2] > z_hi))
        if beside.size:
            q = p[beside]
            up = np.maximum(q[:, 1] - field_.height_at(q[:, 0], q[:, 2]), 0.0)
            away = np.column_stack([q[:, 0] - np.clip(q[:, 0], x_lo, x_hi), up, q[:, 2] - np.clip(q[:, 2], z_lo, z_hi)])
            normal[beside] = _unit(away, _UP)
        return normal

    @staticmethod
    def _box_distance(p: F64, h: F64) -> tuple[F64, F64]:
        """Exact box SDF (Quilez): q = |p| - h; d = |max(q, 0)| + min(max_i q_i, 0).

        Outside, the normal points from the nearest box point clamp(p, -h, h) to p; inside (or on the surface),
        it is the face axis of the largest q_i with the sign of p along it.
        """
        q = np.abs(p) - h
        q0, q1, q2 = q[:, 0], q[:, 1], q[:, 2]  # column by column: reductions over a trailing axis of 3 cost more
        m0, m1, m2 = np.maximum(q0, 0.0), np.maximum(q1, 0.0), np.maximum(q2, 0.0)
        outside = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)  # np.linalg.norm's sum, in its order
        largest = np.maximum(np.maximum(q0, q1), q2)
        inside = np.minimum(largest, 0.0)
        axis = _first_max(q0, q1, q2)
        face = np.zeros_like(p)
        rows = np.arange(len(p))
        face[rows, axis] = np.where(p[rows, axis] >= 0.0, 1.0, -1.0)
        normal = np.where((outside > 0.0)[:, None], _unit(p - np.clip(p, -h, h), _UP), face)
        return outside + inside, normal

    # ------------------------------------------------------------------------------------------- ray casts

    def _ray_box(self, o: F64, d: F64, transform: Transform, max_t: float) -> RayHits:
        h = self._box_half_extents(transform)
        parallel = d == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / np.where(parallel, 1.0, d)
            t1, t2 = (-h - o) * inv, (h - o) * inv
        slab_in = np.abs(o) <= h
        t_lo = np.where(parallel, np.where(slab_in, -np.inf, np.inf), np.minimum(t1, t2))
        t_hi = np.where(parallel, np.where(slab_in, np.inf, -np.inf), np.maximum(t1, t2))
        a0, a1, a2 = t_lo[:, 0], t_lo[:, 1], t_lo[:, 2]
        t_near = np.maximum(np.maximum(a0, a1), a2)
        t_far = np.minimum(np.minimum(t_hi[:, 0], t_hi[:, 1]), t_hi[:, 2])
        hit = (t_near <= t_far) & (t_near >= 0.0) & (t_near <= max_t)
        axis = _first_max(a0, a1, a2)
        rows = np.arange(len(o))
        normal = np.zeros_like(o)
        normal[rows, axis] = np.where(d[rows, axis] > 0.0, -1.0, 1.0)
        return hit, t_near, normal

    def _ray_sphere(self, o: F64, d: F64, transform: Transform, max_t: float) -> RayHits:
        r = self._sphere_radius(transform)
        a = np.sum(d * d, axis=-1)
        b = np.sum(o * d, axis=-1)
        c = np.sum(o * o, axis=-1) - r * r
        disc = b * b - a * c
        valid = (disc >= 0.0) & (a > 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (-b - np.sqrt(np.where(valid, disc, 0.0))) / np.where(a > 0.0, a, 1.0)
        hit = valid & (t >= 0.0) & (t <= max_t)
        return hit, t, _unit(o + t[:, None] * d, _UP)

    def _ray_plane(self, o: F64, d: F64, transform: Transform, max_t: float) -> RayHits:
        height = dot(o, self.normal) - self.offset
        approach = dot(d, self.normal)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -height / np.where(approach < 0.0, approach, -1.0)
        hit = (approach < 0.0) & (height >= 0.0) & (t <= max_t)
        return hit, t, np.broadcast_to(self.normal, o.shape).copy()

    def _ray_heightfield(self, o: F64, d: F64, transform: Transform, max_t: float) -> RayHits:
        """Ray march + bracketed root refinement on f(t) = y(t) - h(x(t), z(t)), and the column's side walls.

        The solid is the column below the surface over the footprint (:meth:`HeightField.solid_distance`). A ray
        that enters the footprint from beside it (at t = the later of its x and z slab entries, in [0, max_t])
        with f < 0 there hits the side wall at that t, with the wall's outward normal (the axis entered last, x
        when both at once) (:meth:`_heightfield_wall`). Otherwise only the surface above the footprint is hit: the
        ray is clipped to the field's bounding box (its x/z footprint × [min h, max h]) and to [0, max_t]
        (:meth:`_heightfield_interval`); that interval is sampled at most every spacing/2 of horizontal travel,
        the first sign change of f (above → below) is bracketed, then refined (Illinois false position,
        ``_refine_crossing``). One ray at a time in :func:`_heightfield_interval_kernel` and
        :func:`_heightfield_march_kernel`; :meth:`_ray_heightfield_numpy` is the numpy reference (the same bits).
        Crossings thinner than half a cell may be missed.
        """
        field_ = self.heightfield
        o, d = np.ascontiguousarray(o), np.ascontiguousarray(d)
        t_start, t_end, active, longest = _heightfield_interval_kernel(o, d, *self._heightfield_box(), float(max_t))
        (x_lo, x_hi), (z_lo, z_hi) = field_.bounds()
        return _heightfield_march_kernel(
            o, d, t_start, t_end, active, self._heightfield_steps(longest),
            np.ascontiguousarray(field_.heights, dtype=np.float64), float(field_.origin[0]), float(field_.origin[1]),
            float(field_.spacing), x_lo, x_hi, z_lo, z_hi, float(max_t))

    def _heightfield_box(self) -> tuple[F64, F64]:
        """The field's bounding box (lo, hi): its x/z footprint × [min h, max h], grown vertically by a pad so a
        flat field still brackets its crossing."""
        field_ = self.heightfield
        (x_lo, x_hi), (z_lo, z_hi) = field_.bounds()
        h_min, h_max = field_.height_range
        pad = 1e-6 * (field_.spacing + h_max - h_min)
        return np.array([x_lo, h_min - pad, z_lo]), np.array([x_hi, h_max + pad, z_hi])

    def _heightfield_steps(self, longest: float) -> int:
        """The march's sample count: one every spacing/2 of the longest horizontal travel, and the start."""
        return int(np.ceil(longest / (0.5 * self.heightfield.spacing))) + 1

    def _heightfield_interval(self, o: F64, d: F64, max_t: float) -> tuple[F64, F64, NDArray[np.bool_], int]:
        """Each ray's [t_start, t_end] inside the field's bounding box and [0, max_t], whether it is non-empty
        (and the ray has a direction), and the march's sample count (every spacing/2 of the longest horizontal
        travel). The numpy reference of :func:`_heightfield_interval_kernel`."""
        lo, hi = self._heightfield_box()
        parallel = d == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / np.where(parallel, 1.0, d)
            t1, t2 = (lo - o) * inv, (hi - o) * inv
        slab_in = (o >= lo) & (o <= hi)
        t_lo = np.where(parallel, np.where(slab_in, -np.inf, np.inf), np.minimum(t1, t2))
        t_hi = np.where(parallel, np.where(slab_in, np.inf, -np.inf), np.maximum(t1, t2))
        t_start = np.maximum(t_lo.max(axis=-1), 0.0)
        t_end = np.minimum(t_hi.min(axis=-1), max_t)
        active = (t_start <= t_end) & (d != 0.0).any(axis=-1)  # a ray without direction meets nothing it is not in
        horizontal = hypot(d[:, 0], d[:, 2]) * np.where(active, t_end - t_start, 0.0)
        return t_start, t_end, active, self._heightfield_steps(np.max(horizontal, initial=0.0))

    def _heightfield_wall(self, o: F64, d: F64, max_t: float) -> tuple[NDArray[np.int64], F64, F64]:
        """The rays that hit a side wall of the field's column: they enter the footprint's x/z rectangle (slab
        method, the operations of :meth:`_heightfield_interval`) at some finite t in [0, max_t], below the
        surface there. Their rows, t, and the wall's outward normal (the axis entered last, x when both at once)."""
        field_ = self.heightfield
        (x_lo, x_hi), (z_lo, z_hi) = field_.bounds()
        lo, hi = np.array([x_lo, z_lo]), np.array([x_hi, z_hi])
        oh, dh = o[:, [0, 2]], d[:, [0, 2]]
        parallel = dh == 0.0
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            inv = 1.0 / np.where(parallel, 1.0, dh)
            t1, t2 = (lo - oh) * inv, (hi - oh) * inv
        slab_in = (oh >= lo) & (oh <= hi)
        t_lo = np.where(parallel, np.where(slab_in, -np.inf, np.inf), np.minimum(t1, t2))
        t_hi = np.where(parallel, np.where(slab_in, np.inf, -np.inf), np.maximum(t1, t2))
        near = np.maximum(t_lo[:, 0], t_lo[:, 1])
        enters = (near >= 0.0) & (near < np.inf) & (near <= np.minimum(t_hi[:, 0], t_hi[:, 1])) & (near <= max_t)
        rows = np.flatnonzero(enters)  # (an entry at t = inf, from a subnormal direction, would sample a NaN point)
        t = near[rows]
        p = o[rows] + t[:, None] * d[rows]
        below = p[:, 1] - field_.height_at(p[:, 0], p[:, 2]) < 0.0
        rows, t = rows[below], t[below]
        axis = np.where(t_lo[rows, 1] > t_lo[rows, 0], 2, 0)
        normal = np.zeros((rows.size, 3))
        normal[np.arange(rows.size), axis] = np.where(d[rows, axis] > 0.0, -1.0, 1.0)
        return rows, t, normal

    def _ray_heightfield_numpy(self, o: F64, d: F64, transform: Transform, max_t: float) -> RayHits:
        """:meth:`_ray_heightfield` in numpy, loops over march chunks and refinement iterations, each vectorized
        over all rays (the reference of its kernel)."""
        field_ = self.heightfield
        n = len(o)
        t_start, t_end, active, steps = self._heightfield_interval(o, d, max_t)
        wall, t_wall, wall_normal = self._heightfield_wall(o, d, max_t)

        def f(t: F64, rows: NDArray[np.int64]) -> F64:
            p = o[rows] + t[:, None] * d[rows]
            return p[:, 1] - field_.height_at(p[:, 0], p[:, 2])

        hit = np.zeros(n, dtype=bool)
        t_above, t_below = np.zeros(n), np.zeros(n)
        marching = active.copy()
        marching[wall] = False  # the wall comes first; the march's step count stays that of every active ray
        pending = np.flatnonzero(marching)
        span = np.where(active, t_end - t_start, 0.0)
        previous_t = t_start.copy()
        previous_f = np.full(n, np.inf)
        previous_f[pending] = f(t_start[pending], pending)
        k = 1
        while pending.size and k <= steps:  # loop over march chunks, vectorized over rays × samples
            ks = np.arange(k, min(k + _HEIGHTFIELD_MARCH_CHUNK, steps + 1))
            ts = t_start[pending, None] + span[pending, None] * (ks[None, :] / steps)
            rows = np.repeat(pending, len(ks))
            fs = f(ts.ravel(), rows).reshape(ts.shape)
            f_prev = np.concatenate([previous_f[pending, None], fs[:, :-1]], axis=1)
            t_prev = np.concatenate([previous_t[pending, None], ts[:, :-1]], axis=1)
            crossing = (f_prev >= 0.0) & (fs < 0.0)
            found = crossing.any(axis=1)
            first = np.argmax(crossing, axis=1)
            rays = pending[found]
            hit[rays] = True
            t_above[rays] = t_prev[found, first[found]]
            t_below[rays] = ts[found, first[found]]
            previous_f[pending], previous_t[pending] = fs[:, -1], ts[:, -1]
            pending = pending[~found]
            k = ks[-1] + 1

        rays = np.flatnonzero(hit)
        t = np.full(n, np.inf)
        t[rays] = _refine_crossing(lambda ts, which: f(ts, rays[which]), t_above[rays], t_below[rays],
                                   f(t_above[rays], rays), f(t_below[rays], rays))
        normal = np.zeros((n, 3))
        p = o[rays] + t[rays, None] * d[rays]
        normal[rays] = field_.normal_at(p[:, 0], p[:, 2])
        hit[wall], t[wall], normal[wall] = True, t_wall, wall_normal
        return hit, t, normal


def _refine_crossing(f, a: F64, b: F64, fa: F64, fb: F64) -> F64:
    """Root of f in brackets [a, b] with f(a) >= 0 > f(b), vectorised: the Illinois variant of regula falsi
    (Dowell & Jarratt 1971), which keeps the bracket and converges superlinearly on the smooth (piecewise
    quadratic) f of a height field; a step that would not shrink the bracket enough is a bisection instead.
    ``f(t, which)`` evaluates the rays ``which`` (indices into a, b).  A ray is done when its bracket is narrower
    than ``_HEIGHTFIELD_TOLERANCE`` or |f| at the new point is below it (median 3 evaluations instead of 40
    bisections).
    """
    a, b, fa, fb = a.copy(), b.copy(), fa.copy(), fb.copy()
    side = np.zeros(a.shape, np.int8)  # which end stayed last time: 1 = a, -1 = b (Illinois halves its f)
    live = np.flatnonzero(b - a > _HEIGHTFIELD_TOLERANCE)
    for _ in range(_HEIGHTFIELD_BISECTIONS):
        if live.size == 0:
            break
        la, lb, lfa, lfb = a[live], b[live], fa[live], fb[live]
        with np.errstate(divide="ignore", invalid="ignore"):
            m = la + (lb - la) * lfa / (lfa - lfb)
        bad = ~np.isfinite(m) | (m <= la) | (m >= lb)
        m = np.where(bad, 0.5 * (la + lb), m)
        fm = f(m, live)
        above = fm >= 0.0
        zero = np.abs(fm) <= _HEIGHTFIELD_TOLERANCE  # on the surface to within 1e-10 of a height unit
        # the kept end whose side repeats gets its f halved (Illinois), so the false position moves
        keep_b = above
        repeat = np.where(keep_b, side[live] == -1, side[live] == 1)
        fb_new = np.where(keep_b & repeat, 0.5 * lfb, lfb)
        fa_new = np.where(~keep_b & repeat, 0.5 * lfa, lfa)
        a[live] = np.where(above, m, la)
        fa[live] = np.where(above, fm, fa_new)
        b[live] = np.where(above, lb, m)
        fb[live] = np.where(above, fb_new, fm)
        side[live] = np.where(above, -1, 1)
        b[live] = np.where(zero, m, b[live])
        a[live] = np.where(zero, m, a[live])
        live = live[(b[live] - a[live]) > _HEIGHTFIELD_TOLERANCE]
    return 0.5 * (a + b)


# ------------------------------------------------------------------------------------ height-field kernel
# _ray_heightfield's march and Illinois refinement one ray at a time, with the numpy code's float operations in its
# order (HeightField.height_at's clip, floor and bilinear blend; the samples t_start + span * (k / steps); the
# refinement's false position, bisection fallback and halving), so hits and t are the same bits.


@kernel(inline="always")
def field_height(heights: F64, ox: float, oz: float, spacing: float, x: float, z: float) -> float:
    """HeightField.height_at for one point, in its operations (clip, floor, bilinear blend): for kernels that
    sample a height field (the collider's ray casts, the toon smoke's solid cells)."""
    rows, cols = heights.shape
    gx = minimum(maximum((x - ox) / spacing, 0.0), float(cols - 1))
    gz = minimum(maximum((z - oz) / spacing, 0.0), float(rows - 1))
    c0 = min(int(gx), cols - 2)
    r0 = min(int(gz), rows - 2)
    tx, tz = gx - c0, gz - r0
    h00, h01 = heights[r0, c0], heights[r0, c0 + 1]
    h10, h11 = heights[r0 + 1, c0], heights[r0 + 1, c0 + 1]
    top = h00 + tx * (h01 - h00)
    bottom = h10 + tx * (h11 - h10)
    return top + tz * (bottom - top)


@kernel(inline="always")
def field_distance(heights: F64, ox: float, oz: float, spacing: float, x: float, y: float, z: float) -> float:
    """HeightField.solid_distance for one point, in its operations (the footprint from ``bounds``, y − h over it,
    √(g_x² + u² + g_z²) beside it): for kernels that test what lies inside a height field (the collider's
    distances, the toon smoke's solid cells)."""
    rows, cols = heights.shape
    x_lo, x_hi = ox, ox + (cols - 1) * spacing
    z_lo, z_hi = oz, oz + (rows - 1) * spacing
    gap = y - field_height(heights, ox, oz, spacing, x, z)
    gx = maximum(maximum(x_lo - x, x - x_hi), 0.0)
    gz = maximum(maximum(z_lo - z, z - z_hi), 0.0)
    if gx > 0.0 or gz > 0.0:
        up = maximum(gap, 0.0)
        return np.sqrt(gx * gx + up * up + gz * gz)
    return gap


@kernel
def _heightfield_distance_kernel(p: F64, heights: F64, ox: float, oz: float, spacing: float) -> tuple[F64, bool]:
    """HeightField.solid_distance of every point, with its operations (:func:`field_distance`), and True; False
    as soon as a point's x or z is NaN (the distances then unfinished), where height_at's indexing would fail."""
    n = p.shape[0]
    distance = np.empty(n)
    for i in range(n):  # compiled loop over points
        x, z = p[i, 0], p[i, 2]
        if x != x or z != z:
            return distance, False
        distance[i] = field_distance(heights, ox, oz, spacing, x, p[i, 1], z)
    return distance, True


@kernel(inline="always")
def _ray_height_gap(o: F64, d: F64, i: int, t: float, heights: F64, ox: float, oz: float, spacing: float) -> float:
    """f(t) = y(t) - h(x(t), z(t)) of ray i."""
    x = o[i, 0] + t * d[i, 0]
    y = o[i, 1] + t * d[i, 1]
    z = o[i, 2] + t * d[i, 2]
    return y - field_height(heights, ox, oz, spacing, x, z)


@kernel(inline="always")
def _field_normal(heights: F64, ox: float, oz: float, spacing: float, x_lo: float, x_hi: float, z_lo: float,
                  z_hi: float, x: float, z: float) -> tuple[float, float, float]:
    """HeightField.normal_at for one point: central differences over ±spacing/2, normalised as np.linalg.norm."""
    x, z = minimum(maximum(x, x_lo), x_hi), minimum(maximum(z, z_lo), z_hi)
    e = 0.5 * spacing
    xa, xb = maximum(x - e, x_lo), minimum(x + e, x_hi)
    za, zb = maximum(z - e, z_lo), minimum(z + e, z_hi)
    dhdx = (field_height(heights, ox, oz, spacing, xb, z) - field_height(heights, ox, oz, spacing, xa, z)) / (xb - xa)
    dhdz = (field_height(heights, ox, oz, spacing, x, zb) - field_height(heights, ox, oz, spacing, x, za)) / (zb - za)
    nx, nz = -dhdx, -dhdz
    norm = np.sqrt(nx * nx + 1.0 + nz * nz)
    return nx / norm, 1.0 / norm, nz / norm


@kernel(inline="always")
def _slab_interval(o: float, d: float, lo: float, hi: float) -> tuple[float, float]:
    """One axis of Collider._heightfield_interval: the ray's entry and exit t of lo <= x <= hi (±inf when it runs
    parallel, inside the slab or not), in its operations (1/d, then (lo − o)·inv, (hi − o)·inv)."""
    if d == 0.0:
        if o >= lo and o <= hi:
            return -np.inf, np.inf
        return np.inf, -np.inf
    inv = 1.0 / d
    t1, t2 = (lo - o) * inv, (hi - o) * inv
    return minimum(t1, t2), maximum(t1, t2)


@kernel
def _heightfield_interval_kernel(o: F64, d: F64, lo: F64, hi: F64, max_t: float
                                 ) -> tuple[F64, F64, NDArray[np.bool_], float]:
    """Collider._heightfield_interval for every ray in one pass: [t_start, t_end] inside the box lo..hi and
    [0, max_t], whether it is non-empty (and the ray has a direction), and the longest horizontal travel over the
    active rays (at least 0; NaN when any ray's is NaN, as numpy's max). Its axis reductions run in their order,
    0, 1, 2, with numpy's max/min semantics (engine.jit's ``maximum`` and ``minimum``), so the values are the same bits."""
    n = o.shape[0]
    t_start, t_end, active = np.empty(n), np.empty(n), np.empty(n, np.bool_)
    longest = 0.0
    for i in range(n):  # compiled loop over rays
        near0, far0 = _slab_interval(o[i, 0], d[i, 0], lo[0], hi[0])
        near1, far1 = _slab_interval(o[i, 1], d[i, 1], lo[1], hi[1])
        near2, far2 = _slab_interval(o[i, 2], d[i, 2], lo[2], hi[2])
        start = maximum(maximum(maximum(near0, near1), near2), 0.0)
        end = minimum(minimum(minimum(far0, far1), far2), max_t)
        live = start <= end and (d[i, 0] != 0.0 or d[i, 1] != 0.0 or d[i, 2] != 0.0)
        t_start[i], t_end[i], active[i] = start, end, live
        longest = maximum(longest, hypot_scalar(d[i, 0], d[i, 2]) * (end - start if live else 0.0))
    return t_start, t_end, active, longest


@kernel
def _heightfield_march_kernel(o: F64, d: F64, t_start: F64, t_end: F64, active: NDArray[np.bool_], steps: int,
                              heights: F64, ox: float, oz: float, spacing: float, x_lo: float, x_hi: float,
                              z_lo: float, z_hi: float, max_t: float) -> tuple[NDArray[np.bool_], F64, F64]:
    """(hit, t, local normal) of every ray: a side wall entered below the surface (Collider._heightfield_wall),
    else the first sign change of f over ``steps`` samples of [t_start, t_end], refined, and the field's normal at
    the hit (0 for misses)."""
    n = o.shape[0]
    hit = np.zeros(n, np.bool_)
    t_out = np.full(n, np.inf)
    normal = np.zeros((n, 3))
    for i in range(n):
        near_x, far_x = _slab_interval(o[i, 0], d[i, 0], x_lo, x_hi)
        near_z, far_z = _slab_interval(o[i, 2], d[i, 2], z_lo, z_hi)
        near = maximum(near_x, near_z)
        if near >= 0.0 and near < np.inf and near <= minimum(far_x, far_z) and near <= max_t:
            if _ray_height_gap(o, d, i, near, heights, ox, oz, spacing) < 0.0:
                hit[i], t_out[i] = True, near
                if near_z > near_x:
                    normal[i, 2] = -1.0 if d[i, 2] > 0.0 else 1.0
                else:
                    normal[i, 0] = -1.0 if d[i, 0] > 0.0 else 1.0
                continue
        if not active[i]:
            continue
        span = t_end[i] - t_start[i]
        previous_t = t_start[i]
        previous_f = _ray_height_gap(o, d, i, previous_t, heights, ox, oz, spacing)
        found = False
        a = b = 0.0
        for k in range(1, steps + 1):
            t = t_start[i] + span * (k / steps)
            f = _ray_height_gap(o, d, i, t, heights, ox, oz, spacing)
            if previous_f >= 0.0 and f < 0.0:
                found, a, b = True, previous_t, t
                break
            previous_t, previous_f = t, f
        if not found:
            continue
        hit[i] = True
        fa = _ray_height_gap(o, d, i, a, heights, ox, oz, spacing)
        fb = _ray_height_gap(o, d, i, b, heights, ox, oz, spacing)
        side = 0
        if b - a > _HEIGHTFIELD_TOLERANCE:
            for _ in range(_HEIGHTFIELD_BISECTIONS):
                m = a + (b - a) * fa / (fa - fb)
                if not np.isfinite(m) or m <= a or m >= b:
                    m = 0.5 * (a + b)
                fm = _ray_height_gap(o, d, i, m, heights, ox, oz, spacing)
                above = fm >= 0.0
                repeat = (side == -1) if above else (side == 1)
                if above:
                    if repeat:
                        fb = 0.5 * fb
                    a, fa = m, fm
                    side = -1
                else:
                    if repeat:
                        fa = 0.5 * fa
                    b, fb = m, fm
                    side = 1
                if abs(fm) <= _HEIGHTFIELD_TOLERANCE:
                    a = b = m
                if not b - a > _HEIGHTFIELD_TOLERANCE:
                    break
        t = 0.5 * (a + b)
        t_out[i] = t
        normal[i, 0], normal[i, 1], normal[i, 2] = _field_normal(
            heights, ox, oz, spacing, x_lo, x_hi, z_lo, z_hi, o[i, 0] + t * d[i, 0], o[i, 2] + t * d[i, 2])
    return hit, t_out, normal


# ------------------------------------------------------------------------------------------- box kernels
# One pass over the rows, the same float operations in the same order as the numpy code above (quat_rotate,
# _box_distance, _unit, _ray_box and ray_cast's inside test), so the results are the same bits; numpy's
# maximum/minimum/clip semantics (NaN propagates; of equal values, e.g. -0.0 and 0.0, the second operand) are
# kept by engine.jit's maximum and minimum. Measured (thread_time, one process, numpy and kernel alternated): 100k rows of a rotated
# box, ray_cast 55.8 -> 5.4 ms and query 34.9 -> 4.8 ms median; in the energy wave's 105k-particle step
# (~4.5k rows cast/queried) the collider calls 2.0-2.2 -> 0.22 ms median.


@kernel(inline="always")
def _first_max_axis(a: float, b: float, c: float) -> int:
    """_first_max for one row: argmax of (a, b, c), the first of equal maxima."""
    axis = 1 if b > a else 0
    if c > maximum(a, b):
        axis = 2
    return axis


@kernel(inline="always")
def _rotate(w: float, ux: float, uy: float, uz: float, vx: float, vy: float, vz: float
            ) -> tuple[float, float, float]:
    """quat_rotate for one vector: v' = v + 2u×(u×v + w·v), u = (x, y, z), with cross's products in its order."""
    sx = (uy * vz - uz * vy) + w * vx
    sy = (uz * vx - ux * vz) + w * vy
    sz = (ux * vy - uy * vx) + w * vz
    return vx + 2.0 * (uy * sz - uz * sy), vy + 2.0 * (uz * sx - ux * sz), vz + 2.0 * (ux * sy - uy * sx)


@kernel(inline="always")
def _box_row(px: float, py: float, pz: float, hx: float, hy: float, hz: float
             ) -> tuple[float, float, float, float]:
    """Collider._box_distance for one local point: the exact box SDF (Quilez) and the outward unit normal."""
    q0, q1, q2 = abs(px) - hx, abs(py) - hy, abs(pz) - hz
    m0, m1, m2 = maximum(q0, 0.0), maximum(q1, 0.0), maximum(q2, 0.0)
    outside = np.sqrt(m0 * m0 + m1 * m1 + m2 * m2)
    distance = outside + minimum(maximum(maximum(q0, q1), q2), 0.0)
    if outside > 0.0:  # from the nearest box point clamp(p, -h, h) to p, as _unit does it
        vx = px - minimum(maximum(px, -hx), hx)
        vy = py - minimum(maximum(py, -hy), hy)
        vz = pz - minimum(maximum(pz, -hz), hz)
        norm = np.sqrt(vx * vx + vy * vy + vz * vz)
        if norm > 0.0:
            return distance, vx / norm, vy / norm, vz / norm
        return distance, 0.0, 1.0, 0.0
    axis = _first_max_axis(q0, q1, q2)
    if axis == 0:
        return distance, (1.0 if px >= 0.0 else -1.0), 0.0, 0.0
    if axis == 1:
        return distance, 0.0, (1.0 if py >= 0.0 else -1.0), 0.0
    return distance, 0.0, 0.0, (1.0 if pz >= 0.0 else -1.0)


@kernel
def _box_query_kernel(points: F64, position: F64, q: F64, inverse: F64, h: F64) -> tuple[F64, F64, F64]:
    """Box signed distance d (N,), penetration depth z = max(0, -d) (eq. 3.2 of the energy wave's thesis) and
    outward world normal (N, 3) of world points: Collider.query / signed_distance for a box in one pass."""
    n = points.shape[0]
    distance, depth, normal = np.empty(n), np.empty(n), np.empty((n, 3))
    for i in range(n):  # compiled loop over points
        lx, ly, lz = _rotate(inverse[0], inverse[1], inverse[2], inverse[3], points[i, 0] - position[0],
                             points[i, 1] - position[1], points[i, 2] - position[2])
        d, nx, ny, nz = _box_row(lx, ly, lz, h[0], h[1], h[2])
        distance[i] = d
        depth[i] = maximum(0.0, -d)
        normal[i, 0], normal[i, 1], normal[i, 2] = _rotate(q[0], q[1], q[2], q[3], nx, ny, nz)
    return distance, depth, normal


@kernel(inline="always")
def _slab(o: float, d: float, h: float) -> tuple[float, float]:
    """One axis of the slab method (Kay & Kajiya 1986): the ray's entry and exit t of |x| <= h."""
    if d == 0.0:  # parallel: inside the slab for every t or never
        if abs(o) <= h:
            return -np.inf, np.inf
        return np.inf, -np.inf
    inv = 1.0 / d
    t1, t2 = (-h - o) * inv, (h - o) * inv
    return minimum(t1, t2), maximum(t1, t2)


@kernel
def _box_ray_cast_kernel(origins: F64, dirs: F64, position: F64, q: F64, inverse: F64, h: F64, max_t: float
                         ) -> tuple[NDArray[np.bool_], F64, F64]:
    """Collider.ray_cast for a box in one pass: slab method (Kay & Kajiya 1986) in the box frame, a ray starting
    inside (signed distance < 0) hits at t = 0 with the nearest face's normal; misses have t = inf, normal 0."""
    n = origins.shape[0]
    hit, t, normal = np.empty(n, dtype=np.bool_), np.empty(n), np.empty((n, 3))
    for i in range(n):  # compiled loop over rays
        ox, oy, oz = _rotate(inverse[0], inverse[1], inverse[2], inverse[3], origins[i, 0] - position[0],
                             origins[i, 1] - position[1], origins[i, 2] - position[2])
        dx, dy, dz = _rotate(inverse[0], inverse[1], inverse[2], inverse[3], dirs[i, 0], dirs[i, 1], dirs[i, 2])
        a0, b0 = _slab(ox, dx, h[0])
        a1, b1 = _slab(oy, dy, h[1])
        a2, b2 = _slab(oz, dz, h[2])
        t_near = maximum(maximum(a0, a1), a2)
        t_far = minimum(minimum(b0, b1), b2)
        distance, nx, ny, nz = _box_row(ox, oy, oz, h[0], h[1], h[2])
        if distance < 0.0:
            hit[i], t[i] = True, 0.0
        elif t_near <= t_far and t_near >= 0.0 and t_near <= max_t:
            hit[i], t[i] = True, t_near
            axis = _first_max_axis(a0, a1, a2)
            nx = ny = nz = 0.0
            if axis == 0:
                nx = -1.0 if dx > 0.0 else 1.0
            elif axis == 1:
                ny = -1.0 if dy > 0.0 else 1.0
            else:
                nz = -1.0 if dz > 0.0 else 1.0
        else:
            hit[i], t[i] = False, np.inf
            nx = ny = nz = 0.0
        normal[i, 0], normal[i, 1], normal[i, 2] = _rotate(q[0], q[1], q[2], q[3], nx, ny, nz)
    return hit, t, normal
