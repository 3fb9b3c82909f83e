"""Config validation: presets, clear errors naming the key, the stability limit, RigidBody's own Collider."""

from __future__ import annotations

import pytest

from engine.app import App
from engine.cli import validate_file
from engine.config import ConfigError
from engine.registry import default_registry
from tests.systems.water_surface.helpers import CONFIGS, write_scene

PRESETS = sorted((CONFIGS / "effects" / "water_surface").glob("*.toml"))


@pytest.fixture(scope="module")
def registry():
    return default_registry()


def test_the_three_presets_exist():
    assert {p.stem for p in PRESETS} == {"paper_pool", "calm_pond", "choppy_lake"}


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.stem)
def test_presets_validate(path, registry):
    assert path.read_text().startswith("#:schema ../../schema/WaterSurface.schema.json")
    validate_file(path, registry)


def test_showcase_scene_validates(registry):
    plan = validate_file(CONFIGS / "scenes" / "water_surface_showcase.toml", registry)
    assert any(c == "WaterSurface" for ent in plan.entities for c, _ in ent.components)


def _error(tmp_path, water: str, bodies: str = "", extra: str = "") -> str:
    with pytest.raises(ConfigError) as info:
        App(write_scene(tmp_path, water, bodies, extra=extra), configs_root=CONFIGS)
    return str(info.value)


def test_wrong_type_names_the_key(tmp_path):
    text = _error(tmp_path, 'wave_speed = "fast"')
    assert "WaterSurface.wave_speed" in text and "valid number" in text


def test_out_of_range_names_the_key(tmp_path):
    text = _error(tmp_path, "damping = 1.5")
    assert "WaterSurface.damping" in text and "less than or equal to 1" in text


def test_unknown_key_suggests_the_near_miss(tmp_path):
    text = _error(tmp_path, "wave_sped = 2.0")
    assert "unknown key 'wave_sped'" in text and "did you mean 'wave_speed'" in text


def test_bad_wave_source_lists_the_choices(tmp_path):
    text = _error(tmp_path, 'wave_source = "outlines"')
    assert "WaterSurface.wave_source" in text and "did you mean 'outline'" in text


def test_unstable_at_the_scene_step_is_rejected_with_the_limit(tmp_path):
    # c·Δt/h = 30 · (1/60) / 0.4 = 1.25 > 1/√2
    text = _error(tmp_path, "wave_speed = 30.0\nspacing = 0.4")
    assert "WaterSurface" in text and "wave_speed" in text
    assert "1.2500" in text and "stability limit 1/√2 ≈ 0.7071" in text and "fixed_dt" in text


def test_unstable_because_of_a_coarse_scene_step(tmp_path):
    text = _error(tmp_path, "wave_speed = 5.0\nspacing = 0.4", extra="fixed_dt = 0.1")
    assert "c·Δt/h = 1.2500" in text and "0.7071" in text


def test_stable_at_the_limit_is_accepted(tmp_path):
    # c·Δt/h = 16.97 · (1/60) / 0.4 = 0.707 (just under 1/√2)
    app = App(write_scene(tmp_path, "wave_speed = 16.97\nspacing = 0.4"), configs_root=CONFIGS)
    assert any("WaterSurface" in record.components for record in app.records)


def test_unstable_at_every_step_fails_in_the_model(tmp_path):
    text = _error(tmp_path, "wave_speed = 1000.0\nspacing = 0.5")
    # inside a scene the model sees the scene's fixed_dt (validation context), so the message names it
    assert "WaterSurface" in text and "with the scene's fixed_dt" in text and "0.7071" in text


def test_extent_sets_the_spacing_and_must_agree(tmp_path):
    app = App(write_scene(tmp_path, "resolution = [11, 21]\nextent = [5.0, 10.0]"), configs_root=CONFIGS)
    from components.water_surface import WaterSurface

    cfg = app.world.query(WaterSurface)[0][1][0]
    assert cfg.spacing == pytest.approx(0.5) and cfg.size == pytest.approx((5.0, 10.0))
    text = _error(tmp_path, "resolution = [11, 11]\nextent = [5.0, 5.0]\nspacing = 0.4")
    assert "spacing 0.4 disagrees with extent" in text
    text = _error(tmp_path, "resolution = [11, 11]\nextent = [5.0, 8.0]")
    assert "must be square" in text


def test_rigid_body_refuses_a_second_collider(tmp_path):
    bodies = """
[[entities]]
name = "crate"
[entities.components.Transform]
position = [0.0, 1.0, 0.0]
[entities.components.Collider]
shape = "box"
[entities.components.RigidBody]
mass = 10.0
"""
    text = _error(tmp_path, "", bodies)
    assert "RigidBody" in text and "remove the [Collider] table" in text


def test_rigid_body_errors_name_the_key(tmp_path):
    bodies = """
[[entities]]
name = "crate"
[entities.components.Transform]
position = [0.0, 1.0, 0.0]
[entities.components.RigidBody]
mass = -1.0
shape = "boxes"
"""
    text = _error(tmp_path, "", bodies)
    assert "RigidBody.mass" in text and "RigidBody.shape" in text and "did you mean 'box'" in text
