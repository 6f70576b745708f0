"""Whether a collision with a robot could have been escaped (docs/avoidability.md): each
judged run's contact between the agent and a robot that decided its failure (else its first),
the agent's admissible manoeuvres
searched for an escape from the moment it first saw that robot and from the start, in the
core (``sitgen_core::avoidability``). A campaign judges its peer-contact failures' top runs;
``sitgen avoidability DB`` judges any.

A verdict sorts a distinct failure: collisions no controller with this sensor could have
escaped rank after the controller's own mistakes (:func:`tier`)."""

from __future__ import annotations

import json
from collections.abc import Iterable, Sequence
from typing import Any

from sitgen import _core
from sitgen.controllers.user import is_user_controller
from sitgen.store import Store, StoreError
from sitgen.triage.recall import WholeRun, regenerate, stored_run, whole_runs

AFTER_S = 5.0
"""How long past the collision an escape must stay clear, seconds (the core's default)."""

PEER_CONTACTS = (
    "drove_into_unseen_peer",
    "drove_into_seen_peer",
    "collided_while_oscillating",
    "collided_as_both_closed_in",
    "struck_while_moving_unseen",
    "struck_while_moving_seen",
    "struck_while_stopped_unseen",
    "struck_while_stopped_seen",
)
"""The failure classes of a contact between the agent and a robot: the runs judged."""

VERDICTS = ("avoidable", "unavoidable_with_this_sensor", "unavoidable")

WORDS = {
    "avoidable": "avoidable",
    "unavoidable_with_this_sensor": "unavoidable with this sensor",
    "unavoidable": "unavoidable",
}

PER_FAILURE = 5
"""A campaign judges this many of each peer-contact distinct failure's top runs."""


def tier(verdict: str | None) -> int:
    """Where a distinct failure whose representative has ``verdict`` ranks: the controller's
    own mistakes (and anything not judged) first, then what a better sensor might have
    saved, then what nothing could have."""
    return {"unavoidable_with_this_sensor": 1, "unavoidable": 2}.get(verdict or "", 0)


def judge(store: Store, run_ids: Iterable[int], workers: int = 1, after_s: float = AFTER_S,
          again: bool = False) -> list[dict[str, Any]]:  # fmt: skip
    """Judge and store each of ``run_ids``'s first collision with a robot (those judged before
    at the same ``after_s`` are kept unless ``again``). Runs without one store nothing; a run
    that cannot be judged (its situation no longer generates, an external controller) stores
    its ``error``. Returns the rows stored."""
    done = store.avoidability()
    wanted = [
        i for i in dict.fromkeys(run_ids)
        if again or i not in done or done[i]["after_s"] != after_s
    ]  # fmt: skip
    jobs, recorded, failed = [], [], []
    rows = [stored_run(store, run_id) for run_id in wanted]
    # A controller that runs outside the core: its recorded path stands in for it (runs kept
    # as summaries made again through it, on the workers).
    users = [row for row in rows if is_user_controller(row["controller"])]
    for row, whole in zip(users, whole_runs(store, users, max(1, workers)), strict=True):
        try:
            if isinstance(whole, StoreError):
                raise ValueError(str(whole))
            recorded.append((row["id"], _recorded_job(row, json.dumps(row["run_spec"]), whole)))
        except ValueError as e:
            failed.append(_row(row["id"], after_s, error=str(e)))
    for row in rows:
        run_id, spec = row["id"], json.dumps(row["run_spec"])
        if is_user_controller(row["controller"]):
            continue
        situation = row["situation"] if row.get("kept") and row.get("situation") else None
        if situation is None:
            try:
                situation = regenerate(row).to_json()
            except (_core.GenerationFailed, _core.SpecError) as e:
                failed.append(_row(run_id, after_s, error=f"its situation does not generate: {e}"))
                continue
        elif not isinstance(situation, str):
            situation = json.dumps(situation)
        jobs.append((run_id, (situation, spec, row["run_seed"], _deciding_s(row))))
    threads = max(1, workers)
    results = _core.judge_avoidability([j for _, j in jobs], after_s, threads)
    results += _core.judge_avoidability_recorded([j for _, j in recorded], after_s, threads)
    judged = list(failed)
    for (run_id, _), text in zip([*jobs, *recorded], results, strict=True):
        out = json.loads(text)
        if "judgement" in out:
            judged.append(_row(run_id, after_s, **out["judgement"]))
        elif "error" in out:
            judged.append(_row(run_id, after_s, error=out["error"]))
    store.record_avoidability(judged)
    return judged


def _deciding_s(row: dict[str, Any]) -> float | None:
    """When the contact that decided a run's failure began, if its class is a contact with a
    robot (None: judge its first contact with a robot)."""
    failure = row.get("failure") or {}
    if failure.get("class") not in PEER_CONTACTS:
        return None
    start = failure.get("features", {}).get("start_s")
    return None if start is None else float(start)


def _recorded_job(
    row: dict[str, Any], spec: str, whole: WholeRun | None
) -> tuple[str, str, int, list[float], int, int]:
    """A run of a controller outside the core (stored ``row``, had ``whole``), as the core
    judges it from its record: the situation, run spec, seed, every pose, and its first
    collision with a robot (from its event log). Raises ValueError if it has none."""
    if whole is None or whole.trajectory is None:
        raise ValueError("its situation was never generated")
    agent = next(r.id for r in whole.situation.robots if r.role == "agent")
    dt_s = float(row["run_spec"].get("sim", {}).get("dt_s", 0.1))
    events = [json.loads(line) for line in whole.events_jsonl.splitlines()]
    # The contact that decided the failure, else the first with a robot.
    deciding = [events[i] for i in (row.get("failure") or {}).get("events", []) if i < len(events)]
    for e in [*deciding, *events]:
        parties = {e["robot"], e["other"]}
        if e["kind"] == "collision" and agent in parties and isinstance(e["other"], int):
            robot = e["other"] if e["robot"] == agent else e["robot"]
            poses: list[float] = whole.trajectory.ravel().astype(float).tolist()
            return (
                whole.situation.to_json(), spec, row["run_seed"], poses,
                round(e["start_s"] / dt_s), robot,
            )  # fmt: skip
    raise ValueError("no collision of the agent with a robot in its event log")


def _row(run_id: int, after_s: float, **fields: Any) -> dict[str, Any]:
    return {"run_id": run_id, "after_s": after_s, "sitgen_version": _core.__version__, **fields}


def judged_runs(store: Store, failures: Sequence[Any], per_failure: int = PER_FAILURE) -> list[int]:
    """The runs a campaign judges: each peer-contact distinct failure's representative and its
    ``per_failure`` best-scoring runs."""
    scores = dict(store.db.execute("SELECT id, score FROM runs").fetchall())
    out: list[int] = []
    for f in failures:
        if f.failure_class in PEER_CONTACTS:
            best = sorted(f.run_ids, key=lambda i: (-scores[i], i))[:per_failure]
            out.extend([f.representative, *best])
    return list(dict.fromkeys(out))


def measure_avoidability(store: Store, failures: Sequence[Any], workers: int = 1) -> int:
    """Judge every peer-contact distinct failure's top runs (:func:`judged_runs`) not judged
    yet; returns how many were judged."""
    return len(judge(store, judged_runs(store, failures), workers))


def in_words(verdict: str | None, avoidable: int | None, judged: int | None) -> str:
    """A distinct failure's avoidability as its table shows it: its representative's verdict
    and how many of its judged runs were avoidable, e.g. ``avoidable (4/5)``; empty if
    nothing was judged."""
    if verdict is None and not judged:
        return ""
    head = WORDS.get(verdict or "", "not judged")
    return f"{head} ({avoidable}/{judged} avoidable)" if judged else head


def describe(row: dict[str, Any]) -> str:
    """A judged run's verdict in words, e.g. ``avoidable: stop at 5.1 s (sighted 13.4 s before
    contact)``."""
    if row.get("error"):
        return f"not judged: {row['error']}"
    verdict = WORDS.get(row["verdict"], row["verdict"])
    rest = "; struck at rest" if row["at_rest"] else ""
    seen = (
        f"seen {row['collision_s'] - row['sighted_s']:.1f} s before contact"
        if row["sighted_s"] is not None
        else "not seen before contact"
    )
    w = row["witness"]
    escape = f"; escape from {w['from_s']:.1f} s: {manoeuvre(w['segments'])}" if w else ""
    return f"{verdict} (robot {row['robot']} at {row['collision_s']:.1f} s, {seen}{rest}){escape}"


def manoeuvre(segments: Sequence[dict[str, Any]]) -> str:
    """A witness's commands in words: ``stop``, ``0.50 m/s, 0.79 rad/s for 1.0 s, then stop``."""
    words = []
    for s in segments:
        v, w = s["v_m_s"], s["w_rad_s"]
        what = "stop" if v == 0 and w == 0 else f"{v:+.2f} m/s, {w:+.2f} rad/s"
        words.append(f"{what} for {s['duration_s']:.1f} s")
    return ", then ".join(words)
