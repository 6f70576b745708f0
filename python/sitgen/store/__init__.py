"""The campaign store: one SQLite file (WAL) holding a campaign, its situations, runs, events
and trajectories. The schema is versioned; docs/store.md documents every table and column.

Writes happen one batch per transaction, so a process killed at any moment leaves every
committed run intact and loses only the runs it had in flight; a resumed campaign skips the
runs already stored.

:class:`Store` opens, upgrades and writes stores; what it keeps of judged runs (fault kills,
diffs, shrinks, robustness, judgements) is its base :class:`~sitgen.store.verdicts.Verdicts`,
its connection :mod:`sitgen.store.connection`. The schema is in :mod:`sitgen.store.schema`, the
records the store hands out in :mod:`sitgen.store.records`; both are named here too, where users
of the store look."""

from __future__ import annotations

import contextlib
import json
import os
import sqlite3
import zlib
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen.store.connection import Connection, read_only_part
from sitgen.store.records import (
    MAX_RUN_ID,
    WORSE,
    Judgement,
    RunRow,
    Scoring,
    StoreError,
    StoreMissing,
    events_digest,
    is_run_id,
    main_events,
    pack_json,
    require_store,
    unpack_json,
)
from sitgen.store.schema import (
    AVOIDABILITY_SCHEMA,
    COST_SCHEMA,
    DESCRIPTOR_SCHEMA,
    DIFF_SCHEMA,
    FAULT_SCHEMA,
    JUDGEMENT_SCHEMA,
    KILL_TEST_COLUMNS,
    KILL_TEST_SCHEMA,
    KINDS,
    PLAN_PARTS,
    REQUIREMENT_SCHEMA,
    ROBUSTNESS_SCHEMA,
    SCHEMA,
    SCHEMA_VERSION,
    SEARCH_SCHEMA,
    SHRINK_SCHEMA,
    TABLES,
    TRAJECTORY_ENCODING,
    upgrade,
)
from sitgen.store.verdicts import Verdicts
from sitgen.store.writing import Writing


class Store(Writing, Verdicts):
    """An open campaign store. Reading (the default) needs an existing store; ``create``
    makes a new one where there is none."""

    def __init__(self, path: str | Path, create: bool = False) -> None:
        self.path = Path(path)
        self._lock: Any = None
        if not create or self.path.is_dir():
            require_store(self.path)
        elif not self.path.exists():
            folder = self.path.parent
            if not folder.is_dir():
                raise StoreError(f"{self.path}: cannot create the store: no folder {folder}")
            if not os.access(folder, os.W_OK | os.X_OK):
                raise StoreError(f"{self.path}: cannot create the store: {folder} is read-only")
        creating = create and not self.path.exists()
        try:
            self._open(create)
        except sqlite3.Error as e:
            if not creating:
                raise
            # A store that could not even be made (a full disk) is not left behind empty.
            with contextlib.suppress(Exception):
                self.db.close()
            for leftover in (self.path, *(Path(f"{self.path}{x}") for x in ("-wal", "-shm"))):
                leftover.unlink(missing_ok=True)
            why = str(e).removeprefix(f"{self.path}: ")
            raise StoreError(f"{self.path}: cannot create the store: {why}") from None

    def _open(self, create: bool) -> None:
        try:
            self.db = sqlite3.connect(self.path, timeout=30.0, factory=Connection)
            self.db.path = str(self.path)
            version = self._schema_version()
            if version is None and not create:
                # A store is only ever made by a command that writes one: a file read as a
                # store (an empty file, say) is an input, and is left as it was.
                self.db.close()
                raise StoreError(
                    f"{self.path}: an empty file or database, not a sitgen campaign store"
                )
            self.db.execute("PRAGMA journal_mode=WAL")
            self.db.execute("PRAGMA synchronous=NORMAL")
            self.db.execute("PRAGMA foreign_keys=ON")
        except sqlite3.DatabaseError as e:
            why = str(e).removeprefix(f"{self.path}: ")
            read_only = read_only_part(self.path)
            if isinstance(e, sqlite3.OperationalError) and read_only is not None:
                # SQLite writes its write-ahead log beside the store even to read it.
                raise StoreError(
                    f"{self.path}: cannot open the store: {read_only} is read-only (SQLite "
                    "writes its log beside the store, even to read it); copy the store to a "
                    "writable folder"
                ) from None
            raise StoreError(f"{self.path}: not a sitgen campaign store ({why})") from None
        if version is not None:
            self._check_tables()
        if version is None:
            with self.db:
                self.db.executescript(
                    SCHEMA
                    + FAULT_SCHEMA
                    + SHRINK_SCHEMA
                    + SEARCH_SCHEMA
                    + JUDGEMENT_SCHEMA
                    + ROBUSTNESS_SCHEMA
                    + KILL_TEST_SCHEMA
                    + DIFF_SCHEMA
                    + COST_SCHEMA
                    + REQUIREMENT_SCHEMA
                    + AVOIDABILITY_SCHEMA
                    + DESCRIPTOR_SCHEMA
                )
                self.db.execute(
                    "INSERT INTO meta (key, value) VALUES ('schema_version', ?)",
                    (str(SCHEMA_VERSION),),
                )
        elif version > SCHEMA_VERSION:
            raise StoreError(
                f"{self.path}: store schema version {version} is newer than this sitgen's "
                f"({SCHEMA_VERSION}); upgrade sitgen"
            )
        elif version < SCHEMA_VERSION:
            with self.db:
                upgrade(self.db, version)

    def _schema_version(self) -> int | None:
        has_meta = self.db.execute(
            "SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'meta'"
        ).fetchone()
        if not has_meta:
            tables = self.db.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
            if tables:
                raise StoreError(f"{self.path}: an SQLite file, but not a sitgen campaign store")
            return None
        row = self.db.execute("SELECT value FROM meta WHERE key = 'schema_version'").fetchone()
        if row is None:
            return None
        try:
            return int(row[0])
        except (TypeError, ValueError):
            raise StoreError(
                f"{self.path}: damaged store: schema_version is {row[0]!r}, not a number"
            ) from None

    def _check_tables(self) -> None:
        present = {r[0] for r in self.db.execute("SELECT name FROM sqlite_master")}
        missing = [t for t in TABLES if t not in present]
        if missing:
            raise StoreError(f"{self.path}: damaged store: no table {', '.join(missing)}")
        # Every reader ranks, sums and formats scores; one that is not a number (a row edited
        # by hand or damaged) is named here once rather than failing each of them.
        bad = self.db.execute(
            "SELECT id, score FROM runs WHERE typeof(score) NOT IN ('real', 'integer') LIMIT 1"
        ).fetchone()
        if bad is not None:
            raise StoreError(
                f"{self.path}: damaged store: run {bad[0]}'s score is {bad[1]!r}, not a number"
            )

    def lock_for_writing(self) -> None:
        """Hold the store for one campaign at a time (an advisory lock, released on close):
        a second campaign on the same store stops with an error instead of interleaving."""
        import fcntl

        self._lock = self.path.open("rb")
        try:
            fcntl.flock(self._lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            self._lock.close()
            self._lock = None
            raise StoreError(
                f"{self.path}: another campaign is writing to this store; wait for it to end "
                "or give another --db"
            ) from None

    def close(self) -> None:
        self.db.close()
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    def __enter__(self) -> Store:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # The campaign.

    def campaign(self) -> dict[str, Any] | None:
        row = self.db.execute(
            "SELECT spec, seed, n, sitgen_version, created_at FROM campaign WHERE id = 1"
        ).fetchone()
        if row is None:
            return None
        return {
            "spec": json.loads(row[0]),
            "seed": row[1],
            "n": row[2],
            "sitgen_version": row[3],
            "created_at": row[4],
        }

    def start_campaign(
        self,
        spec: dict[str, Any],
        seed: int,
        n: int,
        version: str,
        created_at: str,
        evaluation: dict[str, Any] | None = None,
        search: dict[str, Any] | None = None,
        diff: dict[str, Any] | None = None,
    ) -> None:
        """Record the campaign (with ``evaluation``, the plan of a fault evaluation; with
        ``search``, the plan of a search), or check that the store holds this one (then resume
        it)."""
        plans = {"fault_evaluation": evaluation, "search": search, "diff": diff}
        stored = self.campaign()
        if stored is None:
            with self.db:
                self.db.execute(
                    "INSERT INTO campaign (id, spec, seed, n, sitgen_version, created_at) "
                    "VALUES (1, ?, ?, ?, ?, ?)",
                    # In its own order: the order of [vary] is the order genes are drawn in,
                    # which a summary's job is built again with.
                    (json.dumps(spec), seed, n, version, created_at),
                )
                for table, plan in plans.items():
                    if plan is not None:
                        self.db.execute(
                            f"INSERT INTO {table} (id, plan) VALUES (1, ?)",
                            (json.dumps(plan, sort_keys=True),),
                        )
            return
        held = self.kind()
        wanted = next((t for t, p in plans.items() if p is not None), "campaign")
        if held != wanted:
            raise StoreError(
                f"{self.path} holds a {KINDS[held]}, not a {KINDS[wanted]}; give a new --db "
                f"to start this {KINDS[wanted]}"
            )
        if wanted != "campaign":
            row = self.db.execute(f"SELECT plan FROM {wanted} WHERE id = 1").fetchone()
            if json.loads(row[0]) != json.loads(json.dumps(plans[wanted], sort_keys=True)):
                raise StoreError(
                    f"{self.path} holds another {KINDS[wanted]} ({PLAN_PARTS[wanted]} differ); "
                    "give a new --db to start this one, or the same options to resume it"
                )
        same_spec = stored["spec"] == json.loads(json.dumps(spec, sort_keys=True))
        if not same_spec or stored["seed"] != seed:
            differs = "its spec differs" if not same_spec else f"its seed is {stored['seed']}"
            raise StoreError(
                f"{self.path} holds another {KINDS[wanted]} ({differs}); give a new --db to "
                "start this one, or the same spec and seed to resume it"
            )
        with self.db:
            # Stores before version 7 sorted the spec's keys; the jobs are drawn in its order.
            self.db.execute("UPDATE campaign SET spec = ? WHERE id = 1", (json.dumps(spec),))
            if n > stored["n"]:
                self.db.execute("UPDATE campaign SET n = ? WHERE id = 1", (n,))

    def kind(self) -> str:
        """What the store holds: ``campaign``, ``fault_evaluation``, ``search`` or ``diff``."""
        for table in ("fault_evaluation", "search", "diff"):
            if self.db.execute(f"SELECT 1 FROM {table} WHERE id = 1").fetchone():
                return table
        return "campaign"

    def plan(self, kind: str) -> dict[str, Any] | None:
        """The stored plan of a ``fault_evaluation`` or ``search``; None if it holds none."""
        row = self.db.execute(f"SELECT plan FROM {kind} WHERE id = 1").fetchone()
        return None if row is None else dict(json.loads(row[0]))

    def has_runs(self, ids: Iterable[int]) -> set[int]:
        """Those of ``ids`` that are runs of this store."""
        wanted = sorted({i for i in ids if is_run_id(i)})
        found: set[int] = set()
        for i in range(0, len(wanted), 500):
            chunk = wanted[i : i + 500]
            found.update(
                r[0]
                for r in self.db.execute(
                    f"SELECT id FROM runs WHERE id IN ({', '.join('?' for _ in chunk)})", chunk
                )
            )
        return found

    def rescore(self, weights: Scoring) -> None:
        """From now on, read every run's score and breakdown as ``weights`` give them, from
        each run's stored breakdown and failure class (a temporary view shadows ``runs`` for
        this connection only); the store becomes read-only, so nothing rescored is written."""
        self.db.create_function(
            "sitgen_score", 2, lambda b, c: weights.score(json.loads(b), c), deterministic=True
        )
        self.db.create_function(
            "sitgen_breakdown",
            1,
            lambda b: json.dumps(weights.breakdown(json.loads(b)), sort_keys=True),
            deterministic=True,
        )
        columns = [c[1] for c in self.db.execute("PRAGMA main.table_info(runs)")]
        chosen = {
            "score": "sitgen_score(breakdown, failure_class) AS score",
            "breakdown": "sitgen_breakdown(breakdown) AS breakdown",
        }
        with self.db:
            self.db.execute(
                f"CREATE TEMP VIEW runs AS SELECT {', '.join(chosen.get(c, c) for c in columns)} "
                "FROM main.runs"
            )
        self.db.execute("PRAGMA query_only = ON")

    def costs(self, run_ids: Iterable[int] | None = None) -> dict[int, tuple[float, float]]:
        """What runs cost the machine that made them, (wall seconds, processor seconds), by
        run id (every run with a cost if ``run_ids`` is None; runs stored before sitgen kept
        costs have none)."""
        rows = self.db.execute("SELECT run_id, wall_s, cpu_s FROM run_costs").fetchall()
        wanted = None if run_ids is None else set(run_ids)
        return {r: (w, c) for r, w, c in rows if wanted is None or r in wanted}

    def done_ids(self) -> set[int]:
        return {r[0] for r in self.db.execute("SELECT id FROM runs")}

    def run_count(self) -> int:
        count: int = self.db.execute("SELECT count(*) FROM runs").fetchone()[0]
        return count

    # Reading.

    def ranked(
        self, top: int | None = None, failure_class: str | None = None
    ) -> list[dict[str, Any]]:
        """Runs, most dangerous first (score descending, then id), optionally only those of
        one failure class."""
        sql = (
            "SELECT r.id, r.score, r.outcome, r.reason, r.breakdown, r.controller, r.steps, "
            "r.time_s, r.collisions, r.min_clearance_m, r.waypoints_reached, r.waypoints, "
            "s.terrain, s.peers, s.seed, r.failure_class, r.failure "
            "FROM runs r JOIN situations s ON s.id = r.situation_id"
        )
        params: tuple[Any, ...] = ()
        if failure_class is not None:
            sql += " WHERE r.failure_class = ?"
            params = (failure_class,)
        sql += " ORDER BY r.score DESC, r.id"
        if top is not None:
            sql += " LIMIT ?"
            params = (*params, top)
        out = []
        for row in self.db.execute(sql, params):
            breakdown = self.stored_json(row[0], "breakdown", row[4])
            failure = self.stored_json(row[0], "failure", row[16]) if row[16] else None
            out.append(
                {
                    "run": row[0],
                    "score": row[1],
                    "outcome": row[2],
                    "reason": row[3],
                    "main_events": main_events(breakdown),
                    "breakdown": breakdown,
                    "controller": row[5],
                    "steps": row[6],
                    "time_s": row[7],
                    "collisions": row[8],
                    "min_clearance_m": row[9],
                    "waypoints_reached": row[10],
                    "waypoints": row[11],
                    "terrain": row[12],
                    "peers": row[13],
                    "situation_seed": row[14],
                    "failure_class": row[15],
                    "failure": failure["description"] if failure else None,
                    "failure_features": failure["features"] if failure else {},
                    "failure_events": failure["events"] if failure else [],
                }
            )
        return out

    def scores(self) -> list[float]:
        return [r[0] for r in self.db.execute("SELECT score FROM runs ORDER BY id")]

    def _stored_spec(self, text: Any, what: str, run_id: int) -> dict[str, Any]:
        """A spec as stored (a JSON object), or a StoreError that names the run."""
        try:
            spec = json.loads(text)
        except (TypeError, ValueError) as e:
            raise StoreError(
                f"{self.path}: run {run_id}: its stored {what} is damaged ({e})"
            ) from None
        if not isinstance(spec, dict):
            raise StoreError(
                f"{self.path}: run {run_id}: its stored {what} is damaged (not a JSON object)"
            )
        return spec

    def run_row(self, run_id: int) -> dict[str, Any]:
        """Run ``run_id`` as stored: its situation (None if it was never generated, or the
        run is kept as a summary: see ``kept``), specs (None for a summary: its job builds
        them again, :func:`sitgen.triage.recall.stored_run`), seeds and event log ('' for a summary;
        ``events_sha256`` is its digest)."""
        if not is_run_id(run_id):
            raise StoreError(f"{self.path}: no run {run_id} (a run id is 0 to 2^63 - 1)")
        row = self.db.execute(
            "SELECT r.id, s.seed, s.spec, s.situation, s.content_hash, r.run_spec, r.run_seed, "
            "r.controller, r.score, r.events_jsonl, r.outcome, r.failure, r.kept, "
            "r.events_sha256, m.score FROM runs r JOIN main.runs m ON m.id = r.id "
            "JOIN situations s ON s.id = r.situation_id WHERE r.id = ?",
            (run_id,),
        ).fetchone()
        if row is None:
            raise StoreError(f"{self.path}: no run {run_id}")
        kept = row[12] != 0
        situation_spec, run_spec = (
            (self._stored_spec(row[2], "situation spec", run_id),
             self._stored_spec(row[5], "run spec", run_id))
            if kept else (None, None)
        )  # fmt: skip
        return {
            "id": row[0],
            "situation_seed": row[1],
            "situation_spec": situation_spec,
            "situation": row[3],
            "content_hash": row[4],
            "run_spec": run_spec,
            "run_seed": row[6],
            "controller": row[7],
            "score": row[8],
            "events_jsonl": row[9],
            "outcome": row[10],
            "failure": json.loads(row[11]) if row[11] else None,
            "kept": kept,
            "events_sha256": row[13] or events_digest(row[9]),
            # The score the run earned under its own scoring (``score`` is rescored where the
            # store is read with learned weights).
            "stored_score": row[14],
        }

    def trajectory(self, run_id: int) -> npt.NDArray[np.float32] | None:
        if not is_run_id(run_id):
            return None
        row = self.db.execute(
            "SELECT robots, rows, encoding, data FROM trajectories WHERE run_id = ?", (run_id,)
        ).fetchone()
        if row is None:
            return None
        robots, rows, encoding, data = row
        if encoding != TRAJECTORY_ENCODING:
            raise StoreError(f"{self.path}: run {run_id}: unknown trajectory encoding {encoding}")
        try:
            flat = np.frombuffer(zlib.decompress(data), dtype="<f4")
            return flat.reshape(rows, robots, 3)
        except (zlib.error, TypeError, ValueError):
            raise StoreError(
                f"{self.path}: damaged store: run {run_id}'s trajectory does not decode as "
                f"{rows} steps × {robots} robots ({TRAJECTORY_ENCODING})"
            ) from None

    def stored_json(self, run_id: int, column: str, text: Any) -> Any:
        """``text`` (run ``run_id``'s ``column``) parsed as JSON, or a StoreError naming the
        run and the column where it is not (a store damaged or written by hand)."""
        try:
            return json.loads(text)
        except (TypeError, ValueError):
            raise StoreError(
                f"{self.path}: damaged store: run {run_id}'s {column} is not JSON"
            ) from None

    def rows(self, table: str) -> Iterator[dict[str, Any]]:
        """Every row of ``table`` (situations without the embedded situation JSON)."""
        columns = [c[1] for c in self.db.execute(f"PRAGMA table_info({table})")]
        if table == "situations":
            columns.remove("situation")
        if table == "trajectories":
            columns.remove("data")
        cursor = self.db.execute(f"SELECT {', '.join(columns)} FROM {table} ORDER BY 1")
        for values in cursor:
            yield dict(zip(columns, values, strict=True))

    def columns(self, table: str) -> list[str]:
        return [
            c[1]
            for c in self.db.execute(f"PRAGMA table_info({table})")
            if (table, c[1]) not in {("situations", "situation"), ("trajectories", "data")}
        ]


__all__ = [
    "AVOIDABILITY_SCHEMA",
    "COST_SCHEMA",
    "DESCRIPTOR_SCHEMA",
    "DIFF_SCHEMA",
    "FAULT_SCHEMA",
    "JUDGEMENT_SCHEMA",
    "KILL_TEST_COLUMNS",
    "KILL_TEST_SCHEMA",
    "KINDS",
    "MAX_RUN_ID",
    "PLAN_PARTS",
    "REQUIREMENT_SCHEMA",
    "ROBUSTNESS_SCHEMA",
    "SCHEMA",
    "SCHEMA_VERSION",
    "SEARCH_SCHEMA",
    "SHRINK_SCHEMA",
    "TABLES",
    "TRAJECTORY_ENCODING",
    "WORSE",
    "Judgement",
    "RunRow",
    "Scoring",
    "Store",
    "StoreError",
    "StoreMissing",
    "events_digest",
    "is_run_id",
    "main_events",
    "pack_json",
    "require_store",
    "unpack_json",
]
