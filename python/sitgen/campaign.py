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
"""

from __future__ import annotations

import copy
import hashlib
import json
import os
import signal
import statistics
import time
import tomllib
import zlib
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
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
    for key in data:
        if key not in SECTIONS:
            raise _core.SpecError(f"{key}: unknown campaign field; expected one of {SECTIONS}")
    n = data.get("n", 500)
    if not isinstance(n, int) or n < 0:
        raise _core.SpecError(f"n: {n!r} is not a whole number of runs")
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
            numeric = all(isinstance(a, int | float) and not isinstance(a, bool) for a in args)
            if len(args) != 2 or not numeric or args[0] > args[1]:
                raise _core.SpecError(f"{where}.{kind}: expected [lo, hi] numbers with lo <= hi")
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


def _draw(rng: np.random.Generator, kind: str, args: list[Any], current: Any) -> Any:
    if kind == "choice":
        return args[int(rng.integers(len(args)))]
    if kind == "uniform":
        return float(rng.uniform(args[0], args[1]))
    if kind == "int":
        return int(rng.integers(args[0], args[1] + 1))
    if not isinstance(current, int | float):
        raise ValueError(f"scale needs a number there, found {current!r}")
    return float(current * rng.uniform(args[0], args[1]))


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
    """The resolved situation spec."""
    run: dict[str, Any]
    """The run spec."""

    @property
    def controller(self) -> str:
        name: str = self.run.get("controller", {}).get("name", "snd_follow")
        return name


def build_job(spec: CampaignSpec, seed: int, index: int) -> Job:
    """Job ``index``: its draws applied to the base specs, the situation spec resolved and
    checked. Raises SpecError naming the field."""
    rng = np.random.Generator(np.random.PCG64([seed, index]))
    situation = copy.deepcopy(spec.situation)
    run = copy.deepcopy(spec.run)
    # Presets first, so that later paths (and `scale`) see the preset's values.
    ordered = sorted(spec.vary.items(), key=lambda kv: not kv[0].endswith(".preset"))
    resolved = False
    for path, dist in ordered:
        if not resolved and not path.endswith(".preset"):
            situation = _resolve(situation, index)
            resolved = True
        section, _, rest = path.partition(".")
        kind, args = next(iter(dist.items()))

        def draw(old: Any, kind: str = kind, args: list[Any] = args) -> Any:
            return _draw(rng, kind, args, old)

        try:
            _set(situation if section == "situation" else run, rest, draw)
        except ValueError as e:
            raise _core.SpecError(f"vary.{path!r}: {e}") from None
    situation = _resolve(situation, index)
    _core.check_run_spec(json.dumps(run))
    return Job(index=index, seed=job_seed(seed, index), situation=situation, run=run)


def _resolve(situation: dict[str, Any], index: int) -> dict[str, Any]:
    try:
        return load_spec(situation)
    except _core.SpecError as e:
        raise _core.SpecError(f"situation.{e} (job {index})") from None


def build_jobs(spec: CampaignSpec, seed: int, n: int) -> list[Job]:
    """Every job, checked before anything runs."""
    return [build_job(spec, seed, i) for i in range(n)]


def _row(job: Job, result: Mapping[str, Any]) -> RunRow:
    record = json.loads(result["record"]) if result["ok"] else None
    return RunRow(
        id=job.index,
        situation_seed=job.seed,
        situation_spec=job.situation,
        situation_json=result.get("situation"),
        run_spec=job.run,
        run_seed=job.seed,
        controller=job.controller,
        record=record,
        error=None if result["ok"] else result["error"],
        events_jsonl=result.get("events_jsonl", ""),
        trajectory=result.get("trajectory"),
        robots=result.get("robots", 0),
    )


def _core_args(job: Job) -> tuple[str, int, str, int]:
    return (json.dumps(job.situation), job.seed, json.dumps(job.run), job.seed)


def run_user_job(job: Job) -> dict[str, Any]:
    """One job with a Python or external controller (in a worker process)."""
    from sitgen.run import run
    from sitgen.situation import generate_situation

    try:
        situation = generate_situation(job.situation, seed=job.seed)
    except (_core.GenerationFailed, _core.SpecError) as e:
        return {"ok": False, "error": f"generation failed: {e}"}
    rec = run(situation, controller=job.controller, seed=job.seed, spec=job.run)
    record = {
        "outcome": rec.outcome,
        "reason": rec.reason,
        "score": {"total": rec.score, "breakdown": rec.breakdown},
        "events": rec.events,
        "steps": rec.steps,
        "time_s": rec.time_s,
    }
    packed = zlib.compress(rec.trajectory.astype("<f4").tobytes(), 6)
    return {
        "ok": True,
        "situation": situation.to_json(),
        "record": json.dumps(record),
        "events_jsonl": rec.events_jsonl,
        "trajectory": packed,
        "robots": rec.trajectory.shape[1],
    }


def is_user(job: Job) -> bool:
    return job.controller.startswith(("python:", "cmd:"))


class Executor:
    """Runs jobs and yields (job, result) as each finishes; ``stop()`` starts no more."""

    def __init__(self, workers: int, backend: str = "local", address: str | None = None) -> None:
        self.workers = max(1, workers)
        self.backend = backend
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

    def results(self, jobs: list[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        if self.backend == "ray":
            yield from self._ray_results(jobs)
        elif any(is_user(j) for j in jobs):
            yield from self._pool_results(jobs)
        else:
            # Built-in controllers: Rust threads, each job yielded as soon as it is done.
            self._stream = _core.JobStream([_core_args(j) for j in jobs], self.workers)
            for i, result in self._stream:
                yield jobs[i], result

    def _pool_results(self, jobs: list[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        if self.workers == 1:
            for job in jobs:
                if self._stopping:
                    return
                yield job, run_user_job(job)
            return
        with ProcessPoolExecutor(self.workers) as pool:
            futures = {pool.submit(run_user_job, job): job for job in jobs}
            for future in as_completed(futures):
                if self._stopping:
                    for f in futures:
                        f.cancel()
                if not future.cancelled():
                    yield futures[future], future.result()

    def _ray_results(self, jobs: list[Job]) -> Iterator[tuple[Job, dict[str, Any]]]:
        ray = self._ray
        batch = 4
        queue = [jobs[i : i + batch] for i in range(0, len(jobs), batch)]
        pending: dict[Any, list[Job]] = {}
        # Keep a few batches in flight per worker; yield each as it comes back.
        while (queue and not self._stopping) or pending:
            while queue and not self._stopping and len(pending) < 2 * self.workers:
                chunk = queue.pop(0)
                pending[self._remote.remote([_core_args(j) for j in chunk])] = chunk
            ready, _ = ray.wait(list(pending), num_returns=1)
            chunk = pending.pop(ready[0])
            yield from zip(chunk, ray.get(ready[0]), strict=True)

    def stop(self) -> None:
        self._stopping = True
        if self._stream is not None:
            self._stream.stop()


def _ray_batch(args: list[tuple[str, int, str, int]]) -> list[dict[str, Any]]:
    """One batch on a Ray worker: the same Rust call the local backend makes, one thread."""
    from sitgen import _core as core

    return [dict(r) for r in core.run_jobs(args, 1)]


@dataclass(frozen=True)
class CampaignResult:
    """What a campaign did."""

    ran: int
    """Runs done by this call."""
    total: int
    """Runs stored in all."""
    interrupted: bool
    wall_s: float


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
) -> CampaignResult:
    """Run (or resume) a campaign into the store ``db``. Every job is built and checked before
    any runs; runs already stored are skipped; ``stop()`` is checked between batches."""
    n = spec.n if n is None else n
    workers = workers or os.cpu_count() or 1
    jobs = build_jobs(spec, seed, n)
    started = time.perf_counter()
    with Store(db) as store:
        store.start_campaign(
            spec.source,
            seed,
            n,
            _core.__version__,
            datetime.now(UTC).isoformat(timespec="seconds"),
        )
        done = store.done_ids()
        todo = [j for j in jobs if j.index not in done]
        if on_progress:
            on_progress(n - len(todo), n)
        executor = Executor(workers, backend, address)
        ran = 0
        for job, result in executor.results(todo):
            # One transaction per run: a kill loses only the runs in flight.
            store.add_runs([_row(job, result)])
            ran += 1
            if on_progress:
                on_progress(n - len(todo) + ran, n)
            if stop is not None and stop():
                executor.stop()
        interrupted = ran < len(todo)
        total = len(store.done_ids())
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
    """The paper's §4.2 figures (runs, mean and median score, share under 10 points, top runs)
    and the campaign's distinct failures, best first."""
    from sitgen.failures import distinct_failures

    scores = store.scores()
    ranked = store.ranked(top)
    outcomes: dict[str, int] = {}
    for (outcome,) in store.db.execute("SELECT outcome FROM runs"):
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    return {
        "runs": len(scores),
        "mean_score": statistics.fmean(scores) if scores else 0.0,
        "median_score": statistics.median(scores) if scores else 0.0,
        "share_under_10": sum(s < 10 for s in scores) / len(scores) if scores else 0.0,
        "outcomes": outcomes,
        "top": [
            {"run": r["run"], "score": r["score"], "main_events": main_events(r["breakdown"])}
            for r in ranked
        ],
        "distinct": [f.as_dict() for f in distinct_failures(store)],
    }
