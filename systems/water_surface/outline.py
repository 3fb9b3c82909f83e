"""The body outline in the water model (seeds/003, sections 2.2.2, 2.2.3 and 2.3.1), vectorized over bodies.

1. Cross-section D' of each body with the horizontal plane S' at the mean water height where the body is
   (section 2.2.2): box edges QR whose ends lie on opposite sides of S' give the points L' (the ordinary
   line–plane intersection; the printed eq. 2.1 is garbled), sorted counter-clockwise; a sphere gives a regular
   polygon inscribed in its circle of intersection.
2. Points of D' on a grid line or vertex are nudged slightly inwards (figure 2.3).
3. Added points N (section 2.2.3): the vertices L' and the crossings M' of D''s edges with the grid lines, in
   order along the outline, with the outline segments between consecutive points.
4. Wave generation (eq. 2.5–2.7): d(t) is how far the outline point moved in one step; it rises by α·d(t) when
   its position at t − 1 lies inside the cross-section at t, and sinks by α·d(t) when its position at t lay
   inside the cross-section at t − 1.
5. Coupling with the grid (eq. 2.11, 2.12): pairs of points within radius h with weights r_k / h = 1 − |PN| / h,
   and the grid vertices inside the cross-section, which become a reflecting obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from systems.water_surface.geometry import (BOX, EPS_LINE, F64, I64, NUDGE, SPHERE, Bodies, Grid, inside_polygons,
                                            polygon_edges, ranges)

__all__ = ["AddedPoints", "Sections", "added_points", "coupling_pairs", "cross_sections", "nearest_on_outline", "nudge", "outline_impulse",
           "solid_vertices"]

# Box corners c = (sx, sy, sz) ∈ {−1, 1}³ and its 12 edges (corner pairs that differ along one axis).
_SIGNS = np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)])
_EDGES = np.array([(a, b) for a in range(8) for b in range(a + 1, 8)
                   if np.count_nonzero(_SIGNS[a] != _SIGNS[b]) == 1], dtype=np.int64)


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


@dataclass
class Sections:
    """Cross-sections D' (B, V, 2) in grid units with their feature ids (for the added points' keys)."""

    polygons: F64
    counts: I64
    vertex_feature: I64  # (B, V): the box edge or sphere vertex each L' comes from
    edge_feature: I64  # (B, V): the box face or sphere edge that edge k → k + 1 lies on

    @property
    def cuts(self) -> np.ndarray:
        return self.counts >= 3


def cross_sections(bodies: Bodies, plane_y: F64, grid: Grid, sphere_segments: int) -> Sections:
    """Cross-section polygon D' of every body with the horizontal plane y = plane_y[b] (section 2.2.2)."""
    B = len(bodies)
    is_box = bodies.shapes == BOX
    width = max(_MAX_BOX_VERTICES if is_box.any() else 0, sphere_segments if (~is_box).any() else 0, 3)
    polygons = np.zeros((B, width, 2))
    counts = np.zeros(B, np.int64)
    vfeat = np.zeros((B, width), np.int64)
    efeat = np.zeros((B, width), np.int64)
    if is_box.any():
        idx = np.flatnonzero(is_box)
        p, n, f = _box_sections(bodies.take(idx), plane_y[idx], grid)
        polygons[idx, :_MAX_BOX_VERTICES], counts[idx], vfeat[idx, :_MAX_BOX_VERTICES] = p, n, f
        nxt = np.roll(f, -1, axis=1)
        nxt = np.where(np.arange(_MAX_BOX_VERTICES)[None, :] + 1 < n[:, None], nxt, f[:, :1])
        shared = _SHARED_FACE[f, nxt]
        efeat[idx, :_MAX_BOX_VERTICES] = np.where(shared >= 0, shared, 6 + np.arange(_MAX_BOX_VERTICES)[None, :])
    if (~is_box).any():
        idx = np.flatnonzero(~is_box)
        p, n = _sphere_sections(bodies.take(idx), plane_y[idx], grid, sphere_segments)
        polygons[idx, :sphere_segments], counts[idx] = p, n
        vfeat[idx, :sphere_segments] = np.arange(sphere_segments)
        efeat[idx, :sphere_segments] = np.arange(sphere_segments)
    return Sections(polygons, counts, vfeat, efeat)


def _box_sections(bodies: Bodies, plane_y: F64, grid: Grid) -> tuple[F64, I64, I64]:
    local = _SIGNS[None, :, :] * bodies.half[:, None, :]
    corners = bodies.position[:, None, :] + np.einsum("bij,bcj->bci", bodies.rotation, local)
    y = corners[..., 1] - plane_y[:, None]
    above = y >= 0.0
    ya, yb = y[:, _EDGES[:, 0]], y[:, _EDGES[:, 1]]
    straddle = above[:, _EDGES[:, 0]] != above[:, _EDGES[:, 1]]
    t = ya / np.where(straddle, ya - yb, 1.0)
    qa, qr = corners[:, _EDGES[:, 0], :], corners[:, _EDGES[:, 1], :]
    points = grid.to_uv((qa + t[..., None] * (qr - qa))[..., [0, 2]])
    polygons, counts, feature = _sort_ccw(points, straddle)
    return polygons[:, :_MAX_BOX_VERTICES], counts, feature[:, :_MAX_BOX_VERTICES]


def _sort_ccw(points: F64, valid: np.ndarray) -> tuple[F64, I64, I64]:
    """Order the valid points of each row counter-clockwise about their centroid; drop repeated points."""
    n = valid.sum(axis=1)
    centre = np.sum(np.where(valid[..., None], points, 0.0), axis=1) / np.maximum(n, 1)[:, None]
    d = points - centre[:, None, :]
    angle = np.where(valid, np.arctan2(d[..., 1], d[..., 0]), np.inf)
    order = np.argsort(angle, axis=1, kind="stable")
    polygons = np.take_along_axis(points, order[..., None], axis=1)
    ok = np.take_along_axis(valid, order, axis=1)
    # A box vertex lying exactly on the plane gives the same L' from several edges: keep one.
    prev = np.take_along_axis(polygons, np.where(np.arange(len(order[0]))[None, :] == 0, n[:, None] - 1,
                                                 np.arange(len(order[0]))[None, :] - 1).clip(0)[..., None], axis=1)
    repeat = ok & (np.sum((polygons - prev) ** 2, axis=-1) < 1e-20) & (n[:, None] > 1)
    repeat[:, 0] = False
    if repeat.any():
        keep = ok & ~repeat
        again = np.argsort(~keep, axis=1, kind="stable")
        polygons = np.take_along_axis(polygons, again[..., None], axis=1)
        order = np.take_along_axis(order, again, axis=1)
        n = keep.sum(axis=1)
    counts = np.where(n >= 3, n, 0)
    return polygons, counts, order


def _sphere_sections(bodies: Bodies, plane_y: F64, grid: Grid, segments: int) -> tuple[F64, I64]:
    d = plane_y - bodies.position[:, 1]
    rho2 = bodies.radius ** 2 - d ** 2
    rho = np.sqrt(np.maximum(rho2, 0.0)) / grid.h
    angles = 2.0 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=-1)  # counter-clockwise in (u, v)
    centre = grid.to_uv(bodies.position[:, [0, 2]])
    polygons = centre[:, None, :] + rho[:, None, None] * ring[None, :, :]
    return polygons, np.where(rho2 > 0.0, segments, 0).astype(np.int64)


def nudge(sections: Sections) -> Sections:
    """Move polygon vertices that lie on a grid line (or vertex) slightly inwards (section 2.2.2, figure 2.3), so
    an added point never sits on a grid vertex and a vertex on a grid edge adds no extra point."""
    p = sections.polygons.copy()
    valid = np.arange(p.shape[1])[None, :] < sections.counts[:, None]
    centre = np.sum(np.where(valid[..., None], p, 0.0), axis=1) / np.maximum(sections.counts, 1)[:, None]
    on = _on_line(p) & valid[..., None]
    if on.any():
        towards = centre[:, None, :] - p
        length = np.linalg.norm(towards, axis=-1, keepdims=True)
        step = NUDGE * towards / np.where(length > 0.0, length, 1.0)
        p = np.where(on.any(axis=-1, keepdims=True), p + step, p)
        on = _on_line(p) & valid[..., None]
        if on.any():  # moving towards the centre ran along the line: step off it towards the centre's side
            side = np.where(centre[:, None, :] - p >= 0.0, 1.0, -1.0)
            p = np.where(on, p + NUDGE * side, p)
    return Sections(p, sections.counts, sections.vertex_feature, sections.edge_feature)


def _on_line(p: F64) -> np.ndarray:
    return np.abs(p - np.round(p)) < EPS_LINE


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


def added_points(sections: Sections, entities: I64, grid: Grid) -> AddedPoints:
    """The vertices L' and grid-edge crossings M' of every cross-section, ordered along the outline; points off
    the grid's footprint and the segments touching them are dropped."""
    for attempt in range(4):
        points = _outline(sections)
        if points is not None or attempt == 3:
            break
        # An edge of D' passes exactly through a grid vertex: shrink the polygons a hair and cut again.
        valid = np.arange(sections.polygons.shape[1])[None, :] < sections.counts[:, None]
        centre = (np.sum(np.where(valid[..., None], sections.polygons, 0.0), axis=1)
                  / np.maximum(sections.counts, 1)[:, None])
        shrunk = centre[:, None, :] + (sections.polygons - centre[:, None, :]) * (1.0 - 1e-6 * (attempt + 1))
        sections = Sections(shrunk, sections.counts, sections.vertex_feature, sections.edge_feature)
    if points is None:
        points = _outline(sections, strict=False)
    uv, kind, feature, line, body, edge, t = points
    if len(uv) == 0:
        z = np.zeros(0, np.int64)
        return AddedPoints(np.zeros((0, 2)), np.zeros(0, np.int8), z, z, np.zeros((0, 2), np.int64))
    order = np.lexsort((t, edge, body))
    uv, kind, feature, line, body = uv[order], kind[order], feature[order], line[order], body[order]
    n = len(body)
    starts = np.flatnonzero(np.r_[True, body[1:] != body[:-1]])
    body_start = starts[np.searchsorted(starts, np.arange(n), side="right") - 1]
    nxt = np.arange(1, n + 1)
    last = np.r_[body[1:] != body[:-1], True]
    nxt[last] = body_start[last]
    keep = grid.inside(uv)
    remap = np.cumsum(keep) - 1
    seg_ok = keep & keep[nxt]
    segments = np.stack([remap[np.flatnonzero(seg_ok)], remap[nxt[seg_ok]]], axis=-1).astype(np.int64)
    crossing = (kind < 2).astype(np.int64)
    keys = ((entities[body].astype(np.int64) << 32) | (crossing << 30) | (feature.astype(np.int64) << 22)
            | ((kind == 1).astype(np.int64) << 21) | (crossing * line))
    return AddedPoints(uv[keep], kind[keep].astype(np.int8), keys[keep], body[keep], segments.reshape(-1, 2))


def _outline(sections: Sections, strict: bool = True):
    """Vertices and crossings (unsorted) with their sort keys (body, edge, t); None if a crossing hits a vertex."""
    a, b, valid = polygon_edges(sections.polygons, sections.counts)
    eb, ek = np.nonzero(valid)
    A, Bp = a[eb, ek], b[eb, ek]
    efeat = sections.edge_feature[eb, ek]
    parts = [(A, np.full(len(eb), 2, np.int8), sections.vertex_feature[eb, ek], np.zeros(len(eb), np.int64), eb, ek,
              np.full(len(eb), -1.0))]
    for axis in (0, 1):
        lo = np.floor(np.minimum(A[:, axis], Bp[:, axis])).astype(np.int64)
        hi = np.floor(np.maximum(A[:, axis], Bp[:, axis])).astype(np.int64)
        run, line = ranges(lo + 1, hi - lo)
        t = (line - A[run, axis]) / (Bp[run, axis] - A[run, axis])
        other = A[run, 1 - axis] + t * (Bp[run, 1 - axis] - A[run, 1 - axis])
        if strict and axis == 0 and np.any(np.abs(other - np.round(other)) < EPS_LINE):
            return None
        uv = np.empty((len(run), 2))
        uv[:, axis], uv[:, 1 - axis] = line, other
        parts.append((uv, np.full(len(run), axis, np.int8), efeat[run], line, eb[run], ek[run], t))
    return tuple(np.concatenate(column) for column in zip(*parts))


# ---------------------------------------------------------------------------------------- wave generation
def outline_impulse(points: AddedPoints, sections: Sections, previous_polygons: F64, previous_counts: I64,
                    has_previous: np.ndarray, grid: Grid, alpha: float) -> tuple[F64, F64, np.ndarray, np.ndarray]:
    """±α·d(t) for every added point (eq. 2.5–2.7).

    N_c(t − 1), the added point one step earlier, is the point of the previous cross-section D'(t − 1) nearest to
    N_c(t): so d(t) is how far the outline moved there, whatever moved it (the body gliding, turning, or bobbing
    with sloped sides). N_c rises by α·d(t) when N_c(t − 1) lies inside D'(t) (the body pushed that water aside)
    and sinks by α·d(t) when N_c(t) lay inside D'(t − 1) (the body left that space). Bodies without a
    cross-section at t − 1 make no wave this step. Returns (change of height, d(t) in metres, raised, lowered).
    """
    if len(points) == 0:
        empty = np.zeros(0)
        return empty, empty, np.zeros(0, bool), np.zeros(0, bool)
    bi = points.body
    old = has_previous[bi] & (previous_counts[bi] >= 3)
    back = nearest_on_outline(points.uv, previous_polygons[bi], previous_counts[bi])
    back = np.where(old[:, None], back, points.uv)
    d = np.hypot(*(points.uv - back).T) * grid.h  # eq. 2.5
    # The outline itself counts as inside (a corner gliding along a side was on D'(t) at t − 1).
    raised = old & inside_polygons(back, sections.polygons[bi], sections.counts[bi], -_ON_OUTLINE)
    lowered = old & inside_polygons(points.uv, previous_polygons[bi], previous_counts[bi], -_ON_OUTLINE)
    change = alpha * d * (raised.astype(np.float64) - lowered.astype(np.float64))  # eq. 2.6 / 2.7
    # Rises and falls of one body balance (the outline's points are not evenly spaced, so the raw ±α·d would
    # create or remove water): the body's mean change is taken off all of its points.
    count = np.bincount(bi, minlength=len(has_previous))
    mean = np.bincount(bi, change, len(has_previous)) / np.maximum(count, 1)
    return change - mean[bi], d, raised, lowered


def nearest_on_outline(points: F64, polygons: F64, counts: I64) -> F64:
    """The point of each polygon's outline (P, V, 2) nearest to ``points[p]`` (P, 2)."""
    a, b, valid = polygon_edges(polygons, counts)
    e = b - a
    length2 = np.sum(e * e, axis=-1)
    t = np.clip(np.sum((points[:, None, :] - a) * e, axis=-1) / np.where(length2 > 0.0, length2, 1.0), 0.0, 1.0)
    foot = a + t[..., None] * e
    dist2 = np.where(valid, np.sum((foot - points[:, None, :]) ** 2, axis=-1), np.inf)
    best = np.argmin(dist2, axis=1)
    return foot[np.arange(len(points)), best]


# ------------------------------------------------------------------------------------------- coupling
def solid_vertices(sections: Sections, grid: Grid) -> tuple[I64, I64]:
    """Grid vertices strictly inside some cross-section: (flat vertex index, body index). In the outline method
    they are inside the body, so the water there is not simulated and waves reflect at the outline."""
    p, counts = sections.polygons, sections.counts
    valid = (np.arange(p.shape[1])[None, :] < counts[:, None])[..., None]
    lo = np.ceil(np.min(np.where(valid, p, np.inf), axis=1))
    hi = np.floor(np.max(np.where(valid, p, -np.inf), axis=1))
    cut = counts >= 3
    lo = np.where(cut[:, None], np.maximum(lo, 0), 0).astype(np.int64)
    hi = np.where(cut[:, None], np.minimum(hi, [grid.nx - 1, grid.nz - 1]), -1).astype(np.int64)
    width = np.maximum(hi[:, 0] - lo[:, 0] + 1, 0)
    height = np.maximum(hi[:, 1] - lo[:, 1] + 1, 0)
    body, offset = ranges(np.zeros(len(counts), np.int64), width * height)
    if len(body) == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    dv, du = np.divmod(offset, width[body])
    uv = np.stack([lo[body, 0] + du, lo[body, 1] + dv], axis=-1).astype(np.float64)
    inside = inside_polygons(uv, p[body], counts[body])
    flat = (uv[inside, 1] * grid.nx + uv[inside, 0]).astype(np.int64)
    return flat, body[inside]


def coupling_pairs(points: AddedPoints, fluid: np.ndarray, grid: Grid) -> tuple[I64, I64, F64, I64, I64, F64]:
    """Neighbours within radius h for eq. 2.11 / 2.12, with weights r_k / h = 1 − distance / h.

    Returns (grid vertex, added point, weight) for the pairs between the grid and the added points (grid
    vertices inside a body excluded), and (point, point, weight) for the pairs of added points of one body, both
    directions.
    """
    m = len(points)
    if m == 0:
        z = np.zeros(0, np.int64)
        return z, z, np.zeros(0), z, z, np.zeros(0)
    base = np.floor(points.uv).astype(np.int64)
    corner = base[:, None, :] + np.array([[0, 0], [1, 0], [0, 1], [1, 1]])[None, :, :]
    dist = np.linalg.norm(corner - points.uv[:, None, :], axis=-1)
    ok = ((dist < 1.0) & (corner[..., 0] >= 0) & (corner[..., 0] < grid.nx) & (corner[..., 1] >= 0)
          & (corner[..., 1] < grid.nz))
    flat = np.where(ok, corner[..., 1] * grid.nx + corner[..., 0], 0)
    ok &= fluid.ravel()[flat]
    p_idx, c_idx = np.nonzero(ok)
    g = flat[p_idx, c_idx]
    w = 1.0 - dist[p_idx, c_idx]
    # Pairs of added points of the same body (padded per body: bodies hold a few dozen points each).
    body = points.body
    starts = np.flatnonzero(np.r_[True, body[1:] != body[:-1]])
    sizes = np.diff(np.r_[starts, m])
    slot = np.arange(m) - np.repeat(starts, sizes)
    group = np.repeat(np.arange(len(starts)), sizes)
    table = -np.ones((len(starts), int(sizes.max())), np.int64)
    table[group, slot] = np.arange(m)
    first, second = table[:, :, None], table[:, None, :]
    uv = points.uv
    real = (first >= 0) & (second >= 0) & (first != second)
    diff = uv[np.maximum(first, 0)] - uv[np.maximum(second, 0)]
    dd = np.hypot(diff[..., 0], diff[..., 1])
    close = real & (dd < 1.0)
    gi, ai, bi = np.nonzero(close)
    n1 = table[gi, ai]
    n2 = table[gi, bi]
    return g, p_idx.astype(np.int64), w, n1, n2, 1.0 - dd[gi, ai, bi]
