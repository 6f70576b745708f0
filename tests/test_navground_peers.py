"""Peers that run navground's behaviours (or a user's Python class): a crowd that avoids. Who
moved into whom stays the monitor's to say whatever the peers run; a campaign that draws each
peer's controller from a list is the same on 1 and 2 workers; a failure with such a peer
shrinks and reruns the same; a peer's failing controller ends the run naming the peer; and a
program or ROS 2 node as a peer is refused in one line."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sitgen
from sitgen import _core
from sitgen.world.situation import Situation
from tests.conftest import campaign_on_2_and_1_workers, run_cli, two_robots

navground = pytest.importorskip("navground.core", reason="sitgen[navground] is not installed")

CROWD = """
n = 6
[situation.terrain]
preset = "open_field"
width_m = 20.0
height_m = 20.0
[situation.mission]
peers_min = 3
peers_max = 4
peer_mode = "crossing"
min_route_length_m = 10.0
peer_controllers = [
    { name = "navground:ORCA" },
    { name = "navground:HL", params = { tau = 0.4 } },
    { name = "straight" },
]
[run]
time_limit_s = 40.0
"""


class Still:
    """An agent that stands where it starts (a user's controller, as users write one)."""

    def reset(self, info: dict[str, Any]) -> None:
        pass

    def act(self, obs: Any) -> tuple[float, float]:
        return 0.0, 0.0


class Ahead:
    """An agent that drives straight ahead at 0.6 m/s, avoiding nothing."""

    def reset(self, info: dict[str, Any]) -> None:
        pass

    def act(self, obs: Any) -> tuple[float, float]:
        return 0.6, 0.0


class Stumbling:
    """A peer's controller with a bug: it raises after 2 s."""

    def reset(self, info: dict[str, Any]) -> None:
        self.role = info["role"]

    def act(self, obs: Any) -> tuple[float, float]:
        if obs.time > 2.0:
            raise ZeroDivisionError(f"a {self.role} divided by zero")
        return 0.3, 0.0


def test_a_peer_that_avoids_passes_a_standing_agent_that_a_blind_peer_strikes() -> None:
    """Head-on at a standing agent: a ``straight`` peer strikes it (the peer's doing); HL and
    HRVO peers go round it to the end of their route, with no contact."""
    for peer, struck in [("straight", True), ("navground:HL", False), ("navground:HRVO", False)]:
        situation = two_robots((6.0, 10.0, 0.0), (16.0, 10.0, np.pi), [3.0, 10.0], {"name": peer})
        record = sitgen.run(situation, controller=Still(), time_limit=40.0)
        collisions = [e for e in record.events if e["kind"] == "collision"]
        assert record.outcome != "error", record.reason
        if struck:
            assert record.failure is not None
            assert record.failure["class"] == "struck_while_stopped_seen", record.failure
        else:
            assert not collisions, (peer, record.events_text)
            assert record.trajectory[-1, 1, 0] < 4.0, (peer, record.trajectory[-1, 1])


@pytest.mark.parametrize("peer", ["straight", "navground:ORCA", "navground:HL"])
def test_an_agent_that_drives_into_a_slow_peer_ahead_is_at_fault_whatever_the_peer_runs(
    peer: str,
) -> None:
    """The agent closes on a peer driving the same way at 0.15 m/s: the collision is the
    agent's (it drove into a peer it had seen), whether the peer avoids or not."""
    params = {"speed_m_s": 0.15} if peer == "straight" else {"optimal_speed": 0.15}
    situation = two_robots(
        (4.0, 10.0, 0.0), (8.0, 10.0, 0.0), [17.0, 10.0], {"name": peer, "params": params}
    )
    record = sitgen.run(situation, controller=Ahead(), time_limit=40.0)
    assert record.failure is not None and record.failure["class"] == "drove_into_seen_peer"


def test_a_peer_controller_that_fails_ends_the_run_naming_the_peer() -> None:
    name = "python:tests.test_navground_peers:Stumbling"
    situation = two_robots((4.0, 10.0, 0.0), (4.0, 14.0, 0.0), [15.0, 14.0], {"name": name})
    record = sitgen.run(situation, time_limit=20.0)
    assert record.outcome == "error"
    assert record.reason.startswith(f"controller `{name}` of peer 1 raised at 2.1 s:"), (
        record.reason
    )
    assert "a peer divided by zero" in record.reason


def stored(db: Path) -> list[tuple[Any, ...]]:
    with sqlite3.connect(db) as c:
        return c.execute(
            "SELECT r.id, r.outcome, r.reason, r.score, r.failure_class, r.steps, "
            "r.events_sha256, s.situation FROM runs r JOIN situations s ON s.id = r.situation_id "
            "ORDER BY r.id"
        ).fetchall()


def test_a_crowd_of_mixed_peers_runs_the_same_on_1_and_2_workers_and_its_failure_shrinks(
    tmp_path: Path,
) -> None:
    campaign_on_2_and_1_workers(CROWD, tmp_path)
    two = stored(tmp_path / "2.db")
    assert stored(tmp_path / "1.db") == two
    assert len(two) == 6 and not [r for r in two if r[1] == "error"], [r[2] for r in two]
    peers = [
        r["controller"] for row in two for r in json.loads(row[7])["robots"] if r["role"] == "peer"
    ]
    assert {p["name"] for p in peers} == {"navground:ORCA", "navground:HL", "straight"}
    assert {"tau": 0.4} in [p["params"] for p in peers if p["name"] == "navground:HL"]

    # The worst run whose failure a navground peer had a part in, shrunk and rerun.
    runs = sorted((r for r in two if r[4]), key=lambda r: -r[3])
    run_id = next(
        r[0]
        for r in runs
        if any(
            e.get("other") is not None
            and json.loads(r[7])["robots"][e["other"]]["controller"]["name"].startswith("navground")
            for e in map(json.loads, _events(tmp_path / "2.db", r[0]))
        )
    )
    out = tmp_path / "min.json"
    done = run_cli(
        "shrink", str(tmp_path / "2.db"), str(run_id), "--max-probes", "12", "-o", str(out)
    )
    assert done.returncode == 0, done.stderr
    minimal = json.loads(out.read_text())
    assert any(r["controller"]["name"].startswith("navground:") for r in minimal["robots"])
    with sqlite3.connect(tmp_path / "2.db") as c:
        failure_class, run_spec, run_seed = c.execute(
            "SELECT failure_class, run_spec, run_seed FROM shrinks WHERE run_id = ?", (run_id,)
        ).fetchone()
    record = sitgen.run(Situation(out.read_text()), spec=json.loads(run_spec), seed=run_seed)
    assert record.failure is not None and record.failure["class"] == failure_class


def _events(db: Path, run_id: int) -> list[str]:
    with sqlite3.connect(db) as c:
        (text,) = c.execute("SELECT events_jsonl FROM runs WHERE id = ?", (run_id,)).fetchone()
    return [line for line in text.splitlines() if line.strip()]


@pytest.mark.parametrize(
    ("table", "field"),
    [
        ('[situation.mission.peer_controller]\nname = "cmd:walker"', "peer_controller.name"),
        ('[situation.mission]\npeer_controllers = [{ name = "ros2:walker" }]', "[0].name"),
    ],
)
def test_a_program_or_node_as_a_peer_is_refused_in_one_line(
    tmp_path: Path, table: str, field: str
) -> None:
    spec = tmp_path / "c.toml"
    spec.write_text(f'n = 2\n[situation.terrain]\npreset = "open_field"\n{table}\n')
    done = run_cli("campaign", str(spec), "--db", str(tmp_path / "c.db"))
    assert done.returncode == 2, done.stdout
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert field in done.stderr and "drives only the agent" in done.stderr, done.stderr
    assert not (tmp_path / "c.db").exists()


def test_check_controller_drives_a_situation_whose_peers_run_navground(tmp_path: Path) -> None:
    situation = two_robots(
        (4.0, 10.0, 0.0), (16.0, 10.0, np.pi), [3.0, 10.0], {"name": "navground:HL"}
    )
    path = tmp_path / "peers.json"
    situation.save(path)
    done = run_cli("check-controller", "navground:ORCA", "--situation", str(path))
    assert done.returncode == 0, done.stdout + done.stderr
    assert "FAIL" not in done.stdout


def test_a_run_with_an_external_peer_does_not_step_until_the_peer_has_a_controller() -> None:
    situation = two_robots(
        (4.0, 10.0, 0.0), (4.0, 14.0, 0.0), [15.0, 14.0], {"name": "navground:HL"}
    )
    core = _core.Run(situation.to_json(), "{}", 0)
    assert core.external_peers == [1]
    for step in (lambda: core.step(None), core.run_to_end):
        with pytest.raises(ValueError, match="robot 1's controller is external"):
            step()
    core.set_peers({1: lambda *observation: (0.2, 0.0)})
    assert not core.step(None)


def test_navground_with_no_behaviour_names_the_form() -> None:
    done = run_cli("check-controller", "navground:")
    assert done.returncode == 1, done.stdout + done.stderr
    assert "controller `navground:` expected navground:BEHAVIOR" in done.stdout, done.stdout
