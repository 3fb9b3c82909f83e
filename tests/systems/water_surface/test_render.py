"""Headless renders of the three presets and of the wireframe debug view (fig. 3.2), compared with golden images.

Look at tests/golden/water_surface_*.png: the water with sky reflection and depth tint, the bodies drawn by the
mesh pass, and (wireframe) the re-triangulated mesh with the box's outline in orange."""

from __future__ import annotations

import numpy as np
import pytest

from engine.app import App
from tests.render_utils import assert_golden, gl_objects_per_respawn, render_app, track_gl_objects
from tests.systems.water_surface.helpers import CONFIGS

SCENE = """
[scene]
name = "water-render"
seed = 4
plugins = ["render", "water_surface"]

[render]
sun_direction = [0.4, 0.6, -0.5]

[[entities]]
name = "camera"
[entities.components.Transform]
position = [0.0, 5.0, 8.0]
[entities.components.Camera]
controller = "orbit"
target = {target}
distance = {distance}
yaw = {yaw}
pitch = {pitch}

[[entities]]
name = "water"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.WaterSurface]
preset = "water_surface/{preset}"
{water}
{bodies}
"""

GLIDER = """
[[entities]]
name = "box"
scripts = [{{ name = "water_surface.glide", params = {{ velocity = [0.0, 0.0, -1.2], distance = 8.0 }} }}]
[entities.components.Transform]
position = [0.4, 0.0, 2.6]
rotation = [15.0, 0.0, 0.0]
scale = [1.2, 0.6, 1.6]
[entities.components.RigidBody]
kinematic = true
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.4, 0.2]
visible = {visible}
"""


def _crate(name: str, x: float, z: float, yaw: float, shape: str = "box", mass: float = 250.0) -> str:
    return f"""
[[entities]]
name = "{name}"
[entities.components.Transform]
position = [{x}, 0.6, {z}]
rotation = [{yaw}, 6.0, 4.0]
scale = [1.0, 0.8, 1.0]
[entities.components.RigidBody]
shape = "{shape}"
mass = {mass}
[entities.components.Mesh]
shape = "{shape}"
color = [0.62, 0.45, 0.25]
"""


CASES = {
    "paper_pool": dict(preset="paper_pool", water="", steps=100,
                       camera=dict(target=[0.4, 0.0, -0.6], distance=5.0, yaw=160.0, pitch=-30.0),
                       bodies=GLIDER.format(visible="true")),
    "calm_pond": dict(preset="calm_pond", water="resolution = [48, 48]", steps=90,
                      camera=dict(target=[0.0, 0.0, 0.0], distance=9.0, yaw=30.0, pitch=-30.0),
                      bodies=_crate("a", -1.5, 0.5, 20.0) + _crate("b", 1.4, -0.6, -30.0)
                      + _crate("c", 0.3, 1.8, 0.0, "sphere", 200.0)),
    "choppy_lake": dict(preset="choppy_lake", water="resolution = [64, 64]", steps=90,
                        camera=dict(target=[0.0, 0.0, 0.0], distance=14.0, yaw=-20.0, pitch=-24.0),
                        bodies=_crate("a", 0.0, 0.0, 10.0) + _crate("b", 3.0, 2.0, 50.0)),
    "wireframe": dict(preset="paper_pool", water="wireframe = true", steps=45,
                      camera=dict(target=[0.4, 0.0, 1.2], distance=3.6, yaw=0.0, pitch=-62.0),
                      bodies=GLIDER.format(visible="false")),
}


def _app(tmp_path, case: dict) -> App:
    cam = {k: (list(v) if isinstance(v, list) else v) for k, v in case["camera"].items()}
    text = SCENE.format(preset=case["preset"], water=case["water"], bodies=case["bodies"], **cam)
    path = tmp_path / "scene.toml"
    path.write_text(text, encoding="utf-8")
    app = App(path, configs_root=CONFIGS)
    app.step(case["steps"])
    return app


@pytest.mark.parametrize("name", list(CASES))
def test_golden_image(tmp_path, name):
    image = render_app(_app(tmp_path, CASES[name]), width=160, height=120, frames=1)
    pixels = np.asarray(image, np.float64)
    assert pixels.std() > 5.0  # not a blank frame
    assert_golden(image, f"water_surface_{name}")


def test_the_water_is_drawn_over_the_sky(tmp_path):
    """The lower half of the frame looks down on the water: bluish green, unlike the pale sky above."""
    image = np.asarray(render_app(_app(tmp_path, CASES["calm_pond"]), width=160, height=120), np.float64)
    water = image[90:, :, :].reshape(-1, 3).mean(axis=0)
    assert water[2] > water[0] and water[1] > water[0]


def test_rendering_leaves_the_state_alone(tmp_path):
    a, b = _app(tmp_path, CASES["paper_pool"]), _app(tmp_path, CASES["paper_pool"])
    render_app(a, width=64, height=48, frames=3)
    b.step(3)
    assert a.state_hash() == b.state_hash()


def test_a_water_surface_despawned_and_spawned_again_leaves_no_gl_objects_behind(tmp_path, monkeypatch):
    """Each respawn is a new entity: the old one's vertex and index buffers and vertex array are released (they
    stayed in the feature per entity id: +2 buffers and +1 vertex array a respawn)."""
    live = track_gl_objects(monkeypatch)
    case = dict(CASES["paper_pool"], bodies="", steps=1)
    counts = gl_objects_per_respawn(_app(tmp_path, case), "water", live)
    assert counts[1:] == counts[:1] * (len(counts) - 1)


@pytest.mark.parametrize("wall", [True, False])
def test_the_terrains_shadow_takes_the_suns_light_off_the_water(tmp_path, wall):
    """A wall of terrain east of the pond, under a low sun from the east: its shadow covers the water, which loses
    the sun's light on its body and its glint (the sky's reflection stays). Flat ground casts nothing: same bits."""
    from engine.builtin import Terrain, find_named
    from engine.heightfield import HeightField

    case = dict(CASES["calm_pond"], bodies="""
[[entities]]
name = "ground"
[entities.components.Transform]
position = [0.0, -2.0, 0.0]
[entities.components.Terrain]
size_exponent = 5
spacing = 1.0
amplitude = 0.0
""")
    images = []
    for on in (True, False):
        app = _app(tmp_path, case)
        app.config.render.sun_direction = (1.0, 0.5, 0.0)
        app.config.render.terrain_shadows = on
        h = np.zeros((33, 33))
        if wall:  # x in [7, 9] (the grid is centred), 8 m high: the water (y = 0) is shaded for x in [-5, 6]
            h[:, 23:26] = 8.0
        terrain = app.world.get(find_named(app.world, "ground"), Terrain)
        terrain.field = HeightField(h, 1.0, terrain.field.origin)
        images.append(np.asarray(render_app(app, width=160, height=120), np.float64))
    on, off = images
    water = (slice(70, None), slice(None))
    if wall:
        assert on[water].mean() < 0.85 * off[water].mean()
    else:
        np.testing.assert_array_equal(on, off)
