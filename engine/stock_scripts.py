"""Small general-purpose scripts that ship with the engine (used by the sandbox scene).

They use only the public scripting API, like any game's scripts.
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field

from engine import exact
from engine.config import ConfigModel, Vec3
from engine.script import Script, script
from engine.spatial import Transform, quat_from_axis_angle, quat_mul, quat_normalize


@script("spin")
class Spin(Script):
    """Rotates the entity about an axis at a constant rate."""

    class Params(ConfigModel):
        speed: float = Field(90.0, ge=-3600.0, le=3600.0, description="Degrees per second.")
        axis: Vec3 = Field((0.0, 1.0, 0.0), description="Rotation axis (world).")

    def on_update(self, dt: float) -> None:
        if self.ctx.paused:
            return
        t = self.ctx.get(Transform)
        step = quat_from_axis_angle(np.array(self.params.axis), math.radians(self.params.speed) * dt)
        t.rotation = quat_normalize(quat_mul(step, t.rotation))


@script("bob")
class Bob(Script):
    """Moves the entity up and down on a sine wave (phase randomised per entity)."""

    class Params(ConfigModel):
        amplitude: float = Field(0.5, ge=0.0, le=100.0, description="Metres.")
        frequency: float = Field(0.5, gt=0.0, le=20.0, description="Hertz.")

    def on_start(self) -> None:
        self.base_y = float(self.ctx.get(Transform).position[1])
        self.phase = float(self.ctx.rng.uniform(0.0, 2.0 * math.pi))
        self.time = 0.0

    def on_update(self, dt: float) -> None:
        if self.ctx.paused:
            return
        self.time += dt
        y = self.base_y + self.params.amplitude * exact.sin_scalar(2.0 * math.pi * self.params.frequency * self.time
                                                           + self.phase)
        self.ctx.get(Transform).position[1] = y


@script("wasd_mover")
class WasdMover(Script):
    """Moves the entity on the ground plane with W, A, S, D (for the sandbox's player cube)."""

    class Params(ConfigModel):
        speed: float = Field(4.0, ge=0.0, le=100.0, description="Metres per second.")

    def on_update(self, dt: float) -> None:
        if self.ctx.paused:
            return
        inp = self.ctx.input
        move = np.array([inp.is_down("d") - inp.is_down("a"), 0.0, inp.is_down("s") - inp.is_down("w")], float)
        if move.any():
            self.ctx.get(Transform).position += move / exact.length(move) * self.params.speed * dt


@script("spawner")
class Spawner(Script):
    """Spawns short-lived copies of a small cube around the entity at random offsets."""

    class Params(ConfigModel):
        interval: float = Field(1.0, gt=0.0, le=60.0, description="Seconds between spawns.")
        lifetime: float = Field(3.0, gt=0.0, le=600.0, description="Seconds each spawned cube lives.")
        radius: float = Field(2.0, ge=0.0, le=100.0, description="Spawn radius in metres.")
        max_alive: int = Field(16, ge=1, le=1024, description="Cap on live spawned cubes.")

    def on_start(self) -> None:
        self.timer = 0.0
        self.clock = 0.0  # game seconds this script has run, pauses left out (the cubes' lifetimes count these)
        self.alive: list[tuple[int, float]] = []

    def on_update(self, dt: float) -> None:
        from engine.builtin import Name

        if self.ctx.paused:
            return
        self.timer += dt
        self.clock += dt
        now = self.clock
        expired = [e for e, t in self.alive if t <= now]
        for entity in expired:
            self.ctx.despawn(entity)
        self.alive = [(e, t) for e, t in self.alive if t > now]
        if self.timer >= self.params.interval and len(self.alive) < self.params.max_alive:
            self.timer -= self.params.interval
            origin = self.ctx.get(Transform).position
            offset = self.ctx.rng.uniform(-1.0, 1.0, 3) * np.array([1.0, 0.0, 1.0]) * self.params.radius
            pos = origin + offset + np.array([0.0, 0.5, 0.0])
            extra = self.spawn_components()
            entity = self.ctx.spawn(Name("spawned"), Transform(position=pos, scale=np.full(3, 0.3)), *extra)
            self.alive.append((entity, now + self.params.lifetime))

    def spawn_components(self) -> list:
        """Extra components for the spawned cubes (a mesh when the rendering core is loaded)."""
        from engine.registry import RegistryError

        try:
            return [self.ctx.call("render.mesh", shape="box", color=(0.9, 0.6, 0.2))]
        except RegistryError:
            return []


@script("lifetime")
class Lifetime(Script):
    """Despawns its entity after a number of seconds (effects that play once: puffs, bursts)."""

    class Params(ConfigModel):
        seconds: float = Field(3.0, gt=0.0, le=3600.0, description="Seconds before the entity is removed.")

    def on_start(self) -> None:
        self.left = self.params.seconds

    def on_update(self, dt: float) -> None:
        if self.ctx.paused:  # paused game: the effect it removes is frozen too
            return
        self.left -= dt
        if self.left <= 0.0:
            self.ctx.despawn()


@script("snap_to_ground")
class SnapToGround(Script):
    """Places the entity on the terrain once, at start (targets and props in hand-made scenes)."""

    class Params(ConfigModel):
        offset: float = Field(0.0, ge=-1000.0, le=1000.0, description="Metres above the ground.")

    def on_start(self) -> None:
        t = self.ctx.get(Transform)
        ground = self.ctx.ground_height(float(t.position[0]), float(t.position[2]))
        if ground is not None:
            t.position[1] = ground + self.params.offset


SCRIPTS = [Spin, Bob, WasdMover, Spawner, Lifetime, SnapToGround]
