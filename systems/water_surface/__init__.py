"""The water_surface effect plugin (seeds/003, Kosuge 2004): a height-field water surface whose waves start and
reflect at the outline of the bodies that cut it, with floating rigid bodies.

Registers the WaterSurface and RigidBody components, the impact / rigid-body / wave systems of the simulation
stage (in that order), a startup stability check, the commands and scripts of ``api.py``, and, lazily (so the
simulation never imports GL), the render feature that draws the water.
"""

from __future__ import annotations

from engine.registry import Registry
from engine.schedule import Stage


class WaterSurfacePlugin:
    name = "water_surface"

    def build(self, registry: Registry) -> None:
        from components.water_surface import RigidBody, WaterSurface, build_rigid_body, build_water_surface
        from systems.water_surface import api, simulate

        registry.add_component("WaterSurface", WaterSurface, build_water_surface, preset_dir="water_surface")
        registry.add_component("RigidBody", RigidBody, build_rigid_body)
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
        registry.add_render_feature(_make_feature)


def _make_feature(renderer):
    from systems.water_surface.render import WaterFeature

    return WaterFeature(renderer)


plugin = WaterSurfacePlugin()
