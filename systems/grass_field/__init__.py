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


LEVEL0_TRIANGLE_WARNING = 2_000_000  # level-0 triangles a frame: about 0.6 s on a software rasteriser


def check_level_zero_load(plan, text: str) -> list:
    """Scene check (warnings): eq. 1 with the scene's main camera and window puts every cell nearer than
    D₀ = W·L / (2·tan θ·P₀) at level 0.  A length of interest far above the stem's real width makes that most of
    the field, drawn at full detail every frame: legal (it is the paper's rule), but seconds a frame."""
    import math

    from engine.config import Problem, format_key, locate_line

    render = plan.config.render
    cameras = [cfg for ent in plan.entities for c, cfg in ent.components
               if c == "Camera" and cfg.projection == "perspective"]
    if not cameras:
        return []
    main = min(cameras, key=lambda cfg: cfg.priority)
    width = render.width * render.render_scale * main.viewport[2]
    height = render.height * render.render_scale * main.viewport[3]
    tan_x = math.tan(math.radians(main.fov) / 2.0) * width / max(height, 1.0)
    found = []
    for i, ent in enumerate(plan.entities):
        for cname, cfg in ent.components:
            if cname != "GrassField":
                continue
            d0 = width * cfg.length_of_interest / (2.0 * tan_x * cfg.level_thresholds[0])
            view = min(1.0, 2.0 * 2.0 * math.atan(tan_x) / (2.0 * math.pi))  # culling keeps up to twice the angle
            cells = min(cfg.grid_x * cfg.grid_z, math.pi * d0 * d0 / cfg.cell_size ** 2 * view)
            triangles = cells * cfg.plants_per_cell * cfg.level0_triangles()
            if triangles <= LEVEL0_TRIANGLE_WARNING:
                continue
            key = ("entities", i, "components", "GrassField", "length_of_interest")
            found.append(Problem(
                str(plan.file), format_key(key),
                f"with the main camera at {width:.0f} px wide, every cell within D0 = {d0:.4g} units is level 0 "
                f"(eq. 1, P >= {cfg.level_thresholds[0]:g}): about {cells:.0f} cells, {triangles / 1e6:.1f} M "
                f"triangles a frame; L is the stem's diameter in world units (the paper: 0.5 for plants about 20 "
                f"tall, cells of 100)", cfg.length_of_interest, None, locate_line(text, key)))
    return found


class _Plugin:
    name = "grass_field"

    def build(self, registry) -> None:
        registry.add_component("GrassField", GrassFieldConfig, build_grass_field, preset_dir="grass_field")
        registry.add_system(place_system, Stage.STARTUP, name="grass_field.place")
        registry.add_scene_check(check_level_zero_load)
        registry.add_command("grass_field.set_max_level", set_max_level)
        registry.add_command("grass_field.set_debug_levels", set_debug_levels)
        registry.add_render_feature(_feature)  # GL is imported only when a renderer asks


plugin = _Plugin()
