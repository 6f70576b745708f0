"""Shrinking: ddmin's contract, a hand-built failure whose irrelevant peers and obstacles go,
the minimal situation failing the same way on ``sitgen run``, determinism across worker
counts, a stored run's shrink in the store and the report, and the errors a user can meet."""

from __future__ import annotations

import json
import sqlite3
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import sitgen
from sitgen import _core
from sitgen.triage.candidate import ShrinkResult
from sitgen.triage.ddmin import ddmin
from sitgen.triage.shrink import shrink
from sitgen.world.situation import Situation
from tests.conftest import ROOT, run_cli
from tests.test_campaign import write_spec

# --- ddmin


@given(st.integers(1, 40), st.sets(st.integers(0, 39), max_size=6))
def test_ddmin_finds_exactly_the_items_a_failure_needs(n: int, needed: set[int]) -> None:
    """With a failure that needs a set of items (and any superset fails), ddmin returns that
    set, in order, and asks only about subsets of what it holds."""
    needed = {k for k in needed if k < n}
    asked: list[list[int]] = []

    def fails(subsets: list[list[int]]) -> list[bool]:
        asked.extend(subsets)
        return [needed <= set(s) for s in subsets]

    assert ddmin(list(range(n)), fails) == sorted(needed)
    assert all(set(s) <= set(range(n)) for s in asked)


def test_ddmin_keeps_a_pair_that_fails_only_together() -> None:
    def fails(subsets: list[list[str]]) -> list[bool]:
        return [{"b", "e"} <= set(s) for s in subsets]

    assert ddmin(list("abcdefgh"), fails) == ["b", "e"]


# --- a hand-built failure

CELLS = 200
RES = 0.1


def rect(occupied: np.ndarray, x: tuple[float, float], y: tuple[float, float]) -> None:
    """Occupy the cells inside [x0, x1) × [y0, y1) metres (row 0 at the top)."""
    c0, c1 = round(x[0] / RES), round(x[1] / RES)
    r0, r1 = CELLS - round(y[1] / RES), CELLS - round(y[0] / RES)
    occupied[r0:r1, c0:c1] = True


def robot(
    base: dict[str, Any], start: tuple[float, float, float], route: list[list[float]], name: str
) -> dict[str, Any]:
    return {
        **base,
        "start": {"x_m": start[0], "y_m": start[1], "heading_rad": start[2]},
        "waypoints": route,
        "controller": {"name": name, "params": {}},
        "at_end": "stop",
    }


@pytest.fixture(scope="module")
def head_on() -> Situation:
    """A 20 m square: a snd_follow agent driving east along a corridor 1.2 m wide (y 9.4–10.6
    m) and a peer driving west at it along the same line (the agent stops; the peer drives
    in), four peers shuttling in the open north of it, far from both, and a rock block in the
    far corner."""
    base = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)
    occupied = np.zeros((CELLS, CELLS), dtype=bool)
    rect(occupied, (5.0, 20.0), (9.1, 9.4))
    rect(occupied, (5.0, 20.0), (10.6, 10.9))
    rect(occupied, (1.0, 3.0), (1.0, 3.0))
    template = json.loads(base.to_json())["robots"][0]
    robots = [
        robot(template, (8.0, 10.0, 0.0), [[18.0, 10.0]], "snd_follow"),
        robot(template, (17.0, 10.0, np.pi), [[6.0, 10.0]], "straight"),
    ]
    robots += [
        robot(template, (3.0 + 4 * k, 15.0, 0.0), [[4.0 + 4 * k, 18.0]], "straight")
        for k in range(4)
    ]
    robots = [{**r, "id": i, "role": "agent" if i == 0 else "peer"} for i, r in enumerate(robots)]
    return Situation(_core.shrunk_situation(base.to_json(), occupied, RES, json.dumps(robots)))


RUN = {"time_limit_s": 60.0, "controller": {"name": "snd_follow", "params": {}}}


@pytest.fixture(scope="module")
def shrunk(head_on: Situation) -> ShrinkResult:
    return shrink(head_on, RUN, workers=2)


def test_the_hand_built_situation_fails_as_built(head_on: Situation) -> None:
    record = sitgen.run(head_on, spec=RUN)
    assert record.failure is not None
    assert record.failure["class"] in ("struck_while_stopped_seen", "collided_while_oscillating")


def test_of_five_peers_only_the_one_that_matters_is_kept(shrunk: ShrinkResult) -> None:
    assert shrunk.before.peers == 5 and shrunk.after.peers == 1
    peer = shrunk.minimal.robots[1]
    # The peer kept drives west along the corridor's line; the shuttling ones ran north.
    assert peer.waypoints[-1][1] == pytest.approx(peer.start.y_m, abs=0.2)
    assert abs(np.cos(peer.start.heading_rad) + 1) < 0.1
    assert "peers: 5 → 1" in shrunk.reductions


def test_obstacles_that_play_no_part_are_removed(shrunk: ShrinkResult) -> None:
    rock = 20 * 20
    assert shrunk.before.obstacle_cells == 2 * 150 * 3 + rock
    assert shrunk.after.obstacle_cells < shrunk.before.obstacle_cells - rock
    width, height = shrunk.after.map_m
    assert width * height < 20 * 20


def test_the_minimal_situation_fails_the_same_way_sooner(shrunk: ShrinkResult) -> None:
    record = sitgen.run(shrunk.minimal, spec=RUN)
    assert record.failure is not None and record.failure["class"] == shrunk.failure_class
    assert shrunk.after.time_to_failure_s < shrunk.before.time_to_failure_s
    assert shrunk.minimal.content_hash_matches()
    assert json.loads(shrunk.minimal.to_json())["provenance"]["shrunk_from"] == (
        shrunk.original.content_hash
    )
    assert shrunk.probes > 0 and not shrunk.exhausted


def test_the_same_input_shrinks_the_same_way_on_any_worker_count(
    head_on: Situation, shrunk: ShrinkResult
) -> None:
    one = shrink(head_on, RUN, workers=1)
    assert one.minimal.to_json() == shrunk.minimal.to_json()
    assert (one.probes, one.skipped, one.reductions) == (
        shrunk.probes,
        shrunk.skipped,
        shrunk.reductions,
    )


def test_a_budget_too_small_stops_with_what_it_has(head_on: Situation) -> None:
    small = shrink(head_on, RUN, workers=2, max_probes=3)
    assert small.exhausted and small.probes <= 3 + 2
    record = sitgen.run(small.minimal, spec=RUN)
    assert record.failure is not None and record.failure["class"] == small.failure_class


# --- the command


def test_sitgen_shrink_writes_a_minimal_situation_that_sitgen_run_fails_the_same_way(
    head_on: Situation, tmp_path: Path
) -> None:
    source = tmp_path / "head_on.json"
    head_on.save(source)
    out = tmp_path / "min" / "head_on.min.json"
    done = run_cli(
        "shrink", str(source), "--controller", "snd_follow", "--time-limit", "60",
        "-o", str(out), "--format", "json", "--workers", "1",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["before"]["peers"] == 5 and summary["after"]["peers"] == 1
    assert Path(summary["figure"]).stat().st_size > 0
    # The rerun command it prints reproduces the class.
    args = summary["rerun"].split()[1:]
    again = run_cli(*args, "--json")
    assert again.returncode == 0, again.stderr
    assert json.loads(again.stdout)["failure"]["class"] == summary["class"]
    table = run_cli("shrink", str(source), "-c", "snd_follow", "--time-limit", "60", "-o", str(out))
    assert table.returncode == 0, table.stderr
    assert "peers" in table.stdout and "rerun: sitgen run" in table.stdout


def test_a_run_without_a_failure_is_refused(tmp_path: Path) -> None:
    quiet = sitgen.generate_situation(
        {"terrain": {"preset": "open_field"}, "mission": {"peers_max": 0}}, seed=2
    )
    record = sitgen.run(quiet, time_limit=600)
    assert record.failure is None, "the fixture must not fail"
    path = tmp_path / "quiet.json"
    quiet.save(path)
    done = run_cli("shrink", str(path))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"error: {path}: the run does not fail (it has no failure class): nothing to shrink"
    ]


def test_a_class_the_run_does_not_show_is_refused(head_on: Situation, tmp_path: Path) -> None:
    path = tmp_path / "head_on.json"
    head_on.save(path)
    done = run_cli("shrink", str(path), "--time-limit", "60", "--class", "drove_into_wall")
    assert done.returncode == 2
    assert "not drove_into_wall" in done.stderr and len(done.stderr.strip().splitlines()) == 1
    done = run_cli("shrink", str(path), "--class", "no_such_class")
    assert done.returncode == 2 and "--class: unknown failure class" in done.stderr


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("{not json", "not JSON"),
        ('{"format": "sitgen.situation/1", "map": 3}', "map"),
        ('{"terrain": {"preset": "caves"}}', "format"),
    ],
)
def test_a_corrupt_or_foreign_situation_file_gets_one_line(
    tmp_path: Path, text: str, says: str
) -> None:
    path = tmp_path / "bad.json"
    path.write_text(text)
    done = run_cli("shrink", str(path))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}") and says in lines[0]


FOLLOWER_CMD = f"cmd:{sys.executable} {ROOT / 'examples/ros2/follower_cmd.py'}"
"""The route follower of examples/ros2 as a program: it does not steer around the peer."""


def test_a_user_controllers_failure_shrinks_the_same_on_any_worker_count(
    head_on: Situation,
) -> None:
    run_spec = {"time_limit_s": 60.0, "controller": {"name": FOLLOWER_CMD, "params": {}}}
    two = shrink(head_on, run_spec, workers=2, max_probes=150)
    assert two.before.peers == 5 and two.after.peers == 1
    record = sitgen.run(two.minimal, spec=run_spec)
    assert record.failure is not None and record.failure["class"] == two.failure_class
    one = shrink(head_on, run_spec, workers=1, max_probes=150)
    assert one.minimal.to_json() == two.minimal.to_json()
    assert (one.probes, one.skipped) == (two.probes, two.skipped)


def test_bad_shrink_options_are_refused(head_on: Situation, tmp_path: Path) -> None:
    path = tmp_path / "head_on.json"
    head_on.save(path)
    done = run_cli("shrink", str(path), "--max-probes", "0")
    assert done.returncode == 2 and "--max-probes: 0 is not in [1, 1000000]" in done.stderr
    done = run_cli("shrink", str(path), "--workers", "100000")
    assert done.returncode == 2 and "--workers: 100000 is not in" in done.stderr


# --- a campaign's runs


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A small campaign whose top two distinct failures are shrunk at the end."""
    tmp = tmp_path_factory.mktemp("campaign")
    db = tmp / "c.db"
    done = run_cli(
        "campaign", str(write_spec(tmp)), "--n", "12", "--seed", "3", "--db", str(db),
        "--shrink-top", "2",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "shrunk" in done.stdout
    return db


def test_campaign_shrink_top_keeps_the_representatives_shrinks(campaign: Path) -> None:
    with sqlite3.connect(campaign) as db:
        rows = db.execute(
            "SELECT run_id, failure_class, situation, run_spec, run_seed, before, after "
            "FROM shrinks"
        ).fetchall()
        classes = dict(db.execute("SELECT id, failure_class FROM runs"))
    assert 1 <= len(rows) <= 2
    for run_id, failure_class, situation, run_spec, run_seed, before, after in rows:
        assert classes[run_id] == failure_class
        a, b = json.loads(before), json.loads(after)
        assert b["peers"] <= a["peers"] and b["obstacle_cells"] <= a["obstacle_cells"]
        assert b["time_to_failure_s"] <= a["time_to_failure_s"]
        record = sitgen.run(Situation(situation), spec=json.loads(run_spec), seed=run_seed)
        assert record.failure is not None and record.failure["class"] == failure_class
    # Run again, the campaign is complete and its shrinks are not redone.
    spec = campaign.parent / "campaign.toml"
    done = run_cli(
        "campaign", str(spec), "--n", "12", "--seed", "3", "--db", str(campaign),
        "--shrink-top", "2",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "already shrunk" in done.stdout


def test_sitgen_shrink_of_a_stored_run_and_its_report(campaign: Path, tmp_path: Path) -> None:
    with sqlite3.connect(campaign) as db:
        failing, clean = (
            db.execute("SELECT min(id) FROM runs WHERE failure_class IS NOT NULL").fetchone()[0],
            db.execute("SELECT min(id) FROM runs WHERE failure_class IS NULL").fetchone()[0],
        )
    done = run_cli("shrink", str(campaign), str(failing), "-o", str(tmp_path / "m.json"))
    assert done.returncode == 0, done.stderr
    with sqlite3.connect(campaign) as db:
        assert db.execute("SELECT 1 FROM shrinks WHERE run_id = ?", (failing,)).fetchone()
    if clean is not None:
        done = run_cli("shrink", str(campaign), str(clean))
        assert done.returncode == 2
        assert done.stderr.strip() == (
            f"error: run {clean}: the run does not fail (it has no failure class): nothing to "
            "shrink"
        )
    done = run_cli("shrink", str(campaign), "99999")
    assert done.returncode == 2 and "no run 99999" in done.stderr
    done = run_cli("shrink", str(campaign))
    assert done.returncode == 2 and "give the run to shrink" in done.stderr
    report = tmp_path / "report"
    done = run_cli("report", str(campaign), "-o", str(report))
    assert done.returncode == 0, done.stderr
    page = (report / f"run-{failing}.html").read_text()
    assert "id='minimal'" in page and f"run-{failing}-min.json" in page
    assert (report / f"run-{failing}-min.json").exists()
    assert (report / f"run-{failing}-min.png").stat().st_size > 0
    index = (report / "index.html").read_text()
    shrunk_cards = index.count("class='minimal'")
    with sqlite3.connect(campaign) as db:
        representatives_shrunk = db.execute("SELECT count(*) FROM shrinks").fetchone()[0]
    # The cards of shrunk representatives link their minimal repro (the stored run above may
    # or may not be a representative).
    assert 1 <= shrunk_cards <= representatives_shrunk
