"""Seeded faults and their kill rate: the kill rule on constructed records, `sitgen faults` end
to end (JSON, worker count, resuming after a kill, the report), bad fault ids, and the
controllers left byte-identical without a fault."""

from __future__ import annotations

import hashlib
import json
import signal
import sqlite3
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sitgen import _core
from sitgen.execution.jobs import build_job, parse_campaign
from sitgen.generation.faults import RUN_STRIDE, fault_slot, faults_of
from sitgen.triage.kill import (
    ALPHA,
    COPIES,
    KILL_MARGIN_POINTS,
    MUTANTS,
    STAGES,
    Event,
    Outcome,
    p_value,
    score_margin,
    verdict,
)
from sitgen.triage.kill import screen as kill
from tests.conftest import ROOT, run_cli
from tests.test_campaign import SMALL, start_command, wait_for_runs, write_spec

# --- the kill rule, on constructed records


def outcome(failure: str | None, *others: str, score: float = 0.0) -> Outcome:
    """A run failing with ``failure`` whose events also show ``others``."""
    return Outcome(failure, frozenset(others) | ({failure} if failure else set()), score)


def test_a_failure_class_the_correct_run_does_not_show_kills() -> None:
    correct = outcome("approached_by_peer", score=12.0)
    faulty = outcome("drove_into_seen_peer", "approached_by_peer", score=130.0)
    k = kill(correct, faulty)
    assert k is not None and k.by == "class"
    assert k.classes == ("drove_into_seen_peer",) and k.score_delta == 118.0
    # Worse than a run without any failure: a kill too.
    k = kill(outcome(None), outcome("oscillated_beside_wall", score=25.0))
    assert k is not None and k.by == "class"


def test_a_class_the_correct_run_shows_even_as_a_lesser_event_does_not_kill() -> None:
    correct = outcome("struck_while_stopped_seen", "oscillated_beside_wall", score=400.0)
    faulty = outcome("oscillated_beside_wall", score=60.0)
    assert kill(correct, faulty) is None
    # Nor does a faulty run with fewer failures, or none.
    assert kill(correct, outcome(None)) is None


def test_a_worse_score_kills_only_beyond_the_margin() -> None:
    correct = outcome("struck_while_stopped_seen", score=1000.0)
    margin = score_margin(1000.0)
    assert margin == 500.0  # half the correct score, above the 100-point floor
    same = "struck_while_stopped_seen"
    assert kill(correct, outcome(same, score=1000.0 + margin)) is None
    k = kill(correct, outcome(same, score=1000.0 + margin + 1))
    assert k is not None and k.by == "score" and k.classes == (same,)
    # A small correct score: the floor holds.
    assert score_margin(10.0) == KILL_MARGIN_POINTS
    assert kill(outcome(None, score=10.0), outcome(None, score=110.0)) is None
    assert kill(outcome(None, score=10.0), outcome(None, score=110.5)) is not None


def test_errors_kill_only_on_the_faulty_side() -> None:
    broken = Outcome(None, frozenset(), 0.0, error=True)
    assert kill(broken, outcome("drove_into_wall", score=500.0)) is None
    k = kill(outcome(None), broken)
    assert k is not None and k.by == "error"


# --- the robust kill rule: the test on perturbed copies, its early stopping, the mutants


def test_the_level_needs_near_perfect_separation_of_eight_copies() -> None:
    assert p_value(8, 0, 8) <= ALPHA and p_value(8, 1, 8) <= ALPHA and p_value(7, 0, 8) <= ALPHA
    assert p_value(7, 1, 8) > ALPHA and p_value(6, 0, 8) > ALPHA and p_value(8, 2, 8) > ALPHA
    # Alike counts never kill, however many.
    assert all(p_value(n, n, 8) > 0.4 for n in range(9))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), min_size=COPIES, max_size=COPIES))
def test_early_stopping_gives_the_full_tests_verdict(copies: list[tuple[bool, bool]]) -> None:
    """Curtailment: the verdict at the first look that has one is the verdict of all eight."""
    faulty, correct = sum(f for f, _ in copies), sum(c for _, c in copies)
    full = p_value(faulty, correct, COPIES) <= ALPHA
    assert verdict(faulty, correct, COPIES) is full
    for look in STAGES:
        f = sum(x for x, _ in copies[:look])
        c = sum(y for _, y in copies[:look])
        early = verdict(f, c, look)
        if early is not None:
            assert early is full, (look, f, c)
            break


def test_the_event_a_copy_is_judged_by_is_the_screens_difference() -> None:
    correct = outcome("approached_by_peer", score=12.0)
    by_class = Event("class", "drove_into_seen_peer")
    assert by_class.shown(outcome("drove_into_seen_peer", score=1.0))
    assert not by_class.shown(outcome("approached_by_peer", "drove_into_seen_peer"))
    by_score = Event("score", threshold=correct.score + score_margin(correct.score))
    assert by_score.shown(outcome(None, score=112.5)) and not by_score.shown(
        outcome(None, score=112)
    )
    broken = Outcome(None, frozenset(), 0.0, error=True)
    assert Event("error").shown(broken) and not by_score.shown(broken)


def test_equivalent_mutants_nudge_a_parameter_by_at_most_1e_5() -> None:
    assert len(MUTANTS) >= 5
    for m in MUTANTS:
        assert 0 < abs(m.factor - 1) <= 1e-5 * (1 + 1e-9)
        nudged = m.params({})[m.param]
        assert nudged != m.default and abs(nudged / m.default - 1) <= 1e-5 * (1 + 1e-9)
        assert m.params({m.param: 2.0})[m.param] == 2.0 * m.factor
        # The core takes the nudged controller.
        _core.check_run_spec(
            json.dumps({"controller": {"name": m.controllers[-1], "params": m.params({})}})
        )


# --- without a fault, every controller is unchanged


def test_without_a_fault_event_logs_are_byte_identical_to_the_checked_in_digests() -> None:
    """The digests were taken before faults existed: paper campaign seed 7, jobs 0-5, each
    built-in controller that has faults."""
    expected: dict[str, str] = json.loads(
        (ROOT / "tests" / "data" / "unfaulted_event_logs.json").read_text()
    )
    spec = parse_campaign(None)
    args = []
    for key in sorted(expected):
        controller, i = key.split("/")
        job = build_job(spec, 7, int(i))
        run = dict(job.run, controller={"name": controller})
        args.append((json.dumps(job.situation), job.seed, json.dumps(run), job.seed))
    results = _core.run_jobs(args, 2)
    got = [hashlib.sha256(r["events_jsonl"].encode()).hexdigest() for r in results]
    assert got == [expected[key] for key in sorted(expected)]


# --- the command

SPEC = SMALL.replace("n = 8", "n = 20")
FAULTS = "mirrored_scan,sector_off_by_one,inside_radius_stop_removed"


def evaluate(tmp_path: Path, db: Path, *extra: str) -> dict[str, Any]:
    spec = write_spec(tmp_path, SPEC)
    done = run_cli(
        "faults", str(spec), "--budget", "20", "--seed", "2", "--db", str(db),
        "--faults", FAULTS, "--format", "json", *extra,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return report


def stored_runs(db: Path) -> dict[int, tuple[str, str]]:
    with sqlite3.connect(db) as c:
        return {
            i: (ctrl, log)
            for i, ctrl, log in c.execute("SELECT id, controller, events_jsonl FROM runs")
        }


@pytest.fixture(scope="module")
def reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    tmp = tmp_path_factory.mktemp("faults")
    db = tmp / "reference.db"
    return db, evaluate(tmp, db, "--workers", "1")


def stored_runs_count(db: Path) -> int:
    with sqlite3.connect(db) as c:
        return int(c.execute("SELECT count(*) FROM runs").fetchone()[0])


def test_the_json_report_gives_each_fault_and_the_kill_rate(
    reference: tuple[Path, dict[str, Any]],
) -> None:
    db, report = reference
    assert report["controller"] == "snd_follow" and report["situations"] == 20
    # In catalogue order, whatever order --faults gave.
    assert [f["id"] for f in report["faults"]] == sorted(FAULTS.split(","), key=fault_slot)
    killed = [f for f in report["faults"] if f["killed"]]
    assert report["kill_rate"] == len(killed) / 3
    assert killed, "a mirrored scan is killed within 20 situations"
    curve = report["curve"]
    assert curve[-1] == {"budget": 20, "kill_rate": report["kill_rate"]}
    assert [c["kill_rate"] for c in curve] == sorted(c["kill_rate"] for c in curve)
    # What the kill rule cost: every candidate test, by the copies a side it ran before it
    # decided, and the copies among all runs.
    tests = {int(k): v for k, v in report["tests_by_copies"].items()}
    assert set(tests) <= {2, 4, 8} and sum(tests.values()) >= len(killed)
    assert report["runs"] == stored_runs_count(db) + report["perturbed_copies"]
    # Each test ran its faulty copies; a correct copy serves every arm tested on its situation.
    faulty_copies = sum(k * v for k, v in tests.items())
    assert 0 < faulty_copies <= report["perturbed_copies"] <= 2 * faulty_copies
    runs = stored_runs(db)
    with sqlite3.connect(db) as c:
        classes = dict(c.execute("SELECT id, failure_class FROM runs"))
        scores = dict(c.execute("SELECT id, score FROM runs"))
    for f in report["faults"]:
        if not f["killed"]:
            assert f["runs_to_first_kill"] is None and not f["possibly_equivalent"]
            # Run on every situation, and never killed.
            situations = [i for i in range(20) if i * RUN_STRIDE + fault_slot(f["id"]) in runs]
            assert situations == list(range(20))
            continue
        n = f["runs_to_first_kill"]
        situation = n - 1
        assert f["run"] == situation * RUN_STRIDE + fault_slot(f["id"])
        assert f["correct_run"] == situation * RUN_STRIDE
        assert runs[f["run"]][0] == f"snd_follow+{f['id']}"
        correct_log = runs[f["correct_run"]][1]
        shown = set(_core.event_classes(correct_log, 0))
        if f["by"] == "class":
            assert f["classes"] == [classes[f["run"]]] and classes[f["run"]] not in shown
        else:
            assert f["by"] == "score"
            assert scores[f["run"]] - scores[f["correct_run"]] > score_margin(
                scores[f["correct_run"]]
            )
        # Not run after the chunk it was killed in.
        later = [i for i in range(20) if i * RUN_STRIDE + fault_slot(f["id"]) in runs]
        assert max(later) < (situation // 16 + 1) * 16


def test_the_same_results_and_runs_whatever_the_worker_count(
    tmp_path: Path, reference: tuple[Path, dict[str, Any]]
) -> None:
    db, report = reference
    two = tmp_path / "two.db"
    assert evaluate(tmp_path, two, "--workers", "2") == report
    assert stored_runs(two) == stored_runs(db)


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGINT])
def test_an_evaluation_killed_part_way_resumes_to_the_same_results(
    tmp_path: Path, reference: tuple[Path, dict[str, Any]], how: int
) -> None:
    db, report = reference
    spec = write_spec(tmp_path, SPEC)
    resumed = tmp_path / "resumed.db"
    args = ("--budget", "20", "--seed", "2", "--faults", FAULTS, "--workers", "1")
    proc = start_command(spec, resumed, *args, command="faults")
    wait_for_runs(resumed, 5, proc)
    proc.send_signal(how)
    _, err = proc.communicate(timeout=120)
    if how == signal.SIGINT:
        assert proc.returncode == 130 and "stopped early" in err, err
    assert evaluate(tmp_path, resumed) == report
    assert stored_runs(resumed) == stored_runs(db)


def test_a_report_of_an_evaluation_shows_its_faults(
    tmp_path: Path, reference: tuple[Path, dict[str, Any]]
) -> None:
    db, report = reference
    out = tmp_path / "report"
    done = run_cli("report", str(db), "-o", str(out))
    assert done.returncode == 0, done.stderr
    index = (out / "index.html").read_text()
    assert "id='faults'" in index
    for f in report["faults"]:
        assert f"data-fault='{f['id']}'" in index
        if f["killed"]:
            assert (out / f"run-{f['run']}.html").exists()
            assert (out / f"run-{f['correct_run']}.html").exists()


def test_bad_fault_ids_and_stores_are_one_line_errors(
    tmp_path: Path, reference: tuple[Path, dict[str, Any]]
) -> None:
    spec = write_spec(tmp_path, SPEC)
    db = tmp_path / "bad.db"

    def error(*args: str) -> str:
        done = run_cli("faults", str(spec), "--budget", "2", "--db", str(db), *args)
        assert done.returncode == 2, done.stdout + done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        return lines[0]

    assert error("--faults", "nope").startswith("error: --faults: unknown fault `nope`")
    assert error("--faults", "vo_static_peers").startswith(
        "error: --faults: `vo_static_peers` is not a fault of `snd_follow`"
    )
    assert error("--strategy", "psychic").startswith("error: --strategy: `psychic`")
    assert not db.exists()
    # A campaign's store is not an evaluation's, nor the other way round.
    held, _ = reference
    line = error("--faults", "mirrored_scan", "--db", str(held))
    assert "holds another fault evaluation" in line
    campaign = tmp_path / "campaign.db"
    assert run_cli("campaign", str(spec), "--n", "1", "--db", str(campaign)).returncode == 0
    assert "holds a campaign, not a fault evaluation" in error("--db", str(campaign))
    assert "holds a fault evaluation, not a campaign" in (
        run_cli("campaign", str(spec), "--n", "1", "--db", str(held)).stderr
    )


@pytest.mark.parametrize(
    ("controller", "fault", "message"),
    [
        ("snd_follow", "teleport", "run.controller.fault: unknown fault `teleport`"),
        ("follow", "stale_scan", "run.controller.fault: `stale_scan` is not a fault of"),
        ("vo", "dwa_point_robot", "run.controller.fault: `dwa_point_robot` is not a fault of"),
    ],
)
def test_a_run_spec_naming_a_fault_its_controller_lacks_is_a_one_line_error(
    tmp_path: Path, controller: str, fault: str, message: str
) -> None:
    spec = write_spec(
        tmp_path, SPEC + f'[run.controller]\nname = "{controller}"\nfault = "{fault}"\n'
    )
    done = run_cli("campaign", str(spec), "--n", "1", "--db", str(tmp_path / "c.db"))
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [done.stderr.strip()]
    assert message in done.stderr


def test_every_controller_with_avoidance_has_its_faults() -> None:
    assert len(faults_of("snd_follow")) >= 10 and len(faults_of("snd")) >= 10
    assert len(faults_of("vo")) >= 2 and len(faults_of("dwa")) >= 2
    assert faults_of("straight") == [] and faults_of("follow") == []
    # Run ids leave room for the correct run and every fault of the catalogue.
    assert len(_core.fault_catalogue()) < RUN_STRIDE


def test_the_documented_catalogue_is_the_catalogue() -> None:
    """docs/faults.md's table row for each fault gives the catalogue's own controllers and
    text, and lists no other fault."""
    doc = (ROOT / "docs" / "faults.md").read_text()
    table = doc.split("## The catalogue")[1].split("## The kill rule")[0]
    rows = {
        line.split("|")[1].strip().strip("`"): [c.strip() for c in line.split("|")[2:-1]]
        for line in table.splitlines()
        if line.startswith("| `")
    }
    catalogue = _core.fault_catalogue()
    assert sorted(rows) == sorted(f["id"] for f in catalogue)
    for f in catalogue:
        controllers, _seam, changes, stands_for, exposed_by = rows[f["id"]]
        assert controllers == ", ".join(f["controllers"]), f["id"]
        # The catalogue's text, with names of code set as code.
        assert (changes.replace("`", ""), stands_for) == (f["changes"], f["stands_for"]), f["id"]
        assert exposed_by == (f["exposed_by"] or "-"), f["id"]


def test_barn_worlds_are_a_strategy_of_their_own(tmp_path: Path, shared_data: Path) -> None:
    from sitgen.world.maps import barn_situation

    world = barn_situation(shared_data / "barn", 0)
    assert [r.role for r in world.robots] == ["agent"]
    assert world.agent.body["model"] == "jackal" and world.agent.waypoints[-1] == (2.25, 13.0)
    spec = write_spec(tmp_path, "[run]\ntime_limit_s = 100.0\n")
    db = tmp_path / "barn.db"
    args = ("faults", str(spec), "--strategy", "barn", "--budget", "3", "--db", str(db))
    done = run_cli(*args, "--barn-dir", str(shared_data / "barn"), "--format", "json")
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["strategy"] == "barn" and report["situations"] == 3
    with sqlite3.connect(db) as c:
        terrains = {t for (t,) in c.execute("SELECT terrain FROM situations")}
    assert terrains == {"given"}
    assert run_cli("rerun", str(db), "0").returncode == 0
    missing = run_cli(*args, "--barn-dir", str(tmp_path))
    assert missing.returncode == 2 and "--barn-dir:" in missing.stderr
    more = run_cli(*args[:-4], "--budget", "301", "--db", str(tmp_path / "x.db"))
    assert more.returncode == 2, more.stderr
