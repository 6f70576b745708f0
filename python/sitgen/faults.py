"""Fault-finding power: how many of the seeded faults a way of generating situations kills
within a budget (the paper's §6, after Nguyen et al.: the proportion of known faults found,
rather than run scores or fitness).

An evaluation takes a campaign spec whose agent has one built-in controller and a list of that
controller's seeded faults (``docs/faults.md``). Situation ``i`` is the campaign's job ``i``
(same spec, same seed, so the same situation and run seed a campaign would give it); on it the
correct controller runs, and so does every fault not yet killed. A fault is *killed* at the first
situation where :func:`kill` says its run failed in a way the correct run did not. The budget is
the number of situations; a fault's *runs to first kill* is the number of situations it took
(1-based), and the kill rate at budget ``b`` is the share of faults killed within ``b``.

Situations go in chunks of :data:`CHUNK`: a fault killed in one chunk is not run in the next.
Chunks do not depend on the worker count, so neither does anything stored; each chunk's runs
and kills are stored in one transaction, so a killed evaluation loses only the chunk in flight
and the same command resumes it. Runs are stored like a campaign's (``rank``, ``report`` and
``rerun`` work on them), with ids ``i × RUN_STRIDE`` for the correct run on situation ``i`` and
``i × RUN_STRIDE + 1 + k`` for the fault at catalogue position ``k``.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import json
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from sitgen import _core
from sitgen.campaign import (
    CampaignSpec,
    Executor,
    Job,
    _row,
    check_campaign,
    check_workers,
    controller_names,
    job_seed,
    started_at,
    stream_jobs,
)
from sitgen.maps import BARN_WORLDS, BarnWorlds
from sitgen.store import KINDS, Store, StoreError

KILL_MARGIN_POINTS = 100.0
"""A faulty run that shows no new failure class kills its fault only if it scores worse than
the correct run by more than this many points (one collision's start penalty)…"""
KILL_MARGIN_SHARE = 0.5
"""…and by more than this share of the correct run's score (a long pinning of the correct run
varies by more than 100 points from a small perturbation alone)."""
POSSIBLY_EQUIVALENT_AFTER = 200
"""A fault still alive after this many situations is reported as possibly equivalent."""
CHUNK = 16
"""Situations run between two kill checks."""
RUN_STRIDE = 64
"""Run ids per situation: the correct run and up to 63 faults."""
STRATEGIES = ("random", "barn", "stored")
"""How situations are drawn: ``random`` is the campaign's own generation (the paper's);
``barn`` takes the 300 BARN worlds (a fixed, hand-curated benchmark, no peers) in an order
shuffled by the seed, with the campaign's run spec; ``stored`` takes the situations of a stored
campaign or search (``--situations``) in the order it ran them, each with its own run spec and
seed, so that any way of generating (a search, too) can be measured by what it kills."""
MAX_BUDGET = 1_000_000
"""Most situations an evaluation may ask for (``random``; ``barn`` has 300)."""
CURVE_BUDGETS = (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 5000, 10000)
"""Budgets at which the kill-rate curve is given (and the evaluation's own)."""


@functools.cache
def catalogue() -> tuple[dict[str, Any], ...]:
    """Every seeded fault (``id``, ``controllers``, ``changes``, ``stands_for``), in catalogue
    order (read from the core once)."""
    return tuple(_core.fault_catalogue())


@functools.cache
def _slots() -> dict[str, int]:
    return {f["id"]: 1 + k for k, f in enumerate(catalogue())}


def faults_of(controller: str) -> list[str]:
    """The ids of the faults ``controller`` has, in catalogue order."""
    return [f["id"] for f in catalogue() if controller in f["controllers"]]


# The kill rule.


@dataclass(frozen=True)
class Outcome:
    """What the kill rule reads of a run."""

    failure_class: str | None
    """The run's failure class (its most severe event's class); None if nothing failed."""
    classes: frozenset[str]
    """Every failure class its events show."""
    score: float
    error: bool = False
    """The run could not be made or its controller failed."""


@dataclass(frozen=True)
class Kill:
    """Why a faulty run killed its fault."""

    by: str
    """``class``: it fails with a failure class the correct run does not show; ``score``: it
    scored worse by more than the margin; ``error``: its controller failed where the correct
    one did not."""
    classes: tuple[str, ...]
    """The faulty run's failure class (none for a run without one)."""
    score_delta: float
    """Faulty score − correct score."""


def score_margin(correct_score: float) -> float:
    """How much worse than the correct run a faulty run must score to kill by score."""
    return max(KILL_MARGIN_POINTS, KILL_MARGIN_SHARE * correct_score)


def kill(correct: Outcome, faulty: Outcome) -> Kill | None:
    """Whether the faulty run on a situation kills its fault, given the correct run on the same
    situation with the same run seed: it fails with a failure class that the correct run does
    not show at all (not even as a lesser event), or it scores worse by more than
    :func:`score_margin`. A situation the correct run could not use (an error) kills nothing."""
    if correct.error:
        return None
    delta = faulty.score - correct.score
    if faulty.error:
        return Kill("error", (), delta)
    own = () if faulty.failure_class is None else (faulty.failure_class,)
    if faulty.failure_class is not None and faulty.failure_class not in correct.classes:
        return Kill("class", own, delta)
    if delta > score_margin(correct.score):
        return Kill("score", own, delta)
    return None


def outcome_of(store: Store, run_id: int) -> Outcome | None:
    """The kill rule's view of stored run ``run_id``; None if it is not stored."""
    row = store.db.execute(
        "SELECT outcome, score, events_jsonl, failure_class FROM runs WHERE id = ?", (run_id,)
    ).fetchone()
    if row is None:
        return None
    outcome, score, events, failure_class = row
    classes = frozenset(_core.event_classes(events, 0)) if events else frozenset()
    return Outcome(failure_class, classes, score, outcome == "error")


# Planning an evaluation.


@dataclass(frozen=True)
class FaultPlan:
    """What an evaluation runs: the agent's controller spec (without a fault) and the faults."""

    controller: dict[str, Any]
    faults: tuple[str, ...]
    strategy: str = "random"
    situations: str | None = None
    """The store the situations come from (strategy ``stored``)."""

    def as_dict(self) -> dict[str, Any]:
        # Only a stored strategy names its source, so older evaluations' plans still match.
        source = {} if self.situations is None else {"situations": self.situations}
        return {
            **source,
            "controller": self.controller,
            "faults": list(self.faults),
            "strategy": self.strategy,
            "kill_margin_points": KILL_MARGIN_POINTS,
            "kill_margin_share": KILL_MARGIN_SHARE,
        }


def plan_faults(
    spec: CampaignSpec, faults: list[str] | None = None, strategy: str = "random"
) -> FaultPlan:
    """The evaluation of ``spec``'s agent controller under ``faults`` (default: all it has).
    Raises SpecError naming the field or option."""
    if strategy not in STRATEGIES:
        raise _core.SpecError(f"--strategy: `{strategy}` is not one of {', '.join(STRATEGIES)}")
    names = sorted({name for _, name in controller_names(spec)})
    if len(names) > 1:
        raise _core.SpecError(
            f"vary: the campaign gives its agent {len(names)} controllers ({', '.join(names)}); "
            "a fault evaluation needs one"
        )
    run_controller = spec.run.get("controller")
    mission = spec.situation.get("mission", {}).get("agent_controller")
    controller = copy.deepcopy(run_controller or mission or {"name": "snd_follow"})
    where = "run.controller" if run_controller else "situation.mission.agent_controller"
    if not isinstance(controller, dict) or not isinstance(controller.get("name"), str):
        raise _core.SpecError(f"{where}: expected a table with a name")
    if "fault" in controller:
        raise _core.SpecError(
            f"{where}.fault: a fault evaluation switches the faults on itself; remove it"
        )
    name = controller["name"]
    _core.check_controller(name, f"{where}.name")
    own = faults_of(name)
    if not own:
        raise _core.SpecError(
            f"{where}.name: `{name}` has no seeded faults; these controllers do: "
            + ", ".join(sorted({c for f in catalogue() for c in f["controllers"]}))
        )
    if faults is None:
        return FaultPlan(controller, tuple(own), strategy)
    known = [f["id"] for f in catalogue()]
    for fault in faults:
        if fault not in known:
            raise _core.SpecError(
                f"--faults: unknown fault `{fault}`; expected one of {', '.join(known)}"
            )
        if fault not in own:
            raise _core.SpecError(
                f"--faults: `{fault}` is not a fault of `{name}`; its faults: {', '.join(own)}"
            )
    if not faults:
        raise _core.SpecError("--faults: no fault named")
    return FaultPlan(controller, tuple(f for f in own if f in faults), strategy)


def fault_slot(fault: str) -> int:
    """The fault's position in the run ids of a situation (1 + its catalogue position)."""
    return _slots()[fault]


class Situations:
    """Situation ``i`` of an evaluation, as the job a campaign would run there."""

    def __init__(
        self,
        spec: CampaignSpec,
        seed: int,
        strategy: str,
        barn_dir: Path | None = None,
        stored: Path | None = None,
    ) -> None:
        self.spec, self.seed, self.strategy = spec, seed, strategy
        self.barn: BarnWorlds | None = None
        self.stored: Store | None = None
        self.order: list[int] = []
        if strategy == "stored":
            if stored is None:
                raise _core.SpecError(
                    "--situations: strategy stored needs a campaign or search store"
                )
            try:
                self.stored = Store(stored)
            except StoreError as e:
                raise _core.SpecError(f"--situations: {e}") from None
            kind = self.stored.kind()
            if kind == "fault_evaluation":
                raise _core.SpecError(
                    f"--situations: {stored} holds a fault evaluation; give a campaign or search"
                )
            self.order = sorted(self.stored.done_ids())
        elif strategy == "barn":
            try:
                self.barn = BarnWorlds(barn_dir or Path("."))
            except OSError as e:
                raise _core.SpecError(
                    f"--barn-dir: {barn_dir} holds no BARN data ({e}); give ../shared/data/barn"
                ) from None
            rng = np.random.Generator(np.random.PCG64(seed))
            self.order = [int(k) for k in rng.permutation(BARN_WORLDS)]

    def most(self) -> int:
        """How many situations there are."""
        if self.strategy == "stored":
            return len(self.order)
        return BARN_WORLDS if self.strategy == "barn" else MAX_BUDGET

    def close(self) -> None:
        if self.stored is not None:
            self.stored.close()

    def job(self, i: int) -> Job:
        """Situation ``i``'s job; one whose spec cannot be built carries its error."""
        if self.stored is not None:
            row = self.stored.run_row(self.order[i])
            # A stored situation that could not be built is not retried: it kills nothing.
            error = None if row["content_hash"] else "spec: its situation could not be built"
            seed = row["situation_seed"]
            return Job(i, seed, row["situation_spec"], row["run_spec"], error)
        if self.barn is not None:
            situation = json.loads(self.barn.situation(self.order[i]).to_json())
            return Job(i, job_seed(self.seed, i), situation, copy.deepcopy(self.spec.run))
        return next(stream_jobs(self.spec, self.seed, [i]))


def _jobs(situations: Situations, i: int, plan: FaultPlan, faults: list[str]) -> list[Job]:
    """Situation ``i``'s runs: the correct controller's, then each fault's."""
    base = situations.job(i)
    jobs = []
    for slot, fault in [(0, None), *((fault_slot(f), f) for f in faults)]:
        controller = dict(plan.controller, **({"fault": fault} if fault else {}))
        run = dict(base.run, controller=controller)
        jobs.append(Job(i * RUN_STRIDE + slot, base.seed, base.situation, run, base.error))
    return jobs


# Running an evaluation.


@dataclass(frozen=True)
class FaultsResult:
    """What an evaluation call did."""

    ran: int
    """Runs done by this call."""
    situations: int
    """Situations evaluated in all."""
    interrupted: bool
    wall_s: float


def _alive_before(store: Store, plan: FaultPlan, situation: int) -> list[str]:
    killed = {
        fault
        for (fault,) in store.db.execute(
            "SELECT fault FROM fault_kills WHERE situation < ?", (situation,)
        )
    }
    return [f for f in plan.faults if f not in killed]


def _kills(store: Store, situations: range, alive: list[str]) -> dict[str, tuple[int, Kill]]:
    """The first kill within ``situations`` of each fault in ``alive``."""
    found: dict[str, tuple[int, Kill]] = {}
    for i in situations:
        correct = outcome_of(store, i * RUN_STRIDE)
        if correct is None:
            continue
        for fault in alive:
            if fault in found:
                continue
            faulty = outcome_of(store, i * RUN_STRIDE + fault_slot(fault))
            if faulty is not None and (k := kill(correct, faulty)) is not None:
                found[fault] = (i, k)
    return found


def run_faults(
    spec: CampaignSpec,
    db: str | Path,
    seed: int = 0,
    budget: int = 100,
    faults: list[str] | None = None,
    strategy: str = "random",
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    stop: Callable[[], bool] | None = None,
    barn_dir: Path | None = None,
    situations_db: Path | None = None,
) -> FaultsResult:
    """Evaluate (or resume evaluating) ``spec``'s agent controller under ``faults`` on
    ``budget`` situations, into store ``db``. ``on_progress(situations done, budget)``;
    ``stop()`` is checked after every run and ends the evaluation after the chunk in flight's
    runs are abandoned (they are run again on resume)."""
    if not 1 <= budget <= MAX_BUDGET:
        raise _core.SpecError(f"--budget: {budget} is not in [1, {MAX_BUDGET}]")
    workers = check_workers(workers, backend)
    plan = plan_faults(spec, faults, strategy)
    if strategy == "stored" and situations_db is not None:
        plan = dataclasses.replace(plan, situations=str(situations_db))
    situations = Situations(spec, seed, strategy, barn_dir, situations_db)
    try:
        return _run_faults(
            spec, db, seed, budget, plan, situations, workers, backend, address, on_progress, stop
        )
    finally:
        situations.close()


def _run_faults(
    spec: CampaignSpec,
    db: str | Path,
    seed: int,
    budget: int,
    plan: FaultPlan,
    situations: Situations,
    workers: int,
    backend: str,
    address: str | None,
    on_progress: Callable[[int, int], None] | None,
    stop: Callable[[], bool] | None,
) -> FaultsResult:
    strategy = plan.strategy
    if budget > situations.most():
        raise _core.SpecError(
            f"--budget: {budget} is more than the {situations.most()} situations of "
            f"strategy {strategy}"
        )
    started = time.perf_counter()
    # A benchmark's situations are given: only the campaign's controllers need checking.
    check_campaign(spec, seed, budget if strategy == "random" else 0, stop)
    if stop is not None and stop():
        return FaultsResult(0, 0, True, time.perf_counter() - started)
    with Store(db, create=True) as store:
        store.lock_for_writing()
        store.start_campaign(
            spec.source, seed, budget, _core.__version__, started_at(), evaluation=plan.as_dict()
        )
        done = store.done_ids()
        executor = Executor(workers, backend, address)
        ran = 0
        interrupted = False
        if on_progress:
            on_progress(0, budget)
        for first in range(0, budget, CHUNK):
            chunk = range(first, min(first + CHUNK, budget))
            alive = _alive_before(store, plan, first)
            jobs = [
                j for i in chunk for j in _jobs(situations, i, plan, alive) if j.index not in done
            ]
            rows = []
            for job, result in executor.results(jobs):
                rows.append(_row(job, result))
                ran += 1
                if stop is not None and stop():
                    executor.stop()
            # Finished runs are kept even if the chunk is not: a resumed evaluation skips them.
            store.add_runs(rows)
            done.update(row.id for row in rows)
            if len(rows) < len(jobs):
                interrupted = True
                break
            store.record_kills(
                {
                    fault: (situation, situation * RUN_STRIDE + fault_slot(fault), k)
                    for fault, (situation, k) in _kills(store, chunk, alive).items()
                }
            )
            if on_progress:
                on_progress(chunk.stop, budget)
            if stop is not None and stop():
                interrupted = chunk.stop < budget
                break
        evaluated = _evaluated(store)
    return FaultsResult(ran, evaluated, interrupted, time.perf_counter() - started)


def _evaluated(store: Store) -> int:
    """Situations evaluated: the correct runs stored (each chunk is stored whole)."""
    count: int = store.db.execute(
        "SELECT count(*) FROM runs WHERE id % ? = 0", (RUN_STRIDE,)
    ).fetchone()[0]
    return count


# Reading an evaluation.


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

    @property
    def kill_rate(self) -> float:
        return sum(f.killed for f in self.faults) / len(self.faults) if self.faults else 0.0

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
            "curve": self.curve(),
            "faults": [f.as_dict() for f in self.faults],
        }


def kill_rate_at(report: FaultReport, budget: int) -> float:
    """The share of the report's faults killed within ``budget`` situations."""
    if not report.faults:
        return 0.0
    killed = sum(
        f.runs_to_first_kill is not None and f.runs_to_first_kill <= budget for f in report.faults
    )
    return killed / len(report.faults)


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
    kills = {
        fault: (situation, run_id, by, json.loads(classes), delta)
        for fault, situation, run_id, by, classes, delta in store.db.execute(
            "SELECT fault, situation, run_id, by, classes, score_delta FROM fault_kills"
        )
    }
    situations = _evaluated(store)
    info = {f["id"]: f for f in catalogue()}
    report = FaultReport(
        controller=plan["controller"]["name"],
        strategy=plan["strategy"],
        seed=campaign.get("seed", 0),
        budget=campaign.get("n", 0),
        situations=situations,
    )
    for fault in plan["faults"]:
        entry = info.get(fault, {"changes": "(not in this sitgen's catalogue)", "stands_for": ""})
        row = FaultRow(
            id=fault,
            killed=fault in kills,
            runs_to_first_kill=None,
            by=None,
            classes=[],
            run=None,
            correct_run=None,
            score_delta=None,
            possibly_equivalent=fault not in kills and situations >= POSSIBLY_EQUIVALENT_AFTER,
            changes=entry["changes"],
            stands_for=entry["stands_for"],
        )
        if fault in kills:
            situation, row.run, row.by, row.classes, row.score_delta = kills[fault]
            row.runs_to_first_kill = situation + 1
            row.correct_run = situation * RUN_STRIDE
        report.faults.append(row)
    return report


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
        return f"killed at situation {row.runs_to_first_kill} ({how})"
    if row.possibly_equivalent:
        return f"possibly equivalent: not killed in {situations} situations"
    return f"not killed in {situations} situations"


def summary_lines(report: FaultReport) -> list[str]:
    """The kill rate and its curve, in words."""
    curve = ", ".join(f"{c['budget']:g}: {c['kill_rate']:.0%}" for c in report.curve())
    return [
        f"{report.controller}, {report.strategy} situations, seed {report.seed}: "
        f"{sum(f.killed for f in report.faults)} of {len(report.faults)} faults killed in "
        f"{report.situations} situations (kill rate {report.kill_rate:.0%})",
        f"kill rate by budget: {curve}",
    ]


def report_from(db: str | Path) -> FaultReport:
    """The results of the evaluation in store ``db``."""
    with Store(db) as store:
        return fault_report(store)
