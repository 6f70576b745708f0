"""What the store hands out and takes in, and its errors: a run's row, a judgement, run ids,
JSON packing, the scoring a rescored store reads through."""

from __future__ import annotations

import hashlib
import json
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

MAX_RUN_ID = 2**63 - 1


"""The largest run id (SQLite's INTEGER is a signed 64-bit number)."""


def is_run_id(value: object) -> bool:
    """Whether ``value`` can be a run id: an integer (not a bool) in [0, 2^63 - 1]. Every place
    a run id enters (the command line, the judging page, a judgements file) goes through the
    store's readers, which treat anything else as a run the store does not hold."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_RUN_ID


WORSE = ("a", "b", "equal")


"""What a judgement says: run ``a`` is more dangerous, run ``b`` is, or neither."""


@dataclass(frozen=True)
class Judgement:
    """One pairwise judgement: which of runs ``a`` and ``b`` is more dangerous (the store's
    ``judgements`` rows; :mod:`sitgen.triage.weights` fits penalties to them)."""

    a: int
    b: int
    worse: str
    who: str = ""
    at: str = ""
    """When, ISO 8601 UTC."""

    def as_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "worse": self.worse, "who": self.who, "at": self.at}


class Scoring(Protocol):
    """What rescoring a store needs of a scoring table (:class:`sitgen.triage.weights.Weights`)."""

    def score(self, stored: Mapping[str, Any], failure_class: str | None) -> float: ...

    def breakdown(self, stored: Mapping[str, Any]) -> dict[str, dict[str, float]]: ...


class StoreError(Exception):
    """A store that cannot be used (wrong file, other campaign, newer schema)."""


class StoreMissing(StoreError):
    """No store where one was named: a mistyped path or a folder (bad input, not damage)."""


def require_store(path: Path) -> None:
    """Raise StoreMissing unless ``path`` is a file: reading a mistyped path must not create
    an empty store."""
    if path.is_dir():
        raise StoreMissing(f"{path}: is a folder, not a campaign store")
    if not path.is_file():
        raise StoreMissing(f"{path}: no such campaign store")


@dataclass(frozen=True)
class RunRow:
    """One stored run, as produced by a campaign."""

    id: int
    situation_seed: int
    situation_spec: dict[str, Any]
    situation_json: str | None
    run_spec: dict[str, Any]
    run_seed: int
    controller: str
    record: dict[str, Any] | None
    """The run record (outcome, reason, score, events, …); None if generation failed."""
    error: str | None
    events_jsonl: str
    trajectory: bytes | None
    robots: int
    generation: int | None = None
    """The search generation that made it (None for a campaign's run)."""
    parents: tuple[int, ...] | None = None
    """The runs a search mutated to make it (empty for a fresh draw; None in a campaign)."""
    genes: dict[str, Any] | None = None
    """A search's genome for it: each varied field's draw and the situation seed."""
    cost: tuple[float, float] | None = None
    """What it cost the machine that made it: (wall seconds, processor seconds)."""
    descriptors: str | None = None
    """Its situation's descriptors (JSON, docs/explain.md), as the core computed them."""
    keep: bool = True
    """Store the run whole (its situation, specs, event log and trajectory), or only its
    summary (a campaign's run: its specs follow from the campaign, and the rest comes back by
    re-simulation, :mod:`sitgen.triage.recall`)."""

    @property
    def whole(self) -> bool:
        """Whether it is stored whole. A summary keeps what ranks, groups and finds the run
        again, not what re-simulation gives back; a run that failed is always kept whole
        (there is nothing to re-run)."""
        return self.keep or self.record is None

    @property
    def outcome_record(self) -> dict[str, Any]:
        """Its run record, or the record of an error where generation failed."""
        return self.record or {
            "outcome": "error",
            "reason": self.error or "unknown failure",
            "score": {"total": 0.0, "breakdown": {}},
            "events": [],
            "steps": 0,
            "time_s": 0.0,
        }

    def situation_values(self) -> tuple[Any, ...]:
        """Its row of ``situations`` (id, seed, spec, terrain, peers, content_hash,
        situation)."""
        situation = json.loads(self.situation_json) if self.situation_json else None
        spec = self.situation_spec
        # A situation given whole (a benchmark world) has no terrain spec to name it by.
        terrain = (
            spec.get("terrain", {}).get("preset")
            or spec.get("terrain", {}).get("source", {}).get("kind")
            or ("given" if "format" in spec else None)
        )
        return (
            self.id,
            self.situation_seed,
            json.dumps(self.situation_spec, sort_keys=True) if self.whole else "",
            terrain,
            len(situation["robots"]) - 1 if situation else None,
            situation["provenance"]["content_hash"] if situation else None,
            self.situation_json if self.whole else None,
        )

    def run_values(self) -> tuple[Any, ...]:
        """Its row of ``runs``, in the table's column order."""
        situation = json.loads(self.situation_json) if self.situation_json else None
        rec = self.outcome_record
        events = rec["events"]
        agent_clearances = [
            e["details"]["min_clearance_m"]
            for e in events
            if e["kind"] == "unsafe_proximity" and e["scored"]
        ]
        failure = rec.get("failure")
        return (
            self.id,
            self.id,
            self.controller,
            json.dumps(self.run_spec, sort_keys=True) if self.whole else "",
            self.run_seed,
            rec["outcome"],
            rec["reason"],
            rec["score"]["total"],
            json.dumps(rec["score"]["breakdown"], sort_keys=True),
            rec["steps"],
            rec["time_s"],
            sum(1 for e in events if e["kind"] == "collision" and e["scored"]),
            min(agent_clearances) if agent_clearances else None,
            sum(1 for e in events if e["kind"] == "waypoint_reached" and e["robot"] == 0),
            len(situation["robots"][0]["waypoints"]) if situation else 0,
            self.events_jsonl if self.whole else "",
            failure["class"] if failure else None,
            json.dumps(failure, sort_keys=True) if failure else None,
            self.generation,
            None if self.parents is None else json.dumps(list(self.parents)),
            None if self.genes is None else json.dumps(self.genes, sort_keys=True),
            pack_json(rec["coverage"]) if rec.get("coverage") else None,
            int(self.whole),
            events_digest(self.events_jsonl),
        )

    def requirement_values(self) -> list[tuple[Any, ...]]:
        """Its rows of ``requirement_verdicts``, one per requirement of its run spec."""
        formulas = {r["name"]: r["formula"] for r in self.run_spec.get("requirement", [])}
        rows = []
        for v in (self.record or {}).get("requirements", []):
            rho = v["robustness"]
            interval = v.get("interval_s") or (None, None)
            rows.append(
                (
                    self.id,
                    v["name"],
                    formulas.get(v["name"], ""),
                    None if rho is None else float(rho),
                    int(v["violated"]),
                    v.get("first_violation_s"),
                    interval[0],
                    interval[1],
                    v["weight"],
                    v.get("error"),
                )
            )
        return rows

    def event_values(self) -> list[tuple[Any, ...]]:
        """Its rows of ``events``, one per event in order."""
        return [
            (
                self.id,
                seq,
                e["kind"],
                e["start_s"],
                e["end_s"],
                e["robot"],
                None if e["other"] is None else str(e["other"]),
                int(e["scored"]),
                json.dumps(e["details"], sort_keys=True),
            )
            for seq, e in enumerate(self.outcome_record["events"])
        ]


def pack_json(value: Any) -> bytes:
    """A JSON value as a stored column holds a long one: sorted-key JSON, zlib'd (a run's
    coverage: its cell names repeat, and shrink to about two fifths)."""
    return zlib.compress(json.dumps(value, sort_keys=True).encode(), 9)


def unpack_json(stored: str | bytes) -> Any:
    """A JSON column's value: zlib'd (:func:`pack_json`) or, as stores before version 7 hold
    it, text."""
    return json.loads(zlib.decompress(stored) if isinstance(stored, bytes) else stored)


def events_digest(events_jsonl: str) -> str:
    """The digest a stored run keeps of its event log: what re-simulation must reproduce."""
    return hashlib.sha256(events_jsonl.encode()).hexdigest()


def main_events(breakdown: dict[str, Any]) -> str:
    """The kinds that earned points, most points first: ``collision×2, unsafe_proximity×1``."""
    ordered = sorted(breakdown.items(), key=lambda kv: (-kv[1]["points"], kv[0]))
    return ", ".join(f"{kind}×{line['count']}" for kind, line in ordered)
