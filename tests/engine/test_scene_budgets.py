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
