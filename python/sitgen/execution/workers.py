"""The processes a campaign's user-controller runs go to: pool workers forked from a clean
fork server, which die with the campaign however it ends, keep their output from the
campaign's, share the cores out, and make each job as :func:`run_user_job` does (a ``python:``
class there in a runner, :mod:`sitgen.controllers.sandbox`); idle pools kept for the next batch;
a job made alone in a worker of its own, its class in a host process, where a worker died.
The executors that hand jobs out are in :mod:`sitgen.execution.campaign`.
"""

from __future__ import annotations

import atexit
import json
import multiprocessing
import multiprocessing.connection
import multiprocessing.forkserver
import os
import signal
import threading
import zlib
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from sitgen import _core
from sitgen.controllers.external import pin_to_one_core
from sitgen.controllers.host import die_with_parent
from sitgen.controllers.marks import MARK, marked_env
from sitgen.execution.jobs import Job
from sitgen.run import run
from sitgen.world.requirements import verdicts_json


def run_user_job(job: Job, in_process: bool = True) -> dict[str, Any]:
    """One job with a Python or external controller (in a worker process; ``in_process``: a
    ``python:`` class is called in it, else in a host process of its own)."""

    try:
        situation = job.built()
    except (_core.GenerationFailed, _core.SpecError) as e:
        return {"ok": False, "error": f"generation failed: {e}"}
    rec = run(
        situation,
        controller=job.controller,
        seed=job.noise_seed,
        spec=job.run,
        in_process=in_process,
    )
    record = {
        "outcome": rec.outcome,
        "reason": rec.reason,
        "score": {"total": rec.score, "breakdown": rec.breakdown},
        "events": rec.events,
        "steps": rec.steps,
        "time_s": rec.time_s,
        "failure": rec.failure,
        "coverage": rec.coverage,
        # As the core writes a record: only where the run spec has requirements.
        **({"requirements": verdicts_json(rec.requirements)} if rec.requirements else {}),
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
        "wall_s": rec.cost[0],
        "cpu_s": rec.cost[1],
    }


def _die_with_campaign() -> None:
    """End this worker when the process that asked for it ends, however it ends. The worker's
    parent is the fork server, which outlives a campaign killed outright (its workers keep it
    alive, and it them), so the worker watches the campaign's own sentinel, a pipe that closes
    when the campaign does, and kills itself then; the programs it started die with it."""
    parent = multiprocessing.parent_process()
    if parent is None or parent.sentinel is None:
        die_with_parent()
        return
    sentinel = parent.sentinel

    def watch() -> None:
        multiprocessing.connection.wait([sentinel])
        os.kill(os.getpid(), signal.SIGKILL)

    threading.Thread(target=watch, name="sitgen-campaign-watch", daemon=True).start()


def _worker_start(slots: Any = None) -> None:
    """A pool worker: Ctrl-C is the campaign's to handle (it finishes the runs in flight), and
    the worker dies with the campaign even if that is killed outright. What a controller called
    in it prints goes nowhere, as a host process's output does (the campaign's own output stays
    readable, ``--format json`` included). With ``slots`` (a shared counter), the worker takes
    the next one and keeps to that CPU of those allowed, it and the programs it starts, so that
    a program in lockstep with it shares its core and the workers share the cores out
    (:func:`sitgen.controllers.external.pin_to_one_core`)."""

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _die_with_campaign()
    if slots is not None and hasattr(os, "sched_getaffinity"):
        with slots.get_lock():
            slot = slots.value
            slots.value += 1
        allowed = sorted(os.sched_getaffinity(0))
        pin_to_one_core(allowed[slot % len(allowed)])
    quiet = os.open(os.devnull, os.O_WRONLY)
    for fd in (1, 2):
        os.dup2(quiet, fd)
    os.close(quiet)


def safe_user_job(job: Job, in_process: bool = True, cwd: str | None = None) -> dict[str, Any]:
    """:func:`run_user_job` from the folder ``cwd`` (the campaign's: a worker forked from the
    fork server starts in the folder the server did, and a controller's relative path or module
    is the campaign's), with any failure of sitgen's own on that run stored as its error rather
    than ending the campaign."""
    if cwd is not None and os.getcwd() != cwd:
        os.chdir(cwd)
    try:
        return run_user_job(job, in_process)
    except BaseException as e:  # sitgen's own bug on one run must not end the campaign
        return {"ok": False, "error": f"sitgen failed on this run: {type(e).__name__}: {e}"}


def pool_context() -> multiprocessing.context.BaseContext:
    """How pool workers start: forked from a clean server process, never from this one. A
    process that has used the core's thread pool (a search has) cannot be forked safely: the
    child inherits the pool without its threads, and its first parallel call waits forever.
    The server imports the campaign's code once, so a worker starts in milliseconds."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload([__name__])
    # The server starts carrying this process's controller mark, and so does every process
    # forked from it or from its workers without exec (a user's daemon): /proc shows a forked
    # process the environment its ancestor was executed with, so this process's reaper finds
    # them all should it die outright (sitgen.controllers.marks.marked_env).
    mark = marked_env()[1]
    previous = os.environ.get(MARK)
    os.environ[MARK] = mark
    try:
        multiprocessing.forkserver.ensure_running()
    finally:
        if previous is None:
            del os.environ[MARK]
        else:
            os.environ[MARK] = previous
    return context


IDLE_POOLS: dict[int, ProcessPoolExecutor] = {}
"""Pools whose last batch finished, by worker count, kept for the next batch of this process
(workers start once, not once per batch); shut when the process exits."""


def idle_pool(workers: int) -> ProcessPoolExecutor:
    """An idle pool of ``workers`` workers, kept from an earlier batch or new."""
    pool = IDLE_POOLS.pop(workers, None)
    if pool is not None:
        return pool
    context = pool_context()
    slots = context.Value("i", 0)
    return ProcessPoolExecutor(workers, context, initializer=_worker_start, initargs=(slots,))


@atexit.register
def _shutidle_pools() -> None:
    while IDLE_POOLS:
        shut(IDLE_POOLS.popitem()[1])


def alone(job: Job) -> dict[str, Any]:
    """Run one job in a worker of its own, a ``python:`` class in a host process of its own
    there (so that what killed a worker is reported as the host reports it): its result, or
    an error if the worker dies."""
    pool = ProcessPoolExecutor(1, pool_context(), initializer=_worker_start)
    try:
        return pool.submit(safe_user_job, job, False, os.getcwd()).result()
    except BrokenProcessPool:
        return {
            "ok": False,
            "error": "the worker process running it died (killed by a signal or out of memory)",
        }
    finally:
        shut(pool)


def shut(pool: ProcessPoolExecutor) -> None:
    """Shut a pool down now: queued runs are cancelled and its workers killed (their
    controllers die with them), so nothing outlives the campaign."""
    processes = list(getattr(pool, "_processes", {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        if process.is_alive():
            process.kill()
    for process in processes:
        process.join()
