"""Headless rendering of the energy wave: golden images, every preset draws, GPU expansion of M and N sprites."""

from pathlib import Path

import numpy as np
import pytest

from engine.app import App
from systems.energy_wave.extract import extract_frame, pack_emitter
from tests.render_utils import assert_golden, render_app

from .helpers import add_box, add_emitter, make_app

ROOT = Path(__file__).resolve().parents[3]
PRESETS = sorted(p.stem for p in (ROOT / "configs" / "effects" / "energy_wave").glob("*.toml"))

SCENE = """
[scene]
seed = 5
plugins = ["render", "energy_wave"]
[render]
sky_top = [0.02, 0.03, 0.08]
sky_horizon = [0.06, 0.07, 0.12]
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "orbit"
target = [0.0, 1.0, -0.8]
distance = 3.2
yaw = 30.0
pitch = -10.0
[[entities]]
name = "wall"
[entities.components.Transform]
position = [0.0, 1.0, -1.15]
scale = [3.0, 2.2, 0.3]
[entities.components.Collider]
shape = "box"
[entities.components.Mesh]
shape = "box"
color = [0.3, 0.3, 0.34]
[[entities]]
name = "emitter"
[entities.components.Transform]
position = [0.0, 1.0, 1.2]
[entities.components.EnergyWaveEmitter]
preset = "energy_wave/{preset}"
{extra}
"""


def scene_app(tmp_path, preset: str, extra: str = "") -> App:
    path = tmp_path / "energy_wave_scene.toml"
    path.write_text(SCENE.format(preset=preset, extra=extra), encoding="utf-8")
    return App(path, configs_root=ROOT / "configs")


def _render(tmp_path, preset, steps=70, size=(160, 120), extra=""):
    app = scene_app(tmp_path, preset, extra)
    app.step(steps)
    return np.asarray(render_app(app, width=size[0], height=size[1], frames=1), np.float32), app


@pytest.mark.parametrize("preset", ["reference", "pattern_c", "pattern_g"])
def test_golden_images(tmp_path, preset):
    app = scene_app(tmp_path, preset)
    app.step(70)
    image = render_app(app, width=160, height=120, frames=1)
    assert_golden(image, f"energy_wave_{preset}")


def test_every_preset_renders_a_visible_wave(tmp_path):
    dark, _ = _render(tmp_path, "reference", steps=1, size=(64, 48), extra="emitting = false")
    for preset in PRESETS:
        # presets fired in bursts by scripts (emitting = false) are shown emitting continuously here
        image, _ = _render(tmp_path, preset, steps=60, size=(64, 48), extra="emitting = true")
        glow = image.mean(axis=2) - dark.mean(axis=2)
        assert (glow > 60).sum() > 20, preset  # plenty of pixels much brighter than the empty scene
        assert image.max() > 200, preset


def test_glow_pass_adds_a_halo(tmp_path):
    plain, _ = _render(tmp_path, "reference", size=(96, 72), extra="glow = 0.0")
    glowing, _ = _render(tmp_path, "reference", size=(96, 72), extra="glow = 2.0")
    assert glowing.mean() > plain.mean() + 2.0


def test_occluded_particles_are_hidden(tmp_path):
    """A box filling the view in front of the camera hides the whole wave, glow included (depth test)."""
    blocker = """
[[entities]]
name = "blocker"
[entities.components.Transform]
position = [1.36, 1.47, 1.57]
scale = [3.0, 3.0, 0.1]
[entities.components.Mesh]
shape = "box"
color = [0.2, 0.2, 0.2]
"""
    visible, _ = _render(tmp_path, "reference", size=(64, 48))
    no_wave, _ = _render(tmp_path, "reference", size=(64, 48), extra="emitting = false")
    hidden, _ = _render(tmp_path, "reference", size=(64, 48), extra=blocker)
    blocker_only, _ = _render(tmp_path, "reference", size=(64, 48), extra="emitting = false\n" + blocker)
    assert np.abs(visible - no_wave).max() > 100  # without the blocker the wave shows
    assert np.abs(hidden - blocker_only).max() <= 2  # behind it, nothing of the wave reaches the image


def test_cpu_records_do_not_grow_with_m_or_n():
    sizes = []
    for samples in (1, 5, 64):
        app = make_app(8)
        add_box(app, (0.0, 0.0, -1.2), (2.0, 2.0, 0.2))
        entity, cfg, st = add_emitter(app, splash_samples=samples, trail_textures=samples, continuity_probability=0.5)
        app.step(50)
        records, counts = pack_emitter(cfg, st)
        assert records.shape == (st.particles.count, 12) and sum(counts) == st.particles.count
        frame = extract_frame(app.world)
        single, trail, bar = counts
        assert frame.sprites() == single + samples * (trail + bar)
        sizes.append(records.nbytes / st.particles.count)
    assert sizes[0] == sizes[1] == sizes[2]  # one record per particle whatever M and N


def _expand_on_gpu(mode, sprites, records, roundness=0.5, spacing=0.4, size=1.0, trail_end=0.4):
    """Run particles.vert with transform feedback: the world-space corners of every sprite it expands.

    With view_proj = identity and the camera axes = world x and y, corner k of sprite j is centre ± size."""
    import moderngl

    from systems.energy_wave.render import RECORDS_PER_ROW, SHADERS
    from tests.render_utils import gl_context

    ctx = gl_context()
    prog = ctx.program(vertex_shader=(SHADERS / "particles.vert").read_text(), varyings=["gl_Position"])
    data = np.zeros((RECORDS_PER_ROW, 12), np.float32)
    data[: len(records)] = records
    tex = ctx.texture((RECORDS_PER_ROW * 3, 1), 4, data.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.use(0)
    values = dict(records=0, records_per_row=RECORDS_PER_ROW, camera_right=(1.0, 0.0, 0.0),
                  camera_up=(0.0, 1.0, 0.0), first=0, sprites=sprites, mode=mode, size=size,
                  spacing=spacing * size, roundness=roundness, trail_end=trail_end)
    for name, value in values.items():
        if name in prog:
            prog[name].value = value
    prog["view_proj"].write(np.eye(4, dtype=np.float32).tobytes())
    vao = ctx.vertex_array(prog, [])  # corners from gl_VertexID: 4 a sprite (the draw indexes them as two triangles)
    out = ctx.buffer(reserve=len(records) * sprites * 4 * 16)
    fbo = ctx.simple_framebuffer((1, 1))  # a draw, even with rasterization off, needs a complete framebuffer
    fbo.use()
    vao.transform(out, mode=moderngl.POINTS, vertices=4 * len(records) * sprites)
    corners = np.frombuffer(out.read(), np.float32).reshape(len(records), sprites, 4, 4)[..., :3]
    for obj in (vao, out, fbo, tex, prog):
        obj.release()
    return corners.mean(axis=2), (corners[:, :, 3, 0] - corners[:, :, 0, 0]) / 2.0  # centres, sizes


def _record(position, hit=(0.0, 0.0, 0.0), direction=(1.0, 0.0, 0.0), alpha=1.0):
    return np.array([*position, alpha, *hit, 0.0, *direction, 0.0], np.float32)


def test_gpu_bars_follow_eq_3_8_and_tips_eq_3_9():
    from systems.energy_wave.simulate import bar_offsets, bar_sizes

    q = np.array([1.0, 2.0, 3.0])
    d = np.array([0.0, 0.6, 0.8])
    for n, t in [(12, 1.0), (12, 0.1), (24, 0.01), (5, 0.5)]:
        centres, sizes = _expand_on_gpu(2, n, [_record(q, direction=d)], roundness=t, spacing=0.4, size=0.5)
        expected = q + bar_offsets(n, 0.4 * 0.5)[:, None] * d
        np.testing.assert_allclose(centres[0], expected, atol=1e-5)
        np.testing.assert_allclose(sizes[0], 0.5 * bar_sizes(n, t), atol=1e-5)
        if t == 1.0:
            assert np.ptp(sizes[0]) < 1e-6  # round: every sprite of size S
        else:
            assert np.all(np.diff(sizes[0]) < 0)  # sharp: shrinking towards the tips


def test_gpu_trails_follow_eq_3_7():
    from systems.energy_wave.simulate import trail_fractions, trail_sizes

    p0, p1 = np.array([0.0, 0.0, 0.0]), np.array([2.0, -1.0, 0.5])
    centres, sizes = _expand_on_gpu(1, 8, [_record(p1, hit=p0)], size=0.2, trail_end=0.4)
    np.testing.assert_allclose(centres[0], p0 + trail_fractions(8)[:, None] * (p1 - p0), atol=1e-5)
    np.testing.assert_allclose(sizes[0], 0.2 * trail_sizes(8, 0.4), atol=1e-5)
    centres, sizes = _expand_on_gpu(0, 1, [_record(p1, hit=p0), _record(p0)], size=0.2)
    np.testing.assert_allclose(centres[:, 0], [p1, p0], atol=1e-6)  # single sprites sit on the particle


def test_rendering_does_not_change_the_state(tmp_path):
    rendered = scene_app(tmp_path, "reference")
    plain = scene_app(tmp_path, "reference")
    rendered.step(30)
    render_app(rendered, width=48, height=32, frames=5)
    plain.step(35)
    assert rendered.state_hash() == plain.state_hash()


@pytest.mark.parametrize("extra", ["", "glow = 0.0", "glow_radius = 6.0\nparticle_size = 0.2"])
def test_scissored_passes_give_the_full_screen_image(tmp_path, monkeypatch, extra):
    """The passes limited to the sprites' screen rectangle (grown by the glow's reach) draw the same image as the
    passes over the whole view (sprite bounds replaced by the whole view)."""
    from systems.energy_wave import render

    scissored, app = _render(tmp_path, "reference", size=(160, 120), extra=extra)
    data = extract_frame(app.world)
    monkeypatch.setattr(render, "sprite_bounds", lambda *args: (0.0, 0.0, 1.0, 1.0))
    full, _ = _render(tmp_path, "reference", size=(160, 120), extra=extra)
    assert np.array_equal(scissored, full)
    assert len(data.records) > 100


def test_sprite_bounds_enclose_every_sprite_corner():
    """Sprite bounds against the corners of every sprite expanded on the GPU (trails, bars, singles)."""
    from systems.energy_wave.extract import EmitterDraw, FrameData
    from systems.energy_wave.render import sprite_bounds

    app = make_app(8)
    add_box(app, (0.0, 0.0, -1.2), (2.0, 2.0, 0.2))
    _, cfg, st = add_emitter(app, splash_samples=6, trail_textures=4, continuity_probability=0.5,
                             splash_roundness=0.2, bar_spacing=1.5)
    app.step(40)
    records, counts = pack_emitter(cfg, st)
    data = FrameData(records, [EmitterDraw(0, counts, cfg)])
    eye = np.array([0.6, 0.3, 2.5])
    forward = -eye / np.linalg.norm(eye)
    right = np.cross(forward, [0.0, 1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    view = np.eye(4)
    view[0, :3], view[1, :3], view[2, :3] = right, up, -forward
    view[:3, 3] = -view[:3, :3] @ eye
    f, near, far = 1.0 / np.tan(np.radians(30.0)), 0.1, 50.0
    proj = np.array([[f, 0, 0, 0], [0, f, 0, 0], [0, 0, (far + near) / (near - far), 2 * far * near / (near - far)],
                     [0, 0, -1, 0]])
    view_proj = (proj @ view).astype(np.float32)
    u0, v0, u1, v1 = sprite_bounds(data, view_proj, right, up)
    corners = []
    single, trail, bar = counts
    for mode, sprites, rows in ((0, 1, slice(0, single)), (1, cfg.trail_textures, slice(single, single + trail)),
                                (2, cfg.splash_samples, slice(single + trail, None))):
        if len(records[rows]):
            centres, sizes = _expand_on_gpu(mode, sprites, records[rows], roundness=cfg.splash_roundness,
                                            spacing=cfg.bar_spacing, size=cfg.particle_size,
                                            trail_end=cfg.trail_end_scale)
            for a in (-1.0, 1.0):
                for b in (-1.0, 1.0):
                    corners.append((centres + (a * right + b * up) * sizes[..., None]).reshape(-1, 3))
    corners = np.concatenate(corners)
    clip = np.c_[corners, np.ones(len(corners))] @ view_proj.T.astype(np.float64)
    uv = clip[:, :2] / clip[:, 3:] * 0.5 + 0.5
    assert min(trail, bar) > 0
    assert (uv[:, 0] >= u0 - 1e-6).all() and (uv[:, 0] <= u1 + 1e-6).all()
    assert (uv[:, 1] >= v0 - 1e-6).all() and (uv[:, 1] <= v1 + 1e-6).all()
    assert u1 - u0 < 1.5 * np.ptp(uv[:, 0]) and v1 - v0 < 1.5 * np.ptp(uv[:, 1])  # and not much larger


def _points_on_gpu(mode, sprites, records, point_scale, roundness=0.5, spacing=0.4, size=1.0, trail_end=0.4,
                   view_proj=None):
    """Run particles.vert's POINTS variant with transform feedback: each sprite's clip position and point size."""
    import moderngl

    from engine.render.renderer import _with_defines
    from systems.energy_wave.render import RECORDS_PER_ROW, SHADERS
    from tests.render_utils import gl_context

    ctx = gl_context()
    prog = ctx.program(vertex_shader=_with_defines((SHADERS / "particles.vert").read_text(), ("POINTS",)),
                       varyings=["gl_Position", "gl_PointSize", "v_alpha"])
    data = np.zeros((RECORDS_PER_ROW, 12), np.float32)
    data[: len(records)] = records
    tex = ctx.texture((RECORDS_PER_ROW * 3, 1), 4, data.tobytes(), dtype="f4")
    tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
    tex.use(0)
    values = dict(records=0, records_per_row=RECORDS_PER_ROW, first=0, sprites=sprites, mode=mode, size=size,
                  spacing=spacing * size, roundness=roundness, trail_end=trail_end, point_scale=point_scale)
    for name, value in values.items():
        if name in prog:
            prog[name].value = value
    m = np.eye(4, dtype=np.float32) if view_proj is None else view_proj
    prog["view_proj"].write(m.T.astype(np.float32).tobytes())
    vao = ctx.vertex_array(prog, [])
    out = ctx.buffer(reserve=len(records) * sprites * 6 * 4)
    fbo = ctx.simple_framebuffer((1, 1))
    fbo.use()
    vao.transform(out, mode=moderngl.POINTS, vertices=len(records) * sprites)
    result = np.frombuffer(out.read(), np.float32).reshape(len(records), sprites, 6)
    for obj in (vao, out, fbo, tex, prog):
        obj.release()
    return result[..., :4], result[..., 4], result[..., 5]


def test_point_sprites_follow_the_same_equations_as_the_quads():
    """POINTS variant: one vertex a sprite at the quad's centre (eqs. 3.7, 3.8), point size = the quad's projected
    side (eq. 3.9 sizes times point_scale / w); a sprite under a pixel is a one-pixel point with its area's share."""
    q, d = np.array([1.0, 2.0, 3.0]), np.array([0.0, 0.6, 0.8])
    for mode, n, record in ((2, 12, _record(q, direction=d, alpha=0.7)), (1, 8, _record(q, hit=(0.0, 0.0, 0.0))),
                            (0, 1, _record(q))):
        centres, sizes = _expand_on_gpu(mode, n, [record], roundness=0.1, spacing=0.4, size=0.5)
        clip, points, alpha = _points_on_gpu(mode, n, [record], point_scale=20.0, roundness=0.1, spacing=0.4,
                                             size=0.5)
        np.testing.assert_allclose(clip[0, :, :3], centres[0], atol=1e-5)
        np.testing.assert_allclose(points[0], 20.0 * sizes[0], atol=1e-4)  # side = 2 × half-size × 10 at w = 1
        np.testing.assert_allclose(alpha[0], record[3])  # every side > 1 pixel: alpha untouched
    # perspective: the side shrinks as 1 / w, as the projected quad does
    proj = np.array([[1.5, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.0, -0.2], [0, 0, -1.0, 0]], np.float32)
    clip, points, alpha = _points_on_gpu(0, 1, [_record((0.3, -0.2, -4.0))], point_scale=2.0 * 60, size=0.25,
                                         view_proj=proj)
    assert abs(clip[0, 0, 3] - 4.0) < 1e-6
    assert abs(points[0, 0] - 0.25 * 2.0 * 60 / 4.0) < 1e-4  # s · P11 · H / w pixels
    # under a pixel: side 0.4 -> a one-pixel point carrying 0.4² of the alpha
    clip, points, alpha = _points_on_gpu(0, 1, [_record(q, alpha=0.5)], point_scale=0.8, size=0.5)
    assert points[0, 0] == 1.0 and abs(alpha[0, 0] - 0.5 * 0.4 ** 2) < 1e-6


def test_point_sprites_draw_the_quads_picture_and_fall_back_for_large_sprites(tmp_path):
    from systems.energy_wave.render import largest_sprite_pixels
    from tests.render_utils import make_renderer

    pictures, paths = {}, {}
    for name, points, limit in (("points", True, None), ("quads", False, None), ("fallback", True, 1.0)):
        app = scene_app(tmp_path, "reference")
        app.step(70)
        renderer = make_renderer(app, 240, 180)
        feature = next(f for f in renderer.features if f.name == "energy_wave")
        feature.point_sprites = points
        driver_limit = feature.max_point_size  # GL_POINT_SIZE_RANGE's upper end
        if limit is not None:
            feature.max_point_size = limit  # every sprite is larger: the frame draws quads
        try:
            app.render_frame()
            pictures[name] = np.asarray(renderer.read_image(), np.int16)
            paths[name] = feature.last_sprite_path
            largest = largest_sprite_pixels(feature.extract(app.world), renderer.views[0].view_proj, 90)
        finally:
            renderer.release()
            app.renderer = None
    assert paths == {"points": "points", "quads": "quads", "fallback": "quads"}
    assert 1.0 < largest < driver_limit
    diff = np.abs(pictures["points"] - pictures["quads"])
    assert diff.mean() < 0.05 and diff.max() <= 16  # the same squares; only rounding differs
    assert np.array_equal(pictures["fallback"], pictures["quads"])
    assert (pictures["quads"].mean(axis=2) > 150).sum() > 500  # the splash is there, not only the beam


@pytest.mark.parametrize("keep_depth", [True, False])
def test_over_a_kept_static_layer_only_the_waves_rectangle_is_tone_mapped_and_the_bits_stay(tmp_path, keep_depth):
    """A still camera: the wall and the sky come back from the renderer's static layer, and the present copies
    that layer's tone-mapped picture and tone-maps only the composite's rectangle (where the wave and its glow
    can be).  The half-resolution depth is copied on the first restored frame and kept for the next ones
    (keep_half_depth; off: copied every frame).  Every frame is the same bits as with [render]
    static_layer_cache off."""
    from tests.render_utils import make_renderer

    def run(cache: bool):
        app = scene_app(tmp_path, "reference")
        app.config.render.static_layer_cache = cache
        app.step(40)
        renderer = make_renderer(app, 160, 120)
        feature = next(f for f in renderer.features if f.name == "energy_wave")
        feature.keep_half_depth = keep_depth
        pictures, regions = [], []
        try:
            for _ in range(6):
                app.step(1)
                before = feature.depth_copies
                app.render_frame()
                copies.append(feature.depth_copies - before)
                pictures.append(np.asarray(renderer.read_image()))
                regions.append(renderer.views[0].extra["present_region"])
                restores.append(renderer.views[0].extra.get("restore", {}).get("color"))
        finally:
            renderer.release()
            app.renderer = None
        return pictures, regions

    restores, copies = [], []
    cached, regions = run(True)
    # restored frames: only the wave's layer, folded into the tone map, wrote the colour, so the present reads the
    # kept colour and the restore copies only the depth
    assert restores == [None] * 3 + [False] * 3
    assert copies == ([1] * 4 + [0] * 2 if keep_depth else [1] * 6)  # drawn, drawn, stored, restored x 3
    copies.clear()
    plain, whole = run(False)
    assert copies == [1] * 6
    assert whole == [None] * 6
    assert regions[:3] == [None] * 3 and all(r is not None for r in regions[3:])  # drawn, drawn, stored, restored
    assert all(0 < r[2] * r[3] < 160 * 120 for r in regions[3:])
    for a, b in zip(cached, plain):
        assert np.array_equal(a, b)


SECOND_EMITTER = """
[[entities]]
name = "emitter2"
[entities.components.Transform]
position = [0.5, 1.3, 1.2]
[entities.components.EnergyWaveEmitter]
preset = "energy_wave/reference"
color = [1.0, 0.35, 0.2]
"""


@pytest.mark.parametrize("extra", ["", SECOND_EMITTER])
def test_one_colour_pair_draws_two_channel_buffers_with_the_rgb_picture(tmp_path, extra):
    """One colour pair in the view: the buffers hold the weights Σ g·I and Σ g³·I (two channels) and the layer's
    matrix applies the colours; the picture is the RGB buffers' within rounding.  Two pairs: RGB buffers."""
    from tests.render_utils import make_renderer

    pictures, channels = {}, {}
    for pairs in (True, False):
        app = scene_app(tmp_path, "reference", extra)
        app.step(70)
        renderer = make_renderer(app, 200, 150)
        feature = next(f for f in renderer.features if f.name == "energy_wave")
        feature.colour_pairs = pairs
        try:
            app.render_frame()
            pictures[pairs] = np.asarray(renderer.read_image(), np.int16)
            channels[pairs] = feature.last_channels
        finally:
            renderer.release()
            app.renderer = None
    assert channels == ({True: 2, False: 3} if not extra else {True: 3, False: 3})
    diff = np.abs(pictures[True] - pictures[False])
    assert diff.max() <= 1
    if not extra:
        assert (pictures[True].mean(axis=2) > 150).sum() > 300  # the splash is there
    else:
        assert np.array_equal(pictures[True], pictures[False])  # the same path


def test_the_composite_is_folded_into_the_tone_map_with_the_same_picture(tmp_path):
    """Nothing is drawn over the wave: the view's tone map adds its layer and the composite pass draws nothing;
    the picture is the composite pass's within rounding (the pass rounds the sum to half floats)."""
    from tests.render_utils import make_renderer

    pictures, folded = {}, {}
    for fold in (True, False):
        app = scene_app(tmp_path, "reference")
        app.step(70)
        renderer = make_renderer(app, 200, 150)
        renderer.fold_color_layers = fold
        try:
            app.render_frame()
            pictures[fold] = np.asarray(renderer.read_image(), np.int16)
            layer = renderer.views[0].extra["color_layer"][0]
            folded[fold] = layer.folded
        finally:
            renderer.release()
            app.renderer = None
    assert folded == {True: True, False: False}
    diff = np.abs(pictures[True] - pictures[False])
    assert diff.max() <= 1 and (pictures[True].mean(axis=2) > 150).sum() > 300


def _bilinear_1d(signal: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Linear filtering of a 1-D texture (texel k centred at k + 0.5) at texel coordinates ``x``, clamped."""
    t = x - 0.5
    k = np.floor(t).astype(int)
    f = t - k
    last = len(signal) - 1
    return (1.0 - f) * signal[np.clip(k, 0, last)] + f * signal[np.clip(k + 1, 0, last)]


@pytest.mark.parametrize("radius", [0.5, 1.0, 2.0, 3.0, 4.5, 8.0])
@pytest.mark.parametrize("ratio", [1, 2])
def test_paired_blur_taps_sum_what_the_nine_bilinear_taps_sum(radius, ratio):
    """blur_taps' paired fetches against the nine taps of glow_blur.frag, each filtered bilinearly, on a random
    signal (the edges clamped, as the buffers are): the same values; radius 2 needs 5 fetches downsampling from
    the particle buffer and 3 along y."""
    from systems.energy_wave.render import GAUSS_9, blur_taps

    rng = np.random.default_rng(7)
    target = 40
    signal = rng.random(target * ratio)
    centres = (np.arange(target) + 0.5) * ratio  # output pixel centres in source texels
    step = radius / 4.0 * ratio
    reference = sum(GAUSS_9[abs(j)] * _bilinear_1d(signal, centres + j * step) for j in range(-4, 5))
    offsets, weights = blur_taps(radius, target * ratio, target)
    paired = sum(w * _bilinear_1d(signal, centres + o) for o, w in zip(offsets, weights))
    assert np.allclose(paired, reference, rtol=0, atol=1e-12)
    assert len(offsets) <= 9
    if radius == 2.0:
        assert len(offsets) == (5 if ratio == 2 else 3)


def test_blur_taps_fall_back_to_nine_when_the_grids_do_not_line_up():
    from systems.energy_wave.render import blur_taps

    offsets, weights = blur_taps(2.0, 639, 319)
    assert len(offsets) == 9 and np.isclose(weights.sum(), 1.0)
    assert np.allclose(offsets, np.arange(-4, 5) * 0.5 * 639 / 319)


def _bilinear_2d(image: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """``image`` (rows, columns, channels) filtered linearly at the grid ``ys`` × ``xs`` (texel coordinates),
    clamped at the edges."""
    for axis, x in ((0, ys), (1, xs)):
        t = x - 0.5
        k = np.floor(t).astype(int)
        f = np.expand_dims(t - k, tuple(a for a in range(3) if a != axis))
        last = image.shape[axis] - 1
        image = ((1.0 - f) * np.take(image, np.clip(k, 0, last), axis=axis)
                 + f * np.take(image, np.clip(k + 1, 0, last), axis=axis))
    return image


def test_the_glow_buffer_is_the_nine_tap_gaussian_of_the_particle_buffer(tmp_path, monkeypatch):
    """The glow the bloom adds (blur_y, read back when glow_add runs) against the nine bilinear taps per axis of
    glow_blur.frag computed here from the particle buffer: the paired fetches (160 x 120: buffers 80 x 60 and
    40 x 30, the grids line up) give the same buffer; the passes cover whole targets (bounds = the view)."""
    from systems.energy_wave import render

    seen = {}

    def spy(renderer, target, texture, matrix, region):
        seen["particles"] = np.frombuffer(target.read(), np.float32).reshape(target.height, target.width, -1)
        seen["glow"] = np.frombuffer(texture.read(), np.float32).reshape(texture.height, texture.width, -1)
        return add_texture(renderer, target, texture, matrix, region)

    add_texture = render.add_texture
    monkeypatch.setattr(render, "add_texture", spy)
    monkeypatch.setattr(render, "sprite_bounds", lambda *args: (0.0, 0.0, 1.0, 1.0))
    radius = 3.0
    _render(tmp_path, "reference", extra=f"glow_radius = {radius}")
    particles, glow = seen["particles"].astype(np.float64), seen["glow"]
    assert particles.shape[:2] == (60, 80) and glow.shape[:2] == (30, 40) and particles.max() > 0.1
    weights = [render.GAUSS_9[abs(j)] for j in range(-4, 5)]
    centre_x, centre_y = (np.arange(40) + 0.5) * 2, (np.arange(30) + 0.5) * 2  # glow texels in particle texels
    blur_x = sum(w * _bilinear_2d(particles, centre_x + j * radius / 2, centre_y) for j, w in zip(range(-4, 5), weights))
    rows = np.arange(30) + 0.5
    expected = sum(w * _bilinear_2d(blur_x, np.arange(40) + 0.5, rows + j * radius / 4)
                   for j, w in zip(range(-4, 5), weights))
    assert np.abs(glow - expected).max() <= 1e-4 * particles.max()
    assert render.blur_taps(radius, 80, 40)[0].size < 9 and render.blur_taps(radius, 30, 30)[0].size < 9


def test_the_half_depth_kept_for_a_camera_goes_with_the_camera(tmp_path, monkeypatch):
    """The half-resolution depth kept per camera (keep_half_depth) is released when the camera is despawned, with
    the framebuffer the renderer made for it; it stayed, one depth texture and one framebuffer per camera gone."""
    from tests.render_utils import gl_objects_per_respawn, track_gl_objects

    live = track_gl_objects(monkeypatch)
    app = scene_app(tmp_path, "reference")
    app.step(10)
    counts = gl_objects_per_respawn(app, "camera", live, cycles=3, frames=5)  # drawn, drawn, stored, restored x 2
    assert counts[1:] == counts[:1] * (len(counts) - 1)
