"""Situation coverage: named cells from hand-built situations through the Python API, the
coverage of a store through the CLI against its JSON schema and its own invariants, the same
cells on a rerun and from a user controller, old stores, the coverage-guided search, and the
report's heat grid in a real browser."""

from __future__ import annotations

import base64
import json
import math
import sqlite3
import zlib
from pathlib import Path
from typing import Any

import jsonschema
import numpy as np
import pytest

import sitgen
from sitgen import _core
from sitgen.execution.jobs import parse_campaign
from sitgen.generation.genome import Genome
from sitgen.generation.guidance import GUIDE_EPSILON, guide_weights, guided_genes
from sitgen.generation.search import run_search
from sitgen.generation.search.plan import BATCH, INITIAL, SearchPlan
from sitgen.store import Store
from sitgen.triage.coverage import all_cells, dimensions, split, stored, summarise, total_cells
from tests.conftest import ROOT, open_page, run_cli
from tests.test_campaign import write_spec

SCHEMA = json.loads((ROOT / "schema" / "coverage-report.schema.json").read_text())

PEERS = """
n = 16
[situation.terrain]
preset = "open_field"
width_m = 20.0
height_m = 20.0
[situation.mission]
peers_min = 3
peers_max = 4
peer_mode = "crossing"
min_route_length_m = 10.0
[run]
time_limit_s = 60.0
[vary]
"situation.terrain.preset" = { choice = ["open_field", "rocky_desert", "urban"] }
"situation.mission.peer_at_end" = { choice = ["stop", "loop"] }
"""
"""A small campaign whose peers cross the agent's route: encounters in most runs."""


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("coverage")
    db = tmp / "c.db"
    done = run_cli("campaign", str(write_spec(tmp, PEERS)), "--db", str(db), "--seed", "2")
    assert done.returncode == 0, done.stderr
    return db


def coverage_json(db: Path) -> dict[str, Any]:
    done = run_cli("coverage", str(db), "--format", "json")
    assert done.returncode == 0, done.stderr
    out: dict[str, Any] = json.loads(done.stdout)
    return out


def head_on(lateral_m: float) -> sitgen.Situation:
    """The agent and a peer driving at each other on an empty 20 m map, ``lateral_m`` apart
    sideways, both with the `straight` controller."""
    spec = {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 1, "peers_max": 1}}
    data = json.loads(sitgen.generate_situation(spec, seed=1).to_json())
    empty = zlib.compress(bytes(200 * 200 // 8))
    data["map"].update(rows=200, cols=200, resolution_m=0.1, data=base64.b64encode(empty).decode())
    agent, peer = data["robots"][:2]
    agent.update(start={"x_m": 4.0, "y_m": 10.0, "heading_rad": 0.0}, waypoints=[[16.0, 10.0]])
    y = 10.0 + lateral_m
    peer.update(start={"x_m": 16.0, "y_m": y, "heading_rad": math.pi}, waypoints=[[4.0, y]])
    for r in (agent, peer):
        r["controller"] = {"name": "straight", "params": {}}
    return sitgen.Situation(json.dumps(data))


# --- cells from what happened


def test_a_head_on_pass_marks_head_on_cells_and_a_distant_one_marks_none() -> None:
    rec = sitgen.run(head_on(0.8), time_limit=30.0)
    assert rec.coverage is not None
    assert rec.coverage["encounters"] == 1
    assert "head_on/under_0.5m/open/fast" in rec.coverage["cells"]
    assert {split(c)[0] for c in rec.coverage["cells"]} == {"head_on"}
    # The same robots 5 m apart sideways never come within 2 m: nothing happened, nothing marked.
    far = sitgen.run(head_on(5.0), time_limit=30.0)
    assert far.coverage == {"cells": [], "encounters": 0, "failure_cell": None}


def test_the_space_is_the_product_of_its_dimensions() -> None:
    dims = dimensions()
    assert [d.name for d in dims] == ["interaction", "clearance", "context", "speed"]
    assert total_cells() == 560 == len(all_cells()) == len(set(all_cells()))
    assert all(len(split(c)) == 4 for c in all_cells())


# --- a store's coverage through the CLI


def test_the_json_matches_its_schema_and_its_own_counts(campaign: Path) -> None:
    report = coverage_json(campaign)
    jsonschema.validate(report, SCHEMA)
    assert report["total"] == total_cells()
    assert 0 < report["covered"] == len(report["cells"]) <= report["total"]
    assert report["ratio"] == pytest.approx(report["covered"] / report["total"])
    assert report["runs"] + report["runs_without_coverage"] == 16
    cells = {c["cell"] for c in report["cells"]}
    assert cells <= set(all_cells())
    for k, d in enumerate(report["dimensions"]):
        # Every covered cell has one value on each dimension.
        assert sum(v["covered"] for v in d["values"]) == report["covered"]
        for v in d["values"]:
            assert v["covered"] == sum(1 for c in cells if split(c)[k] == v["value"])
    for p in report["pairwise"]:
        assert p["covered"] == sum(1 for q in p["pairs"] if q["runs"]) <= p["total"]
    # Failures that began in a cell began in a covered one, and each is counted once.
    with sqlite3.connect(campaign) as c:
        failing = c.execute("SELECT count(*) FROM runs WHERE failure_class IS NOT NULL").fetchone()
    assert sum(f["runs"] for f in report["failures"]) == failing[0]
    for f in report["failures"]:
        assert set(f["cells"]) <= cells
        assert sum(f["cells"].values()) + f["outside"] == f["runs"]
    table = run_cli("coverage", str(campaign))
    assert table.returncode == 0, table.stderr
    assert f"{report['covered']} of 560 cells covered" in table.stdout


def test_a_rerun_and_the_python_api_mark_the_cells_the_store_holds(campaign: Path) -> None:
    with Store(campaign) as store:
        runs, _ = stored(store)
        row = store.db.execute(
            "SELECT s.situation, r.run_seed FROM runs r JOIN situations s ON s.id = r.id "
            "WHERE r.id = ?",
            (runs[0].id,),
        ).fetchone()
    situation = sitgen.Situation(row[0])
    rec = sitgen.run(situation, seed=row[1], time_limit=60.0)
    assert rec.coverage is not None
    assert tuple(rec.coverage["cells"]) == runs[0].cells
    assert rec.coverage["failure_cell"] == runs[0].failure_cell


def test_a_python_controllers_runs_store_their_coverage_and_failure(tmp_path: Path) -> None:
    cautious = ROOT / "examples" / "controllers" / "cautious.py"
    spec = PEERS.replace("n = 16", "n = 3") + (
        f'\n[run.controller]\nname = "python:{cautious}:Cautious"\n'
    )
    db = tmp_path / "py.db"
    done = run_cli("campaign", str(write_spec(tmp_path, spec)), "--db", str(db), cwd=ROOT)
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(db) as c:
        rows = c.execute("SELECT coverage, failure_class, events_jsonl FROM runs").fetchall()
    assert all(cov is not None for cov, _, _ in rows)
    for _, cls, events in rows:
        classified = _core.classify_events(events, 0)
        assert cls == (json.loads(classified)["class"] if classified else None)


def test_runs_stored_before_coverage_count_as_without_it(campaign: Path, tmp_path: Path) -> None:
    old = tmp_path / "old.db"
    old.write_bytes(campaign.read_bytes())
    with sqlite3.connect(old) as c:
        c.execute("ALTER TABLE runs DROP COLUMN coverage")
        c.execute("UPDATE meta SET value = '5' WHERE key = 'schema_version'")
    report = coverage_json(old)
    assert (report["runs"], report["runs_without_coverage"], report["covered"]) == (0, 16, 0)
    jsonschema.validate(report, SCHEMA)


def test_a_missing_store_and_a_bad_format_fail_in_one_line(tmp_path: Path) -> None:
    missing = run_cli("coverage", str(tmp_path / "none.db"))
    assert missing.returncode != 0 and len(missing.stderr.strip().splitlines()) == 1
    assert "none.db" in missing.stderr
    bad = run_cli("coverage", str(tmp_path / "none.db"), "--format", "xml")
    assert bad.returncode == 2 and "--format" in bad.stderr


# --- the coverage-guided search


def test_the_guide_favours_levels_whose_runs_reached_rare_cells() -> None:
    spec = parse_campaign(PEERS)
    # Level 2 of the terrain gene (urban) reached cells no other run did; levels 0 and 1 only
    # a cell every run reached.
    covered = [
        (Genome((0, 0), 1, 1, 1), ("head_on/under_2m/open/fast",)),
        (Genome((1, 0), 2, 2, 2), ("head_on/under_2m/open/fast",)),
        (
            Genome((2, 1), 3, 3, 3),
            ("head_on/under_2m/open/fast", "hidden/contact/blind_corner/slow"),
        ),
    ]
    terrain, at_end = guide_weights(spec, covered)
    assert terrain.sum() == pytest.approx(1.0) and at_end.sum() == pytest.approx(1.0)
    assert terrain[2] > terrain[0] == pytest.approx(terrain[1])
    assert at_end[1] > at_end[0]
    assert terrain.min() >= GUIDE_EPSILON / 3
    draws = [guided_genes(spec, [terrain, at_end], np.random.default_rng(k))[0] for k in range(400)]
    assert draws.count(2) > draws.count(0)


def test_a_coverage_search_is_guided_after_generation_0_and_repeats_itself(
    tmp_path: Path,
) -> None:
    spec = parse_campaign(PEERS)
    budget = INITIAL + BATCH
    for name in ("a", "b"):
        db = tmp_path / f"{name}.db"
        run_search(spec, db, seed=4, budget=budget, plan=SearchPlan("coverage"))
    rows = []
    for name in ("a", "b"):
        with sqlite3.connect(tmp_path / f"{name}.db") as c:
            rows.append(c.execute("SELECT id, genes, coverage FROM runs ORDER BY id").fetchall())
    assert rows[0] == rows[1]
    operators = [json.loads(g)["operator"] for _, g, _ in rows[0]]
    assert operators == ["fresh"] * INITIAL + ["guided"] * BATCH
    with Store(tmp_path / "a.db") as store:
        runs, _ = stored(store)
    first = summarise([r for r in runs if r.id < INITIAL])
    assert 0 < first["covered"] <= summarise(runs)["covered"]
    bad = run_cli("search", "--strategy", "cover", "--db", str(tmp_path / "x.db"))
    assert bad.returncode == 2 and "--strategy" in bad.stderr and "coverage" in bad.stderr


# --- the report


def test_the_report_shows_coverage_as_a_heat_grid_with_failures_marked(
    campaign: Path, tmp_path: Path, browser: Any
) -> None:
    report = coverage_json(campaign)
    out = tmp_path / "report"
    assert run_cli("report", str(campaign), "-o", str(out)).returncode == 0
    page, errors = open_page(browser, out / "index.html")
    grid = page.locator("#coverage-grid")
    assert grid.get_attribute("data-covered") == str(report["covered"])
    assert page.locator("#coverage-grid td").count() == report["total"]
    covered = page.locator("#coverage-grid td.covered")
    assert covered.count() == report["covered"]
    marked = {
        covered.nth(k).get_attribute("data-cell")
        for k in range(covered.count())
        if "failed" in (covered.nth(k).get_attribute("class") or "")
    }
    assert marked == {c["cell"] for c in report["cells"] if c["failures"]}
    assert errors == []


def test_the_example_campaign_builds_jobs_in_every_terrain_and_peer_mode() -> None:
    from sitgen.execution.jobs import build_job

    text = (ROOT / "examples" / "campaigns" / "coverage.toml").read_text()
    spec = parse_campaign(text, "examples/campaigns/coverage.toml")
    jobs = [build_job(spec, 1, i) for i in range(40)]
    assert {j.situation["terrain"]["preset"] for j in jobs} == {
        "open_field",
        "rocky_desert",
        "caves",
        "urban",
    }
    assert {j.situation["mission"]["peer_mode"] for j in jobs} == {"random", "crossing"}
    speeds = [j.situation["mission"]["peer_controller"]["params"]["speed_m_s"] for j in jobs]
    assert all(0.2 <= s <= 0.8 for s in speeds)
