"""The engine's core plugin: components every game needs (Name, Transform, Collider, Terrain) and the
input and script systems.  Rendering components (Camera, Mesh) are registered by the rendering core.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field as dataclass_field
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import AfterValidator, Field, ValidationInfo, field_validator

from engine.collider import Collider
from typing import Annotated

from engine.config import ConfigModel, Vec3, _as_tuple
from engine.heightfield import HeightField, load_heightmap_png, midpoint_displacement
from engine.input import InputQueue, InputState
from engine.registry import BuildContext, Registry
from engine.schedule import Stage
from engine.script import destroy_scripts, run_scripts
from engine.spatial import Transform, quat_from_euler
from engine.textures import load_texture
from engine.world import World


@dataclass
class Name:
    """A human-readable entity name (from the scene's ``name`` key)."""

    value: str


def find_named(world: World, name: str) -> int | None:
    """The lowest-id live entity the scene (or a prefab) named ``name``; None when there is none."""
    for entity, (n,) in world.query(Name):
        if n.value == name:
            return entity
    return None


def entity_ref(world: World, ref, param: str = "entity") -> int:
    """The entity a command argument names: an id, or the ``name`` the scene (or a prefab) gave it (the lowest
    id of that name).  A name nobody has raises ValueError with the nearest name; ``param``: the argument's name
    for the message."""
    if isinstance(ref, str):
        found = find_named(world, ref)
        if found is None:
            from engine.config import suggest

            close = suggest(ref, [n.value for _, (n,) in world.query(Name)])
            raise ValueError(f"{param}: no entity named '{ref}'" + (f"; did you mean '{close}'?" if close else ""))
        return found
    if isinstance(ref, (bool, float)) or not isinstance(ref, (int, np.integer)):
        raise ValueError(f"{param}: expected an entity id or name, got {ref!r}")
    return int(ref)


HalfExtents3 = Annotated[list[Annotated[float, Field(ge=0.0, le=10000.0)]], Field(min_length=3, max_length=3),
                         AfterValidator(_as_tuple)]
Scale3 = Annotated[list[Annotated[float, Field(ge=0.001, le=1000.0)]], Field(min_length=3, max_length=3),
                   AfterValidator(_as_tuple)]


class TransformConfig(ConfigModel):
    """Position, rotation and scale of an entity."""

    position: Vec3 = Field((0.0, 0.0, 0.0), description="World position in metres (x, y up, z).")
    rotation: Vec3 = Field((0.0, 0.0, 0.0),
                           description="Yaw, pitch, roll in degrees (yaw about +y, pitch about +x, roll about +z).")
    scale: Scale3 = Field((1.0, 1.0, 1.0), description="Scale per axis; each in [0.001, 1000].")

    def build(self) -> Transform:
        yaw, pitch, roll = (math.radians(a) for a in self.rotation)
        return Transform(np.array(self.position, float), quat_from_euler(yaw, pitch, roll),
                         np.array(self.scale, float))


class ColliderConfig(ConfigModel):
    """A collision shape queried by effects (energy-wave hits, water bodies, dust particles)."""

    shape: Literal["box", "sphere", "plane"] = Field(
        "box", description="Shape kind (height fields come from Terrain and WaterSurface: solid below their surface "
                           "over their footprint only, nothing beside it however low).")
    half_extents: HalfExtents3 = Field((0.5, 0.5, 0.5),
                                       description="Box half sizes in local units; each in [0, 10000].")
    radius: float = Field(0.5, gt=0.0, le=10000.0, description="Sphere radius in local units.")
    normal: Vec3 = Field((0.0, 1.0, 0.0), description="Plane normal (local); the solid side is below.")
    offset: float = Field(0.0, ge=-1e6, le=1e6, description="Plane offset along its normal.")
    layer: str = Field("default", max_length=64, description="Collision layer name.")
    is_trigger: bool = Field(False, description="Reports hits but effects pass through.")

    @field_validator("normal")
    @classmethod
    def _nonzero_normal(cls, normal: tuple[float, ...]) -> tuple[float, ...]:
        if math.sqrt(sum(x * x for x in normal)) < 1e-9:
            raise ValueError("expected a non-zero direction")
        return normal


def _build_collider(cfg: ColliderConfig, ctx: BuildContext) -> Collider:
    return Collider(shape=cfg.shape, half_extents=np.array(cfg.half_extents, float), radius=cfg.radius,
                    normal=np.array(cfg.normal, float), offset=cfg.offset, layer=cfg.layer,
                    is_trigger=cfg.is_trigger)


class TerrainConfig(ConfigModel):
    """A height-field terrain: midpoint displacement (seeded) or a PNG height map; also a collider."""

    size_exponent: int = Field(6, ge=2, le=10, description="Grid is 2^n + 1 points per side (midpoint displacement).")
    spacing: float = Field(2.0, gt=0.0, le=1000.0, description="Distance between grid points in metres.")
    roughness: float = Field(0.55, gt=0.0, le=1.0, description="Amplitude ratio per subdivision level (H).")
    amplitude: float = Field(8.0, ge=0.0, le=1000.0, description="Initial random displacement in metres.")
    heightmap: str | None = Field(None, description="PNG height map inside the configs root (instead of generation).")
    height_scale: float = Field(10.0, gt=0.0, le=10000.0, description="Metres for a white pixel of the height map.")
    flatten: float = Field(0.0, ge=0.0, le=1.0, description="Blend towards the mean height (1 = flat).")
    colors: list[Vec3] = Field([(0.07, 0.15, 0.04), (0.13, 0.22, 0.06), (0.28, 0.24, 0.16), (0.75, 0.75, 0.75)],
                               min_length=2, max_length=8, description="Colour ramp from low to high.")
    texture: str | None = Field(None, description="Ground texture: an 8-bit image (PNG, JPEG) inside the configs root, "
                                "tiled over the terrain; the ground's colour is the ramp's colour times the "
                                "texture's (sRGB decoded), e.g. the sand of seeds/004 section 3.1.")
    texture_size: float = Field(4.0, gt=0.0, le=10000.0, description="Metres covered by one repeat of the texture.")
    texture_strength: float = Field(1.0, ge=0.0, le=1.0,
                                    description="How much of the texture shows: 0 = the colour ramp alone, 1 = ramp "
                                                "times texture.")
    centered: bool = Field(True, description="Centre the terrain on the entity's position.")
    lod_pixels: float = Field(2.0, ge=0.0, le=64.0,
                              description="Level of detail: each chunk is drawn with the coarsest grid whose height "
                                          "error stays within this many pixels on screen (lighting is baked per grid "
                                          "point, so it keeps full detail at every level); 0 draws full detail "
                                          "everywhere.")

    @field_validator("heightmap")
    @classmethod
    def _heightmap_file(cls, value: str | None, info: ValidationInfo) -> str | None:
        """The PNG must lie inside the configs root and be a whole, readable grayscale image of a sane size;
        checked when the file is validated (the loaders pass ``configs_root`` as validation context) rather than
        at spawn."""
        path = _checked_asset(value, info, "height map", load_heightmap_png)
        if path is not None and path.suffix.lower() != ".png":
            raise ValueError(f"height map '{path}' must be a .png file")
        return value

    @field_validator("texture")
    @classmethod
    def _texture_file(cls, value: str | None, info: ValidationInfo) -> str | None:
        """The image must lie inside the configs root (or the engine's stock configs) and decode, checked when the
        file is validated, as the height map is."""
        _checked_asset(value, info, "texture", load_texture)
        return value


def _checked_asset(value: str | None, info: ValidationInfo, what: str, load) -> Path | None:
    """The file an asset field names (:func:`engine.config.resolve_asset`), decoded by ``load`` as the spawn will
    (a truncated file fails at validation, not at spawn); None for no value, or when validated without a configs
    root (then only the text is checked: relative, not escaping)."""
    from engine.config import resolve_asset

    if value is None:
        return None
    root = (info.context or {}).get("configs_root")
    if root is None:  # validated alone: only what the text itself shows
        if value.startswith(("/", "\\")) or ":" in value or ".." in Path(value).parts:
            raise ValueError(f"path '{value}' must be relative to the configs root and stay inside it")
        return None
    path = resolve_asset(root, value)  # ValueError names the escape
    try:
        load(path)
    except FileNotFoundError:
        raise ValueError(f"{what} not found: {path}") from None
    return path


@dataclass
class Terrain:
    """Runtime terrain: the height field (its collider is a separate Collider component)."""

    config: TerrainConfig
    field: HeightField
    texture: np.ndarray | None = dataclass_field(default=None, metadata={"hash": False})  # linear RGB (rows, cols, 3)


def _build_terrain(cfg: TerrainConfig, ctx: BuildContext) -> list:
    from engine.config import resolve_asset

    if cfg.heightmap:
        heights = load_heightmap_png(resolve_asset(ctx.configs_root, cfg.heightmap), cfg.height_scale)
    else:
        heights = midpoint_displacement(cfg.size_exponent, cfg.roughness, cfg.amplitude, ctx.rng("terrain"))
    if cfg.flatten:
        heights = heights + (heights.mean() - heights) * cfg.flatten
    rows, cols = heights.shape
    origin = np.zeros(2)
    if cfg.centered:
        origin = -0.5 * np.array([(cols - 1) * cfg.spacing, (rows - 1) * cfg.spacing])
    field = HeightField(heights, cfg.spacing, origin)
    texture = load_texture(resolve_asset(ctx.configs_root, cfg.texture)) if cfg.texture else None
    return [Terrain(cfg, field, texture), Collider(shape="heightfield", heightfield=field)]


def ground_height(world: World, x: float, z: float) -> float | None:
    """World height of the first (lowest id) Terrain under world (x, z), placed by its Transform; None without one."""
    for entity, (terrain,) in world.query(Terrain):
        t = world.try_get(entity, Transform)
        ox, oy, oz = t.position if t is not None else (0.0, 0.0, 0.0)
        return float(terrain.field.height_at(np.array([x - ox]), np.array([z - oz]))[0] + oy)
    return None


def input_system(world: World, dt: float) -> None:
    """Input stage: fold the events due this tick into InputState (recording or replaying them)."""
    queue = world.resource(InputQueue)
    events = queue.take()
    source = world.try_resource(InputSource)
    if source is not None:
        events = source.filter(world.tick, events)
    world.resource(InputState).apply(events)


class InputSource:
    """Optional resource that records or replays the per-tick input (set by the runner)."""

    def __init__(self, recorder=None, replay=None) -> None:
        self.recorder = recorder
        self.replay = replay

    def filter(self, tick: int, events: list):
        if self.replay is not None:
            events = self.replay.events_for(tick)
        if self.recorder is not None:
            self.recorder.record(tick, events)
        return events


def _setup_world(world: World) -> None:
    world.insert_resource(InputQueue())
    world.insert_resource(InputState(), state=True)
    world.despawn_hooks.append(destroy_scripts)
    world.despawn_hooks.append(lambda w, e: w.random.drop(e))


def _pause(world: World, entity: int, paused: bool = True) -> bool:
    """``ctx.call("engine.pause")`` pauses the game (calling it again keeps it paused);
    ``ctx.call("engine.pause", paused=False)`` resumes it.  Returns the new state.  A pause key toggles with
    ``engine.toggle_pause``."""
    from engine.app import TimeControl

    if not isinstance(paused, (bool, np.bool_)):
        raise TypeError(f"command 'engine.pause': paused must be True or False, got {paused!r} (engine.pause "
                        "pauses, paused=False resumes; to toggle, call 'engine.toggle_pause')")
    control = world.resource(TimeControl)
    control.paused = bool(paused)
    return control.paused


def _toggle_pause(world: World, entity: int) -> bool:
    """``ctx.call("engine.toggle_pause")`` pauses a running game and resumes a paused one (the pause key);
    returns the new state."""
    from engine.app import TimeControl

    control = world.resource(TimeControl)
    control.paused = not control.paused
    return control.paused


def _restart(world: World, entity: int) -> None:
    """``ctx.call("engine.restart")``: rebuild the scene after this tick."""
    from engine.app import TimeControl

    world.resource(TimeControl).restart_requested = True


class CorePlugin:
    name = "core"

    def build(self, registry: Registry) -> None:
        registry.add_component("Transform", TransformConfig, lambda cfg, ctx: cfg.build())
        registry.add_component("Collider", ColliderConfig, _build_collider)
        registry.add_component("Terrain", TerrainConfig, _build_terrain, preset_dir="terrain")
        registry.add_system(input_system, Stage.INPUT, name="core.input")
        registry.add_system(run_scripts, Stage.SCRIPT, name="core.scripts")
        registry.on_world(_setup_world)
        registry.add_command("engine.pause", _pause)
        registry.add_command("engine.toggle_pause", _toggle_pause)
        registry.add_command("engine.restart", _restart)
        from engine import stock_scripts

        registry.add_scripts(stock_scripts.SCRIPTS)
