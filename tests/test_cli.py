"""The ``sitgen`` command, end to end, as a user runs it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml
from PIL import Image

import sitgen
from sitgen.world.config import preset_spec

from .conftest import ROOT, run_cli


def test_terrain_from_a_preset_writes_png_and_yaml(tmp_path: Path) -> None:
    out = tmp_path / "maps" / "caves.png"
    r = run_cli("terrain", "--preset", "caves", "--seed", "7", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "400 × 400 cells, 40 m × 40 m at 0.1 m/cell, coverage 0.4" in r.stdout
    meta = yaml.safe_load(out.with_suffix(".yaml").read_text())
    assert meta["image"] == "caves.png" and meta["resolution"] == 0.1
    pixels = np.asarray(Image.open(out))
    expected = sitgen.generate_terrain(preset_spec("caves"), seed=7)
    assert np.array_equal(pixels == 0, expected.occupied)


def test_terrain_from_a_spec_file_prints_json(tmp_path: Path) -> None:
    spec = ROOT / "examples" / "specs" / "paper_terrain.toml"
    out = tmp_path / "paper.pgm"
    r = run_cli("terrain", str(spec), "--seed", "3", "-o", str(out), "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["seed"] == 3
    assert [s["stage"] for s in summary["stages"]] == ["source", "pixelise", "coverage", "border"]
    target = summary["spec"]["terrain"]["filters"][1]["target"]
    assert abs(summary["coverage"] - target) <= 0.01
    assert out.read_bytes().startswith(b"P5")


def test_the_same_seed_writes_the_same_bytes(tmp_path: Path) -> None:
    for name in ("a", "b"):
        r = run_cli("terrain", "--preset", "urban", "-s", "9", "-o", str(tmp_path / f"{name}.png"))
        assert r.returncode == 0, r.stderr
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_a_bad_spec_exits_2_with_one_line_naming_the_field(tmp_path: Path) -> None:
    spec = tmp_path / "bad.toml"
    spec.write_text(
        '[[terrain.filters]]\nkind = "pixelise"\n[[terrain.filters]]\nkind = "invert"\n'
        '[[terrain.filters]]\nkind = "coverage"\ntarget = 1.7\n'
    )
    r = run_cli("terrain", str(spec), "-o", str(tmp_path / "x.png"))
    assert r.returncode == 2
    assert r.stderr == "error: terrain.filters[2].target: 1.7 is not in [0, 1]\n"
    assert not (tmp_path / "x.png").exists()


def test_usage_errors_exit_2_without_a_traceback(tmp_path: Path) -> None:
    cases = [
        ("terrain", "--preset", "moon"),
        ("terrain", str(tmp_path / "missing.toml")),
        ("terrain", "--preset", "maze", "-o", str(tmp_path / "map.jpg")),
        ("terrain", "--preset", "maze", "--seed", "-4"),
    ]
    for args in cases:
        r = run_cli(*args)
        assert r.returncode == 2, (args, r.stderr)
        assert "Traceback" not in r.stderr
    r = run_cli("terrain", "--preset", "moon")
    assert r.stderr.startswith("error: terrain.preset: unknown preset `moon`")


def test_demo_writes_every_preset_runs_the_campaign_and_reports(tmp_path: Path) -> None:
    r = run_cli("demo", "-o", str(tmp_path / "demo"), "--n", "30")
    assert r.returncode == 0, r.stderr
    for name in sitgen.preset_names():
        for suffix in (".png", ".yaml", ".json", "-situation.png"):
            assert (tmp_path / "demo" / f"{name}{suffix}").is_file(), f"{name}{suffix}"
        sitgen.Situation.load(tmp_path / "demo" / f"{name}.json")
    assert (tmp_path / "demo" / "paper.db").is_file()
    index = tmp_path / "demo" / "report" / "index.html"
    assert index.is_file()
    assert "distinct failures" in r.stdout
    assert r.stdout.rstrip().endswith(f"report: {index}")


def test_presets_and_schema_commands() -> None:
    r = run_cli("presets")
    assert r.returncode == 0
    assert [line.split()[0] for line in r.stdout.splitlines()] == sitgen.preset_names()
    r = run_cli("presets", "caves")
    assert 'kind = "caves"' in r.stdout
    r = run_cli("schema")
    assert json.loads(r.stdout)["title"] == "SituationSpec"


def test_generate_show_and_export_end_to_end(tmp_path: Path) -> None:
    situation = tmp_path / "s.json"
    r = run_cli("generate", "--preset", "urban", "--seed", "5", "-o", str(situation))
    assert r.returncode == 0, r.stderr
    assert "peers" in r.stdout and "sha256:" in r.stdout
    again = tmp_path / "again.json"
    run_cli("generate", "--preset", "urban", "--seed", "5", "-o", str(again))
    assert situation.read_bytes() == again.read_bytes()
    r = run_cli("show", str(situation), "-o", str(tmp_path / "fig.png"))
    assert r.returncode == 0, r.stderr
    assert Image.open(tmp_path / "fig.png").size[0] > 400
    r = run_cli("export", str(situation), "--format", "stage", "-o", str(tmp_path / "stage"))
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "stage" / "situation.world").is_file()
    r = run_cli("export", str(situation), "--format", "ros", "-o", str(tmp_path / "ros"))
    assert r.returncode == 0 and (tmp_path / "ros" / "map.yaml").is_file()


def test_bad_situation_files_and_formats_exit_2(tmp_path: Path) -> None:
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "sitgen.situation/1"}')
    r = run_cli("show", str(bad))
    assert r.returncode == 2
    assert r.stderr.startswith(f"error: {bad}: ") and "Traceback" not in r.stderr
    r = run_cli("generate", "--preset", "maze", "-o", str(tmp_path / "s.json"))
    r = run_cli("export", str(tmp_path / "s.json"), "--format", "gazebo")
    assert r.returncode == 2 and "stage, ros" in r.stderr
