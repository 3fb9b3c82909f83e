"""The plugin in a world: registration, determinism, snapshots, script commands, colliders as obstacles."""

import numpy as np
import pytest

from components.toon_smoke import ToonSmokeState, ToonSmokeVolumeConfig
from engine.app import TimeControl
from engine.config import ConfigError
from engine.registry import default_registry
from engine.schedule import Stage
from systems.toon_smoke import live_update, simulate
from tests.systems.toon_smoke.helpers import make_app, scene_text

SMALL = """simulation_resolution = [16, 16, 16]
display_resolution = [32, 32, 32]
extent = [2.0, 2.0, 2.0]
obstacle_radius = 0.3
particle_count = 150
blob_radius = 0.1
blob_radius_max = 0.15
blob_stretch_max = 1.5
noise_octaves = 1
[[entities.components.ToonSmokeVolume.sources]]
name = "jet"
position = [0.0, -0.7, 0.0]
radius = 0.25
velocity_jitter = 0.5
"""


def small_app(tmp_path, seed=None, extra=""):
    return make_app(tmp_path, scene_text("paper", camera=False, extra=SMALL + extra), seed=seed)


def _volume(app):
    return app.world.query(ToonSmokeVolumeConfig, ToonSmokeState)[0]


def test_plugin_registers_component_systems_commands_and_script():
    registry = default_registry(["toon_smoke"])
    assert registry.component("ToonSmokeVolume").preset_dir == "toon_smoke"
    names = [name for _, names in registry.schedule.order() for name in names]
    assert names.index("toon_smoke.simulate") < names.index("toon_smoke.display")
    stages = {name: stage for stage, names in registry.schedule.order() for name in names}
    assert stages["toon_smoke.simulate"] is Stage.SIMULATION and stages["toon_smoke.display"] is Stage.FRAME_UPDATE
    assert {"toon_smoke.set_source", "toon_smoke.puff"} <= set(registry.commands)
    assert "toon_smoke_puffer" in registry.scripts


def test_same_seed_same_hash_different_seed_differs(tmp_path):
    hashes = []
    for seed in (4, 4, 5):
        app = small_app(tmp_path, seed=seed)
        app.step(8)
        hashes.append(app.state_hash())
    assert hashes[0] == hashes[1]
    assert hashes[0] != hashes[2]


def test_snapshot_restore_continues_bit_identically(tmp_path):
    app = small_app(tmp_path, seed=2)
    app.step(5)
    snap = app.snapshot()
    app.step(5)
    expected = app.state_hash()
    app.restore(snap)
    app.step(5)
    assert app.state_hash() == expected


def test_mesh_is_rebuilt_once_per_batch_of_ticks_from_the_last_state(tmp_path):
    """The display grid and mesh are derived once after a frame's ticks (the frame-update stage), not per tick."""
    app = small_app(tmp_path)
    app.step(20)
    _, (cfg, state) = _volume(app)
    version = state.mesh_version
    assert len(state.mesh_faces) > 0
    app.step(3)
    assert state.mesh_version == version + 1
    for _ in range(3):
        app.step(1)
    assert state.mesh_version == version + 4
    app.step(0)
    assert state.mesh_version == version + 4
    # what was derived is the display of the last tick's state, as a step that derives it directly gives it
    shown, faces = state.display_density.copy(), state.mesh_faces.copy()
    simulate.display_grid(cfg, state)
    simulate.mesh_step(cfg, state)
    assert np.array_equal(shown, state.display_density) and np.array_equal(faces, state.mesh_faces)


def test_one_batch_or_single_ticks_give_the_same_state_and_picture(tmp_path):
    batched, single = small_app(tmp_path, seed=3), small_app(tmp_path, seed=3)
    batched.step(12)
    for _ in range(12):
        single.step(1)
    assert batched.state_hash() == single.state_hash()
    a, b = _volume(batched)[1][1], _volume(single)[1][1]
    assert np.array_equal(a.display_density, b.display_density)
    assert np.array_equal(a.mesh_vertices, b.mesh_vertices) and np.array_equal(a.mesh_faces, b.mesh_faces)


def test_a_config_change_while_paused_re_derives_the_mesh(tmp_path):
    app = small_app(tmp_path)
    app.step(20)
    entity, (cfg, state) = _volume(app)
    version = state.mesh_version
    app.world.resource(TimeControl).paused = True
    app.step(1)  # paused: no simulation, nothing to re-derive
    assert state.mesh_version == version
    new = cfg.model_copy(update={"iso_density": cfg.iso_density * 2})
    app.world.add(entity, new)  # as the hot reloader swaps a config in place
    live_update(cfg, new, app.world, entity)
    app.step(1)
    assert state.mesh_version == version + 1


def test_set_source_switches_emission(tmp_path):
    app = small_app(tmp_path)
    entity, (_, state) = _volume(app)
    call = app.registry.command("toon_smoke.set_source")
    call(app.world, entity, name="jet", enabled=False)
    app.step(5)
    assert state.density.max() == 0.0
    call(app.world, entity, name="jet", enabled=True, density_rate=12.0, velocity=(0.0, 2.0, 0.0))
    assert state.sources[0].density_rate == 12.0 and np.allclose(state.sources[0].velocity, (0, 2, 0))
    app.step(3)
    assert state.density.max() > 0.5
    with pytest.raises(ValueError, match="did you mean 'jet'"):
        call(app.world, entity, name="jte", enabled=False)
    with pytest.raises(ConfigError, match="density_rate"):
        call(app.world, entity, name="jet", density_rate=-1.0)


def test_puff_adds_smoke_expansion_and_particles(tmp_path):
    app = small_app(tmp_path, extra='density_rate = 0.0\n')
    entity, (_, state) = _volume(app)
    app.step(1)
    assert state.density.max() == 0.0
    app.registry.command("toon_smoke.puff")(app.world, entity, position=(0.5, 0.5, 0.0), radius=0.4, density=2.0,
                                              speed=2.0, particles=40)
    assert 1.5 < state.density.max() <= 2.0  # 2·(1 − d²/r²) at the cell centres nearest the puff centre
    assert state.expansion.max() == pytest.approx(3.0 * 2.0 / 0.4)
    near = np.linalg.norm(state.particles - (0.5, 0.5, 0.0), axis=1) <= 0.4 + 1e-9
    assert near.sum() >= 40
    app.step(1)
    assert not state.expansion.any()  # consumed by one projection
    with pytest.raises(ValueError, match="no entity named"):
        app.registry.command("toon_smoke.puff")(app.world, entity, volume="smok")


def test_puffer_script_fires_puffs(tmp_path):
    text = scene_text("paper", camera=False, extra=SMALL + "density_rate = 0.0\n")
    text = text.replace('name = "smoke"\n', 'name = "smoke"\nscripts = [{ name = "toon_smoke_puffer", params = '
                                            '{ interval = 0.1, position = [0.0, 0.5, 0.0], radius = 0.3 } }]\n')
    app = make_app(tmp_path, text)
    app.step(4)
    _, (_, state) = _volume(app)
    assert state.density.max() > 1.0


def test_other_colliders_are_obstacles(tmp_path):
    extra = """
[[entities]]
name = "box"
[entities.components.Transform]
position = [0.6, 0.0, 0.0]
[entities.components.Collider]
shape = "box"
half_extents = [0.2, 0.2, 0.2]
"""
    app = small_app(tmp_path, extra=extra)
    app.step(2)
    _, (_, state) = _volume(app)
    x, y, z = np.broadcast_arrays(*state.geometry.local_centres())
    in_box = (np.abs(x - 0.6) < 0.19) & (np.abs(y) < 0.19) & (np.abs(z) < 0.19)
    assert in_box.any() and np.all(state.solid[in_box])
