"""Search toward distinct failures: the driver that runs a search generation by generation
into its store, resumes it, and replays a stored one (its options: :mod:`.plan`; its archive
and the choice of each run: :mod:`.archive`; the situation operators of the default strategy:
:mod:`sitgen.generation.mutation`).

The paper (§6) notes that random generation "would spend most of its time generating safe
situations" and asks for a generator tuned to give fewer low scores without losing diversity.
A search keeps an *archive* of the runs so far and draws each generation from it
(:mod:`.archive`); what follows is how the runs of a search are made and stored.

Runs are numbered like a campaign's jobs. Run ``i`` of generation 0 (the first :data:`INITIAL`)
and every *fresh* run (a share :data:`FRESH_SHARE` of each later generation, which keeps
exploring) is exactly the campaign's job ``i`` with the same seed; ``--strategy random`` makes
every run fresh, so it *is* the campaign. Generation ``g ≥ 1`` holds the next :data:`BATCH`
runs and is drawn from the archive as generations ``< g`` left it, with a stream seeded by
(seed, run index): a search is a pure function of (spec, seed, options), whatever the worker
count, and a budget only truncates it. Each run is stored as it ends (its generation, parents
and genes with it); the same command resumes, rebuilding the archive from the store.
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sitgen import _core
from sitgen.execution.campaign import Executor, run_row, started_at
from sitgen.execution.jobs import (
    CampaignSpec,
    campaign_from_data,
    check_campaign,
    check_workers,
    runs_in_python,
)
from sitgen.generation.genome import (
    Genome,
)
from sitgen.generation.mutation.parent import Parent
from sitgen.generation.search.archive import (
    Archive,
    Child,
    job_of,
)
from sitgen.generation.search.plan import (
    MAX_BUDGET,
    Like,
    SearchPlan,
    generation_runs,
    plan_search,
)
from sitgen.store import KINDS, Store, StoreError, unpack_json
from sitgen.triage.recall import regenerate, stored_run
from sitgen.triage.variants import Screen, variant
from sitgen.world.situation import Situation


def _view(store: Store, spec: CampaignSpec, ids: Sequence[int]) -> list[dict[str, Any]]:
    """What the archive reads of stored runs ``ids`` (one query; in run order)."""
    marks = ", ".join("?" for _ in ids)
    rows = store.db.execute(
        "SELECT r.id, r.outcome, r.score, r.failure_class, r.failure, r.min_clearance_m, "
        "r.genes, r.coverage, r.parents, s.terrain, s.peers FROM runs r "
        "JOIN situations s ON s.id = r.situation_id "
        f"WHERE r.id IN ({marks}) ORDER BY r.id",
        list(ids),
    )
    out = []
    for (
        run_id,
        outcome,
        score,
        cls,
        failure,
        clearance,
        genes,
        coverage,
        parents,
        terrain,
        peers,
    ) in rows:
        features = json.loads(failure)["features"] if failure else {}
        gene_data = None if genes is None else json.loads(genes)
        record = unpack_json(coverage) if coverage else None
        out.append(
            {
                "id": run_id,
                "outcome": outcome,
                "score": score,
                "failure_class": cls,
                "bearing": features.get("bearing"),
                "min_clearance_m": clearance,
                "genome": None if gene_data is None else Genome.from_dict(spec, gene_data),
                "cells": tuple(record["cells"]) if record else (),
                "variant": variant(cls, record),
                "operator": None if gene_data is None else gene_data.get("operator"),
                "parents": json.loads(parents) if parents else [],
                "terrain": terrain,
                "peers": peers,
            }
        )
    robustness = store.requirement_robustness_of([v["id"] for v in out])
    for v in out:
        v["robustness"] = robustness.get(v["id"], {})
    return out


@dataclass(frozen=True)
class SearchProgress:
    """Where a search stands (for a progress bar)."""

    runs: int
    budget: int
    cells: int
    classes: int
    """Failure classes found so far."""
    best: float
    """Best objective in the archive."""


@dataclass(frozen=True)
class SearchResult:
    """What a search call did."""

    ran: int
    total: int
    interrupted: bool
    wall_s: float
    cells: int
    qd_score: float


def run_search(
    spec: CampaignSpec,
    db: str | Path,
    seed: int = 0,
    budget: int = 500,
    plan: SearchPlan | None = None,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    on_progress: Callable[[SearchProgress], None] | None = None,
    stop: Callable[[], bool] | None = None,
) -> SearchResult:
    """Run (or resume) a search of ``budget`` runs into store ``db``. The spec, options and
    controllers are checked before any run; ``stop()`` is checked after every run, and the
    runs in flight are kept."""
    if not 1 <= budget <= MAX_BUDGET:
        raise _core.SpecError(f"--budget: {budget} is not in [1, {MAX_BUDGET}]")
    plan = plan or SearchPlan()
    plan = plan_search(
        spec,
        plan.strategy,
        plan.measures,
        plan.objective,
        plan.threshold,
        plan.target_class,
        plan.like,
        plan.requirement,
    )
    workers = check_workers(workers, backend)
    started = time.perf_counter()
    check_campaign(spec, seed, budget, stop)
    if stop is not None and stop():
        return SearchResult(0, 0, True, time.perf_counter() - started, 0, 0.0)
    user = runs_in_python(spec)
    with Store(db, create=True) as store:
        store.lock_for_writing()
        store.start_campaign(
            spec.source, seed, budget, _core.__version__, started_at(), search=plan.as_dict()
        )
        done = store.done_ids()
        archive = Archive(spec, seed, plan)
        archive.parent_of = lambda run_id: parent_of(store, run_id)
        if plan.strategy == "mutation":
            archive.screen = Screen(workers if backend == "local" else 1)
        executor = Executor(workers, backend, address, user=user)
        classes_seen = {
            c for (c,) in store.db.execute("SELECT DISTINCT failure_class FROM runs") if c
        }
        ran = 0
        interrupted = False

        def progress() -> None:
            if on_progress is not None:
                s = archive.stats()
                on_progress(SearchProgress(len(done), budget, s.cells, len(classes_seen), s.best))

        progress()
        generation = 0
        while generation_runs(generation).start < budget:
            children = [c for c in archive.ask(generation) if c.index < budget]
            views = _view(store, spec, [c.index for c in children if c.index in done])
            _check_stored(store, children, views)
            todo = [c for c in children if c.index not in done]
            if todo and not interrupted:
                by_index = {c.index: c for c in todo}
                for job, result in executor.results([job_of(spec, c) for c in todo]):
                    child = by_index[job.index]
                    row = dataclasses.replace(
                        run_row(job, result),
                        generation=generation,
                        parents=child.parents,
                        genes=child.stored_genes(spec),
                    )
                    # One transaction per run: a kill loses only the runs in flight.
                    store.add_runs([row])
                    done.add(job.index)
                    ran += 1
                    failure = (row.record or {}).get("failure")
                    if failure:
                        classes_seen.add(failure["class"])
                    progress()
                    if stop is not None and stop():
                        executor.stop()
            if any(c.index not in done for c in children):
                interrupted = True
                break
            views += _view(store, spec, [c.index for c in todo])
            views.sort(key=lambda v: int(v["id"]))
            archive.screen_runs(store, views)
            archive.tell(views)
            generation += 1
        total = store.run_count()
        stats = archive.stats()
    return SearchResult(
        ran, total, interrupted, time.perf_counter() - started, stats.cells, stats.qd_score
    )


def parent_of(store: Store, run_id: int) -> Parent:
    """Stored run ``run_id`` as a parent of the mutation strategy."""
    return stored_parent(store, run_id)[1]


def stored_parent(store: Store, run_id: int) -> tuple[dict[str, Any], Parent, dict[str, Any]]:
    """Stored run ``run_id`` (:func:`stored_run`), as a parent (its situation, kept or made
    again, and where its failure began), and its coverage record."""
    row = stored_run(store, run_id)
    if row["situation"] is not None:
        situation = Situation(row["situation"], check_start=False)
    else:
        situation = regenerate(row)
    coverage, failure, time_s, steps = store.db.execute(
        "SELECT coverage, failure, time_s, steps FROM runs WHERE id = ?", (run_id,)
    ).fetchone()
    record: dict[str, Any] = unpack_json(coverage) if coverage else {}
    parent = Parent.of(
        situation,
        record,
        json.loads(failure) if failure else None,
        store.trajectory(run_id) if failure else None,
        time_s / steps if steps else None,
    )
    return row, parent, record


def _check_stored(store: Store, children: list[Child], views: list[dict[str, Any]]) -> None:
    """A resumed generation must ask for what was stored (``views``): a store written by
    another sitgen (other variation) cannot be resumed without mixing two searches."""
    asked = {c.index: c.genome for c in children}
    for view in views:
        if view["genome"] != asked[view["id"]]:
            raise StoreError(
                f"{store.path}: run {view['id']} is not the run this search asks for there "
                "(written by another sitgen?); give a new --db"
            )


@dataclass
class SearchReplay:
    """A stored search replayed generation by generation: the archive it ends with and the
    figures over budget."""

    archive: Archive
    curve: list[dict[str, float]] = field(default_factory=list)
    """After each generation: runs, QD score, failure classes found."""


def replay(store: Store) -> SearchReplay:
    """Rebuild a stored search's archive, and its figures over budget. Raises StoreError if
    the store holds no search."""

    raw = store.plan("search")
    campaign = store.campaign()
    if raw is None or campaign is None:
        raise StoreError(
            f"{store.path}: holds a {KINDS[store.kind()]}, not a search (sitgen search)"
        )
    spec = campaign_from_data(campaign["spec"])
    plan = SearchPlan.from_dict(raw)
    archive = Archive(spec, campaign["seed"], plan)
    out = SearchReplay(archive)
    stored = store.done_ids()
    classes: set[str] = set()
    generation = 0
    while ids := [i for i in generation_runs(generation) if i in stored]:
        runs = _view(store, spec, ids)
        archive.tell(runs)
        classes.update(r["failure_class"] for r in runs if r["failure_class"])
        out.curve.append(
            {
                "runs": archive.told,
                "qd_score": archive.stats().qd_score,
                "classes": len(classes),
            }
        )
        generation += 1
    return out


def like_run(source: str) -> Like:
    """``--like DB:RUN``: the stored run a directed search starts from (it must have failed).
    Raises SpecError naming the option."""
    db, _, run = source.rpartition(":")
    if not db or not run.isdigit():
        raise _core.SpecError(f"--like: `{source}` is not DB:RUN (a store and a run id in it)")
    if not Path(db).is_file():
        raise _core.SpecError(f"--like: {db}: no such store")
    with Store(db) as store:
        row, parent, record = stored_parent(store, int(run))
    if row["failure"] is None:
        raise _core.SpecError(f"--like: run {run} of {db} did not fail")
    return Like(
        source,
        parent.situation.to_json(),
        row["run_spec"],
        int(row["run_seed"]),
        str(row["failure"]["class"]),
        record.get("failure_at"),
        record.get("failure_cell"),
        row["failure"]["features"].get("start_s"),
    )
