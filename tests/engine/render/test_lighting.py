"""The light as world state (engine/render/lighting.py): render.light, the renderer drawing it, hashes, snapshots,
hot reload, and the stock sun_cycle script."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from engine.app import App, TimeControl
from engine.config import ConfigError
from engine.reload import HotReloader
from engine.render.lighting import LIGHT_KEYS, Lighting
from engine.scene import RenderSettings
from engine.script import ScriptContext
from engine.stock_scripts import sun_path, tint_light
from tests.render_utils import make_renderer

SCENE = """
[scene]
name = "light"
plugins = ["render"]

[render]
width = 96
height = 64
sun_direction = [0.0, 1.0, 0.0]
sun_color = [1.0, 0.95, 0.85]
ambient = 0.3
fog_density = 0.0
shadows = false
{render}
[[entities]]
name = "camera"
[entities.components.Transform]
[entities.components.Camera]
target = [0.0, 0.0, 0.0]
distance = 8.0
pitch = -50.0

[[entities]]
name = "floor"
[entities.components.Transform]
scale = [30.0, 1.0, 30.0]
[entities.components.Mesh]
shape = "plane"
color = [0.8, 0.8, 0.8]

[[entities]]
name = "crate"
{crate_scripts}
[entities.components.Transform]
position = [0.0, 0.5, 0.0]
[entities.components.Mesh]
shape = "box"
color = [0.8, 0.3, 0.2]
"""

SUN_CYCLE = 'scripts = [{ name = "sun_cycle", params = { period = 2.0, start_hour = 3.0 } }]'


def _scene(tmp_path, render: str = "", scripts: str = "", name: str = "light.toml"):
    path = tmp_path / name
    path.write_text(SCENE.format(render=render, crate_scripts=scripts))
    return path


def _call(app: App, **values):
    """render.light as a script calls it (the command ignores its caller: entity 0 spawns nothing)."""
    return ScriptContext(app.world, 0, "test").call("render.light", **values)


def _floor(image: np.ndarray) -> float:
    """Mean brightness of the bottom rows (the floor in front of the crate)."""
    return float(image[-12:].mean())


def test_the_world_starts_with_the_scenes_light_as_state(tmp_path):
    text = _scene(tmp_path, render="sky_top = [0.1, 0.2, 0.3]").read_text().replace("ambient = 0.3", "ambient = 0.45")
    (tmp_path / "lit.toml").write_text(text)
    app = App(tmp_path / "lit.toml")
    light = app.world.resource(Lighting)
    assert light == Lighting(sun_direction=(0.0, 1.0, 0.0), sun_color=(1.0, 0.95, 0.85), ambient=0.45,
                             sky_top=(0.1, 0.2, 0.3), sky_horizon=RenderSettings().sky_horizon, fog_density=0.0)
    assert all(type(x) is float for v in light.values().values() for x in (v if isinstance(v, tuple) else (v,)))
    assert light in app.world.state_resources()
    default = App().world.resource(Lighting)  # no scene: the [render] defaults
    assert default.values() == {key: getattr(RenderSettings(), key) for key in LIGHT_KEYS}


def test_render_light_sets_the_given_keys_keeps_the_others_and_relights_the_frame(tmp_path):
    app = App(_scene(tmp_path), strict=True)
    renderer = make_renderer(app, 96, 64)  # one renderer throughout: render-extract takes each new light

    def picture() -> np.ndarray:
        app.step(1)
        app.render_frame()
        return np.asarray(renderer.read_image(), np.float64)

    try:
        high = picture()
        before = app.world.resource(Lighting)
        new = _call(app, sun_direction=np.array([1.0, 0.08, 0.0]), sun_color=(1.0, 0.5, 0.3))
        assert new is app.world.resource(Lighting) and new.sun_direction == (1.0, 0.08, 0.0)
        assert new.sun_color == (1.0, 0.5, 0.3)
        assert all(getattr(new, k) == getattr(before, k) for k in ("ambient", "sky_top", "sky_horizon", "fog_density"))
        assert _call(app) is new  # no keys: the light in force
        low = picture()
        assert _floor(low) < 0.8 * _floor(high)  # a low, reddish sun lights the floor less
        assert (low[..., 2].mean() - high[..., 2].mean()) < -5.0  # and its blue least
        _call(app, ambient=3.0, sun_color=(2.0, 2.0, 2.0))
        assert _floor(picture()) > _floor(high)
    finally:
        renderer.release()
        app.renderer = None


def test_a_world_without_the_light_resource_draws_the_settings_light(tmp_path):
    """A world that has no Lighting (built without the render plugin's world setup): the renderer draws its
    settings' light, and use_settings still takes a new sun."""
    app = App(_scene(tmp_path))
    app.world.remove_resource(Lighting)
    renderer = make_renderer(app, 96, 64)
    try:
        app.render_frame()
        assert renderer.settings is app.config.render and np.allclose(renderer.sun_direction, (0.0, 1.0, 0.0))
        high = np.asarray(renderer.read_image(), np.float64)
        renderer.use_settings(app.config.render.model_copy(update={"sun_direction": (1.0, 0.08, 0.0)}))
        app.render_frame()
        assert np.allclose(renderer.sun_direction, np.array([1.0, 0.08, 0.0]) / np.hypot(1.0, 0.08))
        assert _floor(np.asarray(renderer.read_image(), np.float64)) < 0.8 * _floor(high)
    finally:
        renderer.release()
        app.renderer = None


@pytest.mark.parametrize("values, key, words", [
    ({"sun_direction": (0.0, 0.0, 0.0)}, "sun_direction", "non-zero direction"),
    ({"ambient": 4.5}, "ambient", "less than or equal to 4"),
    ({"fog_density": -0.1}, "fog_density", "greater than or equal to 0"),
    ({"sun_color": (1.0, 1.0)}, "sun_color", "at least 3"),
    ({"sky_top": (0.1, 0.2, 99.0)}, "sky_top[2]", "less than or equal to 64"),
    ({"ambient": "0.5"}, "ambient", "valid number"),
    ({"fog_density": float("nan")}, "fog_density", "finite"),
    ({"ambiant": 0.5}, "ambiant", "did you mean 'ambient'"),
    ({"width": 640}, "width", "unknown key"),
])
def test_a_bad_light_raises_naming_the_key_and_keeps_the_light(tmp_path, values, key, words):
    app = App(_scene(tmp_path))
    before = app.world.resource(Lighting)
    with pytest.raises(ConfigError) as caught:
        _call(app, sky_horizon=(0.5, 0.5, 0.5), **values)  # a good key beside the bad one is not taken either
    assert [p.key for p in caught.value.problems] == [key] and words in str(caught.value)
    assert "render.light" in str(caught.value)
    assert app.world.resource(Lighting) is before


def test_a_refused_light_leaves_the_picture_as_it_was(tmp_path):
    app = App(_scene(tmp_path))
    renderer = make_renderer(app, 96, 64)
    try:
        app.render_frame()
        before = np.asarray(renderer.read_image())
        for values in ({"sun_direction": (0.0, 0.0, 0.0), "ambient": 2.0}, {"ambient": -1.0, "sun_color": (0, 0, 0)}):
            with pytest.raises(ConfigError):
                _call(app, **values)
        app.render_frame()
        assert np.array_equal(np.asarray(renderer.read_image()), before)
        _call(app, ambient=2.0)  # the comparison means something: a taken light changes the picture
        app.render_frame()
        assert not np.array_equal(np.asarray(renderer.read_image()), before)
    finally:
        renderer.release()
        app.renderer = None


def test_the_state_hash_covers_the_light_bit_for_bit(tmp_path):
    path = _scene(tmp_path)
    a, b = App(path, seed=3), App(path, seed=3)
    a.step(5)
    b.step(5)
    assert a.state_hash() == b.state_hash()
    _call(a, ambient=0.1 + 0.2)
    _call(b, ambient=0.3)  # one ulp apart
    assert a.world.resource(Lighting).ambient != b.world.resource(Lighting).ambient
    assert a.state_hash() != b.state_hash()
    _call(a, ambient=0.3)
    assert a.state_hash() == b.state_hash()


def test_snapshot_and_restore_rewind_the_light(tmp_path):
    app = App(_scene(tmp_path, scripts=SUN_CYCLE), strict=True)
    app.step(10)
    snap, light, digest = app.snapshot(), app.world.resource(Lighting), app.state_hash()
    app.step(30)
    _call(app, fog_density=0.5)
    assert app.world.resource(Lighting) != light
    app.restore(snap)
    assert app.world.resource(Lighting) == light and app.state_hash() == digest
    app.step(30)
    again = app.world.resource(Lighting)
    app.restore(snap)
    app.step(30)
    assert app.world.resource(Lighting) == again and again.sun_direction != light.sun_direction


def test_sun_cycle_moves_the_sun_over_a_day_and_stops_while_paused(tmp_path):
    app = App(_scene(tmp_path, scripts=SUN_CYCLE), strict=True)  # a day of 2 s (120 ticks) from 3 o'clock
    heights, lights = [], []
    for _ in range(12):
        app.step(10)
        light = app.world.resource(Lighting)
        heights.append(light.sun_direction[1])
        lights.append(light)
    # 0.2 hours a tick: the samples are at 4.8, 6.8, ..., 24.8 and 2.8 o'clock
    assert heights[0] < 0.0 < heights[1] and heights[-2] < 0.0 and heights[-1] < 0.0
    noon = int(np.argmax(heights))
    assert noon == 4 and heights[noon] == pytest.approx(np.cos(np.radians(30.0)), abs=0.03)  # tilt 30: 60° up
    assert np.allclose([np.linalg.norm(light.sun_direction) for light in lights], 1.0)
    assert np.allclose(lights[noon].sun_color, (1.0, 0.95, 0.85)) and lights[noon].ambient == pytest.approx(0.3)
    assert lights[-1].sun_color == (0.0, 0.0, 0.0) and lights[-1].ambient == pytest.approx(0.3 * 0.15)
    app.world.resource(TimeControl).paused = True
    app.step(20)
    assert app.world.resource(Lighting) == lights[-1]


def test_sun_cycle_gives_the_same_hash_in_two_runs_and_in_another_process(tmp_path):
    path = _scene(tmp_path, scripts=SUN_CYCLE)
    runs = []
    for _ in range(2):
        app = App(path, seed=5, strict=True)
        app.step(77)
        runs.append(app.state_hash())
    cli = [sys.executable, "-m", "engine", "run", str(path), "--no-render", "--steps", "77", "--seed", "5", "--hash"]
    out = subprocess.run(cli, capture_output=True, text=True, check=True).stdout.split()[-1]
    assert runs[0] == runs[1] == out
    other = App(path, seed=5, strict=True)
    other.step(76)
    assert other.state_hash() != out  # the light moved in the last tick


def test_a_rendered_run_reaches_the_no_render_runs_hash_and_frames_show_the_extracted_light(tmp_path):
    """With overlapped ticks (the window's default) the next ticks move the sun while a frame draws: the frame
    still shows the light it extracted, the same picture as ticking after it."""
    path = _scene(tmp_path, scripts=SUN_CYCLE.replace("period = 2.0", "period = 0.5"))
    plain = App(path, seed=2, strict=True)
    plain.step(26)
    runs = {}
    for overlapped in (False, True):
        app = App(path, seed=2, strict=True)
        renderer = make_renderer(app, 96, 64)
        pictures = []
        try:
            app.step(1)
            for frame in range(12):
                if overlapped:
                    app.render_frame(overlap=lambda: app.step(2))
                else:
                    app.render_frame()
                    app.step(2)
                pictures.append(np.asarray(renderer.read_image()))
            app.step(1)
        finally:
            renderer.release()
            app.renderer = None
        runs[overlapped] = pictures
        assert app.state_hash() == plain.state_hash() and app.world.tick == 26
    for a, b in zip(runs[False], runs[True]):
        assert np.array_equal(a, b)
    assert len({p.tobytes() for p in runs[False]}) > 6  # the light did change from frame to frame


def test_sun_path_geometry():
    for hour, expected in ((6.0, (1.0, 0.0, 0.0)), (18.0, (-1.0, 0.0, 0.0))):
        assert np.allclose(sun_path(hour, 30.0, 0.0, -90.0), expected, atol=1e-12)
    noon = sun_path(12.0, 30.0, 0.0, -90.0)
    assert np.allclose(noon, (0.0, np.cos(np.radians(30.0)), np.sin(np.radians(30.0))))
    assert np.allclose(sun_path(12.0, 30.0, 90.0, -90.0), (noon[2], noon[1], 0.0))  # turned a quarter about +y
    for hour in np.linspace(0.0, 24.0, 97):
        d = sun_path(float(hour), 40.0, 25.0, 5.0)
        assert np.isclose(np.linalg.norm(d), 1.0) and d[1] >= np.sin(np.radians(5.0)) - 1e-12
    nadir = sun_path(0.0, 0.0, 0.0, 10.0)  # straight down at midnight, held at 10° up: a unit direction still
    assert np.isclose(np.linalg.norm(nadir), 1.0) and np.isclose(nadir[1], np.sin(np.radians(10.0)))


def test_tint_fades_the_sun_out_at_night_and_keeps_the_day_by_day():
    day = {"sun_color": (1.0, 1.0, 1.0), "ambient": 0.4, "sky_top": (0.2, 0.4, 0.8), "sky_horizon": (0.8, 0.8, 0.9)}
    assert tint_light(day, 0.5, 0.15) == day
    night = tint_light(day, -0.5, 0.15)
    assert night["sun_color"] == (0.0, 0.0, 0.0) and night["ambient"] == pytest.approx(0.06)
    dusk = tint_light(day, 0.05, 0.15)
    red, green, blue = dusk["sun_color"]
    assert 0.0 < blue < green < red < 1.0  # a low sun: dimmer and redder


def test_a_hot_reload_writes_the_light_keys_the_file_changed_and_keeps_the_scripts_others(tmp_path):
    path = _scene(tmp_path)
    app = App(path, strict=True)
    reloader = HotReloader(app)
    _call(app, sun_direction=(1.0, 0.2, 0.0), ambient=0.9)
    scripted = app.world.resource(Lighting)
    path.write_text(SCENE.format(render="exposure = 1.5", crate_scripts=""))  # nothing about the light
    assert reloader.poll() and reloader.status.errors == []
    assert app.world.resource(Lighting) is scripted
    path.write_text(SCENE.format(render="exposure = 1.5", crate_scripts="").replace("ambient = 0.3", "ambient = 0.7")
                    .replace("fog_density = 0.0", "fog_density = 0.01"))
    assert reloader.poll() and reloader.status.errors == []
    light = app.world.resource(Lighting)
    assert light.ambient == 0.7 and light.fog_density == 0.01  # the modder's edit
    assert light.sun_direction == (1.0, 0.2, 0.0)  # the script's sun: the file did not change it
    path.write_text(SCENE.format(render="exposure = 1.5\nsky_top = [0.0, 0.0, 99.0]", crate_scripts=""))
    assert reloader.poll() and "sky_top" in reloader.status.errors[0]
    assert app.world.resource(Lighting) is light  # a bad edit keeps the light too
    app.restart()  # R: the world is built again with the file's light
    assert app.world.resource(Lighting).values() == Lighting.of(app.config.render).values()
    assert app.world.resource(Lighting).ambient == 0.7 and app.world.resource(Lighting).sun_direction[0] == 0.0


def test_a_hot_reload_relights_the_renderer_and_use_settings_takes_a_new_sun(tmp_path):
    path = _scene(tmp_path)
    app = App(path, strict=True)
    reloader = HotReloader(app)
    renderer = make_renderer(app, 96, 64)
    try:
        _call(app, ambient=1.2)
        app.render_frame()
        assert renderer.ambient == 1.2 and renderer.settings.ambient == 1.2
        assert renderer.settings is not app.config.render  # the scene's settings object stays the file's
        drawn = renderer.settings
        app.step(1)
        app.render_frame()
        assert renderer.settings is drawn  # the same light: nothing derived again
        path.write_text(SCENE.format(render="sky_top = [0.9, 0.1, 0.1]", crate_scripts=""))
        assert reloader.poll() and reloader.status.errors == []
        app.render_frame()
        assert renderer.settings.sky_top == (0.9, 0.1, 0.1) and renderer.ambient == 1.2
        renderer.use_settings(renderer.settings.model_copy(update={"sun_direction": (0.0, 0.0, 2.0)}))
        assert app.world.resource(Lighting).sun_direction == (0.0, 0.0, 2.0)  # into the world: what is drawn
        app.render_frame()
        assert np.allclose(renderer.sun_direction, (0.0, 0.0, 1.0)) and renderer.ambient == 1.2
    finally:
        renderer.release()
        app.renderer = None
