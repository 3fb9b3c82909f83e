"""ToonSmokeVolume config: presets and the showcase validate; mistakes give errors that name the key."""

import pytest

from engine.cli import validate_file
from engine.config import ConfigError
from engine.registry import default_registry
from tests.systems.toon_smoke.helpers import CONFIGS, PRESET_NAMES, PRESETS, make_app, scene_text


@pytest.fixture(scope="module")
def registry():
    return default_registry(["render", "toon_smoke"])


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_presets_validate(name, registry):
    path = PRESETS / f"{name}.toml"
    assert path.read_text(encoding="utf-8").startswith("#:schema ../../schema/ToonSmokeVolume.schema.json")
    validate_file(path, registry)


def test_showcase_scene_validates(registry):
    plan = validate_file(CONFIGS / "scenes" / "toon_smoke_showcase.toml", registry)
    assert any(c == "ToonSmokeVolume" for ent in plan.entities for c, _ in ent.components)


def _error(tmp_path, extra: str) -> str:
    with pytest.raises(ConfigError) as info:
        make_app(tmp_path, scene_text("paper", camera=False, extra=extra))
    return str(info.value)


def test_wrong_type_names_the_key(tmp_path):
    text = _error(tmp_path, 'particle_count = "many"')
    assert "ToonSmokeVolume.particle_count" in text and "integer" in text


def test_out_of_range_names_the_key(tmp_path):
    text = _error(tmp_path, "noise_strength = 1.5")
    assert "ToonSmokeVolume.noise_strength" in text and "1.5" in text


def test_unknown_key_suggests_the_near_miss(tmp_path):
    text = _error(tmp_path, "iso_densty = 0.4")
    assert "unknown key 'iso_densty'" in text and "did you mean 'iso_density'" in text


def test_grid_sizes_are_checked(tmp_path):
    assert "multiple of 8" in _error(tmp_path, "simulation_resolution = [30, 32, 32]")
    text = _error(tmp_path, "display_resolution = [64, 96, 64]")
    assert "display_resolution" in text and "integer factor" in text


def test_cells_must_be_cubic(tmp_path):
    text = _error(tmp_path, "extent = [4.0, 6.0, 4.0]")
    assert "cubic" in text and "extent" in text


def test_ramp_positions_must_match_colours(tmp_path):
    assert "ramp_positions" in _error(tmp_path, "ramp_positions = [0.0, 0.5]")
    assert "increase" in _error(tmp_path, "ramp_positions = [0.0, 0.4, 0.3]")


def test_nested_source_errors_name_the_source(tmp_path):
    extra = """[[entities.components.ToonSmokeVolume.sources]]
name = "a"
radius = -1.0
"""
    text = _error(tmp_path, extra)
    assert "sources[0].radius" in text


def test_blob_size_bounded_by_the_splat_stencil(tmp_path):
    text = _error(tmp_path, "blob_radius_max = 0.6\nblob_stretch_max = 3.0")
    assert "blob_radius_max" in text and "display cells" in text


def test_grids_whose_coarsest_multigrid_level_is_large_are_refused(tmp_path):
    """8 x 128 x 128 halves only to 2 x 32 x 32 (2048 cells): its dense coarsest inverse took 6.7 s to build and
    27 ms a V-cycle. 16 x 128 x 128 stops at 2 x 16 x 16 = 512 and is accepted."""
    from components.toon_smoke import ToonSmokeVolumeConfig, coarsest_shape

    assert coarsest_shape((8, 128, 128)) == (2, 32, 32) and coarsest_shape((16, 128, 128)) == (2, 16, 16)
    assert coarsest_shape((32, 32, 32)) == (4, 4, 4) and coarsest_shape((24, 48, 24)) == (3, 6, 3)
    text = _error(tmp_path, "simulation_resolution = [8, 128, 128]\ndisplay_resolution = [8, 128, 128]\n"
                            "extent = [0.5, 8.0, 8.0]\npressure_iterations = 20\ndiffusion_iterations = 1")
    assert "simulation_resolution" in text and "[2, 32, 32]" in text and "[16, 128, 128]" in text
    ToonSmokeVolumeConfig.model_validate({"simulation_resolution": [16, 128, 128], "display_resolution":
                                          [16, 128, 128], "extent": [1.0, 8.0, 8.0], "pressure_iterations": 20,
                                          "diffusion_iterations": 1})


def test_levels_the_density_never_reaches_are_refused(tmp_path):
    text = _error(tmp_path, "iso_density = 4.0\ndensity_limit = 4.0")
    assert "iso_density" in text and "density_limit" in text
    text = _error(tmp_path, "particle_density_threshold = 5.0\ndensity_limit = 4.0")
    assert "particle_density_threshold" in text and "blob" in text
