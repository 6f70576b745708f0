"""Campaigns that keep only some runs whole (``--keep-trajectories``): which runs are kept,
what a summary holds, and that a summary's run comes back by re-simulation exactly as the
run was (the same log, the same trajectory), through ``show``, ``rerun`` and ``report``."""

from __future__ import annotations

import math
import sqlite3
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from sitgen.execution.campaign import Keep
from sitgen.store import RunRow, Store, StoreError
from sitgen.triage.recall import stored_run, whole_run
from tests.conftest import run_cli
from tests.test_campaign import SMALL, write_spec

SPEC = SMALL.replace("n = 8", "n = 12")


def campaign(tmp_path: Path, keep: str, name: str) -> Path:
    db = tmp_path / f"{name}.db"
    done = run_cli(
        "campaign", str(write_spec(tmp_path, SPEC)), "--db", str(db), "--seed", "4",
        "--workers", "2", "--keep-trajectories", keep,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return db


@pytest.fixture(scope="module")
def stores(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The same campaign kept ``all``, ``none``, ``top:3`` and ``failures``."""
    tmp = tmp_path_factory.mktemp("keep")
    return {keep: campaign(tmp, keep, keep.replace(":", "")) for keep in ("all", "none", "top:3")}


def table(db: Path, sql: str) -> list[tuple[object, ...]]:
    with sqlite3.connect(db) as c:
        return c.execute(sql).fetchall()


def test_top_k_keeps_exactly_the_k_best_runs_whole(stores: dict[str, Path]) -> None:
    db = stores["top:3"]
    ranked = [r[0] for r in table(db, "SELECT id FROM runs ORDER BY score DESC, id")]
    whole = {r[0] for r in table(db, "SELECT id FROM runs WHERE kept = 1")}
    assert whole == set(ranked[:3])
    assert {r[0] for r in table(db, "SELECT run_id FROM trajectories")} == whole
    assert {r[0] for r in table(db, "SELECT DISTINCT run_id FROM events")} <= whole
    # The summaries: no specs, situation, log or trajectory; what ranks and groups them stays.
    for spec, situation, run_spec, log, digest, content_hash in table(
        db,
        "SELECT s.spec, s.situation, r.run_spec, r.events_jsonl, r.events_sha256, "
        "s.content_hash FROM runs r JOIN situations s ON s.id = r.id WHERE r.kept = 0",
    ):
        assert (spec, situation, run_spec, log) == ("", None, "", "")
        assert isinstance(digest, str) and len(digest) == 64 and content_hash
    # Ranking and distinct failures read summaries as they read whole runs.
    assert table(db, "SELECT id, score, failure_class FROM runs ORDER BY id") == table(
        stores["all"], "SELECT id, score, failure_class FROM runs ORDER BY id"
    )


def test_a_summary_is_re_simulated_to_the_run_that_was_stored(stores: dict[str, Path]) -> None:
    with Store(stores["all"]) as full, Store(stores["none"]) as summary:
        for run_id in range(12):
            a, b = stored_run(full, run_id), stored_run(summary, run_id)
            kept, again = whole_run(full, a), whole_run(summary, b)
            assert kept is not None and again is not None
            assert not kept.resimulated and again.resimulated
            assert again.events_jsonl == kept.events_jsonl
            assert again.situation.content_hash == kept.situation.content_hash
            assert kept.trajectory is not None and again.trajectory is not None
            assert np.array_equal(again.trajectory, kept.trajectory)
            # The specs a summary's job is built again from are those the whole run stored.
            assert (a["situation_spec"], a["run_spec"]) == (b["situation_spec"], b["run_spec"])


def test_a_summary_that_re_simulates_differently_is_refused(
    stores: dict[str, Path], tmp_path: Path
) -> None:
    db = tmp_path / "tampered.db"
    db.write_bytes(stores["none"].read_bytes())
    with sqlite3.connect(db) as c:
        c.execute("UPDATE runs SET score = score + 1 WHERE id = 2")
    with Store(db) as store, pytest.raises(StoreError, match=r"run 2 .* different score"):
        whole_run(store, stored_run(store, 2))


def test_show_rerun_and_report_work_on_summaries(stores: dict[str, Path], tmp_path: Path) -> None:
    db = stores["none"]
    figure = tmp_path / "run.png"
    done = run_cli("show", str(db), "--run", "5", "-o", str(figure))
    assert done.returncode == 0, done.stderr
    assert figure.read_bytes().startswith(b"\x89PNG")
    done = run_cli("rerun", str(db), "5")
    assert done.returncode == 0, done.stderr
    assert "event log identical" in done.stdout
    out = tmp_path / "report"
    done = run_cli("report", str(db), "-o", str(out), "--top", "4")
    assert done.returncode == 0, done.stderr
    best = table(db, "SELECT id FROM runs ORDER BY score DESC, id LIMIT 4")
    for (run_id,) in best:
        assert (out / f"run-{run_id}.html").exists()
        assert (out / f"run-{run_id}.js").read_text().count("trajectory") >= 1


def test_failures_keeps_the_runs_with_a_failure_class(tmp_path: Path) -> None:
    db = campaign(tmp_path, "failures", "failures")
    rows = table(db, "SELECT kept, failure_class IS NOT NULL FROM runs")
    assert rows and all(kept == failed for kept, failed in rows)


@pytest.mark.parametrize("keep", ["top:0", "top:", "some", "top:-2", "all:3"])
def test_a_bad_keep_option_is_a_one_line_error(tmp_path: Path, keep: str) -> None:
    db = tmp_path / "bad.db"
    done = run_cli("campaign", "--n", "2", "--db", str(db), "--keep-trajectories", keep)
    assert done.returncode != 0
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "--keep-trajectories" in lines[0] and keep in lines[0]
    assert not db.exists()


def summary_row(run_id: int, score: float, failure: str | None = None) -> RunRow:
    record = {"score": {"total": score}, "failure": {"class": failure} if failure else None}
    return RunRow(
        id=run_id, situation_seed=0, situation_spec={}, situation_json=None, run_spec={},
        run_seed=0, controller="snd_follow", record=record, error=None, events_jsonl="",
        trajectory=None, robots=1,
    )  # fmt: skip


def test_top_k_pushes_out_the_lowest_ranked_and_raises_the_packing_bar() -> None:
    keep = Keep("top:2")
    assert keep.pack_rule() == (-math.inf, False)
    kept = [keep.admit(summary_row(i, s)) for i, s in enumerate([5.0, 9.0, 1.0, 7.0, 9.0])]
    # 5 and 9 fill it; 1 is below both; 7 pushes 5 out; the second 9 ties the first but ranks
    # after it (id order), and pushes 7 out.
    assert [(row.keep, out) for row, out in kept] == [
        (True, []), (True, []), (False, []), (True, [0]), (True, [3]),
    ]  # fmt: skip
    assert keep.pack_rule() == (9.0, False)


def test_the_other_modes_admit_as_they_say() -> None:
    assert Keep("all").admit(summary_row(0, 0.0))[0].keep
    assert not Keep("none").admit(summary_row(0, 1e6))[0].keep
    failures = Keep("failures")
    assert failures.admit(summary_row(0, 0.0, "drove_into_wall"))[0].keep
    assert not failures.admit(summary_row(1, 1e6))[0].keep
    assert failures.pack_rule() == (math.inf, True)
    assert Keep("none").pack_rule() == (math.inf, False)
    # A run that could not be run is kept whole whatever the mode: there is nothing to re-run.
    error = replace(summary_row(2, 0.0), record=None, error="generation failed")
    assert Keep("none").admit(error)[0].keep
