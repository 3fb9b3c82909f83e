"""The ToonSmokeVolume step (seeds/002, figure 1), one phase per function (:data:`PHASES`, which the benchmark
times one by one):

1. :func:`update_obstacles` — solid cells from the volume's own sphere and other colliders;
2. :func:`velocity_step`, :func:`projection_step`, :func:`scalar_step` — stable fluids on the simulation grid (§3.1);
3. :func:`advect_particles` — the particles (§3.3);
4. :func:`upsample_step`, :func:`blob_step`, :func:`noise_step` — the display grid (§3.2), blobs (§3.3) and
   noise (§3.4);
5. :func:`mesh_step` — the isosurface at D_iso (§3.5).

Phases 1–3 (:data:`SIMULATION_PHASES`) advance the state; 4 and 5 derive what is drawn from it and feed nothing
back: the display grid is rebuilt from ρ, the particles and the fixed noise every time.  So the systems split
them by rate: ``toon_smoke.simulate`` runs 1–3 on every fixed tick (simulation stage), ``toon_smoke.display``
runs 4–5 once per frame, after the frame's ticks (frame-update stage), and only when a tick ran since it last
did.  When the frame rate is below the tick rate (three ticks a frame at 20 fps) the display work is done once
instead of three times, and the picture is the same: it shows the state after the frame's last tick.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from components.toon_smoke import SourceState, ToonSmokeState, ToonSmokeVolumeConfig
from engine import exact
from engine.collider import Collider
from engine.exact import length
from engine.heightfield import HeightField
from engine.spatial import Transform, quat_conjugate, quat_rotate
from engine.world import World
from systems.toon_smoke import fluid, poisson
from systems.toon_smoke.display import blob_axes, extract_isosurface, noise_factor, splat_blobs
from systems.toon_smoke.grid import Geometry, trilinear_points, upsample_linear

_UP = np.array([0.0, 1.0, 0.0])


# ------------------------------------------------------------------------------------------------ creation
def new_state(cfg: ToonSmokeVolumeConfig, rng: np.random.Generator) -> ToonSmokeState:
    """Zero fluid, particles at random positions (§3.3), the noise seed drawn from the entity's stream."""
    nx, ny, nz = cfg.simulation_resolution
    f32 = np.float32
    geo = geometry_for(cfg)
    state = ToonSmokeState(
        u=np.zeros((nx + 1, ny, nz), f32), v=np.zeros((nx, ny + 1, nz), f32), w=np.zeros((nx, ny, nz + 1), f32),
        density=np.zeros((nx, ny, nz), f32), temperature=np.zeros((nx, ny, nz), f32),
        pressure=np.zeros((nx, ny, nz), f32), expansion=np.zeros((nx, ny, nz), f32),
        particles=np.zeros((cfg.particle_count, 3)), particle_age=np.zeros(cfg.particle_count),
        sources=[SourceState.from_config(s) for s in cfg.sources],
        noise_seed=int(rng.integers(0, 2**31 - 1)),
    )
    state.geometry = geo
    everyone = np.arange(cfg.particle_count)
    state.particles[:] = spawn_positions(cfg, state, rng, len(everyone))
    if cfg.particle_lifetime > 0.0:
        state.particle_age[:] = rng.uniform(0.0, cfg.particle_lifetime, cfg.particle_count)
    return state


def geometry_for(cfg: ToonSmokeVolumeConfig) -> Geometry:
    return Geometry.build(tuple(cfg.simulation_resolution), cfg.display_factor, cfg.extent)


def _geometry(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> Geometry:
    if state.geometry is None:
        state.geometry = geometry_for(cfg)
    return state.geometry


def time_step(cfg: ToonSmokeVolumeConfig, dt: float) -> float:
    return float(cfg.time_step) if cfg.time_step is not None else float(dt)


# ----------------------------------------------------------------------------------------------- obstacles
def update_obstacles(world: World | None, entity: int, transform: Transform, cfg: ToonSmokeVolumeConfig,
                     state: ToonSmokeState) -> None:
    """Solid cells on both grids: the volume's sphere obstacle and, optionally, other entities' colliders.

    Masks and the multigrid hierarchy are rebuilt only when an overlapping collider moved, or the volume moved
    relative to the colliders it overlaps (the sphere obstacle lives in the volume's own frame, so a volume that
    moves with no collider in reach keeps its masks).
    """
    geo = _geometry(cfg, state)
    colliders = _overlapping_colliders(world, entity, transform, cfg) if world is not None else []
    placement = (transform.position.tobytes(), transform.rotation.tobytes()) if colliders else ()
    key = (placement, cfg.obstacle_radius, tuple(cfg.obstacle_center),
           tuple((e, t.position.tobytes(), t.rotation.tobytes(), t.scale.tobytes(), id(c), c.shape, c.radius,
                  c.half_extents.tobytes(), c.offset) for e, t, c in colliders))
    if state.solid is not None and state.solid_key == key:
        return
    state.solid = _solid_mask(geo.local_centres(), transform, cfg, colliders)
    state.display_solid = _solid_mask(geo.local_display_centres(), transform, cfg, colliders)
    state.hierarchy = poisson.build_hierarchy(state.solid, cfg.open_flags)
    state.solid_key = key
    for field_ in (state.density, state.temperature, state.pressure):
        field_[state.solid] = 0.0


def _overlapping_colliders(world: World, entity: int, transform: Transform, cfg: ToonSmokeVolumeConfig) -> list:
    """Colliders that may reach into the volume (a cheap bounding test per collider entity, every step).

    Lengths are √(d·d) summed in order, as engine.exact's ``length``, in Python floats (the same IEEE operations on
    the float64 positions, so the same bits, without a numpy call per product)."""
    if not cfg.collide_with_colliders:
        return []
    reach = 0.5 * _length(*(float(e) for e in cfg.extent))
    px, py, pz = transform.position.tolist()
    found = []
    for other, (t, collider) in world.query(Transform, Collider):
        if other == entity or collider.is_trigger:
            continue
        shape = collider.shape
        if shape == "sphere" or shape == "box":
            qx, qy, qz = t.position.tolist()
            gap = _length(qx - px, qy - py, qz - pz) - reach
            sx, sy, sz = t.scale.tolist()
            if shape == "sphere" and gap > collider.radius * _max_abs(sx, sy, sz):
                continue
            if shape == "box":
                hx, hy, hz = collider.half_extents.tolist()
                if gap > _length(hx * sx, hy * sy, hz * sz):
                    continue
        if shape == "heightfield":
            fx, fy, fz = t.position.tolist()
            if not _reaches_up_to(collider.heightfield, fy, py - reach, px - fx, pz - fz):
                continue
        found.append((other, t, collider))
    return found


def _reaches_up_to(field: HeightField, base: float, bottom: float, x: float, z: float) -> bool:
    """Whether not bottom > base + max(heights) (so a NaN reaches), reading one sample first: the one nearest
    (x, z) in the field's unrotated frame, under a volume that sits on the ground.  Rounding is monotonic, so
    bottom ≤ base + h for one sample h means bottom ≤ base + max too; only when that sample lies below does the
    whole field's max decide, as before."""
    heights = field.heights
    rows, cols = heights.shape
    col, row = ((x - float(field.origin[0])) / field.spacing, (z - float(field.origin[1])) / field.spacing)
    col = min(max(int(col + 0.5), 0), cols - 1) if math.isfinite(col) else 0
    row = min(max(int(row + 0.5), 0), rows - 1) if math.isfinite(row) else 0
    if not bottom > base + float(heights[row, col]):
        return True
    return not bottom > base + float(heights.max())


def _overlapping_colliders_numpy(world: World, entity: int, transform: Transform, cfg: ToonSmokeVolumeConfig
                                 ) -> list:
    """:func:`_overlapping_colliders` with engine.exact's ``length`` on numpy vectors (its reference)."""
    if not cfg.collide_with_colliders:
        return []
    extent = np.asarray(cfg.extent, float)
    reach = 0.5 * float(length(extent))
    found = []
    for other, (t, collider) in world.query(Transform, Collider):
        if other == entity or collider.is_trigger:
            continue
        d = t.position - transform.position
        gap = float(length(d)) - reach
        if collider.shape == "sphere" and gap > collider.radius * float(np.max(np.abs(t.scale))):
            continue
        if collider.shape == "box":
            e = collider.half_extents * t.scale
            if gap > float(length(e)):
                continue
        if collider.shape == "heightfield":
            top = t.position[1] + float(collider.heightfield.heights.max())
            if transform.position[1] - reach > top:
                continue
        found.append((other, t, collider))
    return found


def _length(x: float, y: float, z: float) -> float:
    """√((x·x + y·y) + z·z): engine.exact's ``length`` of one vector, in Python floats."""
    return math.sqrt(x * x + y * y + z * z)


def _max_abs(x: float, y: float, z: float) -> float:
    """max(|x|, |y|, |z|) with a NaN winning, as ``np.max(np.abs(v))``."""
    top = abs(x)
    for value in (abs(y), abs(z)):
        if value > top or value != value:
            top = value
    return top


def _solid_mask(centres, transform: Transform, cfg: ToonSmokeVolumeConfig, colliders: list) -> np.ndarray:
    """Cells (centres: the three broadcastable axes of local coordinates) inside the sphere obstacle or a collider.

    Height fields are tested compiled (:func:`systems.toon_smoke.kernels.heightfield_solid_kernel`, the same
    operations as ``Collider.signed_distance``); other shapes by the collider itself.  The same mask as
    :func:`_solid_mask_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import heightfield_solid_kernel

    x, y, z = np.broadcast_arrays(*centres)
    solid = np.zeros(x.shape, bool)
    if cfg.obstacle_radius > 0.0:
        c = cfg.obstacle_center
        solid |= (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 < cfg.obstacle_radius ** 2
    world_points = None
    for _, t, collider in colliders:
        if collider.shape == "heightfield" and _finite(transform, t):
            field = collider.heightfield
            heightfield_solid_kernel(*(np.ascontiguousarray(c, np.float64).reshape(-1) for c in centres),
                                     transform.position, transform.rotation, t.position, t.rotation,
                                     field.heights, float(field.spacing), field.origin, solid)
            continue
        if world_points is None:
            local = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=-1)
            world_points = transform.position + quat_rotate(transform.rotation, local)
        solid |= (collider.signed_distance(world_points, t) < 0.0).reshape(x.shape)
    return solid


def _finite(*transforms: Transform) -> bool:
    return all(np.isfinite(t.position).all() and np.isfinite(t.rotation).all() for t in transforms)


def _solid_mask_numpy(centres, transform: Transform, cfg: ToonSmokeVolumeConfig, colliders: list) -> np.ndarray:
    """:func:`_solid_mask` with every collider's own ``signed_distance`` (its reference)."""
    x, y, z = np.broadcast_arrays(*centres)
    solid = np.zeros(x.shape, bool)
    if cfg.obstacle_radius > 0.0:
        c = cfg.obstacle_center
        solid |= (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 < cfg.obstacle_radius ** 2
    if colliders:
        local = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=-1)
        world_points = transform.position + quat_rotate(transform.rotation, local)
        for _, t, collider in colliders:
            solid |= (collider.signed_distance(world_points, t) < 0.0).reshape(x.shape)
    return solid


# ------------------------------------------------------------------------------------------------- fluid
def apply_sources(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, dt: float,
                  rng: np.random.Generator | None = None) -> None:
    """Each active source adds density and heat inside its sphere and imposes its velocity (plus its seeded jitter)
    there, in place."""
    geo = _geometry(cfg, state)
    for source in state.sources:
        if not source.active(state.time):
            continue
        p = source.position
        inside = geo.sphere_mask("c", p, source.radius)
        state.density += np.float32(source.density_rate * dt) * inside
        state.temperature += np.float32(source.temperature_rate * dt) * inside
        if source.radial_speed != 0.0:
            state.expansion += np.float32(3.0 * source.radial_speed / source.radius) * inside
        velocity = source.velocity
        if source.velocity_jitter > 0.0 and rng is not None:
            velocity = velocity + rng.uniform(-source.velocity_jitter, source.velocity_jitter, 3)
        impose_velocity(geo, state, p, source.radius, velocity)
    np.minimum(state.density, np.float32(cfg.density_limit), out=state.density)
    np.minimum(state.temperature, np.float32(cfg.temperature_limit), out=state.temperature)


def impose_velocity(geo: Geometry, state: ToonSmokeState, centre, radius: float, velocity) -> None:
    """Set the face velocities inside a sphere to ``velocity`` (a jet or a chimney's draught), in place."""
    for axis, comp in enumerate((state.u, state.v, state.w)):
        np.copyto(comp, np.float32(velocity[axis]), where=geo.sphere_mask("uvw"[axis], centre, radius))


def velocity_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, dt: float, up_local: np.ndarray,
                  rng: np.random.Generator | None = None) -> None:
    """Stam 1999 up to the projection, in the paper's order (seeds/002 §3.1: external forces, advection,
    diffusion, projection): add buoyancy (β·T − α·ρ along up) and vorticity confinement, impose the sources,
    self-advect u, diffuse (ν), and zero the normal velocity on walls and solids."""
    geo = _geometry(cfg, state)
    h = geo.h
    fluid.body_forces(state.u, state.v, state.w, state.temperature, state.density, cfg.buoyancy, cfg.smoke_weight,
                      up_local, cfg.vorticity_confinement, h, dt)
    apply_sources(cfg, state, dt, rng)
    state.u, state.v, state.w = fluid.advect_velocity(geo, state.u, state.v, state.w, dt)
    if cfg.viscosity > 0.0:
        state.u, state.v, state.w = (fluid.diffuse(c, cfg.viscosity, dt, h, cfg.diffusion_iterations)
                                     for c in (state.u, state.v, state.w))
    fluid.enforce_solid_faces(state.u, state.v, state.w, state.hierarchy)


def projection_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """The pressure projection (MGPCG), with the puffs' and blasts' divergence sources; records the divergence
    before and after."""
    target = state.expansion if state.expansion.any() else None
    state.pressure, state.divergence_before, state.divergence_after, state.pressure_iterations_used = fluid.project(
        state.u, state.v, state.w, _geometry(cfg, state).h, state.hierarchy, state.pressure,
        cfg.pressure_tolerance, cfg.pressure_iterations, target)
    if target is not None:
        state.expansion = np.zeros_like(state.expansion)


def scalar_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, dt: float) -> None:
    """Advect ρ and T with the divergence-free velocity, diffuse (κ), fade, clear solids, clamp to the limits."""
    geo = _geometry(cfg, state)
    density, temperature = fluid.advect_scalars(geo, [state.density, state.temperature], state.u, state.v,
                                                state.w, dt)
    if cfg.diffusion > 0.0:
        density = fluid.diffuse(density, cfg.diffusion, dt, geo.h, cfg.diffusion_iterations)
        temperature = fluid.diffuse(temperature, cfg.diffusion, dt, geo.h, cfg.diffusion_iterations)
    state.density, state.temperature = fade_and_clamp(cfg, state, density, temperature, dt)


def fade_and_clamp(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, density: np.ndarray,
                   temperature: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Fade ρ and T (dissipation, cooling), clear the solid cells, clamp to the limits: in place on the new fields,
    one compiled pass (:func:`systems.toon_smoke.kernels.fade_and_clamp_kernel`); the same bits as
    :func:`fade_and_clamp_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import fade_and_clamp_kernel

    weight = state.hierarchy.fluid_weight if state.hierarchy is not None else None
    fade_and_clamp_kernel(density, temperature, cfg.density_dissipation > 0.0,
                          np.float32(1.0 / (1.0 + cfg.density_dissipation * dt)), cfg.temperature_cooling > 0.0,
                          np.float32(1.0 / (1.0 + cfg.temperature_cooling * dt)),
                          density if weight is None else weight, weight is not None,
                          np.float32(cfg.density_limit), np.float32(cfg.temperature_limit))
    return density, temperature


def fade_and_clamp_numpy(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, density: np.ndarray,
                         temperature: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fade_and_clamp` in numpy (its reference); returns new arrays."""
    if cfg.density_dissipation > 0.0:
        density *= np.float32(1.0 / (1.0 + cfg.density_dissipation * dt))
    if cfg.temperature_cooling > 0.0:
        temperature *= np.float32(1.0 / (1.0 + cfg.temperature_cooling * dt))
    fluid_cells = state.hierarchy.fluid_weight if state.hierarchy is not None else np.float32(1.0)
    return (np.minimum(density * fluid_cells, np.float32(cfg.density_limit)),
            np.minimum(temperature * fluid_cells, np.float32(cfg.temperature_limit)))


def fluid_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, dt: float, up_local: np.ndarray,
               rng: np.random.Generator | None = None) -> None:
    """One stable-fluids step (Stam 1999; seeds/002 §3.1): velocity, projection, scalars."""
    velocity_step(cfg, state, dt, up_local, rng)
    projection_step(cfg, state)
    scalar_step(cfg, state, dt)


# ------------------------------------------------------------------------------------------------ particles
def spawn_positions(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, rng: np.random.Generator, count: int
                    ) -> np.ndarray:
    """``count`` new particle positions (local metres): uniform in the box, or uniform in an active source."""
    if count == 0:
        return np.zeros((0, 3))
    extent = np.asarray(cfg.extent, float)
    active = [s for s in state.sources if s.active(state.time)]
    if cfg.particle_spawn == "sources" and active:
        which = rng.integers(0, len(active), count)
        centres = np.array([s.position for s in active])[which]
        radii = np.array([s.radius for s in active])[which]
        return np.clip(ball_points(rng, centres, radii, count), -0.5 * extent, 0.5 * extent)
    return (rng.random((count, 3)) - 0.5) * extent


def ball_points(rng: np.random.Generator, centres: np.ndarray, radii: np.ndarray | float, count: int) -> np.ndarray:
    """``count`` points uniform in balls of ``radii`` about ``centres`` (each broadcast over the points): a normal
    triple's direction, then a uniform's cube root for the distance (engine.exact's, the same bits everywhere)."""
    direction = rng.standard_normal((count, 3))
    direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), 1e-12)
    return centres + direction * (radii * exact.cbrt(rng.random(count)))[:, None]


def advect_particles(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, dt: float, rng: np.random.Generator
                     ) -> None:
    """Move particles with the flow (midpoint rule); rebirth those that left, entered a solid or grew old.

    The midpoint rule runs compiled (:func:`systems.toon_smoke.kernels.advect_particles_kernel`): the same bits as
    two queries of :class:`systems.toon_smoke.grid.MacSampler`, its numpy reference in the tests; so does the
    choice of who is reborn (:func:`rebirth`)."""
    geo = _geometry(cfg, state)
    p = state.particles
    if len(p) == 0:
        state.particle_velocity = np.zeros((0, 3))
        return
    from systems.toon_smoke.kernels import advect_particles_kernel, mac_velocity_kernel

    u, v, w = (np.ascontiguousarray(c, np.float32) for c in (state.u, state.v, state.w))
    half_extent, h = 0.5 * geo.extent, float(geo.h)
    p, velocity = advect_particles_kernel(np.ascontiguousarray(p, np.float64), u, v, w, half_extent, h, 0.5 * dt,
                                          float(dt))
    reborn, count = rebirth(cfg, state, p, dt)
    if count:
        p[reborn] = spawn_positions(cfg, state, rng, count)
        state.particle_age[reborn] = 0.0
        velocity[reborn] = mac_velocity_kernel(p[reborn], u, v, w, half_extent, h)
    state.particles = p
    state.particle_velocity = velocity  # the midpoint velocity stretches the blobs (figure 2)


def rebirth(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, p: np.ndarray, dt: float
            ) -> tuple[np.ndarray, int]:
    """Age the particles by ``dt`` (in place) and flag those to rebirth: outside the box, in a solid display cell,
    or as old as ``particle_lifetime``.  Returns (the flags, their count); one compiled pass
    (:func:`systems.toon_smoke.kernels.particle_rebirth_kernel`), the same flags and ages as
    :func:`rebirth_numpy`, its reference in the tests."""
    from systems.toon_smoke.kernels import particle_rebirth_kernel

    geo = _geometry(cfg, state)
    solid = state.display_solid
    reborn, count = particle_rebirth_kernel(p, state.particle_age, float(dt), 0.5 * geo.extent,
                                            _NO_SOLID if solid is None else solid, solid is not None,
                                            float(geo.h), geo.factor, float(cfg.particle_lifetime))
    return reborn, int(count)


_NO_SOLID = np.zeros((1, 1, 1), bool)


def rebirth_numpy(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, p: np.ndarray, dt: float
                  ) -> tuple[np.ndarray, int]:
    """:func:`rebirth` in numpy (its reference)."""
    geo = _geometry(cfg, state)
    state.particle_age += dt
    reborn = np.any(np.abs(p) > 0.5 * geo.extent, axis=1)
    if state.display_solid is not None and state.display_solid.any():
        reborn |= _nearest(state.display_solid, geo.to_cells(p) * geo.factor)
    if cfg.particle_lifetime > 0.0:
        reborn |= state.particle_age >= cfg.particle_lifetime
    return reborn, int(reborn.sum())


def _nearest(mask: np.ndarray, cells: np.ndarray) -> np.ndarray:
    index = np.clip(np.floor(cells).astype(np.intp), 0, np.array(mask.shape) - 1)
    return mask[index[:, 0], index[:, 1], index[:, 2]]


# ------------------------------------------------------------------------------------------------ display
def upsample_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """§3.2: copy the simulation density onto the display grid (trilinear upsampling)."""
    state.display_density = upsample_linear(state.density, _geometry(cfg, state).factor)


def blob_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """§3.3: particles where the display density exceeds D_p add their blobs."""
    state.blob_count = add_particle_blobs(cfg, state, state.display_density)


def noise_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """§3.4: multiply by the Perlin noise factor, clear solid cells, clamp to the density limit."""
    display = state.display_density
    display *= _masked_noise(cfg, state, _geometry(cfg, state))
    np.minimum(display, np.float32(cfg.density_limit), out=display)  # every term is ≥ 0 already


def _masked_noise(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, geo: Geometry) -> np.ndarray:
    """The noise factor of §3.4 (computed once: it depends on position alone), zeroed in solid display cells."""
    key = ("noise", state.noise_seed, state.solid_key)
    if state.noise_factor is None or state.noise_key != key:
        if state.noise_base is None:
            state.noise_base = noise_factor(geo, state.noise_seed, cfg.noise_scale, cfg.noise_strength,
                                            cfg.noise_octaves)
        factor = state.noise_base.copy()
        if state.display_solid is not None:
            factor[state.display_solid] = 0.0
        state.noise_factor, state.noise_key = factor, key
    return state.noise_factor


def add_particle_blobs(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState, display: np.ndarray) -> int:
    """Where the density at a particle exceeds D_p, splat its velocity-stretched ellipsoid (figure 2)."""
    geo = _geometry(cfg, state)
    if len(state.particles) == 0:
        return 0
    cells = geo.to_cells(state.particles) * geo.factor - 0.5  # display index space
    rho = trilinear_points(display.shape, cells.T).gather(display)
    active = rho > cfg.particle_density_threshold
    if not active.any():
        return 0
    vel = state.particle_velocity[active]
    speed = np.linalg.norm(vel, axis=1)
    direction = np.divide(vel, speed[:, None], out=np.tile([0.0, 1.0, 0.0], (len(vel), 1)),
                          where=speed[:, None] > 0)
    along, across = blob_axes(rho[active], speed, cfg.particle_density_threshold, cfg.blob_radius,
                              cfg.blob_radius_per_density, cfg.blob_radius_max, cfg.blob_stretch,
                              cfg.blob_stretch_max)
    cell = geo.h / geo.factor
    return splat_blobs(display, cells[active], direction, along / cell, across / cell, cfg.blob_density)


# --------------------------------------------------------------------------------------------------- mesh
def mesh_step(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """Re-mesh the display density at D_iso (§3.5)."""
    geo = _geometry(cfg, state)
    if state.display_density is None:
        return
    cell = geo.h / geo.factor
    origin = -0.5 * geo.extent + 0.5 * cell
    state.mesh_vertices, state.mesh_normals, state.mesh_faces = extract_isosurface(
        state.display_density, cfg.iso_density, cell, origin)
    state.mesh_version += 1


# ---------------------------------------------------------------------------------------------- the systems
@dataclass
class StepContext:
    """Everything one phase of one volume's step may use."""

    world: World | None
    entity: int
    transform: Transform
    cfg: ToonSmokeVolumeConfig
    state: ToonSmokeState
    dt: float
    rng: np.random.Generator


def _up_local(ctx: StepContext) -> np.ndarray:
    """World up in the volume's frame (read-only; kept per rotation: volumes rarely turn)."""
    key = ctx.transform.rotation.tobytes()
    up = _UP_LOCAL.get(key)
    if up is None:
        up = quat_rotate(quat_conjugate(ctx.transform.rotation), _UP)
        up.flags.writeable = False
        if len(_UP_LOCAL) >= 64:
            _UP_LOCAL.clear()
        _UP_LOCAL[key] = up
    return up


_UP_LOCAL: dict[bytes, np.ndarray] = {}


# The phases of one step, in order (seeds/002 figure 1); the benchmark times each one.  The simulation phases
# advance the state; the display phases derive the display grid from it (see the module docstring).
SIMULATION_PHASES: tuple[tuple[str, Callable[[StepContext], None]], ...] = (
    ("obstacles", lambda c: update_obstacles(c.world, c.entity, c.transform, c.cfg, c.state)),
    ("velocity (forces, sources, advect)", lambda c: velocity_step(c.cfg, c.state, c.dt, _up_local(c), c.rng)),
    ("pressure projection (MGPCG)", lambda c: projection_step(c.cfg, c.state)),
    ("density + temperature", lambda c: scalar_step(c.cfg, c.state, c.dt)),
    ("particles", lambda c: advect_particles(c.cfg, c.state, c.dt, c.rng)),
)
_DISPLAY: tuple[tuple[str, Callable[[ToonSmokeVolumeConfig, ToonSmokeState], None]], ...] = (
    ("upsample to display grid", upsample_step),
    ("density blobs", blob_step),
    ("noise", noise_step),
)
DISPLAY_PHASES: tuple[tuple[str, Callable[[StepContext], None]], ...] = tuple(
    (name, lambda c, fn=fn: fn(c.cfg, c.state)) for name, fn in _DISPLAY)
PHASES = SIMULATION_PHASES + DISPLAY_PHASES


def step_volume(world: World | None, entity: int, transform: Transform, cfg: ToonSmokeVolumeConfig,
                state: ToonSmokeState, dt: float, rng: np.random.Generator, display: bool = True) -> None:
    """One step of ``dt`` seconds for one volume: :data:`SIMULATION_PHASES`, then (``display``) the display grid
    (:data:`DISPLAY_PHASES`; the mesh is :func:`mesh_step`)."""
    ctx = StepContext(world, entity, transform, cfg, state, dt, rng)
    for _, phase in SIMULATION_PHASES:  # loop over the phases of the step
        phase(ctx)
    state.time += dt
    state.steps += 1
    if display:
        display_grid(cfg, state)


def display_grid(cfg: ToonSmokeVolumeConfig, state: ToonSmokeState) -> None:
    """Display density = noise × (upsampled ρ + particle blobs), clamped to [0, density_limit] (§3.2–3.4): the
    :data:`DISPLAY_PHASES` for the current state."""
    for _, phase in _DISPLAY:
        phase(cfg, state)


def simulate_system(world: World, dt: float) -> None:
    """Simulation stage: step every ToonSmokeVolume (ascending entity id); the display is derived per frame."""
    for entity, (transform, cfg, state) in world.query(Transform, ToonSmokeVolumeConfig, ToonSmokeState):
        step_volume(world, entity, transform, cfg, state, time_step(cfg, dt),
                    world.random.stream("toon_smoke", entity), display=False)


def display_system(world: World, dt: float) -> None:
    """Frame-update stage: the display grid and isosurface of every volume stepped (or reconfigured) since they
    were last derived."""
    for _, (cfg, state) in world.query(ToonSmokeVolumeConfig, ToonSmokeState):
        if state.display_step != state.steps and state.steps > 0:
            display_grid(cfg, state)
            mesh_step(cfg, state)
            state.display_step = state.steps
