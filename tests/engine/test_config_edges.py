"""Edge inputs a fuzzing review found passing validation or escaping it with a traceback: each is now a problem
(or a warning) naming the file and the key, and the scene's other problems are still reported."""

import numpy as np

from engine.cli import main
from engine.registry import default_registry
from engine.scene import RenderSettings, plan_scene

import pytest

from engine.config import ConfigError


def _scene(tmp_path, text: str, name: str = "s.toml"):
    root = tmp_path / "configs" / "scenes"
    root.mkdir(parents=True, exist_ok=True)
    path = root / name
    path.write_text(text)
    return path


def _problems(path):
    with pytest.raises(ConfigError) as err:
        plan_scene(path, default_registry())
    return err.value.problems


def test_a_path_too_long_for_the_os_is_a_problem_at_its_key_not_an_oserror(tmp_path):
    long = "x" * 300
    path = _scene(tmp_path, f'[[entities]]\nname = "e"\n[entities.components.EnergyWaveEmitter]\npreset = "{long}"\n'
                            f'[[entities]]\nname = "t"\n[entities.components.Terrain]\ntexture = "{long}.png"\n')
    problems = _problems(path)
    assert [p.key for p in problems] == ["entities[0].components.EnergyWaveEmitter.preset",
                                         "entities[1].components.Terrain.texture"]
    assert all("too long" in p.message and p.line for p in problems)


def test_validate_reports_a_deeply_nested_file_and_goes_on_with_the_others(tmp_path, capsys):
    deep = _scene(tmp_path, "x = " + "[" * 600 + "]" * 600 + "\n", "a_deep.toml")
    bad = _scene(tmp_path, '[[entities]]\nname = "e"\n[entities.components.EnergyWaveEmitter]\nbeam_speed = "fast"\n',
                 "z_bad.toml")
    assert main(["validate", str(deep.parent)]) == 1
    err = capsys.readouterr().err
    assert f"{deep}: <file>: arrays or tables nested too deeply" in err
    assert f"{bad}:4: entities[0].components.EnergyWaveEmitter.beam_speed" in err
    assert "internal error" not in err and "Traceback" not in err


def test_the_sun_needs_a_direction_and_colours_are_colours(tmp_path):
    path = _scene(tmp_path, "[render]\nsun_direction = [0.0, 0.0, 0.0]\nsun_color = [-1e6, 0.0, 0.0]\n"
                            "sky_top = [0.2, 0.3, 100.0]\n")
    found = {p.key: p for p in _problems(path)}
    assert set(found) == {"render.sun_direction", "render.sun_color[0]", "render.sky_top[2]"}
    assert "non-zero direction" in found["render.sun_direction"].message
    assert RenderSettings(sun_direction=[0.0, 1e-3, 0.0]).sun_direction == (0.0, 1e-3, 0.0)


def test_a_list_where_a_table_belongs_names_no_python_class(tmp_path):
    path = _scene(tmp_path, 'entities = [1]\n')
    (problem,) = _problems(path)
    assert problem.key == "entities[0]" and problem.message.startswith("expected a table")
    assert "EntityConfig" not in str(problem)


def test_a_hidden_feature_that_does_not_exist_is_a_warning_with_the_near_name(tmp_path):
    path = _scene(tmp_path, '[[entities]]\nname = "cam"\n[entities.components.Transform]\n'
                            '[entities.components.Camera]\nhide_features = ["terrain", "grass_feild"]\n')
    plan = plan_scene(path, default_registry())
    (warning,) = [w for w in plan.warnings if "hide_features" in w.key]
    assert warning.key == "entities[0].components.Camera.hide_features[1]" and warning.line == 5
    assert warning.suggestion == "grass_field"


def test_the_registered_feature_names_are_the_features_a_renderer_makes():
    from engine.app import App
    from engine.render.plugin import BUILTIN_FEATURES
    from tests.render_utils import make_renderer

    app = App()
    renderer = make_renderer(app, 16, 16)
    try:
        made = [f.name for f in renderer.features]
    finally:
        renderer.release()
        app.renderer = None
    assert made == list(BUILTIN_FEATURES) + app.registry.render_feature_names
    assert len(set(made)) == len(made) and np.all([isinstance(n, str) and n for n in made])
