"""How the store takes runs in: a run's rows (its situation, summary, cost, requirement
verdicts, and, stored whole, its event log and trajectory) in one transaction, and a run
reduced to its summary. A part of :class:`sitgen.store.Store` (its base class), apart so that
each file reads whole."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable
from typing import Any

from sitgen.store.records import RunRow
from sitgen.store.schema import TRAJECTORY_ENCODING


class Writing:
    """The store's runs, written."""

    db: sqlite3.Connection

    def add_runs(self, rows: Iterable[RunRow], demote: Iterable[int] = ()) -> None:
        """Store finished runs, and reduce the runs ``demote`` to their summary, all or
        none."""
        with self.db:
            for row in rows:
                self._add_run(row)
            for run_id in demote:
                self._demote(run_id)

    def _demote(self, run_id: int) -> None:
        """Keep only run ``run_id``'s summary (a campaign's run; see :attr:`RunRow.keep`)."""
        self.db.execute("UPDATE situations SET spec = '', situation = NULL WHERE id = ?", (run_id,))
        self.db.execute(
            "UPDATE runs SET run_spec = '', events_jsonl = '', kept = 0 WHERE id = ?", (run_id,)
        )
        self.db.execute("DELETE FROM events WHERE run_id = ?", (run_id,))
        self.db.execute("DELETE FROM trajectories WHERE run_id = ?", (run_id,))

    def _add_run(self, row: RunRow) -> None:
        self.db.execute(
            "INSERT INTO situations (id, seed, spec, terrain, peers, content_hash, situation) "
            "VALUES (?, ?, ?, ?, ?, ?, ?)",
            row.situation_values(),
        )
        self.db.execute(
            "INSERT INTO runs (id, situation_id, controller, run_spec, run_seed, outcome, reason, "
            "score, breakdown, steps, time_s, collisions, min_clearance_m, waypoints_reached, "
            "waypoints, events_jsonl, failure_class, failure, generation, parents, genes, "
            "coverage, kept, events_sha256) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            row.run_values(),
        )
        if row.descriptors is not None:
            self.db.execute(
                "INSERT OR REPLACE INTO situation_descriptors (situation_id, descriptors) "
                "VALUES (?, ?)",
                (row.id, row.descriptors),
            )
        if row.cost is not None:
            self.db.execute(
                "INSERT OR REPLACE INTO run_costs (run_id, wall_s, cpu_s) VALUES (?, ?, ?)",
                (row.id, *row.cost),
            )
        self.db.executemany(
            "INSERT INTO requirement_verdicts (run_id, name, formula, robustness, violated, "
            "first_violation_s, interval_start_s, interval_end_s, weight, error) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            row.requirement_values(),
        )
        if not row.whole:
            return
        self.db.executemany(
            "INSERT INTO events (run_id, seq, kind, start_s, end_s, robot, other, scored, "
            "details) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            row.event_values(),
        )
        if row.trajectory is not None:
            self.db.execute(
                "INSERT INTO trajectories (run_id, robots, rows, encoding, data) "
                "VALUES (?, ?, ?, ?, ?)",
                (
                    row.id,
                    row.robots,
                    row.outcome_record["steps"] + 1,
                    TRAJECTORY_ENCODING,
                    row.trajectory,
                ),
            )

    def record_descriptors(self, rows: dict[int, dict[str, Any]]) -> None:
        """Store situations' descriptors, by situation id, in one transaction."""
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO situation_descriptors (situation_id, descriptors) "
                "VALUES (?, ?)",
                [(i, json.dumps(d, sort_keys=True)) for i, d in rows.items()],
            )

    def stored_descriptors(self) -> dict[int, dict[str, Any]]:
        """Every run's stored situation descriptors, by run id."""
        rows = self.db.execute(
            "SELECT r.id, d.descriptors FROM runs r "
            "JOIN situation_descriptors d ON d.situation_id = r.situation_id"
        )
        return {i: json.loads(text) for i, text in rows}
