"""Presets, the showcase scene and config errors (wrong type, out of range, unknown key, inconsistent values)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.cli import validate_file
from engine.config import ConfigError
from engine.registry import default_registry
from engine.scene import plan_scene
from tests.systems.grass_field.helpers import PRESETS, SHOWCASE, scene_text, write_scene

PRESET_NAMES = ["paper", "lawn", "meadow"]


@pytest.fixture(scope="module")
def registry():
    return default_registry()


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_preset_validates(name, registry):
    path = PRESETS / f"{name}.toml"
    assert path.read_text().splitlines()[0] == "#:schema ../../schema/GrassField.schema.json"
    validate_file(path, registry)


def test_paper_preset_is_the_papers_setup(registry):
    from tests.systems.grass_field.helpers import make_field, paper_config

    cfg = paper_config()
    assert cfg.cell_size == 100.0 and cfg.merge_distance == 800.0
    assert cfg.level_thresholds == (4.0, 1.5, 1.0, 0.75) and cfg.length_of_interest == 0.5
    _, data = make_field(cfg)
    assert 15.0 <= data.plant_height <= 25.0  # "plants about 20 tall"


def test_showcase_validates(registry):
    plan = validate_file(SHOWCASE, registry)
    assert any(c == "GrassField" for ent in plan.entities for c, _ in ent.components)


def test_showcase_runs_a_day():
    """The showcase's sun_cycle (a day of 180 s from 8 o'clock) moves the sun 30 degrees in 15 s of game time."""
    from engine.app import App
    from engine.render.lighting import Lighting

    app = App(SHOWCASE, strict=True)
    app.step(1)
    start = np.asarray(app.world.resource(Lighting).sun_direction)
    app.step(round(15.0 / app.config.scene.fixed_dt))
    end = np.asarray(app.world.resource(Lighting).sun_direction)
    angle = np.degrees(np.arccos(np.clip(start @ end / np.linalg.norm(start) / np.linalg.norm(end), -1.0, 1.0)))
    assert abs(angle - 30.0) < 1.0, angle


def _problems(tmp_path, registry, body: str):
    path = write_scene(tmp_path, scene_text(body, terrain=False))
    with pytest.raises(ConfigError) as info:
        plan_scene(path, registry)
    return info.value.problems


@pytest.mark.parametrize("body, key, words", [
    ('grid_x = "10"', "GrassField.grid_x", "integer"),
    ("plants_per_cell = 0", "GrassField.plants_per_cell", "greater than or equal to 1"),
    ("cell_size = 1e9", "GrassField.cell_size", "less than or equal"),
    ("level_thresholds = [0.75, 1.0, 1.5, 4.0]", "GrassField.level_thresholds", "strictly decreasing"),
    ("level_thresholds = [4.0, 1.5, 1.0, 0.0]", "GrassField.level_thresholds", "positive"),
    ("level_thresholds = [4.0, 1.5, 1.0, 1.0]", "GrassField.level_thresholds", "strictly decreasing"),
    ("level_thresholds = [4.0, 1.5, 1.0, 2.0]", "GrassField.level_thresholds", "strictly decreasing"),
    ("level_thresholds = [4.0, 4.0, 1.0, 0.5]", "GrassField.level_thresholds", "strictly decreasing"),
    ("leaf_subdivisions = [4.0, 2.0, 1.0]", "GrassField.leaf_subdivisions", "at least 4"),
    ("max_level = 6", "GrassField.max_level", "less than or equal to 5"),
])
def test_bad_values_name_the_key(tmp_path, registry, body, key, words):
    problems = _problems(tmp_path, registry, body)
    assert len(problems) == 1
    assert problems[0].key.endswith(key), problems[0]
    assert words in str(problems[0])
    assert str(problems[0]).count("got ") <= 1, problems[0]  # the value once, not again after the message


def test_unknown_key_suggests_the_near_miss(tmp_path, registry):
    problems = _problems(tmp_path, registry, "plants_per_cel = 10")
    assert problems[0].key.endswith("GrassField.plants_per_cel")
    assert problems[0].suggestion == "plants_per_cell"
    assert "did you mean 'plants_per_cell'" in str(problems[0])


def test_plant_budget_is_enforced(tmp_path, registry):
    problems = _problems(tmp_path, registry, "grid_x = 256\ngrid_z = 256\nplants_per_cell = 64")
    assert "grid_x * grid_z * plants_per_cell" in str(problems[0])


def test_preset_value_overridden_inline(tmp_path, registry):
    path = write_scene(tmp_path, scene_text('preset = "grass_field/paper"\ngrid_x = 3\ngrid_z = 2', terrain=False))
    plan = plan_scene(path, registry)
    cfg = dict(plan.entities[0].components)["GrassField"]
    assert (cfg.grid_x, cfg.grid_z, cfg.cell_size) == (3, 2, 100.0)


CAMERA = "[entities.components.Transform]\nposition = [0.0, 30.0, 0.0]\n[entities.components.Camera]\nfov = 60.0\n"


@pytest.mark.parametrize("length, warned", [(0.5, False), (100.0, True)])
def test_a_length_of_interest_that_makes_most_cells_level_0_is_a_warning(tmp_path, registry, length, warned):
    """Eq. 1 with L = 100 on the paper's grid (40 x 40 cells of 100, 40 plants) makes every cell within about
    12,000 units level 0 at 960 px: about 80 M triangles a frame.  Legal (the paper's rule), so a warning, not an error."""
    body = f'preset = "grass_field/paper"\ngrid_x = 40\ngrid_z = 40\nplants_per_cell = 40\nlength_of_interest = {length}'
    plan = plan_scene(write_scene(tmp_path, scene_text(body, CAMERA, terrain=False)), registry)
    found = [w for w in plan.warnings if w.key.endswith("GrassField.length_of_interest")]
    assert bool(found) == warned
    if warned:
        assert "level 0" in found[0].message and "M triangles a frame" in found[0].message and found[0].line


@pytest.mark.parametrize("camera, warned", [
    (CAMERA + 'hide_features = ["grass_field"]\n', False),  # the only view does not draw the field
    (CAMERA + "enabled = false\n", False),
    ("", True),  # no camera: the renderer's default view
])
def test_the_level_0_warning_follows_the_views_that_draw_the_field(tmp_path, registry, camera, warned):
    body = 'preset = "grass_field/paper"\ngrid_x = 40\ngrid_z = 40\nplants_per_cell = 40\nlength_of_interest = 100.0'
    plan = plan_scene(write_scene(tmp_path, scene_text(body, camera, terrain=False)), registry)
    found = [w for w in plan.warnings if w.key.endswith("GrassField.length_of_interest")]
    assert bool(found) == warned
    if warned:
        assert "in 'the default view'" in found[0].message
