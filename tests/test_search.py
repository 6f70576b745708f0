"""Search: the archive on a synthetic objective, the variation's bounds, the same runs whatever
the worker count and however a search was interrupted, a budget that only truncates, random
search being the campaign, and a search's store through failures, report, rerun and faults."""

from __future__ import annotations

import json
import signal
import sqlite3
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sitgen import _core
from sitgen.execution.jobs import parse_campaign
from sitgen.generation.genome import OPERATORS, fresh, vary
from sitgen.generation.search import run_search
from sitgen.generation.search.archive import Archive
from sitgen.generation.search.elites import Elite, Elites
from sitgen.generation.search.plan import BATCH, INITIAL, SearchPlan, generation_of
from tests.conftest import open_page, run_cli
from tests.test_campaign import SMALL, start_command, wait_for_runs, write_spec

SEARCHED = SMALL.replace(
    '"situation.terrain.filters',
    '"situation.mission.min_route_length_m" = '
    '{ uniform = [6.0, 10.0] }\n"situation.terrain.filters',
)
"""A small campaign spec with a choice, reals, a scale and a mission gene."""
BUDGET = INITIAL + 2 * BATCH
ELITES = SearchPlan("map-elites")
"""These tests are MAP-Elites' (the default strategy, mutation, is tested in test_mutation)."""
"""Generation 0 and two generations of variation."""


def spec_of(text: str = SEARCHED) -> Any:
    return parse_campaign(text)


def stored(db: Path) -> list[tuple[Any, ...]]:
    """Every run as the search made it: id, generation, parents, genes, situation, log, score."""
    with sqlite3.connect(db) as c:
        return c.execute(
            "SELECT r.id, r.generation, r.parents, r.genes, s.content_hash, r.events_jsonl, "
            "r.score FROM runs r JOIN situations s ON s.id = r.situation_id ORDER BY r.id"
        ).fetchall()


def view(run_id: int, cls: str | None, terrain: str, score: float, spec: Any) -> dict[str, Any]:
    return {
        "id": run_id,
        "outcome": "completed",
        "score": score,
        "failure_class": cls,
        "bearing": None,
        "min_clearance_m": None,
        "genome": fresh(spec, 0, run_id),
        "terrain": terrain,
        "peers": 0,
        "cells": (),
        "variant": None if cls is None else f"{cls}/no_peer/open",
        "operator": "fresh",
    }


# --- the archive and the variation


def test_the_archive_keeps_the_best_run_per_cell_and_picks_parents_evenly_over_cells() -> None:
    """On a synthetic objective: each cell's elite is its highest-scoring run, the QD score is
    the elites' sum, and parents are drawn evenly over cells however many runs fell in each."""
    spec = spec_of()
    archive = Archive(spec, 0, ELITES)
    runs = [view(i, "drove_into_wall", "caves", float(i), spec) for i in range(100)]
    runs += [view(100, "oscillated_in_open", "open_field", 5.0, spec)]
    runs += [view(101, None, "caves", 50.0, spec), view(102, None, "caves", 7.0, spec)]
    archive.tell(runs)
    stats = archive.stats()
    assert stats.cells == 3
    assert stats.qd_score == pytest.approx(99.0 + 5.0 + 50.0)
    assert stats.best == 99.0
    assert sorted(archive.elites()) == [99, 100, 101]
    parents = Counter(p for g in range(1, 60) for c in archive.ask(g) for p in c.parents[:1])
    assert set(parents) == {99, 100, 101}
    assert min(parents.values()) > 0.2 * sum(parents.values())
    # The threshold objective: every run at or above it is as good as any other.
    capped = Archive(spec, 0, SearchPlan(objective="threshold", threshold=10.0))
    capped.tell(runs)
    assert capped.stats().qd_score == pytest.approx(1.0 + 0.5 + 1.0)


def test_children_stay_in_their_distributions_and_never_repeat_a_run() -> None:
    spec = spec_of()
    first, second = fresh(spec, 1, 0), fresh(spec, 1, 1)
    seen: Counter[str] = Counter()
    for index in range(400):
        rng = np.random.Generator(np.random.PCG64([1, index, 1]))
        operator, child = vary(spec, 1, index + 1000, first, second, rng)
        seen[operator] += 1
        draws = child.as_dict(spec)["draws"]
        assert draws["situation.terrain.preset"] in (0, 1, 2)
        assert 16.0 <= draws["situation.terrain.width_m"] <= 24.0
        assert 0.8 <= draws["situation.terrain.filters.coverage.target"] <= 1.2
        assert 6.0 <= draws["situation.mission.min_route_length_m"] <= 10.0
        assert child.seed not in (first.seed, second.seed)
        if operator == "new_mission":
            # The same map: terrain genes and terrain seed as the elite's.
            assert child.terrain_seed == first.terrain_seed
            assert child.mission_seed != first.mission_seed
            parent = first.as_dict(spec)["draws"]
            assert {k: v for k, v in draws.items() if k.startswith("situation.terrain.")} == {
                k: v for k, v in parent.items() if k.startswith("situation.terrain.")
            }
        if operator == "tune":
            assert (child.terrain_seed, child.mission_seed) == (
                first.terrain_seed,
                first.mission_seed,
            )
    assert set(seen) == set(OPERATORS)


def test_generations_are_fixed_by_run_index() -> None:
    assert [generation_of(i) for i in (0, INITIAL - 1, INITIAL, INITIAL + BATCH)] == [0, 0, 1, 2]


# --- runs


def test_a_search_is_the_same_on_one_and_two_workers_and_a_budget_only_truncates(
    tmp_path: Path,
) -> None:
    spec = spec_of()
    one, two, short = tmp_path / "one.db", tmp_path / "two.db", tmp_path / "short.db"
    a = run_search(spec, one, seed=4, budget=BUDGET, workers=1, plan=ELITES)
    assert (a.ran, a.total, a.interrupted) == (BUDGET, BUDGET, False)
    run_search(spec, two, seed=4, budget=BUDGET, workers=2, plan=ELITES)
    assert stored(one) == stored(two)
    run_search(spec, short, seed=4, budget=INITIAL + BATCH + 3, workers=2, plan=ELITES)
    assert stored(short) == stored(one)[: INITIAL + BATCH + 3]
    rows = stored(one)
    assert {r[1] for r in rows} == {0, 1, 2}
    varied = [r for r in rows if json.loads(r[2])]
    assert varied, "generations after the first vary elites"
    for r in varied:
        assert all(p < INITIAL + BATCH * (r[1] - 1) for p in json.loads(r[2]))
    # Growing the budget extends the same search.
    more = run_search(spec, short, seed=4, budget=BUDGET, workers=1, plan=ELITES)
    assert more.ran == BUDGET - (INITIAL + BATCH + 3)
    assert stored(short) == rows


def test_random_search_is_the_campaign(tmp_path: Path) -> None:
    spec = write_spec(tmp_path, SEARCHED.replace("n = 8", "n = 12"))
    campaign, search = tmp_path / "campaign.db", tmp_path / "search.db"
    assert run_cli("campaign", str(spec), "--db", str(campaign), "--seed", "2").returncode == 0
    done = run_cli(
        "search",
        str(spec),
        "--db",
        str(search),
        "--seed",
        "2",
        "--budget",
        "12",
        "--strategy",
        "random",
    )
    assert done.returncode == 0, done.stderr
    assert [r[4:] for r in stored(search)] == [r[4:] for r in stored(campaign)]


def test_a_stopped_search_resumes_to_the_same_runs(tmp_path: Path) -> None:
    spec = spec_of()
    reference, db = tmp_path / "reference.db", tmp_path / "stopped.db"
    run_search(spec, reference, seed=6, budget=BUDGET, plan=ELITES)
    calls = []

    def stop() -> bool:
        calls.append(1)
        return len(calls) > INITIAL + 5

    first = run_search(spec, db, seed=6, budget=BUDGET, workers=1, stop=stop, plan=ELITES)
    assert first.interrupted and first.total < BUDGET
    rest = run_search(spec, db, seed=6, budget=BUDGET, workers=2, plan=ELITES)
    assert rest.ran == BUDGET - first.total and not rest.interrupted
    assert stored(db) == stored(reference)


@pytest.mark.parametrize("how", [signal.SIGKILL, signal.SIGINT])
def test_a_killed_search_command_resumes_to_the_same_runs(tmp_path: Path, how: int) -> None:
    spec = write_spec(tmp_path, SEARCHED)
    budget = str(INITIAL + BATCH)
    reference = tmp_path / "reference.db"
    elites = ("--strategy", "map-elites")
    done = run_cli(
        "search", str(spec), "--db", str(reference), "--seed", "8", "--budget", budget, *elites
    )
    assert done.returncode == 0, done.stderr
    db = tmp_path / "killed.db"
    proc = start_command(
        spec, db, "--seed", "8", "--budget", budget, "--workers", "1", *elites, command="search"
    )
    wait_for_runs(db, INITIAL + 2, proc)
    proc.send_signal(how)
    proc.communicate(timeout=120)
    again = run_cli(
        "search", str(spec), "--db", str(db), "--seed", "8", "--budget", budget, *elites
    )
    assert again.returncode == 0, again.stderr
    assert stored(db) == stored(reference)


# --- the store through the other commands


def test_a_search_store_works_with_failures_report_rerun_and_faults(
    tmp_path: Path, browser: Any
) -> None:
    spec = write_spec(tmp_path, SEARCHED)
    db = tmp_path / "search.db"
    done = run_cli(
        "search", str(spec), "--db", str(db), "--seed", "3", "--budget", str(BUDGET),
        "--strategy", "map-elites",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "archive" in done.stdout and "distinct failures" in done.stdout
    failures = run_cli("failures", str(db), "--format", "json")
    assert failures.returncode == 0, failures.stderr
    with sqlite3.connect(db) as c:
        classes = {k for (k,) in c.execute("SELECT DISTINCT failure_class FROM runs") if k}
        staged = c.execute(
            "SELECT r.id FROM runs r JOIN situations s ON s.id = r.situation_id "
            "WHERE s.spec LIKE '%\"seed\"%' ORDER BY r.score DESC LIMIT 1"
        ).fetchone()
    assert {f["class"] for f in json.loads(failures.stdout)} == classes
    # A varied run (its stages with seeds of their own) reruns to the same bytes.
    assert staged is not None
    rerun = run_cli("rerun", str(db), str(staged[0]))
    assert rerun.returncode == 0, rerun.stdout
    assert "event log identical" in rerun.stdout
    out = tmp_path / "report"
    assert run_cli("report", str(db), "-o", str(out)).returncode == 0
    page, errors = open_page(browser, out / "index.html")
    assert page.locator("h1").inner_text() == "sitgen search report"
    cells = page.locator("#archive td.elite")
    assert cells.count() == int(page.locator("#archive").get_attribute("data-cells") or 0) > 0
    first = cells.first.get_attribute("data-run")
    cells.first.locator("a").click()
    assert page.url.endswith(f"run-{first}.html")
    page.go_back()
    assert page.locator("#classes-curve polyline").count() == 1
    assert page.locator("#qd-curve circle").count() == 3  # one point per generation
    assert errors == []
    # Its situations measure the seeded faults like any generation's.
    faults = run_cli(
        "faults",
        "--strategy",
        "stored",
        "--situations",
        str(db),
        "--budget",
        "4",
        "--db",
        str(tmp_path / "faults.db"),
        "--format",
        "json",
    )
    assert faults.returncode == 0, faults.stderr
    assert json.loads(faults.stdout)["situations"] == 4


def test_bad_input_fails_before_any_run_naming_the_field(tmp_path: Path) -> None:
    db = tmp_path / "search.db"

    def error(*args: str) -> str:
        done = run_cli("search", *args, "--db", str(db), "--budget", "40")
        assert done.returncode == 2, done.stdout + done.stderr
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1, done.stderr
        return lines[0]

    bad = write_spec(tmp_path, SEARCHED.replace("uniform = [16.0, 24.0]", "uniform = [24, 16]"))
    assert "vary.'situation.terrain.width_m'.uniform" in error(str(bad))
    assert error("--measures", "colour").startswith("error: --measures: unknown measure `colour`")
    assert "--measures" in error("--measures", "peers,terrain,failure_class")
    assert error("--strategy", "annealing").startswith("error: --strategy: `annealing`")
    assert error("--objective", "joy").startswith("error: --objective: `joy`")
    assert not db.exists()
    spec = write_spec(tmp_path, SEARCHED)
    campaign = tmp_path / "campaign.db"
    assert run_cli("campaign", str(spec), "--n", "1", "--db", str(campaign)).returncode == 0
    done = run_cli("search", str(spec), "--db", str(campaign), "--budget", "2")
    assert done.returncode == 2 and "holds a campaign, not a search" in done.stderr
    with pytest.raises(_core.SpecError, match="--budget"):
        run_search(spec_of(), tmp_path / "x.db", budget=0, plan=ELITES)


def test_elites_keep_a_batchs_best_run_per_cell_and_replace_only_a_worse_elite() -> None:
    elites = Elites([2, 3])
    assert elites.empty and elites.stats() == (0, 0.0, None)
    # In one batch a cell takes its best run, the first of equal ones.
    elites.add(
        [(0, 1), (0, 1), (1, 2), (0, 1)],
        [Elite(5.0, 1), Elite(7.0, 2), Elite(1.0, 3), Elite(7.0, 4)],
    )
    assert [(c, e.run_id) for c, e in elites.by_cell()] == [((0, 1), 2), ((1, 2), 3)]
    # An elite gives way only to a strictly better run; a cell outside the grid is clipped in.
    elites.add([(0, 1), (1, 2), (5, -1)], [Elite(7.0, 5), Elite(1.5, 6), Elite(0.0, 7)])
    assert [(c, e.run_id) for c, e in elites.by_cell()] == [((0, 1), 2), ((1, 0), 7), ((1, 2), 6)]
    assert elites.stats() == (3, 8.5, 7.0)
