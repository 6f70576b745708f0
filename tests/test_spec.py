"""The situation spec: errors that name the field, presets, and the checked-in schema."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

import sitgen
from sitgen import _core

ROOT = Path(__file__).resolve().parent.parent

BAD_SPECS = [
    (
        {
            "terrain": {
                "filters": [
                    {"kind": "pixelise"},
                    {"kind": "invert"},
                    {"kind": "coverage", "target": 1.7},
                ]
            }
        },
        "terrain.filters[2].target: 1.7 is not in [0, 1]",
    ),
    ({"terrain": {"colour": "red"}}, "terrain.colour: unknown field `colour`"),
    ({"terrain": {"resolution_m": "fine"}}, "terrain.resolution_m: invalid type: string"),
    ({"terrain": {"preset": "moon"}}, "terrain.preset: unknown preset `moon`; expected one of"),
    ({"terrain": {"filters": [{"kind": "blur"}]}}, "terrain.filters[0].kind: unknown filter"),
    (
        {"terrain": {"source": {"kind": "perlin", "octaves": 0}}},
        "terrain.source.octaves: 0 is not in [1, 16]",
    ),
    ({"terrain": {"preset": "caves", "width_m": -3}}, "terrain.width_m: -3 is not in (0, 10000]"),
    ({"mision": {}}, "mision: unknown field `mision`"),
    (
        {"terrain": {"preset": "maze"}, "mission": {"peers_min": 4, "peers_max": 2}},
        "mission.peers_max: 2 is not in [4, 20]",
    ),
]


@pytest.mark.parametrize(("spec", "message"), BAD_SPECS)
def test_bad_specs_name_the_field(spec: dict[str, object], message: str) -> None:
    with pytest.raises(sitgen.SpecError) as info:
        sitgen.load_spec(spec)
    text = str(info.value)
    assert text.startswith(message), text
    assert "\n" not in text


def test_a_preset_with_overrides_resolves_to_the_full_spec() -> None:
    spec = sitgen.load_spec({"terrain": {"preset": "caves", "source": {"fill": 0.5}}})
    terrain = spec["terrain"]
    assert terrain["preset"] == "caves"
    assert terrain["source"]["kind"] == "caves"
    assert terrain["source"]["fill"] == 0.5
    assert terrain["source"]["smooth_passes"] == 4
    assert terrain["filters"][0]["kind"] == "coverage"


def test_the_checked_in_schema_is_the_generated_one_and_valid() -> None:
    checked_in = (ROOT / "schema" / "situation-spec.schema.json").read_text()
    assert checked_in == _core.spec_json_schema()
    schema = json.loads(checked_in)
    jsonschema.Draft202012Validator.check_schema(schema)


@pytest.mark.parametrize("name", sitgen.preset_names())
def test_resolved_presets_validate_against_the_schema(name: str) -> None:
    schema = json.loads((ROOT / "schema" / "situation-spec.schema.json").read_text())
    jsonschema.validate(sitgen.load_spec({"terrain": {"preset": name}}), schema)


def test_the_example_specs_are_valid() -> None:
    specs = sorted((ROOT / "examples" / "specs").glob("*.toml"))
    assert specs, "examples/specs has no spec"
    for path in specs:
        sitgen.load_spec(path)
