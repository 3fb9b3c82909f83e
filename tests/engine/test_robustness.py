"""Bad input gets a clear error naming the file and the key, and the engine keeps what it had.

Three paths: the command line (validate / run / graph / gallery, every failure a non-zero exit with file, key,
value and expectation, never a traceback), hot reload (a bad edit leaves the running app as it was, with the
problem in ReloadStatus) and scripts (a raising script is disabled and reported, the game goes on).
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from pydantic import Field

from engine.app import App
from engine.builtin import Terrain
from engine.cli import main
from engine.config import ConfigError, ConfigModel
from engine.registry import default_registry
from engine.reload import HotReloader
from engine.schedule import Stage
from engine.scene import plan_scene
from engine.script import Script, ScriptError, ScriptRuntime, script

REPO = Path(__file__).resolve().parents[2]


# ------------------------------------------------------------------------------------------- helpers
def configs(tmp_path: Path) -> Path:
    """An empty configs root with a water preset and three height maps (a good one, a text file, a truncated
    PNG)."""
    root = tmp_path / "configs"
    for sub in ("scenes", "prefabs", "assets", "effects/water_surface"):
        (root / sub).mkdir(parents=True)
    (root / "effects" / "water_surface" / "calm.toml").write_text("wave_speed = 1.0\n")
    Image.fromarray(np.full((5, 5), 128, np.uint8), "L").save(root / "assets" / "hills.png")
    (root / "assets" / "notes.png").write_text("not an image\n")
    noise = np.random.default_rng(0).integers(0, 256, (64, 64), dtype=np.uint8)
    Image.fromarray(noise, "L").save(root / "assets" / "cut.png")
    cut = (root / "assets" / "cut.png").read_bytes()
    (root / "assets" / "cut.png").write_bytes(cut[:len(cut) // 2])  # a valid header, half the pixels
    return root


def scene(root: Path, text: str, name: str = "s.toml") -> Path:
    path = root / "scenes" / name
    path.write_text(text)
    return path


def cli(capsys, *argv: str) -> tuple[int, str]:
    """Run the command line in-process: an exception escaping main() would be the traceback a user sees."""
    code = main(list(argv))
    out = capsys.readouterr()
    text = out.out + out.err
    assert "Traceback" not in text
    return code, text


def problems_of(path: Path, registry=None) -> list:
    with pytest.raises(ConfigError) as err:
        plan_scene(path, registry or default_registry())
    return err.value.problems


ENTITY = '[[entities]]\nname = "e"\n'


# ---------------------------------------------------------------------------------------- the CLI
def test_validate_missing_file_and_empty_directory(tmp_path, capsys):
    code, text = cli(capsys, "validate", str(tmp_path / "nope.toml"))
    assert code == 1 and "nope.toml" in text and "no such file" in text
    (tmp_path / "empty").mkdir()
    code, text = cli(capsys, "validate", str(tmp_path / "empty"))
    assert code == 1 and "no .toml files" in text  # not "validated 0 file(s)" and success


def test_validate_syntax_error_names_file_and_line(tmp_path, capsys):
    path = scene(configs(tmp_path), '[scene]\nname = "x"\n[[entities]\n')
    code, text = cli(capsys, "validate", str(path))
    assert code == 1 and f"{path}:3:" in text and "TOML syntax error" in text


def test_a_bad_scene_table_does_not_hide_the_entity_problems(tmp_path, capsys):
    path = scene(configs(tmp_path), '[scene]\nseed = "seven"\n' + ENTITY
                 + "[entities.components.Transform]\nscael = [1.0, 1.0, 1.0]\nposition = [0.0, nan, 0.0]\n"
                 + "[entities.components.Colider]\n")
    keys = {p.key: p for p in problems_of(path)}
    assert set(keys) == {"scene.seed", "entities[0].components.Transform.scael",
                         "entities[0].components.Transform.position[1]", "entities[0].components.Colider"}
    assert keys["entities[0].components.Transform.scael"].suggestion == "scale"
    assert keys["entities[0].components.Colider"].suggestion == "Collider"
    assert "finite" in keys["entities[0].components.Transform.position[1]"].message  # TOML's nan is refused
    code, text = cli(capsys, "run", str(path), "--no-render", "--steps", "1")
    assert code == 1 and "4 problems" in text and "did you mean 'scale'" in text  # run reports them all too


@pytest.mark.parametrize("preset, expected", [
    ("../../../etc/passwd", "escapes the configs root"),
    ("/etc/passwd", "must be relative"),
    ("water_surface/nope", "preset not found"),
    ("clam", "did you mean 'calm'"),
    (5, "expected a preset name string"),
])
def test_bad_preset_reference(tmp_path, capsys, preset, expected):
    value = f'"{preset}"' if isinstance(preset, str) else preset
    path = scene(configs(tmp_path), ENTITY + f"[entities.components.WaterSurface]\npreset = {value}\n")
    code, text = cli(capsys, "validate", str(path))
    assert code == 1 and expected in text
    assert f"{path}:4: entities[0].components.WaterSurface.preset" in text and repr(preset) in text


@pytest.mark.parametrize("key, value, expected", [
    ("heightmap", "assets/missing.png", "height map not found"),
    ("heightmap", "assets/notes.png", "not a readable image"),
    ("heightmap", "assets/cut.png", "not a readable image"),  # the header reads: validate passed it, the spawn failed
    ("heightmap", "../../outside.png", "escapes the configs root"),
    ("texture", "assets/missing.png", "texture not found"),
    ("texture", "assets/notes.png", "not a readable image"),
    ("texture", "assets/cut.png", "not a readable image"),  # the header reads; the pixels do not
    ("texture", "../../outside.png", "escapes the configs root"),
])
def test_bad_terrain_asset_is_caught_by_validate_with_its_key(tmp_path, capsys, key, value, expected):
    root = configs(tmp_path)
    path = scene(root, ENTITY + f'[entities.components.Terrain]\n{key} = "{value}"\n')
    (p,) = problems_of(path)
    assert p.key == f"entities[0].components.Terrain.{key}" and p.value == value and expected in p.message
    code, text = cli(capsys, "validate", str(path))  # before this, validate passed and only run failed
    assert code == 1 and expected in text
    good = scene(root, ENTITY + f'[entities.components.Terrain]\n{key} = "assets/hills.png"\n', "good.toml")
    assert cli(capsys, "validate", str(good))[0] == 0


def test_a_grey_ground_texture_is_decoded_from_srgb(tmp_path):
    good = scene(configs(tmp_path), ENTITY + '[entities.components.Terrain]\ntexture = "assets/hills.png"\n')
    (terrain,) = [t for _, (t,) in App(good).world.query(Terrain)]  # grey 128 decoded from sRGB: 0.2158 linear
    assert terrain.texture.shape == (5, 5, 3) and np.allclose(terrain.texture, 0.21586, atol=1e-5)


def test_a_stock_preset_finds_its_stock_texture_from_a_game_folder(tmp_path, capsys):
    """terrain/dust_devil_desert names assets/sand.png; a game's own configs root without that file uses the
    engine's, as it uses the engine's preset (and its own file of the same name when it has one)."""
    root = configs(tmp_path)
    path = scene(root, ENTITY + '[entities.components.Terrain]\npreset = "terrain/dust_devil_desert"\n')
    assert cli(capsys, "validate", str(path))[0] == 0
    (terrain,) = [t for _, (t,) in App(path).world.query(Terrain)]
    assert terrain.texture.shape == (256, 256, 3)
    Image.fromarray(np.full((3, 2), 255, np.uint8), "L").save(root / "assets" / "sand.png")
    (terrain,) = [t for _, (t,) in App(path).world.query(Terrain)]
    assert terrain.texture.shape == (3, 2, 3) and np.all(terrain.texture == 1.0)


def test_heightmap_too_large_is_refused_from_the_header(tmp_path):
    from engine.heightfield import MAX_HEIGHTMAP_SIDE, inspect_heightmap

    big = tmp_path / "big.png"
    Image.new("L", (MAX_HEIGHTMAP_SIDE + 1, 2)).save(big)
    with pytest.raises(ValueError, match="pixels per side"):
        inspect_heightmap(big)


def test_unregistered_script_and_bad_params(tmp_path, capsys):
    path = scene(configs(tmp_path), ENTITY + 'scripts = [{ name = "spn" }, { name = "spin", params = { sped = 1.0 } },'
                                             ' { name = "spin", params = { speed = "fast" } }]\n')
    keys = {p.key: p for p in problems_of(path)}
    assert keys["entities[0].scripts[0].name"].suggestion == "spin"
    assert keys["entities[0].scripts[1].params.sped"].suggestion == "speed"
    assert keys["entities[0].scripts[2].params.speed"].value == "fast"


def test_prefab_reports_every_problem(tmp_path, capsys):
    root = configs(tmp_path)
    (root / "prefabs" / "rock.toml").write_text(
        'nmae = "rock"\nscripts = [{ name = "lifetme" }]\n[components.Transform]\nscael = [1.0, 1.0, 1.0]\n'
        '[components.Terrain]\nheightmap = "assets/missing.png"\n')
    code, text = cli(capsys, "validate", str(root / "prefabs"))
    assert code == 1
    for key in ("nmae", "scripts[0].name", "components.Transform.scael", "components.Terrain.heightmap"):
        assert "rock.toml:" in text and f": {key}: " in text, key


def test_prefab_spawn_errors(tmp_path):
    from engine.prefab import PrefabLibrary

    root = configs(tmp_path)
    (root / "prefabs" / "rock.toml").write_text("[components.Transform]\n")
    library = PrefabLibrary(default_registry(), root)
    with pytest.raises(ConfigError, match="did you mean 'rock'"):
        library.plan("rokc")
    with pytest.raises(ConfigError, match="escapes"):
        library.plan("../scenes/s")


def test_run_and_graph_with_missing_or_bad_scene(tmp_path, capsys):
    missing = str(tmp_path / "missing.toml")
    for command in (["run", missing, "--no-render"], ["graph", missing]):
        code, text = cli(capsys, *command)
        assert code == 1 and "missing.toml" in text and "file not found" in text
    code, text = cli(capsys, "run", str(tmp_path), "--no-render")  # a directory
    assert code == 1 and "cannot read file" in text


def test_run_rejects_bad_arguments_without_traceback(tmp_path, capsys):
    for args in (["--seed", "-1"], ["--steps", "-3"], ["--size", "0", "0"]):
        with pytest.raises(SystemExit) as exit_:
            main(["run", "configs/scenes/sandbox.toml", "--no-render", *args])
        assert exit_.value.code == 2 and "invalid whole number" in capsys.readouterr().err
    recording = tmp_path / "input.jsonl"
    recording.write_text('{"format": "ecsfx-input/1"}\n{"tick": 1}\n')
    code, text = cli(capsys, "run", "configs/scenes/sandbox.toml", "--no-render", "--replay", str(recording))
    assert code == 1 and f"{recording}:2:" in text
    with pytest.raises(ConfigError, match="seed"):
        App("configs/scenes/sandbox.toml", seed=-1)


def test_unknown_plugin_in_scene_names_the_key(tmp_path):
    path = scene(configs(tmp_path), '[scene]\nplugins = ["water_surfce"]\n')
    with pytest.raises(ConfigError) as err:
        App(path)
    (p,) = err.value.problems
    assert p.key == "scene.plugins" and "did you mean 'water_surface'" in p.message


@pytest.mark.parametrize("given", ["none", "default", "core only"])
def test_an_unknown_plugin_in_the_scene_is_an_error_whatever_registry_app_is_given(tmp_path, given):
    """[scene] plugins names a plugin no package declares: a ConfigError naming the file, the key, its line and
    the near miss, with App's own registry or one passed in (was: silently ignored when registry= was given)."""
    path = scene(configs(tmp_path), '[scene]\nname = "x"\nplugins = ["nonexistent_plugin", "water_surfce"]\n')
    registry = {"none": None, "default": default_registry(), "core only": default_registry([])}[given]
    with pytest.raises(ConfigError) as err:
        App(path, registry=registry)
    unknown, near = err.value.problems
    assert (unknown.file, unknown.key, unknown.line) == (str(path), "scene.plugins", 3)
    assert "unknown plugin 'nonexistent_plugin'" in unknown.message and "render" in unknown.message
    assert near.key == "scene.plugins" and "did you mean 'water_surface'" in near.message


def test_a_scene_plugin_missing_from_the_registry_app_is_given_is_named(tmp_path):
    """A plugin that exists but is not installed in the registry passed to App: its components would be unknown,
    so the scene's plugins entry says why (and every problem is reported at once)."""
    path = scene(configs(tmp_path), '[scene]\nplugins = ["render", "dust_devil"]\n')
    with pytest.raises(ConfigError) as err:
        App(path, registry=default_registry(["render"]))
    (p,) = err.value.problems
    assert p.key == "scene.plugins" and "plugin 'dust_devil' is not installed in this registry" in p.message
    assert App(path, registry=default_registry(["render", "dust_devil"])).registry.plugins[-1] == "dust_devil"


def test_gallery_bad_arguments_fail_before_rendering(tmp_path, capsys):
    root = configs(tmp_path)
    code, text = cli(capsys, "gallery", "--configs", str(tmp_path / "nowhere"), "--out", str(tmp_path / "g"))
    assert code == 1 and "--configs" in text
    code, text = cli(capsys, "gallery", "--configs", str(root), "--out", str(tmp_path / "g"), "--only", "clam")
    assert code == 1 and "--only: no preset matches" in text and "water_surface/calm" in text


def test_gallery_steps_line_is_checked(tmp_path):
    from engine.gallery import _gallery_steps

    preset = tmp_path / "p.toml"
    preset.write_text("#:gallery-steps lots\n")
    with pytest.raises(ConfigError, match="gallery-steps"):
        _gallery_steps("", tmp_path, preset)


def test_a_factory_raising_anything_is_a_config_error(tmp_path):
    class Boom(ConfigModel):
        size: int = Field(1, ge=1, le=10)

    def build(cfg, ctx):
        raise KeyError("lookup inside the plugin")

    registry = default_registry([])
    registry.add_component("Boom", Boom, build)
    path = scene(configs(tmp_path), ENTITY + "[entities.components.Transform]\n[entities.components.Boom]\n")
    with pytest.raises(ConfigError) as err:
        App(path, registry=registry)
    (p,) = err.value.problems
    assert p.key == "entities[0].components.Boom" and "KeyError" in p.message


def test_the_real_entry_point_prints_no_traceback(tmp_path):
    root = configs(tmp_path)
    scene(root, "[[entities]\n", "syntax.toml")
    scene(root, ENTITY + '[entities.components.Terrain]\nheightmap = "assets/notes.png"\n', "png.toml")
    scene(root, ENTITY + "[entities.components.WaterSurface]\ndamping = 2.0\n", "range.toml")
    done = subprocess.run([sys.executable, "-m", "engine", "validate", str(root)], capture_output=True, text=True,
                          cwd=REPO, timeout=120)
    assert done.returncode == 1 and "Traceback" not in done.stderr + done.stdout
    assert "range.toml:4: entities[0].components.WaterSurface.damping" in done.stderr
    assert "png.toml:4: entities[0].components.Terrain.heightmap" in done.stderr
    assert "3 with problems" in done.stdout


# ------------------------------------------------------------------------------------------ hot reload
from tests.engine.test_reload import PumpConfig, PumpState, pump_system  # noqa: E402

# the test component of test_reload.py (a rate and a capacity-sized array), under the name "Tank"
TankConfig, TankState, tank_system = PumpConfig, PumpState, pump_system


def tank_build(cfg, ctx):
    if cfg.capacity == 13:
        raise RuntimeError("unlucky capacity")  # not a ValueError: a plugin bug that must not crash the game
    return [cfg, TankState(np.zeros(cfg.capacity))]


TANK_SCENE = """
[[entities]]
name = "tank"
[entities.components.Transform]
[entities.components.Tank]
preset = "tank/basic"
capacity = {capacity}
[[entities]]
name = "{second}"
[entities.components.Tank]
rate = 5.0
capacity = {second_capacity}
"""


def tank_app(tmp_path, capacity=4, second="spare", second_capacity=4, live_update=None):
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    (root / "effects" / "tank").mkdir(parents=True)
    (root / "effects" / "tank" / "basic.toml").write_text("rate = 2.0\n")
    path = root / "scenes" / "s.toml"
    path.write_text(TANK_SCENE.format(capacity=capacity, second=second, second_capacity=second_capacity))
    registry = default_registry([])
    registry.add_component("Tank", TankConfig, tank_build, preset_dir="tank", structural=("capacity",),
                           live_update=live_update)
    registry.add_system(tank_system, Stage.SIMULATION, name="tank")
    app = App(path, registry=registry, strict=True)
    app.step(2)
    return app, HotReloader(app), path


def levels(app, index=0):
    return app.world.get(app.records[index].entity, TankState).levels


def test_reload_unparseable_edit_keeps_the_world(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    good = path.read_text()
    path.write_text(good + "\n[[entities\n")
    assert reloader.poll() and not reloader.reload()
    (error,) = reloader.status.errors
    assert str(path) in error and "TOML syntax error" in error
    app.step(1)
    assert levels(app)[0] == 6.0  # still running with the old config
    path.write_text(good.replace("rate = 5.0", "rate = 6.0"))
    assert reloader.poll() and reloader.status.errors == []


def test_reload_deleted_preset_keeps_the_world_and_names_the_key(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    (path.parents[1] / "effects" / "tank" / "basic.toml").unlink()
    assert reloader.poll()
    (error,) = reloader.status.errors
    assert f"{path}:6: entities[0].components.Tank.preset: preset not found" in error
    app.step(1)
    assert levels(app)[0] == 6.0


def test_reload_renamed_entity_respawns_it(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    old = app.records[1].entity
    path.write_text(TANK_SCENE.format(capacity=4, second="reserve", second_capacity=4))
    assert reloader.poll() and reloader.status.errors == []
    assert not app.world.alive(old) and app.records[1].name == "reserve"
    app.step(1)
    assert levels(app, 1)[0] == 5.0


def test_reload_rename_whose_spawn_fails_keeps_the_old_entity(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    old = app.records[1].entity
    path.write_text(TANK_SCENE.format(capacity=4, second="reserve", second_capacity=13))
    reloader.poll()
    (error,) = reloader.status.errors
    assert str(path) in error and "entities[1].components.Tank" in error and "RuntimeError" in error
    assert app.world.alive(old) and app.records[1].entity == old  # nothing lost
    app.step(1)
    assert levels(app, 1)[0] == 15.0


def test_reload_removed_component(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    second = TANK_SCENE.index('name = "{second}"')
    path.write_text(TANK_SCENE[:second].format(capacity=4) + 'name = "spare"\n[entities.components.Transform]\n')
    assert reloader.poll() and reloader.status.errors == []
    assert not app.world.has(app.records[1].entity, TankState)
    app.step(1)
    assert levels(app)[0] == 6.0


def test_reload_rebuild_raising_keeps_the_old_component(tmp_path):
    app, reloader, path = tank_app(tmp_path)
    state = levels(app)
    path.write_text(TANK_SCENE.format(capacity=13, second="spare", second_capacity=4))
    reloader.poll()  # a RuntimeError in the factory used to escape from here and end the game
    (error,) = reloader.status.errors
    assert str(path) in error and "entities[0].components.Tank" in error and "unlucky capacity" in error
    app.step(1)
    assert levels(app) is state and state[0] == 6.0


def test_reload_live_update_raising_keeps_the_old_config(tmp_path):
    def live_update(old, new, world, entity):
        raise RuntimeError("hook failed")

    app, reloader, path = tank_app(tmp_path, live_update=live_update)
    (path.parents[1] / "effects" / "tank" / "basic.toml").write_text("rate = 9.0\n")
    reloader.poll()
    assert any("entities[0].components.Tank" in e and "hook failed" in e for e in reloader.status.errors)
    app.step(1)
    assert levels(app)[0] == 6.0  # the old rate 2.0 still in force


# --------------------------------------------------------------------------------------------- scripts
@dataclass
class Ping:
    n: int


@dataclass
class Ticks:
    n: int = 0


def faulty(hook: str) -> type[Script]:
    @script(f"faulty_{hook}")
    class Faulty(Script):
        events = (Ping,)

        def on_start(self):
            if hook == "on_start":
                raise RuntimeError("boom")

        def on_update(self, dt):
            if hook == "on_update":
                raise RuntimeError("boom")
            if hook == "call":
                self.ctx.call("engine.pauze")
            if hook == "prefab":
                self.ctx.spawn_prefab("missing")
            if hook == "on_event":
                self.ctx.send(Ping(1))
            if hook == "on_destroy" and self.ctx.tick == 1:
                self.ctx.despawn()

        def on_event(self, event):
            raise RuntimeError("boom")

        def on_destroy(self):
            if hook == "on_destroy":
                raise RuntimeError("boom")

    return Faulty


@script("ticker")
class Ticker(Script):
    def on_update(self, dt):
        self.ctx.world.resource(Ticks).n += 1


HOOKS = {"on_start": "boom", "on_update": "boom", "on_event": "boom", "on_destroy": "boom",
         "call": "unknown command 'engine.pauze'; did you mean 'engine.pause'?", "prefab": "prefab not found"}


def script_app(tmp_path, hook, strict):
    root = configs(tmp_path)
    path = scene(root, f'[[entities]]\nname = "hero"\nscripts = [{{ name = "faulty_{hook}" }}]\n'
                       '[[entities]]\nname = "clock"\nscripts = [{ name = "ticker" }]\n')
    registry = default_registry([])
    registry.add_scripts([faulty(hook), Ticker])
    app = App(path, registry=registry, strict=strict)
    app.world.insert_resource(Ticks())
    return app


@pytest.mark.parametrize("hook", sorted(HOOKS))
def test_script_failure_is_isolated_and_named(tmp_path, caplog, hook):
    app = script_app(tmp_path, hook, strict=False)
    app.step(4)
    assert app.world.resource(Ticks).n == 4  # the other script and the game went on
    (failure,) = app.world.resource(ScriptRuntime).failures
    expected_hook = hook if hook.startswith("on_") else "on_update"
    assert (failure.entity, failure.script, failure.hook) == (1, f"faulty_{hook}", expected_hook)
    assert HOOKS[hook] in failure.error
    assert f"script 'faulty_{hook}' on entity 1 ('hero') raised in {expected_hook}" in caplog.text


@pytest.mark.parametrize("hook", sorted(HOOKS))
def test_script_failure_reraises_in_strict_mode(tmp_path, hook):
    app = script_app(tmp_path, hook, strict=True)
    with pytest.raises(ScriptError, match=rf"script 'faulty_{hook}' on entity 1 \('hero'\) raised in on_"):
        app.step(4)


def test_strict_run_on_the_command_line_reports_without_crashing(tmp_path, capsys, monkeypatch):
    import engine.app

    registry = default_registry([])
    registry.add_script(faulty("on_update"))
    monkeypatch.setattr(engine.app, "default_registry", lambda plugins=None: registry)
    path = scene(configs(tmp_path), '[[entities]]\nname = "hero"\nscripts = [{ name = "faulty_on_update" }]\n')
    code = main(["run", str(path), "--no-render", "--steps", "3", "--strict"])
    err = capsys.readouterr().err
    assert code == 1 and (f"error: {path}: entities[0].scripts[0]: script 'faulty_on_update' on entity 1 ('hero') "
                          "raised in on_update: boom") in err


def test_a_replay_header_with_a_bad_tick_count_is_an_error_naming_the_file(tmp_path, capsys):
    recording = tmp_path / "input.jsonl"
    for ticks in ('"abc"', "1e18", "-4", "true"):
        recording.write_text(f'{{"format": "ecsfx-input/1", "ticks": {ticks}}}\n')
        code, text = cli(capsys, "run", "configs/scenes/sandbox.toml", "--no-render", "--replay", str(recording))
        assert code == 1 and f"{recording}:1: ticks:" in text


def test_validate_plans_a_scene_with_its_own_plugins(tmp_path, capsys):
    root = configs(tmp_path)
    unknown = scene(root, '[scene]\nplugins = ["render", "nope"]\n')
    code, text = cli(capsys, "validate", str(unknown))
    assert code == 1 and "scene.plugins" in text and "nope" in text
    not_listed = scene(root, '[scene]\nplugins = ["render"]\n[[entities]]\nname = "d"\n'
                             '[entities.components.DustDevil]\n')
    code, text = cli(capsys, "validate", str(not_listed))
    assert code == 1 and "DustDevil" in text and "entities[0]" in text
