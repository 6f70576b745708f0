"""Campaigns end to end through the CLI: results independent of the worker count and the
backend, resumable after SIGKILL and Ctrl-C, bad specs refused before any run, failing
controllers confined to their runs, and reruns that reproduce a stored run."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sitgen.execution.jobs import build_jobs, parse_campaign
from tests.conftest import ROOT, run_cli, sitgen_command

SMALL = """
n = 8
[situation.terrain]
preset = "rocky_desert"
[situation.mission]
peers_min = 0
peers_max = 3
min_route_length_m = 8.0
[run]
time_limit_s = 60.0
[vary]
"situation.terrain.preset" = { choice = ["open_field", "rocky_desert", "caves"] }
"situation.terrain.width_m" = { uniform = [16.0, 24.0] }
"situation.terrain.height_m" = { uniform = [16.0, 24.0] }
"situation.terrain.filters.coverage.target" = { scale = [0.8, 1.2] }
"""


def write_spec(tmp_path: Path, text: str = SMALL, name: str = "campaign.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def ranking(db: Path) -> list[dict[str, object]]:
    done = run_cli("rank", str(db), "--top", "1000", "--format", "json")
    assert done.returncode == 0, done.stderr
    rows: list[dict[str, object]] = json.loads(done.stdout)
    return rows


def event_logs(db: Path) -> dict[int, str]:
    with sqlite3.connect(db) as c:
        return dict(c.execute("SELECT id, events_jsonl FROM runs"))


def test_a_small_campaign_gives_the_same_results_on_one_and_two_workers(tmp_path: Path) -> None:
    spec = write_spec(tmp_path)
    one, two = tmp_path / "one.db", tmp_path / "two.db"
    a = run_cli("campaign", str(spec), "--db", str(one), "--seed", "3", "--workers", "1")
    assert a.returncode == 0, a.stderr
    assert "8 runs in" in a.stdout and "under 10 points" in a.stdout
    b = run_cli("campaign", str(spec), "--db", str(two), "--seed", "3", "--workers", "2")
    assert b.returncode == 0, b.stderr
    assert ranking(one) == ranking(two)
    assert event_logs(one) == event_logs(two)
    rows = ranking(one)
    assert len(rows) == 8
    scores = [float(str(r["score"])) for r in rows]
    assert scores == sorted(scores, reverse=True)
    assert {r["terrain"] for r in rows} <= {"open_field", "rocky_desert", "caves"}
    # Running it again does nothing more and changes nothing.
    again = run_cli("campaign", str(spec), "--db", str(one), "--seed", "3")
    assert "0 runs in" in again.stdout and ranking(one) == rows
    # The store has every table filled and a trajectory per run.
    with sqlite3.connect(one) as c:
        assert c.execute("SELECT count(*) FROM trajectories").fetchone()[0] == 8
        assert c.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        events = c.execute("SELECT count(*) FROM events").fetchone()[0]
    assert events == sum(len(log.splitlines()) for log in event_logs(one).values())


def test_rerun_reproduces_a_stored_run_and_export_writes_every_table(tmp_path: Path) -> None:
    spec = write_spec(tmp_path)
    db = tmp_path / "c.db"
    assert run_cli("campaign", str(spec), "--db", str(db), "--n", "3").returncode == 0
    done = run_cli("rerun", str(db), "2")
    assert done.returncode == 0, done.stdout + done.stderr
    assert "event log identical" in done.stdout and "score identical" in done.stdout
    for fmt in ("csv", "parquet"):
        out = run_cli("export", str(db), "--format", fmt, "-o", str(tmp_path / fmt))
        assert out.returncode == 0, out.stderr
        assert sorted(p.name for p in (tmp_path / fmt).iterdir()) == sorted(
            f"{t}.{fmt}"
            for t in (
                "campaign",
                "situations",
                "runs",
                "run_costs",
                "events",
                "trajectories",
                "judgements",
                "requirement_verdicts",
                "requirement_robustness",
                "avoidability",
                "descriptors",
                # Written where a run failed: these three runs do.
                "run_descriptors",
            )
        )
    import pyarrow.parquet as pq

    runs = pq.read_table(tmp_path / "parquet" / "runs.parquet")
    assert runs.num_rows == 3 and "score" in runs.column_names
    # A tampered store is caught.
    with sqlite3.connect(db) as c:
        c.execute("UPDATE runs SET score = score + 1 WHERE id = 2")
    done = run_cli("rerun", str(db), "2")
    assert done.returncode == 1 and "score DIFFERS" in done.stdout


def start_command(
    spec: Path, db: Path, *extra: str, command: str = "campaign"
) -> subprocess.Popen[str]:
    """``sitgen campaign`` (or another command that takes a spec and a store), in the
    background."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    return subprocess.Popen(
        [*sitgen_command(), command, str(spec), "--db", str(db), *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def wait_for_runs(db: Path, at_least: int, proc: subprocess.Popen[str]) -> int:
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with sqlite3.connect(db, timeout=5) as c:
                done = int(c.execute("SELECT count(*) FROM runs").fetchone()[0])
            if done >= at_least:
                return done
        except sqlite3.OperationalError:
            pass
        time.sleep(0.05)
    raise AssertionError(f"the campaign did not store {at_least} runs in time")


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGINT])
def test_an_interrupted_campaign_resumes_to_the_same_table(tmp_path: Path, how: int) -> None:
    spec = write_spec(tmp_path, SMALL.replace("n = 8", "n = 16"))
    reference = tmp_path / "reference.db"
    assert run_cli("campaign", str(spec), "--db", str(reference), "--seed", "5").returncode == 0
    db = tmp_path / "interrupted.db"
    proc = start_command(spec, db, "--seed", "5", "--workers", "1")
    stored = wait_for_runs(db, 3, proc)
    proc.send_signal(how)
    out, _ = proc.communicate(timeout=120)
    if how == signal.SIGINT:
        assert proc.returncode == 130, out
        assert "stopped early" in out
    with sqlite3.connect(db) as c:
        kept = int(c.execute("SELECT count(*) FROM runs").fetchone()[0])
    assert stored <= kept < 16
    done = run_cli("campaign", str(spec), "--db", str(db), "--seed", "5")
    assert done.returncode == 0, done.stderr
    assert f"{16 - kept} runs in" in done.stdout
    assert ranking(db) == ranking(reference)
    assert event_logs(db) == event_logs(reference)


def test_a_bad_campaign_spec_fails_before_any_run(tmp_path: Path) -> None:
    cases = {
        "situation.terrain.width_m": SMALL.replace("[16.0, 24.0] }", "[-5.0, -1.0] }", 1),
        "situation.mission.peers": SMALL + '"situation.mission.peers" = { int = [0, 3] }\n',
        "vary.'situation.terrain.preset'.choice": SMALL.replace(
            '{ choice = ["open_field", "rocky_desert", "caves"] }', "{ choice = [] }"
        ),
        "run.monitor.unsafe_proximity_m": SMALL + "[run.monitor]\nunsafe_proximity_m = 0\n",
        "colour": "colour = 3\n" + SMALL,
    }
    for k, (field, text) in enumerate(cases.items()):
        db = tmp_path / f"bad{k}.db"
        done = run_cli("campaign", str(write_spec(tmp_path, text)), "--db", str(db))
        assert done.returncode == 2, (field, done.stdout, done.stderr)
        message = done.stderr.strip()
        assert message.startswith("error: ") and field in message, (field, message)
        assert "\n" not in message
        if db.exists():
            with sqlite3.connect(db) as c:
                assert c.execute("SELECT count(*) FROM sqlite_master WHERE name='runs'").fetchone()
                assert c.execute("SELECT count(*) FROM runs").fetchone()[0] == 0


def test_a_controller_that_crashes_in_some_runs_leaves_error_outcomes_there(
    tmp_path: Path,
) -> None:
    program = f"{sys.executable} {ROOT / 'tests' / 'controllers' / 'misbehaving.py'} sometimes"
    text = SMALL + f'[run.controller]\nname = "cmd:{program}"\n'
    db = tmp_path / "crashy.db"
    done = run_cli("campaign", str(write_spec(tmp_path, text)), "--db", str(db), "--workers", "2")
    assert done.returncode == 0, done.stderr
    rows = ranking(db)
    assert len(rows) == 8
    errors = [r for r in rows if r["outcome"] == "error"]
    assert 0 < len(errors) < 8, [r["outcome"] for r in rows]
    assert all("exited with code 4 on reset" in str(r["reason"]) for r in errors)
    assert {r["outcome"] for r in rows if r not in errors} <= {"completed", "timeout"}


def test_jobs_are_a_function_of_the_seed_and_their_index() -> None:
    spec = parse_campaign(SMALL)
    first = build_jobs(spec, 11, 8)
    assert build_jobs(spec, 11, 4) == first[:4]
    assert build_jobs(spec, 12, 8) != first
    assert len({j.seed for j in first}) == 8


def test_the_ray_backend_gives_the_local_ranking(tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="ray is an optional dependency (sitgen[ray])")
    spec = write_spec(tmp_path, SMALL.replace("n = 8", "n = 6"))
    local, remote = tmp_path / "local.db", tmp_path / "ray.db"
    assert run_cli("campaign", str(spec), "--db", str(local), "--seed", "9").returncode == 0
    done = run_cli(
        "campaign", str(spec), "--db", str(remote), "--seed", "9", "--backend", "ray",
        "--workers", "2",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert ranking(remote) == ranking(local)
    assert event_logs(remote) == event_logs(local)


def test_a_campaign_stopped_early_writes_junit_and_a_summary_marked_partial(
    tmp_path: Path,
) -> None:
    """CI that stops a campaign (Ctrl-C, a job's timeout's SIGINT) still gets its JUnit and
    summary, and neither looks final: a failed ``partial`` case, ``partial`` in the summary,
    and exit code 130."""
    from xml.etree import ElementTree

    spec = write_spec(tmp_path, SMALL.replace("n = 8", "n = 200"))
    db, junit, summary = tmp_path / "c.db", tmp_path / "c.xml", tmp_path / "c.json"
    proc = start_command(spec, db, "--workers", "1", "--junit", str(junit), "--summary",
                         str(summary))  # fmt: skip
    wait_for_runs(db, 3, proc)
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, out
    suite = ElementTree.parse(junit).getroot().find("testsuite")
    assert suite is not None
    partial = [c for c in suite.iter("testcase") if c.get("name") == "partial"]
    assert len(partial) == 1 and partial[0].find("failure") is not None
    figures = json.loads(summary.read_text())
    assert figures["partial"] is True and figures["asked"] == 200
    assert 3 <= figures["stored"] < 200


def test_a_long_campaign_prints_progress_lines_when_not_on_a_terminal(tmp_path: Path) -> None:
    """Off a terminal (a CI log) a campaign says how far it is, a line every few percent with
    its rate and time left (here from the start: ``SITGEN_PROGRESS_AFTER_S=0``)."""
    spec = write_spec(tmp_path, SMALL.replace("n = 8", "n = 40"))
    done = subprocess.run(
        [*sitgen_command(), "campaign", str(spec), "--db", str(tmp_path / "p.db"), "--reruns", "0"],
        capture_output=True, text=True, timeout=300, check=False,
        env={**os.environ, "SITGEN_PROGRESS_AFTER_S": "0"},
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.startswith("campaign: ")]
    assert len(lines) >= 10 and lines[-1].startswith("campaign: 40/40 runs (100%)"), lines
    assert all("runs/s" in line for line in lines)
