"""Floating rigid bodies (the engine's requirement after seeds/003's ref. [11]): 6-DOF boxes and spheres with
gravity, buoyancy sampled against the water's height field, water drag, and contacts with the pool.

Buoyancy: each body carries 64 volume samples: a box a 4³ lattice in its own frame, a sphere 64 vertical
columns through it (8 rings at Gauss–Legendre nodes of the disc's area × 8 angles, in the world frame: a sphere
looks the same turned). A sample of volume dV at p, in water of surface height η(x, z), is submerged by the
fraction f = clamp((η − p_y)/s + 1/2, 0, 1), s its vertical thickness (a box's slab; a column's chord), which
makes the submerged volume exact for an upright box and, to 0.2 mm of draft for a radius of 0.5 m, for a
sphere (81 lattice points were 1.6–2.8 cm off). It feels the pressure force ρ·g·f·dV·(−∂η/∂x, 1, −∂η/∂z)
(Archimedes on a sloping surface: the horizontal part is the pressure gradient −ρ·g·∇η, so waves push bodies)
at p; the sum acts at the centre of buoyancy, so boxes bob and tilt back upright. Pressure on a sphere acts
through its centre: its buoyancy has no torque. Drag (implicit, so any drag is stable) slows the body relative
to the water's vertical motion by ``linear_drag`` per kilogram of displaced water, and its spin by
``angular_drag`` × submerged fraction. Integration is semi-implicit Euler, sub-stepped so that the buoyancy
oscillator ω = √(ρ·g·A/m) satisfies ω·Δt ≤ 0.3 at the engine's fixed step (at most ``_MAX_SUBSTEPS`` = 8
sub-steps, so a very light body at a long fixed step may exceed it).

Contacts with the pool's floor (the water's ``depth``) and walls (its footprint): every penetrating box corner
(or sphere support point) gets a normal impulse with restitution and a Coulomb friction impulse, averaged over
the body's contacts, then the body is pushed out.

The systems call :func:`integrate`: one compiled call per water (``body_kernels.float_bodies``) for all of it,
sub-steps and contacts, with the bits of :func:`integrate_numpy`, the numpy statement of the method.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from engine import exact
from engine.exact import matmul, matvec, vecmat
from engine.spatial import cross, quat_mul
from systems.water_surface import body_kernels as BK
from systems.water_surface import kernels as K
from systems.water_surface.geometry import BOX, F64, SPHERE, Grid, all_of, bilinear_slope_pair, max_of, sum_of

__all__ = ["BodyArrays", "apply_impulses", "inertia", "integrate", "integrate_numpy", "limit_speeds", "pool_contacts",
           "water_forces"]

_BOX_N = 4
_SPHERE_RINGS, _SPHERE_ANGLES = 8, 8
_MAX_SUBSTEPS = 8
_OMEGA_DT = 0.3


# kernels.QUAT_TERMS: per entry of R − I, two products q_a·q_b (flattened a·4 + b) and their factors ±2
_FIRST, _SECOND = 4 * K.QUAT_TERMS[:, 1] + K.QUAT_TERMS[:, 2], 4 * K.QUAT_TERMS[:, 4] + K.QUAT_TERMS[:, 5]
_FIRST_SIGN, _SECOND_SIGN = 2.0 * K.QUAT_TERMS[:, 0], 2.0 * K.QUAT_TERMS[:, 3]
_IDENTITY9 = np.eye(3).ravel()


def quat_to_matrix(q: F64) -> F64:
    """Rotation matrices (B, 3, 3) of unit quaternions (B, 4) (w, x, y, z); same as engine.spatial's, for many.

    Each entry is (±2·q_a·q_b + ±2·q_c·q_d) + δ, element-wise (no BLAS, see engine.exact), the bits that
    kernels.wave_bodies computes for the water's outline."""
    products = (q[:, :, None] * q[:, None, :]).reshape(len(q), 16)
    return ((products[:, _FIRST] * _FIRST_SIGN + products[:, _SECOND] * _SECOND_SIGN) + _IDENTITY9).reshape(
        len(q), 3, 3)


def cube(r: F64) -> F64:
    """r³ as r·r·r: numpy's ``r ** 3`` goes through its ``power``, whose SIMD code differs by CPU (engine.exact)."""
    return r * r * r


def _lattice(n: int) -> F64:
    o = (2.0 * np.arange(n) + 1.0) / n - 1.0
    return np.stack(np.meshgrid(o, o, o, indexing="ij"), -1).reshape(-1, 3)


def _columns(rings: int, angles: int) -> tuple[F64, F64, F64]:
    """Vertical columns through the unit sphere: their centres (S, 3) (y = 0), chords (S,) and shares of the
    volume (S,). Rings at the Gauss–Legendre nodes of ρ² (the disc's area) on [0, 1], angles evenly spaced."""
    t, weight = np.polynomial.legendre.leggauss(rings)
    rho = np.sqrt(0.5 * (t + 1.0))
    angle = (np.arange(angles) + 0.5) * (2.0 * np.pi / angles)
    r, a = np.meshgrid(rho, angle, indexing="ij")
    centres = np.stack([r * exact.cos(a), np.zeros_like(r), r * exact.sin(a)], -1).reshape(-1, 3)
    chords = 2.0 * np.sqrt(1.0 - r * r).ravel()
    share = (np.repeat(weight, angles) * chords)  # area weight × chord: each column's volume
    return centres, chords, share / share.sum()


_BOX_SAMPLES = _lattice(_BOX_N)  # in units of the half extents
_SPHERE_SAMPLES, _SPHERE_CHORDS, _SPHERE_COLUMN_SHARE = _columns(_SPHERE_RINGS, _SPHERE_ANGLES)  # units of radius
_SAMPLES = max(len(_BOX_SAMPLES), len(_SPHERE_SAMPLES))
_CORNERS = np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)])


def _padded(samples: F64, share: F64) -> tuple[F64, F64]:
    """Samples as (3, S) (coordinate-major, padded to the larger set) and their shares of the volume (S,) (0 on
    the padding)."""
    table = np.zeros((3, _SAMPLES))
    table[:, :len(samples)] = samples.T
    padded = np.zeros(_SAMPLES)
    padded[:len(samples)] = share
    return table, padded


_BOX_TABLE, _BOX_SHARE = _padded(_BOX_SAMPLES, 1.0 / len(_BOX_SAMPLES))
_SPHERE_TABLE, _SPHERE_SHARE = _padded(_SPHERE_SAMPLES, _SPHERE_COLUMN_SHARE)
_SPHERE_THICKNESS = np.ones(_SAMPLES)  # chords in units of radius (1 on padding, which holds no volume)
_SPHERE_THICKNESS[:len(_SPHERE_SAMPLES)] = _SPHERE_CHORDS
# the same for the compiled step (body_kernels.float_bodies), one row each: box lattice (3), sphere columns (3),
# box shares, sphere shares, sphere chords
_SAMPLE_TABLE = np.concatenate([_BOX_TABLE, _SPHERE_TABLE, [_BOX_SHARE, _SPHERE_SHARE, _SPHERE_THICKNESS]])
_DRY, _DRY_GRID = np.zeros((2, 2)), Grid(2, 2, 1.0, 0.0, 0.0, 0.0)  # placeholders for bodies out of any water


@dataclass
class BodyArrays:
    """Dynamic state of B bodies, gathered from the world for one step and written back after it."""

    shapes: np.ndarray  # (B,) BOX / SPHERE
    half: F64  # (B, 3) world box half extents
    radius: F64  # (B,) world sphere radius
    mass: F64  # (B,)
    position: F64  # (B, 3)
    rotation: F64  # (B, 4) quaternions (w, x, y, z)
    velocity: F64  # (B, 3)
    spin: F64  # (B, 3) angular velocity, world
    force: F64  # (B, 3) external force for this step (scripts), N
    torque: F64  # (B, 3)
    gravity: F64  # (B,)
    linear_damping: F64
    angular_damping: F64
    restitution: F64
    friction: F64
    max_speed: F64  # (B,) m/s
    max_spin: F64  # (B,) rad/s

    def __len__(self) -> int:
        return len(self.mass)

    @property
    def volume(self) -> F64:
        box = 8.0 * np.multiply.reduce(self.half, axis=1)
        return np.where(self.shapes == SPHERE, 4.0 / 3.0 * np.pi * cube(self.radius), box)


def inertia(bodies: BodyArrays) -> F64:
    """Principal moments (B, 3) in the body frame: box m/12·(b² + c², …) with full sizes, sphere 2/5·m·r²."""
    full2 = (2.0 * bodies.half) ** 2
    box = bodies.mass[:, None] / 12.0 * (full2[:, [1, 0, 0]] + full2[:, [2, 2, 1]])
    sphere = 0.4 * bodies.mass * bodies.radius ** 2
    return np.where((bodies.shapes == SPHERE)[:, None], sphere[:, None], box)


def _world_inverse_inertia(rot: F64, moments: F64) -> F64:
    return matmul(rot / moments[:, None, :], rot.transpose(0, 2, 1))


def _rotate(rot: F64, v: F64) -> F64:
    """R·v for (B, 3, 3) matrices and (B, 3) vectors."""
    return matvec(rot, v)


def _unrotate(rot: F64, v: F64) -> F64:
    """Rᵀ·v (world to body frame)."""
    return vecmat(v, rot)


def _samples(bodies: BodyArrays, rot: F64) -> tuple[F64, F64, F64]:
    """World sample offsets (B, 3, S) from the centre of mass (coordinate-major), sample volumes (B, S), vertical
    thickness (B, S). Boxes: their lattice turned with them, one slab thickness each; spheres: the columns, not
    turned, each its chord."""
    is_box = bodies.shapes == BOX
    s = len(_BOX_SAMPLES)
    if all_of(is_box, axis=None):
        local = _BOX_TABLE[None, :, :s] * bodies.half[:, :, None]
        volume = bodies.volume[:, None] * _BOX_SHARE[:s]
        thickness = sum_of(np.abs(rot[:, 1, :]) * bodies.half, axis=1) * (2.0 / _BOX_N)
        return matmul(rot, local), volume, thickness[:, None]
    box = is_box[:, None]
    turned = matmul(rot, _BOX_TABLE[None] * bodies.half[:, :, None])
    offset = np.where(box[:, :, None], turned, _SPHERE_TABLE[None] * bodies.radius[:, None, None])
    volume = bodies.volume[:, None] * np.where(box, _BOX_SHARE, _SPHERE_SHARE)
    thickness_box = sum_of(np.abs(rot[:, 1, :]) * bodies.half, axis=1) * (2.0 / _BOX_N)
    thickness = np.where(box, thickness_box[:, None], _SPHERE_THICKNESS * bodies.radius[:, None])
    return offset, volume, thickness


def water_forces(bodies: BodyArrays, rot: F64, heights: F64, previous: F64, dt: float, grid: Grid, density: float,
                 gravity: F64) -> tuple[F64, F64, F64, F64]:
    """Buoyancy force and torque about the centre of mass (B, 3), submerged volume (B,) and the mean vertical
    water velocity (z(t) − z(t−1)) / Δt over the submerged samples (B,), ``previous`` = z(t − 1).

    Every array is (B, S), one per coordinate: (B, S, 3) arrays with their short last axis cost several times
    more per element."""
    offset, dv, s = _samples(bodies, rot)
    ox, oy, oz = offset[:, 0], offset[:, 1], offset[:, 2]
    position = bodies.position
    py = position[:, 1:2] + oy
    u = (position[:, 0:1] + ox - grid.x0) / grid.h
    v = (position[:, 2:3] + oz - grid.z0) / grid.h
    wet = (u >= 0.0) & (u <= grid.nx - 1) & (v >= 0.0) & (v <= grid.nz - 1)
    eta, du, dz, eta_before = bilinear_slope_pair(heights, previous, u, v)
    frac = np.minimum(np.maximum((grid.y0 + eta - py) / s + 0.5, 0.0), 1.0) * wet
    sub = frac * dv
    push = (density * gravity)[:, None] * sub
    fx, fz = push * du / -grid.h, push * dz / -grid.h
    submerged = sum_of(sub, axis=1)
    w = (eta - eta_before) / dt
    water_velocity = sum_of(sub * w, axis=1) / np.where(submerged > 0.0, submerged, 1.0)
    force = np.empty((len(position), 3))
    torque = np.empty((len(position), 3))
    force[:, 0], force[:, 1], force[:, 2] = sum_of(fx, axis=1), sum_of(push, axis=1), sum_of(fz, axis=1)
    torque[:, 0] = sum_of(oy * fz - oz * push, axis=1)
    torque[:, 1] = sum_of(oz * fx - ox * fz, axis=1)
    torque[:, 2] = sum_of(ox * push - oy * fx, axis=1)
    torque[bodies.shapes == SPHERE] = 0.0  # pressure on a sphere acts through its centre
    return force, torque, submerged, water_velocity


def apply_impulses(bodies: BodyArrays, impulse: F64, angular_impulse: F64) -> None:
    """v += J/m, ω += I⁻¹·L (world inverse inertia)."""
    if not (impulse.any() or angular_impulse.any()):
        return
    rot = quat_to_matrix(bodies.rotation)
    bodies.velocity += impulse / bodies.mass[:, None]
    inv = _world_inverse_inertia(rot, inertia(bodies))
    bodies.spin += matvec(inv, angular_impulse)


def substeps(bodies: BodyArrays, density: float, dt: float) -> int:
    """Sub-steps so that the stiffest body's buoyancy oscillation ω = √(ρ·g·A/m) keeps ω·Δt ≤ 0.3."""
    if len(bodies) == 0:
        return 1
    half = bodies.half
    faces = 4.0 * np.maximum(np.maximum(half[:, 0] * half[:, 1], half[:, 1] * half[:, 2]), half[:, 0] * half[:, 2])
    area = np.where(bodies.shapes == SPHERE, np.pi * bodies.radius ** 2, faces)
    omega = np.sqrt(density * np.maximum(bodies.gravity, 1e-9) * area / bodies.mass)
    return _steps(float(max_of(omega)) * dt / _OMEGA_DT)


def _steps(rate: float) -> int:
    return min(max(math.ceil(rate), 1), _MAX_SUBSTEPS)


def integrate(bodies: BodyArrays, dt: float, water: tuple | None, linear_drag: float = 0.0,
              angular_drag: float = 0.0, density: float = 1000.0, floor: float | None = None) -> F64:
    """Advance the bodies by ``dt`` (sub-stepped); ``water`` = (heights z(t), z(t − 1), grid) or None. With
    ``floor`` (the pool's floor, world y; in the water only), then the contacts with the pool (:func:`pool_contacts`)
    and the speed limits again. Returns the submerged volume (B,) of the last sub-step.

    One compiled call (``body_kernels.float_bodies``) after the damping's exponentials, the bits of
    :func:`integrate_numpy` (a few hundred numpy calls on arrays of a few elements)."""
    n = len(bodies)
    submerged = np.zeros(n)
    if n == 0:
        return submerged
    if water is None:
        heights = previous = _DRY
        grid, steps = _DRY_GRID, 1
    else:
        heights, previous, grid = water
        steps = _steps(BK.substep_rate(bodies.shapes, bodies.half, bodies.radius, bodies.mass, bodies.gravity,
                                       float(density), float(dt)))
    h = dt / steps
    state = np.concatenate((bodies.position, bodies.rotation, bodies.velocity, bodies.spin), axis=1)
    BK.float_bodies(state, submerged, bodies.shapes, bodies.half, bodies.radius, cube(bodies.radius), bodies.mass,
                    bodies.gravity, bodies.force, bodies.torque, exact.exp(-bodies.linear_damping * h),
                    exact.exp(-bodies.angular_damping * h), bodies.max_speed, bodies.max_spin, bodies.restitution,
                    bodies.friction, steps, float(h), float(dt), water is not None, heights, previous, grid.nx,
                    grid.nz, float(grid.x0), float(grid.z0), float(grid.h), float(grid.y0), float(linear_drag),
                    float(angular_drag), float(density), 0.0 if floor is None else float(floor),
                    water is not None and floor is not None, _SAMPLE_TABLE, len(_BOX_SAMPLES), K.QUAT_TERMS,
                    _PLANE_NORMALS, _CORNERS)
    bodies.position, bodies.rotation = state[:, BK.POSITION:BK.ROTATION], state[:, BK.ROTATION:BK.VELOCITY]
    bodies.velocity, bodies.spin = state[:, BK.VELOCITY:BK.SPIN], state[:, BK.SPIN:]
    return submerged


def integrate_numpy(bodies: BodyArrays, dt: float, water: tuple | None, linear_drag: float = 0.0,
                    angular_drag: float = 0.0, density: float = 1000.0, floor: float | None = None) -> F64:
    """:func:`integrate` in numpy, its reference: semi-implicit Euler, vectorized over the bodies, per sub-step
    the forces (:func:`water_forces`), Euler's equations and the quaternion's rate; then, with ``floor``,
    :func:`pool_contacts` and :func:`limit_speeds`."""
    n = substeps(bodies, density, dt) if water is not None else 1
    h = dt / n
    moments = inertia(bodies)
    volume = bodies.volume
    submerged = np.zeros(len(bodies))
    decay_v = exact.exp(-bodies.linear_damping * h)[:, None]
    decay_w = exact.exp(-bodies.angular_damping * h)[:, None]
    weight = bodies.mass * bodies.gravity
    limit_speeds(bodies)  # what impulses and scripts gave; each sub-step limits what it adds
    for _ in range(n):  # sub-steps, vectorized over bodies
        rot = quat_to_matrix(bodies.rotation)
        force = bodies.force.copy()
        force[:, 1] -= weight
        torque = bodies.torque
        if water is not None:
            heights, previous, grid = water
            f, t, submerged, water_up = water_forces(bodies, rot, heights, previous, dt, grid, density,
                                                     bodies.gravity)
            force += f
            torque = torque + t
            drag = linear_drag * density * submerged / bodies.mass
            accel = force / bodies.mass[:, None]
            accel[:, 1] += drag * water_up
            bodies.velocity = (bodies.velocity + h * accel) / (1.0 + h * drag)[:, None] * decay_v
        else:
            bodies.velocity = (bodies.velocity + h * (force / bodies.mass[:, None])) * decay_v
        bodies.velocity = _limit(bodies.velocity, bodies.max_speed)  # before the position moves with it
        # Euler's equations in the body frame: I·ω̇ = τ − ω × I·ω, with I = R·M·Rᵀ (M the principal moments)
        spin_body = _unrotate(rot, bodies.spin)
        gyro = cross(spin_body, moments * spin_body)
        accel = _rotate(rot, (_unrotate(rot, torque) - gyro) / moments)
        spin = bodies.spin + h * accel
        if water is not None:
            spin /= (1.0 + h * angular_drag * submerged / volume)[:, None]
        spin *= decay_w
        bodies.spin = spin = _limit(spin, bodies.max_spin)  # before the rotation turns with it
        bodies.position = bodies.position + h * bodies.velocity
        q = bodies.rotation + (0.5 * h) * _spin_product(spin, bodies.rotation)
        bodies.rotation = q / np.sqrt(sum_of(q * q, axis=1))[:, None]
    if water is not None and floor is not None:
        pool_contacts(bodies, water[2], floor, np.ones(len(bodies), bool))
        limit_speeds(bodies)  # contact impulses may spin a body past its limit
    return submerged


def _limit(v: F64, limit: F64) -> F64:
    """Rows of ``v`` (B, 3) longer than ``limit`` (B,) scaled down to it; the same array when none is (the
    same bits).  A row with a non-finite component becomes zero (a body that overflowed stops instead of
    poisoning the water); a finite row too long to square (1e200) is scaled by its largest component first."""
    with np.errstate(over="ignore", invalid="ignore"):
        length2 = v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2]
        over = ~(length2 <= limit * limit)  # NaN compares false: caught here
        if not over.any():
            return v
        v = v.copy()
        finite = np.isfinite(v).all(axis=1) & over
        rows = v[finite]
        big = np.abs(rows).max(axis=1)
        unit = rows / big[:, None]
        length = big * np.sqrt(unit[:, 0] * unit[:, 0] + unit[:, 1] * unit[:, 1] + unit[:, 2] * unit[:, 2])
        v[finite] = rows * (limit[finite] / length)[:, None]
        v[over & ~finite] = 0.0
    return v


def limit_speeds(bodies: BodyArrays) -> None:
    """Clamp speed and spin to the bodies' ``max_speed`` / ``max_angular_speed`` (RigidBody)."""
    bodies.velocity = _limit(bodies.velocity, bodies.max_speed)
    bodies.spin = _limit(bodies.spin, bodies.max_spin)


def _spin_product(spin: F64, q: F64) -> F64:
    """(0, ω) ⊗ q (Hamilton product; q̇ = ½·(0, ω) ⊗ q) for (B, 3) ω and (B, 4) q."""
    return quat_mul(np.concatenate([np.zeros((len(spin), 1)), spin], axis=1), q)


def pool_contacts(bodies: BodyArrays, grid: Grid, floor: float, active: np.ndarray) -> None:
    """Impulses and push-out against the pool's floor (y ≥ floor) and walls, for the ``active`` bodies.

    Per body and plane, the penetrating corners (a sphere's support point) act as one contact at their centroid:
    a normal impulse with restitution and a Coulomb friction impulse there, then the body is pushed out by the
    deepest penetration.
    """
    if not active.any():
        return
    rot = quat_to_matrix(bodies.rotation)
    normals = _PLANE_NORMALS
    x_hi, z_hi = grid.x0 + (grid.nx - 1) * grid.h, grid.z0 + (grid.nz - 1) * grid.h
    offsets = np.array([floor, grid.x0, -x_hi, grid.z0, -z_hi])
    reach = np.where(bodies.shapes == SPHERE, bodies.radius, np.linalg.norm(bodies.half, axis=1))
    clear = matmul(bodies.position, normals.T) - reach[:, None] > offsets  # (B, P): a plane no corner can reach
    if np.all(clear | ~active[:, None]):
        return
    corners = np.einsum("bij,bcj->bci", rot, _CORNERS[None] * bodies.half[:, None, :])  # (B, 8, 3)
    support = -bodies.radius[:, None, None] * normals[None, :, :]  # (B, P, 3) sphere
    r = np.where((bodies.shapes == SPHERE)[:, None, None, None], support[:, :, None, :],
                 corners[:, None, :, :])  # (B, P, 8, 3) offsets from the centre
    depth = offsets[None, :, None] - np.einsum("bpci,pi->bpc", bodies.position[:, None, None, :] + r, normals)
    touching = (depth > 0.0) & active[:, None, None]  # (B, P, 8)
    count = touching.sum(axis=2)
    if not count.any():
        return
    arm = np.sum(np.where(touching[..., None], r, 0.0), axis=2) / np.maximum(count, 1)[..., None]  # (B, P, 3)
    n = normals[None, :, :]
    vc = bodies.velocity[:, None, :] + cross(bodies.spin[:, None, :], arm)
    vn = np.sum(vc * n, axis=-1)
    hit = (count > 0) & (vn < 0.0)
    inv = _world_inverse_inertia(rot, inertia(bodies))
    k = 1.0 / bodies.mass[:, None] + np.sum(cross(matvec(inv[:, None], cross(arm, n)), arm) * n, -1)
    jn = np.where(hit, -(1.0 + bodies.restitution[:, None]) * vn / k, 0.0)
    vt = vc - vn[..., None] * n
    speed = np.linalg.norm(vt, axis=-1)
    jt = np.minimum(bodies.friction[:, None] * jn, speed / k)
    tangent = vt / np.where(speed > 0.0, speed, 1.0)[..., None]
    impulse = jn[..., None] * n - jt[..., None] * tangent  # (B, P, 3)
    bodies.velocity += impulse.sum(axis=1) / bodies.mass[:, None]
    bodies.spin += matvec(inv, cross(arm, impulse).sum(axis=1))
    push = np.max(np.where(touching, depth, 0.0), axis=2)  # (B, P)
    bodies.position = bodies.position + np.einsum("bp,pi->bi", push, normals)


_PLANE_NORMALS = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
