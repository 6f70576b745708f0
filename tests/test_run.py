"""Runs from Python and the CLI: built-in, Python and external controllers, their failures,
the run record, and check-controller."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import sitgen
from sitgen.run import reset_info
from tests.conftest import ROOT, run_cli
from tests.controllers.pycontrollers import Forward

MISBEHAVING = f"cmd:{sys.executable} {ROOT / 'tests' / 'controllers' / 'misbehaving.py'}"
PY = "python:tests.controllers.pycontrollers"


def test_snd_follow_completes_an_open_field_route() -> None:
    spec = {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 0, "peers_max": 0}}
    situation = sitgen.generate_situation(spec, seed=1)
    record = sitgen.run(situation, time_limit=300)
    assert record.outcome == "completed", record.events_text
    assert record.controller == "snd_follow"
    kinds = [e["kind"] for e in record.events if e["robot"] == 0]
    assert kinds[-1] == "route_completed"
    reached = [e for e in record.events if e["kind"] == "waypoint_reached" and e["robot"] == 0]
    assert len(reached) == len(situation.agent.waypoints)
    assert record.trajectory.shape == (record.steps + 1, len(situation.robots), 3)
    start = situation.agent.start
    assert np.allclose(record.trajectory[0, 0], [start.x_m, start.y_m, start.heading_rad])
    assert record.score == sum(line["points"] for line in record.breakdown.values())


def test_the_same_run_gives_a_byte_identical_event_log(situation: sitgen.Situation) -> None:
    a = sitgen.run(situation, controller="vo", time_limit=60, seed=3)
    b = sitgen.run(situation, controller="vo", time_limit=60, seed=3)
    assert a.events_jsonl == b.events_jsonl
    assert np.array_equal(a.trajectory, b.trajectory)
    lines = a.events_jsonl.splitlines()
    assert [json.loads(line) for line in lines] == a.events


def test_a_python_object_drives_a_run_and_sees_only_its_observation(
    situation: sitgen.Situation,
) -> None:
    controller = Forward()
    record = sitgen.run(situation, controller=controller, time_limit=5)
    assert record.outcome == "timeout"
    assert record.steps == 50
    assert controller.info["waypoints"] == [list(w) for w in situation.agent.waypoints]
    assert len(controller.info["laser"]["angles"]) == 181
    obs = controller.observations[-1]
    assert isinstance(obs, sitgen.Observation)
    assert obs.ranges.shape == (181,)
    assert obs.time == pytest.approx(4.9)
    # It drove straight at 0.3 m/s for 5 s unless something stopped it.
    moved = np.hypot(*(record.trajectory[-1, 0, :2] - record.trajectory[0, 0, :2]))
    assert moved == pytest.approx(1.5) or any(e["kind"] == "collision" for e in record.events)


def test_python_and_external_controllers_agree(situation: sitgen.Situation) -> None:
    name = "examples/controllers/cautious.py:Cautious"
    by_class = sitgen.run(situation, controller=f"python:{ROOT / name}", time_limit=60)
    program = f"cmd:{sys.executable} {ROOT / 'examples/controllers/cautious_cmd.py'}"
    by_program = sitgen.run(situation, controller=program, time_limit=60)
    assert by_class.outcome != "error", by_class.reason
    assert by_class.events_jsonl == by_program.events_jsonl
    assert np.array_equal(by_class.trajectory, by_program.trajectory)


@pytest.mark.parametrize(
    ("controller", "reason"),
    [
        (f"{MISBEHAVING} crash", "exited with code 3 at 0.4 s: 'simulated failure in the planner'"),
        (f"{MISBEHAVING} garbage", "sent a malformed reply at 0.4 s: not JSON: 'hello'"),
        (f"{MISBEHAVING} noreply", "sent a malformed reply at 0.4 s: expected"),
        (f"{MISBEHAVING} nan", "not finite: (NaN, 0)"),
        ("cmd:/nonexistent/controller", "could not start"),
        (f"{PY}:Raises", "raised at 0.5 s: ValueError: lost track of the goal"),
        (f"{PY}:ReturnsText", "returned ('fast', 'left'); expected (v, omega) numbers"),
        (f"{PY}:ReturnsNaN", "not finite"),
        (f"{PY}:NoAct", "has no method `act`"),
        (f"{PY}:Missing", "module has no `Missing`"),
        ("python:no_such_module:X", "failed to load: ModuleNotFoundError"),
    ],
)
def test_failing_controllers_give_error_outcomes(
    situation: sitgen.Situation, controller: str, reason: str
) -> None:
    record = sitgen.run(situation, controller=controller, time_limit=30)
    assert record.outcome == "error"
    assert reason in record.reason, record.reason
    assert "\n" not in record.reason


def test_a_hanging_controller_times_out_and_the_next_run_starts_fresh(
    situation: sitgen.Situation,
) -> None:
    hung = sitgen.run(
        situation, controller=f"{MISBEHAVING} hang", time_limit=30, step_timeout_s=0.3
    )
    assert hung.outcome == "error"
    # A program that sleeps uses no processor time: its wall-clock backstop (ten step
    # timeouts, at least 2 s) ends it.
    assert "did not reply within 3 s at 0.4 s; it is waiting" in hung.reason, hung.reason
    assert hung.steps == 4
    fine = sitgen.run(situation, controller=f"{MISBEHAVING} good", time_limit=3)
    assert fine.outcome == "timeout"
    assert fine.steps == 30


def test_cli_run_prints_outcome_score_and_log(situation_file: Path, tmp_path: Path) -> None:
    events = tmp_path / "events.jsonl"
    done = run_cli(
        "run", str(situation_file), "--controller", "follow", "--time-limit", "200",
        "--events", str(events),
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "follow, outcome" in done.stdout
    assert " s  agent    " in done.stdout, "the event log is printed"
    if "outcome timeout" in done.stdout:
        assert "agent    timeout," in done.stdout
    logged = [json.loads(line) for line in events.read_text().splitlines()]
    assert logged and all({"kind", "start_s", "end_s", "robot", "other"} <= set(e) for e in logged)
    as_json = run_cli("run", str(situation_file), "--time-limit", "20", "--json", "--seed", "2")
    record = json.loads(as_json.stdout)
    assert record["seed"] == 2 and record["outcome"] in ("completed", "timeout")


def test_cli_run_reports_a_failing_controller_and_bad_specs(
    situation_file: Path, tmp_path: Path
) -> None:
    done = run_cli("run", str(situation_file), "--controller", f"{MISBEHAVING} crash")
    assert done.returncode == 1
    assert "outcome error" in done.stdout and "exited with code 3" in done.stdout
    bad = run_cli("run", str(situation_file), "--controller", "teleport")
    assert bad.returncode == 2
    assert bad.stderr.strip().startswith("error: run.controller.name: unknown controller")
    spec = tmp_path / "run.toml"
    spec.write_text("time_limit_s = 60\n[monitor]\nunsafe_proximity_m = -1\n")
    bad = run_cli("run", str(situation_file), "--spec", str(spec))
    assert bad.returncode == 2
    assert bad.stderr.strip() == "error: run.monitor.unsafe_proximity_m: -1 is not in (0, 100]"


def test_check_controller_passes_a_good_one_and_names_what_is_wrong() -> None:
    good = run_cli(
        "check-controller", f"python:{ROOT / 'examples/controllers/cautious.py'}:Cautious"
    )
    assert good.returncode == 0, good.stdout + good.stderr
    assert good.stdout.count("ok  ") == 7 and "ok   repeats" in good.stdout
    assert "ok   cost" in good.stdout and "the default campaign (500 runs" in good.stdout
    bad = run_cli("check-controller", f"{MISBEHAVING} garbage")
    assert bad.returncode == 1
    assert "FAIL act" in bad.stdout and "not JSON: 'hello'" in bad.stdout
    missing = run_cli("check-controller", f"{PY}:NoAct")
    assert missing.returncode == 1 and "FAIL loads" in missing.stdout


def test_a_user_controller_with_a_control_period_is_asked_every_kth_step(
    situation: sitgen.Situation,
) -> None:
    controller = Forward()
    spec = {"controller": {"name": "python:any", "control_period_s": 0.5}}
    record = sitgen.run(situation, controller=controller, time_limit=5, spec=spec)
    assert record.steps == 50
    assert [round(o.time, 1) for o in controller.observations] == [
        round(0.5 * k, 1) for k in range(10)
    ]
    assert controller.info["control_period_s"] == 0.5
    assert controller.observations[0].max_range == 10.0
    # Its command stayed in force between: it drove 0.3 m/s for the whole 5 s.
    moved = np.hypot(*(record.trajectory[-1, 0, :2] - record.trajectory[0, 0, :2]))
    assert moved == pytest.approx(1.5) or any(e["kind"] == "collision" for e in record.events)


@pytest.mark.parametrize(
    ("at_end", "targets"),
    [
        ("stop", [(1.0, 0.0), (2.0, 0.0), None]),
        ("loop", [(1.0, 0.0), (2.0, 0.0), (1.0, 0.0), (2.0, 0.0)]),
        ("reverse", [(1.0, 0.0), (2.0, 0.0), (1.0, 0.0), (0.0, 0.0), (1.0, 0.0)]),
    ],
)
def test_a_route_follower_goes_on_past_the_routes_end_as_at_end_says(
    at_end: str, targets: list[tuple[float, float] | None]
) -> None:
    """The route sitgen's peers follow (and a navground peer), driven to each target in turn:
    the start, the waypoints, then what ``at_end`` says."""
    follower = sitgen.RouteFollower((0.0, 0.0), [(1.0, 0.0), (2.0, 0.0)], at_end, 0.1)
    position = (0.0, 0.0)
    for expected in targets:
        target = follower.target(position)
        assert target == expected
        if target is not None:
            position = target
    with pytest.raises(sitgen.SpecError, match="at_end"):
        sitgen.RouteFollower((0.0, 0.0), [(1.0, 0.0)], "bounce", 0.1)


def test_a_controller_is_told_what_the_monitor_judges_it_by(situation: sitgen.Situation) -> None:
    """The reset message carries the waypoint radius and the monitor's thresholds, as the run
    spec resolves them, on either path (a class raises with what it was told)."""
    info = reset_info(situation, {"monitor": {"waypoint_radius_m": 0.8}}, situation.agent.id)
    assert info["waypoint_radius_m"] == 0.8 and info["monitor"]["waypoint_radius_m"] == 0.8
    assert info["monitor"]["unsafe_proximity_m"] == 0.5
    assert reset_info(situation, {}, situation.agent.id)["waypoint_radius_m"] == 0.5
    spec = {"monitor": {"waypoint_radius_m": 0.8}}
    for fast in (False, True):
        record = sitgen.run(situation, controller=f"{PY}:SaysItsRadius", spec=spec,
                            time_limit=2.0, in_process=fast)  # fmt: skip
        assert record.reason.endswith("told 0.8 m, near miss within 0.5 m"), record.reason
