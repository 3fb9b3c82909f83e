"""Hot reload of the effect components: live parameters swap in place (state kept, the new value works at the
next tick), structural keys rebuild the component (see each plugin's ``structural`` / ``live_update``)."""

from __future__ import annotations

import numpy as np
import pytest

from components.dust_devil import DustDevilConfig, DustDevilState
from components.energy_wave import EnergyWaveEmitter, EnergyWaveState
from components.toon_smoke import ToonSmokeState, ToonSmokeVolumeConfig
from components.water_surface import RigidBody, RigidBodyState, WaterState, WaterSurface
from engine.app import App
from engine.collider import Collider
from engine.registry import default_registry
from engine.reload import HotReloader
from engine.spatial import Transform


class Scene:
    """A one-file scene in ``tmp_path/configs/scenes/s.toml`` with its App and HotReloader."""

    def __init__(self, tmp_path, plugins: list[str], text: str) -> None:
        root = tmp_path / "configs"
        (root / "scenes").mkdir(parents=True)
        self.file = root / "scenes" / "s.toml"
        self.header = f'[scene]\nseed = 5\nplugins = {plugins!r}\n'.replace("'", '"')
        self.file.write_text(self.header + text)
        self.app = App(self.file, strict=True)
        self.reloader = HotReloader(self.app)

    def rewrite(self, text: str) -> list[str]:
        """Write new content and reload it; returns what the reload changed."""
        self.file.write_text(self.header + text)
        assert self.reloader.poll()
        assert self.reloader.status.errors == []
        return self.reloader.status.last_changes

    def get(self, ctype, index: int = 0):
        return self.app.world.get(self.app.records[index].entity, ctype)


@pytest.mark.parametrize("name", ["EnergyWaveEmitter", "ToonSmokeVolume", "WaterSurface", "RigidBody", "DustDevil"])
def test_structural_keys_are_declared_and_are_fields(name):
    spec = default_registry().component(name)
    assert spec.structural is not None  # None would rebuild on every edit
    assert set(spec.structural) <= set(spec.model.model_fields)


# ---------------------------------------------------------------------------------------------- energy_wave
EMITTER = """
[[entities]]
name = "emitter"
[entities.components.Transform]
[entities.components.EnergyWaveEmitter]
emission_rate = {rate}
max_particles = {capacity}
emitting = {emitting}
beam_range = 100.0
"""


def emitter(rate=600.0, capacity=500, emitting="true"):
    return EMITTER.format(rate=rate, capacity=capacity, emitting=emitting)


def test_energy_wave_parameters_live_and_buffer_resized_in_place(tmp_path):
    s = Scene(tmp_path, ["energy_wave"], emitter())
    s.app.step(5)
    state = s.get(EnergyWaveState)
    assert state.emitted == 50  # 600/s at 60 Hz: 10 a tick
    s.rewrite(emitter(rate=1200.0))
    assert s.get(EnergyWaveState) is state and s.get(EnergyWaveEmitter).emission_rate == 1200.0
    s.app.step(1)
    assert state.emitted == 70  # 20 in the next tick

    # max_particles shrinks the buffer at once, keeping the first live particles (no rebuild)
    kept = state.particles.live("position")[:60].copy()
    changes = s.rewrite(emitter(rate=1200.0, capacity=60))
    assert s.get(EnergyWaveState) is state and not any("rebuilt" in c for c in changes)
    assert state.particles.capacity == 60 and state.particles.count == 60
    np.testing.assert_array_equal(state.particles.live("position"), kept)
    s.rewrite(emitter(rate=1200.0, capacity=1000))  # and grows it
    assert state.particles.capacity == 1000 and len(state.particles.position) == 1000
    np.testing.assert_array_equal(state.particles.live("position"), kept)

    # emitting is copied into the state at build time: an edit switches the emission now
    s.rewrite(emitter(rate=1200.0, capacity=1000, emitting="false"))
    assert s.get(EnergyWaveState) is state and state.emitting is False
    s.app.step(1)
    assert state.emitted == 70 and state.particles.count == 60


# ----------------------------------------------------------------------------------------------- toon_smoke
SMOKE = """
[[entities]]
name = "smoke"
[entities.components.Transform]
[entities.components.ToonSmokeVolume]
simulation_resolution = [{n}, {n}, {n}]
display_resolution = [{n}, {n}, {n}]
extent = [2.0, 2.0, 2.0]
particle_count = {particles}
pressure_iterations = 10
density_limit = {limit}
obstacle_radius = {obstacle}
noise_strength = {noise}
sources = [
  {{ name = "a", position = [0.0, -0.5, 0.0], radius = 0.5, density_rate = {rate} }},
  {{ name = "b", position = [0.5, -0.5, 0.5], radius = 0.3 }},
]
"""


def smoke(n=8, particles=16, limit=4.0, obstacle=0.0, noise=0.35, rate=60.0):
    return SMOKE.format(n=n, particles=particles, limit=limit, obstacle=obstacle, noise=noise, rate=rate)


def test_toon_smoke_parameters_live_caches_follow_and_grids_rebuild(tmp_path):
    s = Scene(tmp_path, ["toon_smoke"], smoke())
    s.app.step(3)
    state = s.get(ToonSmokeState)
    assert state.density.max() > 1.0  # the source saturates towards density_limit 4

    s.rewrite(smoke(limit=1.0))  # a plain parameter: read at the next step
    assert s.get(ToonSmokeState) is state and s.get(ToonSmokeVolumeConfig).density_limit == 1.0
    s.app.step(1)
    assert state.density.max() <= 1.0

    # sources are copied into the state: an edited source is re-read, an unchanged one keeps its runtime changes
    state.sources[1].enabled = False  # as the toon_smoke.set_source command would
    b = state.sources[1]
    s.rewrite(smoke(limit=1.0, rate=20.0))
    assert s.get(ToonSmokeState) is state
    assert state.sources[0].density_rate == 20.0 and state.sources[1] is b and b.enabled is False

    # the obstacle masks are cached on the transforms: an obstacle edit must reach the solid cells
    assert not state.solid.any()
    s.rewrite(smoke(limit=1.0, rate=20.0, obstacle=0.5))
    s.app.step(1)
    assert s.get(ToonSmokeState) is state and state.solid.any() and state.display_solid.any()
    assert np.all(state.noise_factor[state.display_solid] == 0.0)

    # the noise factor is computed once: a noise edit must recompute it
    assert not np.all(state.noise_base == 1.0)
    s.rewrite(smoke(limit=1.0, rate=20.0, obstacle=0.5, noise=0.0))
    s.app.step(1)
    assert s.get(ToonSmokeState) is state and np.all(state.noise_base == 1.0)

    # structural: the grid resolution and the particle count rebuild the state
    changes = s.rewrite(smoke(n=16, particles=32, limit=1.0, rate=20.0, obstacle=0.5, noise=0.0))
    new = s.get(ToonSmokeState)
    assert new is not state and any("rebuilt" in c for c in changes)
    assert new.density.shape == (16, 16, 16) and new.particles.shape == (32, 3)
    s.app.step(1)
    assert new.display_density.shape == (16, 16, 16)


# -------------------------------------------------------------------------------------------- water_surface
WATER = """
[[entities]]
name = "pond"
[entities.components.Transform]
[entities.components.WaterSurface]
resolution = [{n}, {n}]
spacing = 0.5
wave_speed = {speed}
wave_source = "{source}"

[[entities]]
name = "post"
[entities.components.Transform]
position = [0.0, 0.0, 0.0]
[entities.components.RigidBody]
kinematic = true
half_extents = [0.6, 0.6, 0.6]

[[entities]]
name = "falling"
[entities.components.Transform]
position = [50.0, 100.0, 0.0]
[entities.components.RigidBody]
linear_damping = 0.0
gravity = {gravity}
half_extents = {half}
velocity = {velocity}
"""


def water(n=9, speed=2.0, source="outline", gravity=9.81, half="[0.5, 0.5, 0.5]", velocity="[0.0, 0.0, 0.0]"):
    return WATER.format(n=n, speed=speed, source=source, gravity=gravity, half=half, velocity=velocity)


def test_water_surface_parameters_live_and_resolution_rebuilds(tmp_path):
    s = Scene(tmp_path, ["water_surface"], water())
    s.app.step(30)  # the kinematic post stands in the pool (it cuts the water but does not move)
    state = s.get(WaterState)
    dt = s.app.dt
    assert state.coefficient_k == pytest.approx((2.0 * dt / 0.5) ** 2)
    s.rewrite(water(speed=1.0))
    assert s.get(WaterState) is state and s.get(WaterSurface).wave_speed == 1.0
    s.app.step(1)
    assert state.coefficient_k == pytest.approx((1.0 * dt / 0.5) ** 2)  # the cached eq. 2.8 coefficients follow
    np.testing.assert_allclose(state.coefficient, 2.0 - state.coefficient_k * state.degree)

    # switching the wave source keeps the water and makes no wave of its own (the post does not move)
    before = state.heights.copy()
    s.rewrite(water(speed=1.0, source="grid"))
    assert s.get(WaterState) is state
    s.app.step(1)
    assert np.abs(state.heights - before).max() < 0.05

    # structural: the grid's size rebuilds the state and its height-field collider
    changes = s.rewrite(water(n=11, speed=1.0, source="grid"))
    new = s.get(WaterState)
    assert new is not state and any("pond.WaterSurface: rebuilt" in c for c in changes)
    assert new.heights.shape == (11, 11) and s.get(Collider).heightfield.heights.shape == (11, 11)
    s.app.step(1)


def test_water_surface_fixed_dt_edit_runs_at_the_step_it_was_validated_at(tmp_path):
    s = Scene(tmp_path, ["water_surface"], water())
    s.app.step(5)
    state = s.get(WaterState)
    s.header += "fixed_dt = 0.001\n"  # wave_speed 150 m/s is stable at 1/1000 s, not at 1/60 s
    changes = s.rewrite(water(speed=150.0))
    assert s.app.dt == 0.001 and s.get(WaterState) is state
    assert any("fixed_dt" in c for c in changes) and any("parameters updated (wave_speed)" in c for c in changes)
    s.app.step(5)  # the old reload kept 1/60 s: the stability check raised CrossFieldError here, every tick
    assert np.isfinite(state.heights).all()
    assert state.coefficient_k == pytest.approx((150.0 * 0.001 / 0.5) ** 2)


def test_rigid_body_parameters_live_collider_follows_and_velocity_rebuilds(tmp_path):
    s = Scene(tmp_path, ["water_surface"], water())
    s.app.step(3)
    state = s.get(RigidBodyState, 2)
    dt = s.app.dt
    v0 = state.velocity[1]
    assert v0 == pytest.approx(-9.81 * 3 * dt)
    s.rewrite(water(gravity=1.0))
    assert s.get(RigidBodyState, 2) is state and s.get(RigidBody, 2).gravity == 1.0
    s.app.step(1)
    assert state.velocity[1] - v0 == pytest.approx(-1.0 * dt)

    # the size lives in the body's Collider: an edit reaches it, the motion is kept
    s.rewrite(water(gravity=1.0, half="[1.0, 0.25, 0.5]"))
    assert s.get(RigidBodyState, 2) is state
    np.testing.assert_array_equal(s.get(Collider, 2).half_extents, [1.0, 0.25, 0.5])

    # structural: the initial velocity rebuilds the body's state where the body now is
    transform = s.get(Transform, 2)
    position = transform.position.copy()
    changes = s.rewrite(water(gravity=1.0, half="[1.0, 0.25, 0.5]", velocity="[0.0, 5.0, 0.0]"))
    new = s.get(RigidBodyState, 2)
    assert new is not state and any("falling.RigidBody: rebuilt" in c for c in changes)
    np.testing.assert_array_equal(new.velocity, [0.0, 5.0, 0.0])
    np.testing.assert_array_equal(s.get(Collider, 2).half_extents, [1.0, 0.25, 0.5])
    np.testing.assert_array_equal(transform.position, position)
    s.app.step(1)
    assert new.velocity[1] == pytest.approx(5.0 - dt)


# ----------------------------------------------------------------------------------------------- dust_devil
DEVIL = """
[[entities]]
name = "devil"
[entities.components.Transform]
[entities.components.DustDevil]
particle_count = {count}
prewarm_time = 0.0
grid_resolution = [{n}, {n}, {n}]
"""


def test_dust_devil_parameters_live_and_particle_count_rebuilds(tmp_path):
    s = Scene(tmp_path, ["dust_devil"], DEVIL.format(count=200, n=8))
    s.app.step(2)
    state = s.get(DustDevilState)
    assert state.wind.resolution == (8, 8, 8)
    s.rewrite(DEVIL.format(count=200, n=12))
    assert s.get(DustDevilState) is state and s.get(DustDevilConfig).grid_resolution == (12, 12, 12)
    s.app.step(1)
    assert state.steps == 3 and state.wind.resolution == (12, 12, 12)  # the wind grid follows at the next step

    changes = s.rewrite(DEVIL.format(count=300, n=12))
    new = s.get(DustDevilState)
    assert new is not state and any("rebuilt" in c for c in changes) and new.count == 300
    s.app.step(1)
    assert new.steps == 1 and new.positions.shape == (300, 3)
