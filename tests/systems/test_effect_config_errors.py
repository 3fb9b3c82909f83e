"""Out-of-range values in every effect component: a ConfigError with the file, the TOML key path, the value and
what was expected; and every numeric config field bounded (so no file can size memory or break stability)."""

from __future__ import annotations

import math
import re

import pytest
from pydantic import ValidationError

from engine.cli import main
from engine.config import ConfigError
from engine.registry import default_registry
from engine.scene import plan_scene

REGISTRY = default_registry()

# component, TOML lines of its table, key under the component ("" = a whole-table check), value, expectation
CASES = [
    ("EnergyWaveEmitter", "max_particles = 0", "max_particles", 0, "greater than or equal to 1"),
    ("EnergyWaveEmitter", "circular_probability = 1.5", "circular_probability", 1.5, "less than or equal to 1"),
    ("EnergyWaveEmitter", "splash_samples = 1000", "splash_samples", 1000, "less than or equal to 64"),
    ("EnergyWaveEmitter", "beam_speed = nan", "beam_speed", math.nan, "finite number"),
    ("GrassField", "grid_x = 100000", "grid_x", 100000, "less than or equal to 256"),
    ("GrassField", "grid_x = 256\ngrid_z = 256\nplants_per_cell = 256", "plants_per_cell", None, "exceeds 1048576"),
    ("GrassField", "length_of_interest = 0.000001", "length_of_interest", None, "dots per stem"),
    ("ToonSmokeVolume", "simulation_resolution = [12, 16, 16]", "simulation_resolution[0]", 12, "multiple of 8"),
    ("ToonSmokeVolume", "particle_count = 1000000", "particle_count", 1000000, "less than or equal to 100000"),
    ("ToonSmokeVolume", "display_resolution = [40, 40, 40]", "display_resolution", None, "integer factor 1..4"),
    ("WaterSurface", "resolution = [4096, 4]", "resolution[0]", 4096, "less than or equal to 2048"),
    ("WaterSurface", "damping = 2.0", "damping", 2.0, "less than or equal to 1"),
    ("WaterSurface", "wave_speed = 100.0", "wave_speed", None, "stability limit"),
    ("RigidBody", "mass = 0.0", "mass", 0.0, "greater than 0"),
    ("RigidBody", "velocity = [1e9, 0.0, 0.0]", "velocity[0]", 1e9, "less than or equal to 1000000"),
    ("RigidBody", 'shape = "box"\nhalf_extents = [0.0, 1.0, 1.0]', "half_extents[0]", 0.0,
     "greater than or equal to 0.001"),
    ("DustDevil", "particle_count = 10000000", "particle_count", 10000000, "less than or equal to 200000"),
    ("DustDevil", "grid_resolution = [2, 32, 32]", "grid_resolution[0]", 2, "greater than or equal to 4"),
    ("Terrain", "size_exponent = 40", "size_exponent", 40, "less than or equal to 10"),
    ("Terrain", "spacing = 0.0", "spacing", 0.0, "greater than 0"),
    ("Terrain", "colors = [[inf, 0.0, 0.0], [0.0, 0.0, 0.0]]", "colors[0][0]", math.inf, "finite number"),
    ("Camera", "fov = 500.0", "fov", 500.0, "less than or equal to 150"),
    ("Camera", "near = 0.0", "near", 0.0, "greater than or equal to 0.0001"),
    ("Mesh", "emissive = -1.0", "emissive", -1.0, "greater than or equal to 0"),
    ("Mesh", "color = [100.0, 0.0, 0.0]", "color[0]", 100.0, "less than or equal to 64"),
    ("Collider", "radius = -1.0", "radius", -1.0, "greater than 0"),
    ("Collider", "half_extents = [-1.0, 1.0, 1.0]", "half_extents[0]", -1.0, "greater than or equal to 0"),
    ("Collider", "normal = [0.0, 0.0, 0.0]", "normal", [0.0, 0.0, 0.0], "non-zero direction"),
    # joint budgets and sizes that passed validation and then crashed, hung or took gigabytes (a fuzzing review)
    ("EnergyWaveEmitter", "max_particles = 1000000\ntrail_textures = 64", "max_particles", None,
     "max_particles * max(trail_textures, splash_samples) = 64000000 sprites exceeds 2000000"),
    ("GrassField", "branch_count = 32\nbranch_segments = 24\nstem_sides = 32", "branch_count", None,
     "exceeds 20000 (about the triangles"),
    ("ToonSmokeVolume", "simulation_resolution = [64, 64, 64]\ndisplay_resolution = [256, 256, 256]\n"
                        "extent = [4.0, 4.0, 4.0]", "display_resolution", None, "more than 4194304"),
    ("ToonSmokeVolume", "simulation_resolution = [128, 128, 128]\ndisplay_resolution = [128, 128, 128]\n"
                        "pressure_iterations = 500", "simulation_resolution", None,
     "cell sweeps a tick exceeds 33554432"),
    ("ToonSmokeVolume", 'sources = [{ name = "s", radius = 1e-200 }]', "sources[0].radius", 1e-200,
     "greater than or equal to 0.01"),
    ("RigidBody", 'shape = "sphere"\nradius = 1e-300', "radius", 1e-300, "greater than or equal to 0.001"),
    ("RigidBody", 'shape = "box"\nhalf_extents = [1e-300, 1.0, 1.0]', "half_extents[0]", 1e-300,
     "greater than or equal to 0.001"),
    ("DustDevil", "particle_count = 200000\nsub_particles = 2\nrepeats = 20\npoint_size = 32.0", "point_size", None,
     "pixels a frame exceeds"),
    ("DustDevil", "particle_count = 200000\nsubsteps = 8\nprewarm_time = 60.0", "prewarm_time", None,
     "particle steps before the first frame exceeds 100000000"),
    # subnormal numbers pass gt=0 bounds and overflow their reciprocals (a fuzzing review: mass crashed a tick)
    ("RigidBody", "mass = 1e-320", "mass", 1e-320, "subnormal number"),
    ("EnergyWaveEmitter", "beam_speed = 5e-324", "beam_speed", 5e-324, "subnormal number"),
    ("ToonSmokeVolume", "noise_scale = 5e-324", "noise_scale", 5e-324, "subnormal number"),
    ("Terrain", "spacing = 1e-320", "spacing", 1e-320, "subnormal number"),
    ("Transform", "position = [0.0, -5e-324, 0.0]", "position", [0.0, -5e-324, 0.0], "subnormal number"),
]


def write_scene(tmp_path, cases):
    root = tmp_path / "configs"
    (root / "scenes").mkdir(parents=True, exist_ok=True)
    text = ""
    for i, (component, lines, *_rest) in enumerate(cases):
        text += f'[[entities]]\nname = "e{i}"\n[entities.components.{component}]\n{lines}\n'
    path = root / "scenes" / "s.toml"
    path.write_text(text)
    return path


def same(a, b) -> bool:
    return (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b)) or a == b


@pytest.mark.parametrize("component, lines, key, value, expected", CASES,
                         ids=[f"{c[0]}-{c[2] or 'table'}-{i}" for i, c in enumerate(CASES)])
def test_out_of_range_value_names_file_key_value_and_expectation(tmp_path, component, lines, key, value, expected):
    path = write_scene(tmp_path, [(component, lines)])
    with pytest.raises(ConfigError) as err:
        plan_scene(path, REGISTRY)
    (problem,) = err.value.problems
    table = f"entities[0].components.{component}"
    assert problem.file == str(path)
    assert problem.key == (f"{table}.{key}" if key else table)
    assert problem.line is not None and problem.line >= 3
    # a bound must be the bound: "less than or equal to 64" must not pass as the start of "... to 640"
    assert re.search(re.escape(expected) + r"(?![\d.]*\d)", problem.message), problem.message
    if value is not None:
        assert same(problem.value, value)
    else:  # a check across keys: reported at the first key it names that the table writes, on its line
        assert problem.value is None
        written = [x.split(" ")[0] for x in lines.split("\n")]
        assert problem.line == 4 + written.index(key), problem


def test_validate_reports_every_case_at_once_without_traceback(tmp_path, capsys):
    path = write_scene(tmp_path, CASES)
    assert main(["validate", str(path)]) == 1
    out = capsys.readouterr()
    assert "Traceback" not in out.err + out.out
    lines = [line for line in out.err.splitlines() if line.startswith(str(path))]
    assert len(lines) == len(CASES)


def _unbounded(schema: dict, defs: dict, path: str) -> list[str]:
    """Numeric leaves of a JSON schema without both a lower and an upper bound, and lists without maxItems."""
    if "$ref" in schema:
        return _unbounded(defs[schema["$ref"].split("/")[-1]], defs, path)
    found = []
    for sub in schema.get("anyOf", []) + schema.get("allOf", []):
        found += _unbounded(sub, defs, path)
    kind = schema.get("type")
    if kind in ("number", "integer"):
        low = "minimum" in schema or "exclusiveMinimum" in schema
        high = "maximum" in schema or "exclusiveMaximum" in schema
        if not (low and high):
            found.append(path)
    elif kind == "array":
        if "maxItems" not in schema:
            found.append(f"{path} (no maxItems)")
        found += _unbounded(schema.get("items", {}), defs, f"{path}[]")
    for name, sub in schema.get("properties", {}).items():
        found += _unbounded(sub, defs, f"{path}.{name}")
    return found


def test_every_numeric_config_field_is_bounded():
    models = {name: spec.model for name, spec in REGISTRY.components.items()}
    models |= {f"script:{name}": cls.Params for name, cls in REGISTRY.scripts.items()}
    unbounded = []
    for name, model in sorted(models.items()):
        schema = model.model_json_schema()
        unbounded += _unbounded(schema, schema.get("$defs", {}), name)
    assert unbounded == []


def _float_fields(model) -> list[str]:
    return [f for f, info in model.model_fields.items() if info.annotation in (float, float | None)]


@pytest.mark.parametrize("name", sorted(n for n, spec in REGISTRY.components.items() if _float_fields(spec.model)))
def test_no_float_field_accepts_nan_or_inf(name):
    """TOML has nan and inf literals; a float field that took one would poison the simulation silently."""
    model = REGISTRY.components[name].model
    for field in _float_fields(model):
        for bad in (math.nan, math.inf):
            with pytest.raises(ValidationError, match="finite number"):
                model.model_validate({field: bad})


def test_cross_key_problem_is_reported_beside_field_errors(tmp_path):
    """pydantic checks a model's keys together only once each key is valid; a modder still sees both kinds of
    problem in one pass, each at its own key and line."""
    path = write_scene(tmp_path, [("WaterSurface", "damping = 2.0\nwave_speed = 300.0")])
    with pytest.raises(ConfigError) as err:
        plan_scene(path, REGISTRY)
    table = "entities[0].components.WaterSurface"
    found = {(p.key, p.line) for p in err.value.problems}
    assert found == {(f"{table}.damping", 4), (f"{table}.wave_speed", 5)}, err.value
    assert "stability limit" in str(err.value)


def test_cross_key_problem_hidden_when_one_of_its_keys_is_invalid(tmp_path):
    """A joint check whose own keys have errors is not run on stand-in defaults: only the field error shows."""
    path = write_scene(tmp_path, [("ToonSmokeVolume", "simulation_resolution = [12, 16, 16]\n"
                                                      "display_resolution = [40, 40, 40]\nparticle_count = 1000000")])
    with pytest.raises(ConfigError) as err:
        plan_scene(path, REGISTRY)
    keys = sorted(p.key.rsplit(".", 1)[-1] for p in err.value.problems)
    assert keys == ["particle_count", "simulation_resolution[0]"], err.value


def test_cross_key_problem_of_a_preset_names_the_preset(tmp_path):
    """A joint check failing on a key the preset sets (and the scene does not override) points at the preset."""
    path = write_scene(tmp_path, [("WaterSurface", 'preset = "bad"\ndamping = 2.0')])
    preset = tmp_path / "configs" / "effects" / "water_surface" / "bad.toml"
    preset.parent.mkdir(parents=True)
    preset.write_text("resolution = [16, 16]\nspacing = 0.1\nwave_speed = 300.0\n")
    with pytest.raises(ConfigError) as err:
        plan_scene(path, REGISTRY)
    where = {(p.file, p.key, p.line) for p in err.value.problems}
    assert where == {(str(path), "entities[0].components.WaterSurface.damping", 5),
                     (str(preset), "wave_speed", 3)}, err.value
