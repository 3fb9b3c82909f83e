"""Compiled kernels (``engine.jit.kernel``) of the toon smoke's per-step loops.

:func:`splat_blobs_kernel`: the density blobs of §3.3 (figure 2, seeds/002), one ellipsoidal bump per particle.
In numpy (:func:`systems.toon_smoke.display.splat_blobs_numpy`) this is whole (particles × stencil) arrays, masks, a
gather and an unbuffered ``np.add.at`` per stencil size: on the demo's 32³ display grid with a few hundred
particles the calls, not the arithmetic, took the time (about 1.4 ms a volume a step).  Here it is one loop over
the particles and their stencil cells, with no temporaries.

The float32 operations are those of the numpy code, in its order (the stencil products summed left to right in
both, no BLAS matrix product, whose rounding would depend on the library and the CPU), and the blobs are added to a
zeroed buffer in the numpy code's order (stencil sizes ascending, particles, stencil cells) and the buffer to the
grid, so the two give the same bits (tested).
"""

from __future__ import annotations

import math

import numpy as np

from engine.collider import field_distance
from engine.jit import kernel, pairwise_sum


@kernel
def splat_blobs_kernel(target, centres, directions, along, across, amplitude):  # pragma: no cover
    """Add amplitude·(1 − q²)³ per particle to ``target`` (float32, in place), with
    q² = (d·û)²/a² + (|d|² − (d·û)²)/b² < 1 (figure 2, seeds/002; see ``display.splat_blobs``).

    ``centres`` (N, 3) are in the grid's index space (cell i's centre at i), ``directions`` (N, 3) unit stretch
    axes û, ``along``/``across`` (N,) the semi-axes a, b in cells.  Blobs centred more than one cell outside the grid are skipped; stencil cells outside it are
    dropped.  Returns the number of blobs added.
    """
    nx, ny, nz = target.shape
    n = centres.shape[0]
    box = np.zeros(target.shape, np.float32)
    reach = np.empty(n, np.int64)
    near = np.zeros(n, np.bool_)
    max_reach = 1
    count = 0
    for p in range(n):
        ok = True
        for k in range(3):
            c = centres[p, k]
            if not (c >= -1.0 and c <= target.shape[k]):
                ok = False
        near[p] = ok
        r = max(int(math.ceil(along[p])), 1)
        reach[p] = r
        if ok:
            count += 1
            max_reach = max(max_reach, r)
    amp = np.float32(amplitude)
    one = np.float32(1.0)
    for r in range(1, max_reach + 1):  # stencil sizes ascending, as numpy's np.unique(reach)
        limit = (r + 0.87) ** 2
        for p in range(n):
            if not near[p] or reach[p] != r:
                continue
            c0, c1, c2 = np.float32(centres[p, 0]), np.float32(centres[p, 1]), np.float32(centres[p, 2])
            b0, b1, b2 = np.float32(np.rint(c0)), np.float32(np.rint(c1)), np.float32(np.rint(c2))
            f0, f1, f2 = b0 - c0, b1 - c1, b2 - c2
            a0, a1, a2 = np.float32(directions[p, 0]), np.float32(directions[p, 1]), np.float32(directions[p, 2])
            fa = f0 * a0 + f1 * a1 + f2 * a2
            ff = f0 * f0 + f1 * f1 + f2 * f2
            g0, g1, g2 = f0 + f0, f1 + f1, f2 + f2
            inv_a2 = np.float32(1.0 / along[p] ** 2)
            inv_b2 = np.float32(1.0 / across[p] ** 2)
            shape_term = inv_a2 - inv_b2
            i0, j0, k0 = int(b0), int(b1), int(b2)
            for ox in range(-r, r + 1):
                for oy in range(-r, r + 1):
                    for oz in range(-r, r + 1):
                        if ox * ox + oy * oy + oz * oz > limit:
                            continue
                        x, y, z = np.float32(ox), np.float32(oy), np.float32(oz)
                        t = fa + (a0 * x + a1 * y + a2 * z)
                        d2 = ff + (g0 * x + g1 * y + g2 * z)
                        d2 += x * x + y * y + z * z
                        t *= t
                        t *= shape_term
                        d2 *= inv_b2
                        t += d2  # 1 - q
                        if not t < one:
                            continue
                        i, j, kk = i0 + ox, j0 + oy, k0 + oz
                        if i < 0 or i >= nx or j < 0 or j >= ny or kk < 0 or kk >= nz:
                            continue
                        q = one - t
                        box[i, j, kk] += amp * q * q * q
    for i in range(nx):
        for j in range(ny):
            for kk in range(nz):
                target[i, j, kk] += box[i, j, kk]
    return count


# --- Semi-Lagrangian advection (Stam 1999 §2.3; seeds/002 §3.1) -------------------------------------------------
#
# The numpy reference (:func:`systems.toon_smoke.fluid.advect_velocity_numpy` and ``advect_scalars_numpy``) builds
# the velocity at every sample, the back-traced points, the clamped coordinates, the eight corner indices and the
# eight gathered corner values as whole arrays: some forty calls and as many temporaries per step on a 32³ grid.
# The kernels below do the same float32 operations, in the same order, per sample in one pass, so the results have
# the same bits:
#   cell velocity    ½·(a + b) (the sum rounded, then halved),
#   onto a face      (c_lo + c_hi)·½, the border faces copying their cell,
#   back-trace       p = (x − (u·s)) − stagger,
#   clamp            c = min(max(p, 0), n − 1), i = min(int(c), n − 2), f = c − i,
#   trilinear blend  lerps along z, then y, then x: lo + (hi − lo)·f.


@kernel
def _cell_velocities(u, v, w):  # pragma: no cover
    """Velocity at cell centres, the mean of each cell's two faces per axis (``fluid.cell_velocity``)."""
    nx, ny, nz = u.shape[0] - 1, v.shape[1] - 1, w.shape[2] - 1
    cu = np.empty((nx, ny, nz), np.float32)
    cv = np.empty((nx, ny, nz), np.float32)
    cw = np.empty((nx, ny, nz), np.float32)
    half = np.float32(0.5)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                cu[i, j, k] = half * (u[i, j, k] + u[i + 1, j, k])
                cv[i, j, k] = half * (v[i, j, k] + v[i, j + 1, k])
                cw[i, j, k] = half * (w[i, j, k] + w[i, j, k + 1])
    return cu, cv, cw


@kernel(inline="always")
def _on_face(c, axis, i, j, k):  # pragma: no cover
    """A cell field at face (i, j, k) normal to ``axis``: mean of the two cells, the border faces copy their cell
    (``fluid._to_faces``)."""
    n = c.shape[axis]
    if axis == 0:
        if i == 0:
            return c[0, j, k]
        if i == n:
            return c[n - 1, j, k]
        return (c[i - 1, j, k] + c[i, j, k]) * np.float32(0.5)
    if axis == 1:
        if j == 0:
            return c[i, 0, k]
        if j == n:
            return c[i, n - 1, k]
        return (c[i, j - 1, k] + c[i, j, k]) * np.float32(0.5)
    if k == 0:
        return c[i, j, 0]
    if k == n:
        return c[i, j, n - 1]
    return (c[i, j, k - 1] + c[i, j, k]) * np.float32(0.5)


@kernel(inline="always")
def _clamp_axis(p, n):  # pragma: no cover
    """Clamped coordinate along one axis of n samples: (base index, fraction), as ``grid.trilinear_points``."""
    c = p
    if c <= np.float32(0.0):  # np.maximum(p, 0): −0 becomes +0, NaN stays NaN
        c = np.float32(0.0)
    top = np.float32(n - 1)
    if c > top:
        c = top
    i = int(c)
    if i > n - 2:
        i = n - 2
    return i, c - np.float32(i)


@kernel(inline="always")
def _trilinear(values, px, py, pz):  # pragma: no cover
    """Trilinear sample of ``values`` at index-space point (px, py, pz), clamped (``grid.Trilinear.gather``)."""
    nx, ny, nz = values.shape
    i, fx = _clamp_axis(px, nx)
    j, fy = _clamp_axis(py, ny)
    k, fz = _clamp_axis(pz, nz)
    return _blend(values, i, j, k, fx, fy, fz)


@kernel(inline="always")
def _blend(values, i, j, k, fx, fy, fz):  # pragma: no cover
    """Lerp the eight corners from (i, j, k) along z, then y, then x (``grid._blend_in_place``)."""
    v000, v001 = values[i, j, k], values[i, j, k + 1]
    v010, v011 = values[i, j + 1, k], values[i, j + 1, k + 1]
    v100, v101 = values[i + 1, j, k], values[i + 1, j, k + 1]
    v110, v111 = values[i + 1, j + 1, k], values[i + 1, j + 1, k + 1]
    c00 = (v001 - v000) * fz + v000
    c01 = (v011 - v010) * fz + v010
    c10 = (v101 - v100) * fz + v100
    c11 = (v111 - v110) * fz + v110
    c0 = (c01 - c00) * fy + c00
    c1 = (c11 - c10) * fy + c10
    return (c1 - c0) * fx + c0


@kernel
def _advect_component(values, axis, own, cu, cv, cw, s):  # pragma: no cover
    """One MAC component traced from its own faces: u_new(x) = u(x − s·u(x)) (Stam 1999 §2.3, ``s`` = Δt/h),
    the other two components at a face being the face average of their cell values."""
    n0, n1, n2 = values.shape
    out = np.empty_like(values)
    half = np.float32(0.5)
    zero = np.float32(0.0)
    sx = half if axis != 0 else zero  # the component's stagger, subtracted from the back-traced point
    sy = half if axis != 1 else zero
    sz = half if axis != 2 else zero
    for i in range(n0):
        bx = np.float32(i) if axis == 0 else np.float32(i + 0.5)
        for j in range(n1):
            by = np.float32(j) if axis == 1 else np.float32(j + 0.5)
            for k in range(n2):
                bz = np.float32(k) if axis == 2 else np.float32(k + 0.5)
                vx = own[i, j, k] if axis == 0 else _on_face(cu, axis, i, j, k)
                vy = own[i, j, k] if axis == 1 else _on_face(cv, axis, i, j, k)
                vz = own[i, j, k] if axis == 2 else _on_face(cw, axis, i, j, k)
                px = (bx - vx * s) - sx
                py = (by - vy * s) - sy
                pz = (bz - vz * s) - sz
                out[i, j, k] = _trilinear(values, px, py, pz)
    return out


@kernel
def advect_velocity_kernel(u, v, w, s):  # pragma: no cover
    """Semi-Lagrangian self-advection of a MAC velocity (Stam 1999 §2.3; seeds/002 §3.1), back-traces clamped to
    the box; ``s`` = Δt/h (float32).  Returns new (u, v, w) arrays."""
    cu, cv, cw = _cell_velocities(u, v, w)
    return (_advect_component(u, 0, u, cu, cv, cw, s), _advect_component(v, 1, v, cu, cv, cw, s),
            _advect_component(w, 2, w, cu, cv, cw, s))


@kernel
def advect_scalars_kernel(a, b, u, v, w, s):  # pragma: no cover
    """Semi-Lagrangian advection of two cell-centred scalars (density, temperature) by a MAC velocity (Stam 1999
    §2.3): each cell reads both fields at x − s·u(x), u being the cell-centre velocity.  Returns two new arrays."""
    cu, cv, cw = _cell_velocities(u, v, w)
    nx, ny, nz = a.shape
    out_a = np.empty_like(a)
    out_b = np.empty_like(b)
    half = np.float32(0.5)
    for i in range(nx):
        bx = np.float32(i + 0.5)
        for j in range(ny):
            by = np.float32(j + 0.5)
            for k in range(nz):
                bz = np.float32(k + 0.5)
                px = (bx - cu[i, j, k] * s) - half
                py = (by - cv[i, j, k] * s) - half
                pz = (bz - cw[i, j, k] * s) - half
                ci, fx = _clamp_axis(px, nx)  # one clamp for both fields (they share the grid)
                cj, fy = _clamp_axis(py, ny)
                ck, fz = _clamp_axis(pz, nz)
                out_a[i, j, k] = _blend(a, ci, cj, ck, fx, fy, fz)
                out_b[i, j, k] = _blend(b, ci, cj, ck, fx, fy, fz)
    return out_a, out_b


@kernel(inline="always")
def _mac_at(u, v, w, half, h, px, py, pz, out, row):  # pragma: no cover
    """Velocity at one local point (metres), each component trilinear on its staggered grid, into ``out[row]``:
    ``grid.MacSampler.sample`` at ``geo.to_cells(point)`` (float64 coordinates and fractions, float32 values)."""
    cx = (px + half[0]) / h
    cy = (py + half[1]) / h
    cz = (pz + half[2]) / h
    out[row, 0] = _trilinear(u, cx, cy - 0.5, cz - 0.5)
    out[row, 1] = _trilinear(v, cx - 0.5, cy, cz - 0.5)
    out[row, 2] = _trilinear(w, cx - 0.5, cy - 0.5, cz)


@kernel
def mac_velocity_kernel(points, u, v, w, half, h):  # pragma: no cover
    """Fluid velocity (N, 3) float64 at local points (N, 3), as ``grid.MacSampler.sample`` at
    ``geo.to_cells(points)``; ``half`` is half the box's extent, ``h`` the cell size."""
    out = np.empty((points.shape[0], 3))
    for n in range(points.shape[0]):
        _mac_at(u, v, w, half, h, points[n, 0], points[n, 1], points[n, 2], out, n)
    return out


@kernel
def advect_particles_kernel(p, u, v, w, half, h, half_dt, dt):  # pragma: no cover
    """The midpoint rule of ``simulate.advect_particles``: mid = p + (½Δt)·u(p), then p + Δt·u(mid).  Returns
    (new positions, the midpoint velocities), the same operations per particle as the numpy reference."""
    n = p.shape[0]
    first = np.empty((1, 3))
    velocity = np.empty((n, 3))
    moved = np.empty((n, 3))
    for r in range(n):
        _mac_at(u, v, w, half, h, p[r, 0], p[r, 1], p[r, 2], first, 0)
        _mac_at(u, v, w, half, h, p[r, 0] + half_dt * first[0, 0], p[r, 1] + half_dt * first[0, 1],
                p[r, 2] + half_dt * first[0, 2], velocity, r)
        for a in range(3):
            moved[r, a] = p[r, a] + dt * velocity[r, a]
    return moved, velocity


@kernel(inline="always")
def _central(f, i, j, k, axis, inv_h):  # pragma: no cover
    """∂f/∂axis at cell (i, j, k): central difference, one-sided at the walls (``fluid.vorticity_force``'s d)."""
    n = f.shape[axis]  # at least 2 (the configs allow 8 cells and up)
    c = i if axis == 0 else (j if axis == 1 else k)
    if c == 0:
        lo, hi = 0, 1
    elif c == n - 1:
        lo, hi = n - 2, n - 1
    else:
        lo, hi = c - 1, c + 1
    if axis == 0:
        diff = f[hi, j, k] - f[lo, j, k]
    elif axis == 1:
        diff = f[i, hi, k] - f[i, lo, k]
    else:
        diff = f[i, j, hi] - f[i, j, lo]
    if c != 0 and c != n - 1:
        diff = diff * np.float32(0.5)
    return diff * inv_h


@kernel
def body_forces_kernel(u, v, w, temperature, density, buoyancy, weight, up, use_up, confine, eps_h, inv_h,
                       dt):  # pragma: no cover
    """u += Δt·f on the faces (in place) with f = (β·T − α·ρ)·up + ε h (N × ω) at the cells (buoyancy and
    vorticity confinement, ``fluid.body_forces_numpy``), averaged onto the faces; float32 throughout, the numpy
    code's operations in its order.  ``use_up[a]``: whether up has a component along a; ``confine``: ε > 0."""
    nx, ny, nz = temperature.shape
    half = np.float32(0.5)
    fx = np.zeros((nx, ny, nz), np.float32)
    fy = np.zeros((nx, ny, nz), np.float32)
    fz = np.zeros((nx, ny, nz), np.float32)
    has = (use_up[0] or confine, use_up[1] or confine, use_up[2] or confine)
    if confine:
        uc = np.empty((nx, ny, nz), np.float32)
        vc = np.empty((nx, ny, nz), np.float32)
        wc = np.empty((nx, ny, nz), np.float32)
        for i in range(nx):
            for j in range(ny):
                for k in range(nz):
                    uc[i, j, k] = half * (u[i, j, k] + u[i + 1, j, k])
                    vc[i, j, k] = half * (v[i, j, k] + v[i, j + 1, k])
                    wc[i, j, k] = half * (w[i, j, k] + w[i, j, k + 1])
        ox = np.empty((nx, ny, nz), np.float32)
        oy = np.empty((nx, ny, nz), np.float32)
        oz = np.empty((nx, ny, nz), np.float32)
        mag = np.empty((nx, ny, nz), np.float32)
        for i in range(nx):
            for j in range(ny):
                for k in range(nz):
                    a = _central(wc, i, j, k, 1, inv_h) - _central(vc, i, j, k, 2, inv_h)
                    b = _central(uc, i, j, k, 2, inv_h) - _central(wc, i, j, k, 0, inv_h)
                    c = _central(vc, i, j, k, 0, inv_h) - _central(uc, i, j, k, 1, inv_h)
                    ox[i, j, k], oy[i, j, k], oz[i, j, k] = a, b, c
                    mag[i, j, k] = np.sqrt((a * a + b * b) + c * c)
        tiny = np.float32(1e-6)
        for i in range(nx):
            for j in range(ny):
                for k in range(nz):
                    gx = _central(mag, i, j, k, 0, inv_h)
                    gy = _central(mag, i, j, k, 1, inv_h)
                    gz = _central(mag, i, j, k, 2, inv_h)
                    scale = eps_h / (np.sqrt((gx * gx + gy * gy) + gz * gz) + tiny)
                    gx, gy, gz = gx * scale, gy * scale, gz * scale
                    a, b, c = ox[i, j, k], oy[i, j, k], oz[i, j, k]
                    fx[i, j, k] = gy * c - gz * b
                    fy[i, j, k] = gz * a - gx * c
                    fz[i, j, k] = gx * b - gy * a
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                lift = buoyancy * temperature[i, j, k] - weight * density[i, j, k]
                if use_up[0]:
                    fx[i, j, k] = lift * up[0] + fx[i, j, k] if confine else lift * up[0]
                if use_up[1]:
                    fy[i, j, k] = lift * up[1] + fy[i, j, k] if confine else lift * up[1]
                if use_up[2]:
                    fz[i, j, k] = lift * up[2] + fz[i, j, k] if confine else lift * up[2]
    if has[0]:
        _add_face_force(u, fx, 0, dt)
    if has[1]:
        _add_face_force(v, fy, 1, dt)
    if has[2]:
        _add_face_force(w, fz, 2, dt)


@kernel(inline="always")
def _add_face_force(comp, f, axis, dt):  # pragma: no cover
    """comp += Δt·(f on the faces normal to ``axis``): the mean of the two cells, a border face its cell
    (``fluid._to_faces``)."""
    n0, n1, n2 = comp.shape
    n = f.shape[axis]
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                c = i if axis == 0 else (j if axis == 1 else k)
                if c == 0:
                    face = f[i, j, k]
                elif c == n:
                    face = f[i - 1, j, k] if axis == 0 else (f[i, j - 1, k] if axis == 1 else f[i, j, k - 1])
                elif axis == 0:
                    face = (f[i - 1, j, k] + f[i, j, k]) * np.float32(0.5)
                elif axis == 1:
                    face = (f[i, j - 1, k] + f[i, j, k]) * np.float32(0.5)
                else:
                    face = (f[i, j, k - 1] + f[i, j, k]) * np.float32(0.5)
                comp[i, j, k] += dt * face


# --- Multigrid smoother and residual of the pressure solve (McAdams et al. 2010; seeds/002 §3.1) -----------------
#
# The numpy reference (:func:`systems.toon_smoke.poisson._half_sweep_numpy`, ``_residual_numpy``) works on the
# padded flat layout of a level (:class:`systems.toon_smoke.poisson.Level`): six shifted views summed, then a few
# whole-vector products, eight to fourteen calls per half sweep.  These kernels do the same float32 operations in
# the same order per cell, in two passes where the numpy code reads the old iterate everywhere (the neighbour sums
# first, then the blend), so the results have the same bits.


@kernel
def _neighbour_sums(x, sx, sy, coefficients, weighted, start, out):  # pragma: no cover
    """Σ_f A_f φ_nb(f) over the span into ``out``, taken −x, +x, −y, +y, −z, +z left to right (neighbours at
    ∓ sx, ∓ sy, ∓ 1); without ``weighted`` every A_f·φ_nb is φ_nb (``poisson._neighbour_sum``).  The neighbours
    are read through shifted views indexed by the loop counter: no negative-index wrap-around tests, so the loop
    vectorizes."""
    n = out.shape[0]
    xmx, xpx = x[start - sx:start - sx + n], x[start + sx:start + sx + n]
    xmy, xpy = x[start - sy:start - sy + n], x[start + sy:start + sy + n]
    xmz, xpz = x[start - 1:start - 1 + n], x[start + 1:start + 1 + n]
    if weighted:
        c0, c1, c2, c3, c4, c5 = (coefficients[0], coefficients[1], coefficients[2], coefficients[3],
                                  coefficients[4], coefficients[5])
        for t in range(n):
            nb = ((c0[t] * xmx[t] + c1[t] * xpx[t]) + c2[t] * xmy[t]) + c3[t] * xpy[t]
            out[t] = (nb + c4[t] * xmz[t]) + c5[t] * xpz[t]
    else:
        for t in range(n):
            out[t] = ((((xmx[t] + xpx[t]) + xmy[t]) + xpy[t]) + xmz[t]) + xpz[t]


@kernel
def half_sweep_kernel(x, b, keep, scale, sx, sy, coefficients, weighted, start, s):  # pragma: no cover
    """One colour of red–black Gauss–Seidel for M φ = b (the projection's 7-point Laplacian): over the span,
    φ ← keep·φ + scale·(b + Σ A φ_nb), with scale = 1/diag on the colour's active cells and 0 elsewhere, keep
    the complement.  ``x`` is the padded flat iterate (in place), ``start`` the span's first index, ``s`` scratch;
    all sums from the old iterate first, then the blend, as the numpy code."""
    n = s.shape[0]
    _neighbour_sums(x, sx, sy, coefficients, weighted, start, s)
    xs = x[start:start + n]
    for t in range(n):  # every sum is taken: the blend may now overwrite the iterate
        xs[t] = keep[t] * xs[t] + scale[t] * (b[t] + s[t])


@kernel
def pre_smooth_kernel(x, b, red_scale, black_scale, keep_red, keep_black, sx, sy, coefficients, weighted, start,
                      s, sweeps):  # pragma: no cover
    """A V-cycle's pre-smoothing on one level from φ = 0 (``poisson._v_cycle``), in one call: the first red half
    sweep (φ = red_scale·b, no neighbours to sum), then black, then ``sweeps`` − 1 more (red, black) pairs."""
    n = s.shape[0]
    xs = x[start:start + n]
    for t in range(n):
        xs[t] = red_scale[t] * b[t]
    half_sweep_kernel(x, b, keep_black, black_scale, sx, sy, coefficients, weighted, start, s)
    for _ in range(sweeps - 1):
        half_sweep_kernel(x, b, keep_red, red_scale, sx, sy, coefficients, weighted, start, s)
        half_sweep_kernel(x, b, keep_black, black_scale, sx, sy, coefficients, weighted, start, s)


@kernel
def post_smooth_kernel(x, b, red_scale, black_scale, keep_red, keep_black, sx, sy, coefficients, weighted, start,
                       s, sweeps, coarse_x, parent_index, inactive):  # pragma: no cover
    """A V-cycle's coarse correction and post-smoothing on one level (``poisson._v_cycle``), in one call: each
    cell adds its parent's coarse value (0 on inactive cells), then ``sweeps`` (black, red) pairs."""
    n = s.shape[0]
    xs = x[start:start + n]
    for t in range(n):
        xs[t] = np.float32(0.0) if inactive[t] else xs[t] + coarse_x[parent_index[t]]
    for _ in range(sweeps):
        half_sweep_kernel(x, b, keep_black, black_scale, sx, sy, coefficients, weighted, start, s)
        half_sweep_kernel(x, b, keep_red, red_scale, sx, sy, coefficients, weighted, start, s)


@kernel
def restrict_kernel(r, out):  # pragma: no cover
    """Coarse right-hand side ``out`` (nx/2, ny/2, nz/2) from the fine residual ``r`` (nx, ny, nz): the children
    summed in x pairs, then y pairs, then z pairs, times ½ (``poisson._restrict_numpy``, the same order)."""
    n0, n1, n2 = out.shape
    for i in range(n0):
        for j in range(n1):
            for k in range(n2):
                a0 = (r[2 * i, 2 * j, 2 * k] + r[2 * i + 1, 2 * j, 2 * k]) + (
                    r[2 * i, 2 * j + 1, 2 * k] + r[2 * i + 1, 2 * j + 1, 2 * k])
                a1 = (r[2 * i, 2 * j, 2 * k + 1] + r[2 * i + 1, 2 * j, 2 * k + 1]) + (
                    r[2 * i, 2 * j + 1, 2 * k + 1] + r[2 * i + 1, 2 * j + 1, 2 * k + 1])
                out[i, j, k] = (a0 + a1) * np.float32(0.5)


@kernel
def residual_kernel(x, b, diag, inactive, sx, sy, coefficients, weighted, start, r):  # pragma: no cover
    """r = b − M φ over the span, 0 on inactive cells, (M φ)_c = diag_c·φ_c − Σ A φ_nb (the poisson module)."""
    n = r.shape[0]
    _neighbour_sums(x, sx, sy, coefficients, weighted, start, r)
    xs = x[start:start + n]
    for t in range(n):
        v = b[t] - (diag[t] * xs[t] - r[t])
        r[t] = np.float32(0.0) if inactive[t] else v


# --- The whole MGPCG solve in one call (McAdams et al. 2010; seeds/002 §3.1) --------------------------------------
#
# The numpy reference (:func:`systems.toon_smoke.poisson.solve_numpy`) runs conjugate gradients as some thirty
# numpy and compiled calls per iteration (the operator, two dot products, max|r|, the V-cycle's kernels per level
# and its dense coarse solve, the zero-mean projection, the vector updates): on a 16³ grid the calls cost more
# than the arithmetic.  :func:`mgpcg_kernel` runs the same loop, from the initial residual to the report, with the
# same float32 operations in the same order (the smoothers, residual and restriction above, called per level) and
# numpy's float64 reductions written out: a contiguous ``sum`` is numpy's pairwise summation
# (:func:`engine.jit.pairwise_sum`), and a float32 array summed with ``dtype=np.float64`` is cast in buffers of
# ``np.getbufsize()`` elements, each buffer summed pairwise and added to a running total that starts at +0.


@kernel
def _dot(a, b, products):  # pragma: no cover
    """Σ a·b in float64 as ``np.multiply(a, b, dtype=np.float64).sum()``: exact products of the float32 values,
    summed pairwise onto +0 (``poisson._dot``)."""
    n = a.shape[0]
    for t in range(n):
        products[t] = np.float64(a[t]) * np.float64(b[t])
    return 0.0 + pairwise_sum(products, 0, n)


@kernel(inline="always")
def _max_abs(a):  # pragma: no cover
    """max |a| (float32) as ``np.abs(a).max()``; a NaN wins, as in numpy."""
    top = np.float32(0.0)
    for t in range(a.shape[0]):
        v = abs(a[t])
        if v > top or v != v:
            top = v
    return top


@kernel
def _sum_active(x, active, values, buffer_size):  # pragma: no cover
    """Σ x over the active cells in float64, and their count, as ``x[active].sum(dtype=np.float64)``: the active
    values gathered in order into ``values``, then, as numpy sums a float32 array into float64, cast a buffer of
    ``buffer_size`` at a time, each buffer summed pairwise and added to a total that starts at +0."""
    count = 0
    for c in range(x.shape[0]):
        if active[c]:
            values[count] = np.float64(x[c])
            count += 1
    total = 0.0
    for lo in range(0, count, buffer_size):
        total += pairwise_sum(values, lo, min(buffer_size, count - lo))
    return total, count


@kernel
def _remove_mean(x, active, values, buffer_size):  # pragma: no cover
    """x −= the mean over the active cells (``poisson._remove_mean``): the float64 sum (:func:`_sum_active`)
    divided by the count, rounded to float32, subtracted from each active value."""
    total, count = _sum_active(x, active, values, buffer_size)
    if count == 0:
        return
    mean = np.float32(total / count)
    for c in range(x.shape[0]):
        if active[c]:
            x[c] = x[c] - mean


@kernel
def _vectors(levels, d):  # pragma: no cover
    """Level ``d``'s padded flat x, b and r (views into the packed vectors, ``poisson._PackedLevels``) and its
    padded shape."""
    table, vectors = levels[0], levels[1]
    offset, shape = table[d, 0], (table[d, 1], table[d, 2], table[d, 3])
    end = offset + shape[0] * shape[1] * shape[2]
    return vectors[0, offset:end], vectors[1, offset:end], vectors[2, offset:end], shape


@kernel
def _span(levels, d):  # pragma: no cover
    """Level ``d``'s arrays over its span (views into the packed arrays): the scratch s, the diagonal, the red and
    black scales, keep_red, keep_black, the inactive flags, the parent indices and the neighbour coefficients
    (6, span; (6, 0) when the level is not weighted); then sx, sy (the span starts at sx) and whether it is
    weighted."""
    table, _, scratch, stencil, inactive, parents, coefficients = levels[:7]
    sx, sy = table[d, 2] * table[d, 3], table[d, 3]
    n = table[d, 1] * sx - 2 * sx
    lo, hi, weighted = table[d, 4], table[d, 4] + n, table[d, 6] != 0
    first = table[d, 5]
    c = coefficients[first:first + 6 * n if weighted else first].reshape((6, n if weighted else 0))
    return (scratch[lo:hi], stencil[0, lo:hi], stencil[1, lo:hi], stencil[2, lo:hi], stencil[3, lo:hi],
            stencil[4, lo:hi], inactive[lo:hi], parents[lo:hi], c, sx, sy, weighted)


@kernel(inline="always")
def _copy_real_cells(padded, compact, shape, padded_shape, into_padded):  # pragma: no cover
    """Copy between a compact field (C order over ``shape``) and the real cells of a padded flat vector: into the
    padded one when ``into_padded`` (its ghosts untouched), else out of it."""
    py, pz, nz = padded_shape[1], padded_shape[2], shape[2]
    for i in range(shape[0]):
        for j in range(shape[1]):
            row, c = ((i + 1) * py + (j + 1)) * pz + 1, (i * shape[1] + j) * nz
            inner, outer = padded[row:row + nz], compact[c:c + nz]
            if into_padded:
                for k in range(nz):  # views indexed by the loop counter: 3x faster than a slice assignment
                    inner[k] = outer[k]
            else:
                for k in range(nz):
                    outer[k] = inner[k]


@kernel
def _apply_operator(levels, phi, shape, out):  # pragma: no cover
    """M φ on the fine level (``poisson.apply_operator``): φ into the level's padded x, then over the span
    diag·φ − Σ A φ_nb (0 on the inactive cells of an unweighted level) into its r, whose real cells go to the
    compact ``out``."""
    x, _, r, padded_shape = _vectors(levels, 0)
    s, diag, _, _, _, _, inactive, _, coefficients, sx, sy, weighted = _span(levels, 0)
    _copy_real_cells(x, phi, shape, padded_shape, True)
    _neighbour_sums(x, sx, sy, coefficients, weighted, sx, s)
    n = s.shape[0]
    xs, rs = x[sx:sx + n], r[sx:sx + n]
    for t in range(n):
        v = diag[t] * xs[t] - s[t]
        rs[t] = np.float32(0.0) if (inactive[t] and not weighted) else v
    _copy_real_cells(r, out, shape, padded_shape, False)


@kernel
def _v_cycle(levels, rhs, shape, products, sweeps, out):  # pragma: no cover
    """One V-cycle from the compact ``rhs`` into the compact ``out`` (``poisson.v_cycle``): level by level down,
    pre-smoothing, the residual and its restriction; the dense solve on the coarsest (each row's products summed
    pairwise onto +0, as numpy's ``sum(axis=1)`` of a C-ordered matrix); level by level up, the prolongation and
    post-smoothing."""
    count, dense_inverse, dense_cells = levels[0].shape[0], levels[7], levels[8]
    _, b, _, padded_shape = _vectors(levels, 0)
    _copy_real_cells(b, rhs, shape, padded_shape, True)
    for d in range(count - 1):  # loop over the levels, down
        x, b, r, padded_shape = _vectors(levels, d)
        s, diag, red, black, keep_red, keep_black, inactive, _, coefficients, sx, sy, weighted = _span(levels, d)
        n = s.shape[0]
        pre_smooth_kernel(x, b[sx:sx + n], red, black, keep_red, keep_black, sx, sy, coefficients, weighted, sx, s,
                          sweeps)
        residual_kernel(x, b[sx:sx + n], diag, inactive, sx, sy, coefficients, weighted, sx, r[sx:sx + n])
        _, coarse_b, _, coarse_shape = _vectors(levels, d + 1)
        restrict_kernel(r.reshape(padded_shape)[1:-1, 1:-1, 1:-1], coarse_b.reshape(coarse_shape)[1:-1, 1:-1, 1:-1])
    x, b = _vectors(levels, count - 1)[:2]
    m = dense_cells.shape[0]
    coarse_b = np.empty(m)
    for j in range(m):
        coarse_b[j] = b[dense_cells[j]]
    for i in range(m):
        for j in range(m):
            products[j] = dense_inverse[i, j] * coarse_b[j]
        x[dense_cells[i]] = np.float32(0.0 + pairwise_sum(products, 0, m))
    for d in range(count - 2, -1, -1):  # loop over the levels, up
        x, b = _vectors(levels, d)[:2]
        s, _, red, black, keep_red, keep_black, inactive, parent, coefficients, sx, sy, weighted = _span(levels, d)
        n = s.shape[0]
        post_smooth_kernel(x, b[sx:sx + n], red, black, keep_red, keep_black, sx, sy, coefficients, weighted, sx, s,
                           sweeps, _vectors(levels, d + 1)[0], parent, inactive)
    x, _, _, padded_shape = _vectors(levels, 0)
    _copy_real_cells(x, out, shape, padded_shape, False)


@kernel
def mgpcg_kernel(b, x0, warm, active, singular, tolerance, max_iterations, buffer_size, table, vectors, scratch,
                 stencil, inactive, parents, coefficients, dense_inverse, dense_cells, sweeps):  # pragma: no cover
    """Multigrid-preconditioned conjugate gradients for M φ = b until max|r| ≤ tolerance · max|b|
    (``poisson.solve_numpy``: the same operations in the same order, so the same bits).

    ``b``, ``x0`` and ``active`` are the fine level's (nx, ny, nz) fields (``x0`` is read only when ``warm``);
    ``table`` … ``dense_cells`` the levels packed end to end (``poisson._PackedLevels``), whose x, b, r and scratch
    are overwritten; ``buffer_size`` numpy's (``np.getbufsize()``).  Returns (φ (nx, ny, nz) float32, iterations,
    max|r| at exit, max|b|).
    """
    levels = (table, vectors, scratch, stencil, inactive, parents, coefficients, dense_inverse, dense_cells)
    shape = b.shape
    n = shape[0] * shape[1] * shape[2]
    on = np.empty(n, np.bool_)
    rhs = np.empty(n, np.float32)
    x = np.zeros(n, np.float32)
    nz, zero = shape[2], np.float32(0.0)
    for i in range(shape[0]):
        for j in range(shape[1]):
            c = (i * shape[1] + j) * nz
            row_on, row_rhs, row_x, row_active, row_b, row_x0 = (on[c:c + nz], rhs[c:c + nz], x[c:c + nz],
                                                                 active[i, j], b[i, j], x0[i, j])
            for k in range(nz):
                row_on[k] = row_active[k]
                row_rhs[k] = np.float32(row_b[k]) if row_active[k] else zero
            if warm:
                for k in range(nz):
                    row_x[k] = np.float32(row_x0[k]) if row_active[k] else zero
    products = np.empty(max(n, dense_cells.shape[0]), np.float64)
    if singular:
        _remove_mean(rhs, on, products, buffer_size)
    b_max = np.float64(_max_abs(rhs))
    r = np.empty(n, np.float32)
    ap = np.empty(n, np.float32)
    z = np.empty(n, np.float32)
    _apply_operator(levels, x, shape, ap)
    for c in range(n):
        r[c] = rhs[c] - ap[c] if on[c] else np.float32(0.0)
    threshold = tolerance * b_max
    res = np.float64(_max_abs(r))
    iterations = 0
    if res <= threshold or b_max == 0.0:
        return x.reshape(shape), iterations, res, b_max
    _v_cycle(levels, r, shape, products, sweeps, z)
    if singular:
        _remove_mean(z, on, products, buffer_size)
    p = z.copy()
    rz = _dot(r, z, products)
    while iterations < max_iterations:
        iterations += 1
        _apply_operator(levels, p, shape, ap)
        p_ap = _dot(p, ap, products)
        if p_ap <= 0.0:
            break
        alpha = np.float32(rz / p_ap)
        for c in range(n):
            x[c] = x[c] + alpha * p[c]
            r[c] = r[c] - alpha * ap[c]
        res = np.float64(_max_abs(r))
        if res <= threshold:
            break
        _v_cycle(levels, r, shape, products, sweeps, z)
        if singular:
            _remove_mean(z, on, products, buffer_size)
        rz_new = _dot(r, z, products)
        beta = np.float32(rz_new / rz)
        for c in range(n):
            p[c] = p[c] * beta + z[c]
        rz = rz_new
    return x.reshape(shape), iterations, res, b_max


# --- The projection around the solve (Stam 1999 §2.5; seeds/002 §3.1) ---------------------------------------------
#
# The numpy reference (:func:`systems.toon_smoke.fluid.project_numpy`) takes the divergence, the target's
# difference, its largest value over the fluid and the right-hand side as whole-array expressions, then the
# pressure gradient face by face, and the divergence again: some forty calls and a dozen temporaries per step on a
# 16³ grid, more time than the solve's arithmetic.  The two kernels below do the same float32 operations per cell
# or face, in numpy's order (each difference, then the sums left to right, the division by h, the target's
# subtraction; the gradient's difference, its product with A_f, then the face's update), so the bits are the same.


@kernel(inline="always")
def _cell_divergence(u, v, w, i, j, k, h):  # pragma: no cover
    """(∇·u) of cell (i, j, k) as ``fluid.divergence``: ((u₊ − u₋) + (v₊ − v₋)) + (w₊ − w₋), over h."""
    flux = (u[i + 1, j, k] - u[i, j, k]) + (v[i, j + 1, k] - v[i, j, k])
    return (flux + (w[i, j, k + 1] - w[i, j, k])) / h


@kernel(inline="always")
def _max_abs_divergence(u, v, w, h, target, has_target, active, rhs, write_rhs):  # pragma: no cover
    """max |∇·u − target| over the active cells, 0 when there are none (``fluid._max_abs``: float32, a NaN wins);
    with ``write_rhs``, also ``rhs`` = −(∇·u − target)·h on every cell."""
    nx, ny, nz = active.shape
    top = np.float32(0.0)
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                d = _cell_divergence(u, v, w, i, j, k, h)
                if has_target:
                    d = d - target[i, j, k]
                if write_rhs:
                    rhs[i, j, k] = -d * h
                if active[i, j, k]:
                    a = abs(d)
                    if a > top or a != a:
                        top = a
    return top


@kernel
def divergence_rhs_kernel(u, v, w, h, target, has_target, active):  # pragma: no cover
    """Before the solve (``fluid.project_numpy``): b = −(∇·u − target)·h (float32, every cell) and
    max |∇·u − target| over the active cells.  ``h`` is float32; ``target`` is read only with ``has_target``."""
    rhs = np.empty(active.shape, np.float32)
    top = _max_abs_divergence(u, v, w, h, target, has_target, active, rhs, True)
    return rhs, top


@kernel
def pressure_update_kernel(u, v, w, phi, ax, ay, az, h, target, has_target, active):  # pragma: no cover
    """After the solve (``fluid.project_numpy``), in place: u_f −= A_f (φ_hi − φ_lo) on every interior face,
    −= A_f φ on the low border faces and += A_f φ on the high ones (the ghost holds φ = 0); then returns
    max |∇·u − target| over the active cells, from the updated faces."""
    nx, ny, nz = phi.shape
    for i in range(nx + 1):
        for j in range(ny):
            for k in range(nz):
                if i == 0:
                    u[i, j, k] -= ax[i, j, k] * phi[0, j, k]
                elif i == nx:
                    u[i, j, k] += ax[i, j, k] * phi[nx - 1, j, k]
                else:
                    u[i, j, k] -= ax[i, j, k] * (phi[i, j, k] - phi[i - 1, j, k])
    for i in range(nx):
        for j in range(ny + 1):
            for k in range(nz):
                if j == 0:
                    v[i, j, k] -= ay[i, j, k] * phi[i, 0, k]
                elif j == ny:
                    v[i, j, k] += ay[i, j, k] * phi[i, ny - 1, k]
                else:
                    v[i, j, k] -= ay[i, j, k] * (phi[i, j, k] - phi[i, j - 1, k])
    for i in range(nx):
        for j in range(ny):
            for k in range(nz + 1):
                if k == 0:
                    w[i, j, k] -= az[i, j, k] * phi[i, j, 0]
                elif k == nz:
                    w[i, j, k] += az[i, j, k] * phi[i, j, nz - 1]
                else:
                    w[i, j, k] -= az[i, j, k] * (phi[i, j, k] - phi[i, j, k - 1])
    return _max_abs_divergence(u, v, w, h, target, has_target, active, phi, False)


# --- After the advection: the scalars' fade and clamp, the particles' rebirth (seeds/002 §3.1, §3.3) --------------


@kernel
def fade_and_clamp_kernel(density, temperature, fade_density, density_factor, fade_temperature,
                          temperature_factor, fluid_weight, weighted, density_limit, temperature_limit
                          ):  # pragma: no cover
    """In place: ρ ·= its fade factor (with ``fade_density``), T ·= its own (with ``fade_temperature``), both ·= the
    fluid weight (1 in fluid cells, 0 in solids; with ``weighted``: the numpy code's product with a scalar 1 leaves
    every value as it is), then ``np.minimum`` with the limit (a NaN stays, an equal value gives the limit); float32,
    the order of ``simulate.fade_and_clamp_numpy``."""
    nx, ny, nz = density.shape
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                d = density[i, j, k]
                t = temperature[i, j, k]
                if fade_density:
                    d = d * density_factor
                if fade_temperature:
                    t = t * temperature_factor
                if weighted:
                    d = d * fluid_weight[i, j, k]
                    t = t * fluid_weight[i, j, k]
                density[i, j, k] = d if d < density_limit or d != d else density_limit
                temperature[i, j, k] = t if t < temperature_limit or t != t else temperature_limit


@kernel
def particle_rebirth_kernel(p, age, dt, half, solid, has_solid, h, factor, lifetime):  # pragma: no cover
    """Which particles are reborn (``simulate.advect_particles``'s numpy reference): age += Δt (in place), then a
    particle is reborn when it left the box (|p_a| > half_a on an axis), when the display cell it is in is solid
    (``has_solid``; cell ⌊(p + half)/h · factor⌋ clamped to the grid) or when its age reached ``lifetime`` (> 0).
    Returns (the flags, their count).  A NaN coordinate reads cell 0, as numpy's cast to an index does (x86)."""
    n = p.shape[0]
    reborn = np.zeros(n, np.bool_)
    count = 0
    for r in range(n):
        age[r] += dt
        out = abs(p[r, 0]) > half[0] or abs(p[r, 1]) > half[1] or abs(p[r, 2]) > half[2]
        if has_solid and not out:  # inside the box: a finite cell index, clamped only by a rounding
            i = _display_cell(p[r, 0], half[0], h, factor, solid.shape[0])
            j = _display_cell(p[r, 1], half[1], h, factor, solid.shape[1])
            k = _display_cell(p[r, 2], half[2], h, factor, solid.shape[2])
            out = solid[i, j, k]
        if lifetime > 0.0 and age[r] >= lifetime:
            out = True
        reborn[r] = out
        count += out
    return reborn, count


@kernel(inline="always")
def _display_cell(x, half, h, factor, n):  # pragma: no cover
    """The display cell along one axis holding local coordinate x (``simulate._nearest`` of ``geo.to_cells``)."""
    c = np.floor(((x + half) / h) * factor)
    if c != c:
        return 0
    return min(max(int(c), 0), n - 1)


# --- Solid cells under a height field (a new volume, or a collider moved) ----------------------------------------
#
# The numpy path (:func:`systems.toon_smoke.simulate._solid_mask_numpy`) turns every cell centre into world
# coordinates (``quat_rotate``, two cross products over all the points), then into the collider's frame (two more)
# and measures the height field's solid (``HeightField.solid_distance``: nothing beside the footprint, the gap to
# ``HeightField.height_at`` over it): on a puff's 32³ display grid about 7 ms per height field, and a puff near the
# ground in the demo overlaps two (the terrain and the water).  The kernel below does the same float64 operations
# per point, in the same order: ``engine.spatial.quat_rotate`` (v + 2·u × (u × v + w·v), the cross products' terms
# as ``engine.spatial.cross``), the collider's conjugate rotation, and the solid's distance
# (:func:`engine.collider.field_distance`: the footprint's walls, the bilinear sample clamped, lerped along x, then
# z).  A sign of zero may differ where numpy's clip returns its bound; the comparison d < 0 does not see it.


@kernel(inline="always")
def _rotate(qw, qx, qy, qz, vx, vy, vz):  # pragma: no cover
    """``engine.spatial.quat_rotate`` of one vector: v + 2.0·(u × (u × v + w·v)), u = (qx, qy, qz)."""
    tx = (qy * vz - qz * vy) + qw * vx
    ty = (qz * vx - qx * vz) + qw * vy
    tz = (qx * vy - qy * vx) + qw * vz
    return (vx + 2.0 * (qy * tz - qz * ty), vy + 2.0 * (qz * tx - qx * tz), vz + 2.0 * (qx * ty - qy * tx))


@kernel
def heightfield_solid_kernel(xs, ys, zs, position, rotation, field_position, field_rotation, heights, spacing,
                             origin, solid):  # pragma: no cover
    """solid[i, j, k] |= the cell centre (xs[i], ys[j], zs[k]) (local metres of a volume placed at ``position``,
    ``rotation``) lies inside a height field collider (``Collider.signed_distance`` < 0: below the surface over the
    footprint, ``HeightField.solid_distance``; nothing beside it).  Finite coordinates; ``solid`` in place."""
    qw, qx, qy, qz = rotation[0], rotation[1], rotation[2], rotation[3]
    cw, cx, cy, cz = field_rotation[0], -1.0 * field_rotation[1], -1.0 * field_rotation[2], -1.0 * field_rotation[3]
    for i in range(xs.shape[0]):
        for j in range(ys.shape[0]):
            for k in range(zs.shape[0]):
                rx, ry, rz = _rotate(qw, qx, qy, qz, xs[i], ys[j], zs[k])
                px, py, pz = _rotate(cw, cx, cy, cz, (position[0] + rx) - field_position[0],
                                     (position[1] + ry) - field_position[1], (position[2] + rz) - field_position[2])
                if field_distance(heights, origin[0], origin[1], spacing, px, py, pz) < 0.0:
                    solid[i, j, k] = True
