"""The compiled step of the floating bodies (bodies.integrate, one call of body_kernels.float_bodies) gives the bits of
the numpy step it replaced (bodies.integrate_numpy with pool_contacts and limit_speeds), every tick: positions,
quaternions, velocities, spins and submerged volumes compared as bit patterns (a −0.0 for a 0.0 fails too).

Scenes: boxes and spheres together and apart, one body alone (numpy rotates its pool corners in another order
then), a tilted box, a box dropped from above, light bodies (8 sub-steps) and heavy ones (1), bodies leaving the
pool and out of any water, bodies against the floor and walls, huge and non-finite velocities, forces and
torques (the speed limits' branches), impulses between ticks; and whole scenes through the systems: two waters
and dry land, scripts' impulses and forces, the showcase scene."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from components.water_surface import RigidBodyState
from engine.app import App
from engine.builtin import find_named
from engine.spatial import Transform, quat_from_euler
from systems.water_surface import simulate
from systems.water_surface.bodies import BodyArrays, apply_impulses, integrate, integrate_numpy, substeps
from systems.water_surface.geometry import BOX, SPHERE, Grid
from tests.systems.water_surface.helpers import CONFIGS, rigid_body_entity, write_scene

DT = 1.0 / 60.0
GRID = Grid(16, 14, 0.4, -3.0, -2.6, 0.2)
FLOOR = GRID.y0 - 1.2
FIELDS = ("position", "rotation", "velocity", "spin")


def _bits(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def assert_same_bits(got, want, what: str) -> None:
    got, want = np.asarray(got), np.asarray(want)
    assert got.shape == want.shape, what
    same = _bits(got) == _bits(want)
    assert np.array_equal(_bits(got), _bits(want)), f"{what}: {got[~same]} instead of {want[~same]}"


def _body(shape="box", position=(0.0, 0.3, 0.0), euler=(0.0, 0.0, 0.0), half=(0.5, 0.3, 0.4), radius=0.45,
          mass=120.0, velocity=(0.0, 0.0, 0.0), spin=(0.0, 0.0, 0.0), force=(0.0, 0.0, 0.0), torque=(0.0, 0.0, 0.0),
          gravity=9.81, linear_damping=0.05, angular_damping=0.05, restitution=0.2, friction=0.5, max_speed=1000.0,
          max_spin=100.0) -> dict:
    return dict(shape=BOX if shape == "box" else SPHERE, half=half, radius=radius, mass=mass, position=position,
                rotation=quat_from_euler(*np.radians(euler)), velocity=velocity, spin=spin, force=force,
                torque=torque, gravity=gravity, linear_damping=linear_damping, angular_damping=angular_damping,
                restitution=restitution, friction=friction, max_speed=max_speed, max_spin=max_spin)


def _arrays(*bodies: dict) -> BodyArrays:
    column = lambda key: np.array([b[key] for b in bodies], np.float64)  # noqa: E731
    return BodyArrays(shapes=np.array([b["shape"] for b in bodies], np.int8), half=column("half"),
                      radius=column("radius"), mass=column("mass"), position=column("position"),
                      rotation=column("rotation"), velocity=column("velocity"), spin=column("spin"),
                      force=column("force"), torque=column("torque"), gravity=column("gravity"),
                      linear_damping=column("linear_damping"), angular_damping=column("angular_damping"),
                      restitution=column("restitution"), friction=column("friction"),
                      max_speed=column("max_speed"), max_spin=column("max_spin"))


def _water(t: int) -> tuple[np.ndarray, np.ndarray, Grid]:
    """Waves crossing the pool (z(t), z(t − 1)) plus a fixed random roughness."""
    def heights(tick):
        z, x = np.mgrid[0:GRID.nz, 0:GRID.nx] * GRID.h
        return 0.12 * np.sin(1.3 * x + 0.7 * z - 0.09 * tick) + 0.05 * np.cos(2.1 * z - 0.13 * tick) + rough

    rough = 0.01 * np.random.default_rng(4).standard_normal((GRID.nz, GRID.nx))
    return heights(t), heights(t - 1), GRID


def assert_step_matches(fast: BodyArrays, slow: BodyArrays, water, t: int, what: str, **options) -> None:
    want = integrate_numpy(slow, DT, water, **options)
    got = integrate(fast, DT, water, **options)
    assert_same_bits(got, want, f"{what}, tick {t}: submerged volume")
    for field in FIELDS:
        assert_same_bits(getattr(fast, field), getattr(slow, field), f"{what}, tick {t}: {field}")


POOL = dict(linear_drag=0.6, angular_drag=0.4, density=1000.0, floor=FLOOR)

SCENES = {
    "boxes and spheres": [_body(position=(0.2, 0.4, -0.3), euler=(30.0, 5.0, 2.0)),
                          _body("sphere", position=(1.3, 0.9, 0.8), velocity=(0.4, -1.0, 0.2), mass=80.0),
                          _body(position=(-1.2, 0.1, 1.1), half=(0.7, 0.25, 0.35), euler=(-50.0, 0.0, 8.0), mass=90.0),
                          _body("sphere", position=(-1.5, 0.3, -1.4), radius=0.3, mass=20.0, spin=(0.0, 1.0, 2.0)),
                          _body(position=(1.8, 0.5, -1.5), half=(0.3, 0.3, 0.3), mass=15.0)],
    "tilted box alone": [_body(position=(0.1, 0.25, 0.2), euler=(20.0, 35.0, -25.0), half=(0.6, 0.2, 0.45))],
    "sphere alone": [_body("sphere", position=(0.0, 0.2, 0.0), radius=0.5, mass=150.0, spin=(0.3, 0.0, -0.2))],
    "dropped from above": [_body(position=(0.3, 3.0, -0.2), euler=(10.0, 15.0, 20.0), velocity=(0.0, -6.0, 0.0)),
                           _body("sphere", position=(-1.0, 2.5, 0.5), radius=0.35, velocity=(0.5, -8.0, 0.0)),
                           _body(position=(1.2, 2.0, 1.0), half=(0.8, 0.1, 0.8), mass=5.0, velocity=(0.0, -8.0, 0.0),
                                 euler=(0.0, 3.0, 0.0))],
    "light bodies, 8 sub-steps": [_body(position=(0.0, 0.5, 0.0), half=(0.9, 0.05, 0.8), mass=1.0),
                                  _body("sphere", position=(1.0, 0.6, 1.0), radius=0.4, mass=3.0)],
    "heavy box alone on the floor": [_body(position=(0.4, -0.3, -0.2), euler=(25.0, 10.0, 6.0), mass=500.0,
                                           spin=(0.5, 0.0, 0.3))],
    "heavy bodies sink to the floor": [_body(position=(0.3, 0.0, 0.1), euler=(12.0, 0.0, 0.0), mass=600.0),
                                       _body("sphere", position=(-1.0, 0.0, -0.6), radius=0.4, mass=900.0)],
    "against the walls": [_body(position=(-2.55, 0.2, 0.0), euler=(40.0, 0.0, 0.0), velocity=(-3.0, 0.0, 0.5),
                                force=(-2000.0, 0.0, 300.0)),
                          _body("sphere", position=(2.6, 0.3, 2.2), radius=0.4, velocity=(4.0, -1.0, 3.0),
                                force=(1500.0, 0.0, 1500.0), restitution=0.9, friction=1.5),
                          _body(position=(0.0, 0.2, -2.3), euler=(0.0, 0.0, 30.0), velocity=(0.0, 0.0, -5.0),
                                torque=(0.0, 200.0, 0.0), restitution=0.0, friction=0.0)],
    "leaving the pool": [_body(position=(2.0, 0.3, 0.0), velocity=(9.0, 5.0, 0.0), mass=60.0),
                         _body("sphere", position=(0.0, 0.3, 1.8), radius=0.3, velocity=(0.0, 6.0, 7.0)),
                         _body(position=(-1.0, 0.4, -0.5), half=(0.8, 0.1, 0.6), mass=3.0, velocity=(-4.0, 1.0, -3.0))],
    "limits": [_body(position=(0.2, 0.3, 0.1), spin=(5.0e3, 1.5e3, 0.5e3), max_spin=1000.0),
               _body(position=(-1.0, 0.3, 0.5), velocity=(1e200, 0.0, -1e200), force=(1e12, 1e200, 3e11),
                     torque=(1e150, -1e150, 1e140), max_speed=50.0, max_spin=20.0),
               _body("sphere", position=(1.0, 0.3, -1.0), velocity=(np.inf, 0.0, 0.0), spin=(0.0, np.nan, 0.0)),
               _body(position=(0.5, 0.3, 1.5), velocity=(30.0, 40.0, 0.0), max_speed=25.0, spin=(3.0, 4.0, 0.0),
                     max_spin=5.0)],
    "still and upright": [_body(position=(0.0, 0.2, 0.0)), _body(position=(1.5, 0.2, 1.0), euler=(90.0, 0.0, 0.0))],
}


@pytest.mark.parametrize("name", SCENES)
def test_the_compiled_step_repeats_the_numpy_step_bit_for_bit(name):
    slow = _arrays(*SCENES[name])
    fast = copy.deepcopy(slow)
    with np.errstate(all="ignore"):
        for t in range(150):
            assert_step_matches(fast, slow, _water(t), t, name, **POOL)


def test_the_scenes_cover_one_and_eight_sub_steps():
    counts = {name: substeps(_arrays(*bodies), 1000.0, DT) for name, bodies in SCENES.items()}
    assert counts["light bodies, 8 sub-steps"] == 8 and counts["heavy bodies sink to the floor"] == 1
    assert len(set(counts.values())) >= 3


@pytest.mark.parametrize("name", ["boxes and spheres", "dropped from above", "limits"])
def test_bodies_out_of_any_water(name):
    """integrate(bodies, dt, None): the systems' bodies over dry land (one sub-step, no buoyancy, no drag)."""
    slow = _arrays(*SCENES[name])
    fast = copy.deepcopy(slow)
    with np.errstate(all="ignore"):
        for t in range(90):
            assert_step_matches(fast, slow, None, t, f"{name}, dry")


def test_bodies_leaving_the_pool_without_contacts():
    """Without ``floor`` (no contacts) the bodies fly out over the pool's edge: samples outside it are dry and
    their water lookups clamped to the border; then back into water for a while, then dry land."""
    slow = _arrays(*SCENES["leaving the pool"])
    fast = copy.deepcopy(slow)
    for t in range(120):
        water = None if t % 40 >= 30 else _water(t)
        assert_step_matches(fast, slow, water, t, "leaving the pool, no contacts", linear_drag=0.3, density=1000.0)
    assert substeps(slow, 1000.0, DT) > 1
    assert (np.abs(slow.position[:, [0, 2]]) > 3.5).all(axis=1).sum() >= 1  # out over the edge


def test_impulses_between_ticks():
    slow = _arrays(*SCENES["boxes and spheres"])
    fast = copy.deepcopy(slow)
    rng = np.random.default_rng(9)
    for t in range(120):
        if t % 7 == 0:
            impulse, angular = 300.0 * rng.standard_normal((5, 3)), 80.0 * rng.standard_normal((5, 3))
            impulse[rng.random(5) < 0.4] = 0.0
            apply_impulses(slow, impulse, angular)
            apply_impulses(fast, impulse, angular)
        assert_step_matches(fast, slow, _water(t), t, "impulses", **POOL)


def test_an_empty_group_and_one_body_at_rest():
    empty = _arrays(*SCENES["sphere alone"])
    empty = BodyArrays(**{f: getattr(empty, f)[:0] for f in simulate._FIELDS})
    assert integrate(empty, DT, _water(0), **POOL).shape == (0,)
    flat = (np.zeros((GRID.nz, GRID.nx)), np.zeros((GRID.nz, GRID.nx)), GRID)
    slow = _arrays(_body(position=(0.0, 0.2, 0.0)))
    fast = copy.deepcopy(slow)
    for t in range(60):
        assert_step_matches(fast, slow, flat, t, "at rest", **POOL)


# ----------------------------------------------------------------------------------------- through the systems
TWO_WATERS = """
[[entities]]
name = "second water"
[entities.components.Transform]
position = [12.0, 0.5, 0.0]
[entities.components.WaterSurface]
resolution = [20, 14]
spacing = 0.35
wave_speed = 1.2
damping = 0.995
depth = 1.5
linear_drag = 0.8
angular_drag = 0.5
"""


BODIES = "".join([
    rigid_body_entity("crate", (0.5, 0.4, -0.3), rotation=(30.0, 8.0, 4.0), mass=200.0),
    rigid_body_entity("ball", (-1.0, 1.5, 1.0), shape="sphere", scale=(0.8, 0.8, 0.8), mass=60.0),
    rigid_body_entity("sinker", (1.5, 0.0, 1.5), scale=(0.6, 0.6, 0.6), mass=500.0),
    rigid_body_entity("walker", (-2.2, 0.3, -2.0), velocity=[-4.0, 0.0, -3.0], mass=80.0),
    rigid_body_entity("raft", (12.0, 0.7, 0.5), scale=(1.4, 0.3, 1.0), rotation=(10.0, 0.0, 15.0), mass=150.0),
    rigid_body_entity("buoy", (13.5, 1.5, -0.5), shape="sphere", scale=(0.5, 0.5, 0.5), mass=2.0),  # 2 sub-steps
    rigid_body_entity("falling", (6.0, 4.0, 0.0), rotation=(5.0, 20.0, 0.0), mass=100.0),
])


def _two_apps(tmp_path, water: str, extra: str = "") -> tuple[App, App]:
    path = write_scene(tmp_path, water, BODIES + extra)
    return App(path, configs_root=CONFIGS), App(path, configs_root=CONFIGS)


def _compare_worlds(fast: App, slow: App, what: str) -> None:
    rows = slow.world.query(Transform, RigidBodyState)
    assert rows
    for entity, (t, state) in rows:
        other_t, other = fast.world.get(entity, Transform), fast.world.get(entity, RigidBodyState)
        assert_same_bits(other_t.position, t.position, f"{what}, entity {entity}: position")
        assert_same_bits(other_t.rotation, t.rotation, f"{what}, entity {entity}: rotation")
        assert_same_bits(other.velocity, state.velocity, f"{what}, entity {entity}: velocity")
        assert_same_bits(other.angular_velocity, state.angular_velocity, f"{what}, entity {entity}: spin")
        assert_same_bits(other.submerged_volume, state.submerged_volume, f"{what}, entity {entity}: submerged")
    assert fast.state_hash() == slow.state_hash(), what


def assert_apps_match(fast: App, slow: App, monkeypatch, ticks: int, what: str, between=None) -> None:
    """Tick both apps, ``slow`` with the systems calling integrate_numpy; the same bits after every tick."""
    for t in range(ticks):
        if between is not None:
            between(fast, t)
            between(slow, t)
        fast.step(1)
        with monkeypatch.context() as m:
            m.setattr(simulate, "integrate", integrate_numpy)
            slow.step(1)
        _compare_worlds(fast, slow, f"{what}, tick {t}")


def test_two_waters_and_dry_land_through_the_systems(tmp_path, monkeypatch):
    """The bodies split into one group per water (each its own call) and one over neither (it falls past both);
    one body runs into the first pool's corner."""
    fast, slow = _two_apps(tmp_path, "resolution = [24, 24]\nspacing = 0.3\nwave_speed = 1.5\ndamping = 0.995\n"
                           "depth = 1.0\nlinear_drag = 0.5\nangular_drag = 0.3", TWO_WATERS)
    assert_apps_match(fast, slow, monkeypatch, 240, "two waters")


def test_scripts_impulses_and_forces_through_the_systems(tmp_path, monkeypatch):
    from systems.water_surface.api import apply_force

    def kick(app: App, t: int) -> None:
        crate, ball, raft = (find_named(app.world, name) for name in ("crate", "ball", "raft"))
        if t % 11 == 3:
            simulate.add_impulse(app.world, crate, np.array([150.0, 400.0, -80.0]),
                                 app.world.get(crate, Transform).position + [0.3, 0.1, -0.2])
        if t % 17 == 5:
            simulate.add_impulse(app.world, ball, np.array([0.0, -300.0, 90.0]))
        if 40 <= t < 60:  # the limits hold it
            apply_force(app.world, raft, [1e12, 1e200, 3e11],
                        point=app.world.get(raft, Transform).position + [0.3, 0.0, 0.1])

    fast, slow = _two_apps(tmp_path, "resolution = [24, 24]\nspacing = 0.3\nwave_speed = 1.5\ndamping = 0.995\n"
                           "depth = 1.0", TWO_WATERS)
    with np.errstate(all="ignore"):
        assert_apps_match(fast, slow, monkeypatch, 150, "impulses and forces", between=kick)


def test_the_showcase_scene_through_the_systems(monkeypatch):
    scene = CONFIGS / "scenes" / "water_surface_showcase.toml"
    fast, slow = App(scene, seed=3), App(scene, seed=3)
    assert_apps_match(fast, slow, monkeypatch, 200, "showcase")
