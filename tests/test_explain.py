"""Situation descriptors, recomputed from a situation file by what docs/explain.md says, and
`sitgen explain` end to end: rules with supports and exact intervals, a cross-validated
balanced accuracy, and one-line errors."""

from __future__ import annotations

import itertools
import json
import math
import sqlite3
from pathlib import Path

import numpy as np
import pytest

import sitgen
from sitgen.generation.region import check_where, holds
from sitgen.store import Store
from sitgen.triage.descriptors import describe
from sitgen.triage.recall import resimulate, stored_run
from sitgen.triage.stats import exact_interval
from tests.conftest import ROOT, run_cli


def test_descriptors_recompute_from_the_situation_file_as_the_docs_define_them() -> None:
    s = sitgen.generate_situation(
        {"terrain": {"preset": "rocky_desert"}, "mission": {"peers_min": 3, "peers_max": 3}},
        seed=4,
    )
    data = json.loads(s.to_json())
    agent, peers = data["robots"][0], data["robots"][1:]
    route = [(agent["start"]["x_m"], agent["start"]["y_m"]), *map(tuple, agent["waypoints"])]
    d = describe(s)
    legs = list(itertools.pairwise(route))
    assert d["route_length_m"] == pytest.approx(sum(math.dist(a, b) for a, b in legs))
    assert d["peers"] == len(peers)
    occupied = np.asarray(s.grid.occupied, dtype=bool)
    assert d["obstacle_share"] == pytest.approx(occupied.mean())
    # route_clearance_m: brute force over occupied cell centres at each sample.
    res, rows = s.grid.resolution, occupied.shape[0]
    r, c = np.nonzero(occupied)
    centres = np.stack([(c + 0.5) * res, (rows - 1 - r + 0.5) * res], axis=1)
    least = math.inf
    for a, b in legs:
        k = max(1, int(math.dist(a, b) / res))
        for t in np.linspace(0, 1, k + 1):
            x, y = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])
            cell = np.array([(int(x / res) + 0.5) * res, (int(y / res) + 0.5) * res])
            least = min(least, float(np.min(np.hypot(*(centres - cell).T))) - res / 2)
    assert d["route_clearance_m"] == pytest.approx(least, abs=1e-9)
    assert 0 <= d["crossing_angle_deg"] <= 180
    assert d["crossing_peers"] <= d["peers"]

    # nominal_closest_m: every robot walked along its route at its nominal speed, step by step.
    def at(route: list[tuple[float, float]], s: float, at_end: str) -> tuple[float, float, float]:
        total = sum(math.dist(a, b) for a, b in itertools.pairwise(route))
        if at_end == "loop" and s > total and len(route) > 2:
            # From the last waypoint to the first, and round again.
            cycle = [route[-1], *route[1:]]
            return at(cycle, (s - total) % sum(map(math.dist, cycle, cycle[1:])), "stop")
        if at_end == "reverse":
            s %= 2 * total
            s = 2 * total - s if s > total else s
        s = min(max(s, 0.0), total)
        for a, b in itertools.pairwise(route):
            leg = math.dist(a, b)
            if s <= leg or b == route[-1]:
                f = 0.0 if leg == 0 else min(s / leg, 1.0)
                heading = math.atan2(b[1] - a[1], b[0] - a[0])
                return a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), heading
            s -= leg
        raise AssertionError

    best = (math.inf, 0.0)
    steps = round(sum(math.dist(a, b) for a, b in legs) / 0.4 / 0.1)
    for k in range(steps + 1):
        ax, ay, heading = at(route, 0.4 * k * 0.1, "stop")
        for p in peers:
            speed = p["controller"].get("params", {}).get("speed_m_s", 0.5)
            peer_route = [(p["start"]["x_m"], p["start"]["y_m"]), *map(tuple, p["waypoints"])]
            px, py, _ = at(peer_route, speed * k * 0.1, p["at_end"])
            gap = math.dist((ax, ay), (px, py))
            if gap < best[0]:
                bearing = math.atan2(py - ay, px - ax) - heading
                best = (gap, abs(math.degrees(math.remainder(bearing, math.tau))))
    assert d["nominal_closest_m"] == pytest.approx(best[0], abs=1e-9)
    assert d["nominal_closest_bearing_deg"] == pytest.approx(best[1], abs=1e-6)


def test_explain_gives_rules_with_supports_and_exact_intervals(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    spec = str(ROOT / "examples" / "campaigns" / "paper120.toml")
    assert run_cli("campaign", spec, "--n", "120", "--db", str(db), "--reruns", "0").returncode == 0
    done = run_cli("explain", str(db), "--class", "collision", "--format", "json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["runs"] == 120 and 0 < result["failed"] < 120
    assert 0.0 <= result["balanced_accuracy"] <= 1.0
    assert len(result["balanced_accuracy_folds"]) == 5
    assert result["rules"], "a rule where failures are commoner"
    for rule in result["rules"]:
        assert 0 < rule["failed"] <= rule["runs"]
        assert tuple(rule["interval"]) == pytest.approx(
            exact_interval(rule["failed"], rule["runs"])
        )
        assert rule["rate"] > rule["elsewhere"]
    text = run_cli("explain", str(db), "--class", "collision").stdout
    assert "cross-validated balanced accuracy" in text and " runs fail, " in text
    done = run_cli("explain", str(db))
    assert done.returncode == 2 and "give one of --class, --outcome, --requirement" in done.stderr
    done = run_cli("explain", str(db), "--class", "no_such_class")
    assert done.returncode == 2 and "too few of one kind" in done.stderr


def test_where_generates_only_situations_in_the_region(tmp_path: Path) -> None:
    spec = str(ROOT / "examples" / "campaigns" / "paper120.toml")
    db = tmp_path / "w.db"
    where = "crossing_peers >= 1 and route_length_m < 40"
    done = run_cli("campaign", spec, "--n", "12", "--db", str(db), "--reruns", "0",
                   "--where", where)  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "situations generated to keep 12" in done.stdout
    tree = check_where(where)
    with sqlite3.connect(db) as c:
        kept = [s for (s,) in c.execute("SELECT situation FROM situations ORDER BY id")]
    assert len(kept) == 12
    assert all(holds(tree, describe(sitgen.Situation(s, check_start=False))) for s in kept)
    for bad, said in (
        ("nope > 1", "--where: unknown descriptor 'nope'"),
        ("peers > 100", "a region rarer than 1 in 200"),
        ("__import__('os')", "--where: Call is not allowed"),
    ):
        done = run_cli("campaign", spec, "--n", "2", "--db", str(tmp_path / "x.db"),
                       "--where", bad)  # fmt: skip
        assert done.returncode == 2 and said in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1


def test_confirm_tests_each_rule_on_fresh_situations(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    spec = str(ROOT / "examples" / "campaigns" / "paper120.toml")
    assert run_cli("campaign", spec, "--n", "120", "--db", str(db), "--reruns", "0").returncode == 0
    done = run_cli(
        "explain", str(db), "--class", "collision", "--confirm", "10",
        "--confirm-dir", str(tmp_path / "confirm"), "--format", "json",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert len(result["confirmed"]) == min(3, len(result["rules"]))
    for c, rule in zip(result["confirmed"], result["rules"], strict=False):
        assert c["inside"]["runs"] == 10 and c["outside"]["runs"] == 10
        low, high = rule["interval"]
        assert c["confirmed"] == (low <= c["inside"]["rate"] <= high)
        assert c["separates"] == (c["p_value"] < 0.05)


def test_export_writes_every_runs_descriptors(tmp_path: Path) -> None:
    pq = pytest.importorskip("pyarrow.parquet", reason="pyarrow is in the test extra")
    db = tmp_path / "c.db"
    spec = str(ROOT / "examples" / "campaigns" / "paper120.toml")
    assert run_cli("campaign", spec, "--n", "6", "--db", str(db), "--reruns", "0").returncode == 0
    out = tmp_path / "tables"
    assert run_cli("export", str(db), "-o", str(out), "--format", "parquet").returncode == 0
    table = pq.read_table(out / "descriptors.parquet").to_pylist()
    assert [r["run_id"] for r in table] == list(range(6))
    with sqlite3.connect(db) as c:
        first = c.execute("SELECT situation FROM situations WHERE id = 0").fetchone()[0]
    if first is not None:
        again = describe(sitgen.Situation(first, check_start=False))
        assert table[0]["route_length_m"] == pytest.approx(again["route_length_m"])
    # Run descriptors: every failing run, made again, reduced from its signals as the docs say.
    measured = pq.read_table(out / "run_descriptors.parquet").to_pylist()
    with Store(db) as store:
        failing = [
            i for (i,) in store.db.execute(
                "SELECT id FROM runs WHERE failure_class IS NOT NULL ORDER BY id"
            )
        ]  # fmt: skip
        assert [r["run_id"] for r in measured] == failing
        for r in measured[:2]:
            _, record = resimulate(stored_run(store, r["run_id"]), signals=True)
            gap = np.asarray(record.signals["peer_clearance"])
            speed = np.abs(np.asarray(record.signals["speed"]))
            k = int(np.argmin(gap))
            assert r["closest_approach_m"] == pytest.approx(float(gap[k]))
            assert r["closest_approach_s"] == pytest.approx(0.1 * k)
            assert r["speed_at_closest_m_s"] == pytest.approx(float(speed[k]))
            seen = np.flatnonzero(np.asarray(record.signals["peer_seen"]) > 0)
            if len(seen):
                assert r["first_sight_s"] == pytest.approx(0.1 * seen[0])
                assert r["speed_at_first_sight_m_s"] == pytest.approx(float(speed[seen[0]]))
            else:
                assert r["first_sight_s"] == 1000.0
