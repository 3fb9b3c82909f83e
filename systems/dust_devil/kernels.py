"""Compiled kernels (engine.jit) for the dust devil's particle step (seeds/004), bit for bit the numpy code's.

One call moves every particle through all substeps of a fixed step: wind lookup at the nearest grid point
(2.1) or trilinear, Euler or midpoint, the slope rule of eq. 1 (3.2), never below the terrain, then the age and
out-of-box test.  The numpy path (systems/dust_devil/simulate.py) makes ~60 array passes over the particles a
step; here each particle is loaded once and its grid points are evaluated on first use (the lazy grid of
:class:`~systems.dust_devil.tornado.WindField`).

Every operation is the numpy code's, in its order (``fastmath`` off: no reassociation, no fused multiply-add),
so the positions, hence the state hashes, are the same bits.  The trigonometric per-slice terms of the tornado
(the centre line, r and r2 of each height) are computed by numpy in float64 and passed in; the kernels use only
+ - * / and sqrt.  Written for the fast case the step takes them in: the field box and the terrain are not
rotated and the box has unit scale (dragging only translates); :func:`systems.dust_devil.simulate.step` keeps
the numpy path otherwise.
"""

from __future__ import annotations

import numpy as np

from engine.jit import kernel

SMALL = 1e-11  # Crawfis' SMALL (tornado.SMALL)


@kernel
def advance_particles(positions, ages, lifetimes, dead, flat, known, dims, grid_args, trilinear, midpoint,
                      substeps, h, dt, box_position, terrain, heights, ground_origin, spacing, ground_position):
    """One fixed step of every particle (simulate._advance after the clock and rotation), in place.

    Per substep of ``h``: v = the wind at p (2.1, the nearest grid point or trilinear), or at p + v h/2
    (``midpoint``); in world space (p + the box's position) with ``terrain``: when p + v h would be under the
    ground and the wind points into it (n·v < 0), v becomes r = v - ((n·v) / |n|²) n (eq. 1, 3.2); a next
    position still under the ground is lifted onto it.  Then the age grows by ``dt`` and ``dead`` marks
    particles out of the box or past their lifetime.  Returns the grid points evaluated now (``known`` and
    ``flat`` hold the step's lazy wind grid, tornado.WindField).

    One loop body with no helper functions: numba counts references of every array passed to a helper, which
    cost more than the arithmetic here; the repeated parts are loops instead (lookup stages, cell corners,
    height samples).
    """
    ux, cy_axis, uy, xc, yc, r, r2, size, wind_scale = grid_args
    nx, ny, nz = dims[0], dims[1], dims[2]
    nyz = ny * nz
    rows, cols = heights.shape
    x_lo, z_lo = ground_origin[0], ground_origin[1]
    x_hi, z_hi = x_lo + (cols - 1) * spacing, z_lo + (rows - 1) * spacing
    e = 0.5 * spacing
    half_h = 0.5 * h
    stages = 2 if midpoint else 1
    corners = 8 if trilinear else 1
    v = np.zeros(3)
    n = np.zeros(3)
    nxt = np.zeros(3)
    world = np.zeros(3)
    made = 0
    for i in range(positions.shape[0]):
        px, py, pz = positions[i, 0], positions[i, 1], positions[i, 2]
        for _ in range(substeps):
            for stage in range(stages):  # 0: the wind at p; 1 (midpoint): at p + v h/2
                qx, qy, qz = px, py, pz
                if stage == 1:
                    qx, qy, qz = px + half_h * v[0], py + half_h * v[1], pz + half_h * v[2]
                # to_unit, then lookup_nodes: clamped into the box, in grid units
                gx = min(max(qx / size[0] + 0.5, 0.0), 1.0) * (nx - 1)
                gy = min(max(qy / size[1], 0.0), 1.0) * (ny - 1)
                gz = min(max(qz / size[2] + 0.5, 0.0), 1.0) * (nz - 1)
                if trilinear:
                    i0, i1, i2 = min(int(np.floor(gx)), nx - 2), min(int(np.floor(gy)), ny - 2), \
                        min(int(np.floor(gz)), nz - 2)
                else:
                    i0, i1, i2 = int(np.rint(gx)), int(np.rint(gy)), int(np.rint(gz))
                base = i0 * nyz + i1 * nz + i2
                for corner in range(corners):  # evaluate the grid points read that are not known yet
                    node = base + (corner >> 2) * nyz + ((corner >> 1) & 1) * nz + (corner & 1)
                    if known[node]:
                        continue
                    # gen_tornado (2.1), as tornado._swirl and tornado._field_velocity, in their order
                    ix = node // nyz
                    iy = (node - ix * nyz) // nz
                    iz = node - ix * nyz - iy * nz
                    cz = uy[iy]
                    dx = ux[ix] - xc[iy]
                    dy = cy_axis[iz] - yc[iy]
                    d = np.sqrt(dx * dx + dy * dy)
                    s = abs(r[iy] - d)
                    s = 0.8 - s if s > r2[iy] else 1.0
                    z0 = 0.1 * (0.1 - d * cz)
                    if z0 < 0.0:  # np.maximum(z0, 0.0)
                        z0 = 0.0
                    d = np.sqrt(d * d + z0 * z0)
                    s *= (r[iy] + r2[iy]) - d
                    s /= d + SMALL
                    s /= 1.0 + cz
                    flat[node, 0] = (s * dy + 0.1 * dx) * size[0] * wind_scale
                    flat[node, 1] = (s * z0) * size[1] * wind_scale
                    flat[node, 2] = ((-s) * dx + 0.1 * dy) * (-size[2]) * wind_scale
                    known[node] = True
                    made += 1
                if not trilinear:
                    v[0], v[1], v[2] = flat[base, 0], flat[base, 1], flat[base, 2]
                else:  # gather_wind: along x, then y, then z
                    fx, fy, fz = gx - i0, gy - i1, gz - i2
                    for k in range(3):
                        a = flat[base, k]
                        c00 = a + (flat[base + nyz, k] - a) * fx
                        a = flat[base + nz, k]
                        c10 = a + (flat[base + nz + nyz, k] - a) * fx
                        a = flat[base + 1, k]
                        c01 = a + (flat[base + 1 + nyz, k] - a) * fx
                        a = flat[base + nz + 1, k]
                        c11 = a + (flat[base + nz + 1 + nyz, k] - a) * fx
                        c0 = c00 + (c10 - c00) * fy
                        c1 = c01 + (c11 - c01) * fy
                        v[k] = c0 + (c1 - c0) * fz
            world[0], world[1], world[2] = px + box_position[0], py + box_position[1], pz + box_position[2]
            for k in range(3):
                nxt[k] = world[k] + v[k] * h
            if terrain:
                for attempt in range(2):  # the step, then (eq. 1 applied) the projected step
                    # depth below the ground of nxt: HeightField.height_at (bilinear, clamped) minus local y
                    ground = _ground_height(nxt[0] - ground_position[0], nxt[2] - ground_position[2], heights,
                                            x_lo, z_lo, spacing)
                    depth = ground - (nxt[1] - ground_position[1])
                    if attempt == 1 or depth <= 0.0:
                        break
                    # HeightField.normal_at under the current point: central differences over ±spacing/2
                    x = min(max(world[0] - ground_position[0], x_lo), x_hi)
                    z = min(max(world[2] - ground_position[2], z_lo), z_hi)
                    xa, xb = max(x - e, x_lo), min(x + e, x_hi)
                    za, zb = max(z - e, z_lo), min(z + e, z_hi)
                    east = _ground_height(xb, z, heights, x_lo, z_lo, spacing)
                    west = _ground_height(xa, z, heights, x_lo, z_lo, spacing)
                    north = _ground_height(x, zb, heights, x_lo, z_lo, spacing)
                    south = _ground_height(x, za, heights, x_lo, z_lo, spacing)
                    dnx = -((east - west) / (xb - xa))
                    dnz = -((north - south) / (zb - za))
                    length = np.sqrt(dnx * dnx + 1.0 + dnz * dnz)
                    n[0], n[1], n[2] = dnx / length, 1.0 / length, dnz / length
                    nv = n[0] * v[0] + n[1] * v[1] + n[2] * v[2]
                    if nv >= 0.0:  # wind leaving the ground is kept
                        break
                    k_n = nv / (n[0] * n[0] + n[1] * n[1] + n[2] * n[2])  # eq. 1
                    for k in range(3):
                        v[k] = v[k] - k_n * n[k]
                        nxt[k] = world[k] + v[k] * h
                if depth > 0.0:  # never below the terrain: lifted along up = +y (the ground is not rotated)
                    nxt[0] += depth * 0.0
                    nxt[1] += depth * 1.0
                    nxt[2] += depth * 0.0
            px, py, pz = nxt[0] - box_position[0], nxt[1] - box_position[1], nxt[2] - box_position[2]
        positions[i, 0], positions[i, 1], positions[i, 2] = px, py, pz
        ages[i] += dt
        ux_, uy_, uz_ = px / size[0] + 0.5, py / size[1], pz / size[2] + 0.5
        dead[i] = (ux_ < 0.0 or ux_ > 1.0 or uy_ < 0.0 or uy_ > 1.0 or uz_ < 0.0 or uz_ > 1.0
                   or ages[i] >= lifetimes[i])
    return made


@kernel(inline="always")
def _ground_height(x, z, heights, x_lo, z_lo, spacing):
    """HeightField.height_at at one point (bilinear, clamped to the grid), in its order of operations."""
    rows, cols = heights.shape
    gx = min(max((x - x_lo) / spacing, 0.0), cols - 1)
    gz = min(max((z - z_lo) / spacing, 0.0), rows - 1)
    c0, r0 = min(int(gx), cols - 2), min(int(gz), rows - 2)
    tx, tz = gx - c0, gz - r0
    top = heights[r0, c0] + tx * (heights[r0, c0 + 1] - heights[r0, c0])
    bottom = heights[r0 + 1, c0] + tx * (heights[r0 + 1, c0 + 1] - heights[r0 + 1, c0])
    return top + tz * (bottom - top)


@kernel
def emit_particles(draws, cos_angle, sin_angle, centre, emission_radius, half_x, half_z, box_position, terrain,
                   heights, ground_origin, spacing, ground_position, finish, feet, positions, ages, lifetimes,
                   which, emission_height, size_y, lifetime, jitter):
    """One pass of simulate.emit's placement for the emitted particles i (row i of ``draws``, the numpy
    stream's uniform draws; ``cos_angle``/``sin_angle`` of 2π draws[:, 1] come from numpy too, float64).

    A point uniform in the disc of ``emission_radius`` (radius R sqrt(u0), angle 2π u1) around the vortex centre
    line's field-space (x, z) ``centre`` (one row for all, or one per particle), clamped into the box, on the box
    floor; in world space (+ the box's position) lifted onto the ground with ``terrain``.  ``finish`` False:
    ``feet[i]`` = its field-space height (where simulate.emit looks the centre line up again).  ``finish``
    True: then up by ``emission_height`` u2, capped at the box top, into ``positions[which[i]]`` with age 0 and
    lifetime L (1 - jitter u3).  The numpy code's operations in its order (the ground and the box are not
    rotated and the box has unit scale: up is +y, field space = world - box position)."""
    x_lo, z_lo = ground_origin[0], ground_origin[1]
    shared = centre.shape[0] == 1
    for i in range(draws.shape[0]):
        c = 0 if shared else i
        radius = emission_radius * np.sqrt(draws[i, 0])
        lx = min(max(centre[c, 0] + radius * cos_angle[i], -half_x), half_x)
        lz = min(max(centre[c, 1] + radius * sin_angle[i], -half_z), half_z)
        wx, wy, wz = lx + box_position[0], 0.0 + box_position[1], lz + box_position[2]
        if terrain:  # Ground.lift: points below the surface move up onto it
            depth = _ground_height(wx - ground_position[0], wz - ground_position[2], heights, x_lo, z_lo,
                                   spacing) - (wy - ground_position[1])
            if depth > 0.0:
                wx += depth * 0.0
                wy += depth * 1.0
                wz += depth * 0.0
        if not finish:
            feet[i] = wy - box_position[1]
            continue
        rise = emission_height * draws[i, 2]
        wx += rise * 0.0
        wy += rise * 1.0
        wz += rise * 0.0
        k = which[i]
        positions[k, 0] = wx - box_position[0]
        positions[k, 1] = min(wy - box_position[1], size_y)
        positions[k, 2] = wz - box_position[2]
        ages[k] = 0.0
        lifetimes[k] = lifetime * (1.0 - jitter * draws[i, 3])
