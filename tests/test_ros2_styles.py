"""ROS 2 nodes written the usual ways (tests/ros2_nodes/usual.py: acting in the scan callback on
the latest odometry and goal, spun by rclpy's single-threaded executor or its EventsExecutor, on
a timer on simulated time spun by the single- or multi-threaded executor, through an
approximate-time synchroniser, reading the route once) drive campaigns that store the same
runs, trajectories included, on 2 workers and again on 1 (there with the node kept alive across
runs, where it resets), with every core of the machine kept busy beside them; ``sitgen
check-controller`` says when a node's runs do not repeat, and when it cannot be kept alive.
Skipped, with the reason, where the ROS 2 wheels (sitgen[ros2]) are not installed.

``SITGEN_TEST_STYLE_RUNS`` sets the runs of each campaign (default 20: about 5 minutes for
the six styles' campaigns with both cores busy)."""

from __future__ import annotations

import json
import os
import shutil
import sqlite3
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from sitgen.controllers.ros2 import controller as ros2
from sitgen.controllers.ros2.bridge import ros2_available
from sitgen.run import run
from sitgen.world.config import preset_spec
from sitgen.world.situation import generate_situation
from tests.conftest import ROOT, run_cli, spinning

UNAVAILABLE = ros2_available()
pytestmark = pytest.mark.skipif(UNAVAILABLE is not None, reason=str(UNAVAILABLE))

USUAL = f"ros2:{sys.executable} {ROOT / 'tests/ros2_nodes/usual.py'}"
RUNS = int(os.environ.get("SITGEN_TEST_STYLE_RUNS", "20"))
STORED = (
    "SELECT r.id, r.outcome, r.reason, r.score, r.failure_class, r.steps, r.events_sha256, "
    "t.data FROM runs r LEFT JOIN trajectories t ON t.run_id = r.id ORDER BY r.id"
)


@pytest.fixture(scope="module")
def busy_machine() -> Iterator[None]:
    """Every core kept busy by a process that only spins, for the module's tests; in the
    parallel suite (pytest-xdist) the other test processes keep it busy already."""
    alone = "PYTEST_XDIST_WORKER" not in os.environ
    with spinning((os.cpu_count() or 2) if alone else 0, sessions=False):
        yield


def stored(db: Path) -> list[tuple[Any, ...]]:
    with sqlite3.connect(db) as c:
        return c.execute(STORED).fetchall()


@pytest.mark.parametrize(
    "style",
    [
        "scan_callback",
        "timer",
        "multi_threaded",
        "events_executor",
        "approximate_sync",
        "goal_once",
    ],
)
def test_a_node_written_the_usual_way_gives_the_same_campaign_every_time(
    style: str, tmp_path: Path, busy_machine: None
) -> None:
    spec = tmp_path / "usual.toml"
    spec.write_text(
        f'n = {RUNS}\n[situation.terrain]\npreset = "open_field"\n'
        "[situation.mission]\npeers_min = 0\npeers_max = 2\n"
        f'[run]\ntime_limit_s = 5.0\n[run.controller]\nname = "{USUAL} {style}"\n'
        # What is tested is the order a node gets its inputs in; a generous answer timeout
        # keeps the answers' deadline (tests/test_load.py's) out of it.
        "params = { answer_timeout_s = 10.0 }\n"
    )
    # The campaign on 1 worker repeats the one on 2: the same runs on both are the same runs
    # again, whatever the number of workers. On 1 worker the node is kept alive across runs
    # (keep_alive: one node reset between runs), except the node that reads its route once,
    # which cannot be and is refused before any run, naming the field.
    two = campaign(spec, tmp_path / "two.db", "2")
    assert len(two) == RUNS and all(r[1] != "error" for r in two), [r[:3] for r in two]
    assert all(r[7] is not None for r in two)
    if style != "goal_once":
        assert campaign(spec, tmp_path / "one.db", "1", "--keep-alive") == two
        return
    assert campaign(spec, tmp_path / "one.db", "1") == two
    kept = run_cli(*campaign_args(spec, tmp_path / "kept.db", "1"), "--keep-alive")
    assert kept.returncode == 2, kept.stdout
    (line,) = kept.stderr.strip().splitlines()
    assert line.startswith("error: run.controller.keep_alive: controller `ros2:"), line
    assert "keeps state from run to run" in line, line
    assert not (tmp_path / "kept.db").exists() or stored(tmp_path / "kept.db") == []


def campaign_args(spec: Path, db: Path, workers: str) -> tuple[str, ...]:
    return (
        "campaign", str(spec), "--db", str(db), "--workers", workers, "--reruns", "0",
        "--seed", "3", "--keep-trajectories", "all",
    )  # fmt: skip


def campaign(spec: Path, db: Path, workers: str, *more: str) -> list[tuple[Any, ...]]:
    """``spec``'s campaign on ``workers`` workers: its stored runs."""
    done = run_cli(*campaign_args(spec, db, workers), *more)
    assert done.returncode == 0, done.stderr
    return stored(db)


def test_a_node_with_a_reset_service_kept_alive_runs_as_fresh_nodes(
    tmp_path: Path, busy_machine: None
) -> None:
    # The node reads its route once, and again when its reset service (~/reset) is called.
    spec = tmp_path / "reset.toml"
    spec.write_text(
        f'n = 4\n[situation.terrain]\npreset = "open_field"\n'
        "[situation.mission]\npeers_min = 0\npeers_max = 2\n"
        f'[run]\ntime_limit_s = 5.0\n[run.controller]\nname = "{USUAL} goal_once_reset"\n'
        "params = { answer_timeout_s = 10.0 }\n"
    )
    runs = campaign(spec, tmp_path / "fresh.db", "1")
    assert len(runs) == 4 and all(r[1] != "error" for r in runs), [r[:3] for r in runs]
    assert campaign(spec, tmp_path / "kept.db", "2", "--keep-alive") == runs


def test_check_controller_says_when_a_nodes_runs_do_not_repeat() -> None:
    done = run_cli("check-controller", f"{USUAL} wall_clock", "--steps", "100")
    assert done.returncode == 1, done.stdout + done.stderr
    (line,) = [x for x in done.stdout.splitlines() if "repeats" in x]
    assert line.startswith("FAIL repeats") and "differs from the first" in line, line
    done = run_cli("check-controller", f"{USUAL} timer", "--steps", "100")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ok   repeats  the same" in done.stdout
    # Which side of the lockstep sitgen runs, and why where it is the slower one.
    (act,) = [x for x in done.stdout.splitlines() if x.startswith("ok   act")]
    side = (
        "sitgen's side of each period in C"
        if shutil.which("gcc") is not None
        else "in Python, slower (ros2: the native period hand-over is built with gcc"
    )
    assert side in act, act


def test_check_controller_says_whether_a_node_can_be_kept_alive_across_runs() -> None:
    done = run_cli("check-controller", f"{USUAL} goal_once", "--steps", "30", "--keep-alive")
    assert done.returncode == 1, done.stdout + done.stderr
    (line,) = [x for x in done.stdout.splitlines() if "resets" in x]
    assert line.startswith("FAIL resets") and "keeps state from run to run" in line, line
    done = run_cli("check-controller", f"{USUAL} goal_once_reset", "--steps", "30", "--keep-alive")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "ok   resets   kept alive, a run after another equals a fresh node's" in done.stdout
    done = run_cli("check-controller", "python:examples/controllers/braking.py:Braking",
                   "--keep-alive")  # fmt: skip
    assert done.returncode == 2 and "--keep-alive" in done.stderr, done.stderr


def test_diff_refuses_a_side_kept_alive_that_does_not_reset(tmp_path: Path) -> None:
    kept = json.dumps({"name": f"{USUAL} goal_once", "keep_alive": True})
    done = run_cli(
        "diff", "--a", f"{USUAL} scan_callback", "--b", kept, "--n", "2",
        "--db", str(tmp_path / "d.db"),
    )  # fmt: skip
    assert done.returncode == 2, done.stdout
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("error: --b.keep_alive: controller `ros2:"), line
    assert "keeps state from run to run" in line, line


@pytest.mark.parametrize("style", ["scan_callback", "timer"])
def test_a_first_answer_lost_is_asked_for_again_and_the_run_is_the_same(
    style: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    # As when the node's /cmd_vel writer has not yet matched sitgen's reader: the node's first
    # answer never arrives. The first observation is handed over again, with simulated time
    # set back to the period's start, so that a node acting on a timer on simulated time acts
    # again; the run is then the run that lost nothing.
    situation = generate_situation(preset_spec("open_field"), seed=0)
    node = f"{USUAL} {style}"
    kept = run(situation, controller=node, time_limit=2.0)
    await_answer = ros2.Ros2Controller._await_answer
    lost: list[tuple[float, float, float]] = []

    def losing_the_first(
        self: ros2.Ros2Controller, bridge: Any, t: float, timeout_s: float
    ) -> bool:
        if lost or self._answered_once:
            return await_answer(self, bridge, t, timeout_s)
        taken = bridge.take_answer(self._subscription, self._stamped, timeout_s)
        if taken is not None:
            lost.append(taken)
        self._answers.clear()
        return False

    monkeypatch.setattr(ros2.Ros2Controller, "_await_answer", losing_the_first)
    again = run(situation, controller=node, time_limit=2.0, params={"start_timeout_s": 10.0})
    assert lost, "the node's first answer was not seen"
    assert again.outcome == kept.outcome != "error", (again.reason, kept.reason)
    assert again.trajectory.tolist() == kept.trajectory.tolist()
