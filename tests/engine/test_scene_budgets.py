"""A component's joint limits bound the whole scene too: many entities each under the limit cannot add up past it
(a scene may hold 100,000 entities; each one at its cap would take the memory of the machine)."""

from __future__ import annotations

from pathlib import Path

import pytest

from engine.config import ConfigError
from engine.registry import default_registry
from engine.scene import plan_scene


def _scene(tmp_path: Path, tables: list[str]) -> Path:
    scenes = tmp_path / "configs" / "scenes"
    scenes.mkdir(parents=True)
    text = '[scene]\nname = "budgets"\n'
    for i, table in enumerate(tables):
        text += f'\n[[entities]]\nname = "e{i}"\n{table}\n'
    path = scenes / "s.toml"
    path.write_text(text, encoding="utf-8")
    return path


GRASS = "[entities.components.GrassField]\ngrid_x = 100\ngrid_z = 100\nplants_per_cell = {n}\n"
DEVIL = "[entities.components.DustDevil]\nparticle_count = 100000\nsub_particles = 5\nrepeats = 10\ndrag_camera = \"\"\n"


def test_two_grass_fields_that_together_pass_the_plant_limit_are_refused_naming_both(tmp_path):
    with pytest.raises(ConfigError) as err:
        plan_scene(_scene(tmp_path, [GRASS.format(n=60), GRASS.format(n=60)]), default_registry())
    [problem] = err.value.problems
    assert problem.key == "entities"
    assert "2 GrassField entities together need 1,200,000 plants" in problem.message
    assert "1,048,576" in problem.message and "entities[0], entities[1]" in problem.message


def test_fields_within_the_limit_together_load(tmp_path):
    plan = plan_scene(_scene(tmp_path, [GRASS.format(n=50), GRASS.format(n=50)]), default_registry())
    assert len(plan.entities) == 2


def test_many_dust_devils_each_legal_are_refused_together(tmp_path):
    """Each draws 5 M PBVR points a frame (the limit is 8 M); two are 10 M."""
    with pytest.raises(ConfigError, match="2 DustDevil entities together need 10,000,000 PBVR points"):
        plan_scene(_scene(tmp_path, [DEVIL, DEVIL]), default_registry())


def test_the_budget_is_reported_with_the_scenes_other_problems(tmp_path):
    with pytest.raises(ConfigError) as err:
        plan_scene(_scene(tmp_path, [GRASS.format(n=60), GRASS.format(n=60), "[entities.components.Camera]\nfov = 1.0\n"]),
                   default_registry())
    assert {p.key for p in err.value.problems} == {"entities", "entities[2].components.Camera.fov"}


def _app_with_prefab(tmp_path: Path, scene_tables: list[str]):
    from engine.app import App

    scene = _scene(tmp_path, scene_tables)
    prefabs = scene.parent.parent / "prefabs"
    prefabs.mkdir()
    (prefabs / "devil.toml").write_text('name = "devil"\n' + DEVIL.replace("entities.components", "components"))
    return App(scene, strict=True)


def test_a_prefab_spawned_at_run_time_cannot_pass_the_scene_budget(tmp_path):
    """The scene loads with one dust devil of 5 M PBVR points; a script spawning a second one (10 M together, the
    limit is 8 M) is refused naming the prefab's file and component, and nothing is queued."""
    from engine.script import ScriptContext

    app = _app_with_prefab(tmp_path, [DEVIL])
    ctx = ScriptContext(app.world, 1, "test")
    queued = len(app.world.commands)
    with pytest.raises(ConfigError) as err:
        ctx.spawn_prefab("devil")
    problems = err.value.problems
    assert all(p.file.endswith("devil.toml") and p.key == "components.DustDevil" for p in problems)
    assert any("10,000,000 PBVR points" in p.message and "8,000,000" in p.message for p in problems)
    assert len(app.world.commands) == queued


def test_run_time_budget_counts_queued_spawns_and_despawns(tmp_path):
    from engine.builtin import Name
    from engine.script import ScriptContext

    app = _app_with_prefab(tmp_path, ["[entities.components.Transform]\n"])
    ctx = ScriptContext(app.world, 1, "test")
    ctx.spawn_prefab("devil")  # alone: within the limit
    with pytest.raises(ConfigError, match="10,000,000 PBVR points"):
        ctx.spawn_prefab("devil")  # the first is only queued, and still counts
    app.world.commands.apply()
    [devil] = [e for e, (n,) in app.world.query(Name) if n.value == "devil"]
    ctx.despawn(devil)
    ctx.spawn_prefab("devil")  # replaces the one queued to despawn
    app.world.commands.apply()
    assert [n.value for _, (n,) in app.world.query(Name)].count("devil") == 1
