"""Robust distinct failures with headroom: a failure's *variant* is its base failure class ×
the interaction it began in × the terrain context it began in, and a variant counts once a run
of it recurs under perturbation.

Why: distinct failures counted by class alone saturate near the size of the class taxonomy
(random generation finds 16 within 500 runs), so they cannot show one generator ahead of
another. The interaction (``head_on``, ``crossing_left``, …, ``no_peer`` for a failure no peer
took part in) and the terrain context (``open``, ``corridor``, ``gap``, ``dead_end``,
``blind_corner``) come from the run's coverage record (docs/coverage.md: ``failure_cell``,
``failure_at``): the same class in a corridor and in the open, or met head-on and from the side,
are different things for an engineer to fix.

The yardstick (:func:`robust_variants`) is the same for every strategy and counts every rerun
against the budget: it walks a store's runs in the order they were made, each costing one
evaluation; a failing run whose variant is not yet confirmed is rerun in perturbed copies
(:mod:`sitgen.triage.robustness`; 6 of 8 must recur with the run's class, the robustness
rule) until the verdict is decided — 6 recurred or 3 missed — each copy costing one, so the
verdict is the one all 8 copies would give (copy ``k`` is the same whenever it runs) and no
copy is run that could not change it; a variant is tried at most :data:`ATTEMPTS` times. It
stops when the budget is spent. The rule for one run is :class:`Screen`, which a search uses
on its own runs as it makes them.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

from sitgen.execution.jobs import check_workers
from sitgen.store import Store, unpack_json
from sitgen.triage.recall import stored_run
from sitgen.triage.robustness import RERUNS, ROBUST_SHARE, copies, copy_class, copy_jobs

NO_PEER = "no_peer"
UNKNOWN = "unknown"
ATTEMPTS = 2
"""Runs of one variant the yardstick reruns before it gives the variant up as knife-edge."""


def variant(failure_class: str | None, coverage: dict[str, Any] | None) -> str | None:
    """``CLASS/INTERACTION/CONTEXT`` of a failing run, from its failure class and coverage
    record; None if it did not fail."""
    if failure_class is None:
        return None
    coverage = coverage or {}
    cell = coverage.get("failure_cell")
    parts = cell.split("/") if cell else []
    interaction = parts[0] if parts else NO_PEER
    at = coverage.get("failure_at") or {}
    context = at.get("context") or (parts[2] if len(parts) > 2 else UNKNOWN)
    return f"{failure_class}/{interaction}/{context}"


def interaction_context(key: str) -> str:
    """The ``INTERACTION/CONTEXT`` part of a variant key."""
    return key.split("/", 1)[1]


@dataclass(frozen=True)
class Trial:
    """One variant's robustness test on one run."""

    run_id: int
    key: str
    classes: tuple[str | None, ...]
    robust: bool
    spent_before: int
    """Evaluations spent before this test's copies (runs walked and earlier copies)."""


@dataclass
class Tally:
    """What the yardstick found in a store within a budget."""

    budget: int
    spent: int = 0
    runs: int = 0
    copies: int = 0
    robust: dict[str, int] = field(default_factory=dict)
    """Each robust variant and the run that showed it."""
    trials: list[Trial] = field(default_factory=list)
    at_budget: dict[int, int] = field(default_factory=dict)
    """Robust variants found within each checkpoint budget asked for."""
    first_at: dict[str, int] = field(default_factory=dict)
    """Each robust variant: evaluations spent when it was confirmed."""
    runs_at: dict[int, int] = field(default_factory=dict)
    """Runs walked within each checkpoint budget asked for (the rest of it went on copies)."""


def runs_in_order(store: Store) -> Iterator[tuple[int, str | None, dict[str, Any] | None]]:
    """(run id, failure class, coverage record) of every stored run, in the order made."""
    for run_id, cls, coverage in store.db.execute(
        "SELECT id, failure_class, coverage FROM runs ORDER BY id"
    ):
        yield run_id, cls, unpack_json(coverage) if coverage else None


@dataclass
class Screen:
    """The yardstick's rule for one run at a time: which failing runs get copies, and what they
    showed. The yardstick walks a finished store with it; a search screens its own runs as it
    makes them with the same rule in the same order, so the copies it spends are the ones the
    yardstick would (and counts), and it learns which variants recur."""

    workers: int = 1
    robust: dict[str, int] = field(default_factory=dict)
    """Each robust variant and the run that showed it."""
    attempts: dict[str, int] = field(default_factory=dict)
    """Runs of each variant tested so far."""

    def wants(self, key: str | None) -> bool:
        """Whether a run of variant ``key`` gets copies."""
        return key is not None and key not in self.robust and self.attempts.get(key, 0) < ATTEMPTS

    def test(self, store: Store, run_id: int, key: str, spent: int, most: int) -> Trial:
        """Copies of run ``run_id`` (at most ``most``) and the verdict on variant ``key``."""
        self.attempts[key] = self.attempts.get(key, 0) + 1
        trial = _trial(store, run_id, key, spent, min(most, RERUNS), self.workers)
        if trial.robust:
            self.robust[key] = run_id
        return trial


def robust_variants(
    store: Store,
    budget: int,
    checkpoints: Sequence[int] = (),
    workers: int = 1,
) -> Tally:
    """Walk ``store``'s runs (:mod:`module docs <sitgen.triage.variants>`) within ``budget``
    evaluations; the robust variants found, and how many within each of ``checkpoints``."""
    screen = Screen(check_workers(workers, "local"))
    tally = Tally(budget, robust=screen.robust)
    run_spent: list[int] = []
    for run_id, cls, coverage in runs_in_order(store):
        if tally.spent >= budget:
            break
        tally.spent += 1
        tally.runs += 1
        run_spent.append(tally.spent)
        key = variant(cls, coverage)
        if key is None or not screen.wants(key):
            continue
        left = budget - tally.spent
        if left < math.ceil(ROBUST_SHARE * RERUNS):
            continue  # too little budget left to confirm anything
        trial = screen.test(store, run_id, key, tally.spent, left)
        tally.trials.append(trial)
        tally.spent += len(trial.classes)
        tally.copies += len(trial.classes)
        if trial.robust:
            tally.first_at[key] = tally.spent
    for mark in checkpoints:
        if mark <= budget:
            # Confirmed within the mark: a test whose copies cross it counts after it.
            tally.at_budget[mark] = sum(spent <= mark for spent in tally.first_at.values())
            tally.runs_at[mark] = sum(spent <= mark for spent in run_spent)
    return tally


def _trial(store: Store, run_id: int, key: str, spent: int, most: int, workers: int) -> Trial:
    """The run's copies (at most ``most``) until robustness is decided (curtailed: each batch
    is the fewest further copies that could decide it, so a batch never holds a copy the
    verdict did not need, and the copies run together)."""
    row = stored_run(store, run_id)
    cls = key.split("/", 1)[0]
    need = math.ceil(ROBUST_SHARE * RERUNS - 1e-9)
    may_miss = RERUNS - need
    jobs = copy_jobs(row, RERUNS, 0)
    classes: list[str | None] = []
    hits = 0
    while len(classes) < min(most, RERUNS):
        misses = len(classes) - hits
        if hits >= need or misses > may_miss:
            break
        batch = min(need - hits, may_miss + 1 - misses, most - len(classes))
        done = len(classes)
        classes += [copy_class(r) for r in copies(jobs[done : done + batch], workers)]
        hits = sum(c == cls for c in classes)
    return Trial(run_id, key, tuple(classes), hits >= need, spent)


@dataclass(frozen=True)
class Variant:
    """The runs of one variant in a store."""

    key: str
    runs: int
    best_run: int
    best_score: float


def variants_of(store: Store, failure_class: str | None = None) -> list[Variant]:
    """Every variant among ``store``'s runs (of ``failure_class`` only, if given), most runs
    first, with its highest-scoring run."""
    groups: dict[str, list[tuple[float, int]]] = {}
    for run_id, cls, score, coverage in store.db.execute(
        "SELECT id, failure_class, score, coverage FROM runs WHERE failure_class IS NOT NULL "
        "ORDER BY id"
    ):
        if failure_class is not None and cls != failure_class:
            continue
        key = variant(cls, unpack_json(coverage) if coverage else None)
        assert key is not None
        groups.setdefault(key, []).append((score, run_id))
    out = []
    for key, runs in groups.items():
        score, best = max(runs, key=lambda r: (r[0], -r[1]))
        out.append(Variant(key, len(runs), best, score))
    return sorted(out, key=lambda v: (-v.runs, v.key))
