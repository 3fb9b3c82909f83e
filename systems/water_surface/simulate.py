"""The water plugin's systems and commands: they gather the world's components into arrays, call the pure-numpy
steps (``surface.step_water``, ``bodies.integrate``) and write the results back.

Simulation stage, every fixed tick:
1. ``water_surface.impacts``: Impact events → impulses on rigid bodies, dents in the water.
2. ``water_surface.bodies``: rigid bodies (gravity, buoyancy against the water at t, drag, pool contacts).
3. ``water_surface.waves``: every WaterSurface steps with the bodies at their new transforms (the outline
   method makes the waves), then its height-field Collider follows the water.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from components.water_surface import (RigidBody, RigidBodyState, WaterState, WaterSurface, check_stability)
from engine.collider import Collider
from engine.events import EventReader
from engine.exact import length
from engine.impacts import Impact
from engine.spatial import Transform, cross
from engine.world import World
from systems.water_surface import kernels as K
from systems.water_surface.bodies import BodyArrays, apply_impulses, integrate
from systems.water_surface.geometry import BOX, SPHERE, Bodies, Grid, bilinear, empty_bodies
from systems.water_surface.surface import step_water

__all__ = ["ImpactCursor", "bodies_system", "gather_wave_bodies", "impacts_system", "startup_check",
           "surface_height", "water_grid", "waves_system"]


@dataclass
class ImpactCursor:
    """World resource (part of the state): how far the water plugin has read the Impact events."""

    cursor: int = 0


def setup_world(world: World) -> None:
    world.insert_resource(ImpactCursor(), state=True)


def water_grid(cfg: WaterSurface, state: WaterState, transform: Transform) -> Grid:
    """The water's grid in world space (the entity's position places it; the grid stays axis-aligned)."""
    p = transform.position
    nz, nx = state.heights.shape
    return Grid(nx, nz, cfg.spacing, float(p[0] + state.origin[0]), float(p[2] + state.origin[1]), float(p[1]))


def gather_wave_bodies(world: World) -> Bodies:
    """Every solid box or sphere Collider with a Transform (rigid bodies, scripted props): they cut the water.
    Their world sizes and rotation matrices come from one kernel (``kernels.wave_bodies``, the bits of
    ``quat_to_matrix`` and of ``half_extents × |scale|``, ``radius × max |scale|``)."""
    rows = [(e, t, c) for e, (t, c) in world.query(Transform, Collider)
            if c.shape in ("box", "sphere") and not c.is_trigger]
    if not rows:
        return empty_bodies()
    n = len(rows)
    table = np.concatenate([t.position for _, t, _ in rows] + [t.rotation for _, t, _ in rows]
                           + [t.scale for _, t, _ in rows] + [c.half_extents for _, _, c in rows], dtype=np.float64)
    out = K.wave_bodies(table, np.array([c.radius for _, _, c in rows], np.float64), K.QUAT_TERMS)
    return Bodies(np.array([e for e, _, _ in rows], np.int64),
                  np.array([BOX if c.shape == "box" else SPHERE for _, _, c in rows], np.int8),
                  out[:3 * n].reshape(n, 3), out[3 * n:4 * n], out[4 * n:7 * n].reshape(n, 3),
                  out[7 * n:].reshape(n, 3, 3))


def _waters(world: World) -> list:
    return world.query(Transform, WaterSurface, WaterState)


# ---------------------------------------------------------------------------------------------- systems
def startup_check(world: World, dt: float) -> None:
    """Startup: refuse a water surface that the scene's fixed step makes unstable, and a RigidBody whose Collider
    was replaced by a different shape."""
    for entity, (_, cfg, _) in _waters(world):
        check_stability(cfg.wave_speed, cfg.spacing, dt, f"entity {entity} WaterSurface")
    for entity, (cfg, collider) in world.query(RigidBody, Collider):
        if collider.shape != cfg.shape:
            raise ValueError(f"entity {entity}: RigidBody shape '{cfg.shape}' but its Collider is a "
                             f"'{collider.shape}'; a RigidBody makes its own Collider, remove the [Collider] table")


def impacts_system(world: World, dt: float) -> None:
    """Impact events: an impulse at a point on a rigid body; a dent where something strikes the water."""
    cursor = world.resource(ImpactCursor)
    reader = EventReader(world.events, Impact, cursor.cursor)
    for event in reader.read():
        if world.has(event.target, RigidBodyState, Transform):
            add_impulse(world, event.target, np.array(event.impulse, float), np.array(event.point, float))
        elif world.has(event.target, WaterState, WaterSurface):
            cfg = world.get(event.target, WaterSurface)
            radius = max(cfg.disturbance_radius, cfg.spacing)
            volume = float(length(event.impulse)) / (cfg.water_density * cfg.wave_speed)  # J = ρ·V·c
            add_splash(world, event.target, np.array(event.point, float), volume / (np.pi * radius * radius))
    cursor.cursor = reader.cursor


def add_impulse(world: World, entity: int, impulse: np.ndarray, point: np.ndarray | None = None) -> None:
    """Queue an impulse J (N·s) at a world point (the centre of mass when None) for the body's next step."""
    state = world.get(entity, RigidBodyState)
    state.impulse = state.impulse + impulse
    if point is not None:
        arm = point - world.get(entity, Transform).position
        state.angular_impulse = state.angular_impulse + cross(arm, impulse)


def add_splash(world: World, water: int, point: np.ndarray, height: float) -> None:
    """Queue a dent of ``height`` metres in the water at world ``point`` (applied at the next step)."""
    cfg, state, t = world.get(water, WaterSurface), world.get(water, WaterState), world.get(water, Transform)
    uv = water_grid(cfg, state, t).to_uv(point[[0, 2]])
    state.splashes = [*state.splashes, (float(uv[0]), float(uv[1]), float(height))]


def _gather_dynamic(world: World, dt: float):
    rows = []
    for entity, (t, cfg, state, collider) in world.query(Transform, RigidBody, RigidBodyState, Collider):
        if cfg.kinematic:  # moved by scripts: its velocity is what they did to it
            if state.previous_position is not None:
                state.velocity = (t.position - state.previous_position) / dt
            state.previous_position = t.position.copy()
            state.impulse, state.angular_impulse = np.zeros(3), np.zeros(3)
            continue
        rows.append((entity, t, cfg, state, collider))
    return rows


def bodies_system(world: World, dt: float) -> None:
    """Rigid bodies: pending impulses, then per water they float on (and for those over none) one compiled call
    for the forces, the integration and the pool's contacts (``bodies.integrate``)."""
    rows = _gather_dynamic(world, dt)
    if not rows:
        return
    _, transforms, configs, states, colliders = zip(*rows)
    scale = np.abs(np.array([t.scale for t in transforms]))
    constants = np.array([(c.mass, c.gravity, c.linear_damping, c.angular_damping, c.restitution, c.friction,
                           c.max_speed, c.max_angular_speed) for c in configs]).T.copy()  # contiguous rows
    arrays = BodyArrays(
        shapes=np.array([BOX if c.shape == "box" else SPHERE for c in colliders], np.int8),
        half=np.array([c.half_extents for c in colliders]) * scale,
        radius=np.array([c.radius for c in colliders]) * scale.max(axis=1),
        mass=constants[0], position=np.array([t.position for t in transforms]),
        rotation=np.array([t.rotation for t in transforms]),
        velocity=np.array([s.velocity for s in states]), spin=np.array([s.angular_velocity for s in states]),
        force=np.array([s.force for s in states]), torque=np.array([s.torque for s in states]),
        gravity=constants[1], linear_damping=constants[2], angular_damping=constants[3],
        restitution=constants[4], friction=constants[5], max_speed=constants[6], max_spin=constants[7],
    )
    apply_impulses(arrays, np.array([s.impulse for s in states]), np.array([s.angular_impulse for s in states]))
    owner = -np.ones(len(rows), np.int64)
    submerged = np.zeros(len(rows))
    waters = _waters(world)
    for w, (_, (t, cfg, state)) in enumerate(waters):  # first water (lowest id) under a body carries it
        grid = water_grid(cfg, state, t)
        over = grid.inside(grid.to_uv(arrays.position[:, ::2])) & (owner < 0)
        owner[over] = w
    for w in range(-1, len(waters)):
        index = np.flatnonzero(owner == w)
        if len(index) == 0:
            continue
        whole = len(index) == len(rows)  # every body in the same place: no need to split the arrays
        group = arrays if whole else _take(arrays, index)
        if w < 0:
            integrate(group, dt, None)
        else:
            _, (t, cfg, state) = waters[w]
            grid = water_grid(cfg, state, t)
            submerged[index] = integrate(group, dt, (state.heights, state.previous, grid), cfg.linear_drag,
                                         cfg.angular_drag, cfg.water_density, floor=grid.y0 - cfg.depth)
        if not whole:
            _put(arrays, index, group)
    # write back: rows of fresh arrays (one copy each, not one per body)
    positions, rotations = list(arrays.position.copy()), list(arrays.rotation.copy())
    velocities, spins = list(arrays.velocity.copy()), list(arrays.spin.copy())
    zeros = list(np.zeros((4 * len(rows), 3)))
    volumes = submerged.tolist()
    for b, (t, state) in enumerate(zip(transforms, states)):
        t.position, t.rotation = positions[b], rotations[b]
        state.velocity, state.angular_velocity = velocities[b], spins[b]
        state.impulse, state.angular_impulse, state.force, state.torque = zeros[4 * b:4 * b + 4]
        state.submerged_volume = volumes[b]


_FIELDS = ("shapes", "half", "radius", "mass", "position", "rotation", "velocity", "spin", "force", "torque",
           "gravity", "linear_damping", "angular_damping", "restitution", "friction", "max_speed", "max_spin")


def _take(arrays: BodyArrays, index: np.ndarray) -> BodyArrays:
    return BodyArrays(**{name: getattr(arrays, name)[index] for name in _FIELDS})


def _put(arrays: BodyArrays, index: np.ndarray, group: BodyArrays) -> None:
    for name in ("position", "rotation", "velocity", "spin"):
        getattr(arrays, name)[index] = getattr(group, name)


def waves_system(world: World, dt: float) -> None:
    """Every water surface: one step of the paper's scheme with the bodies at their new transforms."""
    waters = _waters(world)
    if not waters:
        return
    bodies = gather_wave_bodies(world)
    for entity, (t, cfg, state) in waters:
        check_stability(cfg.wave_speed, cfg.spacing, dt, f"entity {entity} WaterSurface")
        rng = world.random.stream("water_surface", entity) if cfg.disturbance_rate > 0.0 else None
        step_water(state, cfg, water_grid(cfg, state, t), bodies, dt, rng, report=False)
        collider = world.try_get(entity, Collider)
        if collider is not None and collider.heightfield is not None:
            collider.heightfield.heights[...] = state.heights


def surface_height(world: World, water: int, points: np.ndarray) -> np.ndarray:
    """World y of the water surface above world points (N, 3) (the rest level outside the pool)."""
    cfg, state, t = world.get(water, WaterSurface), world.get(water, WaterState), world.get(water, Transform)
    grid = water_grid(cfg, state, t)
    uv = grid.to_uv(np.asarray(points, float)[:, [0, 2]])
    return grid.y0 + np.where(grid.inside(uv), bilinear(state.heights, uv), 0.0)
