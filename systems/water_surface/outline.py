"""The body outline in the water model (seeds/003, sections 2.2.2, 2.2.3 and 2.3.1), vectorized over bodies.

1. Cross-section D' of each body with the horizontal plane S' at the mean water height where the body is
   (section 2.2.2): box edges QR whose ends lie on opposite sides of S' give the points L' (the ordinary
   line–plane intersection; the printed eq. 2.1 is garbled), sorted counter-clockwise; a sphere gives a regular
   polygon inscribed in its circle of intersection.
2. Points of D' on a grid line or vertex are nudged slightly inwards (figure 2.3).
3. Added points N (section 2.2.3): the vertices L' and the crossings M' of D''s edges with the grid lines, in
   order along the outline, with the outline segments between consecutive points.
4. Wave generation (eq. 2.5–2.7): d(t) is how far the outline moved at N_c in one step; N_c rises by α·d(t)
   when its position at t − 1 lies inside the cross-section at t, and sinks by α·d(t) when its position at t
   lay inside the cross-section at t − 1.
5. Coupling with the grid (eq. 2.11, 2.12): pairs of points within radius h with weights r_k / h = 1 − |PN| / h,
   and the grid vertices inside the cross-section, which become a reflecting obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from engine import exact
from engine.exact import atan2, matmul
from systems.water_surface.geometry import (BOX, EPS_LINE, F64, I64, NUDGE, Bodies, Grid, all_of, any_of, max_of,
                                            min_of, ranges, sum_of)

__all__ = ["AddedPoints", "Edges", "Sections", "added_points", "coupling_pairs", "cross_sections", "cut_edges",
           "nearest_on_outline", "nudge", "outline_impulse", "solid_vertices", "through_bodies"]

# Box corners c = (sx, sy, sz) ∈ {−1, 1}³ and its 12 edges (corner pairs that differ along one axis).
_SIGNS = np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)])
_EDGES = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)
                   if np.count_nonzero(_SIGNS[a] != _SIGNS[b]) == 1], dtype=np.int64)
_EA, _EB = _EDGES[:, 0], _EDGES[:, 1]


def _shared_faces() -> np.ndarray:
    """(12, 12) table: the box face (2·axis + (sign > 0)) two edges share, or −1."""
    faces = []
    for a, b in _EDGES:
        fixed = np.flatnonzero(_SIGNS[a] == _SIGNS[b])
        faces.append({2 * int(ax) + int(_SIGNS[a][ax] > 0) for ax in fixed})
    table = -np.ones((12, 12), np.int64)
    for i in range(12):
        for j in range(12):
            common = faces[i] & faces[j]
            if i != j and common:
                table[i, j] = min(common)
    return table


_SHARED_FACE = _shared_faces()
_MAX_BOX_VERTICES = 6  # a plane cuts a box in at most a hexagon
_ON_OUTLINE = 3.0 * NUDGE  # grid units: this close to the outline counts as on it in eq. 2.6 / 2.7 (> the nudge)
_HALF_CELLS = np.array([(0, 0), (1, 0), (-1, 1), (0, 1), (1, 1)], np.int64)  # the own square first
# The same tables for the compiled step (kernels.py): the box's edges as corner pairs, the face two edges share.
EDGE_A, EDGE_B = np.ascontiguousarray(_EA), np.ascontiguousarray(_EB)
SHARED_FACE, MAX_BOX_VERTICES = _SHARED_FACE, _MAX_BOX_VERTICES


@dataclass
class Edges:
    """The edges k → k + 1 of padded polygons (B, V): start, direction, and the inward half-plane of each
    (n·p > c inside; padding edges have n = 0, c = −∞ so every point is inside them).

    Vectors are stored coordinate-major, (2, B, V): one numpy call handles both coordinates, and the innermost
    axis stays long (V) when they are broadcast against many points (a trailing axis of 2 is slow)."""

    start: F64  # (2, B, V)
    e: F64  # (2, B, V) end − start
    n: F64  # (2, B, V) inward unit normal (0 on padding and zero-length edges)
    c: F64  # (B, V)
    valid: np.ndarray  # (B, V)
    length2: F64  # (B, V) |e|², 1 where it is 0 (a safe divisor)
    _table: F64 | None = None

    @staticmethod
    def of(polygons: F64, counts: I64) -> Edges:
        b, v = polygons.shape[:2]
        k = np.arange(v)
        valid = k < counts[:, None]
        nxt = np.where(k + 1 < counts[:, None], k + 1, 0)
        start = np.ascontiguousarray(polygons.transpose(2, 0, 1))
        e = start[:, np.arange(b)[:, None], nxt] - start
        ee = e * e
        length2 = ee[0] + ee[1]
        length = exact.hypot(e[0], e[1])
        real = valid & (length > 0.0)
        inv = np.where(real, 1.0 / np.where(real, length, 1.0), 0.0)
        n = e[::-1] * (inv * _FLIP)  # (−e_y, e_x) / |e|: the inward (left) normal
        ns = n * start
        c = np.where(real, ns[0] + ns[1], -np.inf)
        return Edges(start, e, n, c, valid, np.where(length2 > 0.0, length2, 1.0))

    @property
    def table(self) -> F64:
        """(9, V, B), per edge: start (2 rows), direction (2), inward normal (2), c, |e|², and 0 on a real edge,
        ∞ on padding. c is +∞ on every edge of a polygon with fewer than 3 vertices (it contains nothing).

        Edge-major with the polygons last: taking each point's polygon along the last axis gives (9, V, P) rows
        that broadcast against the points' coordinates (P,), all in one gather (``take``: a fancy index on a
        leading axis costs several times more)."""
        if self._table is None:
            c = np.where(self.valid[:, 2:3], self.c, np.inf)
            rows = (self.start[0], self.start[1], self.e[0], self.e[1], self.n[0], self.n[1], c, self.length2,
                    np.where(self.valid, 0.0, np.inf))
            self._table = np.ascontiguousarray(np.stack(rows).transpose(0, 2, 1))
        return self._table

    def columns(self, v: int) -> Edges:
        """The first ``v`` ≥ 3 edge slots of every polygon (views): all of the edges of polygons with at most ``v``
        vertices."""
        if v >= self.c.shape[1]:
            return self
        return Edges(self.start[..., :v], self.e[..., :v], self.n[..., :v], self.c[:, :v], self.valid[:, :v],
                     self.length2[:, :v], self.table[:, :v])

    def inside(self, points: F64, body: I64, margin: float) -> np.ndarray:
        """Whether ``points[p]`` lies inside polygon ``body[p]`` by more than ``margin`` (negative: on or near the
        outline counts too). Polygons with fewer than 3 vertices contain nothing."""
        if len(points) == 0:
            return np.zeros(0, bool)
        u, v = np.ascontiguousarray(points.T)
        return _inside(self.table[4:7].take(body, axis=2), u, v, margin)


def _inside(rows: F64, u: F64, v: F64, margin: float) -> np.ndarray:
    """Points (u, v) inside by more than ``margin``, given the rows (normal u, normal v, c) of their polygons'
    edges, (3, V, P) from :attr:`Edges.table`."""
    d = rows[0] * u + rows[1] * v
    return all_of((d - rows[2]) > margin, axis=0)


def _nearest(rows: F64, u: F64, v: F64) -> tuple[F64, F64]:
    """The point of each polygon's outline nearest to (u, v), given its edges' rows (9, V, P) of
    :attr:`Edges.table`: the projection onto each edge, clamped to it, and the closest of those."""
    ax, ay, ex, ey = rows[0], rows[1], rows[2], rows[3]
    t = np.minimum(np.maximum(((u - ax) * ex + (v - ay) * ey) / rows[7], 0.0), 1.0)
    fx, fy = ax + t * ex, ay + t * ey
    dx, dy = fx - u, fy - v
    dist2 = dx * dx + dy * dy + rows[8]
    p = len(u)
    best = dist2.argmin(axis=0) * p + np.arange(p)
    return fx.ravel().take(best), fy.ravel().take(best)


_FLIP = np.array([-1.0, 1.0])[:, None, None]


@dataclass
class Sections:
    """Cross-sections D' (B, V, 2) in grid units with their feature ids (for the added points' keys)."""

    polygons: F64
    counts: I64
    vertex_feature: I64  # (B, V): the box edge or sphere vertex each L' comes from
    edge_feature: I64  # (B, V): the box face or sphere edge that edge k → k + 1 lies on
    _edges: Edges | None = None

    @property
    def edges(self) -> Edges:
        if self._edges is None:
            self._edges = Edges.of(self.polygons, self.counts)
        return self._edges

    def with_polygons(self, polygons: F64) -> Sections:
        return Sections(polygons, self.counts, self.vertex_feature, self.edge_feature)

    def centres(self) -> F64:
        valid = (np.arange(self.polygons.shape[1]) < self.counts[:, None])[..., None]
        return np.sum(np.where(valid, self.polygons, 0.0), axis=1) / np.maximum(self.counts, 1)[:, None]


def cross_sections(bodies: Bodies, plane_y: F64, grid: Grid, sphere_segments: int) -> Sections:
    """Cross-section polygon D' of every body with the horizontal plane y = plane_y[b] (section 2.2.2)."""
    n = len(bodies)
    is_box = bodies.shapes == BOX
    boxes, spheres = bool(any_of(is_box, axis=None)), not bool(all_of(is_box, axis=None))
    width = max(_MAX_BOX_VERTICES if boxes else 0, sphere_segments if spheres else 0, 3)
    if boxes and not spheres and width == _MAX_BOX_VERTICES:  # the common case: only boxes
        p, c, f = _box_sections(bodies, plane_y, grid)
        return Sections(p, c, f, _box_edge_faces(f, c))
    polygons = np.zeros((n, width, 2))
    counts = np.zeros(n, np.int64)
    vfeat = np.zeros((n, width), np.int64)
    efeat = np.zeros((n, width), np.int64)
    if boxes:
        idx = np.flatnonzero(is_box)
        p, c, f = _box_sections(bodies.take(idx), plane_y[idx], grid)
        polygons[idx, :_MAX_BOX_VERTICES], counts[idx], vfeat[idx, :_MAX_BOX_VERTICES] = p, c, f
        efeat[idx, :_MAX_BOX_VERTICES] = _box_edge_faces(f, c)
    if spheres:
        idx = np.flatnonzero(~is_box)
        p, c = _sphere_sections(bodies.take(idx), plane_y[idx], grid, sphere_segments)
        polygons[idx, :sphere_segments], counts[idx] = p, c
        vfeat[idx, :sphere_segments] = np.arange(sphere_segments)
        efeat[idx, :sphere_segments] = np.arange(sphere_segments)
    return Sections(polygons, counts, vfeat, efeat)


def _box_edge_faces(feature: I64, counts: I64) -> I64:
    """The face each polygon edge lies on: the one its two box edges share."""
    k = np.arange(_MAX_BOX_VERTICES)
    following = np.where(k + 1 < counts[:, None], k + 1, 0) + (_MAX_BOX_VERTICES * np.arange(len(feature)))[:, None]
    shared = _SHARED_FACE.ravel().take(feature * 12 + feature.ravel().take(following))
    return np.where(shared >= 0, shared, 6 + k)


_CORNERS_T = np.ascontiguousarray(_SIGNS.T)  # (3, 8): the corners coordinate-major


def _box_sections(bodies: Bodies, plane_y: F64, grid: Grid) -> tuple[F64, I64, I64]:
    corners = matmul(bodies.rotation, _CORNERS_T * bodies.half[:, :, None]) + bodies.position[:, :, None]  # (B, 3, 8)
    q, r = corners.take(_EA, axis=2), corners.take(_EB, axis=2)  # (B, 3, 12): the two corners Q, R of each edge
    yq, yr = q[:, 1] - plane_y[:, None], r[:, 1] - plane_y[:, None]
    straddle = (yq >= 0.0) != (yr >= 0.0)
    t = yq / np.where(straddle, yq - yr, 1.0)  # L = Q + t·(R − Q) on the plane
    u = (q[:, 0] + t * (r[:, 0] - q[:, 0]) - grid.x0) / grid.h
    v = (q[:, 2] + t * (r[:, 2] - q[:, 2]) - grid.z0) / grid.h
    exact = bool(any_of(yq == 0.0, axis=None) or any_of(yr == 0.0, axis=None))
    return _sort_ccw(u, v, straddle, exact)


def _sort_ccw(u: F64, v: F64, valid: np.ndarray, exact: bool) -> tuple[F64, I64, I64]:
    """The valid points (u, v) of each row counter-clockwise about their centroid (first 6 columns), their count
    and the column each came from; with ``exact`` (a box corner on the plane) repeated points are dropped."""
    n = sum_of(valid, axis=1, dtype=np.int64)
    inv = 1.0 / np.maximum(n, 1)
    cu = sum_of(np.where(valid, u, 0.0), axis=1) * inv
    cv = sum_of(np.where(valid, v, 0.0), axis=1) * inv
    angle = np.where(valid, atan2(v - cv[:, None], u - cu[:, None]), np.inf)
    order = angle.argsort(axis=1, kind="stable")[:, :_MAX_BOX_VERTICES]
    flat = order + (u.shape[1] * np.arange(len(u)))[:, None]
    polygons = np.empty(flat.shape + (2,))
    polygons[..., 0], polygons[..., 1] = u.ravel().take(flat), v.ravel().take(flat)
    if exact:  # a box vertex on the plane gives the same L' from several edges: keep one
        rows = np.arange(len(u))[:, None]
        k = np.arange(_MAX_BOX_VERTICES)
        prev = polygons[rows, np.where(k == 0, n[:, None] - 1, k - 1).clip(0)]
        repeat = (k < n[:, None]) & (np.sum((polygons - prev) ** 2, axis=-1) < 1e-20) & (k > 0)
        keep = (k < n[:, None]) & ~repeat
        again = np.argsort(~keep, axis=1, kind="stable")
        polygons, order, n = polygons[rows, again], order[rows, again], keep.sum(axis=1)
    return polygons, np.where(n >= 3, n, 0), order


@lru_cache(maxsize=8)
def sphere_ring(segments: int) -> F64:
    """(segments, 2) unit circle counter-clockwise in (u, v)."""
    angles = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([exact.cos(angles), exact.sin(angles)], axis=-1)
    ring.setflags(write=False)
    return ring


def _sphere_sections(bodies: Bodies, plane_y: F64, grid: Grid, segments: int) -> tuple[F64, I64]:
    d = plane_y - bodies.position[:, 1]
    rho2 = bodies.radius ** 2 - d ** 2
    rho = np.sqrt(np.maximum(rho2, 0.0)) / grid.h
    centre = grid.to_uv(bodies.position[:, ::2])
    polygons = centre[:, None, :] + rho[:, None, None] * sphere_ring(segments)[None, :, :]
    return polygons, np.where(rho2 > 0.0, segments, 0).astype(np.int64)


def nudge(sections: Sections) -> Sections:
    """Move polygon vertices that lie on a grid line (or vertex) slightly inwards (section 2.2.2, figure 2.3), so
    an added point never sits on a grid vertex and a vertex on a grid edge adds no extra point."""
    p = sections.polygons
    valid = (np.arange(p.shape[1]) < sections.counts[:, None])[..., None]
    on = (np.abs(p - np.rint(p)) < EPS_LINE) & valid
    if not any_of(on, axis=None):
        return sections
    centre = sections.centres()[:, None, :]
    towards = centre - p
    length = np.linalg.norm(towards, axis=-1, keepdims=True)
    p = np.where(on.any(axis=-1, keepdims=True), p + NUDGE * towards / np.where(length > 0.0, length, 1.0), p)
    on = (np.abs(p - np.rint(p)) < EPS_LINE) & valid
    if any_of(on, axis=None):  # moving towards the centre ran along the line: step off it towards the centre's side
        p = np.where(on, p + NUDGE * np.where(centre - p >= 0.0, 1.0, -1.0), p)
    return sections.with_polygons(p)


@dataclass
class AddedPoints:
    """Points added to the water model, in order along each body's outline (section 2.2.3)."""

    uv: F64  # (M, 2) grid units
    kind: np.ndarray  # (M,) int8: 0 on a line u = i, 1 on a line v = j, 2 a vertex L' of D'
    keys: I64  # (M,) identity from step to step: (entity, feature, grid line)
    body: I64  # (M,) index of the body (into the Bodies of this step)
    segments: I64  # (K, 2) consecutive points along the outline (counter-clockwise: the body is on the left)

    def __len__(self) -> int:
        return len(self.uv)

    @staticmethod
    def empty() -> AddedPoints:
        z = np.zeros(0, np.int64)
        return AddedPoints(np.zeros((0, 2)), np.zeros(0, np.int8), z, z, np.zeros((0, 2), np.int64))


def added_points(sections: Sections, entities: I64, grid: Grid) -> tuple[AddedPoints, Sections]:
    """The vertices L' and grid-edge crossings M' of every cross-section, ordered along the outline; points off
    the grid's footprint and the segments touching them are dropped. Returns the points and the sections they
    were cut from (shrunk a hair in the rare case where an edge of D' passes exactly through a grid vertex).

    A point's key (its identity from step to step) is (entity, crossing or vertex, box edge / face or sphere
    vertex / edge, which family of grid lines, grid line), packed in an int64."""
    points = None
    for attempt in range(4):
        points = _outline(sections, strict=attempt < 3)
        if points is not None:
            break
        centre = sections.centres()[:, None, :]
        sections = sections.with_polygons(centre + (sections.polygons - centre) * (1.0 - 1e-6 * (attempt + 1)))
    uv, kind, keys, body, sort_key = points
    n = len(uv)
    if n == 0:
        return AddedPoints.empty(), sections
    order = sort_key.argsort(kind="stable")
    uv, kind, body = uv.take(order, axis=0), kind.take(order), body.take(order)
    keys = (entities.take(body).astype(np.int64) << 32) | keys.take(order)
    nxt = np.arange(1, n + 1)
    if body[0] == body[-1]:  # one outline: it closes on its first point
        nxt[-1] = 0
    else:
        change = np.empty(n + 1, bool)
        change[0] = change[n] = True
        np.not_equal(body[1:], body[:-1], out=change[1:n])
        last = change[1:]
        nxt[last] = np.flatnonzero(change[:n])
    u, v = uv[:, 0], uv[:, 1]
    keep = (u >= 0.0) & (u <= grid.nx - 1) & (v >= 0.0) & (v <= grid.nz - 1)  # on the grid's footprint
    if all_of(keep, axis=None):
        segments = np.empty((n, 2), np.int64)
        segments[:, 0] = np.arange(n)
        segments[:, 1] = nxt
        return AddedPoints(uv, kind, keys, body, segments), sections
    remap = np.cumsum(keep) - 1
    seg_ok = keep & keep[nxt]
    segments = np.stack([remap[seg_ok], remap[nxt[seg_ok]]], axis=-1)
    return AddedPoints(uv[keep], kind[keep], keys[keep], body[keep], segments), sections


_CROSSING_KEY = 1 << 30


def _outline(sections: Sections, strict: bool):
    """Vertices and crossings (unsorted): (uv, kind, key without the entity, body, sort key ordering them along
    the outline: body, edge, t); None if, with ``strict``, an edge crosses a grid vertex. Both families of grid
    lines (u = i: axis 0, v = j: axis 1) are handled in one pass over the (edge, axis) pairs."""
    e = sections.edges
    width = sections.polygons.shape[1]
    real = e.valid.ravel().nonzero()[0]  # flat (body, edge) index of the real edges
    eb = real // width
    a, d = e.start.reshape(2, -1).take(real, axis=1), e.e.reshape(2, -1).take(real, axis=1)  # (2, E): u, v rows
    n = len(real)
    base = real.astype(np.float64) * 2.0  # edge index; t ∈ (0, 1) after it
    b = a + d
    lo = np.floor(np.minimum(a, b)).astype(np.int64)
    hi = np.floor(np.maximum(a, b)).astype(np.int64)
    run, line = ranges((lo + 1).ravel(), (hi - lo).ravel())  # run = axis·E + edge
    axis, edge = np.divmod(run, max(n, 1))
    af, df = a.ravel(), d.ravel()
    t = (line - af.take(run)) / df.take(run)
    across = run + np.where(axis == 0, n, -n)  # the same edge, the other coordinate
    other = af.take(across) + t * df.take(across)
    if strict and any_of((np.abs(other - np.rint(other)) < EPS_LINE) & (axis == 0), axis=None):
        return None
    on_u = axis == 0
    m = len(run)
    uv = np.empty((n + m, 2))
    uv[:n] = a.T
    uv[n:, 0] = np.where(on_u, line, other)
    uv[n:, 1] = np.where(on_u, other, line)
    kind = np.empty(n + m, np.int8)
    kind[:n] = 2
    kind[n:] = axis
    keys = np.empty(n + m, np.int64)
    keys[:n] = sections.vertex_feature.ravel().take(real) << 22
    keys[n:] = (sections.edge_feature.ravel().take(real).take(edge) << 22) | (axis << 21) | line | _CROSSING_KEY
    return uv, kind, keys, np.concatenate([eb, eb.take(edge)]), np.concatenate([base, base.take(edge) + t])


# ---------------------------------------------------------------------------------------- wave generation
def outline_impulse(points: AddedPoints, sections: Sections, previous: Sections, has_previous: np.ndarray,
                    grid: Grid, alpha: float) -> tuple[F64, F64, np.ndarray, np.ndarray]:
    """±α·d(t) for every added point (eq. 2.5–2.7).

    N_c(t − 1), the added point one step earlier, is the point of the previous cross-section D'(t − 1) nearest to
    N_c(t): so d(t) is how far the outline moved there, whatever moved it (the body gliding, turning, or bobbing
    with sloped sides). N_c rises by α·d(t) when N_c(t − 1) lies inside D'(t) (the body pushed that water aside)
    and sinks by α·d(t) when N_c(t) lay inside D'(t − 1) (the body left that space). The outline itself counts as
    inside (a corner gliding along a side was on D'(t) at t − 1). The rises and falls of one body balance: the
    outline's points are not evenly spaced, so the raw ±α·d(t) would create or remove water; the body's mean
    change is taken off all of its points (so a body whose section only grows or shrinks, sinking or rising,
    makes almost no wave: eq. 2.6 as printed made a floating sphere pump its own bobbing; see the effect's docs,
    "Deviations"). Bodies without a cross-section at t − 1 make no wave this step.
    Returns (change of height, d(t) in metres, raised, lowered).
    """
    if len(points) == 0:
        empty = np.zeros(0)
        return empty, empty, np.zeros(0, bool), np.zeros(0, bool)
    bi = points.body
    old = (has_previous & (previous.counts >= 3))[bi]
    every = bool(all_of(old, axis=None))
    back, raised, lowered = _against_outlines(points.uv, bi, previous.edges, sections.edges)
    if not every:
        back = np.where(old[:, None], back, points.uv)
    gap = points.uv - back
    d = exact.hypot(gap[:, 0], gap[:, 1]) * grid.h  # eq. 2.5
    if not every:
        raised &= old
        lowered &= old
    change = alpha * d * np.subtract(raised, lowered, dtype=np.float64)  # eq. 2.6 / 2.7
    nb = len(has_previous)
    mean = np.bincount(bi, change, nb) / np.maximum(np.bincount(bi, minlength=nb), 1)
    return change - mean[bi], d, raised, lowered


def _against_outlines(uv: F64, body: I64, before: Edges, after: Edges) -> tuple[F64, np.ndarray, np.ndarray]:
    """For the added points N_c(t) = ``uv`` of polygons ``body``: N_c(t − 1) (the nearest point of D'(t − 1)),
    whether N_c(t − 1) lies inside D'(t) and whether N_c(t) lay inside D'(t − 1), the outline counting as inside.

    The (edge, point) arrays are as wide as the polygons are padded: the points of polygons with at most six
    edges (boxes) are handled apart from those of wider ones (spheres), so they are not padded to a sphere's
    width (smaller work, and arrays that stay small enough for the allocator to reuse their memory)."""
    groups = [(None, before, after)]
    if before.c.shape[1] > _MAX_BOX_VERTICES:
        used = np.maximum(sum_of(before.valid, axis=1), sum_of(after.valid, axis=1))
        narrow = (used <= _MAX_BOX_VERTICES).take(body)
        if all_of(narrow, axis=None):
            groups = [(None, before.columns(_MAX_BOX_VERTICES), after.columns(_MAX_BOX_VERTICES))]
        elif any_of(narrow, axis=None):
            groups = [(narrow.nonzero()[0], before.columns(_MAX_BOX_VERTICES), after.columns(_MAX_BOX_VERTICES)),
                      ((~narrow).nonzero()[0], before, after)]
    coordinates = np.ascontiguousarray(uv.T)
    back, raised, lowered = np.empty((2, len(uv))), np.empty(len(uv), bool), np.empty(len(uv), bool)
    for index, old, new in groups:
        u, v = coordinates if index is None else coordinates.take(index, axis=1)
        b = body if index is None else body.take(index)
        rows = old.table.take(b, axis=2)
        bu, bv = _nearest(rows, u, v)
        inside_new = _inside(new.table[4:7].take(b, axis=2), bu, bv, -_ON_OUTLINE)
        inside_old = _inside(rows[4:7], u, v, -_ON_OUTLINE)
        if index is None:
            return np.stack([bu, bv], axis=-1), inside_new, inside_old
        back[0, index], back[1, index], raised[index], lowered[index] = bu, bv, inside_new, inside_old
    return back.T, raised, lowered


def _per_point(values: np.ndarray, body: I64, axis: int = 0) -> np.ndarray:
    """``values`` taken at ``body`` along ``axis``, or ``values`` itself when there is one body (it broadcasts)."""
    if values.shape[axis] == 1:
        return values
    return values.take(body, axis=axis)


def nearest_on_outline(points: F64, body: I64, edges: Edges) -> F64:
    """The point of polygon ``body[p]``'s outline nearest to ``points[p]``."""
    u, v = np.ascontiguousarray(points.T)
    return np.stack(_nearest(edges.table.take(body, axis=2), u, v), axis=-1)


# ------------------------------------------------------------------------------------------- coupling
def solid_vertices(sections: Sections, grid: Grid) -> tuple[I64, I64]:
    """Grid vertices strictly inside some cross-section: (flat vertex index, body index), by body, row and column.
    In the outline method they are inside the body, so the water there is not simulated and waves reflect at the
    outline.

    Scanline fill: every grid row v = j through a polygon meets its outline at two points (it is convex, and its
    vertices are off the grid lines); the vertices strictly between them are inside.
    """
    e = sections.edges
    v = sections.polygons[..., 1]
    cut = sections.counts >= 3
    lo = np.where(cut, np.maximum(np.ceil(min_of(np.where(e.valid, v, np.inf), axis=1)), 0), 0).astype(np.int64)
    hi = np.where(cut, np.minimum(np.floor(max_of(np.where(e.valid, v, -np.inf), axis=1)), grid.nz - 1),
                  -1).astype(np.int64)
    body, row = ranges(lo, np.maximum(hi - lo + 1, 0))
    if len(body) == 0:
        return body, body
    table = e.table  # edge-major rows: (V, R) arrays against the rows (R,)
    au, av, du, dv = (table[r].take(body, axis=1) for r in range(4))
    flat = dv != 0.0
    t = (row - av) / np.where(flat, dv, np.inf)
    u = au + t * du
    crosses = (t >= 0.0) & (t < 1.0) & (flat & (table[8].take(body, axis=1) == 0.0))
    left = min_of(np.where(crosses, u, np.inf), axis=0)
    right = max_of(np.where(crosses, u, -np.inf), axis=0)
    ok = (left < np.inf) & (right > -np.inf)
    first = np.where(ok, np.maximum(np.floor(np.where(ok, left, 0.0) + 1e-9) + 1, 0), 0).astype(np.int64)
    last = np.where(ok, np.minimum(np.ceil(np.where(ok, right, 0.0) - 1e-9) - 1, grid.nx - 1), -1).astype(np.int64)
    run, i = ranges(first, np.maximum(last - first + 1, 0))
    return row[run] * grid.nx + i, body[run]


_CORNER_U = np.array([0.0, 1.0, 0.0, 1.0])[:, None]  # the corners (i + a, j + b) of a point's square, a, b ∈ {0, 1}
_CORNER_V = np.array([0.0, 0.0, 1.0, 1.0])[:, None]
_DENSE_PAIRS = 96  # up to this many added points, their pairs come from the full distance matrix


def coupling_pairs(points: AddedPoints, fluid: np.ndarray, grid: Grid, solid_mask: bool = False,
                   slots: I64 | None = None) -> tuple[I64, I64, F64, I64, I64, F64]:
    """Neighbours within radius h for eq. 2.11 / 2.12, with weights r_k / h = 1 − distance / h.

    ``fluid`` marks the water vertices (with ``solid_mask``, it marks the vertices inside bodies instead).

    Returns (grid vertex, added point, weight) for the pairs between the grid and the added points (vertices
    inside a body excluded), and (point, point, weight) for the pairs of added points, both directions. A grid
    vertex within h of a point is a corner of the point's square. Few points: their pairs come from the full
    distance matrix; many: points within h of each other lie in the same or neighbouring squares, so they are
    found by sorting the points by square and looking up each point's own square and half of the 8 around it
    (the other half finds it). Coordinates are handled one at a time (arrays (4, M), (M,), never (..., 2)).
    ``slots``: an optional int64 work array of at least (nz + 2)·(nx + 3) entries (its contents do not matter).
    """
    m = len(points)
    if m == 0:
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0), z, z, np.zeros(0)
    u, v = np.ascontiguousarray(points.uv.T)
    fu, fv = np.floor(u), np.floor(v)
    iu, iv = fu.astype(np.int64), fv.astype(np.int64)
    cu, cv = fu + _CORNER_U, fv + _CORNER_V  # (4, M) corners of each point's square
    du, dv = cu - u, cv - v
    dist = np.sqrt(du * du + dv * dv)  # (np.hypot is several times slower)
    ok = (dist < 1.0) & (cu < grid.nx) & (cv < grid.nz)  # points lie on the footprint
    flat = np.where(ok, (iv * grid.nx + iu) + np.array([0, 1, grid.nx, grid.nx + 1])[:, None], 0)
    if solid_mask:
        ok &= ~fluid.ravel()[flat]
    else:
        ok &= fluid.ravel()[flat]
    p_idx, c_idx = ok.T.nonzero()  # point by point
    pair = c_idx * m + p_idx
    g = flat.ravel().take(pair)
    w = 1.0 - dist.ravel().take(pair)
    if m <= _DENSE_PAIRS:
        du, dv = u[:, None] - u[None, :], v[:, None] - v[None, :]
        dd = np.sqrt(du * du + dv * dv)
        close = dd < 1.0
        np.fill_diagonal(close, False)
        a, b = close.nonzero()
        return g, p_idx, w, a, b, 1.0 - dd[a, b]
    stride = grid.nx + 3
    cell = (iv + 1) * stride + iu + 1
    order = cell.argsort(kind="stable")
    sorted_cell = cell[order]
    wanted = (cell[:, None] + (_HALF_CELLS[:, 1] * stride + _HALF_CELLS[:, 0])).ravel()
    if slots is None or len(slots) < (grid.nz + 2) * stride:
        lo = np.searchsorted(sorted_cell, wanted, "left")
        count = np.searchsorted(sorted_cell, wanted, "right") - lo
    else:  # the squares' runs in the sorted points looked up through ``slots`` instead of a binary search
        start = np.empty(m, bool)
        start[0] = True
        np.not_equal(sorted_cell[1:], sorted_cell[:-1], out=start[1:])
        start = start.nonzero()[0]
        length = np.empty(len(start), np.int64)
        np.subtract(start[1:], start[:-1], out=length[:-1])
        length[-1] = m - start[-1]
        slots[sorted_cell[start]] = np.arange(len(start))
        found = np.minimum(np.maximum(slots[wanted], 0), len(start) - 1)  # unwritten slots hold anything
        hit = sorted_cell[start[found]] == wanted  # true only where the square holds points (so its slot is fresh)
        lo = start[found]
        count = np.where(hit, length[found], 0)
    run, pos = ranges(lo, count)
    first, around = np.divmod(run, len(_HALF_CELLS))
    second = order[pos]
    du, dv = u.take(first) - u.take(second), v.take(first) - v.take(second)
    dd = np.sqrt(du * du + dv * dv)
    # each unordered pair once: across squares from the half neighbourhood, inside a square when first < second
    close = (dd < 1.0) & ((around > 0) | (first < second))
    a, b, weight = first[close], second[close], 1.0 - dd[close]
    return g, p_idx, w, np.concatenate([a, b]), np.concatenate([b, a]), np.concatenate([weight, weight])


PEEK = 1e-3  # grid units: how far along a coupling pair its end on an outline looks into the cross-section
PEEK_MARGIN = 1e-9  # inside by more than this (a pair along one edge of D' stays on it: about 1e-13 off)


def _enters(rows: F64, pu: F64, pv: F64, tu: F64, tv: F64) -> np.ndarray:
    """Whether the segments from points (pu, pv) on outlines towards (tu, tv) start into the cross-section, given
    the rows (normal u, normal v, c) of the points' polygons, (3, V, P)."""
    du, dv = tu - pu, tv - pv
    length = np.sqrt(du * du + dv * dv)
    real = length > 0.0
    step = PEEK / np.where(real, length, 1.0)
    return _inside(rows, pu + du * step, pv + dv * step, PEEK_MARGIN) & real


def through_bodies(points: AddedPoints, edges: Edges, grid: Grid, pairs: tuple) -> tuple:
    """The coupling pairs (``coupling_pairs``) less those whose segment crosses a cross-section: a grid vertex
    and an added point, or two added points, on opposite sides of a body thinner than h (or across a corner of
    one) are not water neighbours, so the body reflects the wave instead of letting it through. The segment
    from an outline point towards its partner crosses when its first ``PEEK`` lies inside the point's polygon
    (a point's polygon is convex and the point is on its outline)."""
    g, p, w, a, b, w2 = pairs
    if len(points) == 0:
        return pairs
    u, v = np.ascontiguousarray(points.uv.T)
    rows = edges.table[4:7]
    gv, gu = np.divmod(g, grid.nx)
    keep = ~_enters(rows.take(points.body.take(p), axis=2), u.take(p), v.take(p), gu.astype(np.float64),
                    gv.astype(np.float64))
    ua, va, ub, vb = u.take(a), v.take(a), u.take(b), v.take(b)
    keep2 = ~(_enters(rows.take(points.body.take(a), axis=2), ua, va, ub, vb)
              | _enters(rows.take(points.body.take(b), axis=2), ub, vb, ua, va))
    return g[keep], p[keep], w[keep], a[keep2], b[keep2], w2[keep2]


def cut_edges(points: AddedPoints, solid: np.ndarray, grid: Grid) -> tuple[I64, I64]:
    """Grid edges between two water vertices that an outline crosses: (lower vertex, upper vertex) (flat
    indices), each once, ascending by lower vertex then by direction (along u before along v).

    A convex outline that crosses a grid edge once leaves one end inside the body; crossing it with both ends in
    the water, it crosses twice: the body lies between two vertices thinner than h, and they must not be each
    other's neighbours (eq. 2.8 on the grid would carry the wave straight through it)."""
    kind = points.kind
    on_line = kind < 2
    if not any_of(on_line, axis=None):
        z = np.zeros(0, np.int64)
        return z, z
    u, v = points.uv[on_line, 0], points.uv[on_line, 1]
    along_v = kind[on_line] == 0  # on a line u = i: the edge from (i, floor v) to (i, floor v + 1)
    i = np.where(along_v, np.rint(u), np.floor(u)).astype(np.int64)
    j = np.where(along_v, np.floor(v), np.rint(v)).astype(np.int64)
    along_u = ~along_v
    ok = (i >= 0) & (j >= 0) & (i + along_u < grid.nx) & (j + along_v < grid.nz)  # both ends on the grid
    lo = j * grid.nx + i
    hi = lo + np.where(along_v, grid.nx, 1)
    flat = solid.ravel()
    ok[ok] = ~flat[lo[ok]] & ~flat[hi[ok]]
    key = np.unique(2 * lo[ok] + along_v[ok])
    lo, direction = np.divmod(key, 2)
    return lo, lo + np.where(direction == 1, grid.nx, 1)
