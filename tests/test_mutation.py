"""Search by situation mutation: every operator makes a valid child that differs where it
should, the same draw makes the same child; the mutation strategy is the same on 1 and 2
workers, resumes after SIGKILL to the same runs, keeps its archive over failure class ×
variant for the report, and a directed search (--like, --class) varies the run it is given;
the yardstick counts every copy against the budget."""

from __future__ import annotations

import copy
import dataclasses
import json
import math
import signal
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sitgen
from sitgen import _core
from sitgen.execution.jobs import build_job
from sitgen.generation.genome import fresh
from sitgen.generation.mutation import OPERATORS, TARGETED, mutate, neighbours, target_of
from sitgen.generation.mutation.approach import (
    AGENT_M_S,
    APPROACHES,
    MEET_BACK_M,
    PEER_CLEAR_M,
    STAGED_MIN_M_S,
    START_S_MAX,
    Ground,
)
from sitgen.generation.mutation.local import SPEED_RANGE, apply_local
from sitgen.generation.mutation.mirror import as_made_by
from sitgen.generation.mutation.parent import (
    IN_RANGE_M,
    KEPT_PAST,
    Parent,
    Track,
    cut_past_failure,
    extended,
)
from sitgen.generation.mutation.places import focus_peer
from sitgen.generation.mutation.terrain import CONTEXTS, POINT_CLEAR_M
from sitgen.generation.search import run_search
from sitgen.generation.search.archive import Archive
from sitgen.generation.search.plan import BATCH, FRONTIER_FLOOR, INITIAL, LOCAL, SearchPlan
from sitgen.store import Store, unpack_json
from sitgen.triage.recall import stored_run
from sitgen.triage.robustness import copies, copy_class, copy_jobs
from sitgen.triage.variants import Screen, robust_variants, variant, variants_of
from tests.conftest import run_cli
from tests.test_campaign import start_command, wait_for_runs, write_spec
from tests.test_search import SEARCHED, spec_of, stored

BUDGET = INITIAL + 3 * BATCH


@pytest.fixture(scope="module")
def parent() -> Parent:
    """A rocky desert with peers, run once: its failure (or a route point) is the focus."""
    situation = sitgen.generate_situation(
        {"terrain": {"preset": "rocky_desert"}, "mission": {"peers_min": 4, "peers_max": 4}},
        seed=4,
    )
    record = sitgen.run(situation, time_limit=200.0)
    assert record.coverage is not None and record.coverage["failure_cell"] is not None
    parent = Parent.of(
        situation,
        record.coverage,
        record.failure,
        record.trajectory,
        record.time_s / record.steps,
    )
    assert parent.failure_pose is not None and parent.failure_s is not None
    assert parent.track is not None
    assert record.failure is not None
    assert parent.variant == variant(record.failure["class"], record.coverage)
    return parent


@pytest.mark.parametrize("operator", OPERATORS)
def test_every_operator_makes_a_valid_child_that_differs_where_it_should(
    parent: Parent, operator: str
) -> None:
    rng = np.random.default_rng(3)
    child = mutate(parent, operator, rng)
    assert child is not None
    assert _core.shrink_check(child, _core.shrink_leg_margin(parent.situation.to_json())) is None
    before, after = json.loads(parent.situation.to_json()), json.loads(child)
    assert after["provenance"]["mutated_from"] == before["provenance"]["content_hash"]
    same_map = np.array_equal(sitgen.Situation(child).grid.occupied, parent.situation.grid.occupied)
    robots_changed = [
        i for i, (a, b) in enumerate(zip(before["robots"], after["robots"], strict=True)) if a != b
    ]
    if operator in ("add_obstacle", "remove_obstacle", "move_obstacle", "reshape_terrain"):
        assert not same_map and not robots_changed
    elif operator == "reshape_and_approach":
        assert parent.failure_pose is not None
        assert not same_map
        assert robots_changed == [focus_peer(before["robots"], parent.failure_pose[:2])]
    elif operator == "mirror":
        width = parent.situation.grid.size_m[0]
        assert not same_map
        for a, b in zip(before["robots"], after["robots"], strict=True):
            assert b["start"]["x_m"] == pytest.approx(width - a["start"]["x_m"])
    else:
        assert same_map and len(robots_changed) == 1
        if operator in ("move_peer", "turn_peer", "retime_peer", "peer_speed", "approach_peer"):
            focus = parent.failure_pose[:2] if parent.failure_pose else None
            if focus is not None:
                assert robots_changed == [focus_peer(before["robots"], focus)]


def _staged_peer(parent: Parent, child: str) -> tuple[dict[str, Any], float, float]:
    """The child's focus peer, and the bearing of its start and its course seen from the agent
    at the parent's failure (radians, 0 ahead, positive to the left)."""
    assert parent.failure_pose is not None
    x, y, heading = parent.failure_pose
    peer = focus_peer(json.loads(parent.situation.to_json())["robots"], (x, y))
    assert peer is not None
    robot: dict[str, Any] = json.loads(child)["robots"][peer]
    start = robot["start"]
    bearing = math.remainder(math.atan2(start["y_m"] - y, start["x_m"] - x) - heading, math.tau)
    course = math.remainder(start["heading_rad"] - heading, math.tau)
    return robot, bearing, course


@pytest.mark.parametrize("target", APPROACHES)
def test_approach_peer_sends_the_peer_through_the_failure_in_the_interaction_asked(
    parent: Parent, target: str
) -> None:
    child = mutate(parent, "approach_peer", np.random.default_rng(5), target)
    assert child is not None
    assert parent.failure_pose is not None and parent.failure_s is not None
    x, y, heading = parent.failure_pose
    robot, bearing, course = _staged_peer(parent, child)
    side = {"head_on": 0, "crossing_left": 1, "crossing_right": -1, "from_behind": 2}
    if target in side and target != "from_behind":
        assert bearing == pytest.approx(side[target] * math.pi / 2, abs=0.6)
    if target == "from_behind":
        assert abs(bearing) > math.pi / 2 and abs(course) < 0.1
    if target == "head_on":
        assert abs(course) == pytest.approx(math.pi, abs=0.1)
    params = robot["controller"]["params"]
    if target == "stopped":
        assert params["start_s"] == START_S_MAX
    else:
        assert 0 <= params["start_s"] <= parent.failure_s
    if target != "overtaking":
        # Its leg passes where they meet: the failure's place or a point the agent drove
        # through on its way there, not ahead of it.
        (mx, my) = robot["waypoints"][0]
        assert math.hypot(mx - x, my - y) <= MEET_BACK_M + 1e-9
        assert (mx - x) * math.cos(heading) + (my - y) * math.sin(heading) <= 1e-9


def test_a_track_says_when_the_agent_came_where() -> None:
    # 0.2 m/s along x for 30 s, back to the start and out again.
    out = np.stack([np.linspace(0, 6, 301), np.zeros(301)], axis=1)
    track = Track(np.concatenate([out, out[::-1], out]), 0.1)
    assert track.arrival_s((2.0, 0.0)) == pytest.approx(8.5, abs=0.11)  # within 0.3 m
    assert track.arrival_s((2.0, 5.0)) == pytest.approx(10.0)  # nearest, never within reach
    # In range of (6, 1) from x = 6 - sqrt(3.5² - 1) on; the pass out and back ended by 70 s.
    assert track.in_range_s((6.0, 1.0), 30.0) == pytest.approx(13.3, abs=0.1)
    assert track.in_range_s((6.0, 1.0), 89.0) == pytest.approx(60.2 + 13.3, abs=0.1)
    assert track.in_range_s((6.0, 1.0), 40.0) == pytest.approx(13.3, abs=0.1)
    assert track.in_range_s((60.0, 0.0), 89.0) is None
    assert track.speed_m_s(20.0) == pytest.approx(0.2)


@pytest.mark.parametrize("target", ["head_on", "crossing_left", "crossing_right"])
def test_a_staged_peer_is_timed_by_where_the_parents_agent_was(parent: Parent, target: str) -> None:
    track = parent.track
    assert track is not None
    unbounded = 0
    for seed in range(6):
        child = mutate(parent, "approach_peer", np.random.default_rng(seed), target)
        assert child is not None
        robot, _, _ = _staged_peer(parent, child)
        params, start = robot["controller"]["params"], robot["start"]
        meeting = tuple(robot["waypoints"][0])
        leg_m = math.hypot(meeting[0] - start["x_m"], meeting[1] - start["y_m"])
        meet_s = track.arrival_s(meeting)
        seen_s = track.in_range_s((start["x_m"], start["y_m"]), meet_s)
        # It reaches the meeting when the agent did (or as soon as it can), having set off
        # before the agent came in range of where it waited, unless that would have it creep
        # slower than it reads as moving or drive faster than a peer does.
        arrives_s = params["start_s"] + leg_m / params["speed_m_s"]
        assert arrives_s == pytest.approx(meet_s, abs=0.01) or params["start_s"] == 0
        if STAGED_MIN_M_S < params["speed_m_s"] < SPEED_RANGE[1]:
            unbounded += 1
            assert seen_s is None or params["start_s"] <= seen_s
    # The departure rule was checked, not only the bounds that override it.
    assert unbounded > 0


def test_a_parent_without_a_track_is_timed_for_a_cruising_agent(parent: Parent) -> None:
    blind = dataclasses.replace(parent, track=None)
    assert parent.failure_s is not None
    child = mutate(blind, "approach_peer", np.random.default_rng(3), "head_on")
    assert child is not None
    robot, _, _ = _staged_peer(parent, child)
    params, start = robot["controller"]["params"], robot["start"]
    meeting = robot["waypoints"][0]
    leg_m = math.hypot(meeting[0] - start["x_m"], meeting[1] - start["y_m"])
    arrives_s = params["start_s"] + leg_m / params["speed_m_s"]
    assert arrives_s == pytest.approx(parent.failure_s, abs=0.01)
    assert parent.failure_s - params["start_s"] >= (leg_m + IN_RANGE_M) / AGENT_M_S


def test_a_peer_sent_head_on_meets_the_agent_head_on(parent: Parent) -> None:
    child = mutate(parent, "approach_peer", np.random.default_rng(5), "head_on")
    assert child is not None
    record = sitgen.run(sitgen.Situation(child), time_limit=200.0)
    assert record.coverage is not None
    assert any(cell.startswith("head_on/") for cell in record.coverage["cells"])


def test_reshape_terrain_makes_the_context_it_aims_at(parent: Parent) -> None:
    assert parent.failure_pose is not None
    made = {}
    for target in CONTEXTS:
        for seed in range(6):
            child = mutate(parent, "reshape_terrain", np.random.default_rng(seed), target)
            if child is not None:
                made[target] = child
                break
    assert "open" in made and len(made) >= 3, sorted(made)
    x, y, _ = parent.failure_pose
    before = parent.situation.grid.occupied
    resolution = parent.situation.grid.resolution
    agent_route = [
        tuple(w) for w in json.loads(parent.situation.to_json())["robots"][0]["waypoints"]
    ]
    for target, child in made.items():
        assert _core.agent_context(child, *parent.failure_pose) == target
        after = sitgen.Situation(child).grid.occupied
        rows, cols = np.nonzero(after != before)
        assert rows.size, target
        xs, ys = (cols + 0.5) * resolution, (before.shape[0] - rows - 0.5) * resolution
        # Only the walls round the failure are redrawn…
        assert np.hypot(xs - x, ys - y).max() <= 4.5, target
        # …and nothing new stands on the agent's route.
        added = after[rows, cols]
        for wx, wy in agent_route:
            near = np.hypot(xs[added] - wx, ys[added] - wy)
            assert near.size == 0 or near.min() >= POINT_CLEAR_M - resolution, target


def test_reshape_terrain_keeps_a_child_that_reads_as_another_context_it_may_make(
    parent: Parent,
) -> None:
    assert parent.failure_pose is not None
    own = parent.variant.split("/")[2] if parent.variant else None
    made = 0
    for target in CONTEXTS:
        accept = [c for c in CONTEXTS if c not in (target, own)][:2]
        for seed in range(4):
            child = mutate(parent, "reshape_terrain", np.random.default_rng(seed), target, accept)
            if child is not None:
                made += 1
                assert _core.agent_context(child, *parent.failure_pose) in (target, *accept)
    assert made >= len(CONTEXTS)


def test_reshape_and_approach_stages_the_interaction_in_the_context_it_aims_at(
    parent: Parent,
) -> None:
    assert parent.failure_pose is not None
    made = 0
    for target in ("crossing_left/open", "head_on/corridor", "stopped/blind_corner"):
        interaction, context = target.split("/")
        child = mutate(parent, "reshape_and_approach", np.random.default_rng(2), target)
        if child is None:
            continue
        made += 1
        assert _core.agent_context(child, *parent.failure_pose) == context
        robot, bearing, _ = _staged_peer(parent, child)
        if interaction == "crossing_left":
            assert bearing == pytest.approx(math.pi / 2, abs=0.6)
        elif interaction == "head_on":
            assert abs(bearing) < 0.6
        else:
            assert robot["controller"]["params"]["start_s"] == START_S_MAX
    assert made >= 2


def test_a_staged_meeting_moves_back_along_the_agents_way_until_the_peer_has_room() -> None:
    # 10 x 10 m at 0.1 m, a wall from x = 6 m: the agent failed at (5.8, 5) facing it.
    occupied = np.zeros((100, 100), dtype=bool)
    occupied[:, 60:] = True
    ground = Ground.of(occupied, 0.1)
    start, back = (5.8, 5.0), math.pi
    # From the left (the peer comes from +y and goes on to -y): the first point back from the
    # wall with ground clear for the peer.
    meeting = ground.meeting(start, back, MEET_BACK_M, math.pi / 2, 1.5, -math.pi / 2)
    assert meeting is not None
    (x, y), room = meeting
    assert y == pytest.approx(5.0) and 6.0 - x == pytest.approx(PEER_CLEAR_M, abs=0.1)
    assert room >= 1.5
    # Head-on (from the wall's side) there is no room anywhere within MEET_BACK_M of it.
    assert ground.meeting(start, back, MEET_BACK_M, 0.0, 1.5, math.pi) is None


def _without_peers(parent: Parent) -> Parent:
    """``parent`` with its peers taken out (its failure where it was)."""
    alone = json.loads(parent.situation.to_json())
    alone["robots"] = alone["robots"][:1]
    return Parent(
        sitgen.Situation(json.dumps(alone), check_start=False),
        parent.failure_pose,
        parent.variant,
        parent.failure_s,
    )


def test_approach_peer_brings_in_a_peer_where_the_situation_has_none(parent: Parent) -> None:
    lone = _without_peers(parent)
    child = mutate(lone, "approach_peer", np.random.default_rng(5), "crossing_left")
    assert child is not None
    margin = _core.shrink_leg_margin(lone.situation.to_json())
    assert _core.shrink_check(child, margin) is None
    robots = json.loads(child)["robots"]
    assert len(robots) == 2 and robots[1]["role"] == "peer" and robots[1]["id"] == 1
    assert robots[1]["body"] == robots[0]["body"]
    assert robots[1]["controller"]["name"] == "straight"
    record = sitgen.run(sitgen.Situation(child), time_limit=200.0)
    assert record.coverage is not None and record.coverage["encounters"] >= 1


def test_a_crowd_meets_the_agent_from_every_side_at_once(parent: Parent) -> None:
    alone = _without_peers(parent)
    assert parent.failure_pose is not None
    x, y, heading = parent.failure_pose
    for who in (parent, alone):
        for seed in range(4):
            rng = np.random.default_rng(seed)
            child = mutate(who, "approach_peer", rng, "crossing_left", crowd=1.0)
            assert child is not None
            original = who.situation.to_json()
            assert _core.shrink_check(child, _core.shrink_leg_margin(original)) is None
            before, robots = json.loads(original)["robots"], json.loads(child)["robots"]
            # Never more peers than the spec's peers_max (4 here): its own, or new ones.
            assert len(robots) - 1 <= 4
            sides = []
            for robot in robots[1:]:
                start = robot["start"]
                bearing = math.atan2(start["y_m"] - y, start["x_m"] - x) - heading
                course = math.remainder(start["heading_rad"] - heading, math.tau)
                meets = robot["waypoints"] and math.dist(robot["waypoints"][0], (x, y)) <= 1.5
                if not meets:
                    # A peer of the situation left where it was (its side had no room).
                    assert robot == before[robot["id"]]
                    continue
                ahead = abs(math.remainder(bearing, math.tau)) < math.pi / 4
                stopped = robot["controller"]["params"]["start_s"] == START_S_MAX
                sides.append("stopped" if stopped else "head_on" if ahead else round(course))
            # The staged peer and at least two more, each from its own side of the crowd.
            assert len(sides) >= 3 and len(set(sides)) == len(sides)
            assert set(sides) <= {"stopped", "head_on", -2, 2}


def test_an_extended_child_goes_on_past_its_goal(parent: Parent) -> None:
    child = mutate(parent, "add_obstacle", np.random.default_rng(2))
    assert child is not None
    longer = extended(child, np.random.default_rng(4))
    assert longer == extended(child, np.random.default_rng(4))
    assert _core.shrink_check(longer, _core.shrink_leg_margin(child)) is None
    before, after = json.loads(child)["robots"], json.loads(longer)["robots"]
    kept = len(before[0]["waypoints"])
    assert after[0]["waypoints"][:kept] == before[0]["waypoints"]
    assert len(after[0]["waypoints"]) > kept and after[1:] == before[1:]
    new = np.array([before[0]["waypoints"][-1], *after[0]["waypoints"][kept:]])
    length = float(np.linalg.norm(np.diff(new, axis=0), axis=1).sum())
    # The mission goes on at least as far again as the spec asks of a route (RDP cuts
    # corners, so a little less than the planned length is allowed).
    assert length >= 0.9 * parent.situation.spec["mission"]["min_route_length_m"]
    assert np.array_equal(
        sitgen.Situation(longer).grid.occupied, sitgen.Situation(child).grid.occupied
    )


def test_a_child_s_mission_ends_a_waypoint_past_where_its_parent_failed(parent: Parent) -> None:
    child = mutate(parent, "add_obstacle", np.random.default_rng(2))
    assert child is not None
    waypoints = json.loads(child)["robots"][0]["waypoints"]
    start = json.loads(child)["robots"][0]["start"]
    assert len(waypoints) >= 3
    # A failure that began on the second leg (from waypoint 0 to waypoint 1).
    a, b = np.array(waypoints[0]), np.array(waypoints[1])
    x, y = (a + b) / 2
    early = dataclasses.replace(parent, failure_pose=(float(x), float(y), 0.0))
    cut = cut_past_failure(child, early)
    assert json.loads(cut)["robots"][0]["waypoints"] == waypoints[: 2 + KEPT_PAST]
    assert json.loads(cut)["robots"][0]["start"] == start
    assert json.loads(cut)["robots"][1:] == json.loads(child)["robots"][1:]
    assert _core.shrink_check(cut, _core.shrink_leg_margin(child)) is None
    # Nothing to cut: a failure on the last leg, no failure, a failure of the whole mission.
    x, y = waypoints[-1]
    assert cut_past_failure(child, dataclasses.replace(parent, failure_pose=(x, y, 0.0))) == child
    assert cut_past_failure(child, dataclasses.replace(parent, failure_pose=None)) == child
    assert early.variant is not None
    whole = "route_not_completed/" + early.variant.split("/", 1)[1]
    assert cut_past_failure(child, dataclasses.replace(early, variant=whole)) == child


def test_a_share_of_a_mutation_searchs_fresh_jobs_go_on_past_their_goal() -> None:
    spec = spec_of()
    children = Archive(spec, 3, SearchPlan("mutation")).ask(0)
    assert children == Archive(spec, 3, SearchPlan("mutation")).ask(0)
    assert [c.index for c in children] == list(range(INITIAL))
    stretched = [c for c in children if c.situation is not None]
    # A draw per job: some go on, some are the campaign's jobs as they are.
    assert 0 < len(stretched) < len(children)
    for child in children:
        assert (child.operator, child.parents) == ("fresh", ())
        assert child.genome == fresh(spec, 3, child.index)
    for child in stretched:
        assert child.situation is not None
        job = build_job(spec, 3, child.index)
        made = sitgen.generate_situation(job.situation, seed=job.seed)
        before = json.loads(made.to_json())["robots"]
        after = json.loads(child.situation)["robots"]
        kept = len(before[0]["waypoints"])
        assert len(after[0]["waypoints"]) > kept
        assert after[0]["waypoints"][:kept] == before[0]["waypoints"]
        assert after[1:] == before[1:]
        assert np.array_equal(sitgen.Situation(child.situation).grid.occupied, made.grid.occupied)


def test_the_same_draw_makes_the_same_child(parent: Parent) -> None:
    for operator in OPERATORS:
        a = mutate(parent, operator, np.random.default_rng(11))
        b = mutate(parent, operator, np.random.default_rng(11))
        assert a == b


def test_a_run_has_a_variant_from_where_its_failure_began(parent: Parent) -> None:
    record = sitgen.run(parent.situation, time_limit=200.0)
    assert record.failure is not None
    key = variant(record.failure["class"], record.coverage)
    assert key is not None and key.startswith(record.failure["class"] + "/")
    _, interaction, context = key.split("/")
    assert context in dict(_core.coverage_dimensions())["context"]
    assert interaction in (*dict(_core.coverage_dimensions())["interaction"], "no_peer")
    x, y, _ = record.coverage["failure_at"]["pose"]  # type: ignore[index]
    assert 0 <= x <= parent.situation.grid.size_m[0] and 0 <= y <= parent.situation.grid.size_m[1]
    assert variant(None, record.coverage) is None


def test_a_mutation_search_is_the_same_on_one_and_two_workers(tmp_path: Path) -> None:
    spec = spec_of()
    one, two = tmp_path / "one.db", tmp_path / "two.db"
    plan = SearchPlan("mutation", ("failure_class", "variant"))
    run_search(spec, one, seed=3, budget=BUDGET, plan=plan, workers=1)
    run_search(spec, two, seed=3, budget=BUDGET, plan=plan, workers=2)
    assert stored(one) == stored(two)
    rows = stored(one)
    operators = [json.loads(r[3])["operator"] for r in rows]
    assert set(operators) - {"fresh"} <= set(OPERATORS)
    # Later generations are mostly mutants: each way of making a child starts equally likely.
    assert sum(op in OPERATORS for op in operators) >= BATCH
    with Store(one) as store:
        found = variants_of(store)
        tally = robust_variants(store, 80, (40, 80))
    assert found and tally.spent <= 80 + 8
    assert tally.runs + tally.copies == tally.spent
    assert 0 < tally.runs_at[40] <= tally.runs_at[80] <= tally.runs
    assert tally.at_budget[40] <= tally.at_budget[80] == len(tally.robust)
    # A test stops once its verdict is decided, and it is the verdict of all 8 copies.
    assert tally.trials
    with Store(one) as store:
        tried = [(t, stored_run(store, t.run_id)) for t in tally.trials[:3]]
    for trial, row in tried:
        every = [copy_class(r) for r in copies(copy_jobs(row, 8, 0), 2)]
        cls = trial.key.split("/", 1)[0]
        hits = [c == cls for c in every]
        assert trial.classes == tuple(every[: len(trial.classes)])
        assert trial.robust == (sum(hits) >= 6)
        decided = [sum(hits[:n]) >= 6 or n - sum(hits[:n]) >= 3 for n in range(1, 9)]
        assert len(trial.classes) == 1 + decided.index(True)


@pytest.mark.parametrize("how", [signal.SIGKILL])
def test_a_killed_mutation_search_resumes_to_the_same_runs(tmp_path: Path, how: int) -> None:
    spec = write_spec(tmp_path, SEARCHED)
    budget = str(INITIAL + 2 * BATCH)
    args = ("--seed", "8", "--budget", budget, "--strategy", "mutation", "--reruns", "2")
    reference = tmp_path / "reference.db"
    done = run_cli("search", str(spec), "--db", str(reference), *args)
    assert done.returncode == 0, done.stderr
    assert "variants" in done.stdout
    db = tmp_path / "killed.db"
    proc = start_command(spec, db, *args, "--workers", "1", command="search")
    wait_for_runs(db, INITIAL + 4, proc)
    proc.send_signal(how)
    proc.communicate(timeout=120)
    again = run_cli("search", str(spec), "--db", str(db), *args)
    assert again.returncode == 0, again.stderr
    assert stored(db) == stored(reference)
    report = tmp_path / "report"
    assert run_cli("report", str(db), "-o", str(report), "--top", "3").returncode == 0
    page = (report / "index.html").read_text()
    assert "variant" in page


def test_a_directed_search_varies_the_run_it_is_given(tmp_path: Path) -> None:
    campaign = tmp_path / "c.db"
    assert (
        run_cli(
            "campaign", "--n", "12", "--seed", "1", "--db", str(campaign), "--reruns", "0"
        ).returncode
        == 0
    )
    with Store(campaign) as store:
        run_id, cls = store.db.execute(
            "SELECT id, failure_class FROM runs WHERE failure_class IS NOT NULL "
            "ORDER BY score DESC LIMIT 1"
        ).fetchone()
    db = tmp_path / "like.db"
    done = run_cli(
        "search", "--strategy", "mutation", "--like", f"{campaign}:{run_id}", "--budget", "48",
        "--db", str(db), "--reruns", "2",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert f"variants of {cls}" in done.stdout
    rows = stored(db)
    first = rows[0]
    with Store(campaign) as store:
        original = store.run_row(run_id)
    assert first[6] == original["score"]  # the run itself, run again
    operators = [json.loads(r[3])["operator"] for r in rows[1:]]
    assert "fresh" not in operators
    with Store(db) as store:
        assert any(v.key.startswith(cls + "/") for v in variants_of(store, cls))
    wrong = run_cli(
        "search", "--strategy", "random", "--like", f"{campaign}:{run_id}",
        "--db", str(tmp_path / "x.db"),
    )  # fmt: skip
    assert wrong.returncode == 2, wrong.stderr
    assert "--like: directs the mutation strategy (the default), not --strategy random" in (
        wrong.stderr
    )
    bad = run_cli(
        "search", "--strategy", "mutation", "--class", "nope", "--db", str(tmp_path / "y.db")
    )
    assert bad.returncode == 2 and "--class: unknown failure class" in bad.stderr
    missing = run_cli(
        "search", "--strategy", "mutation", "--like", "no.db:3", "--db", str(tmp_path / "z.db")
    )
    assert missing.returncode == 2 and "--like: no.db: no such store" in missing.stderr


def test_curiosity_prefers_the_way_that_found_new_robust_variants() -> None:
    archive = Archive(spec_of(), 0, SearchPlan("mutation", ("failure_class", "variant")))
    families = (*TARGETED, LOCAL)
    archive.arm_runs = {("fresh", "fresh"): 40} | {("confirmed", a): 40 for a in families}
    archive.arm_runs |= {("unconfirmed", a): 10 for a in families}
    archive.arm_new = {("confirmed", "reshape_terrain"): 12, ("fresh", "fresh"): 4}
    archive.arm_new[("unconfirmed", LOCAL)] = 6
    rng = np.random.default_rng(0)
    local = [a for a in OPERATORS if a not in TARGETED]
    picks = Counter(archive._arm(rng, set(), True, "confirmed") for _ in range(400))
    assert picks.most_common(1)[0][0] == "reshape_terrain"
    assert picks["reshape_terrain"] > 0.8 * 400 and sum(picks[a] for a in local) < 0.05 * 400
    # Each parent context keeps its own record: what keeps an unconfirmed variant differs. The
    # local operators are one arm, and the one that runs is any of them.
    picks = Counter(archive._arm(rng, set(), True, "unconfirmed") for _ in range(400))
    assert sum(picks[a] for a in local) > 0.8 * 400
    assert len([a for a in local if picks[a]]) == len(local)
    # A way never tried is drawn from the pooled share (about 0.15 here), not a coin flip
    # (which would beat reshape_terrain's 0.3 seven times in ten): now and then.
    archive.arm_runs[("confirmed", "approach_peer")] = 0
    picks = Counter(archive._arm(rng, set(), True, "confirmed") for _ in range(400))
    assert 0 < picks["approach_peer"] < 0.4 * 400 < picks["reshape_terrain"]
    # What was tried for this child is not drawn again, nor a family all of whose operators
    # were; a directed search draws no fresh job.
    assert archive._arm(rng, {"reshape_terrain"}, False, "confirmed") not in (
        "reshape_terrain",
        "fresh",
    )
    assert archive._arm(rng, {"approach_peer", *local}, False, "unconfirmed") == "reshape_terrain"


def test_parents_whose_neighbouring_variants_are_all_known_are_drawn_seldom() -> None:
    archive = Archive(spec_of(), 0, SearchPlan("mutation", ("failure_class", "variant")))
    known, open_ = "drove_into_wall/no_peer/corridor", "turned_into_wall/head_on/gap"
    archive.variant_of = {1: known, 2: open_}
    archive.variants_seen = {v for op in TARGETED for v in neighbours(known, op).values()} | {
        known,
        open_,
    }
    assert archive._frontier(1) == pytest.approx(FRONTIER_FLOOR)
    assert archive._frontier(2) == pytest.approx(FRONTIER_FLOOR + 1.0)
    rng = np.random.default_rng(0)
    picks = Counter(archive._novel([1, 2], rng) for _ in range(600))
    # Same cell runs, no screen: weights 0.1 against 1.1.
    assert 0 < picks[0] < 0.15 * 600 < picks[1]


def test_the_screen_tests_a_variant_on_two_runs_at_most_and_never_once_confirmed() -> None:
    screen = Screen()
    assert not screen.wants(None) and screen.wants("a/no_peer/open")
    screen.attempts["a/no_peer/open"] = 2
    assert not screen.wants("a/no_peer/open")
    screen.robust["b/head_on/gap"] = 7
    assert not screen.wants("b/head_on/gap")


def test_a_target_is_the_interaction_context_or_both_an_operator_changes() -> None:
    key = "drove_into_wall/head_on/corridor"
    assert target_of(key, "approach_peer") == "head_on"
    assert target_of(key, "reshape_terrain") == "corridor"
    assert target_of(key, "reshape_and_approach") == "head_on/corridor"
    assert neighbours(key, "approach_peer") == {
        i: f"drove_into_wall/{i}/corridor" for i in APPROACHES if i != "head_on"
    }
    assert neighbours(key, "reshape_terrain") == {
        c: f"drove_into_wall/head_on/{c}" for c in CONTEXTS if c != "corridor"
    }
    both = neighbours(key, "reshape_and_approach")
    assert len(both) == (len(APPROACHES) - 1) * (len(CONTEXTS) - 1)
    assert both["stopped/gap"] == "drove_into_wall/stopped/gap"
    assert not any(t.startswith("head_on/") or t.endswith("/corridor") for t in both)


def test_a_mirrored_child_aims_at_the_crossing_from_the_other_side() -> None:
    assert neighbours("struck_while_stopped_seen/crossing_left/gap", "mirror") == {
        "crossing_right": "struck_while_stopped_seen/crossing_right/gap"
    }
    assert target_of("drove_close_to_peer/crossing_right/open", "mirror") == "crossing_right"
    # Every other interaction reads the same mirrored: nothing new to aim at.
    for interaction in ("head_on", "from_behind", "overtaking", "stopped", "no_peer"):
        assert neighbours(f"drove_close_to_peer/{interaction}/open", "mirror") == {}


def test_a_mirrored_child_is_cut_past_where_its_parent_failed_mirrored(parent: Parent) -> None:
    own = parent.situation.to_json()
    waypoints = json.loads(own)["robots"][0]["waypoints"]
    assert len(waypoints) >= 3
    # A failure that began on the second leg, facing north-east.
    x, y = (np.array(waypoints[0]) + np.array(waypoints[1])) / 2
    early = dataclasses.replace(parent, failure_pose=(float(x), float(y), math.pi / 4))
    child = mutate(early, "mirror", np.random.default_rng(0))
    assert child is not None
    mirrored = as_made_by(early, "mirror")
    assert mirrored.failure_pose is not None
    width = parent.situation.grid.size_m[0]
    assert mirrored.failure_pose == pytest.approx((width - x, y, 3 * math.pi / 4))
    kept = len(json.loads(cut_past_failure(own, early))["robots"][0]["waypoints"])
    assert kept < len(waypoints), "nothing to cut: no test"
    cut = json.loads(cut_past_failure(child, mirrored))["robots"][0]["waypoints"]
    assert len(cut) == kept
    assert as_made_by(parent, "add_obstacle") is parent


def test_a_targeted_child_keeps_the_target_it_was_aimed_at(tmp_path: Path) -> None:
    db = tmp_path / "aims.db"
    run_search(spec_of(), db, seed=2, budget=INITIAL + 3 * BATCH, plan=SearchPlan("mutation"))
    with Store(db) as store:
        rows = store.db.execute(
            "SELECT id, parents, genes, failure_class, coverage FROM runs ORDER BY id"
        ).fetchall()
    variants = {r[0]: variant(r[3], unpack_json(r[4]) if r[4] else None) for r in rows}
    aimed = 0
    for _, parents, genes, _, _ in rows:
        how = json.loads(genes)
        if how["operator"] not in TARGETED:
            assert "aim" not in how
            continue
        # A mirrored child is made only where the other side is a variant not seen yet.
        assert how["operator"] != "mirror" or "aim" in how
        if "aim" in how:
            parent = json.loads(parents)[0]
            assert how["aim"] in neighbours(variants[parent], how["operator"])
            aimed += 1
    assert aimed, "no targeted child was aimed"


@pytest.mark.parametrize(
    ("peers", "param"),
    [("navground:ORCA", "optimal_speed"), ("vo", "speed_m_s"), ("snd", None)],
)
def test_a_peers_speed_is_varied_by_the_parameter_its_controller_has(
    parent: Parent, peers: str, param: str | None
) -> None:
    """``peer_speed`` scales the cruising speed under the name the peer's controller gives it,
    and leaves a controller without one alone (a child the peer's controller would refuse is
    never made); a staged approach's peer runs ``straight``, whose departure it times."""
    data = json.loads(parent.situation.to_json())
    for robot in data["robots"][1:]:
        robot["controller"] = {"name": peers, "params": {}}
    situation = sitgen.Situation(json.dumps(data))
    assert parent.failure_pose is not None
    focus = parent.failure_pose[:2]
    robots = copy.deepcopy(data["robots"])
    occupied = situation.grid.occupied.copy()
    edit = apply_local("peer_speed", robots, occupied, 0.1, focus, parent, np.random.default_rng(2))
    peer = focus_peer(data["robots"], focus)
    assert peer is not None
    if param is None:
        assert edit is None
    else:
        assert edit is not None
        assert set(robots[peer]["controller"]["params"]) == {param}
    staged = dataclasses.replace(parent, situation=situation)
    child = mutate(staged, "approach_peer", np.random.default_rng(5), "head_on")
    assert child is not None
    robot = json.loads(child)["robots"][peer]
    assert robot["controller"]["name"] == "straight"
    assert set(robot["controller"]["params"]) == {"speed_m_s", "start_s"}
