"""Reading a campaign back: the ranking, exports for analysis, and reruns that confirm a stored
run is reproduced bit for bit."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from sitgen import _core
from sitgen.run import run
from sitgen.store import Store, events_digest
from sitgen.triage.descriptors import NUMERIC, RUN_NUMERIC, described, run_descriptors
from sitgen.triage.failures import check_class, distinct_failures
from sitgen.triage.recall import regenerate, resimulate_checked, stored_run
from sitgen.triage.robustness import verdict
from sitgen.triage.rows import write_rows
from sitgen.triage.weights import Weights

RANK_COLUMNS = (
    "rank",
    "run",
    "score",
    "outcome",
    "main_events",
    "failure_class",
    "failure",
    "terrain",
    "peers",
    "collisions",
    "min_clearance_m",
    "waypoints_reached",
    "waypoints",
    "time_s",
    "controller",
    "situation_seed",
    "reason",
    "robustness",
)

TABLES = (
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
)


def ranked_rows(
    db: str | Path,
    top: int | None = None,
    failure_class: str | None = None,
    distinct: bool = False,
    weights: Weights | None = None,
) -> list[dict[str, Any]]:
    """The top runs, most dangerous first, with their rank (1 = first). ``failure_class``
    keeps the runs of one class; ``distinct`` puts the representative of each distinct failure
    first (best first, each marked with its ``distinct`` key), then the rest by score.
    ``weights``: rescore every run by learned weights first."""

    if failure_class is not None:
        check_class(failure_class)
    with Store(db) as store:
        if weights is not None:
            store.rescore(weights)
        rows = store.ranked(None if distinct else top, failure_class)
        if distinct:
            failures = [
                f
                for f in distinct_failures(store)
                if failure_class is None or f.failure_class == failure_class
            ]
            by_id = {r["run"]: r for r in rows}
            first = [{**by_id[f.representative], "distinct": f.key} for f in failures]
            chosen = {f.representative for f in failures}
            rows = first + [r for r in rows if r["run"] not in chosen]
            rows = rows[:top] if top is not None else rows
        measured = store.robustness(r["run"] for r in rows)
    return [
        {"rank": i + 1, **r, "robustness": robustness_of(measured.get(r["run"]))}
        for i, r in enumerate(rows)
    ]


def robustness_of(measured: dict[str, Any] | None) -> str:
    """A run's stored robustness as ``robust 7/8`` or ``knife-edge 3/8``; '' if unmeasured."""
    if measured is None:
        return ""
    recurs, reruns = measured["recurs"], measured["reruns"]
    return f"{verdict(recurs, reruns)} {recurs}/{reruns}"


def write_ranking(rows: list[dict[str, Any]], format: str, out: TextIO) -> None:
    """Write the ranking as ``csv`` or ``json``."""
    write_rows(rows, RANK_COLUMNS, format, out)


def export_tables(db: str | Path, directory: Path, format: str) -> list[Path]:
    """Write every table of the store (the situations without their embedded JSON, the
    trajectories without their data) as Parquet or CSV files in ``directory``."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    with Store(db) as store:
        for table in TABLES:
            columns = store.columns(table)
            rows = list(store.rows(table))
            path = directory / f"{table}.{format}"
            if format == "csv":
                with path.open("w", newline="") as f:
                    writer = csv.DictWriter(f, fieldnames=columns)
                    writer.writeheader()
                    writer.writerows(rows)
            else:
                try:
                    import pyarrow as pa
                    import pyarrow.parquet as pq
                except ImportError:
                    raise _core.SpecError(
                        "--format: parquet needs pyarrow; pip install 'sitgen[analysis]' or use csv"
                    ) from None
                arrays = {c: [r[c] for r in rows] for c in columns}
                pq.write_table(pa.table(arrays), path)
            written.append(path)
    return written


def export_descriptors(db: str | Path, directory: Path, format: str) -> Path | None:
    """Every run's situation descriptors (docs/explain.md), a row a run (``run_id`` then each
    descriptor), as ``descriptors.parquet`` or ``.csv`` in ``directory``; None for an empty
    store."""
    with Store(db) as store:
        by_run = described(store)
    if not by_run:
        return None
    names = [*NUMERIC, "terrain"]
    columns: dict[str, list[Any]] = {"run_id": list(by_run)}
    for name in names:
        columns[name] = [d[name] for d in by_run.values()]
    path = directory / f"descriptors.{format}"
    _write_columns(columns, path, format)
    return path


def export_run_descriptors(db: str | Path, directory: Path, format: str) -> Path | None:
    """Every failing run's run descriptors (docs/explain.md), a row a run (``run_id`` then each
    descriptor), as ``run_descriptors.parquet`` or ``.csv`` in ``directory``: each run made
    again for its signals (a run is deterministic) and checked to be the run stored. None
    where no run failed."""
    columns: dict[str, list[Any]] = {c: [] for c in ("run_id", *RUN_NUMERIC)}
    with Store(db) as store:
        failing = [
            i for (i,) in store.db.execute(
                "SELECT id FROM runs WHERE failure_class IS NOT NULL ORDER BY id"
            )
        ]  # fmt: skip
        for run_id in failing:
            row = stored_run(store, run_id)
            _, record = resimulate_checked(store, row, signals=True)
            dt_s = float(row["run_spec"].get("sim", {}).get("dt_s", 0.1))
            measured = run_descriptors(record.signals, dt_s)
            columns["run_id"].append(run_id)
            for name in RUN_NUMERIC:
                columns[name].append(measured[name])
    if not columns["run_id"]:
        return None
    path = directory / f"run_descriptors.{format}"
    _write_columns(columns, path, format)
    return path


def _write_columns(columns: dict[str, list[Any]], path: Path, format: str) -> None:
    if format == "csv":
        with path.open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(columns)
            writer.writerows(zip(*columns.values(), strict=True))
    else:
        import pyarrow as pa
        import pyarrow.parquet as pq

        pq.write_table(pa.table(columns), path)


def export_signals(db: str | Path, directory: Path, format: str) -> Path | None:
    """Every run judged by requirements, its requirement signals one row per sample
    (``run_id``, ``step``, ``time_s``, then each signal of docs/requirements.md), written as
    ``signals.parquet`` or ``.csv`` in ``directory``, so that an outside tool can check a
    verdict. The signals are not stored: each run is made again (a run is deterministic) and
    checked to be the run stored. None where no run was judged by a requirement."""
    names = _core.requirement_signals()
    columns: dict[str, list[Any]] = {c: [] for c in ("run_id", "step", "time_s", *names)}
    with Store(db) as store:
        judged = sorted({v["run_id"] for v in store.requirement_verdicts()})
        if not judged:
            return None
        for run_id in judged:
            row = stored_run(store, run_id)
            _, record = resimulate_checked(store, row, signals=True)
            dt_s = float(row["run_spec"].get("sim", {}).get("dt_s", 0.1))
            n = record.steps + 1
            columns["run_id"] += [run_id] * n
            columns["step"] += range(n)
            columns["time_s"] += [round(k * dt_s, 9) for k in range(n)]
            for name in names:
                columns[name] += record.signals[name].tolist()
    path = directory / f"signals.{format}"
    _write_columns(columns, path, format)
    return path


@dataclass(frozen=True)
class Rerun:
    """What a rerun found."""

    identical: bool
    lines: list[str]


def rerun(db: str | Path, run_id: int) -> Rerun:
    """Regenerate run ``run_id``'s situation from its spec and seed, run it again, and compare
    the situation's content hash, the event log (bytes) and the score with what is stored."""

    with Store(db) as store:
        stored = stored_run(store, run_id)
    lines = [f"run {run_id}: situation seed {stored['situation_seed']}, {stored['controller']}"]
    try:
        situation = regenerate(stored)
    except _core.GenerationFailed as e:
        same = stored["content_hash"] is None
        lines.append(f"generation fails again: {e}" if same else f"generation now fails: {e}")
        return Rerun(same, lines)
    same_situation = situation.content_hash == stored["content_hash"]
    lines.append(
        f"situation {'identical' if same_situation else 'DIFFERS'}: {situation.content_hash}"
    )
    # The stored run spec names the controller if the campaign gave one (with its parameters
    # and any seeded fault); otherwise the situation's own drives, as it did.
    record = run(situation, seed=stored["run_seed"], spec=stored["run_spec"])
    if record.outcome == "error" and stored["outcome"] != "error":
        # Not a different run: this one could not be made now (its program is gone, say).
        lines.append(f"could not be run again: {record.reason}")
        return Rerun(False, lines)
    # A run kept as a summary has only its log's digest: the same bytes give the same digest.
    same_log = events_digest(record.events_jsonl) == stored["events_sha256"]
    events = len(record.events_jsonl.splitlines())
    lines.append(f"event log {'identical' if same_log else 'DIFFERS'} ({events} events)")
    same_score = record.score == stored["score"]
    lines.append(
        f"score {'identical' if same_score else 'DIFFERS'}: {record.score:g}"
        + ("" if same_score else f" (stored {stored['score']:g})")
    )
    return Rerun(same_situation and same_log and same_score, lines)
