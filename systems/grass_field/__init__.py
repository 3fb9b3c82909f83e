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
    """Scene check (warnings): eq. 1 puts every cell nearer than D₀ = W·L / (2·tan θ·P₀) at level 0, for each
    view that draws the field (every enabled perspective camera with a Transform that does not hide it; the
    renderer's default view when the scene has no camera).  A length of interest far above the stem's real
    width makes that most of the field, drawn at full detail every frame: legal (it is the paper's rule), but
    seconds a frame.  The worst view is named."""
    import math

    from engine.config import Problem, format_key, locate_line
    from engine.render.components import CameraConfig

    render = plan.config.render
    views = [(ent.name or f"camera {i}", dict(ent.components)["Camera"]) for i, ent in enumerate(plan.entities)
             if {"Camera", "Transform"} <= {c for c, _ in ent.components}]
    if not any(c == "Camera" for ent in plan.entities for c, _ in ent.components):
        views = [("the default view", CameraConfig(controller="none"))]
    views = [(name, cam) for name, cam in views
             if cam.enabled and cam.projection == "perspective" and "grass_field" not in cam.hide_features]
    found = []
    for i, ent in enumerate(plan.entities):
        for cname, cfg in ent.components:
            if cname != "GrassField":
                continue
            worst = None
            scale = max(render.render_scale, render.software_render_scale or 0.0)  # the larger: the worse case
            for name, cam in views:
                width = render.width * scale * cam.viewport[2]
                height = render.height * scale * cam.viewport[3]
                tan_x = math.tan(math.radians(cam.fov) / 2.0) * width / max(height, 1.0)
                d0 = width * cfg.length_of_interest / (2.0 * tan_x * cfg.level_thresholds[0])
                view = min(1.0, 2.0 * 2.0 * math.atan(tan_x) / (2.0 * math.pi))  # culling keeps twice the angle
                cells = min(cfg.grid_x * cfg.grid_z, math.pi * d0 * d0 / cfg.cell_size ** 2 * view)
                triangles = cells * cfg.plants_per_cell * cfg.level0_triangles()
                if worst is None or triangles > worst[0]:
                    worst = (triangles, name, width, d0, cells)
            if worst is None or worst[0] <= LEVEL0_TRIANGLE_WARNING:
                continue
            triangles, name, width, d0, cells = worst
            key = ("entities", i, "components", "GrassField", "length_of_interest")
            found.append(Problem(
                str(plan.file), format_key(key),
                f"in '{name}' ({width:.0f} px wide) every cell within D0 = {d0:.4g} units is level 0 (eq. 1, "
                f"P >= {cfg.level_thresholds[0]:g}): about {cells:.0f} cells, {triangles / 1e6:.1f} M triangles a "
                f"frame; L is the stem's diameter in world units (the paper: 0.5 for plants about 20 tall, cells "
                f"of 100)", cfg.length_of_interest, None, locate_line(text, key)))
    return found


class _Plugin:
    name = "grass_field"

    def build(self, registry) -> None:
        registry.add_component("GrassField", GrassFieldConfig, build_grass_field, preset_dir="grass_field")
        registry.add_system(place_system, Stage.STARTUP, name="grass_field.place")
        registry.add_scene_check(check_level_zero_load)
        registry.add_command("grass_field.set_max_level", set_max_level)
        registry.add_command("grass_field.set_debug_levels", set_debug_levels)
        registry.add_render_feature(_feature, "grass_field")  # GL is imported only when a renderer asks


plugin = _Plugin()
