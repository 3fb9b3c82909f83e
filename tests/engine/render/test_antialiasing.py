"""Anti-aliasing (render settings ``antialiasing``): FXAA per view, at the view's size, before the HUD."""

import numpy as np
import pytest

from engine.app import App
from engine.config import ConfigError
from engine.scene import RenderSettings
from tests.render_utils import make_renderer

# A dark box turned about the view axis and a ball, against the sky: straight edges at a slant and a curved one.
SCENE = """
[scene]
name = "aa"
seed = 1

[render]
fog_density = 0.0
shadows = false  # "auto" shadow settings differ between the GPU and llvmpipe too: this compares anti-aliasing only

[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 0.0, 0.0]
distance = 6.0
yaw = 0.0
pitch = 0.0

[[entities]]
name = "box"
[entities.components.Transform]
position = [-0.9, 0.0, 0.0]
rotation = [0.0, 0.0, 23.0]
scale = [1.3, 1.3, 1.3]
[entities.components.Mesh]
shape = "box"
color = [0.05, 0.05, 0.06]

[[entities]]
name = "ball"
[entities.components.Transform]
position = [1.2, 0.3, 0.0]
[entities.components.Mesh]
shape = "sphere"
color = [0.9, 0.2, 0.1]
"""


def _scene(tmp_path):
    path = tmp_path / "aa.toml"
    path.write_text(SCENE)
    return path


def _render(path, mode: str, width: int, height: int, software: bool | None = None, frames: int = 1):
    app = App(path)
    app.config.render.antialiasing = mode
    renderer = make_renderer(app, width, height)
    if software is not None:
        renderer.software = software
    try:
        for _ in range(frames):
            app.render_frame()
        order = renderer.declare().compile().order
        return np.asarray(renderer.read_image(), np.float64), order
    finally:
        renderer.release()
        app.renderer = None


def _luma(image: np.ndarray) -> np.ndarray:
    return image @ np.array([0.299, 0.587, 0.114])


def test_fxaa_brings_edges_closer_to_a_supersampled_render(tmp_path):
    """Against the same frame rendered at 4 x 4 the size and averaged down (a 16-sample reference), FXAA's edges
    are much nearer than the aliased ones, and the pixels away from edges are left exactly as they were."""
    path = _scene(tmp_path)
    aliased, _ = _render(path, "off", 128, 80)
    smoothed, order = _render(path, "fxaa", 128, 80)
    big, _ = _render(path, "off", 512, 320)
    reference = big.reshape(80, 4, 128, 4, 3).mean(axis=(1, 3))
    assert "antialias.view0" in order

    luma = _luma(aliased)
    padded = np.pad(luma, 1, mode="edge")
    neighbourhood = np.stack([padded[1 + dy: 81 + dy, 1 + dx: 129 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1)])
    contrast = neighbourhood.max(axis=0) - neighbourhood.min(axis=0)
    edges = contrast > 40.0  # both sides of the box's and the ball's outlines
    flat = contrast < 7.0  # below FXAA's absolute contrast threshold (0.0312 of white): left alone
    assert edges.sum() > 150 and flat.sum() > 6000, (edges.sum(), flat.sum())

    error_aliased = np.abs(aliased - reference)[edges].mean()
    error_smoothed = np.abs(smoothed - reference)[edges].mean()
    assert error_smoothed < 0.75 * error_aliased, (error_smoothed, error_aliased)  # measured 7.8 against 13.5
    assert np.array_equal(smoothed[flat], aliased[flat])


def test_auto_is_fxaa_on_a_gpu_and_off_on_a_software_rasteriser(tmp_path):
    path = _scene(tmp_path)
    software, software_order = _render(path, "auto", 64, 40, software=True)
    hardware, hardware_order = _render(path, "auto", 64, 40, software=False)
    forced, _ = _render(path, "fxaa", 64, 40, software=True)
    off, off_order = _render(path, "off", 64, 40, software=False)
    assert "antialias.view0" not in software_order and "antialias.view0" in hardware_order
    assert "antialias.view0" not in off_order
    assert np.array_equal(hardware, forced) and np.array_equal(software, off)
    assert not np.array_equal(hardware, off)


def test_the_renderer_knows_llvmpipe_is_a_software_rasteriser(tmp_path):
    app = App(_scene(tmp_path))
    renderer = make_renderer(app, 32, 20)
    try:
        name = renderer.ctx.info["GL_RENDERER"].lower()
        assert renderer.software == ("llvmpipe" in name or "softpipe" in name)
    finally:
        renderer.release()
        app.renderer = None


def test_the_hud_is_drawn_after_anti_aliasing(tmp_path):
    """Text stays sharp: the HUD's pixels are the same bits with FXAA on and off."""
    from engine.render.components import Hud

    path = _scene(tmp_path)
    images = {}
    for mode in ("off", "fxaa"):
        app = App(path)
        app.config.render.antialiasing = mode
        app.world.resource(Hud).lines = ["HUD 0123"]
        renderer = make_renderer(app, 128, 80)
        app.render_frame()
        images[mode] = np.asarray(renderer.read_image(), np.int16)
        renderer.release()
        app.renderer = None
    box = (slice(0, 22), slice(0, 60))  # the top-left text box
    assert images["off"][box].std() > 20  # text is there
    assert np.array_equal(images["off"][box], images["fxaa"][box])


def test_below_full_scale_the_view_is_anti_aliased_before_it_is_upscaled(tmp_path):
    path = _scene(tmp_path)
    app = App(path)
    app.config.render.antialiasing = "fxaa"
    app.config.render.render_scale = 0.5
    renderer = make_renderer(app, 128, 80)
    try:
        app.render_frame()
        compiled = renderer.declare().compile()
        order = compiled.order
        assert order.index("tonemap.view0") < order.index("antialias.view0") < order.index("present.view0")
        assert np.asarray(renderer.read_image()).std() > 5
    finally:
        renderer.release()
        app.renderer = None


def test_a_view_drawn_every_nth_frame_is_anti_aliased_once_into_its_kept_picture(tmp_path, monkeypatch):
    from engine.registry import BuildContext
    from engine.render import passes
    from engine.render.components import CameraConfig, build_camera
    from engine.spatial import Transform

    app = App(_scene(tmp_path))
    app.config.render.antialiasing = "fxaa"
    e = app.world.spawn(Transform())
    cfg = CameraConfig(controller="top", projection="orthographic", ortho_height=6.0, viewport=[0.6, 0.6, 0.4, 0.4],
                       priority=5, update_interval=3)
    app.world.add(e, build_camera(cfg, BuildContext(app.world, e, "minimap", "", None)))
    renderer = make_renderer(app, 128, 80)
    smoothed = []
    original = passes.antialias_execute

    def counted(renderer_, pc, ldr, target):
        smoothed[-1].append(pc.pass_name)
        original(renderer_, pc, ldr, target)

    monkeypatch.setattr(passes, "antialias_execute", counted)
    try:
        pictures = []
        for _ in range(4):
            smoothed.append([])
            app.render_frame()
            pictures.append(np.asarray(renderer.read_image(), np.int16)[:32, 77:])  # the minimap's rectangle
        assert smoothed == [["antialias.view0", "antialias.view1"], ["antialias.view0"], ["antialias.view0"],
                            ["antialias.view0", "antialias.view1"]]
        assert np.array_equal(pictures[0], pictures[1])  # the kept, anti-aliased picture shown again
    finally:
        renderer.release()
        app.renderer = None


def test_antialiasing_takes_only_its_three_modes():
    assert RenderSettings(antialiasing="off").antialiasing == "off"
    with pytest.raises(Exception) as info:
        RenderSettings(antialiasing="msaa")
    assert "antialiasing" in str(info.value)


def test_a_scene_with_an_unknown_mode_names_the_file_and_key(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text(SCENE.replace("fog_density = 0.0", 'fog_density = 0.0\nantialiasing = "smaa"'))
    with pytest.raises(ConfigError) as info:
        App(path)
    text = str(info.value)
    assert "bad.toml" in text and "antialiasing" in text and "fxaa" in text
