"""Generated artefacts stay current: JSON Schemas for editors and the component reference docs.

Regenerate with ``python -m engine schema --out configs/schema/`` and ``python -m engine docs``.
"""

import json
import re
import sys
from pathlib import Path

import jsonschema
import pytest

from engine.cli import schema_command
from engine.config import read_toml
from engine.docgen import component_page
from engine.registry import default_registry

ROOT = Path(__file__).resolve().parents[2]
REGISTRY = default_registry()
PRESETS = sorted((ROOT / "configs" / "effects").glob("*/*.toml"))


def test_committed_schemas_are_current(tmp_path):
    schema_command(tmp_path)
    for generated in sorted(tmp_path.glob("*.json")):
        committed = ROOT / "configs" / "schema" / generated.name
        assert committed.exists(), f"{committed} missing: run python -m engine schema --out configs/schema/"
        assert json.loads(committed.read_text()) == json.loads(generated.read_text()), (
            f"{committed.name} is out of date: run python -m engine schema --out configs/schema/")


@pytest.mark.parametrize("name", sorted(REGISTRY.components))
def test_reference_docs_are_current(name):
    page = ROOT / "docs" / "reference" / f"{name}.md"
    assert page.exists() and page.read_text() == component_page(name, REGISTRY), (
        f"{page} is out of date: run python -m engine docs")


@pytest.mark.parametrize("preset", PRESETS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_every_preset_names_its_schema_and_the_schema_accepts_it(preset):
    first = preset.read_text().splitlines()[0]
    match = re.match(r"#:schema\s+(\S+)", first)
    assert match, f"{preset} must start with a '#:schema' comment"
    schema_path = (preset.parent / match.group(1)).resolve()
    spec = REGISTRY.preset_component(preset.parent.name)
    assert spec is not None and schema_path.name == f"{spec.name}.schema.json"
    data, _ = read_toml(preset)
    jsonschema.validate(data, json.loads(schema_path.read_text()))


def test_schema_rejects_bad_configs():
    schema = json.loads((ROOT / "configs" / "schema" / "Terrain.schema.json").read_text())
    for bad in ({"size_exponent": 40}, {"rougness": 0.5}, {"spacing": "2"}):
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(bad, schema)
    jsonschema.validate({"size_exponent": 5, "spacing": 1.5}, schema)
