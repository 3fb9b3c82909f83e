"""One fixed step of the dust devil (seeds/004), pure numpy, vectorized over particles.

Per step: the field clock advances; every ``rotation_interval`` the vortex centre line turns clockwise (seen from
above) by a random angle (2.2); the tornado field is evaluated on the grid (2.1); each particle moves along the
vector of its nearest grid point (or the trilinear one) — in world space, where wind blowing into the terrain is
replaced by its projection on the slope, eq. 1 (3.2) — and never ends below the terrain; particles that leave
the box or outlive their lifetime are emitted again at the funnel's foot.  Particles are stored in field space
(4), so moving the entity's Transform (dragging) moves all of them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from components.dust_devil import DustDevilConfig, DustDevilState
from engine import exact
from engine.heightfield import HeightField
from engine.spatial import Transform, quat_conjugate, quat_is_identity, quat_rotate
from systems.dust_devil.tornado import WindField, centre_line, to_unit

__all__ = ["Ground", "project_onto_slope", "slope_wind", "step", "rotate_centre_line", "centre_at", "emit", "drag",
           "world_positions", "rotation_steps", "marker_points", "to_world", "to_local"]

F64 = NDArray[np.float64]
_UP = np.array([0.0, 1.0, 0.0])


def to_world(transform: Transform, p: F64, direction: bool = False) -> F64:
    """``Transform.to_world`` (for a ``direction``: R·(scale·v)) with fast paths for no rotation / unit scale."""
    out = p if np.all(transform.scale == 1.0) else p * transform.scale
    if not quat_is_identity(transform.rotation):
        out = quat_rotate(transform.rotation, out)
    if direction:
        return out.copy() if out is p else out
    return out + transform.position


def to_local(transform: Transform, p: F64) -> F64:
    """``Transform.to_local`` with fast paths for no rotation / unit scale."""
    p = p - transform.position
    if not quat_is_identity(transform.rotation):
        p = quat_rotate(quat_conjugate(transform.rotation), p)
    if not np.all(transform.scale == 1.0):
        p = p / transform.scale
    return p


@dataclass
class Ground:
    """A terrain height field placed by its entity's Transform (rotation and translation; scale is ignored, as
    for the engine's height-field Collider).  Heights are measured along the terrain's local up axis."""

    field: HeightField
    transform: Transform | None = None

    def _local(self, points: F64) -> F64:
        t = self.transform
        if t is None:
            return points
        local = points - t.position
        return local if quat_is_identity(t.rotation) else quat_rotate(quat_conjugate(t.rotation), local)

    def _world_dir(self, v: F64) -> F64:
        t = self.transform
        return v if t is None or quat_is_identity(t.rotation) else quat_rotate(t.rotation, v)

    def depth(self, points: F64) -> F64:
        """How far (N,) each world point lies below the surface along the terrain's up (negative above)."""
        local = self._local(points)
        return self.field.height_at(local[:, 0], local[:, 2]) - local[:, 1]

    def normal(self, points: F64) -> F64:
        """World unit normals (N, 3) of the surface under each point."""
        local = self._local(points)
        return self._world_dir(self.field.normal_at(local[:, 0], local[:, 2]))

    def up(self) -> F64:
        return self._world_dir(_UP[None, :])[0]

    def lift(self, points: F64) -> F64:
        """``points`` with those below the surface moved up onto it (in place); returns the array."""
        below = self.depth(points)
        mask = below > 0.0
        if mask.any():
            points[mask] += below[mask, None] * self.up()
        return points


def project_onto_slope(v: F64, n: F64) -> F64:
    """Eq. 1 (3.2, seeds/004): r = v - ((n·v) / |n|²) n, the part of v parallel to the ground (r·n = 0)."""
    return v - (np.sum(n * v, axis=-1) / np.sum(n * n, axis=-1))[:, None] * n


def slope_wind(points: F64, v: F64, dt: float, ground: Ground) -> tuple[F64, NDArray[np.intp], F64, F64]:
    """World velocities after the terrain's influence (3.2): where the wind points into the ground (n·v < 0,
    n the normal under the particle) *and* the next position p + v dt would be under it, v is replaced by eq. 1;
    wind leaving the ground is kept.

    Returns (velocities, indices projected, next positions p + v dt with the new v, their depth below ground).
    """
    v = v.copy()
    nxt = points + v * dt
    depth = ground.depth(nxt)
    idx = np.flatnonzero(depth > 0.0)
    if idx.size:
        n = ground.normal(points[idx])
        into = np.sum(n * v[idx], axis=-1) < 0.0
        idx, n = idx[into], n[into]
        v[idx] = project_onto_slope(v[idx], n)
        nxt[idx] = points[idx] + v[idx] * dt
        depth[idx] = ground.depth(nxt[idx])
    return v, idx, nxt, depth


def rotation_steps(cfg: DustDevilConfig, dt: float) -> int:
    """The rotation interval in fixed steps (at least one)."""
    return max(1, int(round(cfg.rotation_interval / dt)))


def rotate_centre_line(cfg: DustDevilConfig, state: DustDevilState, rng: np.random.Generator) -> float:
    """2.2: turn the vortex centre line clockwise (seen from above) by a random angle drawn uniformly within
    ``rotation_angle_range``; returns the angle in radians."""
    lo, hi = cfg.rotation_angle_range
    angle = math.radians(float(rng.uniform(lo, hi)))
    state.centre_rotation = float(np.float64(state.centre_rotation) + angle)
    state.rotation_count += 1
    return angle


def centre_at(cfg: DustDevilConfig, state: DustDevilState, height: F64) -> F64:
    """Field-space (x, z) (N, 2) of the vortex centre line at field-space heights ``height`` (N,)."""
    sx, sy, sz = cfg.field_size
    xc, yc = centre_line(np.clip(height / sy, 0.0, 1.0), state.field_time, state.centre_rotation)
    return np.stack([(xc - 0.5) * sx, (0.5 - yc) * sz], axis=-1)


def emit(cfg: DustDevilConfig, state: DustDevilState, which: NDArray[np.intp], transform: Transform,
         ground: Ground | None, rng: np.random.Generator) -> None:
    """(Re-)emit particles ``which``: uniform in a disc of ``emission_radius`` around the vortex centre line
    where it meets the ground (or the box floor, whichever is higher), up to ``emission_height`` above it;
    fresh age and lifetime."""
    n = int(which.size)
    if n == 0:
        return
    draws = rng.random((n, 4))
    terrain = ground is not None and cfg.terrain_interaction
    if USE_KERNELS and _kernel_case(transform, ground if terrain else None):
        _emit_kernel(cfg, state, which, transform, ground if terrain else None, draws)
        return
    radius = cfg.emission_radius * np.sqrt(draws[:, 0])
    angle = 2.0 * np.pi * draws[:, 1]
    offset = np.stack([radius * exact.cos(angle), radius * exact.sin(angle)], axis=-1)
    sx, sy, sz = cfg.field_size
    half = np.array([0.5 * sx, 0.5 * sz])
    local = np.zeros((n, 3))
    for _ in range(2):  # the centre line at the ground's height, then the ground under that point
        local[:, [0, 2]] = np.clip(centre_at(cfg, state, local[:, 1]) + offset, -half, half)
        local[:, 1] = 0.0
        world = to_world(transform, local)
        if ground is not None and cfg.terrain_interaction:
            ground.lift(world)
        local = to_local(transform, world)
    world += (cfg.emission_height * draws[:, 2])[:, None] * _UP
    local = to_local(transform, world)
    local[:, 1] = np.minimum(local[:, 1], sy)
    state.positions[which] = local
    state.ages[which] = 0.0
    state.lifetimes[which] = cfg.particle_lifetime * (1.0 - cfg.lifetime_jitter * draws[:, 3])


def _emit_kernel(cfg: DustDevilConfig, state: DustDevilState, which: NDArray[np.intp], transform: Transform,
                 ground: Ground | None, draws: F64) -> None:
    """:func:`emit` after its random draws, as two passes of the compiled kernels.emit_particles (the same
    bits): the particles' feet on the ground under the centre line's foot, then, with the centre line looked up
    at those heights, their final places.  The sin and cos stay outside (the angle, the centre line: engine.exact)."""
    from systems.dust_devil.kernels import emit_particles

    angle = 2.0 * np.pi * draws[:, 1]
    cos_angle, sin_angle = exact.cos(angle), exact.sin(angle)
    sx, sy, sz = cfg.field_size
    heights, origin, spacing, ground_position = _ground_args(ground)
    feet = np.empty(len(draws))
    state.positions = np.ascontiguousarray(state.positions, dtype=np.float64)  # written in place (no copy if so)
    state.ages = np.ascontiguousarray(state.ages, dtype=np.float64)
    state.lifetimes = np.ascontiguousarray(state.lifetimes, dtype=np.float64)
    args = (float(cfg.emission_radius), 0.5 * sx, 0.5 * sz, np.asarray(transform.position, dtype=np.float64),
            ground is not None, heights, origin, spacing, ground_position)
    finish = (state.positions, state.ages, state.lifetimes, np.ascontiguousarray(which, dtype=np.intp),
              float(cfg.emission_height), float(sy), float(cfg.particle_lifetime), float(cfg.lifetime_jitter))
    # the centre line at the box floor (the same for every particle), then at each particle's foot
    emit_particles(draws, cos_angle, sin_angle, centre_at(cfg, state, np.zeros(1)), *args, False, feet, *finish)
    emit_particles(draws, cos_angle, sin_angle, centre_at(cfg, state, feet), *args, True, feet, *finish)


def _ground_args(ground: Ground | None) -> tuple[F64, F64, float, F64]:
    """(heights, origin, spacing, position) of the ground for the kernels; a flat dummy without one."""
    if ground is None:
        return _NO_GROUND
    field = ground.field
    position = np.zeros(3) if ground.transform is None else np.asarray(ground.transform.position, dtype=np.float64)
    return field.heights, np.asarray(field.origin, dtype=np.float64), float(field.spacing), position


_NO_GROUND = (np.zeros((2, 2)), np.zeros(2), 1.0, np.zeros(3))


def _update_wind(cfg: DustDevilConfig, state: DustDevilState) -> WindField:
    """The step's wind field (2.1): the last step's field object reset to the new instant when the grid has the
    same resolution (its arrays are reused: no allocation and page faults per step), else a new one."""
    wind = state.wind
    if isinstance(wind, WindField) and wind.resolution == tuple(cfg.grid_resolution):
        wind.reset(cfg.field_size, state.field_time, state.centre_rotation, cfg.wind_scale)
    else:
        state.wind = wind = WindField(cfg.grid_resolution, cfg.field_size, state.field_time,
                                      state.centre_rotation, cfg.wind_scale)
    return wind


def _velocity(cfg: DustDevilConfig, wind: WindField, size: F64, local: F64, h: float) -> F64:
    """Field-space wind (m/s) a particle moves with over a substep ``h``: the looked-up vector (euler, 2.1), or
    the one looked up at the half-step point (midpoint)."""
    v = wind.sample(to_unit(local, size), cfg.lookup)
    if cfg.integrator == "midpoint":
        v = wind.sample(to_unit(local + 0.5 * h * v, size), cfg.lookup)
    return v


def _advance(cfg: DustDevilConfig, state: DustDevilState, transform: Transform, ground: Ground | None,
             rngs: tuple[np.random.Generator, np.random.Generator], dt: float) -> None:
    """One step of the field clock, the centre-line rotation and the particles."""
    emit_rng, rotate_rng = rngs
    state.steps += 1
    state.field_time = float(np.float64(state.field_time) + cfg.time_speed * dt)
    if state.steps % rotation_steps(cfg, dt) == 0:
        rotate_centre_line(cfg, state, rotate_rng)
    wind = _update_wind(cfg, state)
    size = np.asarray(cfg.field_size)
    h = dt / cfg.substeps
    terrain = ground is not None and cfg.terrain_interaction
    if USE_KERNELS and _kernel_case(transform, ground if terrain else None):
        dead = _advance_kernel(cfg, state, transform, ground if terrain else None, wind, h, dt)
        emit(cfg, state, dead, transform, ground, emit_rng)
        return
    for _ in range(cfg.substeps):
        v = to_world(transform, _velocity(cfg, wind, size, state.positions, h), direction=True)
        world = to_world(transform, state.positions)
        if terrain:
            _, _, world, depth = slope_wind(world, v, h, ground)
            below = depth > 0.0
            if below.any():  # particles never end below the terrain
                world[below] += depth[below, None] * ground.up()
        else:
            world += v * h
        state.positions = to_local(transform, world)
    state.ages += dt
    u = to_unit(state.positions, size)
    out_of_box = (u < 0.0) | (u > 1.0)
    outside = out_of_box[:, 0] | out_of_box[:, 1] | out_of_box[:, 2]  # np.any(axis=1) is slow over 3 columns
    dead = np.flatnonzero(outside | (state.ages >= state.lifetimes))
    emit(cfg, state, dead, transform, ground, emit_rng)


USE_KERNELS = True  # the compiled particle step (kernels.py) where it applies; False: numpy only (tests compare)


def _kernel_case(transform: Transform, ground: Ground | None) -> bool:
    """Whether the compiled step applies: the box is not rotated or scaled, the terrain (if any) not rotated."""
    if not (quat_is_identity(transform.rotation) and np.all(transform.scale == 1.0)):
        return False
    return ground is None or ground.transform is None or quat_is_identity(ground.transform.rotation)


def _advance_kernel(cfg: DustDevilConfig, state: DustDevilState, transform: Transform, ground: Ground | None,
                    wind: WindField, h: float, dt: float) -> NDArray[np.intp]:
    """The particles' part of :func:`_advance` as one compiled pass (kernels.advance_particles, the same bits);
    returns the particles to emit again."""
    from systems.dust_devil.kernels import advance_particles

    positions = np.ascontiguousarray(state.positions, dtype=np.float64)
    ages = np.ascontiguousarray(state.ages, dtype=np.float64)
    dead = np.empty(len(positions), dtype=np.bool_)
    heights, origin, spacing, ground_position = _ground_args(ground)
    wind.evaluated += advance_particles(
        positions, ages, np.ascontiguousarray(state.lifetimes, dtype=np.float64), dead, wind._flat, wind._known,
        wind.dims.astype(np.int64), wind.kernel_args(), cfg.lookup == "trilinear", cfg.integrator == "midpoint",
        int(cfg.substeps), float(h), float(dt), np.asarray(transform.position, dtype=np.float64),
        ground is not None, heights, origin, spacing, ground_position)
    state.positions, state.ages = positions, ages
    return np.flatnonzero(dead)


def step(cfg: DustDevilConfig, state: DustDevilState, transform: Transform, ground: Ground | None,
         emit_rng: np.random.Generator, rotate_rng: np.random.Generator, dt: float) -> None:
    """One fixed step; the first one emits every particle (staggered ages) and runs ``prewarm_time``."""
    if not state.started:
        state.started = True
        n = cfg.particle_count
        state.positions = np.zeros((n, 3))
        state.ages = np.zeros(n)
        state.lifetimes = np.ones(n)
        emit(cfg, state, np.arange(n), transform, ground, emit_rng)
        state.ages = state.lifetimes * emit_rng.random(n)  # steady re-emission from the start
        for _ in range(int(round(cfg.prewarm_time / dt))):
            _advance(cfg, state, transform, ground, (emit_rng, rotate_rng), dt)
    _advance(cfg, state, transform, ground, (emit_rng, rotate_rng), dt)


def drag(state: DustDevilState, transform: Transform, delta: ArrayLike, tick: int, interactive: bool = True) -> F64:
    """Section 4: add the dragged distance to the field space's position; particles (stored in field space)
    move with it.  ``interactive`` marks a user's drag (PBVR then uses ``drag_repeats``).  Returns the new
    position."""
    delta = np.asarray(delta, dtype=np.float64)
    if delta.shape != (3,) or not np.all(np.isfinite(delta)):
        raise ValueError(f"drag delta must be 3 finite numbers (world x, y, z), got {delta.tolist()}")
    transform.position = transform.position + delta
    if interactive:
        state.last_drag_tick = int(tick)
    return transform.position.copy()


def world_positions(state: DustDevilState, transform: Transform) -> F64:
    """Particle positions in world space (N, 3)."""
    return to_world(transform, state.positions)


def marker_points(cfg: DustDevilConfig, transform: Transform) -> F64:
    """World positions (9, 3) of the field box's 8 corners and its centre (the red spheres of section 4)."""
    sx, sy, sz = cfg.field_size
    corners = np.array([[x, y, z] for y in (0.0, sy) for z in (-0.5 * sz, 0.5 * sz) for x in (-0.5 * sx, 0.5 * sx)])
    local = np.vstack([corners, [[0.0, 0.5 * sy, 0.0]]])
    return transform.to_world(local)
