"""Compiled kernels (``engine.jit.kernel``) for one water step of seeds/003: the body outline in the water model
(sections 2.2.2–2.2.3), the waves it makes (eq. 2.5–2.7) and the propagation with the added points (eq. 2.8–2.12).

The numpy functions of ``outline.py``, ``waves.py`` and ``surface.py`` are the readable statement of the method;
these kernels do the same arithmetic in the same order, in a few calls per step instead of hundreds of numpy calls
(a 26 × 26 pool is bound by per-call overhead) and in one pass over a large grid instead of seven. Results are the
same bits: where numpy sums an array it uses pairwise summation (:func:`engine.jit.pairwise_sum` repeats it),
``bincount`` sums in order of appearance, a reduction along a leading axis sums in index order; the tests compare
every kernel with its numpy counterpart.

No loop here runs in Python: each is compiled (numba), with IEEE arithmetic in the order written (no fastmath).
"""

from __future__ import annotations

import math

import numpy as np

from engine.exact import atan2_scalar, hypot_scalar
from engine.jit import kernel, pairwise_sum

# Constants of outline.py / geometry.py, repeated as plain numbers for the compiled code.
EPS_LINE = 1e-7
NUDGE = 1e-4
ON_OUTLINE = 3.0 * NUDGE
CROSSING_KEY = 1 << 30
MAX_BOX_VERTICES = 6
DENSE_PAIRS = 96
BUFFER = 8192  # numpy's iterator buffer: a strided window's mean sums blocks of this many values


@kernel
def water_mean(field, solid):
    """Mean height of the water vertices: (Σ field − Σ field[solid]) / (size − len(solid)), each sum as numpy's
    ``np.add.reduce`` takes it (``surface._water_mean``); ``solid`` ascending flat indices (may be empty).  When
    bodies cover every vertex there is no water to measure: the mean of all the vertices (0/0 before, which
    made the whole pool NaN for good)."""
    flat = field.ravel()
    total = 0.0 + pairwise_sum(flat, 0, flat.size)
    if len(solid) == 0 or len(solid) >= flat.size:
        return total / flat.size
    held = np.empty(len(solid))
    for i in range(len(solid)):
        held[i] = flat[solid[i]]
    return (total - (0.0 + pairwise_sum(held, 0, len(held)))) / (flat.size - len(solid))


# ------------------------------------------------------------------------------------------------ bodies
# R − I of a unit quaternion (w, x, y, z) = 2·[[−yy − zz, xy − wz, xz + wy], [xy + wz, −xx − zz, yz − wx],
# [xz − wy, yz + wx, −xx − yy]]: per entry two products q_a·q_b with their signs (also bodies.quat_to_matrix).
QUAT_TERMS = np.array([[-1, 2, 2, -1, 3, 3], [1, 1, 2, -1, 0, 3], [1, 1, 3, 1, 0, 2],
                        [1, 1, 2, 1, 0, 3], [-1, 1, 1, -1, 3, 3], [1, 2, 3, -1, 0, 1],
                        [1, 1, 3, -1, 0, 2], [1, 2, 3, 1, 0, 1], [-1, 1, 1, -1, 2, 2]], np.int64)


@kernel
def wave_bodies(table, radius, terms):
    """The bodies that cut the water (``simulate.gather_wave_bodies``) from ``table``, the blocks (positions (B, 3),
    quaternions (B, 4), scales (B, 3), local half extents (B, 3)) one after the other, and the local radii (B,):
    one buffer holding half extents × |scale| (B, 3), radius × max |scale| (B,), positions (B, 3) and rotation
    matrices (B, 3, 3).

    The matrices are ``bodies.quat_to_matrix``'s bits: per entry (±2·q_a·q_b + ±2·q_c·q_d) + δ, in that order.
    """
    n = len(radius)
    out = np.empty(16 * n)
    quats, scales, halves = 3 * n, 7 * n, 10 * n
    for b in range(n):
        s0, s1, s2 = abs(table[scales + 3 * b]), abs(table[scales + 3 * b + 1]), abs(table[scales + 3 * b + 2])
        out[3 * b] = table[halves + 3 * b] * s0
        out[3 * b + 1] = table[halves + 3 * b + 1] * s1
        out[3 * b + 2] = table[halves + 3 * b + 2] * s2
        out[3 * n + b] = radius[b] * max(max(s0, s1), s2)
        for i in range(3):
            out[4 * n + 3 * b + i] = table[3 * b + i]
        q = table[quats + 4 * b:quats + 4 * b + 4]
        for e in range(9):
            first = (2.0 * terms[e, 0]) * (q[terms[e, 1]] * q[terms[e, 2]])
            second = (2.0 * terms[e, 3]) * (q[terms[e, 4]] * q[terms[e, 5]])
            out[7 * n + 9 * b + e] = (first + second) + (1.0 if e % 4 == 0 else 0.0)
    return out


# ----------------------------------------------------------------------------------------------- sampling
@kernel(inline="always")
def _cell(nx, nz, u, v):
    """The grid cell (i, j) holding the point (u, v) clamped to the grid, and the point's fractions (tu, tv) in it."""
    cu = min(max(u, 0.0), nx - 1)
    cv = min(max(v, 0.0), nz - 1)
    i = min(int(cu), nx - 2)
    j = min(int(cv), nz - 2)
    return i, j, cu - i, cv - j


@kernel(inline="always")
def _bilinear(f, nx, nz, u, v):
    """geometry.bilinear at one point (eq. 2.2; eq. 2.3/2.4 on a grid edge), ``f`` flat, clamped to the grid."""
    i, j, tu, tv = _cell(nx, nz, u, v)
    c = j * nx + i
    z00, z10, z01, z11 = f[c], f[c + 1], f[c + nx], f[c + nx + 1]
    bottom = z00 + tu * (z10 - z00)
    top = z01 + tu * (z11 - z01)
    return bottom + tv * (top - bottom)


@kernel(inline="always")
def _bilinear_slope(f, u, v):
    """geometry.bilinear_with_slope at one point, ``f`` 2-D: the derivatives ∂/∂u, ∂/∂v per grid unit (clamped to
    the grid as :func:`_bilinear`)."""
    nz, nx = f.shape
    i, j, tu, tv = _cell(nx, nz, u, v)
    z00, z10 = f[j, i], f[j, i + 1]
    z01, z11 = f[j + 1, i], f[j + 1, i + 1]
    du = (1.0 - tv) * (z10 - z00) + tv * (z11 - z01)
    return du, (z01 + tu * (z11 - z01)) - (z00 + tu * (z10 - z00))


@kernel
def plane_levels(z, solid, centre, half):
    """S'_z − y0 of each body (``surface.plane_levels``, section 2.2.2): the mean height of the water vertices in
    its footprint window (grid units ``centre`` ± ``half``), of every vertex there when all were inside bodies,
    the height at its centre when the window holds no vertex. Up to 3 bodies numpy took each window's mean
    (pairwise sums), more bodies were summed in order (``bincount``): both are repeated.

    Returns (levels, fallback): ``fallback[b]`` marks a body whose all-solid window is too large to repeat
    numpy's buffered mean (more than 8192 vertices): the caller takes that mean with numpy."""
    nz, nx = z.shape
    nb = len(centre)
    f = z.ravel()
    s = solid.ravel()
    levels = np.empty(nb)
    fallback = np.zeros(nb, np.bool_)
    few = nb <= 3
    buffer = np.empty(0)
    for b in range(nb):
        lo_u = np.int64(max(math.ceil(centre[b, 0] - half[b, 0]), 0))
        lo_v = np.int64(max(math.ceil(centre[b, 1] - half[b, 1]), 0))
        hi_u = np.int64(min(math.floor(centre[b, 0] + half[b, 0]), nx - 1))
        hi_v = np.int64(min(math.floor(centre[b, 1] + half[b, 1]), nz - 1))
        su, sv = max(hi_u - lo_u + 1, 0), max(hi_v - lo_v + 1, 0)
        if su == 0 or sv == 0:
            levels[b] = _bilinear(f, nx, nz, centre[b, 0], centre[b, 1])
            continue
        count = su * sv
        if len(buffer) < count:
            buffer = np.empty(count)
        if few:
            n = 0
            for j in range(lo_v, hi_v + 1):
                for i in range(lo_u, hi_u + 1):
                    c = j * nx + i
                    if not s[c]:
                        buffer[n] = f[c]
                        n += 1
            if n > 0:
                levels[b] = (0.0 + pairwise_sum(buffer, 0, n)) / n
                continue
            if count > BUFFER:
                fallback[b] = True
                levels[b] = 0.0
                continue
            n = 0
            for j in range(lo_v, hi_v + 1):
                for i in range(lo_u, hi_u + 1):
                    buffer[n] = f[j * nx + i]
                    n += 1
            levels[b] = (0.0 + pairwise_sum(buffer, 0, n)) / count
        else:
            wet, every, n_water = 0.0, 0.0, 0.0
            for j in range(lo_v, hi_v + 1):
                for i in range(lo_u, hi_u + 1):
                    c = j * nx + i
                    height = f[c]
                    water = not s[c]
                    n_water += 1.0 if water else 0.0
                    wet += height if water else 0.0
                    every += height
            levels[b] = wet / max(n_water, 1.0) if n_water > 0.0 else every / count
    return levels, fallback


@kernel
def extents(shapes, half, radius, rotation):
    """(B, 3) half size of each body's axis-aligned bounding box (``Bodies.extent``): Σ_j |R_ij|·half_j for a box
    (summed in order j = 0, 1, 2: numpy's einsum may round the last bit differently; the extent only decides
    which bodies and vertices a step looks at), the radius for a sphere."""
    nb = len(shapes)
    out = np.empty((nb, 3))
    for b in range(nb):
        for i in range(3):
            if shapes[b] == 0:
                out[b, i] = (abs(rotation[b, i, 0]) * half[b, 0] + abs(rotation[b, i, 1]) * half[b, 1]) \
                    + abs(rotation[b, i, 2]) * half[b, 2]
            else:
                out[b, i] = radius[b]
    return out


@kernel
def near_bodies(extent, position, x0, z0, h, nx, nz, y0, depth, heights):
    """``surface._near``: bodies whose footprint overlaps the grid and whose vertical extent reaches the water
    (from two half heights above the highest wave; the first height settles most bodies, the maximum is found
    only when one is not settled by it)."""
    nb = len(extent)
    near = np.zeros(nb, np.bool_)
    candidate = np.zeros(nb, np.bool_)
    first = heights.ravel()[0] + y0
    unsettled = False
    for b in range(nb):
        cu = (position[b, 0] - x0) / h
        cv = (position[b, 2] - z0) / h
        hu, hv = extent[b, 0] / h, extent[b, 2] / h
        over = (cu + hu >= 0.0) and (cu - hu <= nx - 1) and (cv + hv >= 0.0) and (cv - hv <= nz - 1)
        candidate[b] = over and position[b, 1] + extent[b, 1] >= y0 - depth
        near[b] = candidate[b] and position[b, 1] - 2.0 * extent[b, 1] <= first + 1e-9
        unsettled |= candidate[b] and not near[b]
    if unsettled:
        highest = heights.max() + y0
        for b in range(nb):
            near[b] = candidate[b] and position[b, 1] - 2.0 * extent[b, 1] <= highest + 1e-9
    return near


@kernel
def bodies_in_water(z, solid, solid_flat, need_volume, shapes, half, radius, position, rotation, x0, z0, h, y0,
                    depth, signs, plane_margin, plane_cells):
    """The start of a step (``surface.step_water``): the water's mean level (the volume to keep) when
    ``need_volume``, the bodies near the water (:func:`near_bodies`) and their plane levels S'_z − y0
    (:func:`plane_levels`, windows grown by ``surface.plane_margin``), and each body's box corners in its own
    frame, ``signs`` (3, 8) × half extents.
    Returns (volume, number near N, number of fallback windows, floats, flags): floats holds the local corners
    (B, 3, 8) then the levels of the near bodies (N), flags (int8) the near mask (B) then the fallback mask (N)
    (two buffers instead of four arrays: each array handed back to Python costs about a microsecond)."""
    nz, nx = z.shape
    nb, nc = len(shapes), signs.shape[1]
    volume = water_mean(z, solid_flat) if need_volume else 0.0
    extent = extents(shapes, half, radius, rotation)
    near = near_bodies(extent, position, x0, z0, h, nx, nz, y0, depth, z)
    count = 0
    for b in range(len(near)):
        count += 1 if near[b] else 0
    centre = np.empty((count, 2))
    size = np.empty((count, 2))
    r = 0
    for b in range(len(near)):
        if near[b]:
            centre[r, 0], centre[r, 1] = (position[b, 0] - x0) / h, (position[b, 2] - z0) / h
            su, sv = extent[b, 0] / h, extent[b, 2] / h
            margin = max(plane_margin * max(su, sv), plane_cells)  # surface.plane_margin
            size[r, 0], size[r, 1] = su + margin, sv + margin
            r += 1
    levels, fallback = plane_levels(z, solid, centre, size)
    floats = np.empty(nb * 3 * nc + count)
    for b in range(nb):
        for i in range(3):
            for c in range(nc):
                floats[(b * 3 + i) * nc + c] = signs[i, c] * half[b, i]
    floats[nb * 3 * nc:] = levels
    flags = np.empty(nb + count, np.int8)
    n_fallback = 0
    for b in range(nb):
        flags[b] = 1 if near[b] else 0
    for b in range(count):
        flags[nb + b] = 1 if fallback[b] else 0
        n_fallback += 1 if fallback[b] else 0
    return volume, count, n_fallback, floats, flags


# ------------------------------------------------------------------------------------- cross-sections D'
@kernel
def box_sections(corners, plane_y, edge_a, edge_b, shared_face, x0, z0, h, polygons, counts, vfeat, efeat, rows):
    """Cross-section D' of boxes ``rows`` with their planes y = plane_y (section 2.2.2; ``outline._box_sections``,
    ``_sort_ccw``, ``_box_edge_faces``): each box edge QR straddling the plane gives L = Q + t·(R − Q), sorted
    counter-clockwise about the centroid (the first 6 columns keep the remaining edges' points as padding, as
    numpy's sort left them); a box corner on the plane gives one L' from several edges: the repeats are dropped.
    Written into ``polygons`` (B, W, 2), ``counts``, ``vfeat`` and ``efeat`` at the rows ``rows``."""
    ne = len(edge_a)
    exact = False
    for r in range(len(rows)):
        b = rows[r]
        for e in range(ne):
            if corners[b, 1, edge_a[e]] - plane_y[b] == 0.0 or corners[b, 1, edge_b[e]] - plane_y[b] == 0.0:
                exact = True
    u = np.empty(ne)
    v = np.empty(ne)
    valid = np.empty(ne, np.bool_)
    angle = np.empty(ne)
    order = np.empty(ne, np.int64)
    buf = np.empty(ne)
    for r in range(len(rows)):
        b = rows[r]
        py = plane_y[b]
        n = 0
        for e in range(ne):
            qa, qb = edge_a[e], edge_b[e]
            yq = corners[b, 1, qa] - py
            yr = corners[b, 1, qb] - py
            straddle = (yq >= 0.0) != (yr >= 0.0)
            t = yq / (yq - yr if straddle else 1.0)
            u[e] = (corners[b, 0, qa] + t * (corners[b, 0, qb] - corners[b, 0, qa]) - x0) / h
            v[e] = (corners[b, 2, qa] + t * (corners[b, 2, qb] - corners[b, 2, qa]) - z0) / h
            valid[e] = straddle
            n += 1 if straddle else 0
        inv = 1.0 / max(n, 1)
        for e in range(ne):
            buf[e] = u[e] if valid[e] else 0.0
        cu = (0.0 + pairwise_sum(buf, 0, ne)) * inv
        for e in range(ne):
            buf[e] = v[e] if valid[e] else 0.0
        cv = (0.0 + pairwise_sum(buf, 0, ne)) * inv
        for e in range(ne):  # stable insertion sort by angle (inf for the edges that do not straddle)
            a = atan2_scalar(v[e] - cv, u[e] - cu) if valid[e] else np.inf
            k = e
            while k > 0 and angle[k - 1] > a:
                angle[k] = angle[k - 1]
                order[k] = order[k - 1]
                k -= 1
            angle[k] = a
            order[k] = e
        width = MAX_BOX_VERTICES
        for k in range(width):
            polygons[b, k, 0] = u[order[k]]
            polygons[b, k, 1] = v[order[k]]
            vfeat[b, k] = order[k]
        if exact:  # a box vertex on the plane: drop the repeats (kept first, the rest after them in order)
            keep = np.empty(width, np.bool_)
            m = 0
            for k in range(width):
                if k >= n:
                    keep[k] = False
                    continue
                p = n - 1 if k == 0 else k - 1
                p = max(p, 0)
                du = polygons[b, k, 0] - polygons[b, p, 0]
                dv = polygons[b, k, 1] - polygons[b, p, 1]
                repeat = k > 0 and (du * du + dv * dv) < 1e-20
                keep[k] = not repeat
                m += 0 if repeat else 1
            pu, pv, pf = polygons[b, :width, 0].copy(), polygons[b, :width, 1].copy(), vfeat[b, :width].copy()
            at = 0
            for flag in (True, False):
                for k in range(width):
                    if keep[k] == flag:
                        polygons[b, at, 0], polygons[b, at, 1], vfeat[b, at] = pu[k], pv[k], pf[k]
                        at += 1
            n = m
        c = n if n >= 3 else 0
        counts[b] = c
        for k in range(width):
            following = k + 1 if k + 1 < c else 0
            face = shared_face[vfeat[b, k], vfeat[b, following]]
            efeat[b, k] = face if face >= 0 else 6 + k


@kernel
def sphere_sections(position, radius, plane_y, ring, x0, z0, h, polygons, counts, vfeat, efeat, rows):
    """Cross-section of spheres ``rows``: the regular polygon inscribed in the circle of intersection
    (``outline._sphere_sections``), written like :func:`box_sections`."""
    segments = len(ring)
    for r in range(len(rows)):
        b = rows[r]
        d = plane_y[b] - position[b, 1]
        rho2 = radius[b] * radius[b] - d * d
        rho = math.sqrt(max(rho2, 0.0)) / h
        cu = (position[b, 0] - x0) / h
        cv = (position[b, 2] - z0) / h
        for k in range(segments):
            polygons[b, k, 0] = cu + rho * ring[k, 0]
            polygons[b, k, 1] = cv + rho * ring[k, 1]
            vfeat[b, k] = k
            efeat[b, k] = k
        counts[b] = segments if rho2 > 0.0 else 0


@kernel(inline="always")
def _centre(polygons, counts, b):
    """``Sections.centres`` of polygon b: its valid vertices summed in order, over max(count, 1)."""
    su, sv = 0.0, 0.0
    for k in range(polygons.shape[1]):
        if k < counts[b]:
            su += polygons[b, k, 0]
            sv += polygons[b, k, 1]
        else:
            su += 0.0
            sv += 0.0
    n = max(counts[b], 1)
    return su / n, sv / n


@kernel(inline="always")
def _on_line(x):
    return abs(x - np.rint(x)) < EPS_LINE


@kernel
def nudge(polygons, counts):
    """``outline.nudge`` in place (figure 2.3): vertices on a grid line or vertex move NUDGE towards the centre,
    then off a line they ran along. Returns whether any moved."""
    moved = False
    for b in range(len(counts)):
        any_on = False
        for k in range(counts[b]):
            if _on_line(polygons[b, k, 0]) or _on_line(polygons[b, k, 1]):
                any_on = True
        if not any_on:
            continue
        moved = True
        cu, cv = _centre(polygons, counts, b)
        for k in range(counts[b]):
            pu, pv = polygons[b, k, 0], polygons[b, k, 1]
            if _on_line(pu) or _on_line(pv):
                tu, tv = cu - pu, cv - pv
                length = math.sqrt(0.0 + tu * tu + tv * tv)
                safe = length if length > 0.0 else 1.0
                pu = pu + NUDGE * tu / safe
                pv = pv + NUDGE * tv / safe
            if _on_line(pu):
                pu = pu + NUDGE * (1.0 if cu - pu >= 0.0 else -1.0)
            if _on_line(pv):
                pv = pv + NUDGE * (1.0 if cv - pv >= 0.0 else -1.0)
            polygons[b, k, 0], polygons[b, k, 1] = pu, pv
    return moved


# -------------------------------------------------------------------------------------------- added points
@kernel
def _crossings(polygons, counts, vfeat, efeat, strict):
    """``outline._outline`` and the ordering of ``outline.added_points``: per polygon edge, its start L' then its
    crossings M' with the grid lines sorted by the numpy sort key (edge index·2 + t, stable: u-lines before
    v-lines, ascending lines). Returns (uv, kind, keys without the entity, body, ok); ok is False when, with
    ``strict``, an edge crosses a u-line at a grid vertex."""
    nb, width = counts.shape[0], polygons.shape[1]
    total = 0
    for b in range(nb):
        for k in range(counts[b]):
            nxt = k + 1 if k + 1 < counts[b] else 0
            for axis in range(2):
                a, e = polygons[b, k, axis], polygons[b, nxt, axis] - polygons[b, k, axis]
                end = a + e
                total += 1 + np.int64(math.floor(max(a, end))) - np.int64(math.floor(min(a, end)))
    uv = np.empty((total, 2))
    kind = np.empty(total, np.int8)
    keys = np.empty(total, np.int64)
    body = np.empty(total, np.int64)
    sort = np.empty(64)
    tmp_t = np.empty(64)
    tmp_line = np.empty(64, np.int64)
    tmp_axis = np.empty(64, np.int64)
    at = 0
    for b in range(nb):
        for k in range(counts[b]):
            nxt = k + 1 if k + 1 < counts[b] else 0
            au, av = polygons[b, k, 0], polygons[b, k, 1]
            eu, ev = polygons[b, nxt, 0] - au, polygons[b, nxt, 1] - av
            base = (b * width + k) * 2.0
            uv[at, 0], uv[at, 1] = au, av
            kind[at] = 2
            keys[at] = vfeat[b, k] << 22
            body[at] = b
            at += 1
            n = 0
            for axis in range(2):
                a = au if axis == 0 else av
                d = eu if axis == 0 else ev
                end = a + d
                lo = np.int64(math.floor(min(a, end)))
                hi = np.int64(math.floor(max(a, end)))
                count = hi - lo
                if n + count > len(sort):
                    size = 2 * (n + count)
                    sort, tmp_t = _grow(sort, size), _grow(tmp_t, size)
                    tmp_line, tmp_axis = _grow_int(tmp_line, size), _grow_int(tmp_axis, size)
                for line in range(lo + 1, hi + 1):
                    t = (line - a) / d
                    key = base + t
                    m = n  # stable insertion by the sort key
                    while m > 0 and sort[m - 1] > key:
                        sort[m], tmp_t[m], tmp_line[m], tmp_axis[m] = sort[m - 1], tmp_t[m - 1], tmp_line[m - 1], \
                            tmp_axis[m - 1]
                        m -= 1
                    sort[m], tmp_t[m], tmp_line[m], tmp_axis[m] = key, t, line, axis
                    n += 1
            for m in range(n):
                t, line, axis = tmp_t[m], tmp_line[m], tmp_axis[m]
                other = av + t * ev if axis == 0 else au + t * eu
                if strict and axis == 0 and abs(other - np.rint(other)) < EPS_LINE:
                    return uv, kind, keys, body, False
                if axis == 0:
                    uv[at, 0], uv[at, 1] = line, other
                else:
                    uv[at, 0], uv[at, 1] = other, line
                kind[at] = axis
                keys[at] = (efeat[b, k] << 22) | (axis << 21) | line | CROSSING_KEY
                body[at] = b
                at += 1
    return uv[:at], kind[:at], keys[:at], body[:at], True


@kernel
def _grow(a, size):
    out = np.empty(size)
    out[:len(a)] = a
    return out


@kernel
def _grow_int(a, size):
    out = np.empty(size, np.int64)
    out[:len(a)] = a
    return out


@kernel
def added_points(polygons, counts, vfeat, efeat, entities, nx, nz):
    """``outline.added_points``: the vertices L' and grid-line crossings M' of every cross-section in order along
    its outline, with their kinds, keys (entity in the high 32 bits) and bodies, and the outline segments between
    consecutive points on the grid's footprint. An edge through a grid vertex shrinks every polygon a hair about
    its centre and tries again (three times; the fourth try accepts it). ``polygons`` is shrunk in place.
    Returns (uv, kind, keys, body, segments)."""
    uv, kind, keys, body, ok = _crossings(polygons, counts, vfeat, efeat, True)
    for attempt in range(3):
        if ok:
            break
        factor = 1.0 - 1e-6 * (attempt + 1)
        for b in range(len(counts)):
            cu, cv = _centre(polygons, counts, b)
            for k in range(polygons.shape[1]):
                polygons[b, k, 0] = cu + (polygons[b, k, 0] - cu) * factor
                polygons[b, k, 1] = cv + (polygons[b, k, 1] - cv) * factor
        uv, kind, keys, body, ok = _crossings(polygons, counts, vfeat, efeat, attempt < 2)
    n = len(uv)
    for i in range(n):
        keys[i] = (entities[body[i]] << 32) | keys[i]
    nxt = np.empty(n, np.int64)
    first = 0
    for i in range(n):  # each point's successor along its outline (the last closes on the first)
        if i > 0 and body[i] != body[i - 1]:
            first = i
        if i + 1 < n and body[i + 1] == body[i]:
            nxt[i] = i + 1
        else:
            nxt[i] = first
    keep = np.empty(n, np.bool_)
    remap = np.empty(n, np.int64)
    kept = 0
    for i in range(n):
        keep[i] = (uv[i, 0] >= 0.0) and (uv[i, 0] <= nx - 1) and (uv[i, 1] >= 0.0) and (uv[i, 1] <= nz - 1)
        remap[i] = kept
        kept += 1 if keep[i] else 0
    segments = np.empty((n, 2), np.int64)
    s = 0
    for i in range(n):
        if keep[i] and keep[nxt[i]]:
            segments[s, 0], segments[s, 1] = remap[i], remap[nxt[i]]
            s += 1
    if kept == n:
        return uv, kind, keys, body, segments[:s]
    out_uv = np.empty((kept, 2))
    out_kind = np.empty(kept, np.int8)
    out_keys = np.empty(kept, np.int64)
    out_body = np.empty(kept, np.int64)
    for i in range(n):
        if keep[i]:
            r = remap[i]
            out_uv[r, 0], out_uv[r, 1], out_kind[r], out_keys[r], out_body[r] = uv[i, 0], uv[i, 1], kind[i], \
                keys[i], body[i]
    return out_uv, out_kind, out_keys, out_body, segments[:s]


# ------------------------------------------------------------------------------------------- edges of D'
@kernel
def edge_table(polygons, counts):
    """``outline.Edges.table`` as (B, V, 9) rows per edge: start u, v; direction; inward normal; c (−∞ on padding,
    +∞ on every edge of a polygon with fewer than 3 vertices); |e|² (1 where 0); 0 on a real edge, ∞ on padding."""
    nb, width = polygons.shape[0], polygons.shape[1]
    table = np.empty((nb, width, 9))
    for b in range(nb):
        for k in range(width):
            valid = k < counts[b]
            nxt = k + 1 if k + 1 < counts[b] else 0
            au, av = polygons[b, k, 0], polygons[b, k, 1]
            eu, ev = polygons[b, nxt, 0] - au, polygons[b, nxt, 1] - av
            length2 = eu * eu + ev * ev
            length = hypot_scalar(eu, ev)
            real = valid and length > 0.0
            inv = 1.0 / length if real else 0.0
            nu, nv = ev * (inv * -1.0), eu * (inv * 1.0)
            c = nu * au + nv * av if real else -np.inf
            row = table[b, k]
            row[0], row[1], row[2], row[3], row[4], row[5] = au, av, eu, ev, nu, nv
            row[6] = c if counts[b] > 2 else np.inf
            row[7] = length2 if length2 > 0.0 else 1.0
            row[8] = 0.0 if valid else np.inf
    return table


@kernel(inline="always")
def _inside(table, b, u, v, margin):
    """``outline._inside``: (u, v) inside polygon b by more than ``margin``. A polygon with fewer than 3 vertices
    (c = +∞) contains nothing; padding edges (after the real ones) contain everything, so the loop stops there."""
    if table[b, 0, 6] == np.inf:
        return False
    for k in range(table.shape[1]):
        row = table[b, k]
        if row[8] != 0.0:
            break
        if not ((row[4] * u + row[5] * v) - row[6] > margin):
            return False
    return True


@kernel(inline="always")
def _nearest(table, b, u, v):
    """``outline._nearest``: the point of polygon b's outline nearest to (u, v) (the first of equal distances;
    padding edges, at distance ∞, only when the polygon has no edge)."""
    best, bu, bv = np.inf, 0.0, 0.0
    for k in range(table.shape[1]):
        row = table[b, k]
        if k > 0 and row[8] != 0.0:
            break
        ax, ay, ex, ey = row[0], row[1], row[2], row[3]
        t = min(max(((u - ax) * ex + (v - ay) * ey) / row[7], 0.0), 1.0)
        fx, fy = ax + t * ex, ay + t * ey
        dx, dy = fx - u, fy - v
        dist2 = dx * dx + dy * dy + row[8]
        if k == 0 or dist2 < best:
            best, bu, bv = dist2, fx, fy
    return bu, bv


@kernel
def outline_impulse(uv, body, before, has_before, after, h, alpha, nb):
    """±α·d(t) for every added point (eq. 2.5–2.7; ``outline.outline_impulse``): N_c(t − 1) is the nearest point
    of D'(t − 1) (``before``, edge tables); N_c rises by α·d(t) when N_c(t − 1) lies inside D'(t) (``after``),
    sinks when N_c(t) lay inside D'(t − 1); each body's mean change is taken off its points.
    Returns (change, raised, lowered)."""
    m = len(uv)
    change = np.empty(m)
    raised = np.zeros(m, np.bool_)
    lowered = np.zeros(m, np.bool_)
    total = np.zeros(nb)
    number = np.zeros(nb, np.int64)
    for i in range(m):
        b = body[i]
        u, v = uv[i, 0], uv[i, 1]
        if has_before[b]:
            bu, bv = _nearest(before, b, u, v)
            raised[i] = _inside(after, b, bu, bv, -ON_OUTLINE)
            lowered[i] = _inside(before, b, u, v, -ON_OUTLINE)
        else:
            bu, bv = u, v
        d = hypot_scalar(u - bu, v - bv) * h  # eq. 2.5
        sign = (1.0 if raised[i] else 0.0) - (1.0 if lowered[i] else 0.0)
        change[i] = alpha * d * sign  # eq. 2.6 / 2.7
        total[b] += change[i]
        number[b] += 1
    for i in range(m):
        b = body[i]
        change[i] = change[i] - total[b] / max(number[b], 1)
    return change, raised, lowered


# ------------------------------------------------------------------------------------------------ coupling
@kernel
def solid_vertices(table, counts, nx, nz):
    """``outline.solid_vertices``: grid vertices strictly inside a cross-section by scanlines (body, row,
    column order). Returns (flat vertex index, body index)."""
    nb, width = table.shape[0], table.shape[1]
    cap = 64
    flat = np.empty(cap, np.int64)
    owner = np.empty(cap, np.int64)
    n = 0
    for b in range(nb):
        if counts[b] < 3:
            continue
        low, high = np.inf, -np.inf
        for k in range(width):
            if table[b, k, 8] == 0.0:
                low = min(low, table[b, k, 1])
                high = max(high, table[b, k, 1])
        lo = np.int64(max(math.ceil(low), 0.0))
        hi = np.int64(min(math.floor(high), nz - 1.0))
        for row in range(lo, hi + 1):
            left, right = np.inf, -np.inf
            for k in range(width):
                r = table[b, k]
                dv = r[3]
                if dv == 0.0 or r[8] != 0.0:
                    continue
                t = (row - r[1]) / dv
                if t >= 0.0 and t < 1.0:
                    u = r[0] + t * r[2]
                    left = min(left, u)
                    right = max(right, u)
            if not (left < np.inf and right > -np.inf):
                continue
            first = np.int64(max(math.floor(left + 1e-9) + 1, 0.0))
            last = np.int64(min(math.ceil(right - 1e-9) - 1, nx - 1.0))
            if last - first + 1 > 0 and n + last - first + 1 > cap:
                cap = 2 * (n + last - first + 1)
                flat, owner = _grow_int(flat, cap), _grow_int(owner, cap)
            for i in range(first, last + 1):
                flat[n] = row * nx + i
                owner[n] = b
                n += 1
    return flat[:n], owner[:n]


@kernel
def solid_mask(solid, shape_z, shape_x):
    """The grid's mask of the vertices inside bodies and their flat indices once each, ascending."""
    mask = np.zeros((shape_z, shape_x), np.bool_)
    flat = mask.ravel()
    for i in range(len(solid)):
        flat[solid[i]] = True
    unique = np.sort(solid)
    n = 0
    for i in range(len(unique)):
        if i == 0 or unique[i] != unique[i - 1]:
            unique[n] = unique[i]
            n += 1
    return mask, unique[:n]


@kernel
def grid_pairs(uv, solid, nx, nz):
    """Grid vertices within radius h of the added points (eq. 2.11; ``outline.coupling_pairs``), the corners of
    each point's square that are water: (vertex, point, weight r_k / h = 1 − distance / h), point by point."""
    m = len(uv)
    g = np.empty(4 * m, np.int64)
    p = np.empty(4 * m, np.int64)
    w = np.empty(4 * m)
    s = solid.ravel()
    n = 0
    for i in range(m):
        u, v = uv[i, 0], uv[i, 1]
        fu, fv = math.floor(u), math.floor(v)
        base = np.int64(fv) * nx + np.int64(fu)
        for c in range(4):
            cu = fu + (c & 1)
            cv = fv + (c >> 1)
            du, dv = cu - u, cv - v
            dist = math.sqrt(du * du + dv * dv)
            if dist < 1.0 and cu < nx and cv < nz:
                vertex = base + (c & 1) + (c >> 1) * nx
                if not s[vertex]:
                    g[n], p[n], w[n] = vertex, i, 1.0 - dist
                    n += 1
    return g[:n], p[:n], w[:n]


@kernel
def point_pairs(uv, nx, nz):
    """Pairs of added points within radius h (eq. 2.12; ``outline.coupling_pairs``), both directions, in numpy's
    order: the full distance matrix row by row up to 96 points, else each point against its own square and half
    of the 8 around it (points sorted by square), then the same pairs reversed. Returns (point, point, weight)."""
    m = len(uv)
    if m <= DENSE_PAIRS:
        a = np.empty(m * m, np.int64)
        b = np.empty(m * m, np.int64)
        w = np.empty(m * m)
        n = 0
        for i in range(m):
            for j in range(m):
                if i == j:
                    continue
                du, dv = uv[i, 0] - uv[j, 0], uv[i, 1] - uv[j, 1]
                dd = math.sqrt(du * du + dv * dv)
                if dd < 1.0:
                    a[n], b[n], w[n] = i, j, 1.0 - dd
                    n += 1
        return a[:n], b[:n], w[:n]
    stride = nx + 3
    cell = np.empty(m, np.int64)
    key = np.empty(m, np.int64)
    for i in range(m):
        cell[i] = (np.int64(math.floor(uv[i, 1])) + 1) * stride + np.int64(math.floor(uv[i, 0])) + 1
        key[i] = cell[i] * m + i  # unique: sorting it is numpy's stable sort of the squares
    key.sort()
    order = np.empty(m, np.int64)
    sorted_cell = np.empty(m, np.int64)
    for r in range(m):
        sorted_cell[r], order[r] = key[r] // m, key[r] % m
    rank = np.empty(m, np.int64)
    for r in range(m):
        rank[order[r]] = r
    cap = 16 * m
    a = np.empty(cap, np.int64)
    b = np.empty(cap, np.int64)
    w = np.empty(cap)
    n = 0
    for i in range(m):
        # the squares in numpy's order: own (0), right (1), then the next row's left, middle, right (2, 3, 4) are
        # two runs of ascending squares in the sorted points: [own, own + 1] and [own + stride − 1, own + stride + 1]
        for run in range(2):
            first = cell[i] + (0 if run == 0 else stride - 1)
            last = first + (1 if run == 0 else 2)
            if run == 0:
                pos = rank[i]
                while pos > 0 and sorted_cell[pos - 1] == first:
                    pos -= 1
            else:
                lo, hi = 0, m
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if sorted_cell[mid] < first:
                        lo = mid + 1
                    else:
                        hi = mid
                pos = lo
            while pos < m and sorted_cell[pos] <= last:
                j = order[pos]
                own = sorted_cell[pos] == cell[i]
                pos += 1
                du, dv = uv[i, 0] - uv[j, 0], uv[i, 1] - uv[j, 1]
                dd2 = du * du + dv * dv
                if dd2 >= 1.0 or (own and i >= j):  # sqrt(x) < 1 needs x < 1
                    continue
                dd = math.sqrt(dd2)
                if dd < 1.0:
                    if n == cap:
                        cap *= 2
                        a, b, w = _grow_int(a, cap), _grow_int(b, cap), _grow(w, cap)
                    a[n], b[n], w[n] = i, j, 1.0 - dd
                    n += 1
    out_a = np.empty(2 * n, np.int64)
    out_b = np.empty(2 * n, np.int64)
    out_w = np.empty(2 * n)
    out_a[:n], out_a[n:] = a[:n], b[:n]
    out_b[:n], out_b[n:] = b[:n], a[:n]
    out_w[:n], out_w[n:] = w[:n], w[:n]
    return out_a, out_b, out_w


PEEK = 1e-3  # outline.PEEK
PEEK_MARGIN = 1e-9  # outline.PEEK_MARGIN


@kernel(inline="always")
def _enters(table, b, pu, pv, tu, tv):
    """``outline._enters``: the segment from (pu, pv) on polygon b's outline towards (tu, tv) starts into it."""
    du, dv = tu - pu, tv - pv
    length = math.sqrt(du * du + dv * dv)
    if not length > 0.0:
        return False
    step = PEEK / length
    return _inside(table, b, pu + du * step, pv + dv * step, PEEK_MARGIN)


@kernel
def through_bodies(table, uv, body, g, p, w, a, b, w2, nx):
    """``outline.through_bodies``: the coupling pairs less those whose segment crosses a cross-section (from an
    outline point, its first ``PEEK`` towards its partner lies inside the point's polygon)."""
    n = 0
    for q in range(len(g)):
        c = g[q]
        i = p[q]
        if not _enters(table, body[i], uv[i, 0], uv[i, 1], np.float64(c % nx), np.float64(c // nx)):
            g[n], p[n], w[n] = c, i, w[q]
            n += 1
    n2 = 0
    for q in range(len(a)):
        i, j = a[q], b[q]
        if not (_enters(table, body[i], uv[i, 0], uv[i, 1], uv[j, 0], uv[j, 1])
                or _enters(table, body[j], uv[j, 0], uv[j, 1], uv[i, 0], uv[i, 1])):
            a[n2], b[n2], w2[n2] = i, j, w2[q]
            n2 += 1
    return g[:n], p[:n], w[:n], a[:n2], b[:n2], w2[:n2]


@kernel
def cut_edges(uv, kind, mask, nx, nz):
    """``outline.cut_edges``: grid edges between two water vertices that an outline crosses (twice: a body
    thinner than h between them), (lower, upper) flat vertex indices, each once, ascending by 2·lower +
    direction."""
    m = len(uv)
    s = mask.ravel()
    key = np.empty(m, np.int64)
    n = 0
    for q in range(m):
        if kind[q] >= 2:
            continue
        along_v = kind[q] == 0
        i = np.int64(np.rint(uv[q, 0])) if along_v else np.int64(math.floor(uv[q, 0]))
        j = np.int64(math.floor(uv[q, 1])) if along_v else np.int64(np.rint(uv[q, 1]))
        if i < 0 or j < 0 or i + (0 if along_v else 1) >= nx or j + (1 if along_v else 0) >= nz:
            continue
        lo = j * nx + i
        hi = lo + (nx if along_v else 1)
        if s[lo] or s[hi]:
            continue
        key[n] = 2 * lo + (1 if along_v else 0)
        n += 1
    key = np.sort(key[:n])
    lo_out = np.empty(n, np.int64)
    hi_out = np.empty(n, np.int64)
    u = 0
    for q in range(n):
        if q > 0 and key[q] == key[q - 1]:
            continue
        lo_out[u] = key[q] // 2
        hi_out[u] = lo_out[u] + (nx if key[q] % 2 == 1 else 1)
        u += 1
    return lo_out[:u], hi_out[:u]


# ---------------------------------------------------------------------------------------------- propagation
@kernel
def wave_grid(z, zp, k, new):
    """Eq. 2.8 on the whole grid in one pass: new = (2 − n·k)·z − z(t − 1) + k·z_left + k·z_right + k·z_up +
    k·z_down, n = 4 inside, 3 on an edge, 2 at a corner (``waves.propagate``'s seven passes with its coefficient
    2 − k·``free_degree``: the same additions in the same order; neighbours beyond the border are absent:
    reflecting borders, eq. 2.9 / 2.10). ``new`` may be ``zp``."""
    nz, nx = z.shape
    for j in range(nz):
        up, down = j > 0, j < nz - 1
        _wave_vertex(z, zp, k, new, j, 0, up, down)
        inner = 2.0 - k * (2.0 + up + down)  # 2 − k·n with n = 2 + 0, 1 or 2 (the coefficient's bits)
        for i in range(1, nx - 1):
            s = inner * z[j, i] - zp[j, i]
            s += z[j, i - 1] * k
            s += z[j, i + 1] * k
            if up:
                s += z[j - 1, i] * k
            if down:
                s += z[j + 1, i] * k
            new[j, i] = s
        if nx > 1:
            _wave_vertex(z, zp, k, new, j, nx - 1, up, down)


@kernel(inline="always")
def _wave_vertex(z, zp, k, new, j, i, up, down):
    """Eq. 2.8 at one vertex of a border column (neighbours beyond the border absent)."""
    nx = z.shape[1]
    left, right = i > 0, i < nx - 1
    s = (2.0 - k * (0.0 + left + right + up + down)) * z[j, i] - zp[j, i]
    if left:
        s += z[j, i - 1] * k
    if right:
        s += z[j, i + 1] * k
    if up:
        s += z[j - 1, i] * k
    if down:
        s += z[j + 1, i] * k
    new[j, i] = s


@kernel
def wave_step(z, zp, k, degree, solid, mask, cut_lo, cut_hi, g, p, w, a, b, w2, points, points_prev, new, slots):
    """One step of eq. 2.8–2.12 (``waves.propagate``): the grid by :func:`wave_grid` into ``new`` (may be ``zp``),
    then the water vertices next to bodies (``solid``: they lose those neighbours, the wave reflects) or to added
    points (pairs ``g``, ``p``, ``w``) again with their own neighbours (eq. 2.11, k lowered to 2/D where the added
    neighbours raise the sum of weights D above 4), and the added points from the grid vertices and points within
    radius h (eq. 2.12; point pairs ``a``, ``b``, ``w2``); the ends ``cut_lo``, ``cut_hi`` of grid edges a thin
    body lies across lose each other. ``slots``: an int64 work array of at least the grid's size (its contents
    do not matter). Returns the added points' heights at t + 1."""
    nz, nx = z.shape
    zf, zpf, mf = z.ravel(), zp.ravel(), mask.ravel()
    # eq. 2.11: per touched vertex, its extra sums in order of entry (solid neighbours first, then point pairs)
    entries = 4 * len(solid) + 2 * len(cut_lo) + len(g)
    touched = np.empty(entries, np.int64)
    value = np.empty(entries)
    weight = np.empty(entries)
    e = 0
    for q in range(len(solid)):  # water neighbours (+u, −u, +v, −v) of the vertices inside bodies lose them
        c = solid[q]
        ci, cj = c % nx, c // nx
        held = -zf[c]
        for nb in range(4):
            if nb == 0:
                if ci + 1 >= nx:
                    continue
                t = c + 1
            elif nb == 1:
                if ci == 0:
                    continue
                t = c - 1
            elif nb == 2:
                if cj + 1 >= nz:
                    continue
                t = c + nx
            else:
                if cj == 0:
                    continue
                t = c - nx
            if mf[t]:
                continue
            touched[e], value[e], weight[e] = t, held, -1.0
            e += 1
    for q in range(len(cut_lo)):  # the two ends of an edge a thin body lies across lose each other
        touched[e], value[e], weight[e] = cut_lo[q], -zf[cut_hi[q]], -1.0
        touched[e + 1], value[e + 1], weight[e + 1] = cut_hi[q], -zf[cut_lo[q]], -1.0
        e += 2
    for q in range(len(g)):  # and the vertices near added points gain them (weight r_k / h)
        touched[e], value[e], weight[e] = g[q], w[q] * points[p[q]], w[q]
        e += 1
    for q in range(e):  # group by vertex through ``slots`` (only entries written here are read back)
        slots[touched[q]] = q
    vertex = np.empty(e, np.int64)
    group = np.empty(e, np.int64)
    u = 0
    for q in range(e):
        if slots[touched[q]] == q:
            vertex[u] = touched[q]
            group[q] = u
            u += 1
    s_extra = np.zeros(u)
    d_extra = np.zeros(u)
    for q in range(e):
        r = group[slots[touched[q]]]
        s_extra[r] += value[q]
        d_extra[r] += weight[q]
    special = np.empty(u)
    for q in range(u):
        c = vertex[q]
        ci, cj = c % nx, c // nx
        s = 0.0
        s += zf[c + 1] if ci + 1 < nx else 0.0
        s += zf[c - 1] if ci > 0 else 0.0
        s += zf[c + nx] if cj + 1 < nz else 0.0
        s += zf[c - nx] if cj > 0 else 0.0
        s = s + s_extra[q]
        d = degree.ravel()[c] + d_extra[q]
        zt = zf[c]
        if d <= 1e-12:
            special[q] = zt
        else:
            kt = min(k, 2.0 / d)
            special[q] = 2.0 * zt - zpf[c] + kt * (s - d * zt)
    m = len(points)  # eq. 2.12 at the added points, before the grid pass overwrites z(t − 1)
    grid_s = np.zeros(m)
    grid_d = np.zeros(m)
    for q in range(len(g)):
        grid_s[p[q]] += w[q] * zf[g[q]]
        grid_d[p[q]] += w[q]
    pair_s = np.zeros(m)
    pair_d = np.zeros(m)
    for q in range(len(a)):
        pair_s[a[q]] += w2[q] * points[b[q]]
        pair_d[a[q]] += w2[q]
    new_points = np.empty(m)
    for i in range(m):
        s = grid_s[i] + pair_s[i]
        d = grid_d[i] + pair_d[i]
        if d <= 0.0:
            new_points[i] = points[i]
        else:
            kn = min(k, 2.0 / d)
            new_points[i] = 2.0 * points[i] - points_prev[i] + kn * (s - d * points[i])
    wave_grid(z, zp, k, new)
    nf = new.ravel()
    for q in range(u):
        nf[vertex[q]] = special[q]
    return new_points


# ----------------------------------------------------------------------------------------------- carried
@kernel
def carried(known, known_heights, known_previous, keys, uv, z, zp):
    """``surface._carried``: N_z(t), N_z(t − 1) of the added points by key from the last step, or lifted onto the
    surface (eq. 2.2–2.4) for new points."""
    nz, nx = z.shape
    zf, zpf = z.ravel(), zp.ravel()
    m = len(keys)
    heights = np.empty(m)
    previous = np.empty(m)
    same = len(known) == m
    for i in range(m if same else 0):
        if known[i] != keys[i]:
            same = False
            break
    if same:  # the same points as last step
        heights[:] = known_heights
        previous[:] = known_previous
        return heights, previous
    order = np.argsort(known)
    sorted_keys = known[order]
    for i in range(m):
        at = np.searchsorted(sorted_keys, keys[i]) if len(known) else 0
        if len(known) and at < len(known) and sorted_keys[at] == keys[i]:
            heights[i] = known_heights[order[at]]
            previous[i] = known_previous[order[at]]
        else:
            heights[i] = _bilinear(zf, nx, nz, uv[i, 0], uv[i, 1])
            previous[i] = _bilinear(zpf, nx, nz, uv[i, 0], uv[i, 1])
    return heights, previous


# --------------------------------------------------------------------------------------------- finishing
@kernel
def finish(z, new, solid, owner, levels, unique, volume, damping, new_points, change, heights):
    """The end of an outline step (``surface._outline_step`` and ``step_water``): the added points' waves
    (eq. 2.6 / 2.7 as displacements), the vertices inside bodies held at S' (no velocity), the water's volume
    kept (both time levels shifted back to the mean at the start of the step) and the damping of section 2.3.2
    about the mean level. ``new_points`` is updated in place; returns the added points' heights at t (their
    history, shifted like the grid)."""
    for i in range(len(new_points)):
        new_points[i] += change[i]
    previous_points = np.empty(len(heights))
    for i in range(len(heights)):
        previous_points[i] = heights[i] + change[i]
    zf, nf = z.ravel(), new.ravel()
    for q in range(len(solid)):
        held = levels[owner[q]]
        nf[solid[q]] = held
        zf[solid[q]] = held
    mean = water_mean(new, unique)
    shift = volume - mean
    if shift != 0.0:
        for c in range(zf.size):
            zf[c] += shift
        for i in range(len(previous_points)):
            previous_points[i] = previous_points[i] + shift
    if damping < 1.0:
        offset = volume - damping * mean
        for c in range(nf.size):
            nf[c] = nf[c] * damping + offset
        for i in range(len(new_points)):
            new_points[i] = volume + damping * (new_points[i] - mean)
    elif shift != 0.0:
        for c in range(nf.size):
            nf[c] += shift
        for i in range(len(new_points)):
            new_points[i] = new_points[i] + shift
    return previous_points


@kernel
def previous_table(known, known_polygons, known_counts, known_table, cached, entities, width):
    """``surface._previous``: the edge table of each body's cross-section at t − 1 (padded or cut to ``width``)
    and whether it had one (3 or more vertices). The same bodies as last step: their table as it was
    (``known_table`` when ``cached``)."""
    nb = len(entities)
    same = len(known) == nb and known_polygons.shape[1] == width and len(known_counts) == nb
    for b in range(nb if same else 0):
        if known[b] != entities[b]:
            same = False
            break
    if same:
        old = np.empty(nb, np.bool_)
        for b in range(nb):
            old[b] = known_counts[b] >= 3
        return (known_table if cached else edge_table(known_polygons, known_counts)), old
    polygons = np.zeros((nb, width, 2))
    counts = np.zeros(nb, np.int64)
    old = np.zeros(nb, np.bool_)
    w = min(width, known_polygons.shape[1])
    for b in range(nb):
        for src in range(len(known)):
            if known[src] == entities[b]:
                polygons[b, :w] = known_polygons[src, :w]
                counts[b] = min(known_counts[src], w)
                old[b] = counts[b] >= 3
                break
    return edge_table(polygons, counts), old


# ------------------------------------------------------------------------------------------- the whole step
@kernel
def outline_step(z, zp, k, degree, new, rotated, shapes, position, radius, plane_y, levels, ring, edge_a, edge_b,
                 shared_face, x0, z0, h, entities, known_keys, known_heights, known_previous, known_entities,
                 known_polygons, known_counts, known_table, cached, alpha, volume, damping, slots):
    """One step of the outline method after the plane levels (``surface._outline_step``): cross-sections D'
    (``corners`` (B, 3, 8) of the boxes, spheres by ``ring``), nudged; added points; their carried heights; the
    waves they make (eq. 2.5–2.7, against D'(t − 1): :func:`previous_table`); the vertices inside
    bodies; the coupling pairs (less those across a body) and the grid edges across thin bodies; eq. 2.8–2.12
    into ``new``; volume and damping.

    Returns its results packed in three buffers (boxing an array for Python costs about a microsecond: one
    buffer per type instead of one array per result), the mask of the vertices inside bodies and the sizes:
    floats (uv (M, 2), change, new point heights, point heights at t (M each), polygons (B, W, 2), edge table of
    D'(t) (B, W, 9)), integers (keys, body (M each), segments (K, 2), solid (S), unique solid (U), counts (B),
    vertex and edge features (B, W each)), bytes (kind, raised, lowered (M each)); mask; M, K, S, U, W.
    """
    nz, nx = z.shape
    nb = len(shapes)
    n_box = 0
    for b in range(nb):
        n_box += 1 if shapes[b] == 0 else 0
    width = max(MAX_BOX_VERTICES if n_box > 0 else 0, len(ring) if n_box < nb else 0, 3)
    corners = np.empty_like(rotated)
    for b in range(nb):
        for i in range(3):
            for c in range(rotated.shape[2]):
                corners[b, i, c] = rotated[b, i, c] + position[b, i]
    polygons = np.zeros((nb, width, 2))
    counts = np.zeros(nb, np.int64)
    vfeat = np.zeros((nb, width), np.int64)
    efeat = np.zeros((nb, width), np.int64)
    boxes = np.empty(nb, np.int64)
    spheres = np.empty(nb, np.int64)
    n_box, n_sphere = 0, 0
    for b in range(nb):
        if shapes[b] == 0:
            boxes[n_box] = b
            n_box += 1
        else:
            spheres[n_sphere] = b
            n_sphere += 1
    if n_box:
        box_sections(corners, plane_y, edge_a, edge_b, shared_face, x0, z0, h, polygons, counts, vfeat, efeat,
                     boxes[:n_box])
    if n_sphere:
        sphere_sections(position, radius, plane_y, ring, x0, z0, h, polygons, counts, vfeat, efeat,
                        spheres[:n_sphere])
    nudge(polygons, counts)
    uv, kind, keys, body, segments = added_points(polygons, counts, vfeat, efeat, entities, nx, nz)
    heights, previous = carried(known_keys, known_heights, known_previous, keys, uv, z, zp)
    before, old = previous_table(known_entities, known_polygons, known_counts, known_table, cached, entities, width)
    after = edge_table(polygons, counts)
    change, raised, lowered = outline_impulse(uv, body, before, old, after, h, alpha, nb)
    solid, owner = solid_vertices(after, counts, nx, nz)
    mask, unique = solid_mask(solid, nz, nx)
    g, p, w = grid_pairs(uv, mask, nx, nz)
    a, b2, w2 = point_pairs(uv, nx, nz)
    g, p, w, a, b2, w2 = through_bodies(after, uv, body, g, p, w, a, b2, w2, nx)
    cut_lo, cut_hi = cut_edges(uv, kind, mask, nx, nz)
    new_points = wave_step(z, zp, k, degree, solid, mask, cut_lo, cut_hi, g, p, w, a, b2, w2, heights, previous,
                           new, slots)
    previous_points = finish(z, new, solid, owner, levels, unique, volume, damping, new_points, change, heights)
    m, n_seg, n_solid, n_unique, bw = len(uv), len(segments), len(solid), len(unique), nb * width
    floats = np.empty(5 * m + 11 * bw)
    floats[:2 * m] = uv.ravel()
    floats[2 * m:3 * m] = change
    floats[3 * m:4 * m] = new_points
    floats[4 * m:5 * m] = previous_points
    floats[5 * m:5 * m + 2 * bw] = polygons.ravel()
    floats[5 * m + 2 * bw:] = after.ravel()
    ints = np.empty(2 * m + 2 * n_seg + n_solid + n_unique + nb + 2 * bw, np.int64)
    at = 0
    for part in (keys, body, segments.ravel(), solid, unique, counts, vfeat.ravel(), efeat.ravel()):
        ints[at:at + len(part)] = part
        at += len(part)
    small = np.empty(3 * m, np.int8)
    small[:m] = kind
    for i in range(m):
        small[m + i] = 1 if raised[i] else 0
        small[2 * m + i] = 1 if lowered[i] else 0
    return floats, ints, small, mask, m, n_seg, n_solid, n_unique, width


# ------------------------------------------------------------------------------------------------ render extract
@kernel
def vertex_records(heights, h, x0, z0, y0, point_uv, point_heights):
    """``mesh.vertex_arrays`` packed for the GPU in one pass: float32 rows (x, y, z, nx, ny, nz), the grid vertices
    (row-major) then the added points; the same float64 arithmetic in the same order (``np.gradient``'s central
    differences inside and one-sided ones on the border, the bilinear slope at the added points, the normal
    divided by its length), rounded to float32 at the end, as ``np.concatenate(...).astype(np.float32)`` does."""
    nz, nx = heights.shape
    points = point_uv.shape[0]
    out = np.empty((nz * nx + points, 6), np.float32)
    for j in range(nz):
        for i in range(nx):
            if i == 0:
                dx = (heights[j, 1] - heights[j, 0]) / h
            elif i == nx - 1:
                dx = (heights[j, nx - 1] - heights[j, nx - 2]) / h
            else:
                dx = (heights[j, i + 1] - heights[j, i - 1]) / (2.0 * h)
            if j == 0:
                dz = (heights[1, i] - heights[0, i]) / h
            elif j == nz - 1:
                dz = (heights[nz - 1, i] - heights[nz - 2, i]) / h
            else:
                dz = (heights[j + 1, i] - heights[j - 1, i]) / (2.0 * h)
            row = out[j * nx + i]
            row[0] = x0 + i * h
            row[1] = y0 + heights[j, i]
            row[2] = z0 + j * h
            _unit_normal(row, -dx, -dz)
    for p in range(points):
        du, dv = _bilinear_slope(heights, point_uv[p, 0], point_uv[p, 1])
        row = out[nz * nx + p]
        row[0] = point_uv[p, 0] * h + x0
        row[1] = y0 + point_heights[p]
        row[2] = point_uv[p, 1] * h + z0
        _unit_normal(row, -du / h, -dv / h)
    return out


@kernel(inline="always")
def _unit_normal(row, a, c):
    """(a, 1, c) / |(a, 1, c)| into ``row[3:6]`` (the length summed x² + y² + z², as ``np.linalg.norm`` does)."""
    length = math.sqrt(a * a + 1.0 + c * c)
    row[3] = a / length
    row[4] = 1.0 / length
    row[5] = c / length
