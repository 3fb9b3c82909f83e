"""Sun shadows ([render] shadows): where they fall, what receives them, when the map is redrawn, opt-outs, the
light box's fit, receiver culling."""

import numpy as np
import pytest

from engine.app import App
from engine.builtin import find_named
from engine.render.feature import View
from engine.render.shadows import fit_light, frustum_sphere, light_basis, may_be_shadowed
from engine.spatial import Transform
from tests.render_utils import make_renderer
from tests.render_utils import world_pixel as _pixel

SUN = (0.5, 1.0, 0.0)  # a box centred 2 m up throws its shadow centre 1 m towards -x


def _scene(tmp_path, ground: str = "terrain", box: bool = True, render: str = "", camera: str = "",
           box_extra: str = "") -> str:
    grounds = {
        "terrain": """[entities.components.Transform]
[entities.components.Terrain]
size_exponent = 4
spacing = 1.0
amplitude = 0.0
colors = [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]
""",
        "plane": """[entities.components.Transform]
scale = [16.0, 1.0, 16.0]
[entities.components.Mesh]
shape = "plane"
color = [0.5, 0.5, 0.5]
""",
    }
    text = f"""[render]
sun_direction = [{SUN[0]}, {SUN[1]}, {SUN[2]}]
fog_density = 0.0
static_layer_cache = false
{render}
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
controller = "top"
projection = "orthographic"
ortho_height = 8.0
distance = 20.0
target = [0.0, 0.0, 0.0]
{camera}
[[entities]]
name = "ground"
{grounds[ground]}
"""
    if box:
        text += f"""
[[entities]]
name = "box"
[entities.components.Transform]
position = [0.0, 2.0, 0.0]
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
{box_extra}
"""
    path = tmp_path / "shadow_scene.toml"
    path.write_text(text)
    return str(path)


def _render(path: str, shadows: bool = True, size=(96, 96)):
    app = App(path)
    app.config.render.shadows = shadows
    renderer = make_renderer(app, *size)
    try:
        app.render_frame()
        order = renderer.graph.compile().order
        return np.asarray(renderer.read_image()).astype(float), renderer.views[0], order, renderer.shadow_draws
    finally:
        renderer.release()
        app.renderer = None


@pytest.mark.parametrize("ground", ["terrain", "plane"])
def test_a_box_shadows_the_ground_where_the_sun_projects_it(tmp_path, ground):
    path = _scene(tmp_path, ground)
    lit, view, order, draws = _render(path, shadows=True)
    plain, _, plain_order, _ = _render(path, shadows=False)
    assert "shadow.view0" in order and "shadow.view0" not in plain_order and draws == 1
    # the box (y 1.5 .. 2.5) projects along the sun onto y = 0 over x in [-1.75, -0.25], z in [-0.5, 0.5]; seen
    # from above the box hides x > -0.5
    shade, sun = _pixel(view, (-1.25, 0.0, 0.0)), _pixel(view, (1.25, 0.0, 0.0))
    assert lit[shade].sum() < 0.75 * plain[shade].sum()  # the sun's light is gone there, the sky's stays
    assert lit[shade].sum() > 0.1 * plain[shade].sum()
    assert np.abs(lit[sun] - plain[sun]).max() <= 1.0
    darker = (plain - lit).sum(axis=-1) > 20.0
    rows, cols = np.nonzero(darker)
    centre = _pixel(view, (-1.1, 0.0, 0.0))  # the visible part's centre: x in [-1.75, -0.5]
    assert 40 < darker.sum() < 600
    assert abs(rows.mean() - centre[0]) < 3 and abs(cols.mean() - centre[1]) < 3


def test_without_casters_there_is_no_shadow_pass_and_the_picture_keeps_its_bits(tmp_path):
    path = _scene(tmp_path, box=False)
    lit, _, order, draws = _render(path, shadows=True)
    plain, _, _, _ = _render(path, shadows=False)
    assert draws == 0 and not any(name.startswith("shadow.") for name in order)
    assert np.array_equal(lit, plain)


def test_opt_outs_camera_and_mesh(tmp_path):
    _, view, order, draws = _render(_scene(tmp_path, camera="shadows = false"))
    assert draws == 0 and "shadow" not in view.extra
    _, view, order, draws = _render(_scene(tmp_path, box_extra="cast_shadows = false"))
    assert draws == 0 and "shadow" not in view.extra  # the box was the only caster (the terrain casts none)


def test_a_still_scene_draws_its_map_once_and_a_moving_caster_redraws_it(tmp_path):
    app = App(_scene(tmp_path))
    renderer = make_renderer(app, 64, 64)
    try:
        for _ in range(3):
            app.render_frame()
        assert renderer.shadow_draws == 1
        assert "shadow.view0" not in renderer.graph.compile().order  # read again, not redrawn
        box = find_named(app.world, "box")
        app.world.get(box, Transform).position[0] += 0.5
        app.render_frame()
        assert renderer.shadow_draws == 2
    finally:
        renderer.release()
        app.renderer = None


def test_receiver_culling_marks_only_what_a_shadow_can_reach():
    basis_sun = np.array([0.0, 1.0, 0.0])  # the sun straight above: shadows fall straight down
    view = _view(np.array([0.0, 10.0, 0.0]))
    from engine.render.shadows import Shadow, light_boxes

    basis = light_basis(basis_sun)
    light_view_proj, matrix, texel, extent = fit_light(view, basis, 50.0, 512, None)
    caster = np.array([[[-0.5, 2.0, -0.5], [0.5, 3.0, 0.5]]])
    shadow = Shadow(None, matrix, light_view_proj, texel, 0.0, 50.0, 512, False, (), basis,
                    light_boxes(basis, caster), extent)
    receivers = np.array([
        [[-1.0, -1.0, -1.0], [1.0, 0.0, 1.0]],  # right below the caster
        [[3.0, -1.0, 3.0], [5.0, 0.0, 5.0]],  # beside it
        [[-1.0, 5.0, -1.0], [1.0, 6.0, 1.0]],  # above it (nearer the sun)
        [[-1.0, -1.0, 900.0], [1.0, 0.0, 902.0]],  # below the light's line but outside the map
    ])
    assert may_be_shadowed(shadow, receivers).tolist() == [True, False, False, False]
    assert may_be_shadowed(None, receivers).tolist() == [False] * 4


def test_the_terrain_draws_the_shadow_lookup_only_on_chunks_a_shadow_reaches(tmp_path):
    path = tmp_path / "big.toml"
    text = open(_scene(tmp_path)).read().replace("size_exponent = 4", "size_exponent = 7")  # 8 x 8 chunks
    path.write_text(text.replace("ortho_height = 8.0", "ortho_height = 130.0"))
    app = App(str(path))
    renderer = make_renderer(app, 64, 64)
    try:
        app.render_frame()
        terrain = next(f for f in renderer.features if f.name == "terrain")
        assert terrain.last_chunks["view0"] == 64 and 0 < terrain.last_shadowed["view0"] <= 4
    finally:
        renderer.release()
        app.renderer = None


def _view(eye: np.ndarray, forward=(0.0, -1.0, 0.0), fov: float = 1.0, ortho: bool = False) -> View:
    from engine.render.components import look_at, perspective

    forward = np.asarray(forward, float)
    up = (0.0, 0.0, -1.0) if abs(forward[1]) > 0.9 else (0.0, 1.0, 0.0)
    view = look_at(eye, eye + forward, up)
    return View("v", 160, 90, view.astype(np.float32), perspective(fov, 160 / 90, 0.1, 500.0).astype(np.float32),
                eye.astype(np.float32), forward.astype(np.float32), 0.1, 500.0, fov, ortho)


def test_the_light_box_keeps_its_size_as_the_camera_turns_and_moves_in_whole_texels():
    sun = np.array([0.4, 0.8, 0.3])
    turned = [_view(np.array([5.0, 3.0, 2.0]), (np.cos(a), -0.3, np.sin(a))) for a in np.linspace(0.0, 3.0, 7)]
    radii = [frustum_sphere(v, 40.0)[1] for v in turned]
    assert max(radii) - min(radii) < 1e-9
    basis = light_basis(sun)
    a = fit_light(_view(np.array([5.0, 3.0, 2.0]), (1.0, -0.3, 0.0)), basis, 40.0, 1024, None)
    b = fit_light(_view(np.array([5.013, 3.0, 2.0]), (1.0, -0.3, 0.0)), basis, 40.0, 1024, None)
    texel = a[2]
    assert 0.013 < texel  # the camera moved less than a texel, so the box across the light moved 0 or 1 texel
    shift = (b[3] - a[3]) / texel
    assert np.allclose(shift, np.round(shift), atol=1e-6) and np.abs(shift).max() <= 1.0 + 1e-9


@pytest.mark.parametrize("change", [{"shadow_filter": "soft"}, {"shadow_bias": 8.0}])
def test_the_static_layer_is_redrawn_when_a_reload_changes_how_receivers_read_the_map(tmp_path, change):
    """The map stays the same (same light box and casters), but the receivers' filter or normal offset changed:
    a static layer kept from before would show the old shadows."""
    path = _scene(tmp_path, render='shadow_filter = "hard"')
    text = open(path).read().replace("static_layer_cache = false", "static_layer_cache = true")
    open(path, "w").write(text)
    images = []
    for frames_before in (3, 0):
        app = App(path)
        renderer = make_renderer(app, 96, 96)
        try:
            for _ in range(frames_before):
                app.render_frame()
            renderer.use_settings(renderer.settings.model_copy(update=change))
            app.render_frame()
            images.append(np.asarray(renderer.read_image()).astype(int))
        finally:
            renderer.release()
            app.renderer = None
    assert np.abs(images[0] - images[1]).max() <= 1


def test_receiver_culling_does_not_cut_the_filtered_edge_of_a_shadow_at_a_chunk_border(tmp_path, monkeypatch):
    """A box whose shadow ends 5 cm before the border between two terrain chunks (x = 0): the four-tap filter
    and the bilinear comparison spread its edge over about two texels (0.2 m each here), into the next chunk,
    which must take the look-up too.  Culling is an optimisation: the picture is the one without it."""
    import engine.render.passes as passes

    path = _scene(tmp_path, render='shadow_filter = "soft"\nshadow_map_size = 256')
    text = open(path).read().replace("size_exponent = 4", "size_exponent = 5").replace("ortho_height = 8.0",
                                                                                    "ortho_height = 3.0")
    text = text.replace(f"sun_direction = [{SUN[0]}, {SUN[1]}, {SUN[2]}]", "sun_direction = [0.0, 1.0, 0.0]")
    open(path, "w").write(text.replace("position = [0.0, 2.0, 0.0]", "position = [-0.55, 2.0, 0.0]"))
    culled, _, _, _ = _render(path)
    monkeypatch.setattr(passes, "may_be_shadowed", lambda shadow, boxes: np.ones(len(boxes), bool))
    every, _, _, _ = _render(path)
    assert not np.array_equal(every, _render(path, shadows=False)[0])
    assert np.abs(culled - every).max() <= 1.0
