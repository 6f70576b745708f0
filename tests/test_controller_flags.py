"""One flag: every command that runs situations names the user's controller with
``--controller`` and gives it parameters with ``--param NAME=VALUE``, no spec file needed, and
the controller gets them (a class as keyword arguments, every controller in its reset info)."""

from __future__ import annotations

import json
import sqlite3
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_cli

TELLS = "python:tests.controllers.pycontrollers:TellsParams"
BRAKING = f"python:{ROOT / 'examples' / 'controllers' / 'braking.py'}:Braking"
SAID = "made with gain=2.5, k=1.0; told gain=2.5, k=1.0"


def stored(db: Path, sql: str) -> list[tuple[str, ...]]:
    """Rows of ``sql`` on store ``db``, every column as text."""
    with sqlite3.connect(db) as con:
        return [tuple(str(v) for v in row) for row in con.execute(sql)]


def test_run_and_check_controller_give_a_class_its_params(situation_file: Path) -> None:
    done = run_cli("run", str(situation_file), "--controller", TELLS, "-p", "gain=2.5", "-p", "k=1")
    assert done.returncode == 1 and SAID in done.stdout, done.stdout + done.stderr
    done = run_cli("check-controller", TELLS, "--param", "gain=2.5", "--param", "k=1")
    assert done.returncode == 1 and SAID in done.stdout, done.stdout + done.stderr


def test_a_campaign_takes_a_controller_and_params_without_a_spec(tmp_path: Path) -> None:
    db = tmp_path / "c.db"
    done = run_cli(
        "campaign", "--controller", TELLS, "--param", "gain=2.5", "--param", "k=1", "--n", "3",
        "--db", str(db), "--reruns", "0", cwd=ROOT,
    )  # fmt: skip
    # Every run is the controller's error, saying what it was given.
    assert done.returncode == 1, done.stderr
    reasons = [r for (r,) in stored(db, "SELECT reason FROM runs")]
    assert len(reasons) == 3 and all(SAID in r for r in reasons), reasons
    specs = [json.loads(s) for (s,) in stored(db, "SELECT run_spec FROM runs")]
    assert {s["controller"]["name"] for s in specs} == {TELLS}
    assert all(s["controller"]["params"] == {"gain": 2.5, "k": 1.0} for s in specs)


@pytest.mark.parametrize("strategy", ["random", "map-elites", "coverage", "mutation"])
def test_every_search_strategy_takes_a_controller(tmp_path: Path, strategy: str) -> None:
    db = tmp_path / "s.db"
    done = run_cli(
        "search", "--controller", BRAKING, "--param", "brake_m=1.0", "--strategy", strategy,
        "--budget", "4", "--seed", "1", "--reruns", "0", "--db", str(db),
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    specs = [json.loads(s) for (s,) in stored(db, "SELECT run_spec FROM runs")]
    assert len(specs) == 4
    assert all(s["controller"] == {"name": BRAKING, "params": {"brake_m": 1.0}} for s in specs)
    if strategy != "mutation":
        return
    # A directed search from one of its runs, and one toward a class, drive the same controller.
    (run_id, cls), *_ = stored(
        db, "SELECT id, failure_class FROM runs WHERE failure_class NOT NULL"
    )
    for how in (["--like", f"{db}:{run_id}"], ["--class", str(cls)]):
        more = tmp_path / f"more{how[0]}.db"
        done = run_cli(
            "search", "--strategy", "mutation", *how, "--controller", BRAKING, "--budget", "2",
            "--seed", "2", "--reruns", "0", "--db", str(more),
        )  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        names = {
            json.loads(s)["controller"]["name"]
            for (s,) in stored(more, "SELECT run_spec FROM runs")
        }
        assert names == {BRAKING}


def test_diff_gives_params_to_both_sides(tmp_path: Path) -> None:
    db = tmp_path / "d.db"
    b = json.dumps({"name": BRAKING, "params": {"brake_m": 1.2}})
    done = run_cli(
        "diff", "--a", BRAKING, "--b", b, "--param", "cone_deg=30", "--n", "3", "--db", str(db),
    )  # fmt: skip
    assert done.returncode in (0, 1), done.stdout + done.stderr
    given = {
        json.dumps(json.loads(s)["controller"]["params"], sort_keys=True)
        for (s,) in stored(db, "SELECT run_spec FROM runs")
    }
    assert given == {'{"cone_deg": 30.0}', '{"brake_m": 1.2, "cone_deg": 30.0}'}


def test_bad_controller_flags_are_one_line_errors(tmp_path: Path) -> None:
    done = run_cli("campaign", "--param", "gain", "--n", "1", "--db", str(tmp_path / "x.db"))
    assert done.returncode == 2 and "--param: `gain` is not NAME=VALUE" in done.stderr
    spec = tmp_path / "varied.toml"
    spec.write_text('[vary]\n"run.controller.name" = { choice = ["vo", "dwa"] }\n')
    done = run_cli("campaign", str(spec), "--controller", "follow", "--db", str(tmp_path / "y.db"))
    assert done.returncode == 2, done.stderr
    assert "--controller: the spec varies run.controller.name" in done.stderr
    done = run_cli("search", "--controller", "turbo", "--db", str(tmp_path / "z.db"))
    assert done.returncode == 2 and "--controller: unknown controller `turbo`" in done.stderr
    assert not (tmp_path / "x.db").exists() and not (tmp_path / "z.db").exists()


def test_the_default_search_runs_a_program_controller_on_one_worker(tmp_path: Path) -> None:
    """The case a pool worker once hung on (waiting on a lock its fork had copied locked)."""
    trivial = f"cmd:{sys.executable} {ROOT / 'benches' / 'trivial_cmd.py'}"
    db = tmp_path / "s.db"
    done = run_cli(
        "search", "--controller", trivial, "--budget", "3", "--seed", "2", "--workers", "1",
        "--reruns", "0", "--db", str(db),
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    assert len(stored(db, "SELECT id FROM runs")) == 3


def test_a_campaigns_stored_situations_name_the_controller_it_was_given(tmp_path: Path) -> None:
    """``--controller`` drives the agent and is what its stored situations say drives it."""
    db = tmp_path / "c.db"
    done = run_cli("campaign", "--controller", "vo", "--n", "2", "--db", str(db), "--reruns", "0")
    assert done.returncode in (0, 1), done.stdout + done.stderr
    with sqlite3.connect(db) as c:
        situations = [json.loads(s) for (s,) in c.execute("SELECT situation FROM situations")]
    assert [s["robots"][0]["controller"]["name"] for s in situations] == ["vo", "vo"]
