"""Rendering on headless EGL (llvmpipe in CI): golden images, no effect on state, views, HUD, CLI."""

import subprocess
import sys

import moderngl
import numpy as np

from engine.app import App
from engine.render.components import Camera, CameraConfig, Hud, build_camera
from engine.spatial import Transform
from tests.render_utils import assert_golden, make_renderer, render_app

SCENE = "configs/scenes/sandbox.toml"


def test_sandbox_golden_image():
    app = App(SCENE)
    image = render_app(app, 200, 120, frames=1, steps_per_frame=30)
    assert_golden(image, "sandbox")


def test_rendering_does_not_change_the_state_hash():
    plain = App(SCENE, seed=9)
    plain.step(20)
    drawn = App(SCENE, seed=9)
    render_app(drawn, 96, 64, frames=20)
    assert drawn.state_hash() == plain.state_hash()


def test_minimap_view_is_composited_with_a_border():
    app = App(SCENE)
    e = app.world.spawn(Transform())
    cfg = CameraConfig(controller="top", projection="orthographic", ortho_height=40.0, viewport=[0.7, 0.7, 0.3, 0.3],
                       priority=5, border_color=[1.0, 0.0, 1.0])
    from engine.registry import BuildContext

    app.world.add(e, build_camera(cfg, BuildContext(app.world, e, "minimap", "", None)))
    renderer = make_renderer(app, 200, 120)
    image = render_app(app, frames=1)
    assert [v.name for v in renderer.views] == ["view0", "view1"]
    px = np.asarray(image)
    # the magenta frame is drawn just outside the minimap rectangle (top-right corner of the window)
    x0, y0 = int(0.7 * 200) - 1, 120 - int(0.7 * 120) - 1
    assert tuple(px[y0 - 5, x0]) == (255, 0, 255)
    assert_golden(image, "sandbox_minimap")


def test_hud_text_is_drawn():
    app = App(SCENE)
    plain = np.asarray(render_app(app, 160, 96), np.int16)
    app.world.resource(Hud).center = "YOU WIN"
    text = np.asarray(render_app(app, 160, 96, frames=1), np.int16)
    changed = np.abs(text - plain).max(axis=2) > 40
    ys, xs = np.nonzero(changed)
    assert changed.sum() > 100 and abs(xs.mean() - 80) < 20 and abs(ys.mean() - 48) < 20


def test_resize_and_pool_reuse():
    app = App(SCENE)
    renderer = make_renderer(app, 64, 48)
    app.step(1)
    for _ in range(4):  # the first frames draw the shadow map, then store the static layer, then restore it
        app.render_frame()
    allocations = renderer.graph.pool.allocations
    compiles = renderer.graph.compile_count
    app.render_frame()
    assert renderer.graph.pool.allocations == allocations  # transient targets reused across frames
    assert renderer.graph.compile_count == compiles  # same passes: no recompile
    renderer.resize(80, 40)
    app.render_frame()
    assert renderer.read_image().size == (80, 40)
    renderer.release()
    app.renderer = None


def test_cli_screenshot_and_graph_dot(tmp_path):
    shot = tmp_path / "shot.png"
    res = subprocess.run([sys.executable, "-m", "engine", "run", SCENE, "--headless", "--steps", "3", "--size", "96",
                          "64", "--screenshot", str(shot), "--profile", "--hash"], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    from PIL import Image

    assert Image.open(shot).size == (96, 64)
    assert "per-pass time" in res.stdout and len(res.stdout.strip().splitlines()[-1]) == 32
    dot = subprocess.run([sys.executable, "-m", "engine", "graph", SCENE, "--dot"], capture_output=True, text=True)
    assert dot.returncode == 0, dot.stderr
    assert dot.stdout.startswith("digraph") and "present.view0" in dot.stdout and "sky.view0" in dot.stdout


def test_a_camera_can_hide_features_in_its_view():
    app = App(SCENE)
    e = app.world.spawn(Transform())
    cfg = CameraConfig(controller="top", projection="orthographic", viewport=[0.5, 0.5, 0.5, 0.5], priority=3,
                       hide_features=["meshes"])
    from engine.registry import BuildContext

    app.world.add(e, build_camera(cfg, BuildContext(app.world, e, "map", "", None)))
    renderer = make_renderer(app, 96, 64)
    app.step(1)
    renderer.extract(app.world)
    order = renderer.declare().compile().order
    renderer.release()
    app.renderer = None
    assert "meshes.view0" in order and "meshes.view1" not in order and "terrain.view1" in order


def test_render_scale_draws_views_smaller_and_presents_full_size():
    app = App(SCENE)
    app.config.render.render_scale = 0.5
    renderer = make_renderer(app, 160, 96)
    image = render_app(app, frames=1)
    assert (renderer.views[0].width, renderer.views[0].height) == (80, 48)
    assert image.size == (160, 96) and np.asarray(image).std() > 5


def test_render_scale_tone_maps_at_view_size_then_upscales():
    """Below full scale the display transform runs at the view's size and the result is upscaled; the image
    matches a full-scale render up to the resolution change."""
    images = {}
    for scale in (1.0, 0.5):
        app = App(SCENE)
        app.config.render.render_scale = scale
        renderer = make_renderer(app, 160, 96)
        images[scale] = np.asarray(render_app(app, frames=1), np.float32)  # releases the renderer
        order = renderer.graph.compile().order  # the last frame's passes (a cached compile: no GL)
        assert ("tonemap.view0" in order) == (scale < 1.0)
        assert "present.view0" in order
    assert np.abs(images[1.0] - images[0.5]).mean() < 3.0  # 0.8 measured; an untoned or unscaled view is far off


def test_software_render_scale_applies_on_a_software_rasteriser_only():
    app = App(SCENE)
    app.config.render.software_render_scale = 0.5
    renderer = make_renderer(app, 160, 96)
    try:
        for software, size in ((True, (80, 48)), (False, (160, 96)), (True, (80, 48))):
            renderer.software = software
            app.render_frame()
            assert (renderer.views[0].width, renderer.views[0].height) == size
        app.config.render.software_render_scale = None  # unset: render_scale everywhere
        app.render_frame()
        assert (renderer.views[0].width, renderer.views[0].height) == (160, 96)
    finally:
        renderer.release()
        app.renderer = None


def test_hud_reuses_its_vertex_array_and_refreshes_the_fps_text_four_times_a_second(monkeypatch):
    from engine.render import passes

    app = App(SCENE)
    renderer = make_renderer(app, 96, 64)
    hud = next(f for f in renderer.features if isinstance(f, passes.HudFeature))
    app.world.resource(Hud).show_fps = True
    app.render_frame()
    vao = hud._vao
    app.render_frame()
    assert vao is not None and hud._vao is vao
    clock = {"t": passes.time.perf_counter() + 1000.0}
    monkeypatch.setattr(passes.time, "perf_counter", lambda: clock["t"])
    renderer.fps = 20.0
    first = hud._fps_line()
    renderer.fps = 50.0
    clock["t"] += 0.1
    assert hud._fps_line() == first == "FPS  20.0"
    clock["t"] += 0.2
    assert hud._fps_line() == "FPS  50.0"
    renderer.release()
    app.renderer = None


def test_reload_shaders_picks_up_edits_and_keeps_the_last_good_program(tmp_path):
    vert = "#version 330\nin vec2 p;\nvoid main() { gl_Position = vec4(p, 0.0, 1.0); }\n"
    frag = "#version 330\nout vec4 c;\nvoid main() { c = vec4(%s); }\n"
    (tmp_path / "flat.vert").write_text(vert)
    (tmp_path / "flat.frag").write_text(frag % "1.0")
    app = App(SCENE)
    renderer = make_renderer(app, 32, 32)
    first = renderer.load_program(tmp_path, "flat")
    assert renderer.load_program(tmp_path, "flat") is first  # cached: no re-read
    (tmp_path / "flat.frag").write_text(frag % "0.5")
    assert renderer.reload_shaders() == []
    edited = renderer.load_program(tmp_path, "flat")
    assert edited is not first
    (tmp_path / "flat.frag").write_text(frag % "this is not glsl")
    errors = renderer.reload_shaders()
    assert len(errors) == 1 and "flat" in errors[0]
    assert renderer.load_program(tmp_path, "flat") is edited
    renderer.release()
    app.renderer = None


def test_compute_shaders_load_by_name_with_defines_and_reload_with_f5(tmp_path):
    comp = ("#version 430\nlayout(local_size_x = 1) in;\nlayout(std430, binding = 0) buffer Out { float v[]; };\n"
            "void main() { v[0] = %s; }\n")
    (tmp_path / "fill.comp").write_text(comp % "float(VALUE)")
    app = App(SCENE)
    renderer = make_renderer(app, 32, 32)
    out = renderer.ctx.buffer(reserve=4)

    def run(shader) -> float:
        out.bind_to_storage_buffer(0)
        shader.run(1)
        renderer.ctx.memory_barrier()
        return float(np.frombuffer(out.read(), np.float32)[0])

    try:
        three = renderer.load_compute(tmp_path, "fill", ("VALUE 3",))
        assert renderer.load_compute(tmp_path, "fill", ("VALUE 3",)) is three  # cached per variant
        assert run(three) == 3.0 and run(renderer.load_compute(tmp_path, "fill", ("VALUE 5",))) == 5.0
        (tmp_path / "fill.comp").write_text(comp % "float(VALUE) + 0.5")
        assert renderer.reload_shaders() == []
        assert run(renderer.load_compute(tmp_path, "fill", ("VALUE 3",))) == 3.5  # the edit is live
        (tmp_path / "fill.comp").write_text(comp % "this is not glsl")
        errors = renderer.reload_shaders()
        assert len(errors) == 2 and all("fill.comp" in e for e in errors)
        assert run(renderer.load_compute(tmp_path, "fill", ("VALUE 3",))) == 3.5  # the last good one stays
    finally:
        out.release()
        renderer.release()
        app.renderer = None


def test_program_variants_define_names_in_every_stage_and_are_cached_apart(tmp_path):
    (tmp_path / "flat.vert").write_text(
        "#version 330\nvoid main() { vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);\n"
        "#ifdef RED\n    p *= 1.0;\n#else\n    p *= 0.0;\n#endif\n    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }\n")
    (tmp_path / "flat.frag").write_text("#version 330\nout vec4 frag;\nvoid main() {\n#ifdef RED\n"
                                        "    frag = vec4(1.0, 0.0, 0.0, 1.0);\n#else\n    frag = vec4(0.0, 0.0, 1.0, 1.0);\n"
                                        "#endif\n}\n")
    app = App(SCENE)
    renderer = make_renderer(app, 32, 32)
    plain, red = renderer.load_program(tmp_path, "flat"), renderer.load_program(tmp_path, "flat", ("RED",))
    assert plain is not red and renderer.load_program(tmp_path, "flat", ("RED",)) is red
    ctx = renderer.ctx
    target = ctx.texture((8, 8), 4)
    fbo = ctx.framebuffer(target)
    pixels = {}
    for name, prog in (("plain", plain), ("red", red)):
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 0.0)
        ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
        vao = ctx.vertex_array(prog, [])
        vao.render(moderngl.TRIANGLES, vertices=3)
        pixels[name] = np.frombuffer(fbo.read(components=4), np.uint8).reshape(8, 8, 4)[4, 4].tolist()
        vao.release()
    assert pixels == {"plain": [0, 0, 0, 0], "red": [255, 0, 0, 255]}  # the define reached both stages
    (tmp_path / "flat.frag").write_text("#version 330\nout vec4 frag;\nvoid main() { frag = vec4(0.5); }\n")
    assert renderer.reload_shaders() == [] and renderer.load_program(tmp_path, "flat", ("RED",)) is not red
    fbo.release(), target.release()
    renderer.release()
    app.renderer = None


def test_the_sun_rectangle_bounds_the_disc_and_vanishes_behind_the_camera():
    from engine.render.components import look_at, perspective
    from engine.render.feature import View
    from engine.render.passes import sun_rect

    def view(target):
        eye = np.zeros(3)
        proj, look = perspective(np.radians(60.0), 1.5, 0.1, 100.0), look_at(eye, np.asarray(target, float))
        fwd = np.asarray(target, float) / np.linalg.norm(target)
        return View("v", 300, 200, look.astype(np.float32), proj.astype(np.float32), eye.astype(np.float32),
                    fwd.astype(np.float32), 0.1, 100.0, np.radians(60.0), False)

    sun = np.array([0.0, 0.3, -1.0])
    sun /= np.linalg.norm(sun)
    v = view([0.0, 0.0, -1.0])
    x0, y0, x1, y1 = sun_rect(v, sun, 0.98)
    # every ray within the disc's cone lands inside: sample the cone's rim and project
    a = np.cross(sun, [1.0, 0.0, 0.0]); a /= np.linalg.norm(a)
    b = np.cross(sun, a)
    angle = np.arccos(0.98)
    for t in np.linspace(0, 2 * np.pi, 64):
        ray = np.cos(angle) * sun + np.sin(angle) * (np.cos(t) * a + np.sin(t) * b)
        clip = np.asarray(v.view_proj, float) @ np.append(ray, 0.0)
        x, y = clip[:2] / clip[3]
        assert x0 - 1e-6 <= np.clip(x, -1, 1) <= x1 + 1e-6 and y0 - 1e-6 <= np.clip(y, -1, 1) <= y1 + 1e-6
    assert (x1 - x0) * (y1 - y0) < 0.5  # a small part of the view, not all of it (4 in NDC)
    assert sun_rect(view([0.0, 0.0, 1.0]), sun, 0.98) is None  # looking away
    assert sun_rect(view([1.0, 0.0, 0.0]), sun, 0.98) == (-1.0, -1.0, 1.0, 1.0)  # the cone straddles the eye's plane


def test_the_sun_disc_shows_where_the_camera_looks_at_the_sun(tmp_path):
    """The disc is drawn apart from the sky gradient (over its own rectangle): it must still be there, round
    and centred on the sun's direction."""
    scene = tmp_path / "sun.toml"
    scene.write_text("""
[scene]
name = "sun"
[render]
sun_direction = [0.0, 0.0, -1.0]
fog_density = 0.0
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
fov = 40.0
controller = "none"
""")
    app = App(scene)
    image = np.asarray(render_app(app, 64, 64, frames=1), np.float64)[..., :3].sum(axis=-1)
    assert image[24:40, 24:40].max() >= 750  # the disc: near white (R + G + B of 255 each at most)
    assert image[:8, :8].max() < 700 and image[-8:, -8:].max() < 700  # the sky and halo away from it
    ys, xs = np.nonzero(image > 730)
    assert 20 < len(xs) < 400  # a disc, not the sky
    assert abs(xs.mean() - 31.5) < 1.5 and abs(ys.mean() - 31.5) < 1.5  # centred on the sun's direction


def test_a_view_with_an_update_interval_renders_every_nth_frame_and_shows_its_last_picture_between():
    from engine.registry import BuildContext

    app = App(SCENE)
    e = app.world.spawn(Transform())
    cfg = CameraConfig(controller="top", projection="orthographic", ortho_height=40.0, viewport=[0.6, 0.6, 0.4, 0.4],
                       priority=5, update_interval=3)
    app.world.add(e, build_camera(cfg, BuildContext(app.world, e, "minimap", "", None)))
    renderer = make_renderer(app, 160, 100)
    drawn, pictures = [], []
    terrain = next(f for f in renderer.features if f.name == "terrain")
    for frame in range(7):
        terrain.last_triangles.clear()
        angle = 0.4 * frame  # the light changes every frame: a rendered picture shows it
        renderer.sun_direction = np.array([np.cos(angle), 1.0, np.sin(angle)], np.float32) / np.sqrt(2.0)
        app.step(1)
        app.render_frame()
        drawn.append("view1" in terrain.last_triangles)
        pictures.append(np.asarray(renderer.read_image(), np.int16)[: 40, 96:])  # the minimap's rectangle
    assert drawn == [True, False, False, True, False, False, True]
    assert all(np.array_equal(pictures[i], pictures[0]) for i in (1, 2))  # the kept picture, not a blank
    assert not np.array_equal(pictures[3], pictures[0])  # rendered again: the new light shows
    # frames far apart in game time (screenshots of a headless run): no stale picture
    terrain.last_triangles.clear()
    app.step(30)  # 0.5 s
    app.render_frame()
    assert "view1" in terrain.last_triangles
    # a new viewport size renders at once, whatever the frame
    app.step(1)
    app.render_frame()
    app.world.get(e, Camera).config = cfg.model_copy(update={"viewport": (0.5, 0.5, 0.5, 0.5)})
    terrain.last_triangles.clear()
    app.step(1)
    app.render_frame()
    assert "view1" in terrain.last_triangles
    renderer.release()
    app.renderer = None


def test_a_view_without_the_sky_still_clears_its_colour():
    """With the sky in a view the clear pass clears depth only (the sky fills every empty pixel); a camera that
    hides the sky gets its colour cleared to the horizon colour, not whatever the pooled target held."""
    app = App(SCENE)
    e = app.world.spawn(Transform(position=(0.0, 40.0, 0.0)))
    cfg = CameraConfig(controller="top", projection="orthographic", viewport=[0.0, 0.0, 0.5, 0.5], priority=3,
                       hide_features=["sky", "terrain", "meshes"])
    from engine.registry import BuildContext

    app.world.add(e, build_camera(cfg, BuildContext(app.world, e, "map", "", None)))
    renderer = make_renderer(app, 96, 64)
    try:
        frames = []
        for _ in range(2):  # the second frame reuses pooled targets that the first frame's sky drew into
            app.step(1)
            app.render_frame()
            frames.append(np.asarray(renderer.read_image().convert("RGB"), np.int16))
    finally:
        renderer.release()
        app.renderer = None
    horizon = frames[0][48:64, 0:48].reshape(-1, 3)  # the inset (bottom-left quarter, image rows top-down)
    assert np.ptp(horizon, axis=0).max() <= 2, "the inset's background is not one flat colour"
    assert horizon.mean() > 20, "the inset's background was never cleared (black)"
    assert np.array_equal(frames[0][48:64, 0:48], frames[1][48:64, 0:48])


def test_reset_frame_clock_keeps_frames_drawn_far_apart_out_of_the_frame_rate():
    app = App(SCENE)
    renderer = make_renderer(app, 96, 64)
    app.render_frame()
    app.render_frame()
    assert renderer.fps > 0.0  # two frames in a row: a frame rate
    renderer.reset_frame_clock()
    assert renderer.fps == 0.0
    app.render_frame()  # the first frame after the reset has no previous frame to measure against
    assert renderer.fps == 0.0
    app.render_frame()
    assert renderer.fps > 0.0
    renderer.release()
    app.renderer = None


def test_reading_the_image_before_the_first_frame_is_an_error_not_a_black_picture():
    import pytest

    app = App(SCENE)
    renderer = make_renderer(app, 32, 20)
    try:
        with pytest.raises(RuntimeError, match="no frame drawn yet"):
            renderer.read_image()
        app.render_frame()
        assert renderer.read_image().size == (32, 20)
    finally:
        renderer.release()
        app.renderer = None


def test_a_respawned_terrain_leaves_no_gl_objects_behind(monkeypatch):
    """A hot reload that removes and re-adds the terrain: its mesh (buffers, shade texture, vertex arrays) was
    kept per entity id for the whole session."""
    from tests.render_utils import gl_objects_per_respawn, track_gl_objects

    live = track_gl_objects(monkeypatch)
    counts = gl_objects_per_respawn(App(SCENE), "ground", live)
    assert counts[1:] == counts[:1] * (len(counts) - 1)


def test_terrain_cache_keys_hold_their_arrays_not_their_ids():
    """id() of a freed array can be given to the next one: a key made of it would bring back a stale mesh."""
    from engine.render.passes import Identity

    a = np.zeros((3, 3))
    assert Identity(a) == Identity(a) and hash(Identity(a)) == hash(Identity(a))
    assert Identity(a) != Identity(a.copy()) and Identity(a) != id(a)


def test_release_frees_every_gl_object_the_renderer_made(monkeypatch):
    from tests.render_utils import track_gl_objects

    live = track_gl_objects(monkeypatch)
    app = App(SCENE)
    renderer = make_renderer(app, 64, 48)
    for _ in range(3):
        app.step(1)
        app.render_frame()
    renderer.release()
    app.renderer = None
    assert {kind: n for kind, n in live().items() if n} == {}
