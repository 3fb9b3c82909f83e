"""The grass_field plugin (seeds/001): clumped grass on a grid drawn with six representations per cell.

Registers:

* component ``GrassField`` (presets in configs/effects/grass_field/): config + random draws of figure 1;
* ``grass_field.place`` (startup): puts every field on the terrain and builds its level meshes (table 1);
* commands for scripts: ``grass_field.set_max_level`` (3, 4 or 5: the paper's method 1, 2 or 3) and
  ``grass_field.set_debug_levels`` (colour cells by level);
* the render feature (imported lazily, so simulation never imports GL): per-cell levels from eq. 1 and
  table 2, cell culling, instanced levels 0-3, the LOD cache of level 4 and the band of level 5.
"""

from __future__ import annotations

from components.grass_field import GrassFieldConfig, build_grass_field
from engine.schedule import Stage
from systems.grass_field.simulate import place_system, set_debug_levels, set_max_level


def _feature(renderer):
    from systems.grass_field.render import GrassFieldFeature

    return GrassFieldFeature(renderer)


class _Plugin:
    name = "grass_field"

    def build(self, registry) -> None:
        registry.add_component("GrassField", GrassFieldConfig, build_grass_field, preset_dir="grass_field")
        registry.add_system(place_system, Stage.STARTUP, name="grass_field.place")
        registry.add_command("grass_field.set_max_level", set_max_level)
        registry.add_command("grass_field.set_debug_levels", set_debug_levels)
        registry.add_render_feature(_feature)  # GL is imported only when a renderer asks


plugin = _Plugin()
