"""What the store keeps of judged runs: fault evaluations' kill checks, controller diffs,
shrink results, robustness verdicts and a person's judgements. A part of :class:`Store`
(its base class), apart so that each file reads whole; every write is one transaction, as
the store's rule says."""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable
from typing import Any

from sitgen.store.records import Judgement, is_run_id
from sitgen.store.schema import KILL_TEST_COLUMNS, add_columns


class Verdicts:
    """The store's verdict tables, written and read."""

    db: sqlite3.Connection

    def record_fault_chunk(self, first: int, copies: int, trials: Iterable[dict[str, Any]]) -> None:
        """Store one chunk of a fault evaluation's kill checks in one transaction: the copies
        it ran, each trial (the columns of ``fault_trials``, ``classes`` a list, and the run id
        of the faulty run it tested as ``run_id``), and as a kill each trial that killed."""
        with self.db:
            add_columns(self.db, "fault_kills", *KILL_TEST_COLUMNS)
            self.db.execute(
                "INSERT OR REPLACE INTO fault_chunks (first, copies) VALUES (?, ?)",
                (first, copies),
            )
            for t in trials:
                test = (t["faulty_recurs"], t["correct_recurs"], t["copies"], t["p_value"])
                self.db.execute(
                    "INSERT OR REPLACE INTO fault_trials (fault, situation, by, classes, "
                    "faulty_recurs, correct_recurs, copies, p_value, killed) "
                    "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (
                        t["fault"],
                        t["situation"],
                        t["by"],
                        json.dumps(t["classes"]),
                        *test,
                        int(t["killed"]),
                    ),
                )
                if t["killed"]:
                    self.db.execute(
                        "INSERT OR REPLACE INTO fault_kills (fault, situation, run_id, by, "
                        "classes, score_delta, faulty_recurs, correct_recurs, copies, p_value) "
                        "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                        (
                            t["fault"],
                            t["situation"],
                            t["run_id"],
                            t["by"],
                            json.dumps(t["classes"]),
                            t["score_delta"],
                            *test,
                        ),
                    )

    def record_diff_chunk(
        self,
        first: int,
        copies: int,
        judged: Iterable[dict[str, Any]],
        alike: Iterable[tuple[int, str]],
    ) -> None:
        """Store one chunk of a controller diff in one transaction: the copies it ran, each
        judged class (the columns of ``diff_results``) and each class both sides showed alike
        (verdict ``unchanged``)."""
        with self.db:
            self.db.execute(
                "INSERT OR REPLACE INTO diff_chunks (first, copies) VALUES (?, ?)",
                (first, copies),
            )
            for j in judged:
                self.db.execute(
                    "INSERT OR REPLACE INTO diff_results (situation, failure_class, a_recurs, "
                    "b_recurs, copies, verdict) VALUES (?, ?, ?, ?, ?, ?)",
                    (j["situation"], j["failure_class"], j["a_recurs"], j["b_recurs"],
                     j["copies"], j["verdict"]),
                )  # fmt: skip
            for situation, failure_class in alike:
                self.db.execute(
                    "INSERT OR REPLACE INTO diff_results (situation, failure_class, copies, "
                    "verdict) VALUES (?, ?, 0, 'unchanged')",
                    (situation, failure_class),
                )

    def record_shrink(self, run_id: int, row: dict[str, Any]) -> None:
        """Store (or replace) the shrink result of run ``run_id``: the columns of ``shrinks``."""
        columns = ["run_id", *row]
        with self.db:
            self.db.execute(
                f"INSERT OR REPLACE INTO shrinks ({', '.join(columns)}) "
                f"VALUES ({', '.join('?' for _ in columns)})",
                (run_id, *row.values()),
            )

    def record_robustness(self, rows: Iterable[dict[str, Any]]) -> None:
        """Store (or replace) failing runs' robustness: the columns of ``robustness``
        (``classes`` and ``perturbation`` as JSON-able values), in one transaction."""
        with self.db:
            for row in rows:
                self.db.execute(
                    "INSERT OR REPLACE INTO robustness (run_id, failure_class, reruns, recurs, "
                    "classes, perturbation, sitgen_version) VALUES (?, ?, ?, ?, ?, ?, ?)",
                    (
                        row["run_id"],
                        row["failure_class"],
                        row["reruns"],
                        row["recurs"],
                        json.dumps(row["classes"]),
                        json.dumps(row["perturbation"], sort_keys=True),
                        row["sitgen_version"],
                    ),
                )

    def robustness(self, run_ids: Iterable[int] | None = None) -> dict[int, dict[str, Any]]:
        """The stored robustness of ``run_ids`` (every measured run if None), by run id; a run
        never measured is absent."""
        rows = self.db.execute(
            "SELECT run_id, failure_class, reruns, recurs, classes, perturbation, "
            "sitgen_version FROM robustness ORDER BY run_id"
        ).fetchall()
        wanted = None if run_ids is None else set(run_ids)
        out: dict[int, dict[str, Any]] = {}
        for run_id, key, reruns, recurs, classes, perturbation, version in rows:
            if wanted is not None and run_id not in wanted:
                continue
            out[run_id] = {
                "run_id": run_id,
                "failure_class": key,
                "reruns": reruns,
                "recurs": recurs,
                "classes": json.loads(classes),
                "perturbation": json.loads(perturbation),
                "sitgen_version": version,
            }
        return out

    def shrink(self, run_id: int) -> dict[str, Any] | None:
        """Run ``run_id``'s shrink result (JSON columns parsed), or None."""
        if not is_run_id(run_id):
            return None
        cursor = self.db.execute("SELECT * FROM shrinks WHERE run_id = ?", (run_id,))
        row = cursor.fetchone()
        if row is None:
            return None
        names = [d[0] for d in cursor.description]
        out = dict(zip(names, row, strict=True))
        for key in ("run_spec", "before", "after", "reductions"):
            out[key] = json.loads(out[key])
        return out

    def add_judgements(
        self, judgements: Iterable[Judgement], source: str, new_only: bool = False
    ) -> int:
        """Store judgements (all or none, in one transaction); ``source`` says where they came
        from (``page``, ``import FILE``). With ``new_only``, one the store already holds (the
        same runs, verdict, judge and time: the same file imported again) is skipped. Returns
        how many were stored."""
        rows = [(j.a, j.b, j.worse, j.who, j.at, source) for j in judgements]
        if new_only:
            held = set(self.db.execute("SELECT a, b, worse, who, at FROM judgements"))
            rows = [r for r in rows if r[:5] not in held]
        with self.db:
            self.db.executemany(
                "INSERT INTO judgements (a, b, worse, who, at, source) VALUES (?, ?, ?, ?, ?, ?)",
                rows,
            )
        return len(rows)

    def judgements(self) -> list[Judgement]:
        """Every stored judgement, in the order made."""
        return [
            Judgement(a, b, worse, who, at)
            for a, b, worse, who, at in self.db.execute(
                "SELECT a, b, worse, who, at FROM judgements ORDER BY id"
            )
        ]

    def requirement_verdicts(
        self, name: str | None = None, violated_only: bool = False, run_id: int | None = None
    ) -> list[dict[str, Any]]:
        """Stored requirement verdicts (all, or requirement ``name``'s), worst robustness
        first, then by run id."""
        sql = (
            "SELECT run_id, name, formula, robustness, violated, first_violation_s, "
            "interval_start_s, interval_end_s, weight, error FROM requirement_verdicts"
        )
        where = []
        args: list[Any] = []
        if name is not None:
            where.append("name = ?")
            args.append(name)
        if violated_only:
            where.append("violated = 1")
        if run_id is not None:
            where.append("run_id = ?")
            args.append(run_id)
        if where:
            sql += " WHERE " + " AND ".join(where)
        sql += " ORDER BY robustness IS NULL, robustness, run_id"
        keys = (
            "run_id",
            "name",
            "formula",
            "robustness",
            "violated",
            "first_violation_s",
            "interval_start_s",
            "interval_end_s",
            "weight",
            "error",
        )
        return [dict(zip(keys, r, strict=True)) for r in self.db.execute(sql, args)]

    def record_requirement_robustness(self, rows: Iterable[dict[str, Any]]) -> None:
        """Store how often requirement violations recurred in perturbed copies: each row's
        ``run_id``, ``name``, ``reruns`` (copies that ran), ``recurs`` and ``copies`` (each
        copy's verdict: ``violated``, ``satisfied`` or ``error``) and ``sitgen_version``."""
        with self.db:
            self.db.executemany(
                "INSERT OR REPLACE INTO requirement_robustness (run_id, name, reruns, recurs, "
                "copies, sitgen_version) VALUES (?, ?, ?, ?, ?, ?)",
                [
                    (r["run_id"], r["name"], r["reruns"], r["recurs"],
                     json.dumps(r["copies"]), r["sitgen_version"])
                    for r in rows
                ],
            )  # fmt: skip

    def requirement_robustness(self) -> dict[tuple[int, str], dict[str, Any]]:
        """Stored requirement robustness by (run id, requirement name)."""
        rows = self.db.execute(
            "SELECT run_id, name, reruns, recurs, copies FROM requirement_robustness"
        )
        return {
            (r, n): {"reruns": k, "recurs": m, "copies": json.loads(c)} for r, n, k, m, c in rows
        }

    def requirement_robustness_of(
        self, run_ids: Iterable[int]
    ) -> dict[int, dict[str, float | None]]:
        """Each of runs ``run_ids``'s robustness of each of its requirements, by run id then
        name (None where a verdict has none)."""
        wanted = list(run_ids)
        out: dict[int, dict[str, float | None]] = {}
        for i in range(0, len(wanted), 500):
            chunk = wanted[i : i + 500]
            rows = self.db.execute(
                "SELECT run_id, name, robustness FROM requirement_verdicts "
                f"WHERE run_id IN ({', '.join('?' for _ in chunk)})",
                chunk,
            )
            for run_id, name, rho in rows:
                out.setdefault(run_id, {})[name] = rho
        return out

    def record_avoidability(self, rows: Iterable[dict[str, Any]]) -> None:
        """Store (or replace) judged runs' avoidability: each row's ``run_id``, ``after_s``,
        ``sitgen_version`` and either the judgement's fields (``witness`` a JSON-able value or
        None) or ``error``, in one transaction."""
        columns = (
            "robot", "collision_s", "sighted_s", "speed_m_s", "turn_rate_rad_s", "at_rest",
            "verdict", "witness", "tried", "error",
        )  # fmt: skip
        with self.db:
            for r in rows:
                values = {c: r.get(c) for c in columns}
                if values["witness"] is not None:
                    values["witness"] = json.dumps(values["witness"])
                self.db.execute(
                    "INSERT OR REPLACE INTO avoidability (run_id, after_s, sitgen_version, "
                    f"{', '.join(columns)}) VALUES ({', '.join('?' * (len(columns) + 3))})",
                    (r["run_id"], r["after_s"], r["sitgen_version"], *values.values()),
                )

    def avoidability(self, run_ids: Iterable[int] | None = None) -> dict[int, dict[str, Any]]:
        """The stored avoidability of ``run_ids`` (every judged run if None), by run id, the
        witness read back from JSON; a run never judged is absent."""
        cursor = self.db.execute("SELECT * FROM avoidability ORDER BY run_id")
        names = [d[0] for d in cursor.description]
        rows = [dict(zip(names, r, strict=True)) for r in cursor]
        wanted = None if run_ids is None else set(run_ids)
        out = {}
        for r in rows:
            if wanted is not None and r["run_id"] not in wanted:
                continue
            r["witness"] = None if r["witness"] is None else json.loads(r["witness"])
            r["at_rest"] = None if r["at_rest"] is None else bool(r["at_rest"])
            out[r["run_id"]] = r
        return out
