"""A shrink's probes run: each candidate situation checked and run once, in the core's
threads for built-in controllers (``_core.shrink_probes``) or, for a user's, in the
campaigns' worker pool; a probe says whether it ran, its failure class, every class its
events show and every requirement it violated (``requirement:NAME``) with when each began,
its length and outcome (:mod:`sitgen.triage.shrink` keeps candidates by them)."""

from __future__ import annotations

import json
from typing import Any

from sitgen import _core
from sitgen.execution.campaign import Executor
from sitgen.execution.jobs import Job
from sitgen.triage.requirements import PREFIX as REQUIREMENT


def user_probes(
    candidates: list[str],
    run_spec: dict[str, Any],
    seed: int,
    leg_margin_m: float | None,
    workers: int,
) -> list[dict[str, Any]]:
    """A probe of each candidate (situation JSON), in order, as the core makes one (``ok``,
    then ``problem`` or ``class``, ``first_s``, ``time_s``, ``outcome``), run for a user
    controller in the campaigns' worker pool (a ``python:`` class called in its worker, a
    worker that dies replaced); a run the controller could not finish is skipped, like a
    candidate that is not valid."""
    probes: list[dict[str, Any]] = [{} for _ in candidates]
    jobs = []
    for i, candidate in enumerate(candidates):
        problem = _core.shrink_check(candidate, leg_margin_m)
        if problem is not None:
            probes[i] = {"ok": False, "problem": problem}
        else:
            jobs.append(Job(i, seed, json.loads(candidate), run_spec, run_seed=seed))
    for job, result in Executor(workers, user=True).results(jobs):
        probes[job.index] = _probe(result)
    return probes


def _probe(result: dict[str, Any]) -> dict[str, Any]:
    if not result["ok"]:
        return {"ok": False, "problem": result["error"]}
    record = json.loads(result["record"])
    if record["outcome"] == "error":
        return {"ok": False, "problem": f"the controller failed: {record['reason']}"}
    # A violated requirement shows as its class, from when the violation began.
    violated = [
        (REQUIREMENT + v["name"], float(v["first_violation_s"]))
        for v in record.get("requirements", [])
        if v["violated"]
    ]
    return {
        "ok": True,
        "class": None if record["failure"] is None else record["failure"]["class"],
        "first_s": [*_core.first_seen(result["events_jsonl"], 0), *violated],
        "time_s": record["time_s"],
        "outcome": record["outcome"],
    }
