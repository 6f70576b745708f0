"""navground's behaviours as the agent (``navground:BEHAVIOR``), with both perceptions:
campaigns without errors, the same on 1 and 2 workers and on either controller path, the map's
walls as the exact perception gives them, and one-line errors for a bad name or parameter."""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import sitgen
from sitgen import _core
from sitgen.controllers.navground import NavgroundController, thinned
from sitgen.execution.jobs import parse_campaign
from sitgen.run import reset_info
from sitgen.world.config import spec_json
from sitgen.world.sim import Observation
from sitgen.world.terrain import wall_segments
from tests.conftest import ROOT, campaign_on_2_and_1_workers, run_cli, sitgen_command

navground = pytest.importorskip("navground.core", reason="sitgen[navground] is not installed")

BEHAVIOURS = ["HL", "ORCA", "HRVO", "SocialForce"]
PERCEPTIONS = ("sensed", "exact")

CAMPAIGN = """
n = 16
[situation.terrain]
preset = "rocky_desert"
width_m = 24.0
height_m = 24.0
[situation.mission]
peers_min = 1
peers_max = 4
min_route_length_m = 12.0
[run]
time_limit_s = 40.0
[run.controller]
name = "navground:HL"
[vary]
"run.controller.name" = { choice = [
    "navground:HL", "navground:ORCA", "navground:HRVO", "navground:SocialForce",
] }
"run.controller.perception" = { choice = ["sensed", "exact"] }
"""


def stored_runs(db: Path) -> list[tuple[Any, ...]]:
    with sqlite3.connect(db) as c:
        return c.execute(
            "SELECT id, run_spec, outcome, reason, score, failure_class, steps, waypoints_reached, "
            "events_sha256 FROM runs ORDER BY id"
        ).fetchall()


def test_every_behaviour_drives_a_campaign_with_both_perceptions_the_same_on_1_and_2_workers(
    tmp_path: Path,
) -> None:
    """One campaign that draws the behaviour and the perception of each run (one campaign,
    not eight, for CI's time), on 2 workers and again on 1: the same runs, none in error."""
    campaign_on_2_and_1_workers(CAMPAIGN, tmp_path)
    two = stored_runs(tmp_path / "2.db")
    assert stored_runs(tmp_path / "1.db") == two
    assert len(two) == 16 and not [r for r in two if r[2] == "error"], [r[3] for r in two]
    controllers = [json.loads(r[1])["controller"] for r in two]
    assert {c["name"] for c in controllers} == {f"navground:{b}" for b in BEHAVIOURS}
    assert {c["perception"] for c in controllers} == set(PERCEPTIONS)
    # Driven by the behaviour, not standing still: most runs reach a waypoint.
    assert sum(r[7] > 0 for r in two) >= 12, [r[7] for r in two]


def test_the_host_process_and_the_fast_path_give_the_same_run(situation: sitgen.Situation) -> None:
    for perception in PERCEPTIONS:
        spec = {"controller": {"name": "navground:ORCA", "perception": perception}}
        host = sitgen.run(situation, time_limit=30.0, spec=spec)
        fast = sitgen.run(situation, time_limit=30.0, spec=spec, in_process=True)
        assert host.outcome != "error", host.reason
        assert np.array_equal(host.trajectory, fast.trajectory) and host.events == fast.events


def test_the_perceptions_differ_where_a_robot_is_out_of_sight(
    situation: sitgen.Situation,
) -> None:
    """The same behaviour sensed and exact drives differently: the exact one knows the peers
    its laser does not see (a finding for a user is in exactly that difference)."""
    specs = [{"controller": {"name": "navground:HL", "perception": p}} for p in PERCEPTIONS]
    runs = [sitgen.run(situation, time_limit=30.0, spec=spec) for spec in specs]
    assert not np.array_equal(runs[0].trajectory, runs[1].trajectory)


def test_params_reach_the_behaviour_under_its_own_names(situation: sitgen.Situation) -> None:
    slow = sitgen.run(
        situation, controller="navground:ORCA", time_limit=20.0,
        params={"optimal_speed": 0.2, "time_horizon": 4.0}, in_process=True,
    )  # fmt: skip
    fast = sitgen.run(situation, controller="navground:ORCA", time_limit=20.0, in_process=True)
    agent = situation.agent.id
    top = [
        float(np.max(np.hypot(*np.diff(r.trajectory[:, agent, :2], axis=0).T))) / 0.1
        for r in (slow, fast)
    ]
    assert top[0] <= 0.2 + 1e-6 < top[1]


def test_a_bad_behaviour_parameter_or_perception_is_one_line_before_any_run(
    tmp_path: Path,
) -> None:
    cases = [
        (["--controller", "navground:Nope"], "no navground behaviour `Nope`; registered: "),
        (["--controller", "navground:HL", "-p", "bogus=1"], "unknown parameter `bogus` of HL"),
        (["--controller", "navground:HL", "-p", "resolution=2.5"], "`resolution` is a whole"),
        (["--controller", "navground:HL", "--perception", "psychic"], "unknown variant"),
    ]
    for args, said in cases:
        db = tmp_path / "x.db"
        done = run_cli("campaign", *args, "--n", "2", "--db", str(db))
        assert done.returncode == 2 and said in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1, done.stderr
        assert not db.exists()


def test_check_controller_passes_every_behaviour() -> None:
    for behavior in BEHAVIOURS:
        done = run_cli("check-controller", f"navground:{behavior}")
        assert done.returncode == 0, done.stdout


def test_the_exact_perception_is_told_the_maps_walls(situation: sitgen.Situation) -> None:
    exact = {"controller": {"name": "navground:HL", "perception": "exact"}}
    info = reset_info(situation, exact, situation.agent.id)
    grid = situation.grid
    assert info["perception"] == "exact"
    assert np.array_equal(info["walls"], wall_segments(grid.occupied, grid.resolution))
    sensed = reset_info(situation, {"controller": {"name": "navground:HL"}}, situation.agent.id)
    assert sensed["perception"] == "sensed" and "walls" not in sensed


def edges_of(occupied: np.ndarray[Any, Any]) -> set[tuple[float, float, float, float]]:
    """Every unit cell edge between an occupied cell and a free one (outside occupied), cell by
    cell: the reference the merged segments must cover exactly."""
    rows, cols = occupied.shape

    def occ(r: int, c: int) -> bool:
        return not (0 <= r < rows and 0 <= c < cols) or bool(occupied[r, c])

    edges = set()
    for r in range(-1, rows + 1):
        for c in range(-1, cols + 1):
            if occ(r, c):
                continue
            y0, x0 = rows - 1 - r, c  # the free cell's bottom-left corner
            for (dr, dc), edge in {
                (-1, 0): (x0, y0 + 1, x0 + 1, y0 + 1), (1, 0): (x0, y0, x0 + 1, y0),
                (0, -1): (x0, y0, x0, y0 + 1), (0, 1): (x0 + 1, y0, x0 + 1, y0 + 1),
            }.items():  # fmt: skip
                if occ(r + dr, c + dc):
                    edges.add(edge)
    return {e for e in edges if all(v >= -1e-9 for v in e)}


@settings(max_examples=60, deadline=None)
@given(arrays(np.bool_, st.tuples(st.integers(1, 7), st.integers(1, 7))))
def test_walls_are_the_free_cells_edges_merged_into_straight_runs(
    occupied: np.ndarray[Any, Any],
) -> None:
    segments = wall_segments(occupied, 1.0)
    unit = set()
    for x1, y1, x2, y2 in segments:
        assert x1 == x2 or y1 == y2, "axis-aligned"
        n = round(abs(x2 - x1) + abs(y2 - y1))
        for k in range(n):
            if x1 == x2:
                unit.add((x1, y1 + k, x1, y1 + k + 1))
            else:
                unit.add((x1 + k, y1, x1 + k + 1, y1))
    # Every edge between free and occupied is covered once, and no other.
    total = sum(abs(s[2] - s[0]) + abs(s[3] - s[1]) for s in segments)
    reference = edges_of(occupied)
    assert unit == reference and total == len(reference)


PLUGIN = '''
import time

import numpy as np
from navground.core import Behavior


class Cautious(Behavior, name="SitgenTestCautious"):
    """Heads for the target at a third of its optimal speed, avoiding nothing; its first
    decision stalls for longer than a user controller's default step timeout."""

    stalled = False

    def desired_velocity_towards_point(self, point, speed, time_step):
        if not Cautious.stalled:
            Cautious.stalled = True
            time.sleep(1.5)
        delta = np.asarray(point) - self.pose.position
        distance = float(np.linalg.norm(delta))
        return delta / distance * min(speed, distance) / 3 if distance > 0 else delta
'''


def test_a_behaviour_a_users_plugin_registers_is_a_controller(tmp_path: Path) -> None:
    """A Python behaviour written as navground's docs say, registered through its plugin entry
    point, is found by name in every process of a campaign; a decision that stalls 1.5 s (a
    loaded machine) does not end its run."""
    (tmp_path / "cautious_plugin.py").write_text(PLUGIN)
    info = tmp_path / "cautious_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: cautious-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        "[navground_behaviors]\ncautious = cautious_plugin:Cautious\n"
    )
    db = tmp_path / "c.db"
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    done = subprocess.run(
        [*sitgen_command(), "campaign", "--controller", "navground:SitgenTestCautious",
         "--n", "3", "--db", str(db), "--reruns", "0"],
        capture_output=True, text=True, env=env, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stderr
    rows = stored_runs(db)
    assert len(rows) == 3 and not [r for r in rows if r[2] == "error"], [r[3] for r in rows]
    assert any(r[7] > 0 for r in rows), "it drove"


@settings(max_examples=60, deadline=None)
@given(arrays(np.float64, st.tuples(st.integers(0, 60), st.just(2)), elements=st.floats(-5, 5)))
def test_thinned_laser_points_keep_one_in_each_cell_and_cover_the_rest(
    points: np.ndarray[Any, Any],
) -> None:
    cell = 0.2
    kept = thinned(points, cell)
    cells = [tuple(c) for c in np.floor(kept / cell).astype(int)]
    assert len(set(cells)) == len(cells), "one a cell"
    # In scan order, each the first of its cell.
    indices = [int(np.flatnonzero((points == k).all(axis=1))[0]) for k in kept]
    assert indices == sorted(indices)
    for p in points:  # every point has a kept one in its own cell
        assert tuple(np.floor(p / cell).astype(int)) in set(cells)


def _distance_to_walls(points: np.ndarray[Any, Any], walls: np.ndarray[Any, Any]) -> Any:
    a, b = walls[:, :2], walls[:, 2:]
    ab = b - a
    length2 = np.maximum((ab * ab).sum(axis=1), 1e-12)
    out = []
    for p in points:
        t = np.clip(((p - a) * ab).sum(axis=1) / length2, 0.0, 1.0)
        out.append(np.hypot(*(a + ab * t[:, None] - p).T).min())
    return np.array(out)


@pytest.mark.parametrize("offset_m", [0.0, 0.3])
def test_the_sensed_obstacles_lie_on_the_walls_wherever_the_laser_sits(offset_m: float) -> None:
    """The laser's end points are taken from the laser, ``sim.laser.offset_x_m`` ahead of the
    pose: every obstacle disc the sensed perception gives lies on a wall (within a cell and the
    laser's noise), with the laser at the pose or 0.3 m ahead of it."""

    situation = sitgen.generate_situation({"terrain": {"preset": "caves"}}, seed=3)
    spec = {"sim": {"laser": {"offset_x_m": offset_m}}, "controller": {"name": "navground:HL"}}
    info = reset_info(situation, spec, situation.agent.id)
    controller = NavgroundController("HL")
    controller.reset(info)
    observed = _core.Run(situation.to_json(), spec_json(spec, "run"), 0).observe_agent()
    x, y, heading = observed["pose"]
    obs = Observation(
        ranges=np.asarray(observed["ranges"]), angles=np.asarray(info["laser"]["angles"]),
        max_range=float(info["laser"]["range_m"]), pose=(x, y, heading),
        velocity=tuple(observed["velocity"]), stalled=observed["stalled"],
        time=observed["time"], tracks=(), waypoints_reached=0,
    )  # fmt: skip
    controller._perceive(obs, x, y, heading)
    discs = controller.behavior.environment_state.static_obstacles
    assert len(discs) >= 5, "a cave wall within the horizon"
    grid = situation.grid
    walls = wall_segments(grid.occupied, grid.resolution)
    off = _distance_to_walls(np.array([d.position for d in discs]), walls)
    assert off.max() < grid.resolution + 0.05, off.max()


def test_ahead_kinematics_lets_the_behaviour_turn_at_full_speed(
    situation: sitgen.Situation,
) -> None:
    """``ahead=1``: navground's Ahead kinematics, limited as the robot is (speed and turn rate
    each on its own), not the two-wheel model that allows 0.29 m/s at 1 rad/s."""

    spec = {"controller": {"name": "navground:HL"}}
    info = reset_info(situation, spec, situation.agent.id)
    for ahead, wheeled in ((0.0, True), (1.0, False)):
        controller = NavgroundController("HL", ahead=ahead)
        controller.reset(info)
        assert controller.behavior.kinematics.is_wheeled() == wheeled
    with pytest.raises(ValueError, match="ahead is a switch"):
        NavgroundController("HL", ahead=0.5)


def test_every_spec_the_case_study_runs_is_in_the_repository() -> None:
    """docs/case-studies/navground.md's numbers come from commands on files the repository
    has: every spec its commands name exists and parses."""

    page = (ROOT / "docs" / "case-studies" / "navground.md").read_text()
    commands = [
        line
        for block in page.split("```sh")[1:]
        for line in block.split("```")[0].splitlines()
        if line.startswith("sitgen ")
    ]
    named = {word for line in commands for word in line.split() if word.endswith(".toml")}
    assert named, "the page runs specs"
    for spec in sorted(named):
        path = ROOT / spec
        assert path.is_file(), f"{spec} is not in the repository"
        parse_campaign(path.read_text(), spec)
