"""Every kind of bad TOML gets one ConfigError naming the file, key, value and a suggestion."""

import subprocess
import sys
from pathlib import Path

import pytest

from engine.app import App
from engine.config import ConfigError
from engine.registry import default_registry
from engine.scene import plan_scene

REGISTRY = default_registry()


def write_scene(tmp_path: Path, body: str, presets: dict[str, str] | None = None) -> Path:
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True)
    for rel, text in (presets or {}).items():
        p = root / "effects" / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text)
    scene = root / "scenes" / "s.toml"
    scene.write_text(body)
    return scene


def problems(scene: Path):
    with pytest.raises(ConfigError) as err:
        plan_scene(scene, REGISTRY)
    return err.value.problems


def test_syntax_error_names_file_and_line(tmp_path):
    scene = write_scene(tmp_path, "[scene]\nname = \n")
    (p,) = problems(scene)
    assert p.file == str(scene) and p.line == 2 and "syntax" in p.message


def test_wrong_type_string_for_number(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\nspacing = "1.5"\n')
    (p,) = problems(scene)
    assert p.key == "entities[0].components.Terrain.spacing" and p.value == "1.5" and p.line == 3
    assert "number" in p.message


def test_unknown_key_did_you_mean(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\nrougness = 0.5\n')
    (p,) = problems(scene)
    assert p.suggestion == "roughness" and "unknown key 'rougness'" in p.message
    assert "did you mean 'roughness'" in str(p)


def test_out_of_range(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\nsize_exponent = 30\n')
    (p,) = problems(scene)
    assert p.key.endswith("size_exponent") and p.value == 30 and "less than or equal to 10" in p.message


def test_unknown_component_and_script_are_reported_together(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\nscripts = [{ name = "spinn" }]\n'
                                  '[entities.components.Transfrom]\nposition = [0.0, 0.0, 0.0]\n')
    found = problems(scene)
    assert len(found) == 2
    comp, scr = found
    assert comp.suggestion == "Transform" and "unknown component" in comp.message
    assert scr.suggestion == "spin" and scr.key == "entities[0].scripts[0].name"


def test_script_params_are_validated(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\nscripts = [{ name = "spin", params = { sped = 3.0 } }]\n')
    (p,) = problems(scene)
    assert p.key == "entities[0].scripts[0].params.sped" and p.suggestion == "speed"


def test_preset_merges_with_inline_overrides(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\npreset = "hills"\namplitude = 2.0\n',
                        {"terrain/hills.toml": "size_exponent = 4\namplitude = 9.0\n"})
    plan = plan_scene(scene, REGISTRY)
    (name, cfg), = plan.entities[0].components
    assert cfg.size_exponent == 4 and cfg.amplitude == 2.0
    assert any(f.name == "hills.toml" for f in plan.files)


def test_error_inside_preset_names_the_preset_file(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\npreset = "hills"\n',
                        {"terrain/hills.toml": "size_exponent = 4\nroughness = 7.0\n"})
    (p,) = problems(scene)
    assert p.file.endswith("hills.toml") and p.key == "roughness" and p.line == 2


def test_missing_preset_lists_available(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\npreset = "hils"\n',
                        {"terrain/hills.toml": "size_exponent = 4\n"})
    (p,) = problems(scene)
    assert "preset not found" in p.message and p.suggestion == "hills" and p.key.endswith("preset")


@pytest.mark.parametrize("path", ["../../../etc/passwd", "/etc/passwd", "terrain/../../../x"])
def test_preset_path_escape_is_rejected(tmp_path, path):
    scene = write_scene(tmp_path, f'[[entities]]\n[entities.components.Terrain]\npreset = "{path}"\n')
    (p,) = problems(scene)
    assert "escapes the configs root" in p.message or "must be relative" in p.message


def test_all_problems_of_a_file_at_once(tmp_path):
    scene = write_scene(tmp_path, '[[entities]]\n[entities.components.Terrain]\nspacing = -1.0\nroughness = 3.0\n'
                                  '[[entities]]\n[entities.components.Collider]\nshape = "cube"\n')
    found = problems(scene)
    assert len(found) == 3
    assert found[2].key == "entities[1].components.Collider.shape" and found[2].line == 7


def test_a_bad_scene_builds_no_app(tmp_path):
    scene = write_scene(tmp_path, '[scene]\nseed = -4\n')
    with pytest.raises(ConfigError, match="scene.seed"):
        App(scene)


def test_validate_cli_exit_codes_without_traceback(tmp_path):
    good = write_scene(tmp_path, '[[entities]]\n[entities.components.Transform]\nposition = [1.0, 2.0, 3.0]\n')
    bad = good.parent / "bad.toml"
    bad.write_text('[[entities]]\n[entities.components.Transform]\npositon = [1.0, 2.0, 3.0]\n')
    ok = subprocess.run([sys.executable, "-m", "engine", "validate", str(good)], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    res = subprocess.run([sys.executable, "-m", "engine", "validate", str(good.parent)], capture_output=True, text=True)
    assert res.returncode == 1
    assert "Traceback" not in res.stderr and "did you mean 'position'" in res.stderr and "bad.toml:3" in res.stderr


def test_a_game_in_its_own_folder_uses_the_stock_presets_and_its_own_first(tmp_path):
    """A scene outside the engine's configs/ names a stock preset its own effects/ does not hold: the engine's is
    used; a preset of its own with the same name wins; a typo lists both folders' presets."""
    from engine.scene import STOCK_CONFIGS

    game = tmp_path / "mygame"
    game.mkdir()
    scene = game / "scene.toml"
    scene.write_text('[[entities]]\n[entities.components.WaterSurface]\npreset = "water_surface/calm_pond"\n')
    plan = plan_scene(scene, REGISTRY)
    assert plan.configs_root == game and STOCK_CONFIGS / "effects" / "water_surface" / "calm_pond.toml" in plan.files
    own = game / "effects" / "water_surface"
    own.mkdir(parents=True)
    (own / "calm_pond.toml").write_text("wave_speed = 0.5\n")
    (own / "mine.toml").write_text("wave_speed = 0.5\n")
    plan = plan_scene(scene, REGISTRY)
    assert own / "calm_pond.toml" in plan.files and plan.entities[0].components[0][1].wave_speed == 0.5
    scene.write_text('[[entities]]\n[entities.components.WaterSurface]\npreset = "water_surface/calm_pnd"\n')
    (p,) = problems(scene)
    assert "preset not found" in p.message and p.suggestion == "calm_pond" and "mine" in p.message
