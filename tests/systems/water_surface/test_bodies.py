"""Floating rigid bodies: buoyancy, draft, sinking, righting, impulses from scripts and impacts, two-way coupling."""

from __future__ import annotations

import numpy as np
import pytest

from components.water_surface import RigidBody, RigidBodyState, WaterState
from engine.app import App
from engine.impacts import Impact
from engine.spatial import Transform, quat_rotate
from systems.water_surface.bodies import BodyArrays, inertia
from systems.water_surface.geometry import BOX, SPHERE
from tests.systems.water_surface.helpers import CONFIGS, rigid_body_entity, write_scene

WATER = "resolution = [16, 16]\nspacing = 0.4\nwave_speed = 1.5\ndamping = 0.99\ndepth = 1.0"


def _app(tmp_path, bodies: str, water: str = WATER) -> App:
    return App(write_scene(tmp_path, water, bodies), configs_root=CONFIGS)


def _entity(app: App, name: str) -> int:
    from engine.builtin import Name

    return next(e for e, (n,) in app.world.query(Name) if n.value == name)


def _roll_pitch(q) -> float:
    """Angle in degrees between the body's up axis and the world's."""
    up = quat_rotate(q, np.array([0.0, 1.0, 0.0]))
    return float(np.degrees(np.arccos(np.clip(up[1], -1.0, 1.0))))


def test_inertia_follows_the_shape():
    bodies = BodyArrays(shapes=np.array([BOX, SPHERE], np.int8), half=np.array([[0.5, 1.0, 1.5], [0.5, 0.5, 0.5]]),
                        radius=np.array([0.5, 2.0]), mass=np.array([12.0, 10.0]), position=np.zeros((2, 3)),
                        rotation=np.tile([1.0, 0, 0, 0], (2, 1)), velocity=np.zeros((2, 3)), spin=np.zeros((2, 3)),
                        force=np.zeros((2, 3)), torque=np.zeros((2, 3)), gravity=np.zeros(2),
                        linear_damping=np.zeros(2), angular_damping=np.zeros(2), restitution=np.zeros(2),
                        friction=np.zeros(2), max_speed=np.full(2, 1e3), max_spin=np.full(2, 1e2))
    moments = inertia(bodies)
    assert moments[0] == pytest.approx([4.0 + 9.0, 1.0 + 9.0, 1.0 + 4.0])  # m/12·(b² + c²), full sizes 1, 2, 3
    assert moments[1] == pytest.approx([16.0] * 3)  # 2/5·m·r²


def test_a_box_released_above_the_water_settles_at_its_draft(tmp_path):
    app = _app(tmp_path, rigid_body_entity("crate", (0.2, 0.45, -0.1), mass=200.0))
    crate = _entity(app, "crate")
    app.step(420)
    t, state = app.world.get(crate, Transform), app.world.get(crate, RigidBodyState)
    draft = 0.3 - t.position[1]  # half height 0.3 above the centre; the water's rest level is 0
    assert draft == pytest.approx(200.0 / (1000.0 * 1.0 * 0.8), rel=0.02)  # mass / (ρ · area)
    assert state.submerged_volume == pytest.approx(0.2, rel=0.02)
    assert np.linalg.norm(state.velocity) < 0.05


def test_a_sphere_floats_with_its_weight_of_water_displaced(tmp_path):
    app = _app(tmp_path, rigid_body_entity("buoy", (0.0, 0.6, 0.0), scale=(1.0, 1.0, 1.0), shape="sphere", mass=150.0))
    buoy = _entity(app, "buoy")
    app.step(420)
    assert app.world.get(buoy, RigidBodyState).submerged_volume == pytest.approx(0.15, rel=0.03)


@pytest.mark.parametrize("density", [0.1, 0.25, 0.75])
def test_a_sphere_floats_at_the_draft_of_its_spherical_cap(tmp_path, density):
    """The centre's height against the exact cap π·d²·(3r − d)/3 = m/ρ for a radius of 0.5 m: within 2 mm (the
    81 lattice points of the old sampling put it 1.6–2.8 cm off)."""
    r, volume = 0.5, 4.0 / 3.0 * np.pi * 0.5 ** 3
    app = _app(tmp_path, rigid_body_entity("buoy", (0.0, 0.2, 0.0), scale=(1.0, 1.0, 1.0), shape="sphere",
                                           mass=density * 1000.0 * volume))
    buoy = _entity(app, "buoy")
    app.step(600)
    lo, hi = 0.0, 2.0 * r  # the draft d by bisection
    for _ in range(60):
        d = 0.5 * (lo + hi)
        lo, hi = (d, hi) if np.pi * d * d * (3.0 * r - d) / 3.0 < density * volume else (lo, d)
    assert app.world.get(buoy, Transform).position[1] == pytest.approx(r - d, abs=0.002)


def test_a_body_denser_than_water_sinks_to_the_floor(tmp_path):
    app = _app(tmp_path, rigid_body_entity("stone", (0.0, 0.5, 0.0), mass=1000.0))  # 0.48 m³: denser than water
    stone = _entity(app, "stone")
    app.step(60)
    assert app.world.get(stone, Transform).position[1] < -0.5  # well under the surface
    app.step(240)
    t, state = app.world.get(stone, Transform), app.world.get(stone, RigidBodyState)
    assert t.position[1] - 0.3 == pytest.approx(-1.0, abs=0.02)  # resting on the floor (depth 1 m)
    assert np.linalg.norm(state.velocity) < 0.05


def test_a_tilted_box_rights_itself(tmp_path):
    app = _app(tmp_path, rigid_body_entity("raft", (0.0, 0.0, 0.0), scale=(1.2, 0.4, 1.0), rotation=(0.0, 0.0, 25.0),
                                           mass=200.0))
    raft = _entity(app, "raft")
    app.step(1)
    assert _roll_pitch(app.world.get(raft, Transform).rotation) > 20.0
    app.step(480)
    assert _roll_pitch(app.world.get(raft, Transform).rotation) < 3.0


@pytest.mark.parametrize("roll", [45.0, 20.0])
def test_a_box_floating_tilted_onto_an_edge_stops_bobbing(tmp_path, roll):
    """A cube at a quarter of water's density floats tilted (on an edge, or about 33° from flat). Its sloped sides
    move the outline while it bobs; with S' taken over its footprint only, its own outline waves raised S' in phase
    with the motion and it bobbed 0.24 m (45°) or 0.42 m (20°) peak to peak for good at α = 1."""
    water = "resolution = [26, 26]\nspacing = 0.4\nwave_speed = 1.5\noutline_constant = 1.0"
    app = _app(tmp_path, rigid_body_entity("crate", (0.0, 0.3, 0.0), scale=(1.0, 1.0, 1.0), rotation=(0.0, 0.0, roll),
                                           mass=250.0), water)
    crate = _entity(app, "crate")
    app.step(12 * 60)
    heights = []
    for _ in range(3 * 60):
        app.step(1)
        heights.append(app.world.get(crate, Transform).position[1])
    assert np.ptp(heights) < 0.01
    assert 25.0 < _roll_pitch(app.world.get(crate, Transform).rotation) < 65.0  # still tilted: it did float

def test_a_script_impulse_changes_the_velocity_by_j_over_m(tmp_path):
    app = _app(tmp_path, rigid_body_entity("crate", (0.0, 30.0, 0.0), mass=50.0, linear_damping=0.0))
    crate = _entity(app, "crate")
    app.registry.command("rigid_body.apply_impulse")(app.world, crate, impulse=(100.0, 0.0, -50.0))
    app.step(1)
    v = app.world.get(crate, RigidBodyState).velocity
    assert v == pytest.approx([2.0, -9.81 / 60.0, -1.0])


def test_an_impact_event_pushes_and_spins_the_body(tmp_path):
    app = _app(tmp_path, rigid_body_entity("crate", (0.0, 30.0, 0.0), scale=(1.0, 1.0, 1.0), mass=60.0,
                                           linear_damping=0.0, angular_damping=0.0, gravity=0.0))
    crate = _entity(app, "crate")
    app.world.events.send(Impact(target=crate, point=(0.5, 30.0, 0.0), impulse=(0.0, 0.0, 12.0)))
    app.step(1)
    state = app.world.get(crate, RigidBodyState)
    assert state.velocity == pytest.approx([0.0, 0.0, 0.2])
    # r × J = (0.5, 0, 0) × (0, 0, 12) = (0, −6, 0); I = m/6 = 10 → ω = −0.6 about y
    assert state.angular_velocity == pytest.approx([0.0, -0.6, 0.0], abs=1e-9)
    app.step(1)
    assert app.world.get(crate, RigidBodyState).velocity == pytest.approx([0.0, 0.0, 0.2])  # read once


def test_an_impact_on_the_water_makes_a_wave(tmp_path):
    app = _app(tmp_path, "")
    water = _entity(app, "water")
    app.world.events.send(Impact(target=water, point=(0.0, 0.0, 0.0), impulse=(0.0, -2000.0, 0.0)))
    app.step(2)
    heights = app.world.get(water, WaterState).heights
    assert heights.min() < -1e-3 and abs(heights.mean()) < 1e-12


def test_waves_move_a_floating_body(tmp_path):
    runs = []
    for splash in (False, True):
        app = _app(tmp_path, rigid_body_entity("crate", (1.0, 0.05, 0.0), mass=200.0, linear_damping=0.0))
        crate = _entity(app, "crate")
        app.step(240)  # settle
        if splash:
            app.registry.command("water_surface.splash")(app.world, crate, point=(-1.0, 0.0, 0.0), height=0.3)
        speed = []
        for _ in range(90):
            app.step(1)
            speed.append(np.abs(app.world.get(crate, RigidBodyState).velocity))
        runs.append(np.max(speed, axis=0))
    calm, hit = runs
    assert hit[1] > 5 * calm[1] + 0.01  # it bobs as the wave passes under it
    assert hit[0] > 5 * calm[0] + 1e-3  # and is pushed along


def test_a_body_away_from_any_water_falls_freely(tmp_path):
    app = _app(tmp_path, rigid_body_entity("rock", (50.0, 10.0, 0.0), mass=10.0, linear_damping=0.0))
    rock = _entity(app, "rock")
    app.step(60)
    assert app.world.get(rock, Transform).position[1] == pytest.approx(10.0 - 0.5 * 9.81 * 1.0, abs=0.1)


def test_a_kinematic_body_follows_its_script_and_keeps_its_velocity(tmp_path):
    glide = '{ name = "water_surface.glide", params = { velocity = [0.6, 0.0, 0.0], distance = 10.0 } }'
    body = rigid_body_entity("barge", (-1.0, 0.0, 0.0), mass=100.0, kinematic=True).replace(
        'name = "barge"', f'name = "barge"\nscripts = [{glide}]')
    app = _app(tmp_path, body)
    barge = _entity(app, "barge")
    app.step(60)
    assert app.world.get(barge, Transform).position == pytest.approx([-0.4, 0.0, 0.0])
    assert app.world.get(barge, RigidBodyState).velocity == pytest.approx([0.6, 0.0, 0.0])
    assert np.abs(app.world.get(_entity(app, "water"), WaterState).heights).max() > 1e-3  # it made waves


# ----------------------------------------------------------------------------- speed limits (robustness)
def test_an_initial_spin_above_the_limit_is_a_config_error_naming_both_keys():
    from engine.config import ConfigError, validate

    with pytest.raises(ConfigError) as err:
        validate(RigidBody, {"angular_velocity": [1.0e6, 0.0, 0.0]}, "crate.toml")
    assert "angular_velocity" in str(err.value) and "max_angular_speed = 100" in str(err.value)
    validate(RigidBody, {"angular_velocity": [1.0e3, 0.0, 0.0], "max_angular_speed": 1000.0}, "crate.toml")


@pytest.mark.parametrize("spin, impulse", [(5.0e3, 0.0), (0.0, 1.0e300), (0.0, float("inf"))])
def test_spin_and_speed_stay_finite_and_limited_whatever_a_script_gives_a_body(tmp_path, spin, impulse):
    """An asymmetric box spun at 5000 rad/s (explicit gyroscopic term: it blew up to NaN and crashed the water's
    rasterisation of the body) or kicked with an overflowing impulse keeps a finite state within its limits."""
    app = _app(tmp_path, rigid_body_entity("crate", (0.2, 0.2, -0.1), scale=(1.0, 0.3, 0.6), mass=100.0,
                                           max_angular_speed=1000.0))
    crate = _entity(app, "crate")
    state = app.world.get(crate, RigidBodyState)
    state.angular_velocity = np.array([spin, 0.3 * spin, 0.1 * spin])
    state.impulse = np.array([impulse, 0.0, 0.0])
    with np.errstate(over="ignore", invalid="ignore"):
        app.step(40)
    t, state = app.world.get(crate, Transform), app.world.get(crate, RigidBodyState)
    assert np.isfinite(t.position).all() and np.isfinite(t.rotation).all()
    assert np.linalg.norm(state.angular_velocity) <= 1000.0 * (1 + 1e-12)
    assert np.linalg.norm(state.velocity) <= 1000.0 * (1 + 1e-12)
    water = app.world.query(WaterState)[0][1][0]
    assert np.isfinite(water.heights).all()


def test_a_huge_force_or_torque_through_the_public_commands_keeps_the_body_within_its_limits(tmp_path):
    """The limit applies before the position and rotation move (a force of 1e12 N moved a body 8e5 m in five
    ticks; 1e200 N at an offset crashed the water with NaN), and after the pool's contacts."""
    from systems.water_surface.api import apply_force

    app = _app(tmp_path, rigid_body_entity("crate", (0.2, 0.2, -0.1), scale=(1.0, 0.3, 0.6), mass=100.0))
    crate = _entity(app, "crate")
    start = app.world.get(crate, Transform).position.copy()
    for _ in range(6):
        apply_force(app.world, crate, [1e12, 1e200, 3e11], point=app.world.get(crate, Transform).position + [0.3, 0, 0.1])
        app.step(1)
    t, state = app.world.get(crate, Transform), app.world.get(crate, RigidBodyState)
    assert np.isfinite(t.position).all() and np.isfinite(t.rotation).all()
    assert np.linalg.norm(t.position - start) <= 6 * 1000.0 / 60.0 * (1 + 1e-9)
    assert np.linalg.norm(state.angular_velocity) <= 100.0 * (1 + 1e-12)


def test_the_limit_scales_a_finite_velocity_too_long_to_square_instead_of_zeroing_it():
    from systems.water_surface.bodies import _limit

    out = _limit(np.array([[1e200, 0.0, -1e200], [np.inf, 0.0, 0.0], [3.0, 4.0, 0.0]]), np.array([10.0, 10.0, 10.0]))
    assert out[0] == pytest.approx([10.0 / np.sqrt(2.0), 0.0, -10.0 / np.sqrt(2.0)])
    assert (out[1] == 0.0).all() and (out[2] == [3.0, 4.0, 0.0]).all()


def test_a_contact_cannot_leave_the_spin_above_its_limit(tmp_path):
    app = _app(tmp_path, rigid_body_entity("crate", (0.2, -0.3, -0.1), rotation=(35.0, 10.0, 20.0), mass=900.0,
                                           velocity=[0.0, -5.0, 0.0], max_angular_speed=0.5))
    crate = _entity(app, "crate")
    for _ in range(30):
        app.step(1)
        assert np.linalg.norm(app.world.get(crate, RigidBodyState).angular_velocity) <= 0.5 * (1 + 1e-12)
