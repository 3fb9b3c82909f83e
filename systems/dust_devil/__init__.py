"""The dust_devil plugin (seeds/004): the DustDevil component, its simulation, dragging and PBVR rendering.

Registers:

* component ``DustDevil`` (presets in configs/effects/dust_devil/);
* ``dust_devil.mouse_drag`` (input stage): a mouse drag in the top-view camera's viewport moves the field;
* ``dust_devil.simulate`` (simulation stage): :func:`systems.dust_devil.simulate.step` per dust devil;
* commands for scripts: ``dust_devil.drag`` (world-space ``delta``), ``dust_devil.pick_drag`` (two ground
  points ``start``, ``end``: the horizontal difference) and ``dust_devil.screen_drag`` (two pixel points in a
  camera's viewport, picked on the ground);
* render features (imported lazily, so simulation never imports GL): the PBVR particles and the red markers.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from components.dust_devil import DustDevilConfig, DustDevilState, build_dust_devil
from engine.schedule import Stage
from engine.spatial import Transform
from systems.dust_devil import picking, simulate

SYSTEM = "dust_devil"


class DragError(ValueError):
    """A drag command could not find its dust devil or camera."""


# ------------------------------------------------------------------------------------------ world lookups
def find_ground(world) -> simulate.Ground | None:
    """The first (lowest id) Terrain entity as a :class:`simulate.Ground`, or None."""
    from engine.builtin import Terrain

    found = world.query(Terrain)
    if not found:
        return None
    entity, (terrain,) = found[0]
    return simulate.Ground(terrain.field, world.try_get(entity, Transform))


def _terrain_collider(world):
    from engine.builtin import Terrain
    from engine.collider import Collider

    for entity, (_, collider) in world.query(Terrain, Collider):
        return collider, world.try_get(entity, Transform) or Transform()
    return None


def _find_camera(world, name: str):
    from engine.builtin import Name
    from engine.render.components import Camera

    for _, (n, camera, transform) in world.query(Name, Camera, Transform):
        if n.value == name:
            return camera, transform
    return None


def window_size(world) -> tuple[int, int]:
    """The window (or offscreen target) size in pixels (engine.render.components.window_size)."""
    from engine.render.components import window_size as engine_window_size

    return engine_window_size(world)


def _target(world, entity, target):
    """The dust devil a command acts on: ``target``, else the calling entity, else the first one."""
    if target is not None:
        from engine.builtin import entity_ref

        try:
            entity = entity_ref(world, target, "target")
        except ValueError as exc:
            raise DragError(str(exc)) from None
        if not world.has(entity, Transform, DustDevilConfig, DustDevilState):
            raise DragError(f"entity {target} is not a dust devil (needs Transform and DustDevil)")
    elif not world.has(entity, Transform, DustDevilConfig, DustDevilState):
        found = world.query(Transform, DustDevilConfig, DustDevilState)
        if not found:
            raise DragError("no dust devil in the world (an entity with Transform and DustDevil)")
        entity = found[0][0]
    return entity, world.get(entity, Transform), world.get(entity, DustDevilState)


def screen_pick(world, camera_name: str, points: Any) -> tuple[np.ndarray, np.ndarray]:
    """Ground points under pixel ``points`` (N, 2) seen by the camera entity named ``camera_name``."""
    cam = _find_camera(world, camera_name)
    if cam is None:
        raise DragError(f"no camera entity named '{camera_name}' (an entity with Name, Camera and Transform)")
    view, proj, vp = picking.camera_matrices(cam[0], cam[1], window_size(world))
    return picking.pick_ground(view, proj, vp, points, _terrain_collider(world))


# ------------------------------------------------------------------------------------------------ commands
def drag_command(world, entity, delta, target=None, interactive=False) -> np.ndarray:
    """``dust_devil.drag``: move the field box (and all its particles) by a world-space ``delta``.
    ``interactive=True`` counts as a user's drag (PBVR drops to ``drag_repeats`` for the next frame)."""
    _, transform, state = _target(world, entity, target)
    return simulate.drag(state, transform, delta, world.tick, bool(interactive))


def pick_drag_command(world, entity, start, end, target=None, interactive=False) -> np.ndarray:
    """``dust_devil.pick_drag``: move by the horizontal difference of two ground pick points."""
    delta = np.asarray(end, dtype=np.float64) - np.asarray(start, dtype=np.float64)
    if delta.shape != (3,):
        raise DragError(f"pick_drag start and end must be world points (x, y, z), got {start!r}, {end!r}")
    delta[1] = 0.0
    return drag_command(world, entity, delta, target, interactive)


def screen_drag_command(world, entity, start, end, camera=None, target=None, interactive=True) -> np.ndarray:
    """``dust_devil.screen_drag``: a mouse drag from pixel ``start`` to ``end`` in a camera's viewport (default:
    the dust devil's ``drag_camera``), picked on the ground; interactive (like the mouse) unless told not."""
    devil, _, _ = _target(world, entity, target)
    name = camera or world.get(devil, DustDevilConfig).drag_camera
    hit, points = screen_pick(world, name, [start, end])
    if not hit.all():
        raise DragError(f"screen_drag {start} -> {end} does not hit the ground inside camera '{name}'s viewport")
    return pick_drag_command(world, entity, points[0], points[1], devil, interactive)


def check_drag_cameras(plan, text: str) -> list:
    """Scene check (warnings): a dust devil's ``drag_camera`` should name a camera entity of the scene, else a
    mouse drag silently does nothing.  Only a warning: a script may spawn that camera later."""
    from engine.config import Problem, format_key, locate_line, suggest

    cameras = [ent.name for ent in plan.entities  # what screen_pick finds: Name, Camera and Transform
               if ent.name and {"Camera", "Transform"} <= {c for c, _ in ent.components}]
    found = []
    for i, ent in enumerate(plan.entities):
        for cname, cfg in ent.components:
            if cname != "DustDevil" or not cfg.drag_camera or cfg.drag_camera in cameras:
                continue
            key = ("entities", i, "components", "DustDevil", "drag_camera")
            listed = ", ".join(f"'{c}'" for c in cameras) or "none"
            how = ("" if "drag_camera" in cfg.model_fields_set else
                   " (the default; set drag_camera = \"\" to turn mouse dragging off)")
            found.append(Problem(str(plan.file), format_key(key),
                                 f"no camera entity named '{cfg.drag_camera}' (with Camera and Transform) in this "
                                 f"scene{how}; mouse drags of this dust devil will do nothing unless a script "
                                 f"spawns it (cameras: {listed})",
                                 None, suggest(cfg.drag_camera, cameras), locate_line(text, key)))
    return found


# ------------------------------------------------------------------------------------------------- systems
def mouse_drag_system(world, dt: float) -> None:
    """Input stage: press in the top view picks the ground, moving the mouse moves the field by the picked
    ground distance (horizontal), release ends the drag (section 4).  A paused game (``engine.pause``) freezes
    the dust devil with the rest of the simulation: no drag starts or goes on while it is paused (a drag in
    progress ends; the button must be pressed again after the pause)."""
    from engine.app import is_paused
    from engine.input import InputState

    inp = world.resource(InputState)
    paused = is_paused(world)
    for _, (transform, cfg, state) in world.query(Transform, DustDevilConfig, DustDevilState):
        button = f"mouse_{cfg.drag_button}"
        if paused or not cfg.drag_camera or not inp.is_down(button):
            state.mouse_dragging = False
            continue
        if not state.mouse_dragging and not inp.was_pressed(button):
            continue
        try:
            hit, point = screen_pick(world, cfg.drag_camera, [inp.mouse])
        except DragError:
            state.mouse_dragging = False
            continue
        if not hit[0]:
            continue
        if state.mouse_dragging:
            delta = point[0] - state.drag_anchor
            delta[1] = 0.0
            simulate.drag(state, transform, delta, world.tick)
        state.mouse_dragging = True
        state.drag_anchor = point[0].copy()


def simulate_system(world, dt: float) -> None:
    """Simulation stage: one step of every dust devil, in entity order."""
    ground = find_ground(world)
    for entity, (transform, cfg, state) in world.query(Transform, DustDevilConfig, DustDevilState):
        simulate.step(cfg, state, transform, ground, world.random.stream(f"{SYSTEM}.emit", entity),
                      world.random.stream(f"{SYSTEM}.rotate", entity), dt)


def _markers_feature(renderer):
    from systems.dust_devil.render import DustDevilMarkers

    return DustDevilMarkers(renderer)


def _particles_feature(renderer):
    from systems.dust_devil.render import DustDevilParticles

    return DustDevilParticles(renderer)


class _Plugin:
    name = "dust_devil"

    def build(self, registry) -> None:
        # hot reload: only the particle count needs a rebuild (it sizes the particle arrays); every other key is
        # read from the config each step (the wind grid is re-evaluated every step from grid_resolution,
        # field_size and wind_scale) or each frame; prewarm_time is read at the first step only.
        registry.add_component("DustDevil", DustDevilConfig, build_dust_devil, preset_dir="dust_devil",
                               structural=("particle_count",))
        registry.add_system(mouse_drag_system, Stage.INPUT, name="dust_devil.mouse_drag", after=("core.input",))
        registry.add_system(simulate_system, Stage.SIMULATION, name="dust_devil.simulate")
        registry.add_scene_check(check_drag_cameras)
        registry.add_command("dust_devil.drag", drag_command)
        registry.add_command("dust_devil.pick_drag", pick_drag_command)
        registry.add_command("dust_devil.screen_drag", screen_drag_command)
        registry.add_render_feature(_markers_feature, "dust_devil_markers")  # GL is imported only when a renderer asks
        registry.add_render_feature(_particles_feature, "dust_devil")


plugin = _Plugin()
