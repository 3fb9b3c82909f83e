"""DustDevil config: presets and the showcase validate; mistakes give errors that name the key."""

from pathlib import Path

import pytest

from components.dust_devil import DustDevilConfig
from engine.cli import validate_file
from engine.config import ConfigError, validate
from engine.registry import default_registry

ROOT = Path(__file__).resolve().parents[3]
PRESETS = sorted((ROOT / "configs/effects/dust_devil").glob("*.toml"))
SHOWCASE = ROOT / "configs/scenes/dust_devil_showcase.toml"


@pytest.fixture(scope="module")
def registry():
    return default_registry()


def test_the_three_presets_exist():
    assert {p.stem for p in PRESETS} >= {"paper", "small_whirl", "large_storm", "tall_column"}


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_preset_validates_and_has_schema_header(path, registry):
    assert path.read_text(encoding="utf-8").startswith("#:schema ../../schema/DustDevil.schema.json")
    validate_file(path, registry)


def test_showcase_scene_validates(registry):
    plan = validate_file(SHOWCASE, registry)
    assert any(c == "DustDevil" for ent in plan.entities for c, _ in ent.components)


def test_paper_preset_is_the_papers_setup():
    import tomllib

    data = tomllib.loads((ROOT / "configs/effects/dust_devil/paper.toml").read_text(encoding="utf-8"))
    cfg = DustDevilConfig.model_validate(data)
    assert 3500 <= cfg.particle_count <= 5000
    assert (cfg.sub_particles, cfg.repeats, cfg.lookup) == (2, 16, "nearest")


def _error(data: dict) -> str:
    with pytest.raises(ConfigError) as info:
        validate(DustDevilConfig, data, "devil.toml")
    return str(info.value)


def test_wrong_type_names_the_key():
    text = _error({"particle_count": "5000"})
    assert "particle_count" in text and "devil.toml" in text


def test_out_of_range_names_the_key():
    assert "repeats" in _error({"repeats": 0})
    assert "grid_resolution[1]" in _error({"grid_resolution": [32, 1000, 32]})
    assert "particle_count" in _error({"particle_count": 10_000_000})


def test_the_pbvr_point_budget_is_enforced():
    """Each of particle_count, sub_particles and repeats is in range alone; together they may not ask for more than
    MAX_PBVR_POINTS points a frame (all three at their maxima: 204.8 million). Without PBVR only the real
    particles are drawn, so the product does not matter."""
    from components.dust_devil import MAX_PBVR_POINTS

    text = _error({"particle_count": 200_000, "sub_particles": 16, "repeats": 64})
    assert "particle_count * sub_particles * repeats = 204800000" in text and str(MAX_PBVR_POINTS) in text
    assert "devil.toml" in text
    DustDevilConfig(particle_count=200_000, sub_particles=16, repeats=64, pbvr=False)
    DustDevilConfig(particle_count=200_000, sub_particles=2, repeats=16)  # 6.4 million: allowed


def test_unknown_key_suggests_the_near_miss():
    text = _error({"sub_particle": 2})
    assert "unknown key 'sub_particle'" in text and "did you mean 'sub_particles'" in text


def test_bad_lookup_mode_suggests():
    text = _error({"lookup": "nearst"})
    assert "lookup" in text and "nearest" in text


def test_angle_range_must_be_ordered():
    assert "rotation_angle_range" in _error({"rotation_angle_range": [30.0, 10.0]})


def test_r_only_drops_while_dragging():
    """drag_repeats caps R while dragging: a larger value (the default 4, or a preset's, over a smaller repeats)
    keeps R at repeats instead of raising it."""
    from components.dust_devil import DustDevilConfig

    assert DustDevilConfig(repeats=2).dragging_repeats == 2
    assert DustDevilConfig(repeats=4, drag_repeats=8).dragging_repeats == 4
    assert DustDevilConfig(repeats=16, drag_repeats=3).dragging_repeats == 3


def test_the_papers_terrain_is_a_terrain_preset_at_the_papers_spacing(registry):
    """terrain/dust_devil_desert: midpoint displacement at grid spacing 2, 64 x 64 polygons (the paper's 63 x 63
    rounded to 2^n + 1 points per side); the showcase uses it."""
    from engine.app import App
    from engine.builtin import Terrain

    preset = ROOT / "configs/effects/terrain/dust_devil_desert.toml"
    assert preset.read_text(encoding="utf-8").startswith("#:schema ../../schema/Terrain.schema.json")
    validate_file(preset, registry)
    app = App(SHOWCASE)
    (terrain,) = [t for _, (t,) in app.world.query(Terrain)]
    assert terrain.field.heights.shape == (65, 65) and terrain.field.spacing == 2.0
    assert str(preset) in map(str, app.plan.files)


# ------------------------------------------------------------------ drag_camera names a camera (a warning)
def _scene(tmp_path, devil: str, cameras=("main", "top")) -> Path:
    configs = tmp_path / "configs" / "scenes"
    configs.mkdir(parents=True)
    text = "[scene]\nname = \"t\"\n\n[[entities]]\nname = \"devil\"\n[entities.components.DustDevil]\n" + devil
    for name in cameras:
        text += f"\n[[entities]]\nname = \"{name}\"\n[entities.components.Transform]\n[entities.components.Camera]\n"
    path = configs / "s.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_a_drag_camera_naming_no_camera_is_a_warning_with_the_key_line_and_a_suggestion(tmp_path, registry, capsys):
    from engine.cli import validate_command

    path = _scene(tmp_path, 'particle_count = 100\ndrag_camera = "topp"\n')
    plan = validate_file(path, registry)  # loads: a script may spawn the camera later
    [warning] = plan.warnings
    assert warning.key == "entities[0].components.DustDevil.drag_camera"
    assert warning.line == 8 and warning.suggestion == "top"
    assert "no camera entity named 'topp'" in warning.message and "'main', 'top'" in warning.message
    assert validate_command([path]) == 0  # printed, not failed
    err = capsys.readouterr()
    assert f"warning: {path}:8: entities[0].components.DustDevil.drag_camera" in err.err
    assert "1 warning(s)" in err.out


def test_the_default_drag_camera_missing_says_how_to_turn_dragging_off(tmp_path, registry):
    plan = validate_file(_scene(tmp_path, "particle_count = 100\n", cameras=("main",)), registry)
    [warning] = plan.warnings
    assert "'top'" in warning.message and 'drag_camera = ""' in warning.message


@pytest.mark.parametrize("devil, cameras", [('drag_camera = "top"\n', ("main", "top")),
                                            ('drag_camera = ""\n', ("main",))])
def test_a_named_camera_or_dragging_off_gives_no_warning(tmp_path, registry, devil, cameras):
    assert validate_file(_scene(tmp_path, "particle_count = 100\n" + devil, cameras), registry).warnings == []


def test_the_app_logs_the_warning_and_keeps_it(tmp_path, caplog):
    from engine.app import App

    with caplog.at_level("WARNING", logger="engine"):
        app = App(_scene(tmp_path, 'particle_count = 100\ndrag_camera = "minimap"\n'))
    assert [w.key for w in app.warnings] == ["entities[0].components.DustDevil.drag_camera"]
    assert "no camera entity named 'minimap'" in caplog.text


def test_a_failing_scene_check_is_a_warning_not_a_crash(tmp_path):
    from engine.scene import plan_scene

    registry = default_registry()
    registry.add_scene_check(lambda plan, text: 1 / 0)
    plan = plan_scene(_scene(tmp_path, "particle_count = 100\n"), registry)
    assert any("ZeroDivisionError" in w.message for w in plan.warnings)


def test_a_camera_without_a_transform_cannot_be_dragged_in_so_it_is_warned(tmp_path, registry):
    path = _scene(tmp_path, 'particle_count = 100\ndrag_camera = "top"\n', cameras=("main",))
    text = path.read_text() + '\n[[entities]]\nname = "top"\n[entities.components.Camera]\n'
    path.write_text(text)
    [warning] = validate_file(path, registry).warnings
    assert "no camera entity named 'top'" in warning.message


def test_a_reload_that_adds_a_warning_shows_it_in_the_status_and_the_hud(tmp_path):
    from engine.app import App
    from engine.reload import HotReloader, ReloadStatus
    from engine.render.frontend import create_headless_context
    from engine.render.passes import HudFeature
    from engine.render.renderer import Renderer

    path = _scene(tmp_path, 'particle_count = 100\ndrag_camera = "top"\n')
    app = App(path)
    reloader = HotReloader(app)
    status = app.world.resource(ReloadStatus)
    assert status.warnings == []
    path.write_text(path.read_text().replace('drag_camera = "top"', 'drag_camera = "topp"'))
    assert reloader.poll() and status.errors == []
    assert len(status.warnings) == 1 and "no camera entity named 'topp'" in status.warnings[0]
    renderer = Renderer(app, create_headless_context(), 64, 48)
    try:
        hud = next(f for f in renderer.features if isinstance(f, HudFeature))
        [item] = [i for i in hud.extract(app.world) if i[0] == "bottom_left"]
        assert item[1][0].startswith("config warning") and "topp" in item[1][1]
    finally:
        renderer.release()
