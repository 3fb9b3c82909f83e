"""Small worlds for the energy-wave tests: an App with only the core and energy_wave plugins."""

from __future__ import annotations

from typing import Any

import numpy as np

from components.energy_wave import EnergyWaveEmitter, EnergyWaveState, build_energy_wave
from engine.app import App
from engine.collider import Collider
from engine.registry import BuildContext, default_registry
from engine.spatial import Transform, quat_from_euler

_REGISTRY = None


def registry():
    global _REGISTRY
    if _REGISTRY is None:
        _REGISTRY = default_registry(["energy_wave"])
    return _REGISTRY


def make_app(seed: int = 1) -> App:
    return App(registry=registry(), seed=seed)


def add_emitter(app: App, position=(0.0, 0.0, 0.0), yaw_pitch_roll=(0.0, 0.0, 0.0),
                **fields: Any) -> tuple[int, EnergyWaveEmitter, EnergyWaveState]:
    """Spawn an emitter looking down -z (rotated by yaw/pitch/roll radians) with config ``fields``."""
    world = app.world
    cfg = EnergyWaveEmitter.model_validate(fields)
    entity = world.reserve()
    comps = build_energy_wave(cfg, BuildContext(world, entity, "emitter", "<test>", None))
    world.spawn(Transform(position=np.array(position, float), rotation=quat_from_euler(*yaw_pitch_roll)),
                *comps, entity=entity)
    return entity, comps[0], comps[1]


def add_box(app: App, position, half_extents=(1.0, 1.0, 0.25), **kw) -> int:
    return app.world.spawn(Transform(position=np.array(position, float)),
                           Collider(shape="box", half_extents=np.array(half_extents, float), **kw))


def state(app: App, entity: int) -> EnergyWaveState:
    return app.world.get(entity, EnergyWaveState)


def live(st: EnergyWaveState, name: str) -> np.ndarray:
    return st.particles.live(name)
