"""Mouse picking helpers for the top-view drag: screen point -> world ray -> ground point."""

import math
from pathlib import Path

import numpy as np

from engine.app import App
from engine.builtin import Terrain
from engine.collider import Collider
from engine.render.components import look_at, orthographic, perspective
from engine.spatial import Transform
from systems.dust_devil import picking, screen_pick

ROOT = Path(__file__).resolve().parents[3]


def _to_pixels(points, view, proj, vp):
    clip = np.column_stack([points, np.ones(len(points))]) @ (proj @ view).T
    ndc = clip[:, :2] / clip[:, 3:]
    return np.column_stack([vp[0] + (ndc[:, 0] + 1) * 0.5 * vp[2], vp[1] + (ndc[:, 1] + 1) * 0.5 * vp[3]])


def test_orthographic_top_view_picks_the_ground_plane():
    view = look_at((5.0, 50.0, -3.0), (5.0, 0.0, -3.0), up=(0.0, 0.0, -1.0))
    proj = orthographic(40.0, 1.5, 0.1, 200.0)
    vp = picking.viewport_pixels((0.5, 0.0, 0.5, 1.0), (1200, 400))  # right half: 600 x 400 px
    rng = np.random.default_rng(0)
    ground = np.column_stack([rng.uniform(-20, 30, 50), np.full(50, 2.5), rng.uniform(-20, 15, 50)])
    px = _to_pixels(ground, view, proj, vp)
    hit, got = picking.pick_ground(view, proj, vp, px, plane_height=2.5)
    inside = (px[:, 0] >= vp[0]) & (px[:, 0] <= vp[0] + vp[2]) & (px[:, 1] >= 0) & (px[:, 1] <= vp[3])
    np.testing.assert_array_equal(hit, inside)
    np.testing.assert_allclose(got[hit], ground[hit], atol=1e-9)


def test_perspective_view_picks_the_terrain():
    from engine.heightfield import HeightField, midpoint_displacement

    field = HeightField(midpoint_displacement(5, 0.5, 4.0, np.random.default_rng(3)), 2.0, np.array([-32.0, -32.0]))
    terrain = (Collider(shape="heightfield", heightfield=field), Transform(np.array([1.0, -2.0, 0.5])))
    view = look_at((30.0, 25.0, 30.0), (0.0, 0.0, 0.0))
    proj = perspective(math.radians(55.0), 4 / 3, 0.1, 500.0)
    vp = picking.viewport_pixels((0.0, 0.0, 1.0, 1.0), (320, 240))
    rng = np.random.default_rng(1)
    xz = rng.uniform(-12.0, 12.0, size=(40, 2))
    surface = np.column_stack([xz[:, 0], field.height_at(xz[:, 0] - 1.0, xz[:, 1] - 0.5) - 2.0, xz[:, 1]])
    hit, got = picking.pick_ground(view, proj, vp, _to_pixels(surface, view, proj, vp), terrain)
    assert hit.mean() > 0.9  # a few may be hidden behind a ridge
    near = np.linalg.norm(got - surface, axis=1) < 1e-3
    assert near[hit].mean() > 0.85


def test_showcase_top_camera_picks_under_the_cursor():
    """In the showcase, the centre of the top view's viewport picks the point under the top camera."""
    app = App(ROOT / "configs/scenes/dust_devil_showcase.toml")
    w, h = app.config.render.width, app.config.render.height
    hit, point = screen_pick(app.world, "top", [(0.25 * w, 0.5 * h), (0.75 * w, 0.5 * h)])
    assert hit.tolist() == [True, False]  # the second point lies in the oblique view
    terrain_entity, (terrain,) = app.world.query(Terrain)[0]
    np.testing.assert_allclose(point[0, [0, 2]], [0.0, 0.0], atol=1e-6)
    assert abs(point[0, 1] - terrain.field.height_at(0.0, 0.0)) < 1e-3
