"""Reading a fault evaluation: each fault's and equivalent mutant's result, the kill rate and
its curve, the false-kill rate, runs to first kill with every perturbed copy counted, in words
and as JSON."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from sitgen.generation.faults import (
    CURVE_BUDGETS,
    POSSIBLY_EQUIVALENT_AFTER,
    RUN_STRIDE,
    catalogue,
    situations_evaluated,
)
from sitgen.store import KINDS, Store, StoreError
from sitgen.triage.kill import (
    MUTANTS,
)


@dataclass
class FaultRow:
    """One fault's result."""

    id: str
    killed: bool
    runs_to_first_kill: int | None
    """Situations it took (1-based); None if not killed."""
    by: str | None
    classes: list[str]
    run: int | None
    """The faulty run that killed it."""
    correct_run: int | None
    """The correct run on the same situation."""
    score_delta: float | None
    possibly_equivalent: bool
    changes: str
    stands_for: str
    faulty_recurs: int | None = None
    """Of the killing test's perturbed copies, the faulty ones showing the failure."""
    correct_recurs: int | None = None
    """…and the correct ones."""
    copies: int | None = None
    """Copies of each side the killing test ran."""
    p_value: float | None = None
    """The killing test's p-value (its bound where it stopped early)."""
    runs_with_reruns: int | None = None
    """Runs up to the first kill, every perturbed copy counted (those of its chunk too)."""
    trials: int = 0
    """Candidate situations tested for it."""

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclass
class FaultReport:
    """An evaluation's results."""

    controller: str
    strategy: str
    seed: int
    budget: int
    situations: int
    """Situations evaluated (equals ``budget`` once finished)."""
    faults: list[FaultRow] = field(default_factory=list)
    mutants: list[FaultRow] = field(default_factory=list)
    """The equivalent mutants run beside the faults: a kill of one is a false kill."""
    runs: int = 0
    """Runs in all, every perturbed copy counted."""
    perturbed_copies: int = 0
    """Of those, the kill tests' perturbed copies."""
    tests_by_copies: dict[int, int] = field(default_factory=dict)
    """Candidate tests (faults' and mutants') by the copies a side they ran before the
    sequential test decided: what the kill rule costs."""

    @property
    def kill_rate(self) -> float:
        return sum(f.killed for f in self.faults) / len(self.faults) if self.faults else 0.0

    @property
    def false_kill_rate(self) -> float:
        """The share of equivalent mutants killed (0 where none ran)."""
        return sum(m.killed for m in self.mutants) / len(self.mutants) if self.mutants else 0.0

    def curve(self) -> list[dict[str, float]]:
        """Kill rate at each budget of :data:`CURVE_BUDGETS` up to the situations evaluated,
        and at that count."""
        budgets = sorted({b for b in CURVE_BUDGETS if b < self.situations} | {self.situations})
        return [{"budget": b, "kill_rate": kill_rate_at(self, b)} for b in budgets if b > 0]

    def as_dict(self) -> dict[str, Any]:
        return {
            "controller": self.controller,
            "strategy": self.strategy,
            "seed": self.seed,
            "budget": self.budget,
            "situations": self.situations,
            "kill_rate": self.kill_rate,
            "killed": sum(f.killed for f in self.faults),
            "false_kill_rate": self.false_kill_rate,
            "runs": self.runs,
            "perturbed_copies": self.perturbed_copies,
            "tests_by_copies": {str(k): v for k, v in sorted(self.tests_by_copies.items())},
            "curve": self.curve(),
            "faults": [f.as_dict() for f in self.faults],
            "mutants": [m.as_dict() for m in self.mutants],
        }


def kill_rate_at(report: FaultReport, budget: int) -> float:
    """The share of the report's faults killed within ``budget`` situations."""
    return share_killed_within(report.faults, budget)


def share_killed_within(rows: list[FaultRow], budget: int) -> float:
    """The share of ``rows`` (faults, or equivalent mutants) killed within ``budget``
    situations; 0 for none."""
    if not rows:
        return 0.0
    killed = sum(f.runs_to_first_kill is not None and f.runs_to_first_kill <= budget for f in rows)
    return killed / len(rows)


def evaluation(store: Store) -> dict[str, Any] | None:
    """The store's fault evaluation plan, or None if it holds none."""
    return store.plan("fault_evaluation")


def fault_report(store: Store) -> FaultReport:
    """The results stored in an evaluation's store. Raises StoreError if it holds none."""
    plan = evaluation(store)
    if plan is None:
        raise StoreError(
            f"{store.path}: holds a {KINDS[store.kind()]}, not a fault evaluation (sitgen faults)"
        )
    campaign = store.campaign() or {}
    kill_columns = {c[1] for c in store.db.execute("PRAGMA table_info(fault_kills)")}
    tested = "faulty_recurs" in kill_columns
    test = ", faulty_recurs, correct_recurs, copies, p_value" if tested else ""
    kills = {
        row[0]: row[1:]
        for row in store.db.execute(
            f"SELECT fault, situation, run_id, by, classes, score_delta{test} FROM fault_kills"
        )
    }
    situations = situations_evaluated(store)
    trials: dict[str, int] = {}
    chunks: list[tuple[int, int]] = []
    tests_by_copies: dict[int, int] = {}
    if store.db.execute("SELECT 1 FROM sqlite_master WHERE name = 'fault_trials'").fetchone():
        trials = dict(
            store.db.execute("SELECT fault, count(*) FROM fault_trials GROUP BY fault").fetchall()
        )
        chunks = store.db.execute(
            "SELECT first, copies FROM fault_chunks ORDER BY first"
        ).fetchall()
        tests_by_copies = dict(
            store.db.execute("SELECT copies, count(*) FROM fault_trials GROUP BY copies")
        )
    runs_at = _runs_with_reruns(store, chunks)
    info = {f["id"]: f for f in catalogue()}
    mutant_info = {m.id: m for m in MUTANTS}
    report = FaultReport(
        controller=plan["controller"]["name"],
        strategy=plan["strategy"],
        seed=campaign.get("seed", 0),
        budget=campaign.get("n", 0),
        situations=situations,
        runs=store.run_count() + sum(c for _, c in chunks),
        perturbed_copies=sum(c for _, c in chunks),
        tests_by_copies=tests_by_copies,
    )
    for arm in [*plan["faults"], *plan.get("mutants", [])]:
        mutant = mutant_info.get(arm)
        if mutant is not None:
            entry = {
                "changes": f"{mutant.param} × {mutant.factor!r} (a relative nudge of "
                f"{abs(mutant.factor - 1):.0e})",
                "stands_for": "an equivalent mutant: no bug at all",
            }
        else:
            entry = info.get(arm, {"changes": "(not in this sitgen's catalogue)", "stands_for": ""})
        row = FaultRow(
            id=arm,
            killed=arm in kills,
            runs_to_first_kill=None,
            by=None,
            classes=[],
            run=None,
            correct_run=None,
            score_delta=None,
            possibly_equivalent=arm not in kills and situations >= POSSIBLY_EQUIVALENT_AFTER,
            changes=entry["changes"],
            stands_for=entry["stands_for"],
            trials=trials.get(arm, 0),
        )
        if arm in kills:
            situation, row.run, row.by, classes, row.score_delta, *counts = kills[arm]
            row.classes = json.loads(classes)
            row.runs_to_first_kill = situation + 1
            row.correct_run = situation * RUN_STRIDE
            if counts:
                row.faulty_recurs, row.correct_recurs, row.copies, row.p_value = counts
            row.runs_with_reruns = runs_at(situation)
        (report.mutants if mutant is not None else report.faults).append(row)
    return report


def _runs_with_reruns(store: Store, chunks: list[tuple[int, int]]) -> Callable[[int], int]:
    """Runs up to and with situation ``i``, every perturbed copy of the chunks up to and with
    its own counted."""
    per_situation: dict[int, int] = dict(
        store.db.execute(
            "SELECT id / ?, count(*) FROM runs GROUP BY id / ?", (RUN_STRIDE, RUN_STRIDE)
        ).fetchall()
    )

    def at(i: int) -> int:
        plain = sum(n for s, n in per_situation.items() if s <= i)
        return plain + sum(c for first, c in chunks if first <= i)

    return at


def write_fault_report(report: FaultReport, out: TextIO) -> None:
    """The report as JSON."""
    json.dump(report.as_dict(), out, indent=2)
    out.write("\n")


def fault_status(row: FaultRow, situations: int) -> str:
    """A fault's result in words."""
    if row.killed:
        how = (
            ", ".join(row.classes)
            if row.by == "class"
            else f"score +{row.score_delta:.0f}"
            if row.by == "score"
            else "controller error"
        )
        if row.copies is not None:
            how += (
                f"; in {row.faulty_recurs}/{row.copies} perturbed copies against "
                f"{row.correct_recurs}/{row.copies}, p ≤ {row.p_value:.1g}"
            )
        return f"killed at situation {row.runs_to_first_kill} ({how})"
    if row.possibly_equivalent:
        return f"possibly equivalent: not killed in {situations} situations"
    return f"not killed in {situations} situations"


def summary_lines(report: FaultReport) -> list[str]:
    """The kill rate and its curve, in words."""
    curve = ", ".join(f"{c['budget']:g}: {c['kill_rate']:.0%}" for c in report.curve())
    lines = [
        f"{report.controller}, {report.strategy} situations, seed {report.seed}: "
        f"{sum(f.killed for f in report.faults)} of {len(report.faults)} faults robustly "
        f"killed in {report.situations} situations, {report.runs} runs with their perturbed "
        f"copies (kill rate {report.kill_rate:.0%})",
        f"kill rate by budget: {curve}",
    ]
    if report.mutants:
        lines.append(
            f"equivalent mutants falsely killed: {sum(m.killed for m in report.mutants)} of "
            f"{len(report.mutants)} (false-kill rate {report.false_kill_rate:.0%})"
        )
    if report.tests_by_copies:
        stages = sorted(report.tests_by_copies)
        lines.append(
            f"kill tests: {sum(report.tests_by_copies.values())} candidate situations, decided "
            f"after {'/'.join(map(str, stages))} copies a side: "
            f"{'/'.join(str(report.tests_by_copies[s]) for s in stages)}; "
            f"{report.perturbed_copies} perturbed copies of {report.runs} runs"
        )
    return lines


def report_from(db: str | Path) -> FaultReport:
    """The results of the evaluation in store ``db``."""
    with Store(db) as store:
        return fault_report(store)
