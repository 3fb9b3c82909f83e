import numpy as np
import pytest

from engine.app import App
from engine.builtin import Name, Terrain
from engine.config import ConfigError
from engine.script import Script, ScriptContext, script
from engine.spatial import Transform


def make(tmp_path, prefab_text):
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    (root / "prefabs").mkdir()
    (root / "prefabs" / "rock.toml").write_text(prefab_text)
    scene = root / "scenes" / "s.toml"
    scene.write_text("[[entities]]\nname = 'a'\n[entities.components.Transform]\n")
    return App(scene, strict=True)


def test_spawn_prefab_is_deferred_and_positioned(tmp_path):
    app = make(tmp_path, "name = 'rock'\n[components.Transform]\nscale = [2.0, 2.0, 2.0]\n"
                         "[components.Terrain]\nsize_exponent = 2\n")
    ctx = ScriptContext(app.world, 1, "test")
    e = ctx.spawn_prefab("rock", position=(1.0, 2.0, 3.0))
    assert not app.world.alive(e)
    app.world.commands.apply()
    assert app.world.get(e, Name).value == "rock"
    assert np.array_equal(app.world.get(e, Transform).position, [1.0, 2.0, 3.0])
    assert app.world.get(e, Transform).scale[0] == 2.0 and app.world.has(e, Terrain)


def test_bad_prefab_reports_file_and_key(tmp_path):
    app = make(tmp_path, "[components.Transform]\nscael = [2.0, 2.0, 2.0]\n")
    ctx = ScriptContext(app.world, 1, "test")
    with pytest.raises(ConfigError) as err:
        ctx.spawn_prefab("rock")
    (p,) = err.value.problems
    assert p.file.endswith("rock.toml") and p.suggestion == "scale"
    with pytest.raises(ConfigError, match="prefab not found"):
        ctx.spawn_prefab("pebble")
    with pytest.raises(ConfigError, match="escapes"):
        ctx.spawn_prefab("../scenes/s")


def test_a_prefab_is_checked_at_the_scenes_step(tmp_path):
    """A water surface stable at the engine's smallest step (1/1000 s, what a prefab checked alone allows) but not
    at the scene's 1/60 s: spawning it is a ConfigError naming the prefab and the key, not a tick that raises."""
    app = make(tmp_path, "[components.Transform]\n[components.WaterSurface]\nresolution = [8, 8]\nspacing = 0.5\n"
                         "wave_speed = 100.0\n")
    from engine.prefab import PrefabLibrary

    alone = PrefabLibrary(app.registry, tmp_path / "configs")
    assert alone.plan("rock").name == "rock"  # validated alone: only the smallest step's limit applies
    ctx = ScriptContext(app.world, 1, "test")
    with pytest.raises(ConfigError) as err:
        ctx.spawn_prefab("rock")
    (p,) = err.value.problems
    assert p.file.endswith("rock.toml") and p.key == "components.WaterSurface.wave_speed" and "stability" in p.message
    app.clock.dt = 1.0 / 1000.0  # a step it can run at (as a hot reload of fixed_dt sets it): checked again
    e = ctx.spawn_prefab("rock")
    app.world.commands.apply()
    assert app.world.alive(e)
