"""Motion after the hit: circular (eqs. 3.2–3.4), irregular (eq. 3.5), collisions with every collider shape,
fig. 4.7 (two boxes), events, and stability at extreme parameters."""

import numpy as np
import pytest

from components.energy_wave import FRAME, EnergyWaveEmitter, EnergyWaveHit
from engine.builtin import Terrain
from engine.collider import Collider
from engine.heightfield import HeightField
from engine.impacts import Impact
from engine.spatial import Transform, quat_rotate
from systems.energy_wave import fire
from systems.energy_wave.neighbours import neighbour_repulsion
from systems.energy_wave.simulate import collision_acceleration, control_point_offsets, penalty_drag

from .helpers import add_box, add_emitter, live, make_app

WALL_Z = -1.0  # front face of the wall used below (normal +z)


def _burst_at_wall(seed=2, ticks=12, count=600, **fields):
    """A single burst (no continuous emission) hitting a wall whose face is at z = WALL_Z."""
    app = make_app(seed)
    add_box(app, (0.0, 0.0, WALL_Z - 0.25), (3.0, 3.0, 0.25))
    entity, cfg, st = add_emitter(app, emitting=False, beam_speed=10.0, **fields)
    fire(app.world, entity, count=count, duration=0.05)
    app.step(ticks)
    return app, entity, st


# ------------------------------------------------------------------------------------------------ eqs 3.2 - 3.4
def test_drag_pushes_out_of_the_surface_eq_3_2():
    n = np.array([[0.0, 0.0, 1.0]])
    entering = np.array([[0.0, 0.0, -5.0]])
    d = penalty_drag(np.array([0.2]), n, entering, spring=1.0, damper=0.8)
    np.testing.assert_allclose(d, [[0.0, 0.0, 0.2 + 0.8 * 5.0]])  # k z n - h (w.n) n, both outward
    # a particle leaving the surface is held back by the damper
    assert penalty_drag(np.array([0.0]), n, -entering, 1.0, 0.8)[0, 2] < 0.0


def test_repulsion_points_away_from_neighbours_eq_3_3():
    p = np.array([[0.0, 0.0, 0.0]])
    q = np.array([[0.5, 0.0, 0.0], [0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])  # one near, one coincident, one far
    r = neighbour_repulsion(p, q, radius=1.0, strength=4.0)
    np.testing.assert_allclose(r, [[4.0 * -0.5 / 0.25, 0.0, 0.0]])  # r (P - Q)/|P - Q|^2, same point ignored


def test_spatial_hash_equals_brute_force():
    rng = np.random.default_rng(0)
    pts = rng.uniform(-2.0, 2.0, (1500, 3))
    pts[:50] = np.round(pts[:50], 1)  # exact duplicates and points on cell borders
    query = np.concatenate([pts[:200], rng.uniform(-2.5, 2.5, (50, 3))])
    radius = 0.3
    diff = query[:, None, :] - pts[None, :, :]
    d2 = np.sum(diff * diff, axis=-1)
    mask = (d2 <= radius * radius) & (d2 > 1e-18)
    brute = 2.0 * np.sum(np.where(mask[..., None], diff / np.where(mask, d2, 1.0)[..., None], 0.0), axis=1)
    np.testing.assert_allclose(neighbour_repulsion(query, pts, radius, 2.0), brute, rtol=1e-10, atol=1e-9)


def test_acceleration_has_magnitude_c_and_a_guard_eq_3_4():
    n = np.tile([0.0, 1.0, 0.0], (3, 1))
    drag = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    rep = np.array([[3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, -5.0, 0.0]])  # the last pushes into the surface
    a = collision_acceleration(drag, rep, n, np.array([2.0, 2.0, 2.0]))
    np.testing.assert_allclose(np.linalg.norm(a, axis=1), [2.0, 2.0, 2.0])
    np.testing.assert_allclose(a[0], 2.0 * np.array([3.0, 1.0, 0.0]) / np.sqrt(10.0))
    np.testing.assert_allclose(a[1], [0.0, 2.0, 0.0])  # D + R = 0 -> along the normal
    np.testing.assert_allclose(a[2], [0.0, 2.0, 0.0])  # inward part of R dropped


def test_circular_particles_spread_radially_around_the_hit():
    app, entity, st = _burst_at_wall(circular_probability=1.0, beam_radius=0.15, count=800, ticks=40)
    pattern = live(st, "pattern")
    assert (pattern >= 0).all() and (pattern % 2 == 0).all()
    offset = live(st, "position") - live(st, "hit_point")
    centre = np.array([0.0, 0.0])  # the beam axis
    radial = live(st, "hit_point")[:, :2] - centre
    accel = live(st, "acceleration")
    # Angular distribution around the wall normal (+z): uniform (mean resultant length of the angles ~ 0).
    phi = np.arctan2(accel[:, 1], accel[:, 0])
    resultant = np.hypot(np.cos(phi).mean(), np.sin(phi).mean())
    assert resultant < 0.1, resultant
    counts = np.histogram(phi, bins=8, range=(-np.pi, np.pi))[0]
    assert counts.min() > 0.6 * counts.mean()
    # Away from the surface (never into it) and mostly outward from the beam axis.
    assert (offset[:, 2] >= -1e-12).all()
    outward = np.einsum("ij,ij->i", accel[:, :2], radial) > 0.0
    assert outward.mean() > 0.7
    # |A| is c ± spread for everyone (eq. 3.4), c of the continuous / separated kind, in m/s per frame.
    mag = np.linalg.norm(accel, axis=1) * FRAME
    cont = pattern < 2
    assert np.all((mag[cont] >= 1.0 - 1e-9) & (mag[cont] <= 2.0 + 1e-9))
    assert np.all((mag[~cont] >= 1.5 - 1e-9) & (mag[~cont] <= 3.5 + 1e-9))


def test_mean_distance_from_the_hit_grows_at_the_speed_the_collision_gave():
    app, entity, st = _burst_at_wall(circular_probability=1.0, count=400, ticks=6)
    means = []
    for _ in range(4):
        app.step(8)
        means.append(np.linalg.norm(live(st, "position") - live(st, "hit_point"), axis=1).mean())
    assert np.all(np.diff(means) > 0.0), means
    # A acts during the collision frame: the particle leaves H with velocity A·frame and keeps it, so after
    # k steps |x - H| = |A| frame k dt, along A.
    k = np.round(live(st, "age") / app.dt)
    offset = live(st, "position") - live(st, "hit_point")
    dist = np.linalg.norm(offset, axis=1)
    accel = live(st, "acceleration")
    expected = np.linalg.norm(accel, axis=1) * FRAME * k * app.dt
    np.testing.assert_allclose(np.einsum("ij,ij->i", offset, accel), dist * np.linalg.norm(accel, axis=1),
                               rtol=1e-9)
    np.testing.assert_allclose(dist, expected, rtol=1e-9, atol=1e-12)


def test_particles_die_after_tau_and_alpha_falls():
    from systems.energy_wave.simulate import alpha

    app, entity, st = _burst_at_wall(circular_probability=1.0, count=200, ticks=8, lifetime_frames=20.0)
    a0 = alpha(st).mean()
    app.step(10)
    assert alpha(st).mean() < a0
    assert np.all(live(st, "age") <= 20 * FRAME + 1e-9)
    app.step(15)
    assert st.particles.count == 0


# ------------------------------------------------------------------------------------------------------ eq 3.5
def test_irregular_particles_reach_their_control_point_at_tau():
    points = [{"position": [0.5, 0.3, 1.0], "probability": 1.0}, {"position": [-0.4, 0.0, 0.6], "probability": 3.0}]
    app, entity, st = _burst_at_wall(circular_probability=0.0, control_points=points, count=400, ticks=4,
                                     lifetime_frames=30.0)
    cfg = app.world.get(entity, EnergyWaveEmitter)
    # Mid-flight: constant velocity v = (E - H)/τ (eq. 3.5).
    app.step(10)
    control = live(st, "control")
    targets = live(st, "hit_point") + np.array([p["position"] for p in points])[control]
    moving = live(st, "age") > app.dt
    np.testing.assert_allclose(live(st, "velocity")[moving], ((targets - live(st, "hit_point")) / (30 * FRAME))[moving],
                               rtol=1e-9, atol=1e-9)
    assert abs((control == 1).mean() - 0.75) < 0.1  # control point chosen by its probability
    # At the end of its life each particle sits on its control point.
    arrived = []
    for _ in range(40):
        app.step(1)
        done = np.abs(live(st, "age") - 30 * FRAME) < 1e-9
        if done.any():
            control = live(st, "control")[done]
            target = live(st, "hit_point")[done] + np.array([p["position"] for p in points])[control]
            arrived.append(np.abs(live(st, "position")[done] - target).max())
    assert arrived and max(arrived) < 1e-9
    assert cfg.lifetime_frames == 30.0


def test_control_points_follow_keyframes_and_noise():
    from engine.noise import PerlinNoise

    cfg = EnergyWaveEmitter.model_validate({"control_points": [
        {"keyframes": [{"time": 0.0, "position": [0.0, 0.0, 0.0]}, {"time": 2.0, "position": [2.0, 0.0, 0.0]}],
         "loop": True},
        {"position": [0.0, 1.0, 0.0], "noise_amplitude": 0.3, "noise_frequency": 2.0}]})
    noise = PerlinNoise(4)
    np.testing.assert_allclose(control_point_offsets(cfg, 0.5, noise)[0], [0.5, 0.0, 0.0])
    np.testing.assert_allclose(control_point_offsets(cfg, 2.5, noise)[0], [0.5, 0.0, 0.0])  # looped
    jitter = np.array([control_point_offsets(cfg, t, noise)[1] for t in np.linspace(0.1, 3.0, 30)])
    assert np.abs(jitter - [0.0, 1.0, 0.0]).max() <= 0.3 * 1.01
    assert jitter.std(axis=0).min() > 0.01  # it moves on every axis


def test_irregular_particles_track_an_animated_control_point():
    points = [{"keyframes": [{"time": 0.0, "position": [-1.0, 0.0, 0.5]}, {"time": 1.0, "position": [1.0, 0.0, 0.5]}],
               "noise_amplitude": 0.05}]
    app, entity, st = _burst_at_wall(circular_probability=0.0, control_points=points, count=200, ticks=4,
                                     lifetime_frames=30.0)
    from systems.energy_wave.simulate import _noise

    cfg = app.world.get(entity, EnergyWaveEmitter)
    for _ in range(40):
        app.step(1)
        done = np.abs(live(st, "age") - 30 * FRAME) < 1e-9
        if done.any():
            e = control_point_offsets(cfg, st.time, _noise(st))[0]
            np.testing.assert_allclose(live(st, "position")[done], live(st, "hit_point")[done] + e, atol=1e-9)
            return
    pytest.fail("no particle reached the end of its life")


def test_control_points_are_relative_to_the_wave_direction():
    """The same config fired along +x instead of -z lands its control point rotated with the emitter."""
    app = make_app(1)
    add_box(app, (2.25, 0.0, 0.0), (0.25, 3.0, 3.0))  # face at x = 2, normal -x
    entity, cfg, st = add_emitter(app, yaw_pitch_roll=(-np.pi / 2, 0.0, 0.0), emitting=False, beam_speed=10.0,
                                  circular_probability=0.0, control_points=[{"position": [0.0, 0.5, 1.0]}])
    fire(app.world, entity, count=100, duration=0.05)
    app.step(20)
    transform = app.world.get(entity, Transform)
    np.testing.assert_allclose(transform.forward(), [1.0, 0.0, 0.0], atol=1e-12)
    offset = quat_rotate(transform.rotation, np.array([0.0, 0.5, 1.0]))  # +z local = back towards the emitter
    np.testing.assert_allclose(offset, [-1.0, 0.5, 0.0], atol=1e-12)
    moving = live(st, "age") > app.dt
    v = live(st, "velocity")[moving]
    np.testing.assert_allclose(v / np.linalg.norm(v, axis=1, keepdims=True),
                               np.tile(offset / np.linalg.norm(offset), (len(v), 1)), atol=1e-9)


def test_turning_the_emitter_after_the_hit_does_not_swing_the_splash():
    """Control points are relative to the direction of the wave a particle came with (eq. 3.5): the player
    turning after firing must not rotate splashes already flying (they swung into the wall before)."""
    from engine.spatial import quat_from_euler

    point = [1.0, 0.0, 0.0]
    app, entity, st = _burst_at_wall(circular_probability=0.0, control_points=[{"position": point}], count=200,
                                     ticks=4, lifetime_frames=30.0)
    fired = app.world.get(entity, Transform).rotation.copy()
    app.world.get(entity, Transform).rotation = quat_from_euler(np.pi / 2, 0.0, 0.0)  # turn 90° about y
    arrived = []
    for _ in range(40):
        app.step(1)
        done = np.abs(live(st, "age") - 30 * FRAME) < 1e-9
        if done.any():
            target = live(st, "hit_point")[done] + quat_rotate(fired, np.array(point))
            arrived.append(np.abs(live(st, "position")[done] - target).max())
    assert arrived and max(arrived) < 1e-9
    assert np.all(live(st, "position")[:, 2] >= WALL_Z - 1e-9)  # none inside the wall


def test_irregular_particles_leave_the_hit_with_the_velocity_of_eq_3_5():
    """On the step of the hit an irregular particle already moves at (E - H) / τ, so its bar is drawn along its
    path (at rest it had no direction and was drawn pointing up)."""
    from systems.energy_wave.extract import _directions

    point = [0.6, 0.0, 0.8]
    app = make_app(2)
    add_box(app, (0.0, 0.0, WALL_Z - 0.25), (3.0, 3.0, 0.25))
    entity, cfg, st = add_emitter(app, emitting=False, beam_speed=10.0, circular_probability=0.0,
                                  control_points=[{"position": point}], lifetime_frames=30.0)
    fire(app.world, entity, count=300, duration=0.05)
    for _ in range(20):
        app.step(1)
        landed = (live(st, "pattern") >= 0) & (live(st, "age") == 0.0)
        if landed.any():
            break
    else:
        pytest.fail("no particle hit the wall")
    expected = np.array(point) / (30 * FRAME)
    np.testing.assert_allclose(live(st, "velocity")[landed], np.tile(expected, (int(landed.sum()), 1)), atol=1e-9)
    d = _directions(live(st, "velocity")[landed], live(st, "acceleration")[landed],
                    live(st, "position")[landed] - live(st, "hit_point")[landed])
    np.testing.assert_allclose(np.abs(d @ (expected / np.linalg.norm(expected))), 1.0, atol=1e-9)


# ---------------------------------------------------------------------------------------------------- collisions
def _events(app, etype, ticks):
    reader = app.world.events.reader(etype)
    per_tick = []
    for _ in range(ticks):
        app.step(1)
        per_tick.append(reader.read())
    return per_tick


def test_fig_4_7_part_of_the_beam_flies_on_to_a_second_box():
    app = make_app(7)
    first = add_box(app, (0.5, 0.0, -2.0), (0.5, 1.0, 0.1))  # covers x > 0 only
    second = add_box(app, (0.0, 0.0, -5.0), (2.0, 2.0, 0.1))
    entity, _, st = add_emitter(app, beam_radius=0.3, emission_rate=2000.0, beam_speed=10.0)
    hits = [h for tick in _events(app, EnergyWaveHit, 70) for h in tick]
    by_target = {first: 0, second: 0}
    for h in hits:
        by_target[h.target] += h.count
    assert by_target[first] > 200 and by_target[second] > 200
    # about half the beam's cross-section is covered by the first box
    assert 0.3 < by_target[first] / (by_target[first] + by_target[second]) < 0.7
    # every particle stopped on the surface of the box it hit
    hit_points = live(st, "hit_point")[live(st, "pattern") >= 0]
    on_first = np.isclose(hit_points[:, 2], -1.9)
    on_second = np.isclose(hit_points[:, 2], -4.9)
    assert (on_first | on_second).all()
    assert (hit_points[on_first, 0] >= -1e-9).all()


def test_impacts_are_aggregated_per_target_per_tick():
    app = make_app(3)
    a = add_box(app, (0.5, 0.0, -1.2), (0.5, 1.0, 0.2))
    b = add_box(app, (-0.5, 0.0, -1.2), (0.5, 1.0, 0.2))
    entity, cfg, st = add_emitter(app, beam_radius=0.2, emission_rate=3000.0, beam_speed=10.0, particle_mass=0.01)
    impacts = _events(app, Impact, 20)
    hits = _events(app, EnergyWaveHit, 1)[0]
    assert any(len(tick) == 2 for tick in impacts)
    for tick in impacts:
        targets = [i.target for i in tick]
        assert len(targets) == len(set(targets))  # one per target per tick
        assert all(i.source == entity and i.kind == "energy_wave" and i.target in (a, b) for i in tick)
    for h in hits:  # impulse = m Σ w, energy = ½ m Σ |w|², all along the beam (-z) at 10 m/s
        np.testing.assert_allclose(h.impulse, [0.0, 0.0, -0.01 * 10.0 * h.count], atol=1e-9)
        assert h.energy == pytest.approx(0.5 * 0.01 * 100.0 * h.count)
        np.testing.assert_allclose(h.normal, [0.0, 0.0, 1.0], atol=1e-9)


@pytest.mark.parametrize("shape", ["sphere", "plane", "heightfield", "rotated_box"])
def test_the_beam_hits_every_collider_shape(shape):
    app = make_app(4)
    world = app.world
    if shape == "sphere":
        target = world.spawn(Transform(position=np.array([0.0, 0.0, -3.0])), Collider(shape="sphere", radius=1.0))
    elif shape == "plane":  # the ground, beam pointing down
        target = world.spawn(Transform(position=np.array([0.0, -2.0, 0.0])), Collider(shape="plane"))
    elif shape == "heightfield":
        xs = np.linspace(-4.0, 4.0, 17)
        field = HeightField(0.3 * np.sin(xs)[None, :] + 0.2 * np.cos(xs)[:, None], 0.5, np.array([-4.0, -4.0]))
        target = world.spawn(Transform(position=np.array([0.0, -2.0, 0.0])), Collider("heightfield", heightfield=field))
    else:
        from engine.spatial import quat_from_axis_angle

        target = world.spawn(Transform(position=np.array([0.0, 0.0, -3.0]),
                                       rotation=quat_from_axis_angle([0.0, 1.0, 0.0], 0.6)), Collider("box"))
    pitch = -np.pi / 2 if shape in ("plane", "heightfield") else 0.0
    entity, _, st = add_emitter(app, yaw_pitch_roll=(0.0, pitch, 0.0), beam_radius=0.2, beam_speed=10.0,
                                circular_probability=1.0)
    app.step(30)
    hit = live(st, "pattern") >= 0
    assert hit.sum() > 50
    transform = world.get(target, Transform)
    collider = world.get(target, Collider)
    distance = collider.signed_distance(live(st, "hit_point")[hit], transform)
    assert np.abs(distance).max() < 1e-6  # hit points lie on the surface
    # circular particles leave the surface (never go into it)
    assert (collider.signed_distance(live(st, "position")[hit], transform) > -1e-6).all()


def test_terrain_component_collides():
    from engine.builtin import TerrainConfig, _build_terrain
    from engine.registry import BuildContext

    app = make_app(2)
    ground = app.world.reserve()
    comps = _build_terrain(TerrainConfig(size_exponent=4, spacing=1.0, amplitude=1.0),
                           BuildContext(app.world, ground, "ground", "<t>", None))
    app.world.spawn(Transform(position=np.array([0.0, -3.0, 0.0])), *comps, entity=ground)
    assert isinstance(comps[0], Terrain)
    entity, _, st = add_emitter(app, yaw_pitch_roll=(0.0, -1.2, 0.0), beam_speed=10.0)
    hits = [h for tick in _events(app, EnergyWaveHit, 40) for h in tick]
    assert hits and all(h.target == ground for h in hits)


def test_beam_that_misses_dies_after_its_range():
    app = make_app(1)
    entity, cfg, st = add_emitter(app, beam_speed=10.0, beam_range=2.0, emission_rate=600.0)
    app.step(60)
    assert st.particles.count > 0
    assert np.linalg.norm(live(st, "position"), axis=1).max() <= 2.0 + 1e-9
    assert (live(st, "pattern") == -1).all()


def test_triggers_report_but_do_not_stop_the_beam():
    app = make_app(1)
    trig = add_box(app, (0.0, 0.0, -1.0), (1.0, 1.0, 0.1), is_trigger=True)
    wall = add_box(app, (0.0, 0.0, -3.0), (1.0, 1.0, 0.1))
    entity, cfg, st = add_emitter(app, beam_speed=10.0, emission_rate=600.0)
    hits = [h for tick in _events(app, EnergyWaveHit, 40) for h in tick]
    impacts = [i for tick in _events(app, Impact, 5) for i in tick]
    assert any(h.target == trig and h.trigger for h in hits)
    assert any(h.target == wall and not h.trigger for h in hits)
    assert impacts and all(i.target == wall for i in impacts)


def test_collision_layers_filter_targets():
    app = make_app(1)
    add_box(app, (0.0, 0.0, -1.0), (1.0, 1.0, 0.1), layer="glass")
    wall = add_box(app, (0.0, 0.0, -3.0), (1.0, 1.0, 0.1), layer="walls")
    entity, cfg, st = add_emitter(app, beam_speed=10.0, emission_rate=600.0, collision_layers=["walls"])
    hits = [h for tick in _events(app, EnergyWaveHit, 40) for h in tick]
    assert hits and all(h.target == wall for h in hits)


# ------------------------------------------------------------------------------------------------------ stability
EXTREMES = [
    dict(acceleration_continuous=0.0, acceleration_separated=0.0, acceleration_continuous_spread=0.0,
         acceleration_separated_spread=0.0),
    dict(spring=0.0, damper=0.0, repulsion=0.0),
    dict(repulsion=1e6, repulsion_radius=100.0, spring=1e6, damper=1e6, equation_unit=1e-4),
    dict(splash_samples=64, trail_textures=64, splash_roundness=1e-6, lifetime_frames=1.0, lifetime_spread=1e4),
    dict(circular_probability=0.5, continuity_probability=0.5, beam_radius=0.0,
         control_points=[{"position": [0.0, 0.0, 0.0], "spread": 0.0}, {"position": [0.0, 0.0, 0.0],
                                                                          "probability": 0.0, "spread": 100.0}]),
    dict(emission_rate=1e7, max_particles=500, acceleration_separated=1e4, lifetime_frames=100_000.0),
]


@pytest.mark.parametrize("fields", EXTREMES)
def test_no_nan_at_extreme_parameters(fields):
    app = make_app(9)
    add_box(app, (0.0, 0.0, -0.6), (1.0, 1.0, 0.1))
    entity, cfg, st = add_emitter(app, beam_speed=20.0, **{"emission_rate": 3000.0, **fields})
    for _ in range(6):  # a long run: 10 s of game time, checked every 100 steps (several lifetimes τ)
        app.step(100)
        buf = st.particles
        assert buf.count > 0
        for array in buf.arrays():
            assert np.isfinite(array[: buf.count]).all()
    if "max_particles" in fields:
        assert buf.count <= 500 and st.dropped > 0


def test_sampled_crowded_cells_estimate_the_exact_sum():
    """Crowded hash cells are sampled (bounded cost): the estimate follows the exact R closely."""
    rng = np.random.default_rng(1)
    pts = rng.normal(0.0, 0.08, (4000, 3))  # a dense core: hundreds of points per cell
    query = pts[:300]
    exact = neighbour_repulsion(query, pts, 0.1, 1.0)
    sampled = neighbour_repulsion(query, pts, 0.1, 1.0, per_bucket_limit=16)
    cos = np.einsum("ij,ij->i", exact, sampled) / (np.linalg.norm(exact, axis=1) * np.linalg.norm(sampled, axis=1))
    assert np.median(cos) > 0.9
    ratio = np.linalg.norm(sampled, axis=1).sum() / np.linalg.norm(exact, axis=1).sum()
    assert 0.8 < ratio < 1.25


def _sampled_reference(query, pts, radius, limit, strength=1.0):
    """The sampled R (eq. 3.3) pair by pair, straight from the definition: the points in reach hashed into a table
    of 2·n (a power of 2, at least 16) buckets, sorted by bucket (ties by index); for each query the buckets of the
    27 cells around it (each bucket once, in ascending order); when some bucket holds more than ``limit``
    points, sample k < limit of a bucket of count c sits at slot floor((k + phase)·c/taken) with weight c/taken,
    the phase a golden-ratio sequence over the non-empty (query, bucket) pairs."""
    from systems.energy_wave.neighbours import _GOLDEN, _hash, in_reach

    near = pts[in_reach(pts, query, radius)]
    table = 1 << max(4, (2 * len(near) - 1).bit_length())
    keys = _hash(np.floor(near / radius).astype(np.int64), table)
    near = near[np.argsort(keys, kind="stable")]
    counts = np.bincount(keys, minlength=table)
    starts = np.cumsum(counts) - counts
    rows = []
    for cell in np.floor(query / radius).astype(np.int64):
        around = {int(_hash(cell + np.array(offset) - 1, table)) for offset in np.ndindex(3, 3, 3)}
        rows.append(sorted(key for key in around if counts[key] > 0))
    sampled = max(counts[key] for keys in rows for key in keys) > limit
    out = np.zeros_like(query)
    serial = 0
    for i, keys in enumerate(rows):
        for key in keys:  # the kernel's float order: per bucket its samples in order, then the buckets in order
            count = int(counts[key])
            taken = min(count, limit) if sampled else count
            stride = count / taken
            phase = serial * _GOLDEN % 1.0 if sampled else 0.0
            serial += 1
            bucket = np.zeros(3)
            for k in range(taken):
                d = query[i] - near[min(starts[key] + int((k + phase) * stride), len(near) - 1)]
                d2 = float(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                if 1e-18 < d2 <= radius * radius:
                    bucket += d * (stride / d2)
            out[i] += bucket
    return out * strength


def test_sampled_repulsion_equals_the_sampling_evaluated_pair_by_pair():
    rng = np.random.default_rng(5)
    pts = np.concatenate([rng.normal(0.0, 0.06, (1500, 3)), rng.uniform(-0.5, 0.5, (300, 3))])
    query = np.concatenate([pts[:60], rng.uniform(-0.3, 0.3, (20, 3))])
    got = neighbour_repulsion(query, pts, 0.1, 1.0, per_bucket_limit=16)
    assert not np.allclose(got, neighbour_repulsion(query, pts, 0.1, 1.0))  # crowded cells were sampled
    np.testing.assert_allclose(got, _sampled_reference(query, pts, 0.1, 16), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("limit", [0, 16, 3])
def test_kernel_repulsion_is_the_pair_by_pair_sum_bit_for_bit(limit):
    """The compiled kernels (hash, bucket scan, sampling, float order) give exactly the pair-by-pair sum."""
    rng = np.random.default_rng(11 + limit)
    pts = np.concatenate([rng.normal(0.3, 0.05, (900, 3)), rng.uniform(-0.4, 0.6, (200, 3))])
    pts[:40] = np.round(pts[:40], 1)  # duplicates and points on cell borders
    query = np.concatenate([pts[:50], pts[:1], rng.uniform(-0.2, 0.8, (30, 3))])  # a query twice
    got = neighbour_repulsion(query, pts, 0.1, 4.0, per_bucket_limit=limit)
    assert np.abs(got).max() > 0.0
    assert np.array_equal(got, _sampled_reference(query, pts, 0.1, limit if limit else 1 << 62, 4.0))


def test_a_target_that_moves_is_hit_where_it_is_now():
    """The sweep's collider bounds are cached while a collider stays put: moving the target (in place, as a
    script does) must move the hits with it."""
    app = make_app(5)
    box = add_box(app, (0.0, 0.0, -2.0), (1.0, 1.0, 0.1))
    entity, _, st = add_emitter(app, beam_radius=0.1, emission_rate=2000.0, beam_speed=10.0)
    first = [h for tick in _events(app, EnergyWaveHit, 20) for h in tick]
    assert first and all(abs(h.point[2] + 1.9) < 1e-6 for h in first)
    app.world.get(box, Transform).position[2] = -4.0  # in place: the same array object
    later = [h for tick in _events(app, EnergyWaveHit, 60)[30:] for h in tick]
    assert later and all(abs(h.point[2] + 3.9) < 1e-6 for h in later)


def test_a_fast_beam_hits_a_thin_wall_just_ahead_of_the_emitter():
    """A new particle is placed up to beam_speed·dt ahead of the emitter (0.75 m at 45 m/s); the stretch between
    the emitter and that point is swept in its first step, so a wall 0.3 m ahead stops the whole beam."""
    from tests.systems.energy_wave.helpers import add_box, add_emitter, live, make_app

    app = make_app(1)
    add_box(app, (0.0, 0.0, -0.35), (2.0, 2.0, 0.05))  # faces at z = -0.30 and -0.40; the beam fires along -z
    _, cfg, st = add_emitter(app, beam_speed=45.0)
    app.step(30)
    pattern, position, age = live(st, "pattern"), live(st, "position"), live(st, "age")
    hit_point = live(st, "hit_point")
    dt = app.clock.dt
    splashes = pattern >= 0
    assert splashes.sum() > 100
    assert np.all(hit_point[splashes, 2] >= -0.30 - 1e-9)  # every hit on the wall's near face
    beam = pattern < 0
    assert np.all(position[beam & (age >= dt), 2] >= -0.30)  # swept once: none went through
    # only the particles of the last step, not swept yet, may lie up to beam_speed·dt ahead (the wall hides them)
    assert np.all(position[beam, 2] >= -45.0 * dt - cfg.beam_radius)


def _pond(app, position) -> int:
    """A still 7.5 m water surface's collider (a flat height field, layer 'water') at ``position``."""
    field = HeightField(np.zeros((16, 16)), 0.5, np.array([-3.75, -3.75]))
    return app.world.spawn(Transform(position=np.array(position, float)),
                           Collider("heightfield", heightfield=field, layer="water"))


def test_a_pond_beside_the_emitter_does_not_swallow_the_beam():
    # A height field counted every point below its surface's level as inside, however far beside its footprint:
    # with a pond 8 m away whose surface is 1 m above the emitter, every particle hit the pond at t = 0 where it
    # was emitted. The pond is solid over its footprint only.
    app = make_app(5)
    pond = _pond(app, (8.0, 1.0, 0.0))
    wall = add_box(app, (0.0, 0.0, -3.0), (1.0, 1.0, 0.1))
    entity, _, st = add_emitter(app, beam_speed=10.0, emission_rate=600.0)
    hits = [h for tick in _events(app, EnergyWaveHit, 40) for h in tick]
    impacts = [i for tick in _events(app, Impact, 5) for i in tick]
    assert hits and all(h.target == wall for h in hits)
    assert impacts and all(i.target == wall for i in impacts) and pond not in [i.target for i in impacts]


def test_a_beam_below_a_ponds_surface_hits_its_side():
    """The pond is the column below its surface over its footprint: a beam flying at it below its surface's
    level stops at the footprint's side (z = -4.25), with the side's normal."""
    app = make_app(5)
    pond = _pond(app, (0.0, 1.0, -8.0))
    entity, _, st = add_emitter(app, beam_radius=0.2, beam_speed=10.0, emission_rate=600.0)
    hits = [h for tick in _events(app, EnergyWaveHit, 50) for h in tick]
    assert hits and all(h.target == pond for h in hits)
    for h in hits:
        np.testing.assert_allclose(h.normal, [0.0, 0.0, 1.0], atol=1e-9)
    hit_points = live(st, "hit_point")[live(st, "pattern") >= 0]
    assert len(hit_points) > 20
    np.testing.assert_allclose(hit_points[:, 2], -4.25, atol=1e-9)
