"""A stored run, whole: its situation, trajectory and event log, from the store where the run
was kept whole, else by re-simulation.

A campaign may keep only some runs whole (``--keep-trajectories``); the rest are stored as a
summary (score, outcome, failure class, coverage, the event log's digest). Every run is
deterministic, so a summary's run is regenerated from its spec and seed and run again, and
the result is checked against what was stored: the situation's content hash, the event log's
digest and the score. ``show``, ``report`` and ``shrink`` read runs through here; ``rerun``
uses the same regeneration to confirm a stored run. The store itself knows nothing of how a
campaign builds its jobs: a summary's specs are built again here (:func:`stored_run`).
"""

from __future__ import annotations

import json
import zlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from sitgen import _core
from sitgen.execution.campaign import PACK_ALL, Executor
from sitgen.execution.jobs import Job, build_job, campaign_from_data
from sitgen.run import RunRecord, run
from sitgen.store import Store, StoreError, events_digest
from sitgen.world.situation import Situation, situation_of


@dataclass(frozen=True)
class WholeRun:
    """A stored run with everything a figure, a replay or a shrink needs."""

    situation: Situation
    trajectory: npt.NDArray[np.float32] | None
    """Poses (x, y, heading) per step per robot; None only for a run stored whole before
    trajectories were kept."""
    events_jsonl: str
    resimulated: bool
    """Whether it came from re-simulation rather than from the store."""


def stored_run(store: Store, run_id: int) -> dict[str, Any]:
    """Run ``run_id`` as stored (:meth:`Store.run_row`), with the situation and run specs of a
    run kept as a summary built again from its campaign's job (the build is deterministic)."""
    row = store.run_row(run_id)
    if row["situation_spec"] is None:
        campaign = store.campaign()
        if campaign is None or store.kind() != "campaign":
            raise StoreError(f"{store.path}: run {run_id} is a summary, but no campaign is stored")
        job = build_job(campaign_from_data(campaign["spec"]), campaign["seed"], run_id)
        # Stored specs went through JSON with sorted keys; so do these, to compare equal.
        row["situation_spec"] = json.loads(json.dumps(job.situation, sort_keys=True))
        row["run_spec"] = json.loads(json.dumps(job.run, sort_keys=True))
    return row


def regenerate(row: dict[str, Any]) -> Situation:
    """The situation of stored run ``row`` (:func:`stored_run`), made again from its spec
    and seed (or read back, if it was given whole). Raises GenerationFailed."""
    return situation_of(row["situation_spec"], row["situation_seed"])


def resimulate(
    row: dict[str, Any], sensed: bool = False, signals: bool = False
) -> tuple[Situation, RunRecord]:
    """Stored run ``row`` generated and run again, as it was run (``sensed``: keeping what
    the agent sensed, :class:`sitgen.run.Sensed`; ``signals``: every requirement signal in
    its record, which changes nothing of the run)."""
    situation = regenerate(row)
    # The stored run spec names the controller if the campaign gave one (with its parameters
    # and any seeded fault); otherwise the situation's own drives, as it did.
    spec = {**row["run_spec"], "signals": True} if signals else row["run_spec"]
    try:
        record = run(situation, seed=row["run_seed"], spec=spec, sensed=sensed)
    except _core.SpecError as e:
        raise StoreError(f"run {row['id']}: its stored run spec does not load ({e})") from None
    return situation, record


def resimulate_checked(
    store: Store, row: dict[str, Any], sensed: bool = False, signals: bool = False
) -> tuple[Situation, RunRecord]:
    """:func:`resimulate`, checked to give back the run that was stored: its situation's
    content hash, its event log's digest and its score. Raises StoreError if it does not
    (another sitgen version, or a controller that is not deterministic) or if the situation no
    longer generates."""
    try:
        situation, record = resimulate(row, sensed, signals)
    except _core.GenerationFailed as e:
        raise StoreError(
            f"{store.path}: run {row['id']}: its situation no longer generates: {e}"
        ) from None
    check_same(store, row, situation, record.events_jsonl, record.score, record.outcome,
               record.reason)  # fmt: skip
    return situation, record


def check_same(
    store: Store,
    row: dict[str, Any],
    situation: Situation,
    events_jsonl: str,
    score: float,
    outcome: str,
    reason: str | None,
) -> None:
    """Raise StoreError unless a run made again of stored run ``row`` (its ``situation``,
    event log, score, outcome and reason) is the run that was stored: the situation's content
    hash, the event log's digest and the score."""
    run_id = row["id"]
    differs = [
        what
        for what, same in (
            ("situation", situation.content_hash == row["content_hash"]),
            ("event log", events_digest(events_jsonl) == row["events_sha256"]),
            ("score", score == row["stored_score"]),
        )
        if not same
    ]
    if differs and outcome == "error" and row["outcome"] != "error":
        # Not a different run: this one could not be made (a program that is gone, a class
        # that no longer loads).
        raise StoreError(f"{store.path}: run {run_id} could not be run again: {reason}")
    if differs:
        version = (store.campaign() or {}).get("sitgen_version", "another version")
        raise StoreError(
            f"{store.path}: run {run_id} does not re-simulate the same: it gives a different "
            f"{', '.join(differs)} (stored by sitgen {version}, this is {_core.__version__}; "
            f"or its controller is not deterministic)"
        )


def whole_runs(
    store: Store, rows: Sequence[dict[str, Any]], workers: int
) -> list[WholeRun | StoreError | None]:
    """:func:`whole_run` of each of ``rows``, those kept as summaries made again together on
    ``workers`` (a process pool where a controller runs outside the core: a slow user
    controller's runs then cost its time once, shared out, not one after another here); a run
    that cannot be had whole gives its StoreError in its place."""
    out: list[WholeRun | StoreError | None] = []
    jobs: list[Job] = []
    for i, row in enumerate(rows):
        kept = _kept_whole(store, row)
        out.append(kept)
        if kept is None and row["content_hash"] is not None:
            jobs.append(Job(i, row["situation_seed"], row["situation_spec"], row["run_spec"],
                            run_seed=row["run_seed"]))  # fmt: skip
    if not jobs:
        return out
    for job, result in Executor(workers, user=any(j.in_python for j in jobs),
                                pack_rule=lambda: PACK_ALL).results(jobs):  # fmt: skip
        try:
            out[job.index] = _checked(store, rows[job.index], result)
        except StoreError as e:
            out[job.index] = e
    return out


def _checked(store: Store, row: dict[str, Any], result: dict[str, Any]) -> WholeRun:
    """A job's ``result`` for stored run ``row`` made again, whole, checked to be the run
    that was stored (:func:`check_same`)."""
    if not result.get("ok"):
        raise StoreError(f"{store.path}: run {row['id']} could not be run again: "
                         f"{result.get('error')}")  # fmt: skip
    record = json.loads(result["record"])
    situation = Situation(result["situation"], check_start=False)
    check_same(store, row, situation, result["events_jsonl"], record["score"]["total"],
               record["outcome"], record.get("reason"))  # fmt: skip
    flat = np.frombuffer(zlib.decompress(result["trajectory"]), dtype="<f4")
    trajectory = flat.reshape(-1, int(result["robots"]), 3)
    return WholeRun(situation, trajectory, result["events_jsonl"], resimulated=True)


def _kept_whole(store: Store, row: dict[str, Any]) -> WholeRun | None:
    """Stored run ``row`` whole as the store keeps it, if it does."""
    if row["content_hash"] is None or not row["kept"] or row["situation"] is None:
        return None
    trajectory = store.trajectory(row["id"])
    if trajectory is None:
        return None
    situation = Situation(row["situation"], check_start=False)
    return WholeRun(situation, trajectory, row["events_jsonl"], resimulated=False)


def whole_run(store: Store, row: dict[str, Any]) -> WholeRun | None:
    """Stored run ``row`` (:func:`stored_run`) whole; None if its situation was never
    generated. Raises StoreError if re-simulation does not give back the run that was stored
    (another sitgen version)."""
    if row["content_hash"] is None:
        return None
    kept = _kept_whole(store, row)
    if kept is not None:
        return kept
    situation, record = resimulate_checked(store, row)
    trajectory = record.trajectory.astype(np.float32)
    return WholeRun(situation, trajectory, record.events_jsonl, resimulated=True)
