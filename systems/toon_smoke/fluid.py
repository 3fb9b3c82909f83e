"""Stable fluids in 3D on a MAC grid (Stam, "Stable Fluids", SIGGRAPH 1999; seeds/002 §3.1), vectorized numpy.

One step of the incompressible Navier–Stokes equations

    ∂u/∂t = −(u·∇)u − ∇p/ρ + ν∇²u + f,   ∇·u = 0

is split as in Stam, in the paper's order: external forces (buoyancy, vorticity confinement, sources),
self-advection (semi-Lagrangian, clamped back-traces), implicit viscous diffusion, and the pressure projection
(:mod:`.poisson`).  Density ρ and
temperature T are then advected by the projected velocity, diffused and dissipated.  Velocities are in m/s, the
grid spacing h in metres; everything the state keeps is float32.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from systems.toon_smoke import poisson
from systems.toon_smoke.grid import F32, Geometry, trilinear_points

__all__ = [
    "advect_scalars",
    "advect_scalars_numpy",
    "advect_velocity",
    "advect_velocity_numpy",
    "body_forces",
    "body_forces_numpy",
    "cell_velocity",
    "diffuse",
    "divergence",
    "enforce_solid_faces",
    "project",
    "project_numpy",
    "vorticity_force",
]


def cell_velocity(u: F32, v: F32, w: F32) -> tuple[F32, F32, F32]:
    """Velocity at cell centres: the mean of the two faces of each cell along each axis."""
    return 0.5 * (u[:-1] + u[1:]), 0.5 * (v[:, :-1] + v[:, 1:]), 0.5 * (w[:, :, :-1] + w[:, :, 1:])


def _to_faces(c: F32, axis: int, out: F32 | None = None) -> F32:
    """Cell values onto the faces normal to ``axis`` (mean of the two cells; the border faces copy their cell)."""
    if out is None:
        shape = list(c.shape)
        shape[axis] += 1
        out = np.empty(shape, c.dtype)
    inner = [slice(None)] * 3
    inner[axis] = slice(1, -1)
    lo, hi = [slice(None)] * 3, [slice(None)] * 3
    lo[axis], hi[axis] = slice(0, -1), slice(1, None)
    inside = out[tuple(inner)]
    np.add(c[tuple(lo)], c[tuple(hi)], out=inside)
    inside *= np.float32(0.5)
    first, last = [slice(None)] * 3, [slice(None)] * 3
    first[axis], last[axis] = 0, -1
    out[tuple(first)] = c[tuple(first)]
    out[tuple(last)] = c[tuple(last)]
    return out


def divergence(u: F32, v: F32, w: F32, h: float) -> F32:
    """∇·u per cell: net outward flux through the six faces over h (1/s)."""
    flux = (u[1:] - u[:-1]) + (v[:, 1:] - v[:, :-1]) + (w[:, :, 1:] - w[:, :, :-1])
    return flux / np.float32(h)


def advect_velocity(geo: Geometry, u: F32, v: F32, w: F32, dt: float) -> tuple[F32, F32, F32]:
    """Semi-Lagrangian self-advection (Stam 1999 §2.3): u_new(x) = u(x − Δt·u(x)), back-traces clamped to the box,
    as one compiled pass per component (:func:`systems.toon_smoke.kernels.advect_velocity_kernel`); the same bits
    as :func:`advect_velocity_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import advect_velocity_kernel

    return advect_velocity_kernel(_f32c(u), _f32c(v), _f32c(w), np.float32(dt / geo.h))


def _f32c(a: F32) -> F32:
    return np.ascontiguousarray(a, np.float32)


def advect_velocity_numpy(geo: Geometry, u: F32, v: F32, w: F32, dt: float) -> tuple[F32, F32, F32]:
    """Semi-Lagrangian self-advection (Stam 1999 §2.3): u_new(x) = u(x − Δt·u(x)), back-traces clamped to the box.

    Each component is traced from its own faces; the two other components at a face are the 4-face averages.
    """
    cells = cell_velocity(u, v, w)
    s = np.float32(dt / geo.h)  # metres per second → cells per step
    out = []
    for axis, (name, values) in enumerate((("u", u), ("v", v), ("w", w))):
        velocity = np.empty((3,) + values.shape, np.float32)  # the velocity at this component's faces
        for other in range(3):
            if other == axis:
                velocity[other] = values
            else:
                _to_faces(cells[other], axis, out=velocity[other])
        points = _clamped_back_trace(geo.backtrace_bases[name], velocity, s)
        points -= _STAGGER[name]
        out.append(trilinear_points(values.shape, points).gather(values))
    return out[0], out[1], out[2]


_STAGGER = {name: np.array(offset, np.float32).reshape(3, 1, 1, 1) for name, offset in
            (("u", (0.0, 0.5, 0.5)), ("v", (0.5, 0.0, 0.5)), ("w", (0.5, 0.5, 0.0)), ("c", (0.5, 0.5, 0.5)))}


def _clamped_back_trace(base: F32, velocity: F32, s: np.float32) -> F32:
    """x − s·u at every sample (3, …) of one grid (in place on ``velocity``).

    The box clamp [0, n] of Stam's back-trace is left to the interpolation, which clamps the sample point to the
    grid's first and last samples: clamp(clamp(x, 0, n) − ½, 0, n − 1) = clamp(x − ½, 0, n − 1) bit for bit (inside
    [0, n] the inner clamp does nothing; below 0 and above n both sides end at 0 and n − 1), and
    clamp(clamp(x, 0, n), 0, n) = clamp(x, 0, n) along a component's own axis.
    """
    velocity *= s
    return np.subtract(base, velocity, out=velocity)


def advect_scalars(geo: Geometry, fields: list[F32], u: F32, v: F32, w: F32, dt: float) -> list[F32]:
    """Semi-Lagrangian advection of cell-centred scalars by the MAC velocity (Stam 1999 §2.3), two fields per
    compiled pass (:func:`systems.toon_smoke.kernels.advect_scalars_kernel`); the same bits as
    :func:`advect_scalars_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import advect_scalars_kernel

    s = np.float32(dt / geo.h)
    u, v, w = _f32c(u), _f32c(v), _f32c(w)
    out: list[F32] = []
    for first in range(0, len(fields), 2):  # loop over the fields, two at a time
        pair = fields[first:first + 2]
        a = _f32c(pair[0])
        b = _f32c(pair[1]) if len(pair) == 2 else a
        out.extend(advect_scalars_kernel(a, b, u, v, w, s)[:len(pair)])
    return out


def advect_scalars_numpy(geo: Geometry, fields: list[F32], u: F32, v: F32, w: F32, dt: float) -> list[F32]:
    """Semi-Lagrangian advection of cell-centred scalars (density, temperature) by the MAC velocity.

    Trilinear interpolation is a convex combination, so the result stays within the old field's range (density
    stays non-negative and bounded).
    """
    points = _clamped_back_trace(geo.backtrace_bases["c"], np.stack(cell_velocity(u, v, w)), np.float32(dt / geo.h))
    points -= _STAGGER["c"]
    return trilinear_points(geo.shape, points).gather_many(fields)


@dataclass
class _Colouring:
    red: NDArray[np.bool_]
    black: NDArray[np.bool_]
    neighbours: F32  # number of in-box neighbours per cell


_COLOURINGS: dict[tuple[int, ...], _Colouring] = {}


def _colouring(shape: tuple[int, ...]) -> _Colouring:
    if shape not in _COLOURINGS:
        i, j, k = np.indices(shape, sparse=True)
        parity = ((i + j + k) & 1).astype(bool)
        count = np.zeros(shape, np.float32)
        for axis in range(3):
            lo, hi = [slice(None)] * 3, [slice(None)] * 3
            lo[axis], hi[axis] = slice(0, -1), slice(1, None)
            count[tuple(lo)] += 1.0
            count[tuple(hi)] += 1.0
        _COLOURINGS[shape] = _Colouring(~parity, parity, count)
    return _COLOURINGS[shape]


def _neighbour_sum(x: F32) -> F32:
    s = np.zeros_like(x)
    s[1:] += x[:-1]
    s[:-1] += x[1:]
    s[:, 1:] += x[:, :-1]
    s[:, :-1] += x[:, 1:]
    s[:, :, 1:] += x[:, :, :-1]
    s[:, :, :-1] += x[:, :, 1:]
    return s


def diffuse(x0: F32, rate: float, dt: float, h: float, iterations: int) -> F32:
    """Implicit diffusion (Stam 1999 §2.4): solve (I − κΔt∇²) x = x0 with red–black Gauss–Seidel sweeps.

    With a = κΔt/h², each cell satisfies (1 + a·n) x − a Σ x_nb = x0 (n in-box neighbours: zero flux at walls).
    Red–black ordering makes each half sweep a whole-array update that is still true Gauss–Seidel.
    """
    if rate <= 0.0:
        return x0
    a = np.float32(rate * dt / (h * h))
    colours = _colouring(x0.shape)
    inv = (1.0 / (1.0 + a * colours.neighbours)).astype(np.float32)
    x = x0.copy()
    for _ in range(iterations):
        for mask in (colours.red, colours.black):
            np.copyto(x, (x0 + a * _neighbour_sum(x)) * inv, where=mask)
    return x


def vorticity_force(u: F32, v: F32, w: F32, h: float, epsilon: float) -> tuple[F32, F32, F32]:
    """Vorticity confinement (Fedkiw, Stam & Jensen 2001, eq. 9–11): f = ε h (N × ω), N = ∇|ω| / |∇|ω||.

    Returns the force per unit mass (m/s²) at cell centres.
    """
    uc, vc, wc = cell_velocity(u, v, w)
    inv_h = np.float32(1.0 / h)

    def d(f: F32, axis: int) -> F32:
        """Central difference ∂f/∂axis (one-sided at the walls): ``np.gradient(f, axis=axis) / h``, written out
        (np.gradient's checks cost more than its arithmetic on these grids); halving is exact, so same bits."""
        out = np.empty_like(f)
        lo, mid, hi = [slice(None)] * 3, [slice(None)] * 3, [slice(None)] * 3
        lo[axis], mid[axis], hi[axis] = slice(None, -2), slice(1, -1), slice(2, None)
        np.subtract(f[tuple(hi)], f[tuple(lo)], out=out[tuple(mid)])
        out[tuple(mid)] *= np.float32(0.5)
        for edge, inner in ((0, 1), (-1, -2)):  # the two walls: one-sided differences
            lo[axis], hi[axis] = (edge, inner) if edge == 0 else (inner, edge)
            np.subtract(f[tuple(hi)], f[tuple(lo)], out=out[tuple(lo if edge == 0 else hi)])
        out *= inv_h
        return out

    # The same operations in the same order as the plain expressions (noted), in place on a few buffers.
    wx = d(wc, 1)
    wx -= d(vc, 2)  # ω = ∇ × u
    wy = d(uc, 2)
    wy -= d(wc, 0)
    wz = d(vc, 0)
    wz -= d(uc, 1)
    scratch = np.empty_like(wx)
    mag = _length(wx, wy, wz, scratch)  # |ω| = sqrt(wx·wx + wy·wy + wz·wz)
    nx, ny, nz = d(mag, 0), d(mag, 1), d(mag, 2)
    norm = _length(nx, ny, nz, mag)  # |∇|ω|| (mag is not needed any more)
    norm += np.float32(1e-6)
    scale = np.divide(np.float32(epsilon * h), norm, out=norm)  # N = ∇|ω| / |∇|ω||, times ε h
    nx *= scale
    ny *= scale
    nz *= scale
    fx = np.multiply(ny, wz)  # N × ω = (ny wz − nz wy, nz wx − nx wz, nx wy − ny wx)
    fx -= np.multiply(nz, wy, out=scratch)
    fy = np.multiply(nz, wx)
    fy -= np.multiply(nx, wz, out=scratch)
    fz = np.multiply(nx, wy)
    fz -= np.multiply(ny, wx, out=scratch)
    return fx, fy, fz


def _length(x: F32, y: F32, z: F32, out: F32) -> F32:
    """sqrt(x·x + y·y + z·z) per cell into ``out`` (summed left to right, as the plain expression)."""
    np.multiply(x, x, out=out)
    out += y * y
    out += z * z
    return np.sqrt(out, out=out)


def body_forces(u: F32, v: F32, w: F32, temperature: F32, density: F32, buoyancy: float, weight: float,
                up: NDArray[np.float64], confinement: float, h: float, dt: float) -> None:
    """Buoyancy (β·T − α·ρ along ``up``) and vorticity confinement (ε), added to the face velocities over Δt, in
    place; one compiled pass (:func:`systems.toon_smoke.kernels.body_forces_kernel`), the same bits as
    :func:`body_forces_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import body_forces_kernel

    up = np.asarray(up, np.float64)
    body_forces_kernel(u, v, w, _f32c(temperature), _f32c(density), np.float32(buoyancy), np.float32(weight),
                       up.astype(np.float32), np.abs(up) > 1e-12, confinement > 0.0, np.float32(confinement * h),
                       np.float32(1.0 / h), np.float32(dt))


def body_forces_numpy(u: F32, v: F32, w: F32, temperature: F32, density: F32, buoyancy: float, weight: float,
                      up: NDArray[np.float64], confinement: float, h: float, dt: float) -> None:
    """:func:`body_forces` in numpy: the cell forces (:func:`vorticity_force`), then :func:`add_cell_force`."""
    lift = np.float32(buoyancy) * temperature - np.float32(weight) * density
    force = [lift * np.float32(up[a]) if abs(up[a]) > 1e-12 else None for a in range(3)]
    if confinement > 0.0:
        vort = vorticity_force(u, v, w, h, confinement)
        force = [vort[a] if force[a] is None else force[a] + vort[a] for a in range(3)]
    add_cell_force(u, v, w, tuple(force), dt)


def add_cell_force(u: F32, v: F32, w: F32, force: tuple[F32 | None, F32 | None, F32 | None], dt: float) -> None:
    """u += Δt·f with a cell-centred force averaged onto the faces (in place)."""
    for axis, (comp, f) in enumerate(zip((u, v, w), force)):
        if f is not None:
            comp += np.float32(dt) * _to_faces(f, axis)


def enforce_solid_faces(u: F32, v: F32, w: F32, hierarchy: poisson.PoissonHierarchy) -> None:
    """u·n = 0 on walls and on faces touching a solid cell (the solid is at rest); open faces keep their value."""
    ax, ay, az = hierarchy.levels[0].faces
    u *= ax
    v *= ay
    w *= az


def project(u: F32, v: F32, w: F32, h: float, hierarchy: poisson.PoissonHierarchy, pressure: F32,
            tolerance: float, max_iterations: int, target: F32 | None = None) -> tuple[F32, float, float, int]:
    """Pressure projection (Stam 1999 §2.5, Helmholtz–Hodge): make ∇·u = 0 in every fluid cell (in place).

    Solves M φ = h·(target − ∇·u) with :func:`poisson.solve` (MGPCG), then u_f −= A_f (φ_nb − φ_c) on every open
    face.  ``target`` is an optional prescribed divergence (explosions, Feldman et al. 2003), 0 elsewhere.
    Returns (φ, max|∇·u − target| before, the same after, iterations); the "after" value is measured from the
    updated velocities, not taken from the solver.  Around the solve, one compiled call before (the divergence,
    its largest value and the right-hand side: :func:`systems.toon_smoke.kernels.divergence_rhs_kernel`) and one
    after (the gradient update and the divergence again: ``pressure_update_kernel``); the same bits as
    :func:`project_numpy`, its reference in the tests.
    """
    from systems.toon_smoke.kernels import divergence_rhs_kernel, pressure_update_kernel

    level = hierarchy.levels[0]
    h32 = np.float32(h)
    has_target = target is not None
    target = _f32c(target) if has_target else level.diag  # a float32 (nx, ny, nz) stand-in, never read
    rhs, div_before = divergence_rhs_kernel(u, v, w, h32, target, has_target, level.active)
    phi, report = poisson.solve(hierarchy, rhs, pressure, tolerance, max_iterations)
    ax, ay, az = level.faces
    div_after = pressure_update_kernel(u, v, w, phi, ax, ay, az, h32, target, has_target, level.active)
    return phi, float(div_before), float(div_after), report.iterations


def project_numpy(u: F32, v: F32, w: F32, h: float, hierarchy: poisson.PoissonHierarchy, pressure: F32,
                  tolerance: float, max_iterations: int, target: F32 | None = None) -> tuple[F32, float, float, int]:
    """:func:`project` as whole-array numpy expressions around the solve (its reference)."""
    level = hierarchy.levels[0]
    fluid = level.active
    before = divergence(u, v, w, h)
    if target is not None:
        before -= target
    div_before = _max_abs(before, fluid)
    phi, report = poisson.solve(hierarchy, -before * np.float32(h), pressure, tolerance, max_iterations)
    ax, ay, az = level.faces
    u[1:-1] -= level.ax * (phi[1:] - phi[:-1])
    u[0] -= ax[0] * phi[0]
    u[-1] += ax[-1] * phi[-1]
    v[:, 1:-1] -= level.ay * (phi[:, 1:] - phi[:, :-1])
    v[:, 0] -= ay[:, 0] * phi[:, 0]
    v[:, -1] += ay[:, -1] * phi[:, -1]
    w[:, :, 1:-1] -= level.az * (phi[:, :, 1:] - phi[:, :, :-1])
    w[:, :, 0] -= az[:, :, 0] * phi[:, :, 0]
    w[:, :, -1] += az[:, :, -1] * phi[:, :, -1]
    after = divergence(u, v, w, h)
    if target is not None:
        after -= target
    div_after = _max_abs(after, fluid)
    return phi, div_before, div_after, report.iterations


def _max_abs(values: F32, where: NDArray[np.bool_]) -> float:
    """max |values| over the cells of ``where`` (0 when there are none), without copying them out first."""
    return float(np.max(np.abs(values), where=where, initial=0.0))
