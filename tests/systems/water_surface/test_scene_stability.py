"""The scene's fixed_dt reaches the WaterSurface validator, so `engine validate` catches an unstable pond."""

import pytest

from engine.config import ConfigError
from engine.registry import default_registry
from engine.scene import plan_scene


def test_validate_uses_the_scenes_fixed_dt(tmp_path):
    root = tmp_path / "configs" / "scenes"
    root.mkdir(parents=True)
    scene = root / "s.toml"
    scene.write_text("[scene]\nfixed_dt = 0.05\n[[entities]]\n[entities.components.Transform]\n"
                     "[entities.components.WaterSurface]\nresolution = [16, 16]\nspacing = 0.5\nwave_speed = 9.0\n")
    with pytest.raises(ConfigError) as err:
        plan_scene(scene, default_registry())
    (p,) = err.value.problems
    assert "1/√2" in p.message or "0.7071" in p.message
    scene.write_text(scene.read_text().replace("fixed_dt = 0.05", "fixed_dt = 0.01"))
    plan_scene(scene, default_registry())  # c·Δt/h = 0.18: stable
