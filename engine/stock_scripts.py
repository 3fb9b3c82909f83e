"""Small general-purpose scripts that ship with the engine (used by the sandbox scene).

They use only the public scripting API, like any game's scripts.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

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


@script("sun_cycle")
class SunCycle(Script):
    """A day of game time: moves the sun along its path every tick (``render.light``); with ``tint`` the sun, the
    ambient light and the sky dim and redden by the sun's height.

    The path is a great circle: the sun rises towards +x at 6 o'clock, stands highest at noon, ``tilt`` degrees
    from the zenith towards +z, sets towards -x at 18 o'clock and is lowest at midnight; ``azimuth`` turns it
    about the vertical.  The hour is ``start_hour`` + 24 × (ticks run, pauses left out) × dt / ``period``, and the
    direction comes from engine.exact's sin and cos: the same bits in every process.

    ``tint``: the sun's colour fades from the day's to black between about 15° above the horizon and 6° under it
    (smoothstep on the height), yellowing then reddening on the way; the ambient light and the sky colours go
    from the day's down to ``night`` of them, the horizon reddening at dawn and dusk.  The day's values are the
    light in force when the script starts, and a field someone else changes (a hot reload of the scene's
    ``[render]``, another script's ``render.light``) becomes that field's new day value.  The fog stays."""

    class Params(ConfigModel):
        period: float = Field(120.0, gt=0.0, le=1.0e7, description="Seconds of game time for a whole day.")
        start_hour: float = Field(9.0, ge=0.0, lt=24.0,
                                  description="The hour when the script starts: 6 sunrise, 12 noon, 18 sunset.")
        azimuth: float = Field(0.0, ge=-360.0, le=360.0,
                               description="Degrees the sun's path is turned about the vertical (0: it rises "
                                           "towards +x and leans towards +z at noon).")
        tilt: float = Field(30.0, ge=0.0, le=89.0, description="Degrees of the noon sun from the zenith (the "
                                                               "path's tilt; about the latitude).")
        min_elevation: float = Field(-90.0, ge=-90.0, le=89.0,
                                     description="The sun never goes lower than this many degrees above the horizon "
                                                 "(e.g. 5: a low sun all night, never under the ground).")
        interval: float = Field(0.0, ge=0.0, le=3600.0,
                                description="Seconds of game time between moves of the sun (0: every tick). Every "
                                            "change of the light re-makes the terrain's light and shadow map (a few "
                                            "ms): a slow day looks the same at 1 s steps and costs less.")
        tint: bool = Field(True, description="Dim and redden the sun, the ambient light and the sky by the sun's "
                                             "height (night, dawn and dusk); off: only the sun's direction moves.")
        night: float = Field(0.15, ge=0.0, le=1.0, description="With tint: the share of the day's ambient light and "
                                                               "sky colours left at night.")

    TINTED: ClassVar[tuple[str, ...]] = ("sun_color", "ambient", "sky_top", "sky_horizon")

    def on_start(self) -> None:
        self.ticks = 0  # ticks run, pauses left out: the game time of the day is ticks × dt
        self.day: dict[str, Any] = {}  # the day's light of the tinted fields
        self.written: dict[str, Any] = {}  # what this script last set them to

    def on_update(self, dt: float) -> None:
        if self.ctx.paused:
            return
        seconds = self.ticks * dt
        self.ticks += 1
        p = self.params
        if p.interval > 0.0:
            seconds = math.floor(seconds / p.interval) * p.interval
        hour = (p.start_hour + 24.0 * seconds / p.period) % 24.0
        direction = sun_path(hour, p.tilt, p.azimuth, p.min_elevation)
        if not p.tint:
            self.ctx.call("render.light", sun_direction=direction)
            return
        light = self.ctx.call("render.light")  # the light in force
        for key in self.TINTED:
            if getattr(light, key) != self.written.get(key):  # set by someone else (or not yet by this script)
                self.day[key] = getattr(light, key)
        self.written = tint_light(self.day, direction[1], p.night)
        self.ctx.call("render.light", sun_direction=direction, **self.written)


def sun_path(hour: float, tilt: float, azimuth: float, min_elevation: float) -> tuple[float, float, float]:
    """The unit direction towards the sun at ``hour`` (degrees for the rest; see :class:`SunCycle`).

    θ = 2π (hour − 6) / 24 from the rising point: d = cos θ · east + sin θ · noon, east = (1, 0, 0) and
    noon = (0, cos tilt, sin tilt); below ``min_elevation`` the height is held at it (the sun slides along that
    circle); then a turn by ``azimuth`` about +y."""
    theta = 2.0 * math.pi * (hour - 6.0) / 24.0
    tilt_r = math.radians(tilt)
    x = exact.cos_scalar(theta)
    y = exact.sin_scalar(theta) * exact.cos_scalar(tilt_r)
    z = exact.sin_scalar(theta) * exact.sin_scalar(tilt_r)
    floor = exact.sin_scalar(math.radians(min_elevation))
    if y < floor:
        across = exact.hypot_scalar(x, z)
        scale = exact.cos_scalar(math.radians(min_elevation))
        x, z = (x / across * scale, z / across * scale) if across > 0.0 else (0.0, -scale)
        y = floor
    a = math.radians(azimuth)
    ca, sa = exact.cos_scalar(a), exact.sin_scalar(a)
    return (x * ca + z * sa, y, z * ca - x * sa)


DAWN_LOW, DAWN_HIGH = -0.1, 0.25  # sin of the sun's height: night below about -6°, full day above about 14.5°


def tint_light(day: dict[str, Any], height: float, night: float) -> dict[str, Any]:
    """The tinted fields of :class:`SunCycle` for a sun whose direction has y = ``height`` (sin of its elevation):
    ``lit`` = smoothstep(DAWN_LOW, DAWN_HIGH, height), ``glow`` = 4 lit (1 − lit) (1 at mid-twilight);
    sun = day sun × lit × (1, 1 − 0.4 glow, 1 − 0.7 glow); ambient and sky top = day × (night + (1 − night) lit);
    horizon likewise × (1, 1 − 0.25 glow, 1 − 0.5 glow)."""
    t = min(max((height - DAWN_LOW) / (DAWN_HIGH - DAWN_LOW), 0.0), 1.0)
    lit = t * t * (3.0 - 2.0 * t)
    glow = 4.0 * lit * (1.0 - lit)
    level = night + (1.0 - night) * lit

    def scaled(color, factors) -> tuple[float, ...]:
        return tuple(c * f for c, f in zip(color, factors))

    return {"sun_color": scaled(day["sun_color"], (lit, lit * (1.0 - 0.4 * glow), lit * (1.0 - 0.7 * glow))),
            "ambient": day["ambient"] * level,
            "sky_top": scaled(day["sky_top"], (level,) * 3),
            "sky_horizon": scaled(day["sky_horizon"], (level, level * (1.0 - 0.25 * glow), level * (1.0 - 0.5 * glow)))}


SCRIPTS = [Spin, Bob, WasdMover, Spawner, Lifetime, SnapToGround, SunCycle]
