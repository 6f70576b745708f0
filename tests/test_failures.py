"""Distinct failures end to end: classes stored per run, ``sitgen failures``, ``rank
--distinct``/``--class``, the campaign summary, explainable splits, and old stores upgraded."""

from __future__ import annotations

import csv
import io
import json
import shutil
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sitgen
from sitgen import _core
from sitgen.store import SCHEMA_VERSION, Store
from sitgen.triage.avoidability import tier
from sitgen.triage.failures import (
    BROAD_RUNS,
    classes,
    distinct_failures,
    silhouette,
    split,
    ward_parts,
)
from sitgen.triage.robustness import is_robust

from .conftest import run_cli


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The paper's campaign, first 60 runs (seed 1): collisions, near misses and oscillation."""
    db = tmp_path_factory.mktemp("failures") / "paper.db"
    r = run_cli("campaign", "--n", "60", "--seed", "1", "--db", str(db))
    assert r.returncode == 0, r.stderr
    return db, r.stdout


def failures_json(db: Path) -> list[dict[str, Any]]:
    r = run_cli("failures", str(db), "--format", "json")
    assert r.returncode == 0, r.stderr
    rows: list[dict[str, Any]] = json.loads(r.stdout)
    return rows


def test_every_run_with_a_scored_failure_has_the_class_the_core_gives_its_log(
    campaign: tuple[Path, str],
) -> None:
    db, _ = campaign
    keys = {k for k, _ in classes()}
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT id, failure_class, failure, events_jsonl, score FROM runs"
        ).fetchall()
    assert len(rows) == 60
    classified = 0
    for run_id, key, failure, events, score in rows:
        expected = _core.classify_events(events, 0)
        assert (json.loads(failure) if failure else None) == (
            json.loads(expected) if expected else None
        ), run_id
        scored_failure = any(
            e["scored"] and e["kind"] not in ("waypoint_reached", "route_completed")
            for e in map(json.loads, events.splitlines())
        )
        assert (key is not None) == scored_failure, run_id
        if key is not None:
            classified += 1
            assert key in keys
            assert score > 0
    assert classified >= 10, "the paper's campaign fails often"


def test_failures_lists_each_distinct_failure_once_best_first(
    campaign: tuple[Path, str],
) -> None:
    db, _ = campaign
    rows = failures_json(db)
    assert rows, "a campaign of 60 runs has failures"
    for row in rows:
        assert {"key", "class", "description", "runs", "best_score", "representative"} <= set(row)
    # Best first, except that collisions no controller with this sensor could have escaped
    # come after the controller's own mistakes (docs/avoidability.md).
    order = [(tier(r["avoidability"]), -r["best_score"]) for r in rows]
    assert order == sorted(order)
    assert len({r["key"] for r in rows}) == len(rows)
    with Store(db) as store:
        scores = {r["run"]: (r["score"], r["failure_class"]) for r in store.ranked()}
        measured = store.robustness()
    assert measured, "the campaign measured its distinct failures' robustness"
    seen: set[int] = set()
    for row in rows:
        members = row["run_ids"]
        assert len(members) == row["runs"]
        assert not seen & set(members), "a run belongs to one distinct failure"
        seen |= set(members)
        assert all(scores[m][1] == row["class"] for m in members)
        best = max(members, key=lambda m: (scores[m][0], -m))
        robust = [m for m in members if m in measured and is_robust(**_counts(measured[m]))]
        # The highest-scoring robust run where one was measured, else the highest-scoring.
        expected = max(robust, key=lambda m: (scores[m][0], -m)) if robust else best
        assert row["representative"] == expected
        assert row["best_score"] == scores[best][0]
        if expected in measured:
            own = measured[expected]
            assert (row["recurs"], row["reruns"]) == (own["recurs"], own["reruns"])
            assert row["robustness"].endswith(f"{own['recurs']}/{own['reruns']}")
        else:
            assert row["robustness"] == "unmeasured" and row["robust"] is None
        assert row["share"] == pytest.approx(row["runs"] / 60)
    assert seen == {run for run, (_, key) in scores.items() if key is not None}
    assert failures_json(db) == rows, "deterministic"
    r = run_cli("failures", str(db), "--format", "csv")
    table = list(csv.DictReader(io.StringIO(r.stdout)))
    assert [t["key"] for t in table] == [row["key"] for row in rows]
    r = run_cli("failures", str(db))
    assert r.returncode == 0 and f"{len(rows)} distinct failures" in r.stdout


def _counts(measured: dict[str, Any]) -> dict[str, int]:
    return {"recurs": measured["recurs"], "reruns": measured["reruns"]}


def test_rank_distinct_puts_each_representative_first_then_the_rest(
    campaign: tuple[Path, str],
) -> None:
    db, _ = campaign
    distinct = failures_json(db)
    r = run_cli("rank", str(db), "--distinct", "--top", "1000", "--format", "json")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert len(rows) == 60
    head = rows[: len(distinct)]
    assert [h["run"] for h in head] == [d["representative"] for d in distinct]
    assert [h["distinct"] for h in head] == [d["key"] for d in distinct]
    rest = rows[len(distinct) :]
    assert [x["score"] for x in rest] == sorted((x["score"] for x in rest), reverse=True)
    assert [x["rank"] for x in rows] == list(range(1, 61))


def test_rank_by_class_and_bad_filters(campaign: tuple[Path, str]) -> None:
    db, _ = campaign
    key = failures_json(db)[0]["class"]
    r = run_cli("rank", str(db), "--class", key, "--format", "json", "--top", "100")
    assert r.returncode == 0, r.stderr
    rows = json.loads(r.stdout)
    assert rows and all(x["failure_class"] == key for x in rows)
    r = run_cli("rank", str(db), "--class", "drove_into_the_moon")
    assert r.returncode == 2
    assert r.stderr.startswith("error: --class: unknown failure class 'drove_into_the_moon'")
    assert len(r.stderr.strip().splitlines()) == 1
    r = run_cli("failures", str(db.parent / "missing.db"))
    assert r.returncode == 2 and "no such campaign store" in r.stderr
    assert not (db.parent / "missing.db").exists()
    r = run_cli("failures", str(db), "--format", "xml")
    assert r.returncode == 2 and "--format" in r.stderr


def test_the_campaign_summary_counts_distinct_failures(campaign: tuple[Path, str]) -> None:
    db, out = campaign
    n = len(failures_json(db))
    assert f"{n} distinct failures" in out


def test_a_store_from_schema_1_is_upgraded_on_open_and_loses_nothing(
    campaign: tuple[Path, str], tmp_path: Path
) -> None:
    db, _ = campaign
    old = tmp_path / "old.db"
    shutil.copy(db, old)
    with sqlite3.connect(old) as c:
        c.execute("DROP INDEX runs_by_failure_class")
        c.execute("ALTER TABLE runs DROP COLUMN failure_class")
        c.execute("ALTER TABLE runs DROP COLUMN failure")
        for column in ("generation", "parents", "genes", "coverage"):
            c.execute(f"ALTER TABLE runs DROP COLUMN {column}")
        for table in ("fault_evaluation", "fault_kills", "shrinks", "search"):
            c.execute(f"DROP TABLE {table}")
        c.execute("UPDATE meta SET value = '1' WHERE key = 'schema_version'")
    before = sqlite3.connect(old).execute("SELECT id, events_jsonl, score FROM runs").fetchall()
    assert failures_json(old) == failures_json(db)
    with sqlite3.connect(old) as c:
        version = c.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        assert version == (str(SCHEMA_VERSION),)
        assert c.execute("SELECT id, events_jsonl, score FROM runs").fetchall() == before
    with sqlite3.connect(old) as c:
        c.execute("UPDATE meta SET value = '99' WHERE key = 'schema_version'")
    r = run_cli("failures", str(old))
    assert r.returncode == 1, "a store sitgen cannot use, as for every store error"
    assert len(r.stderr.strip().splitlines()) == 1
    assert "newer than this sitgen's" in r.stderr and "Traceback" not in r.stderr


def _runs(side: str, seconds: float, n: int, start: int) -> list[dict[str, Any]]:
    return [
        {
            "id": start + i,
            "score": 100.0 + i,
            "terrain": "caves",
            "bearing": side,
            "seconds": seconds + 0.01 * i,
            "agent_mean_speed_m_s": 0.0,
        }
        for i in range(n)
    ]


def test_a_broad_class_splits_where_words_tell_the_parts_apart() -> None:
    runs = _runs("rear", 500.0, 15, 0) + _runs("front", 3.0, 15, 100)
    parts = split(runs)
    assert len(parts) == 2
    (marks_a, a), (marks_b, b) = parts
    assert {r["bearing"] for r in a} == {"rear"} and {r["bearing"] for r in b} == {"front"}
    assert ("from the rear", "rear") in marks_a and ("lasting over 500 s", "long") in marks_a
    assert ("from the front", "front") in marks_b and ("lasting under 3.1 s", "short") in marks_b


def test_a_small_or_uniform_class_stays_whole() -> None:
    small = _runs("rear", 500.0, BROAD_RUNS // 2, 0) + _runs("front", 3.0, 2, 100)
    assert len(split(small)) == 1
    uniform = _runs("left", 10.0, 40, 0)
    assert len(split(uniform)) == 1


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(3, 60),
    dims=st.integers(1, 5),
    k=st.integers(2, 4),
    ties=st.booleans(),
    seed=st.integers(0, 2**32 - 1),
)
def test_silhouette_is_scikit_learn_s(n: int, dims: int, k: int, ties: bool, seed: int) -> None:
    """The split's silhouette, written out to spare a second's import, is scikit-learn's,
    also where points coincide (0/0 counts as 0 in both)."""
    from sklearn.metrics import silhouette_score

    rng = np.random.default_rng(seed)
    x = rng.integers(0, 3, (n, dims)).astype(float) if ties else rng.normal(size=(n, dims))
    labels = np.unique(rng.integers(0, k, n), return_inverse=True)[1]
    if not 2 <= labels.max() + 1 < n:
        return
    from scipy.spatial.distance import cdist

    assert silhouette(cdist(x, x), labels) == pytest.approx(silhouette_score(x, labels), abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(n=st.integers(5, 80), dims=st.integers(1, 6), seed=st.integers(0, 2**32 - 1))
def test_the_ward_cut_is_scikit_learn_s_where_no_merges_tie(n: int, dims: int, seed: int) -> None:
    """The split's Ward parts (SciPy's tree, cut) are the partition scikit-learn's
    AgglomerativeClustering gives (points in general position: no two merges cost the same)."""
    from sklearn.cluster import AgglomerativeClustering

    x = np.random.default_rng(seed).normal(size=(n, dims))
    parts = ward_parts(x, (2, 3, 4))
    assert sorted(parts) == [2, 3, 4]
    for k, ours in parts.items():
        theirs = AgglomerativeClustering(n_clusters=k, linkage="ward").fit_predict(x)
        pairs = set(zip(ours.tolist(), theirs.tolist(), strict=True))
        assert len(pairs) == k, "the same parts, numbered either way"


def test_the_class_of_a_run_reaches_python_runs() -> None:
    s = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=3)
    record = sitgen.run(s, time_limit=5)
    assert record.failure is not None, "a route not completed in 5 s is a failure"
    assert record.failure["class"] == "route_not_completed"
    assert record.failure["description"] == dict(classes())["route_not_completed"]


def test_distinct_failures_of_an_empty_store_are_none(tmp_path: Path) -> None:
    with Store(tmp_path / "empty.db", create=True) as store:
        assert distinct_failures(store) == []


def test_snd_turning_to_and_fro_beside_a_wall_is_an_oscillation() -> None:
    """Job 308 of the paper's campaign (seed 1, caves): SND turns left and right on the spot
    beside a wall from its first second, Player's driver faithfully locked up."""
    from sitgen.execution.jobs import build_job, parse_campaign

    job = build_job(parse_campaign(None), 1, 308)
    s = sitgen.generate_situation(job.situation, seed=job.seed)
    record = sitgen.run(s, spec={**job.run, "time_limit_s": 30}, seed=job.seed)
    assert record.controller == "snd_follow"
    oscillations = [e for e in record.events if e["kind"] == "oscillation" and e["robot"] == 0]
    assert len(oscillations) == 1, record.events_text
    o = oscillations[0]
    assert o["start_s"] < 3.0 and o["end_s"] > 25.0
    assert o["details"]["nearest"] == "wall"
    assert o["details"]["extent_m"] < 0.1
    assert o["details"]["reversals"] > 100
    assert record.failure is not None
    assert record.failure["class"] == "oscillated_beside_wall"


def test_a_planner_circling_a_waypoint_has_a_class_that_ranks_above_a_plain_timeout() -> None:
    """An agent that orbits its first waypoint at about a metre until the time limit fails as
    ``circled_waypoint``, with the orbit's radius and whole turns, and scores above a run
    that merely timed out; a run that never came near has no such event."""
    from tests.controllers.pycontrollers import Orbits

    spec = {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 0, "peers_max": 0}}
    situation = sitgen.generate_situation(spec, seed=1)
    circled = sitgen.run(situation, controller=Orbits(), time_limit=120)
    assert circled.outcome == "timeout" and circled.failure is not None
    assert circled.failure["class"] == "circled_waypoint", circled.failure
    features = circled.failure["features"]
    assert features["turns"] >= 2 and 0.8 < features["radius_m"] < 1.6, features
    assert "circling waypoint 1 at 1.2 m, 2 turns" in circled.events_text

    class Stays:
        def reset(self, info: dict[str, Any]) -> None:
            pass

        def act(self, obs: Any) -> tuple[float, float]:
            return 0.0, 0.0

    stopped = sitgen.run(situation, controller=Stays(), time_limit=120)
    assert stopped.failure is not None and stopped.failure["class"] != "circled_waypoint"
    assert not any(e["kind"] == "circling" for e in stopped.events)
    assert circled.score > stopped.score


def test_runs_that_behave_alike_are_one_failure_whatever_their_terrain() -> None:
    """A hundred timeouts on four terrains are one distinct failure, not four: terrain tells
    parts of a class apart only beside behaviour that differs."""
    from sitgen.triage.failures import BROAD_RUNS, split

    terrains = ("open_field", "rocky_desert", "caves", "urban")
    runs = [
        {"id": i, "score": 20.0, "terrain": terrains[i % 4], "seconds": 0.0, "start_s": 600.0}
        for i in range(max(BROAD_RUNS, 100))
    ]
    assert [marks for marks, _ in split(runs)] == [[]]
