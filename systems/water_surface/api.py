"""What scripts use: the plugin's commands (``ctx.call("rigid_body.apply_impulse", ...)``) and two scripts.

Commands (``target`` defaults to the calling script's entity; for the water ones, to the first water surface):

* ``rigid_body.apply_impulse(impulse, point=None, target=None)``: an impulse J (N·s) at a world point, applied at
  the body's next step (at its centre of mass when no point is given).
* ``rigid_body.apply_force(force, point=None, target=None)``: a force (N) for the next step only.
* ``rigid_body.set_velocity(velocity=None, angular_velocity=None, target=None)``.
* ``water_surface.splash(point, height=0.1, target=None)``: push the water down by ``height`` metres at a point.
* ``water_surface.height_at(point, target=None)`` → the world height of the water surface there.
"""

from __future__ import annotations

import numpy as np
from pydantic import Field

from components.water_surface import RigidBody, RigidBodyState, WaterState
from engine.builtin import entity_ref
from engine.config import ConfigModel, Vec3
from engine.exact import length
from engine.registry import RegistryError
from engine.script import Script, script
from engine.spatial import Transform, cross
from engine.world import World
from systems.water_surface.simulate import add_impulse, add_splash, surface_height

__all__ = ["COMMANDS", "Glide", "SCRIPTS", "Tow"]


def _vec(value, name: str) -> np.ndarray:
    array = np.asarray(value, dtype=np.float64)
    if array.shape != (3,) or not np.all(np.isfinite(array)):
        raise ValueError(f"{name} must be 3 finite numbers (x, y, z), got {value!r}")
    return array


def _body(world: World, entity: int, target: int | str | None) -> int:
    target = entity if target is None else entity_ref(world, target, "target")
    if not world.has(target, RigidBodyState, Transform):
        raise RegistryError(f"entity {target} has no RigidBody (the rigid_body commands act on rigid bodies)")
    return target


def _water(world: World, target: int | None) -> int:
    if target is not None:
        found = entity_ref(world, target, "target")
        if not world.has(found, WaterState):
            raise RegistryError(f"entity {target} has no WaterSurface")
        return found
    found = world.query(WaterState)
    if not found:
        raise RegistryError("there is no WaterSurface in this world")
    return found[0][0]


def apply_impulse(world: World, entity: int, impulse, point=None, target: int | str | None = None) -> None:
    body = _body(world, entity, target)
    add_impulse(world, body, _vec(impulse, "impulse"), None if point is None else _vec(point, "point"))


def apply_force(world: World, entity: int, force, point=None, target: int | str | None = None) -> None:
    body = _body(world, entity, target)
    state = world.get(body, RigidBodyState)
    f = _vec(force, "force")
    state.force = state.force + f
    if point is not None:
        state.torque = state.torque + cross(_vec(point, "point") - world.get(body, Transform).position, f)


def set_velocity(world: World, entity: int, velocity=None, angular_velocity=None, target: int | str | None = None) -> None:
    state = world.get(_body(world, entity, target), RigidBodyState)
    if velocity is not None:
        state.velocity = _vec(velocity, "velocity")
    if angular_velocity is not None:
        state.angular_velocity = _vec(angular_velocity, "angular_velocity")


def splash(world: World, entity: int, point, height: float = 0.1, target: int | str | None = None) -> None:
    add_splash(world, _water(world, target), _vec(point, "point"), float(height))


def height_at(world: World, entity: int, point, target: int | str | None = None) -> float:
    return float(surface_height(world, _water(world, target), _vec(point, "point")[None])[0])


COMMANDS = {
    "rigid_body.apply_impulse": apply_impulse,
    "rigid_body.apply_force": apply_force,
    "rigid_body.set_velocity": set_velocity,
    "water_surface.splash": splash,
    "water_surface.height_at": height_at,
}


@script("water_surface.glide")
class Glide(Script):
    """Moves the entity at a constant velocity and turns back after ``distance`` metres (the paper's moving box;
    use it on kinematic bodies or plain colliders)."""

    class Params(ConfigModel):
        velocity: Vec3 = Field((1.0, 0.0, 0.0), description="Velocity in m/s (world).")
        distance: float = Field(4.0, ge=0.0, le=1e6, description="Metres before turning back (0: never).")

    def on_start(self) -> None:
        self.travelled = 0.0
        self.direction = 1.0

    def on_update(self, dt: float) -> None:
        t = self.ctx.get(Transform)
        step = np.array(self.params.velocity) * (self.direction * dt)
        t.position = t.position + step
        self.travelled += float(length(step))
        if self.params.distance > 0.0 and self.travelled >= self.params.distance:
            self.direction, self.travelled = -self.direction, 0.0


@script("water_surface.tow")
class Tow(Script):
    """Tows a floating rigid body: a horizontal force steering its velocity towards ``velocity`` (a boat's
    propeller), reversing after ``distance`` metres."""

    class Params(ConfigModel):
        velocity: Vec3 = Field((1.0, 0.0, 0.0), description="Target horizontal velocity in m/s.")
        response: float = Field(2.0, gt=0.0, le=100.0, description="How fast the speed is reached, per second.")
        distance: float = Field(6.0, ge=0.0, le=1e6, description="Metres before turning back (0: never).")

    def on_start(self) -> None:
        self.travelled = 0.0
        self.direction = 1.0

    def on_update(self, dt: float) -> None:
        state = self.ctx.get(RigidBodyState)
        mass = self.ctx.get(RigidBody).mass
        target = np.array(self.params.velocity) * self.direction
        error = target - state.velocity
        error[1] = 0.0
        self.ctx.call("rigid_body.apply_force", force=mass * self.params.response * error)
        self.travelled += float(length(state.velocity[[0, 2]])) * dt
        if self.params.distance > 0.0 and self.travelled >= self.params.distance:
            self.direction, self.travelled = -self.direction, 0.0


SCRIPTS = [Glide, Tow]
