"""Floating rigid bodies (the engine's requirement after seeds/003's ref. [11]): 6-DOF boxes and spheres with
gravity, buoyancy sampled against the water's height field, water drag, and contacts with the pool.

Buoyancy: each body carries a lattice of volume samples (4³ for a box, the 81 points of a 5³ lattice inside a
sphere). A sample of volume dV at p, in water of surface height η(x, z), is submerged by the fraction
f = clamp((η − p_y)/s + 1/2, 0, 1), s its vertical thickness, which makes the submerged volume exact for an
upright box. It feels the pressure force ρ·g·f·dV·(−∂η/∂x, 1, −∂η/∂z) (Archimedes on a sloping surface: the
horizontal part is the pressure gradient −ρ·g·∇η, so waves push bodies) at p; the sum acts at the centre of
buoyancy, so bodies bob and tilt back upright. Drag (implicit, so any drag is stable) slows the body relative
to the water's vertical motion by ``linear_drag`` per kilogram of displaced water, and its spin by
``angular_drag`` × submerged fraction. Integration is semi-implicit Euler, sub-stepped so that the buoyancy
oscillator ω = √(ρ·g·A/m) satisfies ω·Δt ≤ 0.3 at the engine's fixed step.

Contacts with the pool's floor (the water's ``depth``) and walls (its footprint): every penetrating box corner
(or sphere support point) gets a normal impulse with restitution and a Coulomb friction impulse, averaged over
the body's contacts, then the body is pushed out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.spatial import cross, quat_mul, quat_normalize
from systems.water_surface.geometry import BOX, F64, SPHERE, Grid, bilinear, bilinear_with_slope

__all__ = ["BodyArrays", "apply_impulses", "inertia", "integrate", "pool_contacts", "water_forces"]

_BOX_N = 4
_SPHERE_N = 5
_MAX_SUBSTEPS = 8
_OMEGA_DT = 0.3


def _quaternion_products() -> F64:
    """(16, 9): the rotation matrix of a unit quaternion q = (w, x, y, z), minus the identity, as a linear map of
    the products q_a·q_b (flattened a·4 + b): R − I = 2·[[−yy − zz, xy − wz, xz + wy], [xy + wz, −xx − zz,
    yz − wx], [xz − wy, yz + wx, −xx − yy]]."""
    w, x, y, z = range(4)
    terms = [[(-1, y, y), (-1, z, z)], [(1, x, y), (-1, w, z)], [(1, x, z), (1, w, y)],
             [(1, x, y), (1, w, z)], [(-1, x, x), (-1, z, z)], [(1, y, z), (-1, w, x)],
             [(1, x, z), (-1, w, y)], [(1, y, z), (1, w, x)], [(-1, x, x), (-1, y, y)]]
    table = np.zeros((16, 9))
    for entry, products in enumerate(terms):
        for sign, a, b in products:
            table[4 * a + b, entry] = 2.0 * sign
    return table


_QUATERNION_PRODUCTS = _quaternion_products()
_IDENTITY9 = np.eye(3).ravel()


def quat_to_matrix(q: F64) -> F64:
    """Rotation matrices (B, 3, 3) of unit quaternions (B, 4) (w, x, y, z); same as engine.spatial's, for many."""
    products = (q[:, :, None] * q[:, None, :]).reshape(len(q), 16)
    return (products @ _QUATERNION_PRODUCTS + _IDENTITY9).reshape(len(q), 3, 3)


def _lattice(n: int) -> F64:
    o = (2.0 * np.arange(n) + 1.0) / n - 1.0
    return np.stack(np.meshgrid(o, o, o, indexing="ij"), -1).reshape(-1, 3)


_BOX_SAMPLES = _lattice(_BOX_N)  # in units of the half extents
_SPHERE_SAMPLES = _lattice(_SPHERE_N)[np.linalg.norm(_lattice(_SPHERE_N), axis=1) <= 1.0]  # units of radius
_SAMPLES = max(len(_BOX_SAMPLES), len(_SPHERE_SAMPLES))
_CORNERS = np.array([[sx, sy, sz] for sx in (-1.0, 1.0) for sy in (-1.0, 1.0) for sz in (-1.0, 1.0)])


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

    def __len__(self) -> int:
        return len(self.mass)

    @property
    def volume(self) -> F64:
        box = 8.0 * np.prod(self.half, axis=1)
        return np.where(self.shapes == SPHERE, 4.0 / 3.0 * np.pi * self.radius ** 3, box)


def inertia(bodies: BodyArrays) -> F64:
    """Principal moments (B, 3) in the body frame: box m/12·(b² + c², …) with full sizes, sphere 2/5·m·r²."""
    full2 = (2.0 * bodies.half) ** 2
    box = bodies.mass[:, None] / 12.0 * np.stack([full2[:, 1] + full2[:, 2], full2[:, 0] + full2[:, 2],
                                                    full2[:, 0] + full2[:, 1]], -1)
    sphere = (0.4 * bodies.mass * bodies.radius ** 2)[:, None] * np.ones(3)
    return np.where((bodies.shapes == SPHERE)[:, None], sphere, box)


def _world_inverse_inertia(rot: F64, moments: F64) -> F64:
    return np.einsum("bij,bj,bkj->bik", rot, 1.0 / moments, rot)


def _samples(bodies: BodyArrays, rot: F64) -> tuple[F64, F64, F64]:
    """World sample offsets (B, S, 3) from the centre of mass, sample volumes (B, S), vertical thickness (B,)."""
    b = len(bodies)
    local = np.zeros((b, _SAMPLES, 3))
    volume = np.zeros((b, _SAMPLES))
    is_box = bodies.shapes == BOX
    local[:, :len(_BOX_SAMPLES)] = np.where(is_box[:, None, None], _BOX_SAMPLES[None] * bodies.half[:, None, :], 0.0)
    volume[:, :len(_BOX_SAMPLES)] = np.where(is_box, bodies.volume / len(_BOX_SAMPLES), 0.0)[:, None]
    sph = ~is_box
    local[sph, :len(_SPHERE_SAMPLES)] = _SPHERE_SAMPLES[None] * bodies.radius[sph, None, None]
    volume[sph] = 0.0
    volume[sph, :len(_SPHERE_SAMPLES)] = (bodies.volume[sph] / len(_SPHERE_SAMPLES))[:, None]
    thickness_box = np.einsum("bj,bj->b", np.abs(rot[:, 1, :]), 2.0 * bodies.half / _BOX_N)
    thickness = np.where(is_box, thickness_box, 2.0 * bodies.radius / _SPHERE_N)
    return np.einsum("bij,bsj->bsi", rot, local), volume, thickness


def water_forces(bodies: BodyArrays, rot: F64, heights: F64, previous: F64, dt: float, grid: Grid, density: float,
                 gravity: F64) -> tuple[F64, F64, F64, F64]:
    """Buoyancy force and torque about the centre of mass (B, 3), submerged volume (B,) and the mean vertical
    water velocity (z(t) − z(t−1)) / Δt over the submerged samples (B,), ``previous`` = z(t − 1)."""
    offset, dv, s = _samples(bodies, rot)
    p = bodies.position[:, None, :] + offset
    uv = grid.to_uv(p[..., [0, 2]])
    wet = grid.inside(uv)
    eta, du, dz = bilinear_with_slope(heights, uv)
    frac = np.clip((grid.y0 + eta - p[..., 1]) / s[:, None] + 0.5, 0.0, 1.0) * wet
    sub = frac * dv
    push = density * gravity[:, None] * sub
    force = np.stack([-push * du / grid.h, push, -push * dz / grid.h], -1)
    submerged = sub.sum(axis=1)
    w = (eta - bilinear(previous, uv)) / dt
    water_velocity = np.sum(sub * w, axis=1) / np.where(submerged > 0.0, submerged, 1.0)
    return force.sum(axis=1), cross(offset, force).sum(axis=1), submerged, water_velocity


def apply_impulses(bodies: BodyArrays, impulse: F64, angular_impulse: F64) -> None:
    """v += J/m, ω += I⁻¹·L (world inverse inertia)."""
    if not (impulse.any() or angular_impulse.any()):
        return
    rot = quat_to_matrix(bodies.rotation)
    bodies.velocity += impulse / bodies.mass[:, None]
    inv = _world_inverse_inertia(rot, inertia(bodies))
    bodies.spin += np.einsum("bij,bj->bi", inv, angular_impulse)


def substeps(bodies: BodyArrays, density: float, dt: float) -> int:
    """Sub-steps so that the stiffest body's buoyancy oscillation ω = √(ρ·g·A/m) keeps ω·Δt ≤ 0.3."""
    if len(bodies) == 0:
        return 1
    faces = 4.0 * np.stack([bodies.half[:, 0] * bodies.half[:, 1], bodies.half[:, 1] * bodies.half[:, 2],
                            bodies.half[:, 0] * bodies.half[:, 2]], -1).max(axis=1)
    area = np.where(bodies.shapes == SPHERE, np.pi * bodies.radius ** 2, faces)
    omega = np.sqrt(density * np.maximum(bodies.gravity, 1e-9) * area / bodies.mass)
    return int(np.clip(np.ceil(float(omega.max()) * dt / _OMEGA_DT), 1, _MAX_SUBSTEPS))


def integrate(bodies: BodyArrays, dt: float, water: tuple | None, linear_drag: float = 0.0,
              angular_drag: float = 0.0, density: float = 1000.0) -> F64:
    """Advance the bodies by ``dt`` (sub-stepped); ``water`` = (heights z(t), z(t − 1), grid) or None.
    Returns the submerged volume (B,) of the last sub-step."""
    n = substeps(bodies, density, dt) if water is not None else 1
    h = dt / n
    moments = inertia(bodies)
    submerged = np.zeros(len(bodies))
    decay_v = np.exp(-bodies.linear_damping * h)[:, None]
    decay_w = np.exp(-bodies.angular_damping * h)[:, None]
    for _ in range(n):  # sub-steps, vectorized over bodies
        rot = quat_to_matrix(bodies.rotation)
        force = bodies.force.copy()
        force[:, 1] -= bodies.mass * bodies.gravity
        torque = bodies.torque.copy()
        drag = np.zeros(len(bodies))
        water_up = np.zeros(len(bodies))
        spin_drag = np.zeros(len(bodies))
        if water is not None:
            heights, previous, grid = water
            f, t, submerged, water_up = water_forces(bodies, rot, heights, previous, dt, grid, density,
                                                     bodies.gravity)
            force += f
            torque += t
            drag = linear_drag * density * submerged / bodies.mass
            spin_drag = angular_drag * submerged / bodies.volume
        accel = force / bodies.mass[:, None]
        accel[:, 1] += drag * water_up
        bodies.velocity = (bodies.velocity + h * accel) / (1.0 + h * drag)[:, None] * decay_v
        inv = _world_inverse_inertia(rot, moments)
        world_inertia = np.einsum("bij,bj,bkj->bik", rot, moments, rot)
        gyro = cross(bodies.spin, np.einsum("bij,bj->bi", world_inertia, bodies.spin))
        bodies.spin = (bodies.spin + h * np.einsum("bij,bj->bi", inv, torque - gyro)) / (1.0 + h * spin_drag)[:, None]
        bodies.spin *= decay_w
        bodies.position = bodies.position + h * bodies.velocity
        spin_q = np.concatenate([np.zeros((len(bodies), 1)), bodies.spin], axis=1)
        bodies.rotation = quat_normalize(bodies.rotation + 0.5 * h * quat_mul(spin_q, bodies.rotation))
    return submerged


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
    clear = bodies.position @ normals.T - reach[:, None] > offsets  # (B, P): a plane no corner can reach
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
    k = 1.0 / bodies.mass[:, None] + np.sum(cross(np.einsum("bij,bpj->bpi", inv, cross(arm, n)), arm) * n, -1)
    jn = np.where(hit, -(1.0 + bodies.restitution[:, None]) * vn / k, 0.0)
    vt = vc - vn[..., None] * n
    speed = np.linalg.norm(vt, axis=-1)
    jt = np.minimum(bodies.friction[:, None] * jn, speed / k)
    tangent = vt / np.where(speed > 0.0, speed, 1.0)[..., None]
    impulse = jn[..., None] * n - jt[..., None] * tangent  # (B, P, 3)
    bodies.velocity += impulse.sum(axis=1) / bodies.mass[:, None]
    bodies.spin += np.einsum("bij,bj->bi", inv, cross(arm, impulse).sum(axis=1))
    push = np.max(np.where(touching, depth, 0.0), axis=2)  # (B, P)
    bodies.position = bodies.position + np.einsum("bp,pi->bi", push, normals)


_PLANE_NORMALS = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
