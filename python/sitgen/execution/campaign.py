"""Campaigns: N randomised situations generated, run, stored and ranked (the paper's §4.2).

What a campaign runs is its spec's jobs (:mod:`sitgen.execution.jobs`: job ``i`` is a pure function
of the spec, the seed and ``i``); this module runs them and stores the results.

Built-in controllers run in Rust across threads (the GIL released); Python and external controllers
run in a process pool; ``backend="ray"`` sends the same batches to a Ray cluster. Every job the
spec can make and every controller it can name is checked before any run
(:func:`sitgen.execution.jobs.check_campaign`). Jobs are then built as they are needed, a few per
worker ahead, so a campaign of any size holds only the runs in flight; a later job whose draws make
a bad spec is stored as that run's ``error``. A worker process that dies takes no campaign down:
its runs are retried one at a time, and a run that kills its worker again is stored as an
``error``."""

from __future__ import annotations

import heapq
import json
import math
import os
import signal
import time
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping
from concurrent.futures import FIRST_COMPLETED, Future, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from sitgen import _core
from sitgen import _core as core
from sitgen.execution.jobs import (
    MAX_RUNS,
    CampaignSpec,
    Job,
    check_campaign,
    check_workers,
    runs_in_python,
    stream_jobs,
)
from sitgen.execution.workers import IDLE_POOLS, alone, idle_pool, safe_user_job, shut
from sitgen.store import RunRow, Store

PACK_ALL = (-math.inf, False)
"""The pack rule that packs every run's trajectory (see ``_core.run_jobs``)."""
PACK_NONE = (math.inf, False)
"""No run's trajectory packed: jobs whose result is read for its record alone (perturbed
copies)."""

DEFAULT_KEEP = "top:50"
"""What a campaign keeps whole by default: the runs the report's default 50 pages show."""


class Keep:
    """Which runs a campaign stores whole (situation, specs, event log, trajectory), as
    ``--keep-trajectories`` says: ``all``, ``failures`` (runs with a failure class),
    ``top:K`` (the K highest-scoring so far; a run pushed out is reduced to its summary) or
    ``none``. The rest keep their summary and are re-simulated on demand
    (:mod:`sitgen.triage.recall`). A run that could not be run is always kept whole."""

    def __init__(self, text: str) -> None:
        mode, _, count = text.partition(":")
        self.mode = mode
        self.k = 0
        if mode == "top" and count.isdigit() and int(count) >= 1:
            self.k = int(count)
        elif mode not in ("all", "failures", "none") or count:
            raise _core.SpecError(
                f"--keep-trajectories: `{text}` is not one of all, failures, top:K (K a whole "
                "number of runs, at least 1), none"
            )
        self._top: list[tuple[float, int]] = []
        """The runs kept by ``top:K``: a heap of (score, −id), the lowest-ranked first."""

    def start(self, store: Store) -> None:
        """Resume: ``top:K`` goes on from the best runs the store keeps whole."""
        if self.mode != "top":
            return
        rows = store.db.execute(
            "SELECT id, score FROM runs WHERE kept IS NOT 0 AND outcome != 'error' "
            "ORDER BY score DESC, id LIMIT ?",
            (self.k,),
        )
        self._top = [(score, -run_id) for run_id, score in rows]
        heapq.heapify(self._top)

    def pack_rule(self) -> tuple[float, bool]:
        """Which runs' trajectories are worth packing now: (minimum score, any failure)."""
        if self.mode == "none":
            return (math.inf, False)
        if self.mode == "failures":
            return (math.inf, True)
        if self.mode == "top" and len(self._top) >= self.k:
            # A run that scores below the K-th best so far can never be kept.
            return (self._top[0][0], False)
        return PACK_ALL

    def admit(self, row: RunRow) -> tuple[RunRow, list[int]]:
        """``row`` marked whole or summary, and the runs it pushes out of the ``top:K``."""
        if row.record is None or self.mode == "all":
            return row, []
        if self.mode == "none":
            return replace(row, keep=False), []
        if self.mode == "failures":
            return replace(row, keep=row.record.get("failure") is not None), []
        rank = (float(row.record["score"]["total"]), -row.id)
        if len(self._top) < self.k:
            heapq.heappush(self._top, rank)
            return row, []
        if rank > self._top[0]:
            _, pushed_out = heapq.heapreplace(self._top, rank)
            return row, [-pushed_out]
        return replace(row, keep=False), []


def run_row(job: Job, result: Mapping[str, Any]) -> RunRow:
    """The stored form of a job's result."""
    record = json.loads(result["record"]) if result["ok"] else None
    return RunRow(
        id=job.index,
        situation_seed=job.seed,
        situation_spec=job.situation,
        situation_json=result.get("situation"),
        run_spec=job.run,
        run_seed=job.noise_seed,
        controller=job.controller,
        record=record,
        error=None if result["ok"] else result["error"],
        events_jsonl=result.get("events_jsonl", ""),
        trajectory=result.get("trajectory"),
        robots=result.get("robots", 0),
        cost=(float(result["wall_s"]), float(result["cpu_s"])) if "cpu_s" in result else None,
        descriptors=result.get("descriptors"),
    )


def run_chunk(
    executor: Executor, store: Store, jobs: list[Job], stop: Callable[[], bool] | None
) -> tuple[list[int], bool]:
    """Run one chunk of ``jobs`` and store its runs in one transaction; returns the ids stored
    and whether every job ran (False: stopped part way). Finished runs are kept even if the
    chunk is not: a resumed evaluation skips them. Fault evaluations and diffs go chunk by
    chunk so that what follows a chunk (kill tests, verdicts) sees all its runs."""
    rows = []
    for job, result in executor.results(jobs):
        rows.append(run_row(job, result))
        if stop is not None and stop():
            executor.stop()
    store.add_runs(rows)
    return [r.id for r in rows], len(rows) == len(jobs)


def _core_args(job: Job) -> tuple[str, int, str, int]:
    return (json.dumps(job.situation), job.seed, json.dumps(job.run), job.noise_seed)


def _failed(job: Job) -> dict[str, Any] | None:
    """The result of a job that cannot run (it could not be built), else None."""
    return None if job.error is None else {"ok": False, "error": job.error}


class Executor:
    """Runs jobs as they are drawn from an iterator, a few per worker ahead, and yields
    (job, result) as each finishes; ``stop()`` starts no more."""

    def __init__(
        self,
        workers: int,
        backend: str = "local",
        address: str | None = None,
        user: bool = False,
        pack_rule: Callable[[], tuple[float, bool]] = lambda: PACK_ALL,
    ) -> None:
        self.workers = max(1, workers)
        self.pack_rule = pack_rule
        """Which of the jobs submitted now get their trajectory packed (see :class:`Keep`)."""
        self.backend = backend
        self.user = user
        """Whether any job may have a Python or external controller (then: a process pool)."""
        self.window = 4 * self.workers
        self._stopping = False
        self._stream: _core.JobStream | None = None
        if backend == "ray":
            try:
                import ray
            except ImportError:
                raise _core.SpecError(
                    "--backend: ray is not installed; pip install 'sitgen[ray]'"
                ) from None
            if not ray.is_initialized():
                ray.init(address=address, include_dashboard=False, log_to_driver=False)
            self._ray = ray
            self._remote = ray.remote(_ray_batch)
        elif backend != "local":
            raise _core.SpecError(f"--backend: `{backend}` is not one of local, ray")

    def results(self, jobs: Iterable[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        if self.backend == "ray":
            yield from self._ray_results(iter(jobs))
        elif self.user:
            yield from self._pool_results(iter(jobs))
        else:
            yield from self._stream_results(iter(jobs))

    def _take(
        self, jobs: Iterator[Job], room: int
    ) -> Generator[tuple[Job, dict[str, Any]], None, list[Job]]:
        """Up to ``room`` jobs to start (none once stopping; fewer when the jobs run out); a job
        that could not be built needs no worker, and is yielded with its error on the way."""
        batch: list[Job] = []
        while not self._stopping and len(batch) < room:
            job = next(jobs, None)
            if job is None:
                break
            failed = _failed(job)
            if failed is not None:
                yield job, failed
            else:
                batch.append(job)
        return batch

    def _stream_results(self, jobs: Iterator[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        """Built-in controllers: Rust threads, each job yielded as soon as it is done. A job
        whose run the Python layer must drive (a peer's ``navground:`` controller in a stored
        situation, say) is set aside and run in a process pool after the rest."""
        stream = self._stream = _core.JobStream(self.workers)
        inflight: dict[int, Job] = {}
        in_python: list[Job] = []
        try:
            while True:
                taken = yield from self._take(jobs, self.window - len(inflight))
                batch: list[Job] = []
                for j in taken:
                    (in_python if j.in_python else batch).append(j)
                if batch:
                    inflight.update((j.index, j) for j in batch)
                    rule = self.pack_rule()
                    stream.submit([(j.index, _core_args(j), rule) for j in batch])
                if not inflight and not taken:
                    break
                if not inflight:
                    continue
                index, result = next(stream)
                job = inflight.pop(index)
                if result is not None:
                    yield job, result
        finally:
            stream.stop()
            stream.close()
        if in_python:
            yield from self._pool_results(iter(in_python))

    def _pool_results(self, jobs: Iterator[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        """Python and external controllers: a process pool. A worker that dies breaks the
        pool; the runs it had in flight are retried one at a time, each in a pool of its own,
        and a run that kills that one too is stored as an error; then a fresh pool goes on."""
        suspects: deque[Job] = deque()
        while not self._stopping:
            if suspects:
                job = suspects.popleft()
                yield job, alone(job)
                continue
            broken = yield from self._pool_pass(jobs, suspects)
            if not broken:
                return

    def _pool_pass(
        self, jobs: Iterator[Job], suspects: deque[Job]
    ) -> Generator[tuple[Job, dict[str, Any]], None, bool]:
        """Run jobs in one pool until they run out (False) or the pool breaks (True, with the
        runs it had in flight put in ``suspects``)."""
        pool = idle_pool(self.workers)
        inflight: dict[Future[dict[str, Any]], Job] = {}
        finished = False
        try:
            while True:
                for job in (yield from self._take(jobs, self.window - len(inflight))):
                    inflight[pool.submit(safe_user_job, job, True, os.getcwd())] = job
                if not inflight:
                    finished = True
                    return False
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                broken = False
                for future in done:
                    job = inflight.pop(future)
                    try:
                        result = future.result()
                    except BrokenProcessPool:
                        broken = True
                        suspects.append(job)
                        continue
                    yield job, result
                if broken:
                    suspects.extend(inflight.values())
                    return True
        finally:
            # A pool left idle serves the next batch (a search's screen asks for a few copies
            # at a time); one stopped part way, or broken, is shut with what runs in it.
            if finished:
                IDLE_POOLS[self.workers] = pool
            else:
                shut(pool)

    def _ray_results(self, jobs: Iterator[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        ray = self._ray
        batch = 4
        pending: dict[Any, list[Job]] = {}
        exhausted = False
        # Keep a few batches in flight per worker; yield each as it comes back.
        while True:
            while not exhausted and not self._stopping and len(pending) < 2 * self.workers:
                chunk = yield from self._take(jobs, batch)
                if chunk:
                    args = [_core_args(j) for j in chunk]
                    pending[self._remote.remote(args, [self.pack_rule()] * len(chunk))] = chunk
                else:
                    exhausted = not self._stopping
            if not pending:
                return
            ready, _ = ray.wait(list(pending), num_returns=1)
            chunk = pending.pop(ready[0])
            yield from zip(chunk, ray.get(ready[0]), strict=True)

    def stop(self) -> None:
        self._stopping = True
        if self._stream is not None:
            self._stream.stop()


def _ray_batch(
    args: list[tuple[str, int, str, int]], pack: list[tuple[float, bool]]
) -> list[dict[str, Any]]:
    """One batch on a Ray worker: the same Rust call the local backend makes, one thread."""

    return [dict(r) for r in core.run_jobs(args, 1, pack)]


@dataclass(frozen=True)
class CampaignResult:
    """What a campaign did."""

    ran: int
    """Runs done by this call."""
    total: int
    """Runs stored in all."""
    interrupted: bool
    wall_s: float


def started_at() -> str:
    """Now, as a store records when a campaign started (UTC, ISO 8601, seconds)."""
    return datetime.now(UTC).isoformat(timespec="seconds")


def run_campaign(
    spec: CampaignSpec,
    db: str | Path,
    seed: int = 0,
    n: int | None = None,
    workers: int | None = None,
    backend: str = "local",
    address: str | None = None,
    on_progress: Callable[..., None] | None = None,
    stop: Callable[[], bool] | None = None,
    keep_trajectories: str = DEFAULT_KEEP,
) -> CampaignResult:
    """Run (or resume) a campaign into the store ``db``: the spec and its controllers are
    checked first (:func:`check_campaign`), runs already stored are skipped, jobs are built as
    they are needed, runs are kept whole as ``keep_trajectories`` says (:class:`Keep`);
    ``stop()`` is checked after every run."""
    keep = Keep(keep_trajectories)
    n = spec.n if n is None else n
    if not 0 <= n <= MAX_RUNS:
        raise _core.SpecError(f"--n: {n} is not in [0, {MAX_RUNS}]")
    workers = check_workers(workers, backend)
    started = time.perf_counter()
    check_campaign(spec, seed, n, stop)
    if stop is not None and stop():
        return CampaignResult(0, 0, True, time.perf_counter() - started)
    user = runs_in_python(spec)
    with Store(db, create=True) as store:
        store.lock_for_writing()
        store.start_campaign(spec.source, seed, n, _core.__version__, started_at())
        done = store.done_ids()
        todo = n - sum(1 for i in done if i < n)
        if on_progress:
            on_progress(n - todo, n)
        keep.start(store)
        executor = Executor(workers, backend, address, user=user, pack_rule=keep.pack_rule)
        jobs = stream_jobs(spec, seed, (i for i in range(n) if i not in done))
        ran = errors = 0
        if stop is not None and stop():
            executor.stop()
        for job, result in executor.results(jobs):
            row, pushed_out = keep.admit(run_row(job, result))
            # One transaction per run: a kill loses only the runs in flight.
            store.add_runs([row], demote=pushed_out)
            ran += 1
            errors += row.record is None or row.record.get("outcome") == "error"
            if on_progress:
                on_progress(n - todo + ran, n, f"{errors} errors" if errors else "")
            if stop is not None and stop():
                executor.stop()
        interrupted = ran < todo
        total = store.run_count()
    return CampaignResult(
        ran=ran, total=total, interrupted=interrupted, wall_s=time.perf_counter() - started
    )


class StopOnInterrupt:
    """Ctrl-C (SIGINT) or SIGTERM asks the campaign to stop after the runs in flight; a second
    Ctrl-C stops at once."""

    def __init__(self) -> None:
        self.requested = False

    def __enter__(self) -> StopOnInterrupt:
        self._old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
        for s in self._old:
            signal.signal(s, self._handle)
        return self

    def _handle(self, signum: int, frame: object) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __exit__(self, *exc: object) -> None:
        for s, handler in self._old.items():
            signal.signal(s, handler)

    def __call__(self) -> bool:
        return self.requested
