"""A violated requirement as a failure: class ``requirement:NAME``, its runs ranked by
robustness (worst first), its worst run's robustness under perturbation (a violation that
recurs in 6 of 8 perturbed copies is robust), listed by ``sitgen failures`` beside sitgen's
own distinct failures (docs/requirements.md)."""

from __future__ import annotations

import json
import statistics
from collections.abc import Sequence
from typing import Any

from sitgen import _core
from sitgen.store import Store
from sitgen.triage.failures import DistinctFailure
from sitgen.triage.kill import REQUIREMENT
from sitgen.triage.recall import stored_run
from sitgen.triage.robustness import RERUNS, check_reruns, copies, copy_jobs

PREFIX = REQUIREMENT
"""A requirement's failure class is its name after this."""


def violations(store: Store) -> dict[str, list[dict[str, Any]]]:
    """Each requirement's stored violations, worst robustness first (then run id)."""
    out: dict[str, list[dict[str, Any]]] = {}
    for v in store.requirement_verdicts(violated_only=True):
        out.setdefault(v["name"], []).append(v)
    return out


def requirement_failures(store: Store) -> list[DistinctFailure]:
    """One distinct failure a violated requirement: its class ``requirement:NAME``, runs
    ranked by robustness (worst first), the worst as representative, the median length of the
    intervals that decided the violations as its duration. Heaviest requirement first, then
    worst robustness."""
    total = store.db.execute("SELECT count(*) FROM runs").fetchone()[0]
    measured = store.requirement_robustness()
    scores = dict(store.db.execute("SELECT id, score FROM runs").fetchall())
    costs = store.costs()
    found = []
    found_rows = violations(store)
    for name, rows in found_rows.items():
        worst = rows[0]
        m = measured.get((worst["run_id"], name))
        cpu = [costs[r["run_id"]][1] for r in rows if r["run_id"] in costs]
        found.append(
            DistinctFailure(
                key=PREFIX + name,
                failure_class=PREFIX + name,
                description=f"violated {name}: {worst['formula']}",
                runs=len(rows),
                share=len(rows) / total if total else 0.0,
                best_score=float(scores.get(worst["run_id"], 0.0)),
                representative=worst["run_id"],
                median_duration_s=statistics.median(
                    (r["interval_end_s"] or 0.0) - (r["interval_start_s"] or 0.0) for r in rows
                ),
                run_ids=[r["run_id"] for r in rows],
                recurs=None if m is None else m["recurs"],
                reruns=None if m is None else m["reruns"],
                rerun_classes=[] if m is None else [_as_class(c, name) for c in m["copies"]],
                median_cpu_s=statistics.median(cpu) if cpu else None,
            )
        )
    # Heaviest first, then worst robustness (each requirement's violations come worst first).
    worst = {name: float(rows[0]["robustness"] or 0.0) for name, rows in found_rows.items()}
    weight = {name: float(rows[0]["weight"]) for name, rows in found_rows.items()}
    found.sort(key=lambda f: (-weight[f.key[len(PREFIX) :]], worst[f.key[len(PREFIX) :]]))
    return found


def _as_class(copy: str, name: str) -> str | None:
    """A copy's verdict as a failure class, as the copies of sitgen's own failures read."""
    return {"violated": PREFIX + name, "error": "error"}.get(copy)


def copy_verdict(result: dict[str, Any], name: str) -> str:
    """A perturbed copy's verdict on requirement ``name``: ``violated``, ``satisfied``, or
    ``error`` (the copy did not run, or has no verdict: left out, never counted as not
    recurring)."""
    if not result.get("ok"):
        return "error"
    record = json.loads(result["record"])
    if record.get("outcome") == "error":
        return "error"
    for v in record.get("requirements", []):
        if v["name"] == name:
            if v["robustness"] is None:
                return "error"
            return "violated" if v["violated"] else "satisfied"
    return "error"


def measure_requirements(
    store: Store,
    reruns: int = RERUNS,
    workers: int = 1,
    names: Sequence[str] | None = None,
) -> list[dict[str, Any]]:
    """Measure and store how often each violated requirement's worst violation recurs in
    ``reruns`` perturbed copies of its run, each run to its time limit (a copy cut short
    could read an `eventually` as violated that its whole run satisfies)."""
    reruns = check_reruns(reruns)
    found = violations(store)
    chosen = [(n, rows[0]["run_id"]) for n, rows in found.items() if names is None or n in names]
    jobs = []
    for i, (_, run_id) in enumerate(chosen):
        jobs.extend(copy_jobs(stored_run(store, run_id), reruns, i * reruns, horizon=False))
    results = copies(jobs, workers)
    rows = []
    for i, (name, run_id) in enumerate(chosen):
        verdicts = [copy_verdict(r, name) for r in results[i * reruns : (i + 1) * reruns]]
        rows.append(
            {
                "run_id": run_id,
                "name": name,
                "reruns": sum(v != "error" for v in verdicts),
                "recurs": sum(v == "violated" for v in verdicts),
                "copies": verdicts,
                "sitgen_version": _core.__version__,
            }
        )
    store.record_requirement_robustness(rows)
    return rows
