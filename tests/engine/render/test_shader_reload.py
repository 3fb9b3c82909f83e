"""F5's shader reload (Renderer.reload_shaders): the programs an edit replaces are released once no vertex array is
made on them (each feature remakes its vertex arrays when load_program hands it a new program), never while one
still is, and the pictures stay what they were."""

import moderngl
import numpy as np
import pytest

import engine.render.renderer as renderer_module
from engine.app import App
from engine.builtin import find_named
from engine.script import ScriptContext
from engine.spatial import Transform
from tests.render_utils import make_renderer, track_gl_objects


def _demo_in_play(app) -> None:
    """The demo 40 ticks into the autopilot's game (beams flying) with a smoke puff in front of the main camera:
    terrain, grass, water, meshes, the dust devil, energy beams, toon smoke, two views and the HUD."""
    from game_demo.autoplay import AutoPilot

    app.pre_tick.append(AutoPilot(window=(160, 96)))
    app.step(40)
    camera = app.world.get(find_named(app.world, "main_camera"), Transform)
    spawner = ScriptContext(app.world, find_named(app.world, "game"), "test")
    spawner.spawn_prefab("smoke_puff", camera.position + 6.0 * camera.forward())
    app.world.commands.apply()


SCENES = {"demo": _demo_in_play,  # every effect (the dust devil as compute-shader PBVR)
          "dust_devil_showcase": lambda app: app.step(10)}  # the dust devil's markers


def _pictures(scene: str, reload_shaders, observe=lambda renderer: None, cycles: int = 3) -> tuple[list, list]:
    """Scene ``scene`` set up by SCENES: two frames, then per cycle ``reload_shaders(renderer)`` and two frames (a
    tick before each: the demo's top view draws every other frame, so two frames give every feature a draw in
    every view), ``observe(renderer)`` after the first two and after each cycle.  Returns the pictures of every
    frame and what each reload returned."""
    app = App(f"configs/scenes/{scene}.toml")
    SCENES[scene](app)
    renderer = make_renderer(app, 160, 96)
    pictures, results = [], []
    try:
        for cycle in range(1 + cycles):
            if cycle:
                results.append(reload_shaders(renderer))
            for _ in range(2):
                app.step(1)
                app.render_frame()
                pictures.append(np.asarray(renderer.read_image()))
            observe(renderer)
        return pictures, results
    finally:
        renderer.release()
        app.renderer = None


@pytest.mark.parametrize("scene", sorted(SCENES))
def test_reloads_that_replace_every_program_keep_the_live_program_count_and_the_pictures(monkeypatch, scene):
    """Each reload sees every shader file edited (a comment appended to what shader_source reads: the same code,
    new programs).  Before, every replaced program stayed alive (reload_shaders dropped it from its table but
    not from the renderer's source cache, nor released it): each reload of the demo left 18 programs more.  The
    pictures are those of a run without reloads: the features that kept a vertex array made on the old program
    (water wireframe, toon smoke, HUD, dust devil) drew with it, the uniforms they set on the new one unseen."""
    from engine.render.passes import HudFeature

    monkeypatch.setattr(HudFeature, "_fps_line", lambda self: "FPS  60.0")  # the measured rate is not compared
    original = renderer_module.shader_source
    reference, _ = _pictures(scene, lambda renderer: [])

    live = track_gl_objects(monkeypatch)
    edit = {"n": 0}
    monkeypatch.setattr(renderer_module, "shader_source",
                        lambda path, depth=0: original(path, depth) + f"\n// edit {edit['n']}\n")

    def reload(renderer):
        loaded = dict(renderer._loaded)
        edit["n"] += 1
        errors = renderer.reload_shaders()
        assert all(renderer.load_program(*key) is not prog for key, prog in loaded.items())  # every one replaced
        return errors

    counts = []
    pictures, results = _pictures(scene, reload, lambda renderer: counts.append(live().get("program", 0)))
    assert results == [[], [], []]
    assert counts[0] >= 3  # the scene's programs: the comparison means something
    assert counts == counts[:1] * 4, f"live programs after the first frames and after each reload's frames: {counts}"
    for frame, (got, want) in enumerate(zip(pictures, reference)):
        assert np.array_equal(got, want), f"frame {frame} differs from the run without reloads"
    assert pictures[0].std() > 10 and not np.array_equal(pictures[0], pictures[-1])  # drawn, and moving


def _flat_shaders(folder, value: str) -> None:
    (folder / "flat.vert").write_text("#version 330\nvoid main() {\n"
                                      "    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);\n"
                                      "    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);\n}\n")
    (folder / "flat.frag").write_text("#version 330\nout vec4 frag;\nvoid main() { frag = vec4(%s); }\n" % value)


def _pixel(renderer, vao) -> list[int]:
    ctx = renderer.ctx
    target = ctx.texture((4, 4), 4)
    fbo = ctx.framebuffer(target)
    fbo.use()
    fbo.clear(0.0, 0.0, 0.0, 0.0)
    ctx.disable(moderngl.DEPTH_TEST | moderngl.BLEND)
    vao.render(moderngl.TRIANGLES, vertices=3)
    pixel = np.frombuffer(fbo.read(components=4), np.uint8).reshape(4, 4, 4)[2, 2].tolist()
    fbo.release(), target.release()
    return pixel


def test_a_replaced_program_a_vertex_array_still_uses_is_kept_until_that_array_is_released(tmp_path):
    """A feature that does not remake its vertex array keeps drawing the old shader, safely: the program is
    released only after the array (moderngl's vertex array holds the program until released, which the renderer
    counts)."""
    _flat_shaders(tmp_path, "1.0, 0.0, 0.0, 1.0")
    app = App("configs/scenes/sandbox.toml")
    renderer = make_renderer(app, 32, 32)
    try:
        old = renderer.load_program(tmp_path, "flat")
        stale = renderer.ctx.vertex_array(old, [])
        _flat_shaders(tmp_path, "0.0, 1.0, 0.0, 1.0")
        assert renderer.reload_shaders() == []
        new = renderer.load_program(tmp_path, "flat")
        assert new is not old
        for _ in range(2):
            app.step(1)
            app.render_frame()
        assert not isinstance(old.mglo, moderngl.InvalidObject)  # still held by ``stale``
        assert _pixel(renderer, stale) == [255, 0, 0, 255]  # and still draws the old shader
        current = renderer.ctx.vertex_array(new, [])
        assert _pixel(renderer, current) == [0, 255, 0, 255]
        current.release()
        stale.release()
        app.step(1)
        app.render_frame()
        assert isinstance(old.mglo, moderngl.InvalidObject)  # released at the end of the next frame
        _flat_shaders(tmp_path, "1.0, 0.0, 0.0, 1.0")  # the old text again: compiled anew, not the released one
        assert renderer.reload_shaders() == []
        again = renderer.load_program(tmp_path, "flat")
        assert again is not old and not isinstance(again.mglo, moderngl.InvalidObject)
    finally:
        renderer.release()
        app.renderer = None


def test_the_renderer_counts_the_vertex_arrays_made_on_a_program(tmp_path):
    """What Renderer._vertex_arrays_on reads: moderngl's vertex array holds its program's internal object from
    ctx.vertex_array to release (with or without buffers and an index buffer)."""
    _flat_shaders(tmp_path, "1.0")
    app = App("configs/scenes/sandbox.toml")
    renderer = make_renderer(app, 32, 32)
    ctx = renderer.ctx
    try:
        prog = renderer.load_program(tmp_path, "flat")
        buffers = ctx.buffer(reserve=64), ctx.buffer(np.arange(3, dtype=np.uint32).tobytes())
        arrays = [ctx.vertex_array(prog, []), ctx.vertex_array(prog, [], buffers[1], 4),
                  ctx.vertex_array(prog, [(buffers[0], "2f", "unused")], skip_errors=True)]
        assert renderer._vertex_arrays_on(prog) == 3
        for left, vao in zip((2, 1, 0), arrays):
            vao.release()
            assert renderer._vertex_arrays_on(prog) == left
        for buf in buffers:
            buf.release()
    finally:
        renderer.release()
        app.renderer = None


def test_a_program_handed_out_by_source_is_never_released_by_a_reload(tmp_path):
    """Renderer.program's callers may keep the program itself (the grass keeps its own per variant): one that a
    loaded shader shares (the same text) is not released when the file is edited."""
    _flat_shaders(tmp_path, "1.0")
    app = App("configs/scenes/sandbox.toml")
    renderer = make_renderer(app, 32, 32)
    try:
        loaded = renderer.load_program(tmp_path, "flat")
        kept = renderer.program((tmp_path / "flat.vert").read_text(), (tmp_path / "flat.frag").read_text())
        assert kept is loaded
        _flat_shaders(tmp_path, "0.5")
        assert renderer.reload_shaders() == [] and renderer.load_program(tmp_path, "flat") is not kept
        app.step(1)
        app.render_frame()
        assert not isinstance(kept.mglo, moderngl.InvalidObject)
        vao = renderer.ctx.vertex_array(kept, [])
        assert _pixel(renderer, vao) == [255, 255, 255, 255]
        vao.release()
    finally:
        renderer.release()
        app.renderer = None
