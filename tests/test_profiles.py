"""Run profiles: the paper's setting is what docs/profiles.md says, field by field, and a
campaign under it runs through the CLI."""

from __future__ import annotations

import json
import re
import tomllib
from pathlib import Path
from typing import Any

import pytest

import sitgen
from sitgen import _core
from sitgen.store import Store
from tests.conftest import ROOT, run_cli


def resolved(spec: dict[str, Any]) -> dict[str, Any]:
    result: dict[str, Any] = json.loads(_core.check_run_spec(json.dumps(spec)))
    return result


def documented_fields() -> dict[str, str]:
    """The table of docs/profiles.md's `paper` section: field → value as written."""
    text = (ROOT / "docs" / "profiles.md").read_text()
    section = text.split("## `paper`, line by line")[1].split("\n## ")[0].split("\n### ")[0]
    rows = re.findall(r"^\| `([a-z_.]+)` \| ([^|]+) \|", section, re.MULTILINE)
    return {field: value.strip().strip("`") for field, value in rows}


def leaves(table: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, dict):
            out.update(leaves(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def test_the_paper_profile_is_what_the_docs_say_line_by_line() -> None:
    documented = documented_fields()
    profile = leaves(tomllib.loads(_core.profile_text("paper")))
    # Every field the profile sets is documented, and nothing else is.
    assert set(documented) == set(profile)
    spec = leaves(resolved({"profile": "paper"}))
    for field, written in documented.items():
        value = spec[field]
        if isinstance(value, str):
            assert value == written, field
        else:
            assert value == pytest.approx(float(written)), field
    # The profile's file gives a source for every line it sets.
    lines = _core.profile_text("paper").splitlines()
    for i, line in enumerate(lines):
        if "=" in line and not line.startswith("#"):
            assert lines[i - 1].startswith("#"), f"no source above {line!r}"


def test_the_default_profile_is_the_defaults() -> None:
    default = resolved({"profile": "default"})
    assert default.pop("profile") == "default"
    assert default == resolved({})


def test_a_spec_overrides_its_profile_and_a_bad_name_is_one_line() -> None:
    spec = resolved({"profile": "paper", "sim": {"laser": {"range_m": 8.0}}})
    assert spec["sim"]["laser"] == {**spec["sim"]["laser"], "range_m": 8.0, "beams": 180}
    with pytest.raises(sitgen.SpecError, match=r"^run\.profile: unknown profile `stage`"):
        resolved({"profile": "stage"})


def test_the_paper_campaign_runs_under_the_profile_through_the_cli(tmp_path: Path) -> None:
    listed = run_cli("profiles")
    assert listed.returncode == 0, listed.stderr
    assert [line.split()[0] for line in listed.stdout.splitlines()] == ["default", "paper"]
    shown = run_cli("profiles", "paper")
    assert shown.stdout == _core.profile_text("paper")
    db = tmp_path / "paper.db"
    done = run_cli(
        "campaign", str(ROOT / "examples" / "campaigns" / "paper.toml"), "-n", "4", "--db", str(db)
    )
    assert done.returncode == 0, done.stderr
    with Store(db) as store:
        specs = [json.loads(r[0]) for r in store.db.execute("SELECT run_spec FROM runs")]
    assert len(specs) == 4
    for spec in specs:
        # What is stored is the spec as resolved: the profile's fields, written out.
        assert spec["profile"] == "paper"
        assert spec["controller"]["control_period_s"] == 0.5
        assert spec["controller"]["params"]["robot_radius"] == 0.25
        assert spec["sim"]["laser"]["beams"] == 180
