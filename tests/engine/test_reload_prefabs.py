"""Hot reload of what prefab-spawned entities read: the prefab's file, its presets and its assets are watched from
the prefab's first spawn; an edit reaches the next spawns and the live entities (parameters in place, structural keys
rebuilt, the position the spawner gave kept); a bad edit is refused naming the file and key, and the last good prefab
stays in force."""

import os
import shutil

import numpy as np
import pytest

from engine.app import App
from engine.builtin import Name
from engine.reload import HotReloader
from engine.script import ScriptContext, Scripts
from engine.spatial import Transform
from tests.engine.test_reload import PumpConfig, PumpState, SpringConfig, registry, spring_registry

TANK = """name = "tank"
scripts = [{{ name = "spin", params = {{ speed = {speed} }} }}]
[components.Transform]
scale = [{scale}, {scale}, {scale}]
[components.Pump]
preset = "pump/fast"
capacity = {capacity}
"""


class Game:
    """A scene with no pump of its own; scripts spawn the ``tank`` prefab, whose Pump takes preset ``pump/fast``
    (read by nothing else)."""

    def __init__(self, tmp_path, rate="2.0", **tank) -> None:
        self.root = tmp_path / "configs"
        (self.root / "scenes").mkdir(parents=True)
        (self.root / "prefabs").mkdir()
        (self.root / "effects" / "pump").mkdir(parents=True)
        self.preset = self.root / "effects" / "pump" / "fast.toml"
        self.prefab = self.root / "prefabs" / "tank.toml"
        self.preset.write_text(f"rate = {rate}\n")
        self.write_tank(**tank)
        scene = self.root / "scenes" / "s.toml"
        scene.write_text('[[entities]]\nname = "spawner"\n[entities.components.Transform]\n')
        reg = registry()
        reg.components["Pump"].preset_dir = "pump"
        self.app = App(scene, registry=reg, strict=True)
        self.reloader = HotReloader(self.app)

    def write_tank(self, speed=1.0, scale=1.0, capacity=4) -> None:
        self.prefab.write_text(TANK.format(speed=speed, scale=scale, capacity=capacity))

    def spawn(self, position=None) -> int:
        entity = ScriptContext(self.app.world, self.app.records[0].entity, "test").spawn_prefab("tank", position)
        self.app.world.commands.apply()
        return entity

    def state(self, entity) -> PumpState:
        return self.app.world.get(entity, PumpState)

    def config(self, entity) -> PumpConfig:
        return self.app.world.get(entity, PumpConfig)


def test_a_preset_only_a_prefab_reads_is_watched_and_reaches_live_entities_and_the_next_spawns(tmp_path):
    game = Game(tmp_path)
    tank = game.spawn(position=(1.0, 2.0, 3.0))
    game.app.step(2)
    state = game.state(tank)
    assert state.levels[0] == 4.0
    assert not game.reloader.poll()  # the prefab's files are watched from its spawn: unchanged, nothing to do
    game.preset.write_text("rate = 10.0\n")
    assert game.reloader.poll() and game.reloader.status.errors == []  # the old code did not watch the preset
    assert game.reloader.status.last_changes == ["prefab tank: the next spawns take the edit",
                                                 "prefab tank.Pump: parameters updated (rate)"]
    game.app.step(1)
    assert game.state(tank) is state and state.levels[0] == 14.0  # live, the simulation state kept
    assert np.array_equal(game.app.world.get(tank, Transform).position, [1.0, 2.0, 3.0])
    assert game.config(game.spawn()).rate == 10.0  # and the next spawn has it (the library cached the old plan)


def test_a_prefab_file_edit_rebuilds_structural_keys_keeps_the_position_and_swaps_script_parameters(tmp_path):
    game = Game(tmp_path)
    tanks = [game.spawn(position=(float(i), 0.0, 0.0)) for i in range(3)]
    game.app.step(1)
    scripts = game.app.world.get(tanks[0], Scripts).slots[0].script
    game.write_tank(speed=5.0, scale=2.0, capacity=8)
    assert game.reloader.poll() and game.reloader.status.errors == []
    changes = game.reloader.status.last_changes
    assert "prefab tank.Pump: rebuilt (3 entities)" in changes  # one line for the three, not three
    assert "prefab tank: script 'spin' parameters updated (3 entities)" in changes
    for i, tank in enumerate(tanks):
        assert game.state(tank).levels.shape == (8,)
        transform = game.app.world.get(tank, Transform)
        assert np.array_equal(transform.position, [float(i), 0.0, 0.0])  # the spawner's, not the prefab's origin
        assert np.array_equal(transform.scale, [2.0, 2.0, 2.0])  # the prefab's new scale
    assert game.app.world.get(tanks[0], Scripts).slots[0].script is scripts and scripts.params.speed == 5.0
    from engine.prefab import PrefabInstance

    assert game.app.world.get(tanks[0], PrefabInstance).components["Pump"][0].capacity == 8


def test_a_bad_prefab_edit_names_the_file_and_key_and_the_last_good_prefab_stays(tmp_path):
    game = Game(tmp_path)
    tank = game.spawn()
    game.app.step(1)
    game.preset.write_text("rat = 10.0\n")  # a typo in the preset only the prefab reads
    assert game.reloader.poll()
    (error,) = game.reloader.status.errors
    assert "fast.toml" in error and "rat" in error and "did you mean 'rate'" in error
    game.app.step(1)
    assert game.state(tank).levels[0] == 4.0  # the old rate
    assert game.config(game.spawn()).rate == 2.0  # new spawns too: the library keeps the last good plan

    game.preset.write_text("rate = 3.0\n")
    game.write_tank(capacity=0)  # out of bounds in the prefab's own file
    assert game.reloader.poll()
    (error,) = game.reloader.status.errors
    assert "tank.toml" in error and "components.Pump.capacity" in error
    assert game.config(tank).rate == 2.0  # refused as a whole: the valid preset edit waits too

    game.write_tank(capacity=4)
    assert game.reloader.poll() and game.reloader.status.errors == []
    assert game.config(tank).rate == 3.0 and game.config(game.spawn()).rate == 3.0


def test_a_prefab_naming_a_missing_preset_reloads_when_it_is_created(tmp_path):
    game = Game(tmp_path)
    game.spawn()
    game.prefab.write_text(game.prefab.read_text().replace("pump/fast", "pump/slow"))
    assert game.reloader.poll() and "preset not found" in game.reloader.status.errors[0]
    assert not game.reloader.poll()  # the same broken content is not reported every poll
    (game.root / "effects" / "pump" / "slow.toml").write_text("rate = 0.5\n")
    assert game.reloader.poll() and game.reloader.status.errors == []
    assert game.config(game.spawn()).rate == 0.5


def test_an_edit_between_the_first_spawn_and_the_next_poll_is_not_missed(tmp_path):
    """A prefab is read when first spawned, which may be just before an editor saves it: the watcher compares with
    what was read, not with what it finds when it first looks."""
    game = Game(tmp_path)
    tank = game.spawn()
    game.preset.write_text("rate = 9.0\n")
    stamp = game.preset.stat().st_mtime_ns + 1_000_000  # a later mtime, however coarse the file system's clock
    os.utime(game.preset, ns=(stamp, stamp))
    assert game.reloader.poll() and game.config(tank).rate == 9.0


def test_an_emptied_prefab_file_is_held_back(tmp_path):
    game = Game(tmp_path)
    tank = game.spawn()
    text = game.prefab.read_text()
    game.prefab.write_text("")
    assert game.reloader.poll() and "tank.toml" in game.reloader.status.errors[0]
    assert "empty" in game.reloader.status.errors[0]
    assert game.app.world.has(tank, PumpState) and game.config(game.spawn()).rate == 2.0
    game.prefab.write_text(text)
    assert game.reloader.poll() and game.reloader.status.errors == []


def test_a_height_map_a_prefab_names_is_watched(tmp_path):
    from PIL import Image

    from engine.builtin import Terrain

    game = Game(tmp_path)
    (game.root / "assets").mkdir()
    heightmap = game.root / "assets" / "bump.png"
    Image.fromarray(np.full((9, 9), 40, np.uint8), "L").save(heightmap)
    (game.root / "prefabs" / "mound.toml").write_text('[components.Transform]\n[components.Terrain]\n'
                                                      'heightmap = "assets/bump.png"\n')
    mound = ScriptContext(game.app.world, game.app.records[0].entity, "test").spawn_prefab("mound", (5.0, 0.0, 5.0))
    game.app.world.commands.apply()
    assert not game.reloader.poll()
    Image.fromarray(np.full((9, 9), 200, np.uint8), "L").save(heightmap)
    assert game.reloader.poll() and game.reloader.status.errors == []
    assert game.reloader.status.last_changes == ["prefab mound.Terrain: rebuilt (a file it reads changed)"]
    assert np.allclose(game.app.world.get(mound, Terrain).field.heights, 200 / 255 * 10.0)
    assert np.array_equal(game.app.world.get(mound, Transform).position, [5.0, 0.0, 5.0])


def test_a_fixed_dt_a_loaded_prefab_cannot_run_at_is_refused_naming_the_prefab(tmp_path):
    """The prefab is planned again at the new step: its entities get a config validated there, and a prefab that
    cannot run at it is named with its file and key (its next spawn would have failed)."""
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    (root / "prefabs").mkdir()
    prefab = root / "prefabs" / "coil.toml"
    prefab.write_text("[components.Spring]\nstiffness = 1000.0\n")
    scene = root / "scenes" / "s.toml"
    scene.write_text('[[entities]]\nname = "a"\n')
    app = App(scene, registry=spring_registry(), strict=True)
    reloader = HotReloader(app)
    coil = ScriptContext(app.world, app.records[0].entity, "test").spawn_prefab("coil")
    app.world.commands.apply()
    scene.write_text('[scene]\nfixed_dt = 0.05\n[[entities]]\nname = "a"\n')
    assert reloader.poll()
    (error,) = reloader.status.errors
    assert "coil.toml" in error and "components.Spring.stiffness" in error and "unstable at fixed_dt 0.05" in error
    assert app.dt == pytest.approx(1 / 60)
    prefab.write_text("[components.Spring]\nstiffness = 100.0\n")  # stable at 0.05 s: the step and the prefab apply
    assert reloader.poll() and reloader.status.errors == [] and app.dt == 0.05
    assert app.world.get(coil, SpringConfig).stiffness == 100.0
    app.step(2)


def test_the_demo_smoke_puff_follows_its_toon_smoke_preset(tmp_path):
    """The demo's case: a destroyed target's smoke_puff prefab takes preset toon_smoke/explosion, which no scene
    entity names; editing it changed nothing while the puff was alive, nor for the next puffs."""
    from components.toon_smoke import ToonSmokeState, ToonSmokeVolumeConfig
    from engine.config import STOCK_CONFIGS

    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    (root / "effects" / "toon_smoke").mkdir(parents=True)
    (root / "prefabs").mkdir()
    shutil.copy(STOCK_CONFIGS / "prefabs" / "smoke_puff.toml", root / "prefabs")
    preset = root / "effects" / "toon_smoke" / "explosion.toml"
    shutil.copy(STOCK_CONFIGS / "effects" / "toon_smoke" / "explosion.toml", preset)
    scene = root / "scenes" / "s.toml"
    scene.write_text('[scene]\nplugins = ["toon_smoke"]\n[[entities]]\nname = "a"\n')
    app = App(scene, strict=True)
    reloader = HotReloader(app)
    puff = ScriptContext(app.world, app.records[0].entity, "test").spawn_prefab("smoke_puff", (0.0, 1.0, 0.0))
    app.world.commands.apply()
    app.step(2)
    state = app.world.get(puff, ToonSmokeState)
    preset.write_text(preset.read_text().replace("buoyancy = 1.2", "buoyancy = 3.5"))
    assert reloader.poll() and reloader.status.errors == []
    assert app.world.get(puff, ToonSmokeVolumeConfig).buoyancy == 3.5
    assert app.world.get(puff, ToonSmokeState) is state  # swapped in place: the smoke keeps flowing
    assert app.world.get(puff, Name).value == "smoke_puff"
    app.step(1)
