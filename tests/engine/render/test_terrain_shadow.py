"""The terrain's own shadows ([render] terrain_shadows, engine/render/terrain_shadow.py): the shadow-height map
against a ray march, where the shadow falls on the terrain, on meshes and on the grass, and when it is re-made."""

import numpy as np
import pytest
from scipy.ndimage import map_coordinates

from engine.app import App
from engine.builtin import Terrain, find_named
from engine.heightfield import HeightField
from engine.render.terrain_shadow import TerrainShadow, penumbra_height, shadow_heights, sun_in_local, visibility
from tests.render_utils import make_renderer
from tests.render_utils import world_pixel as _pixel


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _ray_march(h: np.ndarray, spacing: float, sun: np.ndarray, step: float = 0.25) -> np.ndarray:
    """The definition of the shadow height, marched over the bilinear surface in steps of ``step`` cells along
    the sun's dominant axis (so that an axis-aligned or diagonal march passes through the grid points)."""
    rows, cols = h.shape
    horizontal = np.hypot(sun[0], sun[2])
    u, tan = np.array([sun[0], sun[2]]) / horizontal, sun[1] / horizontal
    step = step / np.abs(u).max()
    gz, gx = np.meshgrid(np.arange(rows, dtype=float), np.arange(cols, dtype=float), indexing="ij")
    s = h.copy()
    for k in range(1, int(2 * (rows + cols) / step)):
        t = k * step
        px, pz = gx + t * u[0], gz + t * u[1]
        inside = (px >= 0) & (px <= cols - 1) & (pz >= 0) & (pz <= rows - 1)
        if not inside.any():
            break
        ground = map_coordinates(h, [pz, px], order=1, mode="nearest")
        s = np.where(inside, np.maximum(s, ground - t * spacing * tan), s)
    return s


def _hills(n: int = 65) -> np.ndarray:
    x, z = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float))
    return (12.0 * np.exp(-((x - 30) ** 2 + (z - 34) ** 2) / 100.0) + 6.0 * np.exp(-((x - 45) ** 2 + (z - 15) ** 2) / 50.0)
            + 1.5 * np.sin(x / 3.5) * np.cos(z / 4.5))


@pytest.mark.parametrize("sun", [(1, 1, 0), (-1, 0.5, 0), (0, 0.6, 1), (0, 0.4, -1), (1, 0.7, 1), (-1, 0.5, 1)])
def test_axis_aligned_and_diagonal_suns_give_the_ray_marched_shadow_heights_exactly(sun):
    h = np.random.default_rng(4).normal(size=(24, 31)).cumsum(0).cumsum(1) * 0.3  # rough: many shadows
    sun = _unit(sun)
    got = shadow_heights(h, 0.5, sun)
    assert (got >= h).all() and (got > h).mean() > 0.05
    # along an axis or a diagonal the sweep's samples are grid points: the march's finer steps on the bilinear
    # surface can only find the same heights there (and between them on the diagonal, where a cell's bilinear
    # surface may bulge above both ends); on the axes it is the same to rounding
    want = _ray_march(h, 0.5, sun)
    if sun[0] == 0 or sun[2] == 0:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    else:
        assert (got <= want + 1e-9).all()


@pytest.mark.parametrize("sun", [(1, 0.5, 0.3), (-0.3, 0.7, -1), (0.9, 0.25, 0.4), (-1, 0.45, 0.7)])
def test_oblique_suns_stay_within_a_cell_of_the_ray_march_on_smooth_hills(sun):
    h = _hills()
    sun = _unit(sun)
    got, want = shadow_heights(h, 1.0, sun), _ray_march(h, 1.0, sun)
    pen = penumbra_height(1.0, sun)
    lit_got, lit_want = visibility(h, got, pen), visibility(h, want, pen)
    assert (lit_want < 0.5).mean() > 0.02  # the hills do shadow part of the ground
    assert np.abs(lit_got - lit_want).mean() < 0.01
    assert abs((lit_got < 0.5).mean() - (lit_want < 0.5).mean()) < 0.01


@pytest.mark.parametrize("sun", [(0.75, 0.5, 0.3), (1.0, 0.2, 0.5), (-0.3, 0.2, -1.0), (0.4, 0.25, -1.0)])
def test_a_narrow_peaks_shadow_reaches_as_far_as_the_ray_march_says(sun):
    """A 3 x 3 tower 20 high under oblique suns: its shadow is as long as the march's (about 20 / tan θ cells),
    however far that is.  A sweep that takes each column's S from the one before it, interpolated at the step's
    fractional row, blurs the shadow sideways at every step: it lost 35-55 % of the length here."""
    sun = _unit(sun)
    n = 170
    col, row = (150 if sun[0] > 0 else 19), (150 if sun[2] > 0 else 19)  # on the sun's side: room for the shadow
    h = np.zeros((n, n))
    h[row - 1:row + 2, col - 1:col + 2] = 20.0
    got, want = shadow_heights(h, 1.0, sun), _ray_march(h, 1.0, sun)
    pen = penumbra_height(1.0, sun)
    lit_got, lit_want = visibility(h, got, pen), visibility(h, want, pen)

    def reach(lit: np.ndarray) -> float:
        rows, cols = np.nonzero(lit < 0.5)
        return float(np.hypot(rows - row, cols - col).max())

    assert reach(lit_want) > 30.0
    assert abs(reach(lit_got) - reach(lit_want)) < 2.0
    assert abs((lit_got < 0.5).sum() - (lit_want < 0.5).sum()) < 0.2 * (lit_want < 0.5).sum()


def test_overhead_and_below_the_horizon():
    h = _hills(17)
    np.testing.assert_array_equal(shadow_heights(h, 1.0, np.array([0.0, 1.0, 0.0])), h)
    below = shadow_heights(h, 1.0, _unit([1.0, -0.1, 0.0]))
    assert (visibility(h + 100.0, below, 1.0) == 0.0).all()


def test_a_turned_terrain_sees_the_sun_in_its_own_frame():
    turn = np.eye(4)
    turn[:3, :3] = [[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]]  # 90 degrees about y: local x -> world -z
    sun = _unit([0.0, 0.5, -1.0])  # from world -z: from the local +x
    np.testing.assert_allclose(sun_in_local(turn, sun), _unit([1.0, 0.5, 0.0]), atol=1e-12)
    scaled = np.diag([1.0, 2.0, 1.0, 1.0])  # heights doubled: the sun looks half as high in local units
    np.testing.assert_allclose(sun_in_local(scaled, _unit([1.0, 1.0, 0.0])), _unit([1.0, 0.5, 0.0]), atol=1e-12)


# ------------------------------------------------------------------------------------------ rendering
SUN = (1.0, 0.5, 0.0)  # from +x, tan(elevation) = 0.5: a wall 4 m high shadows 8 m of flat ground behind it


def _scene(tmp_path, extra: str = "", render: str = "") -> str:
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
ortho_height = 32.0
distance = 40.0
target = [0.0, 0.0, 0.0]

[[entities]]
name = "ground"
[entities.components.Transform]
[entities.components.Terrain]
size_exponent = 5
spacing = 1.0
amplitude = 0.0
colors = [[0.5, 0.5, 0.5], [0.5, 0.5, 0.5]]
{extra}"""
    path = tmp_path / "terrain_shadow.toml"
    path.write_text(text)
    return str(path)


BOXES = """
[[entities]]
name = "shaded_box"
[entities.components.Transform]
position = [0.0, 0.25, -6.0]
scale = [1.0, 0.5, 1.0]
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
cast_shadows = false
[[entities]]
name = "lit_box"
[entities.components.Transform]
position = [-8.0, 0.25, -6.0]
scale = [1.0, 0.5, 1.0]
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
cast_shadows = false
"""


def _wall(app: App) -> None:
    """A wall 4 m high along z over x in [6, 8] (the 33 x 33 grid is centred: x from -16 to 16)."""
    terrain = app.world.get(find_named(app.world, "ground"), Terrain)
    h = np.zeros((33, 33))
    h[:, 22:25] = 4.0
    terrain.field = HeightField(h, 1.0, terrain.field.origin)


def _render(path: str, on: bool, frames: int = 1, size=(128, 128), setup=_wall):
    app = App(path)
    app.config.render.terrain_shadows = on
    app.config.render.shadows = False  # the sun's shadow map apart: only the terrain's own shadow here
    setup(app)
    renderer = make_renderer(app, *size)
    try:
        for _ in range(frames):
            app.render_frame()
        terrain = next(f for f in renderer.features if f.name == "terrain")
        return np.asarray(renderer.read_image()).astype(float), renderer.views[0], terrain.shadow_builds
    finally:
        renderer.release()
        app.renderer = None


def test_a_wall_shadows_the_ground_behind_it_as_far_as_the_sun_reaches(tmp_path):
    path = _scene(tmp_path)
    on, view, builds = _render(path, True, frames=3)
    off, _, _ = _render(path, False)
    assert builds == 1  # made once, kept while nothing changes
    darker = (off - on).sum(axis=-1) > 15.0
    row = 64
    cols = np.flatnonzero(darker[row])
    # the wall's top edge is at x = 6, the sun falls 0.5 m a metre: the ground is shaded from x = -2 to the
    # wall's foot at x = 5, whose face (turned from the sun) is dark either way; the ground beyond is not
    left, right = _pixel(view, (-2.0, 0.0, 0.0))[1], _pixel(view, (5.0, 0.0, 0.0))[1]
    assert abs(cols.min() - left) <= 4 and abs(cols.max() - right) <= 4
    assert darker[:, :left - 5].sum() == 0 and darker[:, _pixel(view, (8.5, 0.0, 0.0))[1]:].sum() == 0
    shade = _pixel(view, (2.0, 0.0, 0.0))
    assert 0.15 * off[shade].sum() < on[shade].sum() < 0.8 * off[shade].sum()  # the sky's light stays
    np.testing.assert_allclose(on[:, :left - 5], off[:, :left - 5], atol=1.0)


def test_meshes_in_the_terrains_shadow_lose_the_suns_light(tmp_path):
    path = _scene(tmp_path, BOXES)
    on, view, _ = _render(path, True)
    off, _, _ = _render(path, False)
    shaded, lit = _pixel(view, (0.0, 0.5, -6.0)), _pixel(view, (-8.0, 0.5, -6.0))
    assert on[shaded].sum() < 0.8 * off[shaded].sum()
    np.testing.assert_allclose(on[lit], off[lit], atol=1.0)


def test_a_view_that_hides_the_terrain_gets_none_of_its_shadow(tmp_path):
    """Camera hide_features = ["terrain"]: the wall is not drawn there, so it shades nothing there either (as a
    hidden feature casts nothing into the sun's shadow maps)."""
    path = _scene(tmp_path, BOXES)
    with open(path) as f:
        text = f.read()
    with open(path, "w") as f:
        f.write(text.replace("distance = 40.0\n", 'distance = 40.0\nhide_features = ["terrain"]\n'))
    on, view, _ = _render(path, True)
    off, _, _ = _render(path, False)
    assert on[_pixel(view, (0.0, 0.5, -6.0))].sum() > 100.0  # the box behind the wall is drawn
    np.testing.assert_array_equal(on, off)


def test_nothing_changes_where_the_terrain_casts_no_shadow(tmp_path):
    path = _scene(tmp_path, BOXES, render="")
    flat = _render(path, True, setup=lambda app: None)[0]
    plain = _render(path, False, setup=lambda app: None)[0]
    np.testing.assert_array_equal(flat, plain)  # flat ground: no shadow, no look-up, the same bits


def test_the_map_is_remade_when_the_sun_moves(tmp_path):
    path = _scene(tmp_path)
    app = App(path)
    app.config.render.shadows = False
    _wall(app)
    renderer = make_renderer(app, 64, 64)
    try:
        app.render_frame()
        app.render_frame()
        terrain = next(f for f in renderer.features if f.name == "terrain")
        first = renderer.terrain_shadow
        assert terrain.shadow_builds == 1 and first is not None
        renderer.use_settings(renderer.settings.model_copy(update={"sun_direction": (1.0, 0.25, 0.0)}))
        app.render_frame()
        assert terrain.shadow_builds == 2 and renderer.terrain_shadow is not first
        assert first.texture is None  # the old map's texture went back
        renderer.use_settings(renderer.settings.model_copy(update={"terrain_shadows": False}))
        app.render_frame()
        assert renderer.terrain_shadow is None
    finally:
        renderer.release()
        app.renderer = None


def test_the_shader_and_the_cpu_read_the_map_alike():
    h = _hills(33)
    from engine.heightfield import HeightField as HF

    field = HF(h, 0.5, np.array([-8.0, -8.0]))
    model = np.eye(4)
    model[:3, 3] = (2.0, 1.0, -3.0)
    shadow = TerrainShadow.build((), field, model, _unit([0.8, 0.4, 0.3]))
    # grid points at their own height: the baked terrain's visibility
    xs = -8.0 + 0.5 * np.arange(33) + 2.0
    zs = -8.0 + 0.5 * np.arange(33) - 3.0
    gx, gz = np.meshgrid(xs, zs)
    points = np.stack([gx, h + 1.0, gz], axis=-1).reshape(-1, 3)
    np.testing.assert_allclose(shadow.visibility(points).reshape(h.shape),
                               visibility(h, shadow.heights, shadow.penumbra), atol=1e-9)
    assert shadow.visibility(np.array([[100.0, 0.0, 0.0]]))[0] == 1.0  # beside the field: lit
