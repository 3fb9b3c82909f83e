"""The water_surface effect plugin (seeds/003, Kosuge 2004): a height-field water surface whose waves start and
reflect at the outline of the bodies that cut it, with floating rigid bodies.

Registers the WaterSurface and RigidBody components, the impact / rigid-body / wave systems of the simulation
stage (in that order), a startup stability check, the commands and scripts of ``api.py``, and, lazily (so the
simulation never imports GL), the render feature that draws the water.
"""

from __future__ import annotations

import numpy as np

from engine.registry import Registry
from engine.schedule import Stage

# Hot reload.  WaterSurface: the grid's shape (resolution), and the spacing h that the build bakes into the
# state's origin and into the height-field Collider (extent sets h).  The coefficient caches of eq. 2.8 are keyed
# on k, so wave_speed is live; everything else is read each step.
WATER_STRUCTURAL = ("resolution", "spacing", "extent")
# RigidBody: the initial velocities are copied into the state at build time (an edit relaunches the body from
# where it is).  shape, half_extents and radius live in the Collider the build adds: live_update replaces it.
BODY_STRUCTURAL = ("velocity", "angular_velocity")


def water_live_update(old, new, world, entity: int) -> None:
    """Switching ``wave_source`` drops the other method's history so the switch makes no wave of its own."""
    from components.water_surface import WaterState

    state = world.try_get(entity, WaterState)
    if state is None or old.wave_source == new.wave_source:
        return
    state.column_depth = None
    if new.wave_source == "grid":  # every body counts as new: its depth change starts from this step
        state.body_entities = np.zeros(0, np.int64)


def body_live_update(old, new, world, entity: int) -> None:
    """A new shape or size: the body's Collider (which the systems read) is rebuilt; its motion is kept."""
    from dataclasses import replace

    from engine.collider import Collider

    if (old.shape, old.half_extents, old.radius) == (new.shape, new.half_extents, new.radius):
        return
    collider = world.try_get(entity, Collider)
    if collider is None:
        return
    world.add(entity, replace(collider, shape=new.shape, half_extents=np.array(new.half_extents, float),
                              radius=new.radius))


class WaterSurfacePlugin:
    name = "water_surface"

    def build(self, registry: Registry) -> None:
        from components.water_surface import RigidBody, WaterSurface, build_rigid_body, build_water_surface
        from systems.water_surface import api, simulate

        registry.add_component("WaterSurface", WaterSurface, build_water_surface, preset_dir="water_surface",
                               structural=WATER_STRUCTURAL, live_update=water_live_update)
        registry.add_component("RigidBody", RigidBody, build_rigid_body, structural=BODY_STRUCTURAL,
                               live_update=body_live_update)
        registry.add_system(simulate.startup_check, Stage.STARTUP, name="water_surface.check")
        registry.add_system(simulate.impacts_system, Stage.SIMULATION, name="water_surface.impacts")
        registry.add_system(simulate.bodies_system, Stage.SIMULATION, name="water_surface.bodies",
                            after=("water_surface.impacts",))
        registry.add_system(simulate.waves_system, Stage.SIMULATION, name="water_surface.waves",
                            after=("water_surface.bodies",))
        for name, fn in api.COMMANDS.items():
            registry.add_command(name, fn)
        registry.add_scripts(api.SCRIPTS)
        registry.on_world(simulate.setup_world)
        registry.add_render_feature(_make_feature, "water_surface")


def _make_feature(renderer):
    from systems.water_surface.render import WaterFeature

    return WaterFeature(renderer)


plugin = WaterSurfacePlugin()
