"""The static layer cache ([render] static_layer_cache): a view whose camera, light and static features stay the
same copies its clear + terrain + sky back from a kept picture; the pictures are the same bits as without it."""

import numpy as np
import pytest

from engine.app import App
from engine.render.components import Camera
from tests.render_utils import make_renderer

SCENE = "configs/scenes/sandbox.toml"  # terrain and sky (static), a spinning crate and a bobbing ball (moving)


def _run(cache: bool, frames: int, events: dict | None = None, size=(160, 96)):
    """Render the sandbox frame by frame with the cache on or off; ``events``: frame index -> f(app, renderer)
    applied before that frame's tick.  Returns the pictures, the main view's outcomes and the renderer's counts."""
    app = App(SCENE)
    app.config.render.static_layer_cache = cache
    renderer = make_renderer(app, *size)
    pictures, outcomes = [], []
    try:
        for frame in range(frames):
            if events and frame in events:
                events[frame](app, renderer)
            app.step(1)
            app.render_frame()
            pictures.append(np.asarray(renderer.read_image()))
            outcomes.append(renderer.views[0].extra.get("static_layer"))
        return pictures, outcomes, dict(renderer.static_layer_counts)
    finally:
        renderer.release()
        app.renderer = None


def _turn_camera(app, renderer):
    for _, (cam,) in app.world.query(Camera):
        cam.yaw += 20.0


def _move_sun(app, renderer):
    renderer.sun_direction = (renderer.sun_direction + np.array([0.3, 0.0, -0.2], np.float32))
    renderer.sun_direction /= np.linalg.norm(renderer.sun_direction)


def _reload(app, renderer):
    assert renderer.reload_shaders() == []


EVENTS = {7: _turn_camera, 11: _move_sun, 15: _reload}
EXPECTED = (["drawn", "drawn", "stored"] + ["restored"] * 4  # the same two frames running, then kept
            + ["drawn", "stored", "restored", "restored"]  # the camera turned: the layer is drawn again
            + ["drawn", "stored", "restored", "restored"]  # the sun moved: the terrain's light is re-baked
            + ["drawn", "stored", "restored"])  # shaders reloaded: pictures of the old programs are stale


@pytest.fixture(scope="module")
def runs():
    frames = len(EXPECTED)
    return _run(True, frames, EVENTS), _run(False, frames, EVENTS)


def test_kept_layer_is_stored_once_stable_and_redrawn_on_every_change(runs):
    (_, outcomes, counts), _ = runs
    assert outcomes == EXPECTED
    assert counts == {k: EXPECTED.count(k) for k in ("drawn", "stored", "restored")}


def test_pictures_are_the_same_bits_as_without_the_cache(runs):
    (cached, _, _), (plain, outcomes, _) = runs
    assert outcomes == [None] * len(EXPECTED)  # off: no view goes through the cache
    for frame, (a, b) in enumerate(zip(cached, plain)):
        assert np.array_equal(a, b), f"frame {frame} ({EXPECTED[frame]}) differs"
    # and the pictures do change: the crate spins over the restored layer, the camera and the sun move
    def change(a, b):
        return float(np.abs(a.astype(int) - b.astype(int)).mean())

    assert 0.0 < change(cached[4], cached[5]) < 1.0
    assert change(cached[6], cached[8]) > 2.0
    assert change(cached[10], cached[12]) > 0.0


def test_moving_meshes_stay_out_of_the_layer_and_still_meshes_join_it():
    app = App(SCENE)
    app.config.render.shadows = False  # moving shadows keep the terrain out too (test_shadows.py)
    renderer = make_renderer(app, 96, 64)
    try:
        app.step(1)
        app.render_frame()
        meshes = next(f for f in renderer.features if f.name == "meshes")
        assert renderer._static_seen[renderer.views[0].camera_entity][1]["meshes"] is not None
        for _ in range(4):  # the crate spins every tick: its key changes, so it is never part of the layer
            app.step(1)
            app.render_frame()
        layer = renderer._static[renderer.views[0].camera_entity].key
        assert [name for name, _ in layer[1]] == ["terrain", "sky"]
        for _ in range(4):  # rendering without ticks: nothing moves, the meshes join the layer
            app.render_frame()
        layer = renderer._static[renderer.views[0].camera_entity].key
        assert [name for name, _ in layer[1]] == ["terrain", "meshes", "sky"]
        assert meshes.static_key(renderer.views[0], meshes.extract(app.world)) == dict(layer[1])["meshes"]
    finally:
        renderer.release()
        app.renderer = None


def test_layer_follows_a_resize_and_is_freed_with_its_camera():
    app = App(SCENE)
    app.config.render.shadows = False  # a resize refits the shadow map: the terrain would join a frame later
    renderer = make_renderer(app, 96, 64)
    try:
        for _ in range(4):
            app.render_frame()
        camera = renderer.views[0].camera_entity
        assert renderer._static[camera].size == (96, 64)
        renderer.resize(80, 48)
        outcomes = []
        for _ in range(4):
            app.render_frame()
            outcomes.append(renderer.views[0].extra["static_layer"])
        assert outcomes == ["drawn", "stored", "restored", "restored"]
        assert renderer._static[camera].size == (80, 48)
        app.config.render.static_layer_cache = False  # switched off: the kept textures are released
        app.render_frame()
        assert camera not in renderer._static and "static_layer" not in renderer.views[0].extra
        app.config.render.static_layer_cache = True
        app.world.despawn(camera)
        app.render_frame()  # the default view (no camera entity) takes over; the old layer is released
        assert camera not in renderer._static
    finally:
        renderer.release()
        app.renderer = None
