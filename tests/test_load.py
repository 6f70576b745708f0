"""Verdicts a loaded machine cannot change: a controller's step deadline counts the processor
time it spends, so a planner that costs milliseconds a step gets the same campaign, robustness
verdicts and repro exit codes beside processes burning every core as alone (docs/
controller-protocol.md, "Deadlines")."""

from __future__ import annotations

import os
import sqlite3
import sys
from pathlib import Path

import pytest

import sitgen
from sitgen.controllers.ros2.bridge import ros2_available
from tests.conftest import ROOT, run_cli, spinning

COSTS_3MS = "python:tests.controllers.careless:Costs3ms"


def _campaign(folder: Path, name: str) -> tuple[list[tuple[object, ...]], list[tuple[object, ...]]]:
    """A campaign of the 3 ms class with a 30 ms step timeout (a wall-clock deadline that
    short fails steps beside eight loops a core, where a 3 ms step takes 20-50 ms of wall
    time): its runs and robustness rows."""
    spec = folder / "slow.toml"
    spec.write_text(
        'n = 4\n[situation.terrain]\npreset = "open_field"\n'
        "[situation.mission]\npeers_min = 1\npeers_max = 2\n"
        "[run]\ntime_limit_s = 8.0\n"
        f'[run.controller]\nname = "{COSTS_3MS}"\nstep_timeout_s = 0.03\n'
    )
    db = folder / name
    done = run_cli("campaign", str(spec), "--db", str(db), "--workers", "2", "--reruns", "2",
                   cwd=ROOT)  # fmt: skip
    assert done.returncode in (0, 1), done.stdout + done.stderr
    with sqlite3.connect(db) as con:
        runs = con.execute("SELECT id, outcome, reason, score FROM runs ORDER BY id").fetchall()
        robust = con.execute(
            "SELECT run_id, reruns, recurs, classes FROM robustness ORDER BY run_id"
        ).fetchall()
    return runs, robust


def test_a_slow_class_gets_the_same_verdicts_on_a_loaded_machine_as_alone(tmp_path: Path) -> None:
    alone = _campaign(tmp_path, "alone.db")
    assert all(outcome != "error" for _, outcome, _, _ in alone[0]), alone[0]
    # Eight loops a core, each in a session of its own: a process of sitgen's gets a ninth of
    # a core or less, and a step of 3 ms of processor time takes ten times that of wall time.
    with spinning(8 * (os.cpu_count() or 1)):
        loaded = _campaign(tmp_path, "loaded.db")
        done = run_cli("export", str(tmp_path / "alone.db"), "--run", "0", "--format",
                       "situation", "-o", str(tmp_path / "repro"), cwd=ROOT)  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        repro = ("run", str(tmp_path / "repro" / "run-0.json"), "--spec",
                 str(tmp_path / "repro" / "run-0.run.json"))  # fmt: skip
        busy = run_cli(*repro, cwd=ROOT)
    idle = run_cli(*repro, cwd=ROOT)
    assert loaded == alone
    assert busy.returncode == idle.returncode == 0, busy.stdout + idle.stdout
    assert busy.stdout.splitlines()[0] == idle.stdout.splitlines()[0]


def test_a_call_is_starved_only_when_it_was_runnable_but_mostly_not_run() -> None:
    from sitgen.controllers.deadlines import starved

    assert starved(10.0, 1.0, 6.0)  # waiting on a run queue most of the time
    assert not starved(10.0, 0.1, 0.2)  # asleep: waiting on something of its own
    assert not starved(10.0, 8.0, 1.0)  # running: computing


def test_a_run_the_machine_fails_is_made_again_and_never_stored_as_the_controllers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A run whose controller the machine starved past its backstop is made again; one the
    machine fails every time is stored with a reason that says the machine failed it."""
    import importlib

    import sitgen
    from sitgen.controllers.deadlines import MACHINE_RETRIES, MachineError

    running = importlib.import_module("sitgen.run")  # the module, not the function

    situation = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)
    made = running._run
    tries: list[int] = []

    def starved_twice(*args: object) -> sitgen.RunRecord:
        tries.append(1)
        if len(tries) <= 2:
            raise MachineError("the machine starved controller `x` of processor time at 0.3 s")
        record: sitgen.RunRecord = made(*args)
        return record

    monkeypatch.setattr(running, "_run", starved_twice)
    record = sitgen.run(situation, controller="straight", time_limit=3)
    assert record.outcome == "timeout" and len(tries) == 3

    def always(*args: object) -> sitgen.RunRecord:
        raise MachineError("the machine starved controller `x` of processor time at 0.3 s")

    monkeypatch.setattr(running, "_run", always)
    record = sitgen.run(situation, controller="straight", time_limit=3)
    assert record.outcome == "error" and record.reason.startswith("the machine "), record.reason
    assert f"(after {MACHINE_RETRIES + 1} tries)" in record.reason


@pytest.mark.skipif(ros2_available() is not None, reason=str(ros2_available()))
def test_a_ros2_node_answers_the_same_periods_on_a_loaded_machine_as_alone() -> None:
    """A node spending 3 ms of processor time on each answer, with 30 ms to answer: beside
    eight loops a core its answers take longer than that in wall time, and were held for those
    periods (another trajectory); counted as its own work, every period is answered as alone."""
    usual = ROOT / "tests/ros2_nodes/usual.py"
    node = f"ros2:/usr/bin/env USUAL_COST_MS=3 {sys.executable} {usual} scan_callback"
    situation = sitgen.generate_situation(
        {"terrain": {"preset": "open_field"}, "mission": {"peers_min": 1, "peers_max": 1}}, seed=1
    )
    spec = {
        "time_limit_s": 8.0,
        "controller": {"name": node, "params": {"answer_timeout_s": 0.03}},
    }

    def driven() -> tuple[str, str, str, bytes]:
        record = sitgen.run(situation, spec=spec)
        return record.outcome, record.reason or "", record.events_jsonl, record.trajectory.tobytes()

    alone = driven()
    assert alone[0] != "error", alone[1]
    with spinning(8 * (os.cpu_count() or 1)):
        loaded = driven()
    assert loaded == alone


def test_a_program_stopped_past_its_backstop_is_the_machines_error_and_run_again(
    tmp_path: Path,
) -> None:
    """A program stopped (SIGSTOP) for 3 s, past its 2 s backstop, neither computes nor waits:
    its run is made again (the program then runs through), never stored as its failure."""
    marker = tmp_path / "stopped-once"
    program = ROOT / "tests/controllers/misbehaving.py"
    situation = sitgen.generate_situation({"terrain": {"preset": "open_field"}}, seed=1)

    def driven() -> sitgen.RunRecord:
        spec = {
            "time_limit_s": 4.0,
            "controller": {"name": f"cmd:{sys.executable} {program} stopped {marker}",
                           "step_timeout_s": 0.2},
        }  # fmt: skip
        return sitgen.run(situation, spec=spec)

    stopped = driven()
    assert marker.exists(), "the first try was stopped"
    assert stopped.outcome != "error", stopped.reason
    again = driven()  # the marker is there: not stopped
    assert (stopped.outcome, stopped.events_jsonl) == (again.outcome, again.events_jsonl)
    assert stopped.trajectory.tobytes() == again.trajectory.tobytes()
