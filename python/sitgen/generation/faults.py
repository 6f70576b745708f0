"""Fault-finding power: how many of the seeded faults a way of generating situations kills
within a budget (the paper's §6, after Nguyen et al.: the proportion of known faults found,
rather than run scores or fitness).

An evaluation takes a campaign spec whose agent has one built-in controller and a list of that
controller's seeded faults (``docs/faults.md``). Situation ``i`` is the campaign's job ``i`` (same
spec, same seed, so the same situation and run seed a campaign would give it); on it the correct
controller runs, and so does every fault not yet killed, and every equivalent mutant
(:data:`sitgen.triage.kill.MUTANTS`) not yet killed. A fault is *killed* at the first situation
where its run passes :func:`sitgen.triage.kill.screen` and its perturbed copies then show the
failure significantly more often than the correct controller's (:mod:`sitgen.triage.kill`). The
budget is the number of situations; a fault's *runs to first kill* is the number of situations it
took (1-based), ``runs_with_reruns`` the runs with every perturbed copy counted, and the kill rate
at budget ``b`` is the share of faults killed within ``b``.

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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.execution.campaign import Executor, run_chunk, started_at
from sitgen.execution.jobs import (
    CampaignSpec,
    Job,
    check_campaign,
    check_workers,
    controller_names,
    job_seed,
    stream_jobs,
)
from sitgen.store import Store, StoreError
from sitgen.triage.kill import (
    ALPHA,
    COPIES,
    KILL_MARGIN_POINTS,
    KILL_MARGIN_SHARE,
    MUTANTS,
    STAGES,
    Event,
    Kill,
    Outcome,
    event_of,
    mutants_of,
    outcome_of_copy,
    p_bounds,
    screen,
    verdict,
)
from sitgen.triage.recall import stored_run
from sitgen.triage.robustness import perturbed
from sitgen.world.maps import BARN_WORLDS, BarnWorlds

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
    """Every seeded fault (``id``, ``controllers``, ``changes``, ``stands_for``,
    ``exposed_by``), in catalogue order (read from the core once)."""
    return tuple(_core.fault_catalogue())


def is_harder(fault: str) -> bool:
    """Whether ``fault`` shows only in particular circumstances (its catalogue entry names the
    kind of situation that exposes it): the faults that tell strategies apart."""
    return any(f["id"] == fault and f["exposed_by"] for f in catalogue())


@functools.cache
def _slots() -> dict[str, int]:
    # Faults from 1 up, equivalent mutants down from the top of a situation's ids.
    faults = {f["id"]: 1 + k for k, f in enumerate(catalogue())}
    mutants = {m.id: RUN_STRIDE - len(MUTANTS) + k for k, m in enumerate(MUTANTS)}
    assert len(faults) < RUN_STRIDE - len(MUTANTS), "the ids of a situation's runs overlap"
    return faults | mutants


def faults_of(controller: str) -> list[str]:
    """The ids of the faults ``controller`` has, in catalogue order."""
    return [f["id"] for f in catalogue() if controller in f["controllers"]]


def outcome_of(store: Store, run_id: int) -> Outcome | None:
    """The kill rule's view of stored run ``run_id``; None if it is not stored."""
    row = store.db.execute(
        "SELECT outcome, score, events_jsonl, failure_class FROM runs WHERE id = ?", (run_id,)
    ).fetchone()
    if row is None:
        return None
    outcome, score, events, failure_class = row
    classes = frozenset(_core.event_classes(events, 0)) if events else frozenset()
    violated = frozenset(
        v["name"] for v in store.requirement_verdicts(violated_only=True, run_id=run_id)
    )
    return Outcome(failure_class, classes, score, outcome == "error", violated)


@dataclass(frozen=True)
class FaultPlan:
    """What an evaluation runs: the agent's controller spec (without a fault), the faults, and
    the equivalent mutants that check the kill rule."""

    controller: dict[str, Any]
    faults: tuple[str, ...]
    strategy: str = "random"
    situations: str | None = None
    """The store the situations come from (strategy ``stored``)."""
    mutants: tuple[str, ...] = ()
    """Ids of the equivalent mutants run beside the faults (:data:`sitgen.triage.kill.MUTANTS`)."""

    @property
    def arms(self) -> tuple[str, ...]:
        """Everything run beside the correct controller: the faults, then the mutants."""
        return self.faults + self.mutants

    def controller_of(self, arm: str) -> dict[str, Any]:
        """The controller spec of fault or mutant ``arm``."""
        mutant = next((m for m in MUTANTS if m.id == arm), None)
        if mutant is None:
            return dict(self.controller, fault=arm)
        return dict(self.controller, params=mutant.params(self.controller.get("params", {})))

    def as_dict(self) -> dict[str, Any]:
        # Only a stored strategy names its source, so older evaluations' plans still match.
        source = {} if self.situations is None else {"situations": self.situations}
        return {
            **source,
            "controller": self.controller,
            "faults": list(self.faults),
            "mutants": list(self.mutants),
            "strategy": self.strategy,
            "kill_margin_points": KILL_MARGIN_POINTS,
            "kill_margin_share": KILL_MARGIN_SHARE,
            "kill_rule": {"alpha": ALPHA, "copies": COPIES, "stages": list(STAGES)},
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
    mutants = tuple(m.id for m in mutants_of(name))
    if faults is None:
        return FaultPlan(controller, tuple(own), strategy, mutants=mutants)
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
    return FaultPlan(controller, tuple(f for f in own if f in faults), strategy, mutants=mutants)


def fault_slot(fault: str) -> int:
    """The position of a fault (1 + its catalogue position) or an equivalent mutant (from
    the top down) in the run ids of a situation."""
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
            row = stored_run(self.stored, self.order[i])
            # A stored situation that could not be built is not retried: it kills nothing.
            error = None if row["content_hash"] else "spec: its situation could not be built"
            seed = row["situation_seed"]
            return Job(i, seed, row["situation_spec"], row["run_spec"], error)
        if self.barn is not None:
            situation = json.loads(self.barn.situation(self.order[i]).to_json())
            return Job(i, job_seed(self.seed, i), situation, copy.deepcopy(self.spec.run))
        return next(stream_jobs(self.spec, self.seed, [i]))


def _jobs(situations: Situations, i: int, plan: FaultPlan, arms: list[str]) -> list[Job]:
    """Situation ``i``'s runs: the correct controller's, then each fault's and mutant's."""
    base = situations.job(i)
    jobs = [Job(i * RUN_STRIDE, base.seed, base.situation, _run_of(base, plan, None), base.error)]
    for arm in arms:
        run = _run_of(base, plan, arm)
        jobs.append(
            Job(i * RUN_STRIDE + fault_slot(arm), base.seed, base.situation, run, base.error)
        )
    return jobs


def _run_of(base: Job, plan: FaultPlan, arm: str | None) -> dict[str, Any]:
    """The run spec of situation ``base`` for the correct controller (None) or ``arm``."""
    controller = plan.controller if arm is None else plan.controller_of(arm)
    return dict(base.run, controller=controller)


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
    return [f for f in plan.arms if f not in killed]


def _candidates(
    store: Store, situations: range, alive: list[str]
) -> dict[str, list[tuple[int, Kill, Event]]]:
    """Each arm's situations within ``situations`` whose unperturbed pair passes the screen,
    in order, with what passed and the event its copies are judged by."""
    found: dict[str, list[tuple[int, Kill, Event]]] = {}
    for i in situations:
        correct = outcome_of(store, i * RUN_STRIDE)
        if correct is None:
            continue
        for arm in alive:
            faulty = outcome_of(store, i * RUN_STRIDE + fault_slot(arm))
            if faulty is not None and (k := screen(correct, faulty)) is not None:
                found.setdefault(arm, []).append((i, k, event_of(correct, k)))
    return found


@dataclass
class Trial:
    """One candidate situation's sequential test for one arm."""

    arm: str
    situation: int
    screened: Kill
    event: Event
    faulty: int = 0
    """Faulty copies that showed the event."""
    correct: int = 0
    """Correct copies that showed it."""
    done: int = 0
    """Copies of each side run."""
    killed: bool | None = None

    def kill(self) -> Kill:
        """The screen's difference with the test's counts."""
        return dataclasses.replace(
            self.screened,
            faulty_recurs=self.faulty,
            correct_recurs=self.correct,
            copies=self.done,
            p_value=self.p_bound(),
        )

    def p_bound(self) -> float:
        """The p-value the verdict rests on: for a kill, the most the full test's could be
        whatever the copies not run would show; for a spare, the least."""
        worst, best = p_bounds(self.faulty, self.correct, self.done)
        return worst if self.killed else best

    def row(self) -> dict[str, Any]:
        """The store's row of this trial (:meth:`Store.record_fault_chunk`)."""
        k = self.kill()
        return {
            "fault": self.arm,
            "situation": self.situation,
            "run_id": self.situation * RUN_STRIDE + fault_slot(self.arm),
            "by": k.by,
            "classes": list(k.classes),
            "score_delta": k.score_delta,
            "faulty_recurs": k.faulty_recurs,
            "correct_recurs": k.correct_recurs,
            "copies": k.copies,
            "p_value": k.p_value,
            "killed": bool(self.killed),
        }


def _confirm(
    executor: Executor,
    situations: Situations,
    plan: FaultPlan,
    candidates: dict[str, list[tuple[int, Kill, Event]]],
    stop: Callable[[], bool] | None,
) -> tuple[list[Trial], int] | None:
    """Test each arm's candidates in order until one kills it (or none is left): every arm's
    trial in flight runs its next stage of copies in one batch with the others, and a copy of
    the correct controller serves every arm tested on its situation. Returns the trials and
    the copies run; None if stopped part way."""
    queue = {arm: list(c) for arm, c in candidates.items()}
    active = {arm: Trial(arm, *queue[arm].pop(0)) for arm in sorted(queue, key=fault_slot)}
    trials: list[Trial] = []
    correct: dict[tuple[int, int], Outcome] = {}
    bases: dict[int, Job] = {}
    copies = 0
    while active:
        wanted: list[tuple[str | None, int, int]] = []
        for t in active.values():
            target = next(n for n in STAGES if n > t.done)
            for k in range(t.done + 1, target + 1):
                wanted.append((t.arm, t.situation, k))
                if (t.situation, k) not in correct and (None, t.situation, k) not in wanted:
                    wanted.append((None, t.situation, k))
        jobs = []
        for index, (arm, i, k) in enumerate(wanted):
            base = bases.setdefault(i, situations.job(i))
            run = perturbed(_run_of(base, plan, arm), k)
            jobs.append(Job(index, base.seed, base.situation, run, base.error))
        seen: dict[int, Outcome] = {}
        for job, result in executor.results(jobs):
            seen[job.index] = outcome_of_copy(result)
            if stop is not None and stop():
                executor.stop()
        if len(seen) < len(jobs):
            return None
        copies += len(jobs)
        for index, (arm, i, k) in enumerate(wanted):
            if arm is None:
                correct[(i, k)] = seen[index]
        for index, (arm, i, k) in enumerate(wanted):
            if arm is None:
                continue
            t = active[arm]
            t.faulty += t.event.shown(seen[index])
            t.correct += t.event.shown(correct[(i, k)])
            t.done = max(t.done, k)
        for arm in list(active):
            t = active[arm]
            t.killed = verdict(t.faulty, t.correct, t.done)
            if t.killed is None:
                continue
            trials.append(t)
            del active[arm]
            if not t.killed and queue[arm]:
                active[arm] = Trial(arm, *queue[arm].pop(0))
    return trials, copies


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
            stored, complete = run_chunk(executor, store, jobs, stop)
            ran += len(stored)
            done.update(stored)
            if not complete:
                interrupted = True
                break
            candidates = _candidates(store, chunk, alive)
            confirmed = _confirm(executor, situations, plan, candidates, stop)
            if confirmed is None:
                interrupted = True
                break
            trials, copies = confirmed
            store.record_fault_chunk(chunk.start, copies, (t.row() for t in trials))
            if on_progress:
                on_progress(chunk.stop, budget)
            if stop is not None and stop():
                interrupted = chunk.stop < budget
                break
        evaluated = situations_evaluated(store)
    return FaultsResult(ran, evaluated, interrupted, time.perf_counter() - started)


def situations_evaluated(store: Store) -> int:
    """Situations evaluated: the correct runs stored (each chunk is stored whole)."""
    count: int = store.db.execute(
        "SELECT count(*) FROM runs WHERE id % ? = 0", (RUN_STRIDE,)
    ).fetchone()[0]
    return count
