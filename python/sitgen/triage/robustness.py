"""Robustness of a failure: in how many of K perturbed copies of a failing run the same
failure (its base class key) recurs.

A run is deterministic to the bit and still chaotic: a controller nudged by a rounding error
can fail with another class. So a failure shown to an engineer, or claimed for a fault, is
checked on copies of its run that a real robot could not tell from the run itself: seeded laser
noise at the sensor's datasheet level and every robot's start jittered within a centimetre and
half a degree (``perturbation`` in the run spec; the sizes and why are in the core's
``run::perturb``, in one place). Copy ``k`` of a run is the run spec with
``perturbation = {rerun = k}``, drawn from the run's seed, so the figure is reproducible and
independent of the worker count. A failure that recurs in at least :data:`ROBUST_SHARE` of
its copies is *robust*; one that recurs less is *knife-edge*.

A copy is watched until :data:`HORIZON_AFTER_S` after the run's failure first showed, and past
that only until it has shown the failure's class or a worse one (the ``horizon_s`` and
``watch_for`` of its perturbation; the controllers are not told); its class is the most severe
it showed by then. The question a copy answers is whether *this* failure shows again where it
showed, not what the robot does minutes later: a robot stuck at 120 s in every copy,
struck by a peer at 530 s in every copy, has a stuck failure that recurs 8 of 8 (its whole
runs' classes would say 0 of 8). And most failing runs then sit stuck until their time limit,
so a copy watched to the limit costs several times one watched to the horizon.
"""

from __future__ import annotations

import contextlib
import copy
import functools
import json
import math
from collections.abc import Iterable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

from sitgen import _core
from sitgen.execution.campaign import PACK_NONE, Executor
from sitgen.execution.jobs import Job, check_workers
from sitgen.store import Store, StoreError
from sitgen.triage.kill import outcome_of_copy
from sitgen.triage.recall import regenerate, stored_run

RERUNS = 8
"""Perturbed copies of a run, by default: enough to tell 8/8 from 4/8, few enough that the
distinct failures of a 500-run campaign cost about a tenth of the campaign."""
MAX_RERUNS = 1000
"""Most copies of one run (the core's ``perturbation.rerun`` bound)."""
ROBUST_SHARE = 0.75
"""A failure recurring in at least this share of its copies (6 of 8) is robust."""
HORIZON_AFTER_S = 60.0
"""Simulated seconds a copy is watched past the time its run's failure first showed: past
every detection window (oscillation 10 s, loitering 20 s) and a copy's drift in timing. On the
default campaign every copy's class is the same as its whole run's (docs/failures.md)."""
MOST_HORIZON_S = 86_400.0
"""The core's bound on ``perturbation.horizon_s`` (a day, as the time limit's)."""
CANDIDATES = 3
"""A distinct failure's highest-scoring runs measured, best first, until one is robust."""
ERROR = "error"
"""A copy's class where its run failed to run (its controller failed)."""


def perturbed(
    run_spec: dict[str, Any], k: int, horizon: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Run spec of copy ``k`` (1-based) of a run with ``run_spec``: the same spec, perturbed
    at the default sizes, watched as ``horizon`` says (:func:`horizon_of`; None: to its time
    limit)."""
    spec = copy.deepcopy(run_spec)
    spec["perturbation"] = {"rerun": k} | (horizon or {})
    return spec


def horizon_of(failure: dict[str, Any]) -> dict[str, Any] | None:
    """How the copies of a run with ``failure`` (its stored failure) are watched: until
    :data:`HORIZON_AFTER_S` after the failure first showed, and past that until they have shown
    its class or a worse one (the perturbation's ``horizon_s`` and ``watch_for``). None for a
    failure stored without its start: to the time limit."""
    start = failure.get("features", {}).get("start_s")
    if start is None:
        return None
    # Past a time limit a horizon changes nothing, and the core takes none past a day's.
    horizon_s = min(float(start) + HORIZON_AFTER_S, MOST_HORIZON_S)
    return {"horizon_s": horizon_s, "watch_for": str(failure["class"])}


def perturbation_sizes() -> dict[str, float]:
    """The default sizes of a copy's perturbations, as the core resolves them, and how long
    past a failure a copy is watched."""
    return dict(_resolved_sizes())


@functools.cache
def _resolved_sizes() -> dict[str, float]:
    spec = json.loads(_core.check_run_spec(json.dumps(perturbed({}, 1))))
    sizes: dict[str, float] = spec["perturbation"]
    return {k: v for k, v in sizes.items() if k != "rerun"} | {"horizon_after_s": HORIZON_AFTER_S}


def measured_as_now(stored: dict[str, Any] | None, reruns: int) -> bool:
    """Whether a stored robustness row counts as measured now: as many copies run (those that
    erred included; its ``reruns`` counts only those judged), or its first copies already
    deciding the verdict of ``reruns`` (:func:`decided`), perturbed and watched as copies are
    today (a row from before the horizon is measured again)."""
    return (
        stored is not None
        and (
            len(stored["classes"]) == reruns
            or decided(stored["classes"], stored["failure_class"], reruns)
        )
        and stored.get("perturbation") == perturbation_sizes()
    )


def decided(classes: Sequence[str | None], failure_class: str, reruns: int) -> bool:
    """Whether the first copies' ``classes`` already decide the verdict of ``reruns`` copies,
    whatever the rest show: enough recur that it is robust (6 of 8), or enough did not that
    it cannot be (3 of 8). A copy that erred counts as neither. The verdict of these copies
    alone (:func:`verdict` of their ``recurs`` and ``reruns``) is then the same."""
    need = math.ceil(ROBUST_SHARE * reruns - 1e-9)
    recurs = sum(c == failure_class for c in classes)
    missed = sum(c != failure_class and c != ERROR for c in classes)
    return len(classes) < reruns and (recurs >= need or missed > reruns - need)


def check_reruns(reruns: int) -> int:
    """``reruns`` if it is in [1, MAX_RERUNS], else an error naming the option."""
    if isinstance(reruns, bool) or not isinstance(reruns, int) or not 1 <= reruns <= MAX_RERUNS:
        raise _core.SpecError(f"--reruns: {reruns!r} is not a whole number in [1, {MAX_RERUNS}]")
    return reruns


@dataclass(frozen=True)
class Robustness:
    """How often a failing run's failure recurs in its perturbed copies."""

    run_id: int
    failure_class: str
    """The run's own (base) failure class."""
    classes: tuple[str | None, ...]
    """Each copy's failure class, in copy order (None: no failure; ``error``: it failed to
    run)."""

    @property
    def reruns(self) -> int:
        """The copies judged: those that ran (a copy that erred says nothing about whether
        the failure recurs, and is left out, never counted as not recurring)."""
        return len(self.classes) - self.errors

    @property
    def errors(self) -> int:
        """The copies that failed to run (their controller failed, or the machine did)."""
        return sum(c == ERROR for c in self.classes)

    @property
    def recurs(self) -> int:
        return sum(c == self.failure_class for c in self.classes)

    @property
    def robust(self) -> bool:
        return is_robust(self.recurs, self.reruns)

    def as_row(self) -> dict[str, Any]:
        """The store's ``robustness`` row."""
        return {
            "run_id": self.run_id,
            "failure_class": self.failure_class,
            "reruns": self.reruns,
            "recurs": self.recurs,
            "classes": list(self.classes),
            "perturbation": perturbation_sizes(),
            "sitgen_version": _core.__version__,
        }


def is_robust(recurs: int, reruns: int) -> bool:
    """Whether a failure recurring in ``recurs`` of ``reruns`` copies is robust."""
    return reruns > 0 and recurs >= math.ceil(ROBUST_SHARE * reruns - 1e-9)


def verdict(recurs: int, reruns: int) -> str:
    """``robust`` or ``knife-edge``; ``unjudged`` where no copy ran (every one erred)."""
    if reruns == 0:
        return "unjudged"
    return "robust" if is_robust(recurs, reruns) else "knife-edge"


def label(recurs: int, reruns: int) -> str:
    """``recurs 7/8``: how a person reads it."""
    return f"recurs {recurs}/{reruns}"


def tally(classes: Iterable[str | None]) -> str:
    """Copies' classes as ``6 × struck_while_stopped_seen, 2 × none``, most frequent first."""
    counts: dict[str, int] = {}
    for c in classes:
        name = "none" if c is None else c
        counts[name] = counts.get(name, 0) + 1
    return ", ".join(
        f"{n} × {c}" for c, n in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0]))
    )


def copy_class(result: dict[str, Any]) -> str | None:
    """A copy's failure class from its job's result (``error`` where it did not run)."""
    outcome = outcome_of_copy(result)
    return ERROR if outcome.error else outcome.failure_class


def shared_situation(row: dict[str, Any], reruns: int) -> dict[str, Any]:
    """What the ``reruns`` copies of stored run ``row`` are given as their situation: with
    more than one, the situation generated once and given whole (a copy's own generation —
    terrain filters, regions, routes — cost more than a short copy's run); else, or where it
    cannot be made again, its spec (each copy then errs and is left out)."""
    with contextlib.suppress(_core.GenerationFailed, _core.SpecError):
        if reruns > 1:
            whole: dict[str, Any] = json.loads(regenerate(row).to_json())
            return whole
    spec: dict[str, Any] = row["situation_spec"]
    return spec


def copy_jobs(
    row: dict[str, Any],
    reruns: int,
    first_index: int,
    horizon: bool = True,
    situation: dict[str, Any] | None = None,
) -> list[Job]:
    """The ``reruns`` perturbed copies of stored failing run ``row`` (:meth:`Store.run_row`),
    each stopped at its horizon (``horizon=False``: run to its time limit, as copies were
    before the horizon), as jobs numbered from ``first_index``; ``situation``: its
    :func:`shared_situation`, if made already."""
    watched = horizon_of(row["failure"]) if horizon else None
    whole = shared_situation(row, reruns) if situation is None else situation
    return [
        Job(
            index=first_index + k - 1,
            seed=row["situation_seed"],
            situation=whole,
            run=perturbed(row["run_spec"], k, watched),
            run_seed=row["run_seed"],
        )
        for k in range(1, reruns + 1)
    ]


def copies(jobs: Sequence[Job], workers: int) -> list[dict[str, Any]]:
    """Run ``jobs`` (perturbed copies, any controllers) on ``workers``: their results in job
    order, whatever the worker count."""
    by_index = dict((job.index, result) for job, result in stream(jobs, jobs, workers))
    return [by_index[j.index] for j in jobs]


def stream(
    jobs: Iterable[Job], every: Iterable[Job], workers: int
) -> Iterator[tuple[Job, dict[str, Any]]]:
    """Copies ``jobs`` run on ``workers`` (drawn as workers free up, so the iterator may
    decide what comes next), each (job, result) as it finishes; ``every``: all the jobs it
    may draw, to tell whether a process pool is needed."""
    user = any(j.in_python for j in every)
    # A copy is read for its record alone: no trajectory is packed for it.
    yield from Executor(workers, user=user, pack_rule=lambda: PACK_NONE).results(jobs)


def measure(
    rows: Sequence[dict[str, Any]],
    reruns: int = RERUNS,
    workers: int = 1,
    horizon: bool = True,
    until_decided: bool = False,
) -> list[Robustness]:
    """The robustness of failing stored runs ``rows`` (:meth:`Store.run_row`), all copies run
    as one batch, taken in turns across the runs (``horizon``: see :func:`copy_jobs`).
    ``until_decided``: a run's copies stop at the first ``k`` whose classes decide its verdict
    (:func:`decided`); the turns have a run's first copies in before its later ones start, and
    ``k`` is read from the copies in order, never from which finished first, so the row is the
    same whatever the worker count. Raises StoreError for a run that has no failure."""
    failure_classes: list[str] = []
    for row in rows:
        if row["failure"] is None:
            raise StoreError(f"run {row['id']}: it did not fail; robustness is a failure's")
        failure_classes.append(str(row["failure"]["class"]))
    # The situations are made again on as many threads as there are workers (the core lets
    # go of the interpreter while it generates): made one after another, the workers would
    # stand idle the while.
    with ThreadPoolExecutor(max(1, min(workers, len(rows)))) as pool:
        situations = list(pool.map(lambda row: shared_situation(row, reruns), rows))
    per_row = [
        copy_jobs(row, reruns, i * reruns, horizon, situation)
        for i, (row, situation) in enumerate(zip(rows, situations, strict=True))
    ]
    got: list[list[str | None]] = [[] for _ in rows]
    waiting: dict[int, str | None] = {}

    def first_copies(i: int) -> list[str | None]:
        """Run ``i``'s classes of its copies 1…k in order, as far as they are in."""
        while len(got[i]) < reruns and i * reruns + len(got[i]) in waiting:
            got[i].append(waiting.pop(i * reruns + len(got[i])))
        return got[i]

    def settled(i: int) -> bool:
        return until_decided and decided(first_copies(i), failure_classes[i], reruns)

    def turns() -> Iterator[Job]:
        for k in range(reruns):
            for i, jobs in enumerate(per_row):
                if not settled(i):
                    yield jobs[k]

    for job, result in stream(turns(), (j for jobs in per_row for j in jobs), workers):
        waiting[job.index] = copy_class(result)
    measured = []
    for i, row in enumerate(rows):
        classes = first_copies(i)
        k = next(
            (
                n
                for n in range(1, reruns)
                if until_decided and decided(classes[:n], failure_classes[i], reruns)
            ),
            reruns,
        )
        measured.append(Robustness(row["id"], failure_classes[i], tuple(classes[:k])))
    return measured


def measure_runs(
    store: Store,
    run_ids: Sequence[int],
    reruns: int = RERUNS,
    workers: int = 1,
    until_decided: bool = False,
) -> list[Robustness]:
    """Measure and store the robustness of stored runs ``run_ids`` (each must have failed;
    ``until_decided``: see :func:`measure`)."""
    workers = check_workers(workers, "local")
    rows = [stored_run(store, i) for i in run_ids]
    measured = measure(rows, check_reruns(reruns), workers, until_decided=until_decided)
    store.record_robustness(r.as_row() for r in measured)
    return measured
