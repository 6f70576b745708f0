"""What a controller change fixed and what it broke: the same situations under controller A
and controller B, each difference in failure judged on perturbed copies.

Situation ``i`` is a campaign's job ``i`` (``strategy = random``: its spec and seed) or the
``i``-th run of a stored campaign or search (``stored``: its situation, run spec and seed). On it A
and B run unperturbed. Where both fail with the same class, or neither fails, the situation is
*unchanged*. Where they differ, each class C that either shows is judged on the same
:data:`sitgen.triage.kill.COPIES` perturbed copies of both (:mod:`sitgen.triage.robustness`): C is
*robustly new in B* on that situation when B's copies fail with C significantly more often than A's
(the kill rule's one-sided Fisher exact test, at its level, stopped early the same way), *robustly
fixed in B* when A's do, and *not robust either way* otherwise.

A distinct failure here is a base failure class. Its verdict sums its situations: new in B
where it is robustly new somewhere and fixed nowhere, fixed where the reverse, ``new and
fixed`` where both, unchanged where it showed alike on every situation it showed on, and not
robust either way for the rest. B *has robust new failures* when any class is robustly new on
any situation: ``sitgen diff`` then exits 1, and ``--junit`` writes a failed test case for it.
A situation either side could not run is not compared, and the diff says so per side (in its
summary, JSON and JUnit) and fails: so does a diff that evaluated fewer situations than asked.

Situations go in chunks of :data:`CHUNK`; each chunk's runs are stored as they finish and its
verdicts in one transaction after its copies, so a killed diff resumes with the same command.
Runs are stored like a campaign's: run ``2i`` is A on situation ``i``, ``2i + 1`` is B.
Reading a stored diff (its verdicts by class, the summary and JUnit) is
:mod:`sitgen.generation.diff_report`.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sitgen import _core
from sitgen.controllers.user import is_user_controller
from sitgen.execution.campaign import Executor, run_chunk, started_at
from sitgen.execution.jobs import (
    CampaignSpec,
    Job,
    check_campaign,
    check_kept_alive,
    check_workers,
)
from sitgen.generation.faults import Situations, outcome_of
from sitgen.store import Store
from sitgen.triage.kill import (
    ALPHA,
    COPIES,
    REQUIREMENT,
    STAGES,
    Outcome,
    outcome_of_copy,
    p_value,
    verdict,
)
from sitgen.triage.robustness import MAX_RERUNS, perturbed

CHUNK = 16
"""Situations run between two rounds of perturbed copies."""
MAX_SITUATIONS = 1_000_000
SIDES = ("a", "b")

NEW = "new in B"
FIXED = "fixed in B"
BOTH = "new and fixed"
UNCHANGED = "unchanged"
NOT_ROBUST = "not robust either way"


def parse_controller(text: str, option: str) -> dict[str, Any]:
    """A controller as ``--a``/``--b`` give it: a name (``snd_follow``, ``python:m:C``,
    ``cmd:prog args``), a built-in with a fault (``snd_follow+safety_distance_halved``), or a
    JSON controller table (``{"name": "snd_follow", "params": {"max_speed": 0.4}}``). Raises
    SpecError naming the option."""
    text = text.strip()
    if text.startswith("{"):
        try:
            controller = json.loads(text)
        except json.JSONDecodeError as e:
            raise _core.SpecError(f"{option}: not a JSON controller table ({e.msg})") from None
        if not isinstance(controller, dict):
            raise _core.SpecError(f"{option}: expected a JSON object with a name")
    elif "+" in text and not is_user_controller(text):
        name, _, fault = text.partition("+")
        controller = {"name": name, "fault": fault}
    else:
        controller = {"name": text}
    if not isinstance(controller.get("name"), str) or not controller["name"]:
        raise _core.SpecError(f"{option}: expected a controller name")
    try:
        _core.check_run_spec(json.dumps({"controller": controller}))
    except _core.SpecError as e:
        raise _core.SpecError(f"{option}: {e}") from None
    return controller


def with_params(
    controller: dict[str, Any],
    params: Mapping[str, float],
    option: str,
    step_timeout_s: float | None = None,
) -> dict[str, Any]:
    """``controller`` (as :func:`parse_controller` gives it) with ``params`` over its own, and
    a user controller's ``step_timeout_s`` (a built-in has none); SpecError names the option
    if the controller does not take them."""
    if step_timeout_s and is_user_controller(str(controller["name"])):
        controller = {**controller, "step_timeout_s": step_timeout_s}
    if not params:
        return controller
    given = {**controller, "params": {**dict(controller.get("params") or {}), **params}}
    try:
        _core.check_run_spec(json.dumps({"controller": given}))
    except _core.SpecError as e:
        raise _core.SpecError(f"{option}: {e}") from None
    return given


@dataclass(frozen=True)
class DiffPlan:
    """What a diff compares."""

    a: dict[str, Any]
    b: dict[str, Any]
    strategy: str = "random"
    situations: str | None = None
    copies: int = COPIES
    """Perturbed copies a side of each difference (``--reruns``)."""

    @property
    def stages(self) -> tuple[int, ...]:
        """After how many copies a side the differences are judged: the kill rule's stages
        below :attr:`copies`, then :attr:`copies`."""
        return (*(s for s in STAGES if s < self.copies), self.copies)

    def as_dict(self) -> dict[str, Any]:
        source = {} if self.situations is None else {"situations": self.situations}
        return {
            **source,
            "a": self.a,
            "b": self.b,
            "strategy": self.strategy,
            "kill_rule": {"alpha": ALPHA, "copies": self.copies, "stages": list(self.stages)},
        }

    def controller(self, side: str) -> dict[str, Any]:
        return self.a if side == "a" else self.b


@dataclass
class Difference:
    """One class on one situation where A and B differ, judged on perturbed copies."""

    situation: int
    failure_class: str
    a_recurs: int = 0
    b_recurs: int = 0
    copies: int = 0
    new: bool | None = None
    """B's copies show it significantly more often (None: undecided yet)."""
    fixed: bool | None = None
    total: int = COPIES
    """Copies a side it is judged on at most."""
    erred: int = 0
    """Copies left out because A's or B's erred (a copy that did not run says nothing about
    whether the class shows; both sides' copy ``k`` are left out together)."""

    @property
    def verdict(self) -> str:
        if self.new:
            return NEW
        if self.fixed:
            return FIXED
        return NOT_ROBUST

    def settle(self) -> bool:
        """Decide what the copies so far allow; whether both directions are decided."""
        judged, total = self.copies - self.erred, self.total - self.erred
        if self.new is None:
            self.new = verdict(self.b_recurs, self.a_recurs, judged, total)
        if self.fixed is None:
            self.fixed = verdict(self.a_recurs, self.b_recurs, judged, total)
        return self.new is not None and self.fixed is not None


def _run_of(base: Job, plan: DiffPlan, side: str) -> dict[str, Any]:
    return dict(base.run, controller=plan.controller(side))


def _jobs(situations: Situations, i: int, plan: DiffPlan) -> list[Job]:
    base = situations.job(i)
    return [
        Job(2 * i + k, base.seed, base.situation, _run_of(base, plan, side), base.error)
        for k, side in enumerate(SIDES)
    ]


def check_copies(copies: int) -> int:
    """``copies`` if the kill rule's test can decide with that many a side, else an error
    naming ``--reruns``: under 7 a side not even all against none reaches its level."""
    least = next(k for k in range(1, 100) if p_value(k, 0, k) <= ALPHA)
    if isinstance(copies, bool) or not least <= copies <= MAX_RERUNS:
        raise _core.SpecError(
            f"--reruns: {copies!r} is not in [{least}, {MAX_RERUNS}] (fewer copies a side "
            f"cannot show a difference at the test's level, {ALPHA:g})"
        )
    return copies


def _differences(store: Store, chunk: range) -> tuple[list[Difference], list[tuple[int, str]]]:
    """The classes to judge on the chunk's situations, and each (situation, class) both
    sides showed alike (unchanged)."""
    judge: list[Difference] = []
    alike: list[tuple[int, str]] = []
    for i in chunk:
        a, b = outcome_of(store, 2 * i), outcome_of(store, 2 * i + 1)
        if a is None or b is None or a.error or b.error:
            continue
        if a.failure_class == b.failure_class:
            if a.failure_class is not None:
                alike.append((i, a.failure_class))
        else:
            shown = {a.failure_class, b.failure_class}
            for c in sorted(x for x in shown if x is not None):
                judge.append(Difference(i, c))
        # Each requirement is judged on its own: violated on one side only is a difference.
        for name in sorted(a.violated | b.violated):
            key = REQUIREMENT + name
            if name in a.violated and name in b.violated:
                alike.append((i, key))
            else:
                judge.append(Difference(i, key))
    return judge, alike


def _judge(
    executor: Executor,
    situations: Situations,
    plan: DiffPlan,
    differences: list[Difference],
    stop: Callable[[], bool] | None,
) -> int | None:
    """Run perturbed copies of both sides, stage by stage, until every difference is settled;
    copies of one situation serve every class judged there. The copies run, or None if
    stopped part way."""
    seen: dict[tuple[str, int, int], Outcome] = {}
    copies = 0
    done = 0
    for target in plan.stages:
        open_ = [j for j in differences if not (j.new is not None and j.fixed is not None)]
        if not open_:
            break
        wanted = sorted(
            {
                (side, j.situation, k)
                for j in open_
                for side in SIDES
                for k in range(done + 1, target + 1)
            }
        )
        jobs = []
        for index, (side, i, k) in enumerate(wanted):
            base = situations.job(i)
            jobs.append(
                Job(
                    index,
                    base.seed,
                    base.situation,
                    perturbed(_run_of(base, plan, side), k),
                    base.error,
                )
            )
        got: dict[int, Outcome] = {}
        for job, result in executor.results(jobs):
            got[job.index] = outcome_of_copy(result)
            if stop is not None and stop():
                executor.stop()
        if len(got) < len(jobs):
            return None
        copies += len(jobs)
        for index, key in enumerate(wanted):
            seen[key] = got[index]
        for j in open_:
            j.total = plan.copies
            for k in range(done + 1, target + 1):
                a, b = seen[("a", j.situation, k)], seen[("b", j.situation, k)]
                if a.error or b.error:
                    j.erred += 1
                    continue
                j.a_recurs += a.shows(j.failure_class)
                j.b_recurs += b.shows(j.failure_class)
            j.copies = target
            j.settle()
        done = target
    return copies


@dataclass(frozen=True)
class DiffResult:
    ran: int
    situations: int
    interrupted: bool
    wall_s: float


def run_diff(
    spec: CampaignSpec,
    db: str | Path,
    plan: DiffPlan,
    seed: int = 0,
    n: int = 100,
    workers: int = 1,
    on_progress: Callable[[int, int], None] | None = None,
    stop: Callable[[], bool] | None = None,
    situations_db: Path | None = None,
) -> DiffResult:
    """Compare (or resume comparing) ``plan``'s controllers on ``n`` situations into ``db``."""
    if not 1 <= n <= MAX_SITUATIONS:
        raise _core.SpecError(f"--n: {n} is not in [1, {MAX_SITUATIONS}]")
    workers = check_workers(workers, "local")
    started = time.perf_counter()
    situations = Situations(spec, seed, plan.strategy, None, situations_db)
    try:
        if n > situations.most():
            raise _core.SpecError(
                f"--n: {n} is more than the {situations.most()} runs of {situations_db}"
            )
        check_campaign(spec, seed, n if plan.strategy == "random" else 0, stop)
        for side in SIDES:
            check_kept_alive(spec, seed, plan.controller(side), f"--{side}")
        user = any(is_user_controller(str(plan.controller(s)["name"])) for s in SIDES)
        with Store(db, create=True) as store:
            store.lock_for_writing()
            store.start_campaign(
                spec.source, seed, n, _core.__version__, started_at(), diff=plan.as_dict()
            )
            done = store.done_ids()
            judged = {s for (s,) in store.db.execute("SELECT first FROM diff_chunks")}
            executor = Executor(workers, user=user)
            ran, interrupted = 0, False
            for first in range(0, n, CHUNK):
                chunk = range(first, min(first + CHUNK, n))
                if first in judged:
                    continue
                jobs = [j for i in chunk for j in _jobs(situations, i, plan) if j.index not in done]
                stored, complete = run_chunk(executor, store, jobs, stop)
                ran += len(stored)
                done.update(stored)
                if not complete:
                    interrupted = True
                    break
                differences, alike = _differences(store, chunk)
                copies = _judge(executor, situations, plan, differences, stop)
                if copies is None:
                    interrupted = True
                    break
                ran += copies
                store.record_diff_chunk(first, copies, [_row_of(j) for j in differences], alike)
                if on_progress:
                    on_progress(chunk.stop, n)
                if stop is not None and stop():
                    interrupted = chunk.stop < n
                    break
            evaluated = store.db.execute("SELECT count(*) FROM runs WHERE id % 2 = 0").fetchone()[0]
    finally:
        situations.close()
    return DiffResult(ran, int(evaluated), interrupted, time.perf_counter() - started)


def _row_of(j: Difference) -> dict[str, Any]:
    return {
        "situation": j.situation,
        "failure_class": j.failure_class,
        "a_recurs": j.a_recurs,
        "b_recurs": j.b_recurs,
        "copies": j.copies - j.erred,
        "verdict": j.verdict,
    }
