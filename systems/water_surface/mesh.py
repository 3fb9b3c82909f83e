"""The re-triangulated water mesh (seeds/003, section 2.2.4, figures 2.7–2.10 and 3.2), vectorized.

Squares C[i, j] holding no added point keep the base model's two triangles (P[i,j], P[i+1,j], P[i,j+1]) and
(P[i+1,j], P[i+1,j+1], P[i,j+1]). A square holding added points is cut along the body outline: its boundary
(corners and the added points on its edges, counter-clockwise) and the outline segments inside it form a planar
graph whose faces are walked with a "next half-edge" rule; every face is then ear-clipped. The result is a
conforming mesh (no T-junctions: each square edge carries the same added points on both sides) that contains
every outline segment as an edge, for any number of added points per square (the paper's cases of 2, 3 and 4
points are special cases). A body whose whole outline lies inside one square becomes a hole, joined to the
square's corner by a bridge edge before ear clipping.

Cheap paths (the same correctness argument for both): a face is triangulated as a fan from the first of its
vertices whose fan triangles are all strictly counter-clockwise, and only faces with no such vertex (rare concave
water-side faces) are ear-clipped. And when the outline's combinatorics did not change since the previous frame
(same points, kinds, segments, squares and grid lines) the previous triangles are kept if they are all still
strictly counter-clockwise. Why that suffices: the triangles of a fan (or any triangulation) of a closed polygon
have that polygon as their boundary chain, so the number of triangles covering a point (counted with orientation)
is the polygon's winding number about it: 1 inside the face, 0 outside and in a hole. When every triangle is
positively oriented this count is the plain number of triangles covering the point, so they tile the face exactly:
no overlap, no gap, no vertex on another triangle's edge (two triangles sharing a corner and a collinear edge on
the same side would overlap near that corner).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from systems.water_surface.geometry import F64, I64, Grid, all_of, any_of, bilinear_with_slope

__all__ = ["WaterMesh", "base_triangles", "retriangulate", "vertex_arrays", "wire_arrays"]


_SHORT_FACE = 8  # faces up to this many vertices are fan-tested together, longer ones (bridged holes) apart
_EPS_AREA = 1e-12  # grid units²: a triangle's doubled signed area must exceed this to count as counter-clockwise


@dataclass
class WaterMesh:
    """Triangles over the vertices [grid vertices (nx·nz, row-major j·nx + i), added points (M)]."""

    triangles: I64  # (T, 3): the untouched squares' base triangles, then the re-triangulated squares' triangles
    cells: I64  # squares that were re-triangulated (j·(nx − 1) + i)
    outline: I64  # (K, 2) outline segments as vertex ids
    key: bytes = b""  # the outline's combinatorics this mesh was built for (see ``retriangulate``'s ``previous``)


def base_triangles(nx: int, nz: int, cells: I64 | None = None) -> I64:
    """The base model's two triangles per square (section 2.2.1, figure 2.2), for all or the given squares."""
    if cells is None:
        cells = np.arange((nx - 1) * (nz - 1))
    j, i = np.divmod(cells, nx - 1)
    p00 = j * nx + i
    p10, p01, p11 = p00 + 1, p00 + nx, p00 + nx + 1
    return np.stack([np.stack([p00, p10, p01], -1), np.stack([p10, p11, p01], -1)], axis=1).reshape(-1, 3)


@lru_cache(maxsize=8)
def _all_base(nx: int, nz: int) -> I64:
    tris = base_triangles(nx, nz).reshape(-1, 6)
    tris.setflags(write=False)
    return tris


def retriangulate(nx: int, nz: int, uv: F64, kind: np.ndarray, segments: I64,
                  previous: WaterMesh | None = None) -> WaterMesh:
    """The water mesh with the squares crossed by the outline re-triangulated (section 2.2.4).

    ``previous``: the mesh of the same surface at the last frame. Its triangles are reused when the added points
    still have the same kinds, squares and grid lines, the same outline segments, and every re-triangulated
    triangle is still strictly counter-clockwise at the new positions (a valid triangulation, see the module
    docstring); otherwise the crossed squares are triangulated afresh.
    """
    g = nx * nz
    if len(segments) == 0:
        return WaterMesh(_all_base(nx, nz).reshape(-1, 3), np.zeros(0, np.int64), np.zeros((0, 2), np.int64))
    cell_of = _segment_cells(nx, nz, uv, segments)
    key = _outline_key(nx, nz, uv, kind, segments, cell_of)
    if previous is not None and previous.key == key:
        cut = previous.triangles[len(previous.triangles) - _cut_count(nx, nz, previous):]
        if _all_counter_clockwise(nx, nz, uv, cut):
            return WaterMesh(previous.triangles, previous.cells, previous.outline, key)
    cells, local = np.unique(cell_of, return_inverse=True)
    faces, positions, lengths = _faces(nx, uv, kind, segments, cells, local)
    triangles = _triangulate(faces, positions, lengths)
    triangles = np.where(triangles < 0, g - 1 - triangles, triangles)  # added point p → vertex g + p
    keep = np.ones((nx - 1) * (nz - 1), bool)
    keep[cells] = False
    regular = _all_base(nx, nz).compress(keep, axis=0).reshape(-1, 3)  # (a boolean row mask is ~5x slower)
    return WaterMesh(np.concatenate([regular, triangles]), cells, segments + g, key)


def _outline_key(nx: int, nz: int, uv: F64, kind: np.ndarray, segments: I64, cell_of: I64) -> bytes:
    """The outline's combinatorics: point kinds, outline segments, their squares, the grid cell or line of each point
    (a crossing on the line u = i keeps (i, ⌊v⌋), one on v = j keeps (⌊u⌋, j), a vertex L' keeps (⌊u⌋, ⌊v⌋))."""
    on_line = np.zeros((len(uv), 2))
    on_line[kind == 0, 0] = 0.5
    on_line[kind == 1, 1] = 0.5
    lines = np.floor(uv + on_line).astype(np.int64)
    return b"".join((np.array([nx, nz]).tobytes(), kind.tobytes(), segments.tobytes(), cell_of.tobytes(), lines.tobytes()))


def _cut_count(nx: int, nz: int, mesh: WaterMesh) -> int:
    """How many of the mesh's triangles (at its end) belong to the re-triangulated squares."""
    return len(mesh.triangles) - 2 * ((nx - 1) * (nz - 1) - len(mesh.cells))


@lru_cache(maxsize=8)
def _grid_uv(nx: int, nz: int) -> F64:
    uv = np.stack(np.meshgrid(np.arange(nx, dtype=np.float64), np.arange(nz, dtype=np.float64)), -1).reshape(-1, 2)
    uv.setflags(write=False)
    return uv


def _all_counter_clockwise(nx: int, nz: int, uv: F64, triangles: I64) -> bool:
    """Whether every triangle (mesh vertex ids) is strictly counter-clockwise in (u, v)."""
    every = np.concatenate([_grid_uv(nx, nz), uv])
    u, v = every[:, 0].take(triangles), every[:, 1].take(triangles)
    du, dv = u[:, 1:] - u[:, :1], v[:, 1:] - v[:, :1]
    return bool(all_of(du[:, 0] * dv[:, 1] - dv[:, 0] * du[:, 1] > _EPS_AREA, axis=None))


def vertex_arrays(grid: Grid, heights: F64, point_uv: F64, point_heights: F64) -> tuple[F64, F64]:
    """World positions and unit normals (N, 3) of the mesh vertices: the grid vertices, then the added points.

    Normals come from the height field: central differences at the grid vertices, the bilinear slope at the
    added points.
    """
    nz, nx = heights.shape
    xs = grid.x0 + np.arange(nx) * grid.h
    zs = grid.z0 + np.arange(nz) * grid.h
    gx, gz = np.meshgrid(xs, zs)
    dz, dx = np.gradient(heights, grid.h)
    grid_pos = np.stack([gx, grid.y0 + heights, gz], -1).reshape(-1, 3)
    grid_n = np.stack([-dx, np.ones_like(dx), -dz], -1).reshape(-1, 3)
    _, du, dv = bilinear_with_slope(heights, point_uv)
    xz = grid.to_xz(point_uv)
    point_pos = np.stack([xz[:, 0], grid.y0 + point_heights, xz[:, 1]], -1)
    point_n = np.stack([-du / grid.h, np.ones(len(point_uv)), -dv / grid.h], -1)
    normals = np.concatenate([grid_n, point_n])
    return np.concatenate([grid_pos, point_pos]), normals / np.linalg.norm(normals, axis=1, keepdims=True)


def wire_arrays(positions: F64, mesh: WaterMesh, edge_color=(0.05, 0.1, 0.15),
                outline_color=(1.0, 0.45, 0.05)) -> F64:
    """Line-list vertices (position, colour) of every triangle edge, then the outline segments on top (fig. 3.2)."""
    t = mesh.triangles
    edges = np.stack([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]], 1).reshape(-1, 2)
    pairs = np.concatenate([edges, mesh.outline])
    colors = np.where((np.arange(len(pairs)) < len(edges))[:, None], edge_color, outline_color)
    pos = positions[pairs.ravel()]
    return np.concatenate([pos, np.repeat(colors, 2, axis=0)], axis=1)


def _segment_cells(nx: int, nz: int, uv: F64, segments: I64) -> I64:
    mid = 0.5 * (uv[segments[:, 0]] + uv[segments[:, 1]])
    ci = np.clip(np.floor(mid[:, 0]).astype(np.int64), 0, nx - 2)
    cj = np.clip(np.floor(mid[:, 1]).astype(np.int64), 0, nz - 2)
    return cj * (nx - 1) + ci


def _faces(nx: int, uv: F64, kind: np.ndarray, segments: I64, cells: I64, local: I64):
    """Faces of every crossed square as padded vertex-id and position arrays, counter-clockwise.

    Half-edges: the ring of every square (its corners and the crossings on its sides, counter-clockwise) at
    [0, r), each outline segment forwards at r + s and backwards at r + k + s. A ring half-edge that reaches a
    crossing leaves along the outline segment that starts or ends there in that square; an outline half-edge that
    reaches a crossing continues along the ring, one that reaches a vertex L' along the outline."""
    c = len(cells)
    k = len(segments)
    m = len(uv)
    cj, ci = np.divmod(cells, nx - 1)
    ends = segments.T.ravel()  # segment starts, then segment ends
    crossing = kind.take(ends) < 2
    q = np.flatnonzero(crossing)  # the ring entries that are crossings, as indices into ``ends``
    e_pt, e_cell = ends.take(q), local.take(q % k)
    corner_ids = (cj * nx + ci)[:, None] + np.array([0, 1, nx + 1, nx])
    ring_cell = np.concatenate([np.repeat(np.arange(c), 4), e_cell])
    position = np.concatenate([np.tile(np.arange(4.0), c), _ring_parameter(uv, kind, e_pt, ci.take(e_cell),
                                                                              cj.take(e_cell))])
    order = (ring_cell * 4.0 + position).argsort()  # by square, then counter-clockwise from its corner (i, j)
    ring_vertex = np.concatenate([corner_ids.ravel(), -1 - e_pt]).take(order)
    ring_cell = ring_cell.take(order)
    r = len(order)
    where = np.empty(r, np.int64)
    where[order] = np.arange(r)  # sorted position of each ring entry
    ring_next = np.arange(1, r + 1)  # the last entry of every square goes back to its first
    last = np.empty(r, bool)
    last[:-1] = ring_cell[1:] != ring_cell[:-1]
    last[-1] = True
    first = np.flatnonzero(np.r_[True, last[:-1]])
    ring_next[last] = first
    h = r + 2 * k
    head = np.concatenate([ring_vertex, -1 - ends])  # the vertex each half-edge starts at
    nxt = np.empty(h, np.int64)
    # a ring half-edge ending at a corner continues along the ring; at a crossing it leaves along the outline
    nxt[:r] = ring_next
    leave = np.empty(r, np.int64)
    leave[where[4 * c:]] = r + q  # from segment s's start: forwards (r + s); from its end: backwards (r + k + s)
    crossing_next = ring_vertex.take(ring_next) < 0
    nxt[:r][crossing_next] = leave.take(ring_next[crossing_next])
    # an outline half-edge ending at a crossing turns onto that square's ring, at a vertex L' continues the outline
    ring_of_end = np.zeros(2 * k, np.int64)
    ring_of_end[q] = where[4 * c:]
    seg_from = np.zeros(m, np.int64)
    seg_from[segments[:, 0]] = np.arange(k)
    seg_to = np.zeros(m, np.int64)
    seg_to[segments[:, 1]] = np.arange(k)
    a_end, b_end = segments[:, 0], segments[:, 1]
    nxt[r:r + k] = np.where(crossing[k:], ring_of_end[k:], r + seg_from.take(b_end))
    nxt[r + k:] = np.where(crossing[:k], ring_of_end[:k], r + k + seg_to.take(a_end))
    rep = _cycles(nxt)
    if any_of(rep[r + k:] >= r + k):  # a backward outline cycle touching no ring: a hole, bridged (rare)
        head, nxt = _bridge_holes(nx, uv, head, nxt, r, k, segments, cells, local, ring_cell, ring_vertex, ring_next)
        rep = _cycles(nxt)
    return _walk(head, nxt, rep, nx, uv)


def _ring_parameter(uv: F64, kind: np.ndarray, points: I64, ci: I64, cj: I64) -> F64:
    """Position s ∈ (0, 4) of each crossing on its square's boundary, counter-clockwise from corner (i, j)."""
    du, dv = uv[:, 0].take(points) - ci, uv[:, 1].take(points) - cj
    on_u = kind.take(points) == 0  # on a line u = const: the left (du ≈ 0) or right (du ≈ 1) side
    return np.where(on_u, np.where(du < 0.5, 4.0 - dv, 1.0 + dv), np.where(dv < 0.5, du, 3.0 - du))


def _cycles(nxt: I64) -> I64:
    """Smallest half-edge index of every half-edge's cycle (pointer jumping)."""
    rep = np.arange(len(nxt))
    jump = nxt.copy()
    for _ in range(int(np.ceil(np.log2(max(len(nxt), 2)))) + 1):
        rep = np.minimum(rep, rep[jump])
        jump = jump[jump]
    return rep


def _bridge_holes(nx, uv, head, nxt, r, k, segments, cells, local, ring_cell, ring_vertex, ring_next):
    """Join each outline that lies wholly inside one square (a hole) to that square's corner (i + 1, j + 1)."""
    rep = _cycles(nxt)
    reps = np.unique(rep[r + k:])  # faces walked along an outline backwards ...
    holes = reps[(reps >= r + k) & ~np.isin(reps, rep[:r])]  # ... that touch no square side: holes
    if len(holes) == 0:
        return head, nxt
    head, nxt = list(head), list(nxt)
    for q in holes:  # one per small body
        members = np.flatnonzero(rep == q)
        pts = -1 - np.asarray(head)[members]
        best = members[np.argmax(uv[pts, 0] + uv[pts, 1])]  # the backward half-edge leaving v*
        v_star = head[best]
        into = int(np.flatnonzero(np.asarray(nxt) == best)[0])  # the hole's half-edge ending at v*
        cell = local[best - r - k]
        cj, ci = divmod(int(cells[cell]), nx - 1)
        corner = (cj + 1) * nx + ci + 1
        entries = np.flatnonzero((ring_cell == cell) & (ring_vertex == corner))
        out_ring = int(entries[0])  # ring half-edge leaving the corner
        in_ring = int(np.flatnonzero(ring_next == out_ring)[0])
        bridge_in, bridge_out = len(head), len(head) + 1
        head += [corner, v_star]
        nxt += [best, out_ring]
        nxt[in_ring] = bridge_in
        nxt[into] = bridge_out
    return np.asarray(head, np.int64), np.asarray(nxt, np.int64)


def _walk(head: I64, nxt: I64, rep: I64, nx: int, uv: F64):
    """Vertex ids and positions of every face (padded), walking each cycle (``rep``: its smallest half-edge) once."""
    starts = np.flatnonzero(rep == np.arange(len(rep)))
    lengths = np.bincount(rep, minlength=len(rep)).take(starts)
    longest = int(lengths.max())
    faces = np.zeros((len(starts), longest), np.int64)
    cur = starts.copy()
    for step in range(longest):  # one step along every face at once
        faces[:, step] = head[cur]
        cur = nxt[cur]
    grid_uv = np.stack([np.mod(faces, nx), faces // nx], -1).astype(np.float64)
    pts = uv[np.clip(-1 - faces, 0, max(len(uv) - 1, 0))] if len(uv) else grid_uv
    positions = np.where((faces < 0)[..., None], pts, grid_uv)
    return faces, positions, lengths


def _triangulate(faces: I64, positions: F64, lengths: I64) -> I64:
    """Triangulate simple counter-clockwise polygons (padded): a fan from the first vertex that makes every fan
    triangle strictly counter-clockwise (a valid triangulation, see the module docstring), ear clipping for the
    faces that have no such vertex. Negative ids (added points) are passed through."""
    f, width = faces.shape
    if width < 3:
        return np.zeros((0, 3), np.int64)
    short = lengths <= _SHORT_FACE
    if width > _SHORT_FACE and any_of(short) and not all_of(short):  # the fan test is (F, L, L): group by length
        parts = []
        for group, w in ((np.flatnonzero(short), _SHORT_FACE), (np.flatnonzero(~short), width)):
            parts.append(_triangulate(faces[group, :w], positions[group, :w], lengths.take(group)))
        return np.concatenate(parts)
    # fan from start s: triangles (s, s + t, s + t + 1) for t = 1 .. length − 2, indices modulo the face length
    s = np.arange(width)[None, :, None]
    t = np.arange(1, width - 1)[None, None, :]
    n = lengths[:, None, None]
    row = (np.arange(f) * width)[:, None, None]
    i1 = row + (s + t) % n
    i2 = row + (s + t + 1) % n
    x, y = np.ascontiguousarray(positions[..., 0]), np.ascontiguousarray(positions[..., 1])
    x0, y0 = x[:, :, None], y[:, :, None]
    x1, y1 = x.take(i1) - x0, y.take(i1) - y0
    x2, y2 = x.take(i2) - x0, y.take(i2) - y0
    used = t < n - 1  # fan triangle t exists
    good = all_of((x1 * y2 - y1 * x2 > _EPS_AREA) | ~used, axis=2) & (s[..., 0] < lengths[:, None])
    fan = any_of(good, axis=1)
    rows = np.flatnonzero(fan)
    start = good.argmax(axis=1).take(rows)[:, None]
    n = lengths.take(rows)[:, None]
    t = t[0, 0][None, :]
    row = (rows * width)[:, None]
    flat = faces.ravel()
    tris = np.stack([np.broadcast_to(flat.take(row + start), (len(rows), width - 2)),
                     flat.take(row + (start + t) % n), flat.take(row + (start + t + 1) % n)], -1)[t < n - 1]
    if fan.all():
        return tris
    rest = np.flatnonzero(~fan)
    return np.concatenate([tris, _ear_clip(faces[rest], positions[rest], lengths[rest])])


def _ear_clip(faces: I64, positions: F64, lengths: I64) -> I64:
    """Triangulate simple counter-clockwise polygons (padded, all at once) by ear clipping."""
    f, width = faces.shape
    slot = np.arange(width)
    alive = slot[None, :] < lengths[:, None]
    nxt = np.where(slot[None, :] + 1 < lengths[:, None], slot[None, :] + 1, 0)
    prv = np.where(slot[None, :] > 0, slot[None, :] - 1, lengths[:, None] - 1)
    remaining = lengths.copy()
    rows = np.arange(f)
    out = []
    scale = 1e-12
    for _ in range(width - 2):  # one ear per face per pass
        active = remaining >= 3
        if not active.any():
            break
        a = positions[rows[:, None], prv]
        c = positions[rows[:, None], nxt]
        b = positions
        ab, bc = b - a, c - b
        turn = ab[..., 0] * bc[..., 1] - ab[..., 1] * bc[..., 0]
        convex = alive & (turn > scale)
        blocked = _blocked(positions, alive, a, b, c, scale)
        ear = convex & ~blocked
        pick = np.where(ear.any(1), np.argmax(ear, 1), np.argmax(np.where(alive, turn, -np.inf), 1))
        pick = np.where(remaining == 3, np.argmax(alive, 1), pick)
        pa, pc = prv[rows, pick], nxt[rows, pick]
        tri = np.stack([faces[rows, pa], faces[rows, pick], faces[rows, pc]], -1)
        area = turn[rows, pick]
        emit = active & (np.abs(area) > scale)
        out.append(tri[emit])
        act = np.flatnonzero(active)
        nxt[act, pa[act]] = pc[act]
        prv[act, pc[act]] = pa[act]
        alive[act, pick[act]] = False
        remaining[act] -= 1
    return np.concatenate(out) if out else np.zeros((0, 3), np.int64)


def _blocked(positions: F64, alive: np.ndarray, a: F64, b: F64, c: F64, eps: float) -> np.ndarray:
    """(F, L): whether another live vertex lies inside or on the triangle (a, b, c) of each candidate ear.

    Coordinates one at a time, test points along the last axis: (F, L, L) arrays whose inner axis is long."""
    qx, qy = positions[:, None, :, 0], positions[:, None, :, 1]  # test points along axis 2
    corners = [(p[..., 0][..., None], p[..., 1][..., None]) for p in (a, b, c)]

    def side(p0, p1):
        return (p1[0] - p0[0]) * (qy - p0[1]) - (p1[1] - p0[1]) * (qx - p0[0])

    inside = (side(corners[0], corners[1]) >= -eps) & (side(corners[1], corners[2]) >= -eps)
    inside &= side(corners[2], corners[0]) >= -eps
    inside &= alive[:, None, :]
    for x, y in corners:
        dx, dy = qx - x, qy - y
        inside &= dx * dx + dy * dy >= 1e-20  # the triangle's own corners do not block it
    return np.logical_or.reduce(inside, axis=2)
