"""EnergyWaveEmitter config: the paper's defaults (table 4.2), the shipped presets, and readable errors."""

from pathlib import Path

import pytest

from components.energy_wave import PATTERN_PARAMETERS, EnergyWaveEmitter
from engine.cli import validate_file
from engine.config import ConfigError, read_toml, validate
from engine.registry import default_registry
from engine.scene import load_component

ROOT = Path(__file__).resolve().parents[3]
PRESETS = ROOT / "configs" / "effects" / "energy_wave"
SCENE = ROOT / "configs" / "scenes" / "energy_wave_showcase.toml"
PRESET_FILES = sorted(PRESETS.glob("*.toml"))


def test_defaults_are_table_4_2():
    cfg = EnergyWaveEmitter()
    table = {"circular_probability": 1.0, "continuity_probability": 0.3, "splash_samples": 12,
             "splash_roundness": 0.5, "lifetime_frames": 40.0, "acceleration_continuous": 1.5,
             "acceleration_continuous_spread": 0.5, "acceleration_separated": 2.5,
             "acceleration_separated_spread": 1.0, "repulsion": 4.0, "spring": 1.0, "damper": 0.8,
             "bar_spacing": 0.4}
    assert {k: getattr(cfg, k) for k in table} == table
    reference = validate(EnergyWaveEmitter, read_toml(PRESETS / "reference.toml")[0], "reference.toml")
    assert reference == cfg


def test_every_field_names_its_meaning():
    for name, info in EnergyWaveEmitter.model_fields.items():
        assert info.description and len(info.description) > 15, name
    symbols = {"circular_probability": "α", "continuity_probability": "β", "splash_samples": "N",
               "splash_roundness": "t", "lifetime_frames": "τ", "acceleration_separated": "c", "repulsion": "r",
               "spring": "k", "damper": "h", "bar_spacing": "u", "trail_textures": "M"}
    for name, symbol in symbols.items():
        assert EnergyWaveEmitter.model_fields[name].description.startswith(symbol), name


@pytest.mark.parametrize("path", PRESET_FILES, ids=lambda p: p.name)
def test_preset_validates(path):
    assert path.read_text(encoding="utf-8").startswith("#:schema ../../schema/EnergyWaveEmitter.schema.json")
    validate_file(path, default_registry())


def test_the_presets_the_issue_lists_exist():
    names = {p.stem for p in PRESET_FILES}
    wanted = {"reference", *(f"pattern_{p.lower()}" for p in "ABCDEFGH"), "fig_4_2_alpha_0_5", "fig_4_2_alpha_0_0",
              "fig_4_3_beta_1_0", "fig_4_3_beta_0_0", "fig_4_4_n_1", "fig_4_4_n_24", "fig_4_5_t_1_0",
              "fig_4_5_t_0_1", "fig_4_8_animated"}
    assert wanted <= names


def _preset(name):
    return validate(EnergyWaveEmitter, read_toml(PRESETS / f"{name}.toml")[0], name)


def test_figure_presets_change_one_parameter():
    assert _preset("fig_4_2_alpha_0_5").circular_probability == 0.5
    alpha0 = _preset("fig_4_2_alpha_0_0")
    assert alpha0.circular_probability == 0.0 and len(alpha0.control_points) == 4
    assert _preset("fig_4_3_beta_1_0").continuity_probability == 1.0
    assert _preset("fig_4_3_beta_0_0").continuity_probability == 0.0
    assert _preset("fig_4_4_n_1").splash_samples == 1
    assert _preset("fig_4_4_n_24").splash_samples == 24
    assert _preset("fig_4_5_t_1_0").splash_roundness == 1.0
    assert _preset("fig_4_5_t_0_1").splash_roundness == 0.1
    animated = _preset("fig_4_8_animated")
    assert animated.circular_probability == 0.0
    assert any(cp.keyframes and cp.loop for cp in animated.control_points)
    assert all(cp.spread > 0 and cp.noise_amplitude > 0 for cp in animated.control_points)


@pytest.mark.parametrize("pattern", list(PATTERN_PARAMETERS))
def test_pattern_presets_match_the_command_table(pattern):
    cfg = _preset(f"pattern_{pattern.lower()}")
    for key, value in PATTERN_PARAMETERS[pattern].items():
        assert getattr(cfg, key) == value


def test_showcase_scene_validates():
    plan = validate_file(SCENE, default_registry())
    assert any(c == "EnergyWaveEmitter" for ent in plan.entities for c, _ in ent.components)


def _errors(data):
    with pytest.raises(ConfigError) as info:
        validate(EnergyWaveEmitter, data, "emitter.toml")
    return info.value


def test_wrong_type_names_the_key():
    err = _errors({"splash_samples": "12"})
    assert err.problems[0].key == "splash_samples"
    assert "splash_samples" in str(err) and "emitter.toml" in str(err)
    assert _errors({"circular_probability": "1.0"}).problems[0].key == "circular_probability"


def test_out_of_range_names_the_key_and_bound():
    err = _errors({"continuity_probability": 1.5})
    assert err.problems[0].key == "continuity_probability"
    assert "1" in err.problems[0].message
    assert _errors({"max_particles": 10**9}).problems[0].key == "max_particles"
    assert _errors({"splash_samples": 0}).problems[0].key == "splash_samples"
    assert _errors({"splash_roundness": 0.0}).problems[0].key == "splash_roundness"
    assert _errors({"trail_textures": 65}).problems[0].key == "trail_textures"
    err = _errors({"control_points": [{"position": [0, 0, 1], "spread": -1.0}]})
    assert err.problems[0].key == "control_points[0].spread"


def test_unknown_key_suggests_the_near_miss():
    err = _errors({"circluar_probability": 0.5})
    assert err.problems[0].key == "circluar_probability"
    assert err.problems[0].suggestion == "circular_probability"
    assert "did you mean 'circular_probability'" in str(err)


def test_irregular_without_control_points_is_an_error():
    err = _errors({"circular_probability": 0.5, "control_points": []})
    assert "control point" in str(err)
    EnergyWaveEmitter.model_validate({"circular_probability": 1.0, "control_points": []})  # fine: no irregular


def test_keyframes_must_be_sorted():
    err = _errors({"control_points": [{"keyframes": [{"time": 1.0, "position": [0, 0, 1]},
                                                      {"time": 0.5, "position": [1, 0, 1]}]}]})
    assert "sorted" in str(err) and err.problems[0].key.startswith("control_points[0]")


def test_scene_override_on_a_preset_is_validated(tmp_path):
    registry = default_registry(["energy_wave"])
    cfg = load_component(registry, "EnergyWaveEmitter", {"preset": "energy_wave/pattern_c", "beam_speed": 9.0},
                         tmp_path / "scene.toml", "", ("entities", 0, "components", "EnergyWaveEmitter"),
                         ROOT / "configs")
    assert cfg.splash_samples == 1 and cfg.beam_speed == 9.0
    with pytest.raises(ConfigError) as info:
        load_component(registry, "EnergyWaveEmitter", {"preset": "energy_wave/pattern_c", "beam_speed": -1.0},
                       tmp_path / "scene.toml", "", ("entities", 0, "components", "EnergyWaveEmitter"),
                       ROOT / "configs")
    assert "beam_speed" in str(info.value)
