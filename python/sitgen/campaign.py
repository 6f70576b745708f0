"""Campaigns: N randomised situations generated, run, stored and ranked (the paper's §4.2).

A campaign spec (TOML) has a base situation spec (``[situation]``), a base run spec
(``[run]``) and distributions (``[vary]``) keyed by dotted paths into either:

- ``{ choice = [a, b, …] }`` one of the values; ``{ uniform = [lo, hi] }`` a real number;
  ``{ int = [lo, hi] }`` an integer, both ends included; ``{ scale = [lo, hi] }`` the value the
  spec already has (after its preset is applied) times a uniform factor;
- a path step that names a list of tables selects the table of that ``kind``:
  ``situation.terrain.filters.coverage.target`` is the coverage filter's target.

Job ``i`` of a campaign with seed ``S`` draws its values from its own stream (numpy's PCG64
seeded with (S, i)) and uses situation seed = run seed = 63 bits of sha256("S:i"): every job
is a pure function of (spec, S, i), so the results do not depend on the worker count, the
backend, the order of completion or on interruptions.

Built-in controllers run in Rust across threads (the GIL released); Python and external
controllers run in a process pool; ``backend="ray"`` sends the same batches to a Ray cluster.

Before any run, the first :data:`CHECKED_JOBS` jobs are built and checked and every controller
the spec can name is checked (a built-in name, a ``cmd:`` program that exists, a ``python:``
class that loads): a bad spec stops the campaign with the field named. Jobs are then built as
they are needed, a few per worker ahead, so a campaign of any size holds only the runs in
flight; a later job whose draws make a bad spec is stored as that run's ``error``. A worker
process that dies takes no campaign down: its runs are retried one at a time, and a run that
kills its worker again is stored as an ``error``.
"""

from __future__ import annotations

import copy
import hashlib
import heapq
import json
import math
import os
import signal
import statistics
import time
import tomllib
import zlib
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from sitgen import _core
from sitgen.config import load_spec
from sitgen.store import RunRow, Store, main_events

DISTRIBUTIONS = ("choice", "uniform", "int", "scale")
SECTIONS = ("n", "situation", "run", "vary")
MAX_RUNS = 1_000_000_000
"""Most runs a campaign may ask for (jobs are streamed, so memory does not grow with it)."""
CHECKED_JOBS = 10_000
"""Jobs built and checked before any run (about a second's work)."""
MAX_WORKERS_PER_CORE = 4
"""Local workers allowed per core: more only adds memory and contention."""
MAX_RAY_WORKERS = 4096
"""Batches a Ray campaign may keep in flight (twice this many, as ``workers`` says)."""


def paper_campaign_text() -> str:
    """The default campaign: the paper's experiment."""
    return resources.files("sitgen").joinpath("paper_campaign.toml").read_text()


@dataclass(frozen=True)
class CampaignSpec:
    """A parsed campaign spec."""

    situation: dict[str, Any]
    run: dict[str, Any]
    vary: dict[str, dict[str, Any]]
    n: int = 500
    source: dict[str, Any] = field(default_factory=dict)
    """The spec as written (stored with the campaign)."""


def parse_campaign(text: str | None, origin: str = "campaign spec") -> CampaignSpec:
    """Parse and check a campaign spec (TOML; None for the paper's). Raises SpecError naming the
    field."""
    if text is None:
        text, origin = paper_campaign_text(), "paper campaign"
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise _core.SpecError(f"{origin}: TOML syntax error: {e}") from None
    return campaign_from_data(data)


def campaign_from_data(data: dict[str, Any]) -> CampaignSpec:
    """Check a campaign spec given as a dict of sections. Raises SpecError naming the field."""
    for key in data:
        if key not in SECTIONS:
            raise _core.SpecError(f"{key}: unknown campaign field; expected one of {SECTIONS}")
    n = data.get("n", 500)
    if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n <= MAX_RUNS:
        raise _core.SpecError(f"n: {n!r} is not a whole number of runs in [0, {MAX_RUNS}]")
    for section in ("situation", "run", "vary"):
        if not isinstance(data.get(section, {}), dict):
            raise _core.SpecError(f"{section}: expected a table")
    vary: dict[str, dict[str, Any]] = data.get("vary", {})
    for path, dist in vary.items():
        where = f"vary.{path!r}"
        if not path.startswith(("situation.", "run.")):
            raise _core.SpecError(f"{where}: a path starts with situation. or run.")
        if not isinstance(dist, dict) or len(dist) != 1 or next(iter(dist)) not in DISTRIBUTIONS:
            raise _core.SpecError(
                f"{where}: expected one of {{ choice = [...] }}, {{ uniform = [lo, hi] }}, "
                "{ int = [lo, hi] }, { scale = [lo, hi] }"
            )
        kind, args = next(iter(dist.items()))
        if not isinstance(args, list) or not args:
            raise _core.SpecError(f"{where}.{kind}: expected a non-empty list")
        if kind != "choice":
            numeric = all(
                isinstance(a, int | float) and not isinstance(a, bool) and math.isfinite(a)
                for a in args
            )
            if len(args) != 2 or not numeric or args[0] > args[1]:
                raise _core.SpecError(
                    f"{where}.{kind}: expected [lo, hi] finite numbers with lo <= hi"
                )
        if kind == "int" and not all(isinstance(a, int) for a in args):
            raise _core.SpecError(f"{where}.int: expected [lo, hi] whole numbers")
    return CampaignSpec(
        situation=data.get("situation", {}),
        run=data.get("run", {}),
        vary=vary,
        n=n,
        source=data,
    )


def job_seed(seed: int, index: int) -> int:
    """The situation and run seed of job ``index`` (63 bits, so SQLite stores it as is)."""
    digest = hashlib.sha256(f"{seed}:{index}".encode()).digest()
    return int.from_bytes(digest[:8], "little") >> 1


def draw_gene(rng: np.random.Generator, kind: str, args: list[Any]) -> int | float:
    """One draw of a ``[vary]`` distribution, as a gene: ``choice`` the index of the value,
    ``uniform`` and ``int`` the value, ``scale`` the factor."""
    if kind == "choice":
        return int(rng.integers(len(args)))
    if kind == "int":
        return int(rng.integers(args[0], args[1] + 1))
    return float(rng.uniform(args[0], args[1]))


def express_gene(kind: str, args: list[Any], gene: int | float, current: Any) -> Any:
    """The value a gene gives the field whose value is ``current``."""
    if kind == "choice":
        return args[int(gene)]
    if kind != "scale":
        return gene
    if not isinstance(current, int | float):
        raise ValueError(f"scale needs a number there, found {current!r}")
    return float(current * gene)


def _set(tree: dict[str, Any], path: str, value: Callable[[Any], Any]) -> None:
    """Replace the value at dotted ``path`` by ``value(old)``; a step naming a list of tables
    selects the table of that ``kind``; missing tables are created."""
    steps = path.split(".")
    node: Any = tree
    for i, step in enumerate(steps):
        last = i == len(steps) - 1
        if isinstance(node, list):
            matches = [t for t in node if isinstance(t, dict) and t.get("kind") == step]
            if not matches:
                raise ValueError(f"no `{step}` in the list at {'.'.join(steps[:i])}")
            if last:
                raise ValueError("a list item cannot be replaced whole")
            node = matches[0]
            continue
        if not isinstance(node, dict):
            raise ValueError(f"{'.'.join(steps[:i])} is not a table")
        if last:
            node[step] = value(node.get(step))
        else:
            node = node.setdefault(step, {})


@dataclass(frozen=True)
class Job:
    """One run of a campaign."""

    index: int
    seed: int
    situation: dict[str, Any]
    """The resolved situation spec (as written, if it could not be built)."""
    run: dict[str, Any]
    """The run spec."""
    error: str | None = None
    """Why the job could not be built (its draws made a bad spec); it is stored, not run."""
    run_seed: int | None = None
    """The run's sensor-noise seed, where it is not the situation's seed (a stored run's
    perturbed copies, :mod:`sitgen.robustness`)."""

    @property
    def noise_seed(self) -> int:
        """The seed the run draws its sensor noise from."""
        return self.seed if self.run_seed is None else self.run_seed

    @property
    def controller(self) -> str:
        """The agent's controller: the run spec's, else the situation's mission's; a seeded
        fault follows its name after a ``+``."""
        mission = self.situation.get("mission", {}).get("agent_controller", {})
        controller = self.run.get("controller", mission)
        name: str = controller.get("name", "snd_follow")
        fault = controller.get("fault")
        return f"{name}+{fault}" if fault else name


def vary_order(spec: CampaignSpec) -> list[tuple[str, dict[str, Any]]]:
    """The ``[vary]`` entries in the order they are drawn and applied: presets first, so that
    later paths (and ``scale``) see the preset's values."""
    return sorted(spec.vary.items(), key=lambda kv: not kv[0].endswith(".preset"))


def draw_genes(spec: CampaignSpec, seed: int, index: int) -> list[int | float]:
    """Job ``index``'s draws, one gene per :func:`vary_order` entry."""
    rng = np.random.Generator(np.random.PCG64([seed, index]))
    return [draw_gene(rng, *next(iter(dist.items()))) for _, dist in vary_order(spec)]


def build_job(spec: CampaignSpec, seed: int, index: int) -> Job:
    """Job ``index``: its draws applied to the base specs, the situation spec resolved and
    checked. Raises SpecError naming the field."""
    return express_job(spec, index, job_seed(seed, index), draw_genes(spec, seed, index))


def express_job(spec: CampaignSpec, index: int, seed: int, genes: Sequence[int | float]) -> Job:
    """The job whose situation and run seed is ``seed`` and whose ``[vary]`` fields take
    ``genes`` (one per :func:`vary_order` entry). Raises SpecError naming the field."""
    situation = copy.deepcopy(spec.situation)
    run = copy.deepcopy(spec.run)
    resolved = False
    for (path, dist), gene in zip(vary_order(spec), genes, strict=True):
        if not resolved and not path.endswith(".preset"):
            situation = _resolve(situation, index)
            resolved = True
        section, _, rest = path.partition(".")
        kind, args = next(iter(dist.items()))

        def value(old: Any, kind: str = kind, args: list[Any] = args, gene: Any = gene) -> Any:
            return express_gene(kind, args, gene, old)

        try:
            _set(situation if section == "situation" else run, rest, value)
        except ValueError as e:
            raise _core.SpecError(f"vary.{path!r}: {e}") from None
    situation = _resolve(situation, index)
    # Stored as the core resolves it, its profile's fields written out: the store says what ran.
    run = json.loads(_core.check_run_spec(json.dumps(run)))
    return Job(index=index, seed=seed, situation=situation, run=run)


def _resolve(situation: dict[str, Any], index: int) -> dict[str, Any]:
    try:
        return load_spec(situation)
    except _core.SpecError as e:
        raise _core.SpecError(f"situation.{e} (job {index})") from None


def build_jobs(spec: CampaignSpec, seed: int, n: int) -> list[Job]:
    """Jobs 0 … n − 1, built and checked (for small campaigns and tests; campaigns stream)."""
    return [build_job(spec, seed, i) for i in range(n)]


def stream_jobs(spec: CampaignSpec, seed: int, indices: Iterable[int]) -> Iterator[Job]:
    """The jobs of ``indices``, built one at a time as they are asked for; a job whose draws
    make a bad spec comes with its ``error`` set instead of stopping the campaign."""
    for i in indices:
        try:
            yield build_job(spec, seed, i)
        except _core.SpecError as e:
            situation = copy.deepcopy(spec.situation)
            yield Job(i, job_seed(seed, i), situation, copy.deepcopy(spec.run), f"spec: {e}")


def controller_names(spec: CampaignSpec) -> list[tuple[str, str]]:
    """Every (field, controller name) the campaign can give its agent."""
    found: list[tuple[str, str]] = []
    mission = spec.situation.get("mission", {})
    bases = {
        "run.controller.name": spec.run.get("controller", {}).get("name"),
        "situation.mission.agent_controller.name": mission.get("agent_controller", {}).get("name"),
    }
    for path, base in bases.items():
        if isinstance(base, str):
            found.append((path, base))
        dist = spec.vary.get(path, {})
        choices = dist.get("choice", [])
        found += [(f"vary.{path!r}.choice", c) for c in choices if isinstance(c, str)]
    return found


def check_campaign(
    spec: CampaignSpec, seed: int, n: int, stop: Callable[[], bool] | None = None
) -> None:
    """Everything that can be checked before any run: the first :data:`CHECKED_JOBS` jobs
    build, and every controller the spec names can be used. Raises SpecError naming the
    field."""
    from sitgen.controllers import ControllerError, check_controller_name

    for i in range(min(n, CHECKED_JOBS)):
        if stop is not None and i % 256 == 0 and stop():
            return
        build_job(spec, seed, i)
    checked: set[str] = set()
    for path, name in controller_names(spec):
        if name in checked:
            continue
        checked.add(name)
        _core.check_controller(name, path)
        try:
            check_controller_name(name)
        except ControllerError as e:
            raise _core.SpecError(f"{path}: {e}") from None


def check_workers(workers: int | None, backend: str) -> int:
    """The worker count to use: the cores by default, else ``workers`` if within the cap
    (:data:`MAX_WORKERS_PER_CORE` per core locally, :data:`MAX_RAY_WORKERS` on Ray)."""
    cores = os.cpu_count() or 1
    if workers is None:
        return cores
    most = MAX_RAY_WORKERS if backend == "ray" else MAX_WORKERS_PER_CORE * cores
    if not 1 <= workers <= most:
        where = "on Ray" if backend == "ray" else f"here ({MAX_WORKERS_PER_CORE} per core)"
        raise _core.SpecError(f"--workers: {workers} is not in [1, {most}], the most {where}")
    return workers


PACK_ALL = (-math.inf, False)
"""The pack rule that packs every run's trajectory (see ``_core.run_jobs``)."""

DEFAULT_KEEP = "top:50"
"""What a campaign keeps whole by default: the runs the report's default 50 pages show."""


class Keep:
    """Which runs a campaign stores whole (situation, specs, event log, trajectory), as
    ``--keep-trajectories`` says: ``all``, ``failures`` (runs with a failure class),
    ``top:K`` (the K highest-scoring so far; a run pushed out is reduced to its summary) or
    ``none``. The rest keep their summary and are re-simulated on demand
    (:mod:`sitgen.recall`). A run that could not be run is always kept whole."""

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


def _row(job: Job, result: Mapping[str, Any]) -> RunRow:
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
    )


def _core_args(job: Job) -> tuple[str, int, str, int]:
    return (json.dumps(job.situation), job.seed, json.dumps(job.run), job.noise_seed)


def run_user_job(job: Job) -> dict[str, Any]:
    """One job with a Python or external controller (in a worker process)."""
    from sitgen.run import run
    from sitgen.situation import Situation, generate_situation

    try:
        situation = (
            Situation(json.dumps(job.situation), check_start=False)
            if "format" in job.situation
            else generate_situation(job.situation, seed=job.seed)
        )
    except (_core.GenerationFailed, _core.SpecError) as e:
        return {"ok": False, "error": f"generation failed: {e}"}
    rec = run(situation, controller=job.controller, seed=job.noise_seed, spec=job.run)
    record = {
        "outcome": rec.outcome,
        "reason": rec.reason,
        "score": {"total": rec.score, "breakdown": rec.breakdown},
        "events": rec.events,
        "steps": rec.steps,
        "time_s": rec.time_s,
        "failure": rec.failure,
        "coverage": rec.coverage,
    }
    # Deflate's fastest level, as the core packs built-in runs (sitgen_core::run::pack_trajectory).
    packed = zlib.compress(rec.trajectory.astype("<f4").tobytes(), 1)
    return {
        "ok": True,
        "situation": situation.to_json(),
        "record": json.dumps(record),
        "events_jsonl": rec.events_jsonl,
        "trajectory": packed,
        "robots": rec.trajectory.shape[1],
    }


def _worker_start() -> None:
    """A pool worker: Ctrl-C is the campaign's to handle (it finishes the runs in flight), and
    the worker dies with the campaign even if that is killed outright."""
    from sitgen.controller_host import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()


def _safe_user_job(job: Job) -> dict[str, Any]:
    """:func:`run_user_job`, with any failure of sitgen's own on that run stored as its error
    rather than ending the campaign."""
    try:
        return run_user_job(job)
    except Exception as e:  # sitgen's own bug on one run must not end the campaign
        return {"ok": False, "error": f"sitgen failed on this run: {type(e).__name__}: {e}"}


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
        """Built-in controllers: Rust threads, each job yielded as soon as it is done."""
        stream = self._stream = _core.JobStream(self.workers)
        inflight: dict[int, Job] = {}
        try:
            while True:
                batch = yield from self._take(jobs, self.window - len(inflight))
                if batch:
                    inflight.update((j.index, j) for j in batch)
                    rule = self.pack_rule()
                    stream.submit([(j.index, _core_args(j), rule) for j in batch])
                if not inflight:
                    return
                index, result = next(stream)
                job = inflight.pop(index)
                if result is not None:
                    yield job, result
        finally:
            stream.stop()
            stream.close()

    def _pool_results(self, jobs: Iterator[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        """Python and external controllers: a process pool. A worker that dies breaks the
        pool; the runs it had in flight are retried one at a time, each in a pool of its own,
        and a run that kills that one too is stored as an error; then a fresh pool goes on."""
        suspects: deque[Job] = deque()
        while not self._stopping:
            if suspects:
                job = suspects.popleft()
                yield job, _alone(job)
                continue
            broken = yield from self._pool_pass(jobs, suspects)
            if not broken:
                return

    def _pool_pass(
        self, jobs: Iterator[Job], suspects: deque[Job]
    ) -> Generator[tuple[Job, dict[str, Any]], None, bool]:
        """Run jobs in one pool until they run out (False) or the pool breaks (True, with the
        runs it had in flight put in ``suspects``)."""
        pool = ProcessPoolExecutor(self.workers, initializer=_worker_start)
        inflight: dict[Future[dict[str, Any]], Job] = {}
        try:
            while True:
                for job in (yield from self._take(jobs, self.window - len(inflight))):
                    inflight[pool.submit(_safe_user_job, job)] = job
                if not inflight:
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
            _shut(pool)

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


def _alone(job: Job) -> dict[str, Any]:
    """Run one job in a worker of its own: its result, or an error if the worker dies."""
    pool = ProcessPoolExecutor(1, initializer=_worker_start)
    try:
        return pool.submit(_safe_user_job, job).result()
    except BrokenProcessPool:
        return {
            "ok": False,
            "error": "the worker process running it died (killed by a signal or out of memory)",
        }
    finally:
        _shut(pool)


def _shut(pool: ProcessPoolExecutor) -> None:
    """Shut a pool down now: queued runs are cancelled and its workers killed (their
    controllers die with them), so nothing outlives the campaign."""
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.kill()
    for process in processes:
        process.join()


def _ray_batch(
    args: list[tuple[str, int, str, int]], pack: list[tuple[float, bool]]
) -> list[dict[str, Any]]:
    """One batch on a Ray worker: the same Rust call the local backend makes, one thread."""
    from sitgen import _core as core

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
    on_progress: Callable[[int, int], None] | None = None,
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
    user = any(name.startswith(("python:", "cmd:")) for _, name in controller_names(spec))
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
        ran = 0
        if stop is not None and stop():
            executor.stop()
        for job, result in executor.results(jobs):
            row, pushed_out = keep.admit(_row(job, result))
            # One transaction per run: a kill loses only the runs in flight.
            store.add_runs([row], demote=pushed_out)
            ran += 1
            if on_progress:
                on_progress(n - todo + ran, n)
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


def summary(store: Store, top: int = 5) -> dict[str, Any]:
    """The paper's §4.2 figures (runs, mean and median score, share under 10 points, top runs),
    the commonest reasons runs were errors, and the campaign's distinct failures, best first."""
    from sitgen.failures import distinct_failures

    scores = store.scores()
    ranked = store.ranked(top)
    outcomes: dict[str, int] = {}
    for (outcome,) in store.db.execute("SELECT outcome FROM runs"):
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    errors = [
        {"reason": reason, "runs": n, "first_run": first}
        for reason, n, first in store.db.execute(
            "SELECT reason, count(*), min(id) FROM runs WHERE outcome = 'error' "
            "GROUP BY reason ORDER BY count(*) DESC, min(id) LIMIT 3"
        )
    ]
    return {
        "runs": len(scores),
        "mean_score": statistics.fmean(scores) if scores else 0.0,
        "median_score": statistics.median(scores) if scores else 0.0,
        "share_under_10": sum(s < 10 for s in scores) / len(scores) if scores else 0.0,
        "outcomes": outcomes,
        "errors": errors,
        "top": [
            {"run": r["run"], "score": r["score"], "main_events": main_events(r["breakdown"])}
            for r in ranked
        ],
        "distinct": [f.as_dict() for f in distinct_failures(store)],
    }
