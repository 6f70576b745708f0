"""`sitgen diff` end to end: a real fault shows robust new failures and exits 1, a 1e-5 nudge
shows none and exits 0, JUnit for CI, the same verdicts whatever the worker count, resuming
after SIGKILL, stored situations, and bad input as one-line errors."""

from __future__ import annotations

import json
import signal
import sqlite3
import subprocess
import time
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

import pytest

from sitgen.generation.diff import BOTH, FIXED, NEW, NOT_ROBUST, UNCHANGED, parse_controller
from tests.conftest import run_cli, sitgen_command

N = "32"
HALVED = "snd_follow+safety_distance_halved"
NUDGED = '{"name": "snd_follow", "params": {"max_speed": 0.499995}}'


def diff_json(db: Path, *args: str) -> tuple[int, dict[str, Any]]:
    done = run_cli("diff", "--n", N, "--seed", "1", "--db", str(db), "--format", "json", *args)
    assert done.returncode in (0, 1), done.stderr
    report: dict[str, Any] = json.loads(done.stdout)
    return done.returncode, report


@pytest.fixture(scope="module")
def halved(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, int, dict[str, Any]]:
    folder = tmp_path_factory.mktemp("diff")
    db = folder / "halved.db"
    code, report = diff_json(db, "--b", HALVED, "--junit", str(folder / "junit.xml"))
    return db, code, report


def test_a_real_fault_has_robust_new_failures_and_fails_the_command(
    halved: tuple[Path, int, dict[str, Any]],
) -> None:
    db, code, report = halved
    assert code == 1
    assert report["robust_new"] >= 1
    assert report["b"] == {"name": "snd_follow", "fault": "safety_distance_halved"}
    verdicts = {c["class"]: c["verdict"] for c in report["classes"]}
    assert set(verdicts.values()) <= {NEW, FIXED, BOTH, UNCHANGED, NOT_ROBUST}
    with sqlite3.connect(db) as c:
        rows = c.execute(
            "SELECT situation, failure_class, a_recurs, b_recurs, copies, verdict "
            "FROM diff_results WHERE verdict != 'unchanged'"
        ).fetchall()
    for situation, key, a, b, copies, verdict in rows:
        assert 0 <= a <= copies and 0 <= b <= copies and copies in (2, 4, 8)
        if verdict == NEW:
            assert b - a >= 6, (situation, key, a, b)
        if verdict == FIXED:
            assert a - b >= 6, (situation, key, a, b)
    new = [c for c in report["classes"] if c["new"]]
    assert len(new) == report["robust_new"]
    # Runs 2i and 2i + 1 are A and B on situation i.
    with sqlite3.connect(db) as c:
        controllers = dict(c.execute("SELECT id, controller FROM runs WHERE id < 4"))
    assert controllers == {0: "snd_follow", 1: HALVED, 2: "snd_follow", 3: HALVED}


def test_junit_has_a_failed_case_per_robust_new_failure(
    halved: tuple[Path, int, dict[str, Any]],
) -> None:
    db, _, report = halved
    suite = ElementTree.parse(db.parent / "junit.xml").getroot().find("testsuite")
    assert suite is not None
    cases = suite.findall("testcase")
    assert [c.get("name") for c in cases] == [c["class"] for c in report["classes"]]
    failed = [c.get("name") for c in cases if c.find("failure") is not None]
    assert failed == [c["class"] for c in report["classes"] if c["new"]]
    assert suite.get("failures") == str(len(failed))


def test_a_negligible_nudge_has_no_robust_new_failure_and_passes(tmp_path: Path) -> None:
    code, report = diff_json(tmp_path / "nudged.db", "--b", NUDGED)
    assert code == 0
    assert report["robust_new"] == 0
    assert not any(c["new"] for c in report["classes"])


def test_the_same_verdicts_whatever_the_workers_and_after_a_sigkill(
    halved: tuple[Path, int, dict[str, Any]], tmp_path: Path
) -> None:
    _, _, expected = halved
    _, one = diff_json(tmp_path / "one.db", "--b", HALVED, "--workers", "1")
    assert one == expected
    db = tmp_path / "killed.db"
    args = ["diff", "--n", N, "--seed", "1", "--db", str(db), "--b", HALVED, "--format", "json"]
    proc = subprocess.Popen([*sitgen_command(), *args], stdout=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and stored_runs(db) < 20:
            time.sleep(0.05)
        assert proc.poll() is None, "killed part way, not after the end"
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    _, resumed = diff_json(db, "--b", HALVED)
    assert resumed == expected


def stored_runs(db: Path) -> int:
    if not db.exists():
        return 0
    try:
        with sqlite3.connect(db, timeout=5) as c:
            return int(c.execute("SELECT count(*) FROM runs").fetchone()[0])
    except sqlite3.OperationalError:
        return 0


def test_stored_situations_are_diffed_as_they_were_run(tmp_path: Path) -> None:
    campaign = tmp_path / "campaign.db"
    assert run_cli("campaign", "--n", "8", "--seed", "2", "--db", str(campaign)).returncode == 0
    code, report = diff_json(
        tmp_path / "stored.db", "--situations", str(campaign), "--b", NUDGED, "--n", "8"
    )
    assert code == 0 and report["situations"] == 8


def test_bad_input_is_a_one_line_error(tmp_path: Path) -> None:
    db = tmp_path / "bad.db"
    for args, expected in [
        ((), "--b"),
        (("--b", "snd_follow+nope"), "--b: run.controller.fault: unknown fault `nope`"),
        (("--b", "{not json"), "--b: not a JSON controller table"),
        (("--b", "warp_drive"), "--b:"),
        (("--b", HALVED, "--format", "xml"), "--format"),
    ]:
        done = run_cli("diff", "--n", "2", "--db", str(db), *args)
        assert done.returncode == 2, (args, done.stdout, done.stderr)
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and expected in lines[0], (args, done.stderr)
    assert not db.exists()
    with pytest.raises(Exception, match="--a: expected a controller name"):
        parse_controller('{"params": {}}', "--a")


def test_the_report_shows_each_robust_difference_as_a_and_b_side_by_side(
    halved: tuple[Path, int, dict[str, Any]], tmp_path: Path
) -> None:
    db, _, report = halved
    out = tmp_path / "report"
    done = run_cli("report", str(db), "-o", str(out))
    assert done.returncode == 0, done.stderr
    index = (out / "index.html").read_text()
    section = index.split("<section id='diff'>")[1].split("</section>")[0]
    new = [c for c in report["classes"] if c["verdict"] in (NEW, BOTH)]
    assert new
    for c in new:
        first = next(p for p in c["pairs"] if p["verdict"] == NEW)
        situation = first["situation"]
        block = section.split(f"<h3>{c['description']}: ")[1].split("<h3>")[0]
        pair = block.split(f"<div class='pair' data-situation='{situation}'")[1]
        pair = pair.split("</div></div>")[0]
        assert pair.startswith(f" data-verdict='{NEW}'")
        # A's run is 2i, B's 2i + 1; both have a page and a figure beside each other.
        a, b = 2 * situation, 2 * situation + 1
        assert pair.index(f"run-{a}.png") < pair.index(f"run-{b}.png")
        assert (out / f"run-{a}.html").is_file() and (out / f"run-{b}.html").is_file()
        assert f"A {first['a_recurs']}/{first['copies']}, B {first['b_recurs']}/" in pair


@pytest.mark.parametrize("b", ["cmd:/bin/false", "cmd:/no/such/program"])
def test_a_b_that_cannot_run_fails_the_gate_and_says_why(tmp_path: Path, b: str) -> None:
    """A regression gate must not pass a B that never ran: its table is empty and it has no
    new failure class, yet the command fails and JUnit holds a failed case with B's reason."""
    junit = tmp_path / "junit.xml"
    done = run_cli(
        "diff", "--a", "snd_follow", "--b", b, "--n", "3", "--db", str(tmp_path / "d.db"),
        "--junit", str(junit), "--format", "json",
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    report = json.loads(done.stdout)
    assert report["failed"] and report["both_ran"] == 0 and report["robust_new"] == 0
    assert [e["situation"] for e in report["b_errors"]] == [0, 1, 2]
    suite = ElementTree.parse(junit).getroot().find("testsuite")
    assert suite is not None and suite.get("failures") == "1"
    case = suite.find("testcase[@name='controller_error']/failure")
    assert case is not None and "B could not run on 3 situation(s) where A ran" in (case.text or "")


def test_diff_s_workers_are_capped_as_everywhere(tmp_path: Path) -> None:
    db = tmp_path / "d.db"
    done = run_cli("diff", "--b", "vo", "--n", "2", "--workers", "1000", "--db", str(db))
    assert done.returncode == 2 and done.stderr.startswith("error: --workers: 1000 is not in")
    assert not db.exists()


def test_an_a_that_cannot_run_somewhere_is_said_per_side_and_fails_the_gate(
    tmp_path: Path,
) -> None:
    """A that errs where B runs: the situation is not compared, the summary, JSON and JUnit
    say which side could not run where, and the gate does not pass on fewer situations."""
    junit = tmp_path / "junit.xml"
    done = run_cli(
        "diff", "--a", "cmd:/bin/false", "--b", "snd_follow", "--n", "2",
        "--db", str(tmp_path / "d.db"), "--junit", str(junit), "--format", "json",
    )  # fmt: skip
    assert done.returncode == 1, done.stdout + done.stderr
    report = json.loads(done.stdout)
    assert report["failed"] and report["b_errors"] == []
    assert [e["situation"] for e in report["not_compared"]["a"]] == [0, 1]
    assert report["not_compared"]["b"] == [] and not report["partial"]
    suite = ElementTree.parse(junit).getroot().find("testsuite")
    assert suite is not None
    case = suite.find("testcase[@name='not_compared_a']/failure")
    assert case is not None and "2 situation(s): 0, 1" in (case.text or ""), case
    table = run_cli(
        "diff", "--a", "cmd:/bin/false", "--b", "snd_follow", "--n", "2",
        "--db", str(tmp_path / "d.db"),
    )  # fmt: skip
    assert table.returncode == 1 and "not compared: A could not run on 2 situation(s)" in (
        table.stdout
    ), table.stdout


def test_a_diff_over_fewer_situations_than_asked_does_not_pass(tmp_path: Path) -> None:
    """A store whose diff was asked for more situations than it evaluated (stopped early) reads
    as partial and failed, whatever its differences."""
    from sitgen.generation.diff_report import diff_report
    from sitgen.store import Store

    db = tmp_path / "d.db"
    done = run_cli("diff", "--a", "snd_follow", "--b", "snd_follow", "--n", "2", "--db", str(db))
    assert done.returncode == 0, done.stdout + done.stderr
    with Store(db) as store:
        assert not diff_report(store).failed
        with store.db:
            store.db.execute("UPDATE campaign SET n = 5 WHERE id = 1")
        report = diff_report(store)
    assert report.partial and report.failed and report.asked == 5


def test_b_param_gives_one_side_a_parameter_as_a_json_table_does(tmp_path: Path) -> None:
    """``--b-param max_speed=0.499995`` is the JSON table of the nudge test, written the short
    way: the same report; ``--reruns`` below what the test can decide on is refused."""
    code, by_flag = diff_json(tmp_path / "flag.db", "--b", "snd_follow", "--b-param",
                              "max_speed=0.499995", "--reruns", "8")  # fmt: skip
    assert code == 0
    assert by_flag["b"] == json.loads(NUDGED)
    too_few = run_cli("diff", "--b", "vo", "--reruns", "3", "--db", str(tmp_path / "few.db"))
    assert too_few.returncode == 2 and "--reruns: 3 is not in [7, 1000]" in too_few.stderr
    assert not (tmp_path / "few.db").exists()
