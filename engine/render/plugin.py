"""The rendering core plugin: Camera and Mesh components, camera controllers, the HUD and Lighting resources, and
the render-extract / render systems that drive an attached :class:`~engine.render.renderer.Renderer`.

Nothing here imports GL: the renderer is created by the front end (window or headless) only.
"""

from __future__ import annotations

from engine.registry import Registry
from engine.config import Problem, as_data, format_key, locate_line, suggest, validate
from engine.render.components import Camera, CameraConfig, Hud, MeshConfig, build_camera, camera_controllers
from engine.render.lighting import light_command, setup_lighting
from engine.schedule import Stage
from engine.world import World


def _renderer(world: World):
    from engine.app import App

    app = world.try_resource(App)
    return None if app is None else app.renderer


def extract_system(world: World, dt: float) -> None:
    """Render-extract stage: the renderer copies what its passes need (the world is only read)."""
    renderer = _renderer(world)
    if renderer is not None:
        renderer.extract(world)


def draw_system(world: World, dt: float) -> None:
    """Render stage: execute the render graph."""
    renderer = _renderer(world)
    if renderer is not None:
        overlap, renderer.pending_overlap = renderer.pending_overlap, None
        renderer.draw(overlap)


def _mesh_command(world: World, entity: int, **values) -> MeshConfig:
    """``ctx.call("render.mesh", shape="box", color=(r, g, b))``: a validated Mesh component."""
    values = {k: as_data(v) for k, v in values.items()}
    return MeshConfig.model_validate(values)


def _set_hud(world: World, entity: int, lines=None, center=None, help=None, show_help=None,
             show_fps=None) -> None:
    """``ctx.call("render.hud", lines=[...], center="...", help=[...], show_help=True, show_fps=True)``: set the
    HUD's fields that are given (the others stay)."""
    hud = world.resource(Hud)
    if isinstance(lines, str) or isinstance(help, str):  # list("hello") would show one letter per line
        raise ValueError("render.hud: lines and help are lists of strings (one per line), got a single string; "
                         "wrap it in a list: lines=[\"...\"]")
    if lines is not None:
        hud.lines = list(lines)
    if center is not None:
        hud.center = str(center)
    if help is not None:
        hud.help = list(help)
    if show_help is not None:
        hud.show_help = bool(show_help)
    if show_fps is not None:
        hud.show_fps = bool(show_fps)


def _camera_command(world: World, entity: int, camera: int | None = None, **values) -> CameraConfig:
    """``ctx.call("render.camera", camera=other, viewport=(x, y, w, h), update_interval=2)``: change fields of a
    Camera's config (the caller's own camera when ``camera`` is omitted), validated like the scene's TOML: a bad
    value raises a ConfigError naming the field and keeps the camera as it was.  Returns the new config."""
    from engine.builtin import entity_ref

    target = entity if camera is None else entity_ref(world, camera, "camera")
    cam = world.get(target, Camera)
    changes = {k: as_data(v) for k, v in values.items()}
    merged = cam.config.model_dump(mode="json", warnings=False) | changes
    config = validate(CameraConfig, merged, file=f"render.camera (entity {target})")
    cam.config = config
    return config


BUILTIN_FEATURES = ("sky", "terrain", "meshes", "hud")  # engine.render.passes.builtin_features' names (no GL here)


def _hidden_feature_check(registry: Registry):
    """A scene check: every name in a Camera's ``hide_features`` is a render feature some plugin registered
    (a typo hides nothing, silently, otherwise); warnings, with the nearest name."""

    def check(plan, text: str) -> list[Problem]:
        known = sorted(set(BUILTIN_FEATURES) | set(registry.render_feature_names))
        found = []
        for i, ent in enumerate(plan.entities):
            for cname, cfg in ent.components:
                if cname != "Camera":
                    continue
                for j, feature in enumerate(cfg.hide_features):
                    if feature not in known:
                        key = ("entities", i, "components", "Camera", "hide_features", j)
                        found.append(Problem(str(plan.file), format_key(key),
                                             f"no render feature is called '{feature}' (known: {', '.join(known)}); "
                                             f"it hides nothing", feature, suggest(feature, known),
                                             locate_line(text, key[:-1])))
        return found

    return check


class RenderPlugin:
    name = "render"

    def build(self, registry: Registry) -> None:
        registry.add_component("Camera", CameraConfig, build_camera)
        registry.add_component("Mesh", MeshConfig)
        registry.add_system(camera_controllers, Stage.INPUT, name="render.camera_controllers", after=("core.input",))
        registry.add_system(extract_system, Stage.RENDER_EXTRACT, name="render.extract")
        registry.add_system(draw_system, Stage.RENDER, name="render.draw")
        registry.add_command("render.mesh", _mesh_command)
        registry.add_command("render.hud", _set_hud)
        registry.add_command("render.camera", _camera_command)
        registry.add_command("render.light", light_command)
        registry.on_world(lambda world: world.insert_resource(Hud()))
        registry.on_world(setup_lighting)
        registry.add_scene_check(_hidden_feature_check(registry))


plugin = RenderPlugin()
