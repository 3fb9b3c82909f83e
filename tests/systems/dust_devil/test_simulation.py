"""Dust devil simulation (seeds/004): rotation (2.2), terrain (3.2, eq. 1), field space and dragging (4)."""

import math

import numpy as np
import pytest

from engine.builtin import Terrain
from engine.heightfield import HeightField
from engine.script import ScriptContext
from engine.spatial import Transform
from systems.dust_devil import find_ground, simulate
from tests.systems.dust_devil.helpers import devil, make_app

SMALL = dict(particle_count=400, prewarm_time=0.0, grid_resolution=[16, 16, 16])


def test_field_time_advances_and_particles_start_at_the_foot(tmp_path):
    app = make_app(tmp_path, **SMALL, time_speed=12.0)
    app.step(30)
    _, t, cfg, state = devil(app)
    assert state.steps == 30
    assert state.field_time == pytest.approx(30 * 12.0 * app.dt)
    u = state.positions / np.asarray(cfg.field_size) + [0.5, 0.0, 0.5]
    assert np.all((u >= 0.0) & (u <= 1.0))
    assert np.all(state.ages < state.lifetimes)


def test_rotation_only_at_the_interval_and_clockwise(tmp_path):
    app = make_app(tmp_path, **SMALL, rotation_interval=0.25, rotation_angle_range=[10.0, 30.0])
    _, _, cfg, state = devil(app)
    angles, counts = [], []
    for _ in range(61):
        app.step(1)
        angles.append(state.centre_rotation)
        counts.append(state.rotation_count)
    changes = [i + 1 for i in range(60) if angles[i + 1] != angles[i]]  # step numbers where it turned
    assert [s + 1 for s in changes] == [15, 30, 45, 60]  # every 15 steps (0.25 s at 60 Hz), never between
    assert counts[-1] == 4  # steps 15, 30, 45, 60
    turns = np.degrees(np.diff([0.0] + [angles[i] for i in (14, 29, 44, 59)]))
    assert np.all((turns >= 10.0) & (turns <= 30.0)) and len(set(np.round(turns, 9))) == 4  # random, in range
    # the centre line itself moved clockwise seen from above: (a x b)_y < 0 about the box's vertical axis
    before = state.centre_rotation
    a = simulate.centre_at(cfg, state, np.array([12.0]))[0]
    state.centre_rotation = before + math.radians(20.0)
    b = simulate.centre_at(cfg, state, np.array([12.0]))[0]
    state.centre_rotation = before
    a3, b3 = np.array([a[0], 0.0, a[1]]), np.array([b[0], 0.0, b[1]])
    assert np.cross(a3, b3)[1] < 0.0


def test_slope_projection_gives_wind_parallel_to_the_ground():
    rng = np.random.default_rng(2)
    v, n = rng.normal(size=(500, 3)), rng.normal(size=(500, 3))  # eq. 1 needs no unit normal
    r = simulate.project_onto_slope(v, n)
    np.testing.assert_allclose(np.sum(r * n, axis=1), 0.0, atol=1e-12)
    # on a tilted plane: wind into the ground that would cross it is projected, wind leaving it is kept
    xs = np.arange(11) * 2.0 - 10.0
    ground = simulate.Ground(HeightField(0.5 * xs[None, :] + 0.0 * xs[:, None], 2.0, np.array([-10.0, -10.0])))
    p = rng.uniform(-6.0, 6.0, size=(400, 3))
    p[:, 1] = 0.5 * p[:, 0] + rng.uniform(0.0, 0.2, 400)  # just above the slope
    v = rng.normal(scale=3.0, size=(400, 3))
    dt = 1 / 60
    out, idx, nxt, depth = simulate.slope_wind(p, v, dt, ground)
    n = ground.normal(p)
    into = np.sum(n * v, axis=1) < 0.0
    crosses = ground.depth(p + v * dt) > 0.0
    expected = np.flatnonzero(into & crosses)
    assert expected.size > 20
    np.testing.assert_array_equal(idx, expected)
    np.testing.assert_allclose(np.sum(out[idx] * n[idx], axis=1), 0.0, atol=1e-12)  # v·n = 0
    kept = np.setdiff1d(np.arange(400), idx)
    np.testing.assert_array_equal(out[kept], v[kept])
    np.testing.assert_allclose(nxt, p + out * dt)


def test_no_particle_below_the_terrain_over_a_long_run(tmp_path):
    app = make_app(tmp_path, amplitude=9.0, position=(4.0, -8.0, -3.0), particle_count=800, prewarm_time=0.0,
                   grid_resolution=[20, 20, 20], wind_scale=1.5, emission_radius=4.0)
    _, t, cfg, state = devil(app)
    app.step(1)
    ground = find_ground(app.world)
    worst = -np.inf
    projected_any = False
    for _ in range(12):
        for _ in range(50):
            app.step(1)
            worst = max(worst, float(ground.depth(simulate.world_positions(state, t)).max()))
        near = ground.depth(simulate.world_positions(state, t)) > -0.05
        projected_any |= bool(near.sum() > 10)
    assert worst <= 1e-9  # never below (up to round-off of the field-space round trip)
    assert projected_any  # the test is not vacuous: many particles ride on the surface


def test_drag_moves_the_field_and_every_particle_by_exactly_the_delta(tmp_path):
    app = make_app(tmp_path, **SMALL)
    app.step(20)
    entity, t, cfg, state = devil(app)
    local_before = state.positions.copy()
    world_before = simulate.world_positions(state, t)
    markers_before = simulate.marker_points(cfg, t)
    delta = np.array([3.25, 0.5, -7.0])
    ctx = ScriptContext(app.world, entity, "test")
    ctx.call("dust_devil.drag", delta=delta)  # as a script does: a programmatic move
    assert not state.dragging(app.world.tick + 1)  # only a user's (interactive) drag lowers R
    ctx.call("dust_devil.drag", delta=-delta)
    ctx.call("dust_devil.drag", delta=delta, interactive=True)
    np.testing.assert_array_equal(state.positions, local_before)  # field space is untouched
    np.testing.assert_allclose(simulate.world_positions(state, t) - world_before, np.broadcast_to(delta, (400, 3)),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(simulate.marker_points(cfg, t) - markers_before, np.broadcast_to(delta, (9, 3)),
                               rtol=0, atol=1e-12)
    assert state.dragging(app.world.tick + 1)  # R drops in the frame after a drag
    app.step(3)
    assert not state.dragging(app.world.tick)


def test_pick_drag_moves_by_the_horizontal_distance(tmp_path):
    app = make_app(tmp_path, **SMALL)
    entity, t, _, _ = devil(app)
    start = t.position.copy()
    app.registry.command("dust_devil.pick_drag")(app.world, 0, start=[1.0, 2.0, 3.0], end=[4.0, -1.0, 1.0])
    np.testing.assert_allclose(t.position - start, [3.0, 0.0, -2.0])


def test_mouse_drag_in_the_top_view(tmp_path):
    from engine.builtin import Name
    from engine.input import InputEvent, InputQueue
    from engine.render.components import Camera, CameraConfig
    from engine.spatial import quat_from_euler

    app = make_app(tmp_path, **SMALL)
    entity, t, cfg, state = devil(app)
    top = CameraConfig(projection="orthographic", ortho_height=108.0, controller="none", viewport=[0.0, 0.0, 0.5, 1.0])
    cam_t = Transform(np.array([0.0, 80.0, 0.0]), quat_from_euler(0.0, -math.pi / 2, 0.0))
    app.world.spawn(Name("top"), cam_t, Camera(top))
    start = t.position.copy()
    queue = app.world.resource(InputQueue)
    queue.push(InputEvent("button_down", "left", x=200.0, y=300.0))
    app.step(1)
    assert state.mouse_dragging and state.dragging(app.world.tick)
    queue.push(InputEvent("mouse_move", x=254.0, y=327.0, dx=54.0, dy=27.0))
    app.step(1)
    queue.push(InputEvent("mouse_move", x=281.0, y=327.0, dx=27.0, dy=0.0))
    app.step(1)
    queue.push(InputEvent("button_up", "left", x=281.0, y=327.0))
    app.step(1)
    assert not state.mouse_dragging
    # window 960 x 540, viewport 480 x 540 px showing 108 m: 0.2 m per pixel; screen up is world -z
    np.testing.assert_allclose(t.position - start, [81 * 0.2, 0.0, -27 * 0.2], atol=1e-9)
    # a press outside the top view's viewport does not drag
    queue.push(InputEvent("button_down", "left", x=700.0, y=300.0))
    queue.push(InputEvent("mouse_move", x=760.0, y=300.0, dx=60.0))
    app.step(2)
    np.testing.assert_allclose(t.position - start, [81 * 0.2, 0.0, -27 * 0.2], atol=1e-9)


def test_screen_drag_command_and_errors(tmp_path):
    from engine.builtin import Name
    from engine.render.components import Camera, CameraConfig
    from engine.spatial import quat_from_euler
    from systems.dust_devil import DragError

    app = make_app(tmp_path, **SMALL)
    _, t, _, _ = devil(app)
    drag = app.registry.command("dust_devil.screen_drag")
    with pytest.raises(DragError, match="no camera entity named 'top'"):
        drag(app.world, 0, start=(10, 10), end=(20, 20))
    top = CameraConfig(projection="orthographic", ortho_height=54.0, controller="none")
    app.world.spawn(Name("top"), Transform(np.array([0.0, 50.0, 0.0]), quat_from_euler(0.0, -math.pi / 2, 0.0)),
                    Camera(top))
    start = t.position.copy()
    drag(app.world, 0, start=(480, 270), end=(580, 170))  # 0.1 m per pixel, down on screen is +z
    np.testing.assert_allclose(t.position - start, [10.0, 0.0, 10.0], atol=1e-9)
    with pytest.raises(ValueError, match="3 finite numbers"):
        app.registry.command("dust_devil.drag")(app.world, 0, delta=[1.0, 2.0])


def test_particles_live_in_field_space(tmp_path):
    app = make_app(tmp_path, terrain=False, **SMALL)
    app.step(5)
    _, t, _, state = devil(app)
    before = state.positions.copy()
    t.position = t.position + np.array([100.0, 0.0, 0.0])  # moving the entity moves the whole dust devil
    np.testing.assert_array_equal(state.positions, before)
    app.step(5)
    assert np.abs(state.positions[:, 0]).max() < 20.0  # still simulated inside the box


def test_same_seed_same_hash_different_seed_different_hash(tmp_path):
    def run(seed, name):
        app = make_app(tmp_path, name=name, seed=seed, **SMALL)
        app.step(40)
        return app

    a, b, c = run(3, "a"), run(3, "b"), run(4, "c")
    assert a.state_hash() == b.state_hash()
    assert a.state_hash() != c.state_hash()
    snap = a.snapshot()
    a.step(10)
    h = a.state_hash()
    a.restore(snap)
    a.step(10)
    assert a.state_hash() == h


@pytest.mark.parametrize("lookup, integrator", [("nearest", "euler"), ("trilinear", "midpoint")])
def test_lookup_and_integrator_options_run(tmp_path, lookup, integrator):
    app = make_app(tmp_path, **SMALL, lookup=lookup, integrator=integrator, substeps=2)
    app.step(30)
    _, _, _, state = devil(app)
    assert np.all(np.isfinite(state.positions))
    assert state.positions[:, 1].max() > 1.0  # the updraft lifts particles


def test_terrain_with_a_transform(tmp_path):
    """The terrain entity's Transform (translation and yaw) places the height field."""
    app = make_app(tmp_path, **SMALL)
    terrain_entity = app.world.query(Terrain)[0][0]
    tt = app.world.get(terrain_entity, Transform)
    from engine.spatial import quat_from_euler

    tt.position = np.array([3.0, 2.0, -1.0])
    tt.rotation = quat_from_euler(0.7, 0.0, 0.0)
    ground = find_ground(app.world)
    hf = app.world.get(terrain_entity, Terrain).field
    local = np.array([[1.5, 0.0, -2.5]])
    world = tt.to_world(local)
    np.testing.assert_allclose(ground.depth(world), hf.height_at(1.5, -2.5))
    app.step(60)
    _, t, _, state = devil(app)
    assert ground.depth(simulate.world_positions(state, t)).max() <= 1e-9


def test_parameters_change_live_and_particle_count_is_structural(tmp_path):
    from engine.registry import default_registry

    spec = default_registry(["render", "dust_devil"]).component("DustDevil")
    assert spec.structural == ("particle_count",)
    app = make_app(tmp_path, **SMALL)
    app.step(2)
    entity, _, cfg, state = devil(app)
    app.world.add(entity, cfg.model_copy(update={"lookup": "trilinear", "field_size": (30.0, 20.0, 30.0)}))
    app.step(2)  # the same state continues with the new parameters
    assert state.steps == 4 and state.wind.resolution == (16, 16, 16) and state.wind.grid.shape == (16, 16, 16, 3)


def test_field_space_transforms_match_the_engine_transform():
    from engine.spatial import quat_from_euler

    rng = np.random.default_rng(8)
    p = rng.normal(size=(50, 3))
    for t in (Transform(np.array([1.0, 2.0, 3.0])),
              Transform(np.array([-4.0, 0.5, 2.0]), quat_from_euler(0.8, 0.1, -0.3), np.array([2.0, 1.5, 0.5]))):
        np.testing.assert_allclose(simulate.to_world(t, p), t.to_world(p), atol=1e-12)
        np.testing.assert_allclose(simulate.to_local(t, p), t.to_local(p), atol=1e-12)
        np.testing.assert_allclose(simulate.to_world(t, p, direction=True), t.to_world(p) - t.position, atol=1e-12)
